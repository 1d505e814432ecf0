//! The disk a planned collection will take, estimated before it starts: from what the
//! database already holds per sample, or, for a database without samples, from a
//! measured simulated run.

use crate::store::StoreError;
use crate::store::file::{db_size, free_bytes};
use std::path::Path;

/// Bytes a sample takes when the database cannot tell yet: 1 500 simulated samples
/// (640×480 PNG frames, their force/torque windows and rows) made a 330 MB database.
pub const ASSUMED_BYTES_PER_SAMPLE: u64 = 220_000;

/// Room kept free beyond the estimate: SQLite's log and the other files beside it.
const MARGIN_BYTES: u64 = 64 * 1024 * 1024;

/// What a planned collection will take against what is free.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DiskPlan {
    /// Samples to collect.
    pub samples: u64,
    /// Bytes per sample.
    pub per_sample_bytes: u64,
    /// Samples the per-sample figure was measured over (0: assumed).
    pub measured_over: u64,
    /// Bytes the run will add.
    pub needed_bytes: u64,
    /// Bytes free where the database is.
    pub free_bytes: u64,
}

impl DiskPlan {
    /// Whether the run fits with a margin (a tenth more, and 64 MiB).
    #[must_use]
    pub fn fits(&self) -> bool {
        self.needed_bytes
            .saturating_add(self.needed_bytes / 10)
            .saturating_add(MARGIN_BYTES)
            <= self.free_bytes
    }

    /// The plan as one line: need, per sample and where that figure comes from, free.
    #[must_use]
    pub fn describe(&self) -> String {
        let source = if self.measured_over > 0 {
            format!("measured over the {} samples stored", self.measured_over)
        } else {
            "assumed until this database holds samples".to_owned()
        };
        format!(
            "about {} for {} samples ({} a sample, {source}); {} free",
            human_bytes(self.needed_bytes),
            self.samples,
            human_bytes(self.per_sample_bytes),
            human_bytes(self.free_bytes)
        )
    }
}

/// The plan for `samples` more samples into the database at `db`, which holds
/// `stored` samples now.
///
/// # Errors
/// The free space cannot be read.
pub fn plan(db: &Path, stored: u64, samples: u64) -> Result<DiskPlan, StoreError> {
    let (per_sample_bytes, measured_over) = match bytes_per_sample(db_size(db).total(), stored) {
        Some(b) => (b, stored),
        None => (ASSUMED_BYTES_PER_SAMPLE, 0),
    };
    Ok(DiskPlan {
        samples,
        per_sample_bytes,
        measured_over,
        needed_bytes: per_sample_bytes.saturating_mul(samples),
        free_bytes: free_bytes(db)?,
    })
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
    fn a_plan_measures_the_database_or_assumes_and_refuses_what_does_not_fit() {
        let free = 10_000_000_000;
        let p = |needed_bytes| DiskPlan {
            samples: 1,
            per_sample_bytes: needed_bytes,
            measured_over: 0,
            needed_bytes,
            free_bytes: free,
        };
        assert!(p(1_000_000_000).fits());
        assert!(!p(free).fits(), "no margin left");
        assert!(!p(u64::MAX).fits(), "no overflow");
        let dir = tempfile::tempdir().expect("temp dir");
        let db = dir.path().join("a.db");
        let fresh = plan(&db, 0, 1500).expect("free space");
        assert_eq!(fresh.per_sample_bytes, ASSUMED_BYTES_PER_SAMPLE);
        assert_eq!(fresh.measured_over, 0);
        assert_eq!(fresh.needed_bytes, 330_000_000);
        std::fs::write(&db, vec![0u8; 1_000_000]).expect("write");
        let measured = plan(&db, 4, 10).expect("free space");
        assert_eq!(measured.per_sample_bytes, 250_000);
        assert_eq!(measured.measured_over, 4);
        assert!(
            measured
                .describe()
                .contains("measured over the 4 samples stored")
        );
    }
}
