//! The force/torque guard: the one check every place that moves an actuator under
//! load applies to every reading (collection's approach, `live`'s press, a grasp on a
//! rig's sensor). A reading trips it when it holds NaN or ∞, when its force magnitude
//! is over the limit, when any torque axis is over the limit, or when its status word
//! is a fault; a stream trips it when it stays silent for the stale limit.
//!
//! The saturation flag alone is not a trip: a saturated axis is at the end of the
//! sensor's range, which the force and torque limits (set below that range) already
//! stop, and the collection window turns it into a rejected label.
//!
//! The guard is synchronous and keeps no clock: its callers feed it readings as they
//! arrive and ask about silence on their own clock (virtual in simulation).

use crate::error::DeviceError;
use softtouch_schemas::{FtReading, FtStatus};
use std::time::Duration;

/// The limits a [`ForceGuard`] checks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceGuard {
    /// Largest force magnitude allowed, N.
    pub max_force_n: f64,
    /// Largest |torque| allowed on any axis, N·m.
    pub max_torque_nm: f64,
    /// Longest silence allowed between readings.
    pub stale: Duration,
}

/// Why the guard stopped the actuator.
#[derive(Debug, Clone, PartialEq)]
pub enum GuardTrip {
    /// A reading over the force or torque limit.
    OverLimit(FtReading),
    /// A reading holding NaN or infinity.
    NonFinite(FtReading),
    /// A reading whose status word reports a fault.
    SensorFault(FtReading),
    /// No reading arrived for this long.
    Stale {
        /// The configured limit (`procedure.ft_stale_s`).
        silent: Duration,
    },
    /// The sensor's link or driver reported an error.
    SensorError(DeviceError),
}

impl std::fmt::Display for GuardTrip {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::OverLimit(r) => write!(f, "reading over the limit at {}", r.wrench_in_sensor),
            Self::NonFinite(r) => write!(
                f,
                "non-finite reading (sequence {}): {:?}",
                r.rdt_sequence,
                r.wrench_in_sensor.to_array()
            ),
            Self::SensorFault(r) => write!(
                f,
                "sensor fault: status {} (sequence {})",
                r.status, r.rdt_sequence
            ),
            Self::Stale { silent } => write!(
                f,
                "stale stream: no force/torque reading for {:.3} s (procedure.ft_stale_s)",
                silent.as_secs_f64()
            ),
            Self::SensorError(e) => write!(f, "sensor error: {e}"),
        }
    }
}

impl ForceGuard {
    /// Checks one reading.
    ///
    /// # Errors
    /// The trip, if the reading trips the guard.
    pub fn check(&self, r: &FtReading) -> Result<(), GuardTrip> {
        let w = &r.wrench_in_sensor;
        if !w.to_array().iter().all(|v| v.is_finite()) {
            return Err(GuardTrip::NonFinite(*r));
        }
        // "Within" rather than "over": a NaN limit then refuses everything, not nothing.
        let within = |v: f64, max: f64| v <= max;
        if !within(w.force_norm_n(), self.max_force_n)
            || w.torque_nm
                .iter()
                .any(|t| !within(t.abs(), self.max_torque_nm))
        {
            return Err(GuardTrip::OverLimit(*r));
        }
        if r.status.is_fault() && r.status != FtStatus::SATURATED {
            return Err(GuardTrip::SensorFault(*r));
        }
        Ok(())
    }

