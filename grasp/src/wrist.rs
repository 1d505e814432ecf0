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
//! the lab crate (this crate names no simulator); on a rig, [`ArmWrist`] turns the
//! arm's flange about the fingers' axis through the [`Arm`] trait (a Franka's
//! Cartesian moves), on a task of its own that follows the loop's latest target.

use crate::GraspError;
#[cfg(doc)]
use softtouch_drivers::Arm;

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

/// A wrist on a real arm: the gripper turned about its own z (the fingers' axis)
/// from where the grasp started, by Cartesian moves of the arm ([`Arm::move_to`],
/// the translation unchanged). A task of its own follows the loop's latest target in
/// steps of at most `max_step_rad` (so a newer target is taken up within one short
/// move), keeps every target inside ±`max_yaw_rad` and refuses a start pose outside
/// the reach box. A move that fails stops the task; the next call reports it (the
/// controller then ends through its own safe exit). Dropping the wrist stops the task.
pub struct ArmWrist {
    target: tokio::sync::watch::Sender<f64>,
    state: std::sync::Arc<std::sync::Mutex<(f64, Option<String>)>>,
    max_yaw_rad: f64,
    task: tokio::task::JoinHandle<()>,
}

impl std::fmt::Debug for ArmWrist {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ArmWrist")
            .field("max_yaw_rad", &self.max_yaw_rad)
            .finish_non_exhaustive()
    }
}

impl Drop for ArmWrist {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// Where the gripper stands at wrist yaw `yaw_rad` from `start`: turned about its own z.
#[must_use]
pub fn turned(start: &softtouch_schemas::ArmPose, yaw_rad: f64) -> softtouch_schemas::ArmPose {
    start.compose(&softtouch_schemas::ArmPose::from_translation_yaw(
        [0.0; 3], yaw_rad,
    ))
}

impl ArmWrist {
    /// Starts following targets from `start` (the gripper's pose when the grasp began)
    /// at `speed_m_s` (the arm's moves; the turn itself is bounded by the arm's own
    /// rotation limits), each step at most `max_step_rad`, every target within
    /// ±`max_yaw_rad`. Needs a tokio runtime.
    ///
    /// # Errors
    /// A start pose outside `workspace`'s reach box, or limits not finite and above 0.
    pub fn start(
        arm: crate::trials::SharedArm,
        start: softtouch_schemas::ArmPose,
        workspace: &softtouch_schemas::rig::WorkspaceBounds,
        speed_m_s: f64,
        max_step_rad: f64,
        max_yaw_rad: f64,
    ) -> Result<Self, GraspError> {
        for (field, v) in [
            ("speed_m_s", speed_m_s),
            ("max_step_rad", max_step_rad),
            ("max_yaw_rad", max_yaw_rad),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(GraspError::Config(format!(
                    "arm wrist {field} {v}: expected a finite value above 0"
                )));
            }
        }
        if !workspace.contains_arm(&start) {
            return Err(GraspError::Config(format!(
                "arm wrist: the start pose {:?} m lies outside workspace.reach_in_base_m",
                start.translation_m
            )));
        }
        let (target, mut rx) = tokio::sync::watch::channel(0.0_f64);
        let state = std::sync::Arc::new(std::sync::Mutex::new((0.0_f64, None::<String>)));
        let shared = std::sync::Arc::clone(&state);
        let task = tokio::spawn(async move {
            let mut at = 0.0_f64;
            loop {
                let goal = *rx.borrow_and_update();
                if (goal - at).abs() < 1e-6 {
                    if rx.changed().await.is_err() {
                        return;
                    }
                    continue;
                }
                let next = at + (goal - at).clamp(-max_step_rad, max_step_rad);
                let moved = arm
                    .lock()
                    .await
                    .move_to(&turned(&start, next), speed_m_s)
                    .await;
                let Ok(mut s) = shared.lock() else { return };
                match moved {
                    Ok(_) => {
                        at = next;
                        s.0 = at;
                    }
                    Err(e) => {
                        s.1 = Some(e.to_string());
                        return;
                    }
                }
            }
        });
        Ok(Self {
            target,
            state,
            max_yaw_rad,
            task,
        })
    }

    fn failed(&self) -> Result<f64, GraspError> {
        let s = self
            .state
            .lock()
            .map_err(|_| GraspError::Config("arm wrist: its state was poisoned".into()))?;
        match &s.1 {
            Some(e) => Err(GraspError::Device(softtouch_drivers::DeviceError::Fault {
                device: "arm wrist".into(),
                code: None,
                message: format!("the wrist's move failed: {e}"),
            })),
            None => Ok(s.0),
        }
    }
}

