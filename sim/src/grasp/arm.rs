//! The arm of a simulated grasp rig, behind the same [`Arm`] trait as a Franka: it
//! carries the soft-finger gripper between poses in the base frame (straight moves,
//! the quintic time law of [`crate::SimArm`], on the injected clock), and what it does
//! to the object follows from where the gripper goes:
//! - coming down to the object's height with the fingers open wider than the object,
//!   the fingers meet a fresh object (the operator set it back in place) where the
//!   grasp pose lies against the object's own pose ([`SoftGraspHandle::place_object`];
//!   none when they miss it);
//! - going up from there starts the grasp's lift ([`SoftGraspHandle::start_lift`]):
//!   the physics decides whether the fingers carry the object;
//! - coming down to the object's height with a held object sets it down;
//! - a turn about the gripper's own axis there turns the grasp's wrist
//!   ([`SoftGraspHandle::set_wrist_target`]; the simulated wrist's own rate applies).
//!
//! One object per arm: the rig's trials of a simulated rig run one object. Poses
//! within [`AT_HEIGHT_M`] of the object's grasp height count as at it, so the rig's
//! approach height must be larger.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use async_trait::async_trait;
use softtouch_drivers::arm::{Arm, ArmState};
use softtouch_drivers::clock::{Clock, TokioClock};
use softtouch_drivers::error::DeviceError;
use softtouch_schemas::{ArmPose, DurationNs, TimestampNs};

use super::{HoldState, SoftGraspHandle};
use crate::arm::{MAX_ACCEL_M_S2, MAX_SPEED_M_S, duration, interpolate, profile};

const DEVICE: &str = "sim-grasp-arm";
/// How close to the object's grasp height counts as at it, m: a perturbed grasp
/// lies a few mm above or below it (whether the fingers still meet the object there
/// is [`crate::GraspObject::placed`]'s call); an approach from above starts higher.
const AT_HEIGHT_M: f64 = 0.02;

/// A move in progress (or done).
#[derive(Debug, Clone, Copy)]
struct Segment {
    t0: TimestampNs,
    t1: TimestampNs,
    from: ArmPose,
    to: ArmPose,
}

impl Segment {
    fn pose_at(&self, t: TimestampNs) -> ArmPose {
        if t >= self.t1 || self.t1 <= self.t0 {
            return self.to;
        }
        let tau = t.0.saturating_sub(self.t0.0) as f64 / (self.t1.0 - self.t0.0) as f64;
        interpolate(&self.from, &self.to, profile(tau))
    }
}

/// The arm of a simulated grasp rig.
#[derive(Debug)]
pub struct SoftGraspArm {
    handle: SoftGraspHandle,
    clock: TokioClock,
    object_at: ArmPose,
    segment: Segment,
    faulted: bool,
    moves: Arc<AtomicU64>,
}

impl SoftGraspArm {
    /// An arm standing at `start` over a grasp whose object stands where the gripper
    /// grasps it at `object_at` (the rig's unperturbed grasp pose), base frame.
    #[must_use]
    pub fn new(
        handle: SoftGraspHandle,
        clock: TokioClock,
        object_at: ArmPose,
        start: ArmPose,
    ) -> Self {
        let now = clock.now();
        Self {
            handle,
            clock,
            object_at: object_at.normalised(),
            segment: Segment {
                t0: now,
                t1: now,
                from: start.normalised(),
                to: start.normalised(),
            },
            faulted: false,
            moves: Arc::new(AtomicU64::new(0)),
        }
    }

    /// Counts the moves started, for a test to see that nothing moved.
    #[must_use]
    pub fn moves(&self) -> Arc<AtomicU64> {
        Arc::clone(&self.moves)
    }

    fn sim(&self, e: &crate::SimError) -> DeviceError {
        DeviceError::Fault {
            device: DEVICE.into(),
            code: None,
            message: e.to_string(),
        }
    }

