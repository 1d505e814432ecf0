//! The disk a planned collection will take, estimated before it starts. A sample is
//! its frame and the rest (its row, its force/torque window, the events and indexes):
//! - the frame: measured over the frames the database holds of the same scene; with
//!   none yet, one frame of the scene rendered and encoded as the store encodes it (a
//!   water scene's frames are nearly three times a dry one's);
//! - the rest: measured over the database (all of it but its frames), or assumed for a
//!   database without samples.

use crate::store::StoreError;
use crate::store::sqlite_file::free_bytes;
use softtouch_schemas::{ContactPose, FrameFormat, FrameMeta, SceneSpec, TimestampNs};
use std::path::Path;

/// Bytes a sample takes besides its frame when the database cannot tell yet: 1 500
/// simulated samples of the default scene made a 330 MB database, 220 kB a sample, of
/// which the frame (640×480 PNG) was about 214 kB.
pub const ASSUMED_NON_FRAME_BYTES: u64 = 6_000;

/// Room kept free beyond the estimate: SQLite's log and the other files beside it.
const MARGIN_BYTES: u64 = 64 * 1024 * 1024;

/// What a database holds, for the estimate: everything, and its frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Footprint {
    /// Samples stored, over every run.
    pub samples: u64,
    /// The database's bytes (file and log, or the server's database size).
    pub total_bytes: u64,
    /// Frames stored, over every run, and their bytes.
    pub frames: (u64, u64),
    /// Frames stored of runs of the scene being planned, and their bytes.
    pub scene_frames: (u64, u64),
}

/// Bytes per sample, and where the figure comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SampleBytes {
    /// Bytes a sample takes.
    pub bytes: u64,
    /// How it was found, for people.
    pub source: String,
}

/// The bytes a sample of `scene` will take in a database holding `held`.
///
/// # Errors
/// The scene cannot be rendered (only asked when the database holds no frame of it).
pub fn sample_bytes(held: &Footprint, scene: &SceneSpec) -> Result<SampleBytes, String> {
    let (frame, frame_source) = match held.scene_frames {
        (n, bytes) if n > 0 => (
            bytes.div_ceil(n),
            format!("its frame measured over {n} of scene `{}`", scene.name),
        ),
        _ => (
            rendered_frame_bytes(scene)?,
            format!(
                "its frame one of scene `{}` rendered and encoded",
                scene.name
            ),
        ),
    };
    let (rest, rest_source) = match held.total_bytes.checked_sub(held.frames.1) {
        Some(rest) if held.samples > 0 => (
            rest.div_ceil(held.samples),
            format!("the rest measured over {} samples", held.samples),
        ),
        _ => (
            ASSUMED_NON_FRAME_BYTES,
            "the rest assumed until the database holds samples".to_owned(),
        ),
    };
    Ok(SampleBytes {
        bytes: frame.saturating_add(rest),
        source: format!("{frame_source}, {rest_source}"),
    })
}

/// One frame of `scene` (its first rod, the middle of its pose ranges), as the store
/// keeps it: its PNG's bytes.
///
/// # Errors
/// The scene cannot be rendered, or the frame encoded.
pub fn rendered_frame_bytes(scene: &SceneSpec) -> Result<u64, String> {
    let rod = scene
        .rods
        .first()
        .ok_or_else(|| format!("scene `{}` has no rod", scene.name))?;
    let mid = |r: &softtouch_schemas::Range| 0.5 * (r.min + r.max);
    let pose = ContactPose {
        x_m: mid(&scene.poses.x_m),
        z_m: mid(&scene.poses.z_m),
        theta_rad: mid(&scene.poses.theta_rad),
    };
    let rendered = softtouch_sim::render_contact(scene, &rod.name, &pose, 0)
        .map_err(|e| format!("rendering a frame of scene `{}`: {e}", scene.name))?;
    let (width, height) = rendered.image.dimensions();
    let frame = softtouch_drivers::Frame {
        meta: FrameMeta {
            t: TimestampNs(0),
            sequence: 0,
            width,
            height,
            format: FrameFormat::Rgb8,
        },
        data: rendered.image.into_raw(),
    };
    let (_, png) = crate::store::encode_for_store(&frame).map_err(|e| e.to_string())?;
    Ok(png.len() as u64)
}

/// What a planned collection will take against what is free.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DiskPlan {
    /// Samples to collect.
    pub samples: u64,
    /// Bytes per sample, and where that figure comes from.
    pub per_sample: SampleBytes,
    /// Bytes the run will add.
    pub needed_bytes: u64,
    /// Bytes free where the database is; `None` on a server, whose disk is not this
    /// machine's to measure.
    pub free_bytes: Option<u64>,
}

impl DiskPlan {
    /// The plan for `samples` samples of `per_sample` bytes into the SQLite file `db`,
    /// or (`None`) a server's database.
    ///
    /// # Errors
    /// The free space beside the file cannot be read.
    pub fn new(
        db: Option<&Path>,
        per_sample: SampleBytes,
        samples: u64,
    ) -> Result<Self, StoreError> {
        Ok(Self {
            samples,
            needed_bytes: per_sample.bytes.saturating_mul(samples),
            per_sample,
            free_bytes: db.map(free_bytes).transpose()?,
        })
    }

