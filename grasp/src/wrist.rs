//! The wrist loop: a second, narrow loop that keeps the torque about the finger's
//! axis τz near zero by turning the wrist (the gripper about its approach axis), on
//! the model's τz estimate.
//!
//! When a gripped object is turned about the fingers' axis, the skin shears and the
//! finger feels τz; turning the wrist with the object relieves the shear. The loop is
//! an integrator with a dead band: `ψ_target ← ψ_target − g·τz·Δt` while |τz| is
//! outside the band, the rate capped and the target kept inside ±`max_yaw_rad`. A
//! missing or non-finite τz holds the target (it never moves the arm).
//!
//! [`Wrist`] is what the loop drives. The simulated soft grasp's handle drives it in
//! the collector (this crate names no simulator); on a real rig it is the arm's last joint: for the Panda a joint-7
//! position set-point streamed by the arm's control task (franka-rs joint position
//! motion generator), the loop only handing it targets.

use crate::GraspError;

/// Something that turns the gripper about its approach axis.
pub trait Wrist: Send + std::fmt::Debug {
    /// Asks for a wrist yaw, rad (absolute, from where the grasp started); returns at
    /// once, the wrist gets there at its own rate.
    fn set_yaw_target(&mut self, yaw_rad: f64) -> Result<(), GraspError>;
    /// Where the wrist is, rad.
    fn yaw_rad(&mut self) -> Result<f64, GraspError>;
}

/// Settings of the wrist loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WristConfig {
    /// Integral gain: rad/s of wrist turn per N·m of τz.
    pub gain_rad_per_nm_s: f64,
    /// |τz| below this holds the wrist, N·m (the estimate's noise).
    pub deadband_nm: f64,
    /// Fastest the target moves, rad/s.
    pub max_rate_rad_s: f64,
    /// The target stays within ±this, rad.
    pub max_yaw_rad: f64,
}

impl Default for WristConfig {
    /// 500 rad/s per N·m (a 1 N·mm twist turns the wrist at 0.5 rad/s), dead band
    /// 0.5 N·mm, at most 1 rad/s, ±π/2. On the simulated twist a small model's τz
    /// reads low (about a quarter of the truth), so a low gain leaves the wrist behind.
    fn default() -> Self {
        Self {
            gain_rad_per_nm_s: 500.0,
            deadband_nm: 0.0005,
            max_rate_rad_s: 1.0,
            max_yaw_rad: std::f64::consts::FRAC_PI_2,
        }
    }
}

impl WristConfig {
    /// Rejects unusable settings, naming the field.
    pub fn validate(&self) -> Result<(), GraspError> {
        let mut out = Vec::new();
        for (field, v) in [
            ("gain_rad_per_nm_s", self.gain_rad_per_nm_s),
            ("max_rate_rad_s", self.max_rate_rad_s),
            ("max_yaw_rad", self.max_yaw_rad),
        ] {
            if !(v.is_finite() && v > 0.0) {
                out.push(format!(
                    "wrist {field} {v}: expected a finite value above 0"
                ));
            }
        }
        if !(self.deadband_nm.is_finite() && self.deadband_nm >= 0.0) {
            out.push(format!(
                "wrist deadband_nm {}: expected a finite value ≥ 0",
                self.deadband_nm
            ));
        }
        if out.is_empty() {
            Ok(())
        } else {
            Err(GraspError::Config(out.join("; ")))
        }
    }
}

/// The wrist loop's state: the target it last asked for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WristLoop {
    config: WristConfig,
    target_rad: f64,
}

impl WristLoop {
    /// A loop starting at yaw 0.
    pub fn new(config: WristConfig) -> Result<Self, GraspError> {
        config.validate()?;
        Ok(Self {
            config,
            target_rad: 0.0,
        })
    }

    /// The target now, rad.
    #[must_use]
    pub fn target_rad(&self) -> f64 {
        self.target_rad
    }

    /// One step on the τz estimate (N·m) over `dt_s`: the new target, or `None` when
    /// it holds (within the dead band, no usable estimate, or no time passed).
    pub fn step(&mut self, torque_z_nm: Option<f64>, dt_s: f64) -> Option<f64> {
        let tz = torque_z_nm.filter(|t| t.is_finite())?;
        if !(dt_s.is_finite() && dt_s > 0.0) || tz.abs() <= self.config.deadband_nm {
            return None;
        }
        let c = &self.config;
        let rate = (-c.gain_rad_per_nm_s * tz).clamp(-c.max_rate_rad_s, c.max_rate_rad_s);
        let next = (self.target_rad + rate * dt_s).clamp(-c.max_yaw_rad, c.max_yaw_rad);
        if (next - self.target_rad).abs() < f64::EPSILON {
            return None;
        }
        self.target_rad = next;
        Some(next)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wrist_turns_against_the_torque_and_holds_on_bad_estimates() {
        let mut w = WristLoop::new(WristConfig {
            gain_rad_per_nm_s: 60.0,
            ..WristConfig::default()
        })
        .expect("valid");
        // A negative τz turns the wrist positive, at most at the rate cap.
        let t = w.step(Some(-0.005), 0.01).expect("moves");
        assert!((t - 0.003).abs() < 1e-12, "{t}");
        let t = w.step(Some(-1.0), 0.01).expect("moves");
        assert!((t - 0.013).abs() < 1e-12, "{t}");
        for bad in [None, Some(f64::NAN), Some(f64::INFINITY), Some(0.0001)] {
            assert_eq!(w.step(bad, 0.01), None, "{bad:?}");
        }
        assert_eq!(w.step(Some(0.01), 0.0), None);
        // Never past the yaw limit.
        for _ in 0..1000 {
            w.step(Some(-1.0), 0.1);
        }
        assert!((w.target_rad() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let bad = WristConfig {
            gain_rad_per_nm_s: 0.0,
            ..WristConfig::default()
        };
        let e = WristLoop::new(bad).expect_err("zero gain");
        assert!(e.to_string().contains("gain_rad_per_nm_s"), "{e}");
    }
}
