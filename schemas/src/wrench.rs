//! Forces and torques, and readings from a force/torque sensor.

use crate::geometry::{ArmPose, cross};
use crate::time::TimestampNs;
use serde::{Deserialize, Serialize};
use std::fmt;

/// A 6-axis wrench: force in N, torque in N·m, both in one frame named by the holder
/// (e.g. `wrench_in_sensor`).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Wrench {
    /// Force `[Fx, Fy, Fz]`, newtons.
    pub force_n: [f64; 3],
    /// Torque `[Tx, Ty, Tz]`, newton-metres.
    pub torque_nm: [f64; 3],
}

/// One wrench axis as labels, statistics and exports name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Axis {
    /// Display name: `Fx` … `Tz`.
    pub name: &'static str,
    /// Lower-case key for columns, file names and CSV headers: `fx` … `tz`.
    pub key: &'static str,
    /// Unit of labels and reports, the paper's: N for forces, N·mm for torques
    /// ([`Wrench`] itself stores N·m).
    pub report_unit: &'static str,
}

/// The six axes in storage, label and export order (`Fx, Fy, Fz, Tx, Ty, Tz`): the
/// one list every crate names axes from.
pub const AXES: [Axis; 6] = [
    Axis::new("Fx", "fx", "N"),
    Axis::new("Fy", "fy", "N"),
    Axis::new("Fz", "fz", "N"),
    Axis::new("Tx", "tx", "N·mm"),
    Axis::new("Ty", "ty", "N·mm"),
    Axis::new("Tz", "tz", "N·mm"),
];

/// The names of [`AXES`] (`Fx` … `Tz`), for code that wants plain strings.
pub const AXIS_NAMES: [&str; 6] = {
    let mut out = [""; 6];
    let mut i = 0;
    while i < 6 {
        out[i] = AXES[i].name;
        i += 1;
    }
    out
};

/// The report units of [`AXES`] (N, N·mm), for code that wants plain strings.
pub const AXIS_UNITS: [&str; 6] = {
    let mut out = [""; 6];
    let mut i = 0;
    while i < 6 {
        out[i] = AXES[i].report_unit;
        i += 1;
    }
    out
};

impl Axis {
    const fn new(name: &'static str, key: &'static str, report_unit: &'static str) -> Self {
        Self {
            name,
            key,
            report_unit,
        }
    }
}

/// A direction of zero length (or not finite): nothing to project a force on.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("direction {0:?} has no usable length: cannot project a force on it")]
pub struct DegenerateDirection(pub [f64; 3]);

impl Wrench {
    /// No force, no torque.
    pub const ZERO: Self = Self {
        force_n: [0.0; 3],
        torque_nm: [0.0; 3],
    };

    /// From six values in SI order `[Fx, Fy, Fz, Tx, Ty, Tz]` (N, N·m).
    #[must_use]
    pub const fn from_array(v: [f64; 6]) -> Self {
        Self {
            force_n: [v[0], v[1], v[2]],
            torque_nm: [v[3], v[4], v[5]],
        }
    }

    /// As six values in SI order `[Fx, Fy, Fz, Tx, Ty, Tz]` (N, N·m).
    #[must_use]
    pub const fn to_array(&self) -> [f64; 6] {
        let [fx, fy, fz] = self.force_n;
        let [tx, ty, tz] = self.torque_nm;
        [fx, fy, fz, tx, ty, tz]
    }

    /// Torque in N·mm, the unit the paper reports.
    #[must_use]
    pub fn torque_nmm(&self) -> [f64; 3] {
        self.torque_nm.map(|t| t * 1000.0)
    }

    /// Magnitude of the force, N.
    #[must_use]
    pub fn force_norm_n(&self) -> f64 {
        self.force_n.iter().map(|f| f * f).sum::<f64>().sqrt()
    }

