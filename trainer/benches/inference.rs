//! Single-image inference on one core (a rayon pool of one thread, as the grasp
//! controller would run it beside the camera): the default model on a preprocessed
//! image, the preprocessing of a raw 640×480 frame (brightness, and chroma), the two
//! together, a medium's image tare on the frame (laid out once, and laid out every
//! frame as it was), and building the colour lookup table that preprocessing uses.
//!
//! `cargo bench -p softtouch-trainer --bench inference`

use criterion::{Criterion, criterion_group, criterion_main};
use softtouch_schemas::ContactPose;
use softtouch_sim::SceneSim;
use softtouch_trainer::{
    FingerTable, GainMap, ImageTare, ModelArtifact, ModelConfig, Predictor, PreparedTare,
};

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
    // The same frame for a model that reads chroma (`train --signal chroma`).
    let chroma = FingerTable::new(&softtouch_trainer::Preprocess {
        signal: softtouch_trainer::Signal::Chroma,
        ..config.preprocess
    });
    group.bench_function("preprocess a 640×480 frame, chroma", |b| {
        pool.install(|| b.iter(|| chroma.apply_into(w, h, &rgb, &mut out).expect("frame")));
    });
    group.bench_function("640×480 frame → wrench", |b| {
        pool.install(|| b.iter(|| predictor.predict_rgb(w, h, &rgb).expect("predict")));
    });
    // A water tare as `grasp trials --tare` fits it: the port's 1.333, a colour per
    // channel and a gain map.
    let tare = water_tare(w, h);
    let prepared = PreparedTare::new(&tare, w, h).expect("tare");
    let mut tared = Vec::new();
    group.bench_function("tare, laid out once", |b| {
        pool.install(|| {
            b.iter(|| prepared.apply_into(w, h, &rgb, &mut tared).expect("tare"));
        });
    });
    group.bench_function("tare, laid out once, two cores", |b| {
        let fork = softtouch_trainer::ScopedThread;
        b.iter(|| {
            prepared
                .apply_on(w, h, &rgb, &mut tared, Some(&fork))
                .expect("tare");
        });
    });
    group.bench_function("tare, laid out per frame", |b| {
        pool.install(|| b.iter(|| tare.apply(w, h, &rgb).expect("tare")));
    });
    predictor.set_tare(Some(tare));
    group.bench_function("frame → wrench via tare", |b| {
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

fn water_tare(w: usize, h: usize) -> ImageTare {
    let mut tare = ImageTare::identity(w, h);
    tare.scale = 1.333;
    tare.gain = [1.445, 0.962, 0.833];
    tare.offset = [24.8, 10.8, -4.0];
    let (mw, mh) = (w / 4, h / 4);
    tare.gain_map = Some(GainMap {
        shrink: 4,
        width: mw,
        height: mh,
        gains: (0..mw * mh * 3)
            .map(|i| 0.8 + (i % 7) as f32 * 0.05)
            .collect(),
    });
    tare
}

criterion_group!(benches, inference);
criterion_main!(benches);
