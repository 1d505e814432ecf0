//! The control cycle's compute, frame → preprocess → inference → projection → stepper
//! → rPR register words, with an untrained net of the default architecture (SVAE,
//! 32×32 input, width 16, latent 32; timing does not depend on the weights) on one
//! core: burn's flex backend runs its kernels on rayon, so the cycle runs inside a
//! one-thread rayon pool (`ThreadPool::install`), as the trainer's latency benchmark
//! does. The frame is a real 640×480 RGB frame of the simulated finger pressed on a rod,
//! raw (RGB8) and as a JPEG (a V4L2 camera in MJPEG mode: the decode is in the cycle).
//! Target: median ≤ 1.5 ms.
//!
//! `cargo bench --workspace --bench cycle`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use softtouch_drivers::Frame;
use softtouch_drivers::hande::regs;
use softtouch_drivers::{GripperCommand, gripper::STROKE_MM};
use softtouch_grasp::{ForceEstimator, Projection, Stepper, StepperConfig, Stroke};
use softtouch_schemas::{ArmPose, ContactPose, FrameFormat, FrameMeta, TimestampNs, defaults};
use softtouch_sim::SceneSim;
use softtouch_trainer::{ModelArtifact, ModelConfig, Predictor};

fn frame() -> Frame {
    let scene = defaults::scene();
    let sim = SceneSim::new(&scene, 1).unwrap_or_else(|e| panic!("{e}"));
    let rod = scene.rods[0].name.clone();
    let pose = ContactPose {
        x_m: 0.02,
        z_m: 0.005,
        theta_rad: 0.3,
    };
    let r = sim
        .render(&rod, &pose, 0, 0.0)
        .unwrap_or_else(|e| panic!("{e}"));
    Frame {
        meta: FrameMeta {
            t: TimestampNs::ZERO,
            sequence: 0,
            width: r.image.width(),
            height: r.image.height(),
            format: FrameFormat::Rgb8,
        },
        data: r.image.into_raw(),
    }
}

fn bench(c: &mut Criterion) {
    let frame = frame();
    let artifact =
        ModelArtifact::untrained(&ModelConfig::default(), 1).unwrap_or_else(|e| panic!("{e}"));
    let mut predictor = Predictor::new(artifact);
    let projection = Projection::along_world_y(ArmPose::from_translation_yaw(
        [0.0; 3],
        -std::f64::consts::FRAC_PI_2,
    ))
    .unwrap_or_else(|e| panic!("{e}"));
    let stepper = Stepper::new(StepperConfig {
        gain_n_per_mm: 4.0,
        tolerance_n: 0.1,
        saturation_n: 1e6,
        stroke: Stroke {
            open_count: 3,
            closed_count: 230,
            mm_per_count: STROKE_MM / 227.0,
        },
    })
    .unwrap_or_else(|e| panic!("{e}"));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap_or_else(|e| panic!("{e}"));
    // The same frame as a V4L2 camera in MJPEG mode delivers it: the decode is part of
    // the cycle then.
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 90)
        .encode(
            &frame.data,
            frame.meta.width,
            frame.meta.height,
            image::ExtendedColorType::Rgb8,
        )
        .unwrap_or_else(|e| panic!("{e}"));
    let jpeg_frame = Frame {
        meta: FrameMeta {
            format: FrameFormat::Jpeg,
            ..frame.meta
        },
        data: jpeg,
    };
    let mut g = c.benchmark_group("control_cycle");
    for (name, frame) in [
        ("rgb8_frame_to_rpr_1_thread", &frame),
        ("jpeg_frame_to_rpr_1_thread", &jpeg_frame),
    ] {
        g.bench_function(name, |b| {
            pool.install(|| {
                b.iter(|| {
                    let wrench = predictor
                        .estimate(black_box(frame))
                        .unwrap_or_else(|e| panic!("{e}"));
                    let f_est = wrench.and_then(|w| projection.grip_force_n(&w));
                    let step = stepper.step(black_box(120), 1.6, f_est);
                    regs::encode_output(
                        regs::R_ACT | regs::R_GTO,
                        GripperCommand {
                            position: step.position_request,
                            speed: 128,
                            force: 255,
                        },
                    )
                });
            });
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