impl Wrist for ArmWrist {
    fn set_yaw_target(&mut self, yaw_rad: f64) -> Result<(), GraspError> {
        self.failed()?;
        if !yaw_rad.is_finite() {
            // A non-finite target never moves the arm.
            return Err(GraspError::Config(format!(
                "arm wrist: target {yaw_rad} rad: expected a finite yaw"
            )));
        }
        let _ = self
            .target
            .send(yaw_rad.clamp(-self.max_yaw_rad, self.max_yaw_rad));
        Ok(())
    }

    fn yaw_rad(&mut self) -> Result<f64, GraspError> {
        self.failed()
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

    /// An arm that records where it is sent, failing from move `fail_at` on.
    #[derive(Debug)]
    struct Recording {
        poses: std::sync::Arc<std::sync::Mutex<Vec<softtouch_schemas::ArmPose>>>,
        fail_at: usize,
    }

    #[async_trait::async_trait]
    impl softtouch_drivers::Arm for Recording {
        async fn move_to(
            &mut self,
            target: &softtouch_schemas::ArmPose,
            _speed_m_s: f64,
        ) -> Result<softtouch_drivers::ArmState, softtouch_drivers::DeviceError> {
            tokio::time::sleep(std::time::Duration::from_millis(10)).await;
            let mut p = self.poses.lock().expect("lock");
            if p.len() >= self.fail_at {
                return Err(softtouch_drivers::DeviceError::Fault {
                    device: "arm".into(),
                    code: Some(1),
                    message: "reflex".into(),
                });
            }
            p.push(*target);
            Ok(softtouch_drivers::ArmState {
                t: softtouch_schemas::TimestampNs::ZERO,
                base_from_finger: *target,
                external_wrench: None,
                faulted: false,
                command_success_rate: None,
            })
        }
        async fn state(
            &mut self,
        ) -> Result<softtouch_drivers::ArmState, softtouch_drivers::DeviceError> {
            Err(softtouch_drivers::DeviceError::InvalidCommand {
                device: "arm".into(),
                message: "unused".into(),
            })
        }
        async fn recover(&mut self) -> Result<(), softtouch_drivers::DeviceError> {
            Ok(())
        }
        async fn stop(&mut self) -> Result<(), softtouch_drivers::DeviceError> {
            Ok(())
        }
    }

    #[tokio::test(start_paused = true)]
    async fn the_arm_wrist_turns_the_flange_in_capped_steps_and_never_on_a_bad_target() {
        let poses = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let arm: crate::trials::SharedArm =
            std::sync::Arc::new(tokio::sync::Mutex::new(Box::new(Recording {
                poses: std::sync::Arc::clone(&poses),
                fail_at: 6,
            })));
        let workspace = softtouch_schemas::defaults::rig().workspace;
        // Pointing down, inside the default reach box.
        let start = softtouch_schemas::ArmPose {
            translation_m: [0.5, 0.0, 0.3],
            rotation_wxyz: [0.0, 1.0, 0.0, 0.0],
        };
        let mut outside = start;
        outside.translation_m[0] = 2.0;
        assert!(ArmWrist::start(arm.clone(), outside, &workspace, 0.1, 0.1, 1.0).is_err());
        let mut w = ArmWrist::start(arm, start, &workspace, 0.1, 0.1, 1.0).expect("starts");
        w.set_yaw_target(0.25).expect("takes it");
        tokio::time::sleep(std::time::Duration::from_millis(200)).await;
        let seen: Vec<(f64, [f64; 3])> = poses
            .lock()
            .expect("lock")
            .iter()
            .map(|p| (start.inverse().compose(p).yaw_rad(), p.translation_m))
            .collect();
        // Steps of at most 0.1 rad about the gripper's own axis, the flange staying put.
        assert_eq!(seen.len(), 3, "{seen:?}");
        for ((yaw, at), want) in seen.iter().zip([0.1, 0.2, 0.25]) {
            assert!((yaw - want).abs() < 1e-9, "{seen:?}");
            assert!(
                at.iter()
                    .zip(start.translation_m)
                    .all(|(a, b)| (a - b).abs() < 1e-12),
                "{seen:?}"
            );
        }
        assert!((w.yaw_rad().expect("yaw") - 0.25).abs() < 1e-9);
        // A NaN target moves nothing; one past the limit stops at it.
        assert!(w.set_yaw_target(f64::NAN).is_err());
        w.set_yaw_target(5.0).expect("clamped");
        tokio::time::sleep(std::time::Duration::from_millis(500)).await;
        // The arm faults on its 7th move: the wrist stops there and says so.
        assert_eq!(poses.lock().expect("lock").len(), 6);
        assert!(w.yaw_rad().is_err());
        assert!(w.set_yaw_target(0.0).is_err());
    }
}
