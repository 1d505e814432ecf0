//! The grasp experiments' settings, each validated one way for every verb that takes
//! it (`grasp follow`, `disturb`, `twist`, `trials`, `bench grasp`): the same flag
//! gets the same range and the same message wherever it is given.

use softtouch_schemas::config::readable;

/// A numeric setting's valid interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setting {
    /// What it is, for the message ("a rate", "a force").
    pub what: &'static str,
    /// Lower bound.
    pub lo: f64,
    /// Whether the lower bound itself is allowed.
    pub lo_inclusive: bool,
    /// Upper bound (allowed).
    pub hi: f64,
    /// Unit, for the message.
    pub unit: &'static str,
}

/// A setting outside its interval: names the flag, the value and what was expected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{flag} {value}: expected {expected}")]
pub struct SettingError {
    /// The flag as the user typed it (`--fps`).
    pub flag: String,
    /// The value given, as a person reads it.
    pub value: String,
    /// What would have been accepted.
    pub expected: String,
}

impl Setting {
    /// `v` if it lies in the interval.
    ///
    /// # Errors
    /// [`SettingError`] naming `flag`, the value and the interval.
    pub fn check(&self, flag: &str, v: f64) -> Result<f64, SettingError> {
        let lo_ok = if self.lo_inclusive {
            v >= self.lo
        } else {
            v > self.lo
        };
        if v.is_finite() && lo_ok && v <= self.hi {
            Ok(v)
        } else {
            let open = if self.lo_inclusive { "[" } else { "(" };
            Err(SettingError {
                flag: flag.to_owned(),
                value: readable(v),
                expected: format!(
                    "{} in {open}{}, {}] {}",
                    self.what,
                    readable(self.lo),
                    readable(self.hi),
                    self.unit
                ),
            })
        }
    }

    /// Every value of a list (`--fps 30,60,120`).
    ///
    /// # Errors
    /// The first value outside the interval.
    pub fn check_all(&self, flag: &str, values: &[f64]) -> Result<(), SettingError> {
        values
            .iter()
            .try_for_each(|v| self.check(flag, *v).map(drop))
    }
}

/// Camera rate, Hz: one control cycle per frame.
pub const FPS_HZ: Setting = Setting {
    what: "a rate",
    lo: 1.0,
    lo_inclusive: true,
    hi: 1000.0,
    unit: "Hz",
};

/// Tolerance δ, N. Above 0: with δ = 0 "within δ" is never observed (a closed-loop
/// trial never confirms, the loop dithers by a count for ever).
pub const TOLERANCE_N: Setting = Setting {
    what: "a force",
    lo: 0.0,
    lo_inclusive: false,
    hi: 5.0,
    unit: "N",
};

/// A phase's duration (hold, settle, turn), s; 0 allowed where a phase may be skipped.
#[must_use]
pub const fn duration_s(zero_allowed: bool) -> Setting {
    Setting {
        what: "a time",
        lo: 0.0,
        lo_inclusive: zero_allowed,
        hi: 600.0,
        unit: "s",
    }
}

/// A target grip force, N, as every verb takes it (`grasp trials --target-n`, `follow
/// --targets`, `disturb`/`twist --target`, `calibrate --target`, `bench grasp`): above
/// 0 (the finger only pushes) and below where the estimate saturates, less δ
/// (`tolerance_n`), as the loop's stepper checks it. Checked before anything is stored.
///
/// # Errors
/// A target the loop could never hold, naming `flag`, the value and the interval.
pub fn check_target_n(flag: &str, target_n: f64, tolerance_n: f64) -> Result<f64, SettingError> {
    let stepper = softtouch_grasp::StepperConfig {
        tolerance_n,
        ..softtouch_grasp::StepperConfig::default()
    };
    stepper
        .check_target(target_n)
        .map(|()| target_n)
        .map_err(|e| {
            let expected = match e {
                softtouch_grasp::GraspError::UnreachableTarget {
                    reachable_n: [lo, hi],
                    why,
                    ..
                } => format!("a force in ({}, {}) N ({why})", readable(lo), readable(hi)),
                other => other.to_string(),
            };
            SettingError {
                flag: flag.to_owned(),
                value: readable(target_n),
                expected,
            }
        })
}

/// Sensorised fingers the loop reads: 1 or 2.
///
/// # Errors
/// Any other count.
pub fn check_fingers(fingers: u8) -> Result<usize, SettingError> {
    match fingers {
        1 | 2 => Ok(usize::from(fingers)),
        n => Err(SettingError {
            flag: "--fingers".into(),
            value: n.to_string(),
            expected: "1 or 2 sensorised fingers".into(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_setting_has_one_interval_and_one_message() {
        assert_eq!(FPS_HZ.check("--fps", 1.0), Ok(1.0));
        assert_eq!(FPS_HZ.check("--fps", 1000.0), Ok(1000.0));
        let e = FPS_HZ.check("--fps", 0.9995).expect_err("below 1");
        assert_eq!(
            e.to_string(),
            "--fps 0.9995: expected a rate in [1, 1000] Hz"
        );
        for bad in [f64::NAN, f64::INFINITY, -1.0, 1000.5, 0.0] {
            assert!(FPS_HZ.check("--fps", bad).is_err(), "{bad}");
        }
        let e = TOLERANCE_N.check("--tolerance", 0.0).expect_err("zero");
        assert_eq!(e.to_string(), "--tolerance 0: expected a force in (0, 5] N");
        assert_eq!(TOLERANCE_N.check("--tolerance", 5.0), Ok(5.0));
        let e = TOLERANCE_N.check("--tolerance", 5e-324).map(|_| ());
        assert_eq!(e, Ok(()), "the smallest positive value is above 0");
        let e = duration_s(false)
            .check("--hold-s", 1e308)
            .expect_err("huge");
        assert_eq!(
            e.to_string(),
            "--hold-s 1e308: expected a time in (0, 600] s"
        );
        assert_eq!(duration_s(true).check("--settle-s", 0.0), Ok(0.0));
        assert!(FPS_HZ.check_all("--fps", &[30.0, 60.0]).is_ok());
        let e = FPS_HZ
            .check_all("--fps", &[30.0, -60.0, f64::NAN])
            .expect_err("one bad");
        assert_eq!(e.value, "-60");
        assert!(FPS_HZ.check_all("--fps", &[]).is_ok());
        assert_eq!(check_fingers(2), Ok(2));
        assert_eq!(
            check_fingers(3).map_err(|e| e.to_string()),
            Err("--fingers 3: expected 1 or 2 sensorised fingers".into())
        );
    }

    #[test]
    fn a_target_force_has_one_interval_for_every_verb() {
        assert_eq!(check_target_n("--target-n", 1.5, 0.1), Ok(1.5));
        for bad in [0.0, -1.0, 20.0, 9.9, f64::NAN, f64::INFINITY] {
            let e = check_target_n("--target-n", bad, 0.1).expect_err("refused");
            assert_eq!(e.flag, "--target-n");
            assert!(e.expected.starts_with("a force in (0, 9.9) N"), "{e}");
        }
        // δ is taken off the top: a wider tolerance leaves less room.
        let e = check_target_n("--targets", 9.5, 0.6).expect_err("refused");
        assert!(
            e.to_string()
                .starts_with("--targets 9.5: expected a force in (0, 9.4) N"),
            "{e}"
        );
    }
}
