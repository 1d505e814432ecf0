//! Time on one monotonic clock, in nanoseconds.
//!
//! Every reading carries a [`TimestampNs`] taken from an injected clock: host
//! monotonic time on a rig, virtual time in simulation. Nothing here reads a clock.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Nanoseconds since the epoch of one monotonic clock (not wall time).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize,
)]
#[serde(transparent)]
pub struct TimestampNs(pub u64);

/// A span of time in nanoseconds.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize,
)]
#[serde(transparent)]
pub struct DurationNs(pub u64);

impl TimestampNs {
    /// The clock's epoch.
    pub const ZERO: Self = Self(0);

    /// Time after `d`, saturating at the end of the clock rather than wrapping.
    #[must_use]
    pub fn saturating_add(self, d: DurationNs) -> Self {
        Self(self.0.saturating_add(d.0))
    }

    /// Time before `d`, saturating at the epoch.
    #[must_use]
    pub fn saturating_sub(self, d: DurationNs) -> Self {
        Self(self.0.saturating_sub(d.0))
    }

    /// Signed difference `self − earlier` in nanoseconds (negative if `earlier` is later).
    #[must_use]
    pub fn signed_since(self, earlier: Self) -> i64 {
        // Both fit in i64 for any clock younger than 292 years; clamp anyway.
        let a = i128::from(self.0);
        let b = i128::from(earlier.0);
        i64::try_from(a - b).unwrap_or(if a > b { i64::MAX } else { i64::MIN })
    }

    /// Seconds since the epoch, for display and plots.
    #[must_use]
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }
}

impl DurationNs {
    /// No time.
    pub const ZERO: Self = Self(0);

    /// From seconds; negative and non-finite inputs give zero, huge inputs saturate.
    #[must_use]
    pub fn from_secs_f64(secs: f64) -> Self {
        if !secs.is_finite() || secs <= 0.0 {
            return Self(0);
        }
        let ns = secs * 1e9;
        if ns >= u64::MAX as f64 {
            Self(u64::MAX)
        } else {
            Self(ns.round() as u64)
        }
    }

    /// From milliseconds.
    #[must_use]
    pub const fn from_millis(ms: u64) -> Self {
        Self(ms.saturating_mul(1_000_000))
    }

    /// In seconds.
    #[must_use]
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }
}

impl fmt::Display for TimestampNs {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "t={:.6} s", self.as_secs_f64())
    }
}

impl fmt::Display for DurationNs {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:.3} ms", self.0 as f64 * 1e-6)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_from_bad_seconds_are_zero_not_garbage() {
        assert_eq!(DurationNs::from_secs_f64(-1.0), DurationNs::ZERO);
        assert_eq!(DurationNs::from_secs_f64(f64::NAN), DurationNs::ZERO);
        assert_eq!(DurationNs::from_secs_f64(f64::INFINITY), DurationNs::ZERO);
        assert_eq!(DurationNs::from_secs_f64(1e30), DurationNs(u64::MAX));
        assert_eq!(DurationNs::from_secs_f64(0.25), DurationNs(250_000_000));
    }

    #[test]
    fn signed_difference_is_exact_and_clamped() {
        assert_eq!(TimestampNs(10).signed_since(TimestampNs(15)), -5);
        assert_eq!(TimestampNs(u64::MAX).signed_since(TimestampNs(0)), i64::MAX);
        assert_eq!(TimestampNs(0).signed_since(TimestampNs(u64::MAX)), i64::MIN);
    }

    #[test]
    fn timestamps_saturate_instead_of_wrapping() {
        assert_eq!(
            TimestampNs(u64::MAX).saturating_add(DurationNs(5)),
            TimestampNs(u64::MAX)
        );
        assert_eq!(
            TimestampNs(3).saturating_sub(DurationNs(5)),
            TimestampNs::ZERO
        );
    }
}
