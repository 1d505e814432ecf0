//! Where a sample's time goes, phase by phase, on the rig's clock (virtual on the
//! simulated rig, the real one on a rig): what `collect` prints at its end and stores
//! as a `phase_times` event, on any arm.

use std::fmt::Write as _;

/// Time spent in each phase of the samples a job took, ns on the rig's clock. Integer
/// nanoseconds, so that the counts of a run compare exactly.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PhaseTimes {
    /// Samples timed (stored, accepted or rejected).
    pub samples: u64,
    /// Moving clear of the rod to the sample's retreat point (planned order), or from
    /// home to the start of the approach.
    pub travel_ns: u64,
    /// Zeroing the force/torque sensor (`tare = "per-sample"`).
    pub tare_ns: u64,
    /// Free space crossed at `travel_speed_m_s` up to the stand-off short of the
    /// finger's first touch (`procedure.standoff_m`).
    pub free_approach_ns: u64,
    /// The approach at `approach_speed_m_s`.
    pub approach_ns: u64,
    /// The approach's last millimetres at `slow_approach_speed_m_s`.
    pub slow_approach_ns: u64,
    /// Waiting `settle_s`, and reading the arm's pose after it.
    pub settle_ns: u64,
    /// The frame and the force/torque window around it.
    pub record_ns: u64,
    /// Back out to the retreat point (planned order) or home.
    pub retreat_ns: u64,
    /// Each sample from its start to its end, everything included (storing, retries,
    /// recoveries).
    pub total_ns: u64,
}

/// The phases in the order a sample goes through them, with their names.
const PHASES: [&str; 8] = [
    "travel",
    "tare",
    "free approach",
    "approach",
    "slow approach",
    "settle",
    "record",
    "retreat",
];

impl PhaseTimes {
    fn phase_ns(&self) -> [u64; 8] {
        [
            self.travel_ns,
            self.tare_ns,
            self.free_approach_ns,
            self.approach_ns,
            self.slow_approach_ns,
            self.settle_ns,
            self.record_ns,
            self.retreat_ns,
        ]
    }

    /// Everything not in a phase: storing, rod changes, retries' extra moves, recoveries.
    #[must_use]
    pub fn other_ns(&self) -> u64 {
        self.total_ns
            .saturating_sub(self.phase_ns().iter().copied().fold(0, u64::saturating_add))
    }

    /// Samples an hour at this pace (0 with nothing timed).
    #[must_use]
    pub fn samples_per_hour(&self) -> f64 {
        if self.total_ns == 0 {
            0.0
        } else {
            self.samples as f64 * 3.6e12 / self.total_ns as f64
        }
    }

    /// The table: each phase's seconds per sample and share of the total.
    #[must_use]
    pub fn table(&self) -> String {
        let mut out = format!(
            "where a sample's time went ({} samples, rig's clock):\n{:<14} {:>12} {:>7}\n",
            self.samples, "phase", "s / sample", "share"
        );
        if self.samples == 0 {
            out.push_str("(no sample taken)\n");
            return out;
        }
        let per = |ns: u64| ns as f64 * 1e-9 / self.samples as f64;
        let share = |ns: u64| {
            if self.total_ns == 0 {
                0.0
            } else {
                100.0 * ns as f64 / self.total_ns as f64
            }
        };
        let rows = PHASES
            .iter()
            .copied()
            .zip(self.phase_ns())
            .chain([("other", self.other_ns())]);
        for (name, ns) in rows {
            let _ = writeln!(out, "{name:<14} {:>12.3} {:>6.1} %", per(ns), share(ns));
        }
        let _ = writeln!(
            out,
            "{:<14} {:>12.3} {:>6.1} %   ({:.0} samples/h)",
            "total",
            per(self.total_ns),
            share(self.total_ns),
            self.samples_per_hour()
        );
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_splits_a_sample_and_names_the_rest_other() {
        let t = PhaseTimes {
            samples: 2,
            travel_ns: 200_000_000,
            approach_ns: 1_000_000_000,
            settle_ns: 600_000_000,
            total_ns: 2_000_000_000,
            ..PhaseTimes::default()
        };
        assert_eq!(t.other_ns(), 200_000_000);
        assert!((t.samples_per_hour() - 3600.0).abs() < 1e-9);
        let table = t.table();
        assert!(
            table.contains("approach              0.500   50.0 %"),
            "{table}"
        );
        assert!(
            table.contains("other                 0.100   10.0 %"),
            "{table}"
        );
        assert!(table.contains("(3600 samples/h)"), "{table}");
        // Nothing timed: no division by zero.
        assert!(PhaseTimes::default().table().contains("no sample taken"));
        assert!(PhaseTimes::default().samples_per_hour().abs() < f64::EPSILON);
        // Phases that overrun the total (clock quirks) never underflow.
        let odd = PhaseTimes {
            samples: 1,
            travel_ns: 5,
            total_ns: 3,
            ..PhaseTimes::default()
        };
        assert_eq!(odd.other_ns(), 0);
    }
}