    /// Whether the run fits with a margin (a tenth more, and 64 MiB); on a server,
    /// always (its administrator's to watch).
    #[must_use]
    pub fn fits(&self) -> bool {
        self.free_bytes.is_none_or(|free| {
            self.needed_bytes
                .saturating_add(self.needed_bytes / 10)
                .saturating_add(MARGIN_BYTES)
                <= free
        })
    }

    /// The plan as one line: need, per sample and where that figure comes from, free.
    #[must_use]
    pub fn describe(&self) -> String {
        format!(
            "about {} for {} samples ({} a sample: {}); {}",
            human_bytes(self.needed_bytes),
            self.samples,
            human_bytes(self.per_sample.bytes),
            self.per_sample.source,
            self.free_bytes.map_or_else(
                || "on the server (its free space is not checked from here)".to_owned(),
                |free| format!("{} free", human_bytes(free))
            )
        )
    }
}

/// Bytes a sample takes in a database of `total_bytes` holding `stored` samples
/// (rounded up); `None` when either is 0 and there is nothing to measure.
#[must_use]
pub fn bytes_per_sample(total_bytes: u64, stored: u64) -> Option<u64> {
    (stored > 0 && total_bytes > 0).then(|| total_bytes.div_ceil(stored))
}

/// `330 MB`, `12.3 GB`, `220 kB`: decimal units, three significant figures at most.
#[must_use]
pub fn human_bytes(n: u64) -> String {
    const UNITS: [&str; 5] = ["B", "kB", "MB", "GB", "TB"];
    let mut v = n as f64;
    let mut unit = 0;
    while v >= 1000.0 && unit + 1 < UNITS.len() {
        v /= 1000.0;
        unit += 1;
    }
    if unit == 0 || v >= 100.0 {
        format!("{v:.0} {}", UNITS[unit])
    } else if v >= 10.0 {
        format!("{v:.1} {}", UNITS[unit])
    } else {
        format!("{v:.2} {}", UNITS[unit])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_read_as_a_person_says_them() {
        assert_eq!(human_bytes(0), "0 B");
        assert_eq!(human_bytes(999), "999 B");
        assert_eq!(human_bytes(220_000), "220 kB");
        assert_eq!(human_bytes(329_986_048), "330 MB");
        assert_eq!(human_bytes(12_345_678_901), "12.3 GB");
        assert_eq!(human_bytes(1_500), "1.50 kB");
        assert_eq!(human_bytes(u64::MAX), "18446744 TB");
    }

    #[test]
    fn a_plan_refuses_what_does_not_fit_and_never_overflows() {
        let free = 10_000_000_000;
        let p = |bytes| DiskPlan {
            samples: 1,
            per_sample: SampleBytes {
                bytes,
                source: "test".into(),
            },
            needed_bytes: bytes,
            free_bytes: Some(free),
        };
        assert!(p(1_000_000_000).fits());
        assert!(!p(free).fits(), "no margin left");
        assert!(!p(u64::MAX).fits(), "no overflow");
        let server = DiskPlan {
            free_bytes: None,
            ..p(u64::MAX)
        };
        assert!(server.fits());
        assert!(server.describe().contains("not checked from here"));
    }

    #[test]
    fn a_sample_is_measured_per_scene_or_its_frame_rendered() {
        let dry = softtouch_schemas::defaults::scene();
        let water = crate::configs::resolve(
            None,
            Some(Path::new(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../scenes/water.toml"
            ))),
        )
        .expect("the water scene")
        .scene;
        // An empty database: a frame of each scene rendered, the rest assumed.
        let empty = Footprint::default();
        let dry_bytes = sample_bytes(&empty, &dry).expect("rendered");
        let wet_bytes = sample_bytes(&empty, &water).expect("rendered");
        assert!(dry_bytes.source.contains("rendered") && dry_bytes.source.contains("assumed"));
        assert!(
            wet_bytes.bytes > 2 * dry_bytes.bytes,
            "water {} B, dry {} B a sample",
            wet_bytes.bytes,
            dry_bytes.bytes
        );
        // The same scene stored: measured, the rest from the database.
        let held = Footprint {
            samples: 10,
            total_bytes: 2_100_000,
            frames: (10, 2_000_000),
            scene_frames: (10, 2_000_000),
        };
        let measured = sample_bytes(&held, &dry).expect("measured");
        assert_eq!(measured.bytes, 200_000 + 10_000);
        assert!(
            measured.source.contains("measured over 10 of scene"),
            "{}",
            measured.source
        );
        // Another scene stored: the rest measured, this scene's frame rendered.
        let other = Footprint {
            scene_frames: (0, 0),
            ..held
        };
        let mixed = sample_bytes(&other, &water).expect("rendered");
        assert_eq!(
            mixed.bytes,
            wet_bytes.bytes - ASSUMED_NON_FRAME_BYTES + 10_000
        );
        // Frames larger than the database said (a size read mid-write): assumed rest.
        let odd = Footprint {
            total_bytes: 1,
            ..held
        };
        assert_eq!(
            sample_bytes(&odd, &dry).expect("measured").bytes,
            200_000 + ASSUMED_NON_FRAME_BYTES
        );
        assert_eq!(bytes_per_sample(0, 3), None);
        assert_eq!(bytes_per_sample(10, 3), Some(4));
    }
}