    /// Checks every reading of a batch, oldest first; the first trip.
    ///
    /// # Errors
    /// The first reading's trip.
    pub fn check_all<'a>(
        &self,
        readings: impl IntoIterator<Item = &'a FtReading>,
    ) -> Result<(), GuardTrip> {
        readings.into_iter().try_for_each(|r| self.check(r))
    }

    /// Checks a silence: no reading for `silent`.
    ///
    /// # Errors
    /// [`GuardTrip::Stale`] when `silent` reaches the stale limit.
    pub fn check_silence(&self, silent: Duration) -> Result<(), GuardTrip> {
        if silent >= self.stale {
            Err(GuardTrip::Stale { silent: self.stale })
        } else {
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use softtouch_schemas::{TimestampNs, Wrench};

    fn reading(force_n: [f64; 3], torque_nm: [f64; 3], status: FtStatus) -> FtReading {
        FtReading {
            t: TimestampNs(7),
            rdt_sequence: 3,
            ft_sequence: 3,
            status,
            wrench_in_sensor: Wrench { force_n, torque_nm },
        }
    }

    const GUARD: ForceGuard = ForceGuard {
        max_force_n: 15.0,
        max_torque_nm: 0.8,
        stale: Duration::from_millis(100),
    };

    /// The test matrix: every kind of reading against the one guard.
    #[test]
    fn every_kind_of_reading_trips_or_passes_as_specified() {
        let ok = FtStatus::OK;
        let cases: Vec<(&str, FtReading, Option<&str>)> = vec![
            ("at rest", reading([0.0; 3], [0.0; 3], ok), None),
            (
                "just under",
                reading([0.0, 0.0, 14.99], [0.79, -0.79, 0.79], ok),
                None,
            ),
            (
                "force exactly at the limit",
                reading([0.0, 0.0, 15.0], [0.0; 3], ok),
                None,
            ),
            // 9² + 9² + 9² = 243 > 15²: each axis is under, the magnitude is not.
            (
                "force magnitude over",
                reading([9.0, 9.0, 9.0], [0.0; 3], ok),
                Some("over"),
            ),
            (
                "negative force over",
                reading([0.0, -15.1, 0.0], [0.0; 3], ok),
                Some("over"),
            ),
            // Each torque axis alone, not the norm: 0.6² · 3 > 0.8² but every axis is under.
            (
                "torque norm over, axes under",
                reading([0.0; 3], [0.6, 0.6, 0.6], ok),
                None,
            ),
            (
                "tx over",
                reading([0.0; 3], [0.81, 0.0, 0.0], ok),
                Some("over"),
            ),
            (
                "ty over",
                reading([0.0; 3], [0.0, -0.81, 0.0], ok),
                Some("over"),
            ),
            (
                "tz over",
                reading([0.0; 3], [0.0, 0.0, 0.81], ok),
                Some("over"),
            ),
            (
                "NaN force",
                reading([f64::NAN, 0.0, 0.0], [0.0; 3], ok),
                Some("nan"),
            ),
            (
                "∞ torque",
                reading([0.0; 3], [0.0, 0.0, f64::INFINITY], ok),
                Some("nan"),
            ),
            (
                "−∞ force",
                reading([0.0, f64::NEG_INFINITY, 0.0], [0.0; 3], ok),
                Some("nan"),
            ),
            (
                "largest finite",
                reading([f64::MAX, 0.0, 0.0], [0.0; 3], ok),
                Some("over"),
            ),
            (
                "status fault",
                reading([0.0; 3], [0.0; 3], FtStatus(0x0010_0000)),
                Some("fault"),
            ),
            (
                "monitor latched (a warning)",
                reading([0.0; 3], [0.0; 3], FtStatus::MONITOR_LATCHED),
                None,
            ),
            (
                "saturation flag (left to the limits)",
                reading([0.0; 3], [0.0; 3], FtStatus::SATURATED),
                None,
            ),
            // A NaN is reported as such even when the status is also a fault.
            (
                "NaN and fault",
                reading([f64::NAN; 3], [0.0; 3], FtStatus(0x0010_0000)),
                Some("nan"),
            ),
        ];
        for (name, r, want) in cases {
            let got = match GUARD.check(&r) {
                Ok(()) => None,
                Err(GuardTrip::OverLimit(x)) => Some(("over", x)),
                Err(GuardTrip::NonFinite(x)) => Some(("nan", x)),
                Err(GuardTrip::SensorFault(x)) => Some(("fault", x)),
                Err(other) => panic!("{name}: unexpected {other}"),
            };
            assert_eq!(got.map(|g| g.0), want, "{name}");
            if let Some((_, x)) = got {
                assert_eq!(
                    x.rdt_sequence, r.rdt_sequence,
                    "{name}: the tripping reading"
                );
            }
        }
    }

    #[test]
    fn a_batch_trips_on_its_first_bad_reading_wherever_it_is() {
        let ok = reading([1.0; 3], [0.0; 3], FtStatus::OK);
        let mut spike = reading([0.0, 0.0, 20.0], [0.0; 3], FtStatus::OK);
        spike.rdt_sequence = 9;
        let mut nan = reading([f64::NAN; 3], [0.0; 3], FtStatus::OK);
        nan.rdt_sequence = 10;
        assert_eq!(GUARD.check_all(&[]), Ok(()));
        assert_eq!(GUARD.check_all(&[ok, ok, ok]), Ok(()));
        assert_eq!(
            GUARD.check_all(&[ok, spike, ok, nan]),
            Err(GuardTrip::OverLimit(spike))
        );
        // NaN ≠ NaN: the tripping reading is told by its sequence.
        assert!(
            matches!(
                GUARD.check_all(&[ok, ok, nan, spike]),
                Err(GuardTrip::NonFinite(r)) if r.rdt_sequence == 10
            ),
            "the NaN comes first"
        );
    }

    #[test]
    fn silence_trips_at_the_stale_limit_and_not_before() {
        assert_eq!(GUARD.check_silence(Duration::ZERO), Ok(()));
        assert_eq!(GUARD.check_silence(Duration::from_millis(99)), Ok(()));
        let stale = GuardTrip::Stale {
            silent: Duration::from_millis(100),
        };
        assert_eq!(
            GUARD.check_silence(Duration::from_millis(100)),
            Err(stale.clone())
        );
        assert_eq!(GUARD.check_silence(Duration::MAX), Err(stale.clone()));
        assert!(stale.to_string().contains("0.100 s"));
    }

    #[test]
    fn limits_that_are_nan_refuse_every_reading() {
        let g = ForceGuard {
            max_force_n: f64::NAN,
            ..GUARD
        };
        assert!(g.check(&reading([0.0; 3], [0.0; 3], FtStatus::OK)).is_err());
    }
}
