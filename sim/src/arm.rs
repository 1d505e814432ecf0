//! The simulated arm: straight Cartesian moves with a smooth (quintic) time law under
//! velocity and acceleration limits, in virtual time; reflex faults on excess contact
//! force or when the scene's `arm_reflex` effect injects one.

use super::world::{Segment, SimWorld};
use super::{lock, rng};
use async_trait::async_trait;
use rand::RngExt;
use softtouch_drivers::arm::{Arm, ArmState};
use softtouch_drivers::clock::{Clock, TokioClock};
use softtouch_drivers::error::DeviceError;
use softtouch_schemas::{ArmPose, ContactPose, DurationNs, TimestampNs};
use std::sync::{Arc, Mutex};

/// Translational speed limit (the Franka's FCI limit), m/s.
pub const MAX_SPEED_M_S: f64 = 1.7;
/// Translational acceleration limit, m/s².
pub const MAX_ACCEL_M_S2: f64 = 4.0;
/// Rotational speed limit, rad/s.
pub const MAX_ROT_SPEED_RAD_S: f64 = 2.5;
/// Rotational acceleration limit, rad/s².
pub const MAX_ROT_ACCEL_RAD_S2: f64 = 10.0;
/// Points along a move at which the contact force is checked against the reflex.
const REFLEX_CHECKS: usize = 64;
const DEVICE: &str = "sim-arm";

/// Quintic (minimum-jerk) time law `s(τ)`, τ ∈ [0, 1]. Peak `ds/dτ` = 1.875,
/// peak `d²s/dτ²` ≈ 5.774.
pub(crate) fn profile(tau: f64) -> f64 {
    let t = tau.clamp(0.0, 1.0);
    t * t * t * (10.0 - 15.0 * t + 6.0 * t * t)
}

/// Duration of a quintic move over `dist` under a speed and acceleration limit.
pub(crate) fn duration(dist: f64, v: f64, a: f64) -> f64 {
    if dist <= 0.0 {
        return 0.0;
    }
    (1.875 * dist / v).max((5.7735 * dist / a).sqrt())
}

/// Pose a fraction `s` of the way (linear translation, normalised-lerp rotation on
/// the short arc).
pub(crate) fn interpolate(a: &ArmPose, b: &ArmPose, s: f64) -> ArmPose {
    let mut qb = b.rotation_wxyz;
    let d: f64 = a.rotation_wxyz.iter().zip(&qb).map(|(x, y)| x * y).sum();
    if d < 0.0 {
        qb = qb.map(|v| -v);
    }
    let q: [f64; 4] =
        std::array::from_fn(|i| a.rotation_wxyz[i] + (qb[i] - a.rotation_wxyz[i]) * s);
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let q = if n > 1e-12 {
        q.map(|v| v / n)
    } else {
        a.rotation_wxyz
    };
    ArmPose {
        translation_m: std::array::from_fn(|i| {
            a.translation_m[i] + (b.translation_m[i] - a.translation_m[i]) * s
        }),
        rotation_wxyz: q,
    }
}

/// The contact pose of a finger pose: `rod_from_finger = base_from_rod⁻¹ · base_from_finger`,
/// read as `Trans(x, y, z) · RotZ(θ)`; the off-plane offset `y` is ignored.
pub(crate) fn contact_from_arm(base_from_rod: &ArmPose, base_from_finger: &ArmPose) -> ContactPose {
    let [w, x, y, z] = base_from_rod.normalised().rotation_wxyz;
    let inv_rot = ArmPose {
        translation_m: [0.0; 3],
        rotation_wxyz: [w, -x, -y, -z],
    };
    let t = base_from_rod.translation_m;
    let d = [
        base_from_finger.translation_m[0] - t[0],
        base_from_finger.translation_m[1] - t[1],
        base_from_finger.translation_m[2] - t[2],
    ];
    let p = inv_rot.rotate(d);
    let rel = ArmPose {
        translation_m: p,
        rotation_wxyz: inv_rot.compose(base_from_finger).rotation_wxyz,
    };
    ContactPose {
        x_m: p[0],
        z_m: p[2],
        theta_rad: rel.yaw_rad(),
    }
}

/// The index of a move's random stream: its start time and its target's bits.
fn move_key(t0: TimestampNs, target: &ArmPose) -> u64 {
    target
        .translation_m
        .iter()
        .chain(&target.rotation_wxyz)
        .fold(t0.0, |h, v| {
            (h ^ v.to_bits())
                .rotate_left(23)
                .wrapping_mul(0x9e37_79b9_7f4a_7c15)
        })
}

/// The simulated arm.
#[derive(Debug)]
pub struct SimArm {
    world: Arc<Mutex<SimWorld>>,
    clock: TokioClock,
    reflex_force_n: f64,
    faulted: bool,
    seed: u64,
}

