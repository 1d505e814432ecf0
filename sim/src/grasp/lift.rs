//! The gripper's trapezoidal lift: its numbers checked once, its phases and motion.

use super::*;

/// A trapezoidal lift of the gripper.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Lift {
    pub(super) t0: TimestampNs,
    pub(super) height_m: f64,
    pub(super) speed_m_s: f64,
    pub(super) accel_m_s2: f64,
}

impl Lift {
    /// A lift from `t0`, its numbers checked: each positive, finite and at most
    /// 2 m, 5 m/s and 100 m/s².
    pub(super) fn checked(
        t0: TimestampNs,
        height_m: f64,
        speed_m_s: f64,
        accel_m_s2: f64,
    ) -> Result<Self, SimError> {
        for (field, v, hi) in [
            ("height_m", height_m, 2.0),
            ("speed_m_s", speed_m_s, 5.0),
            ("accel_m_s2", accel_m_s2, 100.0),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= hi) {
                return Err(SimError::InvalidParameter(format!(
                    "lift {field} = {v}: expected a value in (0, {hi}]"
                )));
            }
        }
        Ok(Self {
            t0,
            height_m,
            speed_m_s,
            accel_m_s2,
        })
    }

    /// The top speed, the ramp's duration and the cruise's, s: a triangle when the
    /// height is too short to reach the speed.
    fn phases(&self) -> (f64, f64, f64) {
        let v_peak = self.speed_m_s.min((self.accel_m_s2 * self.height_m).sqrt());
        let t_acc = v_peak / self.accel_m_s2;
        let cruise_m = self.height_m - v_peak * t_acc;
        (v_peak, t_acc, (cruise_m / v_peak).max(0.0))
    }

    /// How long the lift takes, s.
    pub(super) fn duration_s(&self) -> f64 {
        let (_, t_acc, t_cruise) = self.phases();
        2.0 * t_acc + t_cruise
    }

    /// Velocity (up) and acceleration (up) `tau_s` after the start.
    pub(super) fn motion(&self, tau_s: f64) -> (f64, f64) {
        if tau_s < 0.0 {
            return (0.0, 0.0);
        }
        let a = self.accel_m_s2;
        let (v_peak, t_acc, t_cruise) = self.phases();
        if tau_s < t_acc {
            (a * tau_s, a)
        } else if tau_s < t_acc + t_cruise {
            (v_peak, 0.0)
        } else if tau_s < 2.0 * t_acc + t_cruise {
            (v_peak - a * (tau_s - t_acc - t_cruise), -a)
        } else {
            (0.0, 0.0)
        }
    }
}
