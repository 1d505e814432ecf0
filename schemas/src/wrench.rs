//! Forces and torques, and readings from a force/torque sensor.

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

/// Axis names in storage and export order.
pub const AXES: [&str; 6] = ["fx", "fy", "fz", "tx", "ty", "tz"];

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
/// is only a warning, any other non-zero value is a fault (PROTOCOLS.md §1.1).
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