impl SimArm {
    pub(crate) fn new(
        world: Arc<Mutex<SimWorld>>,
        clock: TokioClock,
        reflex_force_n: f64,
        seed: u64,
    ) -> Self {
        Self {
            world,
            clock,
            reflex_force_n,
            faulted: false,
            seed,
        }
    }

    fn fault(&self, message: String) -> DeviceError {
        DeviceError::Fault {
            device: DEVICE.into(),
            code: Some(0x1),
            message,
        }
    }

    fn read_state(&self, t: TimestampNs) -> Result<ArmState, DeviceError> {
        let mut w = lock(&self.world)?;
        let pose = w.pose_at(t);
        let wrench = w.wrench_for(&pose).map_err(|e| self.fault(e.to_string()))?;
        Ok(ArmState {
            t,
            base_from_finger: pose,
            external_wrench: Some(wrench),
            faulted: self.faulted,
            command_success_rate: None,
        })
    }
}

#[async_trait]
impl Arm for SimArm {
    async fn move_to(&mut self, target: &ArmPose, speed_m_s: f64) -> Result<ArmState, DeviceError> {
        if !target.is_valid() {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: format!("target {target:?} has non-finite values or a zero quaternion"),
            });
        }
        if !(speed_m_s.is_finite() && speed_m_s > 0.0) {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: format!("speed {speed_m_s} m/s must be finite and positive"),
            });
        }
        if self.faulted {
            return Err(self.fault("in reflex: call recover() before moving".into()));
        }
        let now = self.clock.now();
        let target = target.normalised();
        let (t_end, fault_at) = {
            let mut w = lock(&self.world)?;
            let from = w.pose_at(now);
            let d = from.distance_to(&target);
            let secs = duration(d, speed_m_s.min(MAX_SPEED_M_S), MAX_ACCEL_M_S2).max(duration(
                from.angle_to(&target),
                MAX_ROT_SPEED_RAD_S,
                MAX_ROT_ACCEL_RAD_S2,
            ));
            let t_end = now.saturating_add(DurationNs::from_secs_f64(secs));
            let span = (t_end.0 - now.0) as f64;
            // Reflex on excess contact force along the path.
            // Only a move that presses harder than where it started can trip it (a
            // retreat after a reflex must be possible).
            let f_start = w
                .wrench_for(&from)
                .map_err(|e| self.fault(e.to_string()))?
                .force_norm_n();
            let mut fault_at = None;
            for i in 1..=REFLEX_CHECKS {
                let tau = i as f64 / REFLEX_CHECKS as f64;
                let pose = interpolate(&from, &target, profile(tau));
                let f = w
                    .wrench_for(&pose)
                    .map_err(|e| self.fault(e.to_string()))?
                    .force_norm_n();
                if f > self.reflex_force_n && f > f_start {
                    fault_at = Some((
                        TimestampNs(now.0 + (span * tau) as u64),
                        format!(
                            "reflex: contact force {f:.1} N above {:.1} N",
                            self.reflex_force_n
                        ),
                    ));
                    break;
                }
            }
            // Drawn from the stream of this move (its start time and target), not from
            // one sequence: the same move at the same time of a run faults the same way
            // however many moves came before it in this process (a resumed run).
            let mut draws = rng::indexed(self.seed, "arm", move_key(now, &target));
            if let Some(p) = w.scene.effects.arm_reflex_probability
                && draws.random_bool(p.clamp(0.0, 1.0))
            {
                let tau: f64 = draws.random_range(0.2..1.0);
                let t = TimestampNs(now.0 + (span * tau) as u64);
                if fault_at.as_ref().is_none_or(|(tf, _)| t < *tf) {
                    fault_at = Some((
                        t,
                        "reflex: injected by the scene's arm_reflex effect".into(),
                    ));
                }
            }
            w.push_segment(Segment {
                t0: now,
                t1: t_end,
                from,
                to: target,
            });
            if let Some((t, _)) = &fault_at {
                w.truncate_motion(*t);
            }
            (t_end, fault_at)
        };
        if let Some((t, message)) = fault_at {
            tokio::time::sleep_until(self.clock.instant_at(t)).await;
            self.faulted = true;
            return Err(self.fault(message));
        }
        tokio::time::sleep_until(self.clock.instant_at(t_end)).await;
        self.read_state(self.clock.now())
    }

    async fn state(&mut self) -> Result<ArmState, DeviceError> {
        self.read_state(self.clock.now())
    }

    async fn recover(&mut self) -> Result<(), DeviceError> {
        self.faulted = false;
        Ok(())
    }

    async fn stop(&mut self) -> Result<(), DeviceError> {
        let now = self.clock.now();
        lock(&self.world)?.truncate_motion(now);
        Ok(())
    }
}
