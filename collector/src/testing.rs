//! Test fixtures (the `testing` feature, on for this crate's tests and examples): a
//! store in a fresh temporary directory, the [`SampleBuilder`], runs of samples drawn
//! from a seed, and test-pattern frames. They panic on any error.

pub use crate::synthetic::SampleBuilder;

use crate::store::{FrameRecord, NewRun, RunId, Store};
use softtouch_drivers::Frame;
use softtouch_schemas::{
    ContactPose, FrameFormat, FrameMeta, Medium, TimestampNs, Wrench, defaults,
};
use std::future::Future;
use tempfile::TempDir;

/// Runs `f` on a fresh current-thread runtime.
pub fn block_on<F: Future>(f: F) -> F::Output {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap_or_else(|e| panic!("{e}"))
        .block_on(f)
}

/// A fresh temporary directory, removed when dropped.
#[must_use]
pub fn tempdir() -> TempDir {
    tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"))
}

pub use crate::store::testing::{TEST_POSTGRES_ENV, fresh_target, on_postgres};

/// A new store at `file` in a fresh temporary directory (which must outlive it), or a
/// new PostgreSQL database ([`fresh_target`]).
pub async fn temp_store(file: &str) -> (TempDir, Store) {
    let dir = tempdir();
    let target = fresh_target(dir.path(), file).await;
    let store = Store::open(target).await.unwrap_or_else(|e| panic!("{e}"));
    (dir, store)
}

/// Deterministic draws for synthetic data (a 64-bit LCG).
#[derive(Debug, Clone)]
pub struct Lcg(pub u64);

impl Lcg {
    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// x in 0–50 mm, z within ±50 mm, θ within ±π.
    pub fn pose(&mut self) -> ContactPose {
        ContactPose {
            x_m: self.range(0.0, 0.05),
            z_m: self.range(-0.05, 0.05),
            theta_rad: self.range(-std::f64::consts::PI, std::f64::consts::PI),
        }
    }

    /// Fx, Fy within ±3 N, Fz in −10…0.5 N, Tx, Ty within ±0.6 N·m, Tz within ±0.1 N·m.
    pub fn wrench(&mut self) -> Wrench {
        Wrench::from_array([
            self.range(-3.0, 3.0),
            self.range(-3.0, 3.0),
            self.range(-10.0, 0.5),
            self.range(-0.6, 0.6),
            self.range(-0.6, 0.6),
            self.range(-0.1, 0.1),
        ])
    }
}

/// A run's provenance. [`RunPlan::new`]: `circle-10` in one block, in air, with the
/// embedded default rig and on-land scene.
#[derive(Debug, Clone)]
pub struct RunPlan {
    pub seed: u64,
    pub samples: u64,
    /// Rods in order, `rod_block` samples each, cycled.
    pub rods: Vec<String>,
    pub rod_block: u64,
    pub medium: Medium,
    pub scene_name: String,
    pub rig_toml: String,
    pub scene_toml: String,
}

impl RunPlan {
    #[must_use]
    pub fn new(seed: u64, samples: u64) -> Self {
        Self {
            seed,
            samples,
            rods: vec!["circle-10".into()],
            rod_block: samples.max(1),
            medium: Medium::Air,
            scene_name: "on-land".into(),
            rig_toml: defaults::RIG_TOML.into(),
            scene_toml: defaults::SCENE_TOML.into(),
        }
    }

    /// Creates the run (status `running`).
    pub async fn create(&self, store: &Store) -> RunId {
        store
            .create_run(&NewRun {
                seed: self.seed,
                samples_planned: self.samples,
                rod_schedule: &self.rods,
                rod_block: self.rod_block,
                scene_name: &self.scene_name,
                medium: self.medium,
                rig_toml: &self.rig_toml,
                scene_toml: &self.scene_toml,
                poses_from: None,
            })
            .await
            .unwrap_or_else(|e| panic!("{e}"))
    }

    /// The rod of sample `index`.
    #[must_use]
    pub fn rod(&self, index: u64) -> &str {
        let block = usize::try_from(index / self.rod_block.max(1)).unwrap_or(0);
        &self.rods[block % self.rods.len()]
    }
}

/// Creates `plan`'s run and writes samples `0..count`. `each` finishes a builder
/// preset with the index, the plan's rod and medium, drawing from an [`Lcg`] seeded
/// with the plan's seed, and may give a frame, which is stamped with the sample's
/// frame time and index. Windows are [`SampleBuilder::window`].
pub async fn seeded_run(
    store: &Store,
    plan: &RunPlan,
    count: u64,
    mut each: impl FnMut(SampleBuilder, &mut Lcg) -> (SampleBuilder, Option<Frame>),
) -> RunId {
    let run = plan.create(store).await;
    let mut rng = Lcg(plan.seed);
    for index in 0..count {
        let preset = SampleBuilder::new(index)
            .rod(plan.rod(index))
            .medium(plan.medium);
        let (builder, frame) = each(preset, &mut rng);
        let window = builder.window();
        let sample = builder.build();
        let record = frame.as_ref().map(|f| FrameRecord {
            meta: FrameMeta {
                t: sample.frame_t,
                sequence: sample.index,
                ..f.meta
            },
            data: &f.data,
        });
        store
            .append_sample(run, &sample, record, &window)
            .await
            .unwrap_or_else(|e| panic!("sample {index}: {e}"));
    }
    run
}

/// A `width`×`height` test pattern, different for each `seed`, encoded as `format`
/// (stamped t = 0, sequence = `seed`). Gradients with 2×2 speckle: PNG compresses
/// it about as well as a camera frame (≈ 200 KB at 640×480).
#[must_use]
pub fn frame(seed: u64, width: u32, height: u32, format: FrameFormat) -> Frame {
    let k = seed as u32; // the low bits vary the pattern enough
    let img = image::RgbImage::from_fn(width, height, |x, y| {
        let h = (x / 2).wrapping_mul(73_856_093)
            ^ (y / 2).wrapping_mul(19_349_663)
            ^ k.wrapping_mul(83_492_791);
        let v = (x / 4 + y / 3 + (k % 256) * 9 + (h >> 7) % 5) % 256;
        image::Rgb([v as u8, (v / 2 + 60) as u8, (255 - v) as u8])
    });
    let encoded = |f| {
        let mut out = std::io::Cursor::new(Vec::new());
        img.write_to(&mut out, f).unwrap_or_else(|e| panic!("{e}"));
        out.into_inner()
    };
    let data = match format {
        FrameFormat::Png => encoded(image::ImageFormat::Png),
        FrameFormat::Jpeg => encoded(image::ImageFormat::Jpeg),
        FrameFormat::Rgb8 => img.into_raw(),
    };
    Frame {
        meta: FrameMeta {
            t: TimestampNs(0),
            sequence: seed,
            width,
            height,
            format,
        },
        data,
    }
}
