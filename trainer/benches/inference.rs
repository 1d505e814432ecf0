//! Single-image inference on one core (a rayon pool of one thread, as the grasp
//! controller would run it beside the camera): the default model on a preprocessed
//! image, the preprocessing of a raw 640×480 frame, the two together, and building
//! the colour lookup table that preprocessing uses.
//!
//! `cargo bench -p softtouch-trainer --bench inference`

use criterion::{Criterion, criterion_group, criterion_main};
use softtouch_schemas::ContactPose;
use softtouch_sim::SceneSim;
use softtouch_trainer::{FingerTable, ModelArtifact, ModelConfig, Predictor};

fn frame() -> (usize, usize, Vec<u8>) {
    let scene = softtouch_schemas::defaults::scene();
    let sim = SceneSim::new(&scene, 1).expect("default scene");
    let pose = ContactPose {
        x_m: 0.03,
        z_m: 0.01,
        theta_rad: 1.2,
    };
    let rendered = sim
        .render(&scene.rods[0].name, &pose, 0, 0.0)
        .expect("render");
    (
        rendered.image.width() as usize,
        rendered.image.height() as usize,
        rendered.image.into_raw(),
    )
}

fn inference(c: &mut Criterion) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let config = ModelConfig::default();
    let artifact = ModelArtifact::untrained(&config, 1).expect("default config");
    let mut predictor = Predictor::new(artifact);
    let (w, h, rgb) = frame();
    let table = FingerTable::new(&config.preprocess);
    let image = table.apply(w, h, &rgb).expect("frame");

    let p = &config.preprocess;
    let mut group = c.benchmark_group(format!(
        "one core, default model ({0}×{0}×{1}, width {2}, latent {3})",
        p.size_px, p.channels, config.width, config.latent
    ));
    group.bench_function("model on a preprocessed image", |b| {
        pool.install(|| b.iter(|| predictor.predict_preprocessed(&image).expect("predict")));
    });
    let mut out = vec![0.0; config.preprocess.input_len()];
    group.bench_function("preprocess a 640×480 frame", |b| {
        pool.install(|| b.iter(|| table.apply_into(w, h, &rgb, &mut out).expect("frame")));
    });
    group.bench_function("640×480 frame → wrench", |b| {
        pool.install(|| b.iter(|| predictor.predict_rgb(w, h, &rgb).expect("predict")));
    });
    group.finish();

    // Paid once per Predictor and per dataset load, not per frame.
    let mut group = c.benchmark_group("once per model");
    group.sample_size(10);
    group.bench_function("build the colour lookup table (2²⁴ colours)", |b| {
        pool.install(|| b.iter(|| FingerTable::new(&config.preprocess)));
    });
    group.finish();
}

criterion_group!(benches, inference);
criterion_main!(benches);
