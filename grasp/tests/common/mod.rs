//! What the grasp tests share: the 20 mm rod, a tiny SVAE trained on its presses
//! (once per test binary), the projection of the finger's push onto the grip, and the
//! simulator's truth projected like the estimate. Each test file includes it with
//! `mod common;`.
// Each test file uses a part of it; the items are `pub` for the files that include it.
#![allow(dead_code, unreachable_pub)]

use std::sync::OnceLock;

use rand::{RngExt, SeedableRng};
use softtouch_grasp::{Projection, TrueForce};
use softtouch_schemas::{ArmPose, ContactPose, TimestampNs};
use softtouch_sim::SoftGraspHandle;
use softtouch_trainer::labels::label_from_si;
use softtouch_trainer::{
    Example, ModelConfig, ModelKind, Predictor, Preprocess, Quiet, Splits, TrainConfig, train,
};

pub const ROD: &str = "circle-20";
pub const DIAMETER_M: f64 = 0.02;

/// The default scene with a 20 mm round rod added: the presses the model learns from.
fn training_scene() -> softtouch_schemas::SceneSpec {
    let mut scene = softtouch_schemas::defaults::scene();
    scene.rods.push(softtouch_schemas::RodSpec {
        name: ROD.into(),
        shape: softtouch_schemas::RodShape::Circle,
        size_m: DIAMETER_M,
        aspect: 1.0,
    });
    scene
}

/// A tiny SVAE trained on 240 presses of the 20 mm round rod near the side the grasp
/// uses (16×16, width 4; trained once per test binary, a few seconds).
fn model_bytes() -> &'static [u8] {
    static BYTES: OnceLock<Vec<u8>> = OnceLock::new();
    BYTES.get_or_init(|| {
        let sim = softtouch_sim::SceneSim::new(&training_scene(), 3).expect("scene");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
        let p = Preprocess {
            size_px: 16,
            ..Preprocess::default()
        };
        let mut all: Vec<Example> = (0..240)
            .map(|i| {
                let pose = ContactPose {
                    x_m: rng.random_range(-0.004..=0.03),
                    z_m: rng.random_range(-0.01..=0.01),
                    theta_rad: rng.random_range(-0.3..=0.3),
                };
                let r = sim.render(ROD, &pose, i, 0.0).expect("renders");
                let w = r.wrench_in_sensor;
                Example {
                    image: p.apply(640, 480, r.image.as_raw()).expect("preprocesses"),
                    label: label_from_si(w.force_n, w.torque_nm),
                }
            })
            .collect();
        let test = all.split_off(200);
        let val = all.split_off(180);
        let splits = Splits {
            train: all,
            val,
            test,
        };
        let config = ModelConfig {
            kind: ModelKind::Svae,
            width: 4,
            latent: 8,
            preprocess: p,
            ..ModelConfig::default()
        };
        let t = TrainConfig {
            epochs: 25,
            batch_size: 16,
            learning_rate: 3e-3,
            lr_decay: 0.95,
            patience: 0,
            ..TrainConfig::default()
        };
        let trained = train(&config, &t, &splits, None, &mut Quiet).expect("trains");
        trained.artifact.to_bytes().expect("serialises")
    })
}

pub fn predictor() -> Predictor {
    Predictor::from_bytes(model_bytes()).expect("loads")
}

/// The finger's sensor +x faces the object: its push (−x) is the world's +y.
pub fn projection() -> Projection {
    Projection::along_world_y(ArmPose::from_translation_yaw(
        [0.0; 3],
        -std::f64::consts::FRAC_PI_2,
    ))
    .expect("valid")
}

/// The simulator's truth, projected like the estimate: recorded, never fed back.
#[derive(Debug)]
pub struct SimTruth(pub SoftGraspHandle, pub Projection);

impl TrueForce for SimTruth {
    fn true_force_n(&mut self, t: TimestampNs) -> Option<f64> {
        self.0
            .true_wrench(t)
            .ok()
            .and_then(|w| self.1.grip_force_n(&w))
    }
}
