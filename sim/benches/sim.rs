//! One simulated sample, stage by stage: contact, lattice solve, drawing, image
//! effects, PNG encoding, and the whole. `absent_effects` shows that a scene with no
//! effects spends nothing on them. The whole-sample rows alternate two poses, so the
//! renderer's copy of the last drawn lattice never serves them (as in a collection,
//! where every sample is a new pose); `8_same_pose_again` is that copy's case (a
//! steady grasp).
//!
//! `cargo bench --workspace --bench sim`

use criterion::{Criterion, criterion_group, criterion_main};
use softtouch_schemas::{ContactPose, SceneSpec, config, defaults};
use softtouch_sim::{SceneSim, encode_png};
use std::hint::black_box;

fn scenes() -> (SceneSpec, SceneSpec) {
    let mut air = defaults::scene();
    air.effects.clear();
    let water: SceneSpec = config::load_toml(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/water.toml"),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    (air, water)
}

fn bench(c: &mut Criterion) {
    let (air, water) = scenes();
    let pose = ContactPose {
        x_m: 0.035,
        z_m: 0.012,
        theta_rad: 0.8,
    };
    let rod = "circle-10";
    let sim = SceneSim::new(&air, 1).unwrap_or_else(|e| panic!("{e}"));
    let wsim = SceneSim::new(&water, 1).unwrap_or_else(|e| panic!("{e}"));
    let frame = sim
        .render(rod, &pose, 0, 0.0)
        .unwrap_or_else(|e| panic!("{e}"));

    let mut g = c.benchmark_group("sample");
    g.bench_function("1_contact", |b| {
        b.iter(|| sim.stage_contact(rod, black_box(&pose)))
    });
    g.bench_function("2_contact+lattice_solve", |b| {
        b.iter(|| sim.stage_deform(rod, black_box(&pose)))
    });
    g.bench_function("3_contact+solve+draw", |b| {
        b.iter(|| sim.stage_draw(rod, black_box(&pose)))
    });
    let mut img = frame.image.as_raw().clone();
    g.bench_function("4a_absent_effects", |b| {
        b.iter(|| sim.stage_effects(black_box(&mut img), 3, 0.1))
    });
    g.bench_function("4b_water_effects", |b| {
        b.iter(|| wsim.stage_effects(black_box(&mut img), 3, 0.1))
    });
    g.bench_function("5_png_encode", |b| {
        b.iter(|| encode_png(black_box(&frame.image)))
    });
    let other = ContactPose { x_m: 0.03, ..pose };
    let poses = [pose, other];
    let mut k = 0;
    g.bench_function("6_full_sample_air", |b| {
        b.iter(|| {
            k += 1;
            let r = sim
                .render(rod, black_box(&poses[k % 2]), 0, 0.0)
                .unwrap_or_else(|e| panic!("{e}"));
            encode_png(&r.image)
        })
    });
    g.bench_function("7_full_sample_water", |b| {
        b.iter(|| {
            k += 1;
            let r = wsim
                .render(rod, black_box(&poses[k % 2]), 3, 0.1)
                .unwrap_or_else(|e| panic!("{e}"));
            encode_png(&r.image)
        })
    });
    g.bench_function("8_same_pose_again_water_no_png", |b| {
        b.iter(|| wsim.render(rod, black_box(&pose), 3, 0.1))
    });
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(2));
    targets = bench
}
criterion_main!(benches);