    /// Every component is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.to_array().iter().all(|v| v.is_finite())
    }

    /// This wrench, held in frame A about A's origin, expressed in frame B about B's
    /// origin, given `b_from_a` (A's pose in B): `F_b = R·F_a`,
    /// `τ_b = R·τ_a + p × F_b` with `p` A's origin in B, the lever arm of the force
    /// about the new origin. For example
    /// `wrench_in_world = wrench_in_sensor.expressed_in(&world_from_sensor)`.
    #[must_use]
    pub fn expressed_in(&self, b_from_a: &ArmPose) -> Wrench {
        let force_n = b_from_a.rotate(self.force_n);
        let turned = b_from_a.rotate(self.torque_nm);
        let shift = cross(b_from_a.translation_m, force_n);
        Wrench {
            force_n,
            torque_nm: std::array::from_fn(|i| turned[i] + shift[i]),
        }
    }

    /// The force's component along `direction` (same frame as the wrench; any
    /// length, it is normalised), N. A zero or non-finite direction is an error, not
    /// a NaN.
    pub fn force_along(&self, direction: [f64; 3]) -> Result<f64, DegenerateDirection> {
        let norm = direction.iter().map(|d| d * d).sum::<f64>().sqrt();
        if !(norm.is_finite() && norm > 1e-12) {
            return Err(DegenerateDirection(direction));
        }
        Ok(self
            .force_n
            .iter()
            .zip(&direction)
            .map(|(f, d)| f * d / norm)
            .sum())
    }

    /// Component-wise sum.
    #[must_use]
    pub fn add(&self, other: &Wrench) -> Wrench {
        let a = self.to_array();
        let b = other.to_array();
        Wrench::from_array(std::array::from_fn(|i| a[i] + b[i]))
    }
}

impl fmt::Display for Wrench {
    /// `F [fx fy fz] N  T [tx ty tz] N·mm`: the paper's units.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [fx, fy, fz] = self.force_n;
        let [tx, ty, tz] = self.torque_nmm();
        write!(
            f,
            "F [{fx:+.3} {fy:+.3} {fz:+.3}] N  T [{tx:+.1} {ty:+.1} {tz:+.1}] N·mm"
        )
    }
}

/// The status word a Net F/T (or any sensor, mapped onto it) reports with a reading.
///
/// 0 is OK. Bit 31 is the error summary; `0x8001_0000` ("monitor condition latched")
/// is only a warning, any other non-zero value is a fault (docs/PROTOCOLS.md §1.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct FtStatus(pub u32);

impl FtStatus {
    /// Everything fine.
    pub const OK: Self = Self(0);
    /// Monitor condition latched: a warning, the reading is still usable.
    pub const MONITOR_LATCHED: Self = Self(0x8001_0000);
    /// Saturation or ADC fault.
    pub const SATURATED: Self = Self(0x0002_0000);

    /// Status says nothing is wrong.
    #[must_use]
    pub const fn is_ok(self) -> bool {
        self.0 == 0
    }

    /// A warning the reading survives.
    #[must_use]
    pub const fn is_warning(self) -> bool {
        self.0 == Self::MONITOR_LATCHED.0
    }

    /// A fault: the reading must not be used as a label.
    #[must_use]
    pub const fn is_fault(self) -> bool {
        !self.is_ok() && !self.is_warning()
    }
}

impl fmt::Display for FtStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let what = if self.is_ok() {
            "ok"
        } else if self.is_warning() {
            "warning"
        } else {
            "fault"
        };
        write!(f, "0x{:08X} ({what})", self.0)
    }
}

/// One reading of a force/torque sensor, stamped on the host's injected clock.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FtReading {
    /// When the host received the reading.
    pub t: TimestampNs,
    /// Transport sequence number (Net F/T `rdt_sequence`; a counter for other links).
    pub rdt_sequence: u32,
    /// The sensor's own sample counter (Net F/T `ft_sequence`), kept as sent.
    pub ft_sequence: u32,
    /// Status word sent with the reading.
    pub status: FtStatus,
    /// The wrench in the sensor frame, N and N·m.
    pub wrench_in_sensor: Wrench,
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact values are the point of these tests
mod tests {
    use super::*;

    fn close(a: &Wrench, b: &Wrench) -> bool {
        a.to_array()
            .iter()
            .zip(&b.to_array())
            .all(|(x, y)| (x - y).abs() < 1e-12)
    }