    fn at_object_height(&self, p: &ArmPose) -> bool {
        (p.translation_m[2] - self.object_at.translation_m[2]).abs() < AT_HEIGHT_M
    }

    /// The grasp point's offset from the object's pose, in the object's grasp frame.
    fn offset_of(&self, p: &ArmPose) -> [f64; 3] {
        self.object_at.inverse().compose(p).translation_m
    }
}

#[async_trait]
impl Arm for SoftGraspArm {
    async fn move_to(&mut self, target: &ArmPose, speed_m_s: f64) -> Result<ArmState, DeviceError> {
        if !(target.is_valid() && speed_m_s.is_finite() && speed_m_s > 0.0) {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: format!(
                    "target {target:?} at {speed_m_s} m/s: expected a finite pose and a speed above 0"
                ),
            });
        }
        if self.faulted {
            return Err(DeviceError::Fault {
                device: DEVICE.into(),
                code: Some(1),
                message: "in reflex: call recover() before moving".into(),
            });
        }
        self.moves.fetch_add(1, Ordering::Relaxed);
        let now = self.clock.now();
        let from = self.segment.pose_at(now);
        let to = target.normalised();
        let speed = speed_m_s.min(MAX_SPEED_M_S);
        let secs = duration(from.distance_to(&to), speed, MAX_ACCEL_M_S2);
        let t1 = now.saturating_add(DurationNs::from_secs_f64(secs));
        self.segment = Segment {
            t0: now,
            t1,
            from,
            to,
        };
        let dz = to.translation_m[2] - from.translation_m[2];
        let hold = self.handle.hold_state_at(now).map_err(|e| self.sim(&e))?;
        if dz > 1e-4 && self.at_object_height(&from) && hold == HoldState::Resting {
            // The trapezoid closest to this move: its mean speed, the arm's acceleration.
            let mean_speed = (dz / secs.max(1e-6)).min(speed);
            self.handle
                .start_lift(now, dz.min(2.0), mean_speed.max(1e-3), MAX_ACCEL_M_S2)
                .map_err(|e| self.sim(&e))?;
        }
        if self.at_object_height(&to) {
            // A turn of the gripper about its own axis at the object is the wrist's.
            let yaw = self.object_at.inverse().compose(&to).yaw_rad();
            self.handle
                .set_wrist_target(yaw)
                .map_err(|e| self.sim(&e))?;
        }
        tokio::time::sleep_until(self.clock.instant_at(t1)).await;
        if dz < -1e-4 && self.at_object_height(&to) {
            let widest_mm = self
                .handle
                .object()
                .map_err(|e| self.sim(&e))?
                .max_width_m()
                * 1000.0;
            let opening = self.handle.opening_mm().map_err(|e| self.sim(&e))?;
            match self.handle.hold_state().map_err(|e| self.sim(&e))? {
                HoldState::Held => self.handle.set_down().map_err(|e| self.sim(&e))?,
                _ if opening > widest_mm => {
                    self.handle
                        .place_object(self.offset_of(&to))
                        .map_err(|e| self.sim(&e))?;
                }
                _ => {}
            }
        }
        self.state().await
    }

    async fn state(&mut self) -> Result<ArmState, DeviceError> {
        let t = self.clock.now();
        Ok(ArmState {
            t,
            base_from_finger: self.segment.pose_at(t),
            external_wrench: None,
            faulted: self.faulted,
            command_success_rate: None,
        })
    }

    async fn recover(&mut self) -> Result<(), DeviceError> {
        self.faulted = false;
        Ok(())
    }

    async fn stop(&mut self) -> Result<(), DeviceError> {
        // Where a dropped move had got to is where the arm stands.
        let now = self.clock.now();
        let here = self.segment.pose_at(now);
        self.segment = Segment {
            t0: now,
            t1: now,
            from: here,
            to: here,
        };
        Ok(())
    }
}