    const W: Wrench = Wrench::from_array([1.0, -2.0, 3.0, 0.1, -0.2, 0.3]);

    #[test]
    fn the_identity_leaves_a_wrench_alone() {
        assert!(close(&W.expressed_in(&ArmPose::IDENTITY), &W));
    }

    #[test]
    fn a_quarter_turn_about_z_permutes_the_axes() {
        let b_from_a = ArmPose::from_translation_yaw([0.0; 3], std::f64::consts::FRAC_PI_2);
        // x_a → y_b, y_a → −x_b.
        let expect = Wrench::from_array([2.0, 1.0, 3.0, 0.2, 0.1, 0.3]);
        assert!(
            close(&W.expressed_in(&b_from_a), &expect),
            "{}",
            W.expressed_in(&b_from_a)
        );
    }

    #[test]
    fn moving_the_origin_adds_the_lever_arm_torque() {
        // A's origin 0.1 m along x of B: a force of −2 N along y there turns B's origin
        // by 0.1 × (−2) = −0.2 N·m about z; 3 N along z by −0.1 × 3 about y.
        let b_from_a = ArmPose::from_translation_yaw([0.1, 0.0, 0.0], 0.0);
        let expect = Wrench::from_array([1.0, -2.0, 3.0, 0.1, -0.2 - 0.3, 0.3 - 0.2]);
        assert!(close(&W.expressed_in(&b_from_a), &expect));
    }

    #[test]
    fn the_inverse_pose_brings_a_wrench_back() {
        let b_from_a = ArmPose {
            translation_m: [0.3, -0.1, 0.25],
            rotation_wxyz: [0.3, 0.8, -0.2, 0.4],
        };
        let there = W.expressed_in(&b_from_a);
        assert!(!close(&there, &W));
        assert!(close(&there.expressed_in(&b_from_a.inverse()), &W));
        assert!((there.force_norm_n() - W.force_norm_n()).abs() < 1e-12);
    }

    #[test]
    fn force_along_normalises_and_refuses_a_zero_direction() {
        let along = |d| W.force_along(d).expect("a usable direction");
        assert!((along([0.0, 0.0, 1.0]) - 3.0).abs() < 1e-12);
        assert!((along([0.0, -10.0, 0.0]) - 2.0).abs() < 1e-12);
        assert!((along([1.0, 1.0, 0.0]) - (-1.0 / 2f64.sqrt())).abs() < 1e-12);
        assert_eq!(W.force_along([0.0; 3]), Err(DegenerateDirection([0.0; 3])));
        assert!(W.force_along([f64::NAN, 0.0, 1.0]).is_err());
        assert!(W.force_along([f64::INFINITY, 0.0, 0.0]).is_err());
    }

    #[test]
    fn axes_name_key_and_unit_agree() {
        assert_eq!(AXIS_NAMES, ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"]);
        assert_eq!(AXIS_UNITS, ["N", "N", "N", "N·mm", "N·mm", "N·mm"]);
        for a in AXES {
            assert_eq!(a.key, a.name.to_lowercase());
        }
    }

    #[test]
    fn the_monitor_latch_is_a_warning_and_anything_else_a_fault() {
        assert!(FtStatus::OK.is_ok() && !FtStatus::OK.is_fault());
        assert!(FtStatus::MONITOR_LATCHED.is_warning() && !FtStatus::MONITOR_LATCHED.is_fault());
        assert!(FtStatus::SATURATED.is_fault());
        assert!(FtStatus(0x8000_0000).is_fault());
        assert!(FtStatus(0x0010_0000).is_fault());
    }

    #[test]
    fn display_uses_newton_millimetres_for_torque() {
        let w = Wrench::from_array([1.0, -2.0, 3.0, 0.1, -0.2, 0.3]);
        let s = w.to_string();
        assert!(
            s.contains("+100.0") && s.contains("-200.0") && s.contains("N·mm"),
            "{s}"
        );
    }

    #[test]
    fn array_round_trip_keeps_axis_order() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        assert_eq!(Wrench::from_array(v).to_array(), v);
    }
}
