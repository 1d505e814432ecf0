//! The simulated Hand-E: fingers move at the commanded speed in virtual time, stop on
//! an object and squeeze it with the commanded force; the grasp holds while friction
//! on both fingers carries the object's weight plus the fluid's drag.

use super::lock;
use super::world::SimWorld;
use async_trait::async_trait;
use softtouch_drivers::clock::{Clock, TokioClock};
use softtouch_drivers::error::DeviceError;
use softtouch_drivers::gripper::{
    Gripper, GripperCommand, GripperStatus, ObjectStatus, STROKE_MM, opening_mm,
};
use softtouch_schemas::TimestampNs;
use std::sync::{Arc, Mutex};
use std::time::Duration;

const DEVICE: &str = "sim-gripper";
/// Standard gravity, m/s².
pub const G_M_S2: f64 = 9.806_65;
/// Hand-E finger speed range (both fingers), mm/s.
pub const SPEED_MM_S: [f64; 2] = [20.0, 150.0];
/// Hand-E grip force range, N.
pub const FORCE_N: [f64; 2] = [20.0, 185.0];
/// Time the activation sequence takes.
pub const ACTIVATION: Duration = Duration::from_millis(1500);

/// An object between the fingers for grasp trials.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimObject {
    /// Width across the fingers, m.
    pub width_m: f64,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Friction coefficient between the fingers and the object.
    pub friction: f64,
    /// Contact stiffness (finger and object together), N/m: how far the fingers close
    /// past the object's width under the grip force.
    pub stiffness_n_per_m: f64,
}

/// Grip force in N for a force byte.
#[must_use]
pub fn grip_force_n(force: u8) -> f64 {
    FORCE_N[0] + (FORCE_N[1] - FORCE_N[0]) * f64::from(force) / 255.0
}

/// The grasp holds when friction on both fingers carries weight plus drag:
/// `2·μ·F_grip ≥ m·g + drag`.
#[must_use]
pub fn grasp_holds(object: &SimObject, grip_force_n: f64, drag_n: f64) -> bool {
    2.0 * object.friction * grip_force_n >= object.mass_kg * G_M_S2 + drag_n.abs()
}

/// The simulated gripper.
#[derive(Debug)]
pub struct SimGripper {
    world: Arc<Mutex<SimWorld>>,
    clock: TokioClock,
    activated: bool,
    cmd: GripperCommand,
    opening_mm: f64,
    last_t: TimestampNs,
    object: ObjectStatus,
}

impl SimGripper {
    pub(crate) fn new(world: Arc<Mutex<SimWorld>>, clock: TokioClock) -> Self {
        Self {
            world,
            clock,
            activated: false,
            cmd: GripperCommand {
                position: 0,
                speed: 0,
                force: 0,
            },
            opening_mm: STROKE_MM,
            last_t: TimestampNs::ZERO,
            object: ObjectStatus::AtPosition,
        }
    }

    /// Advance the fingers to `now`.
    fn advance(&mut self, now: TimestampNs) -> Result<(), DeviceError> {
        let dt = now.0.saturating_sub(self.last_t.0) as f64 * 1e-9;
        self.last_t = now;
        if !self.activated {
            return Ok(());
        }
        let mut world = lock(&self.world)?;
        let target = opening_mm(self.cmd.position);
        let speed =
            SPEED_MM_S[0] + (SPEED_MM_S[1] - SPEED_MM_S[0]) * f64::from(self.cmd.speed) / 255.0;
        let force = grip_force_n(self.cmd.force);
        let closing = target < self.opening_mm;
        // Where the fingers stop on the object, if there is one in the way.
        let stop = world.object.map(|o| {
            let squeeze_mm =
                (force / o.stiffness_n_per_m.max(1e-9) * 1000.0).min(o.width_m * 1000.0);
            o.width_m * 1000.0 - squeeze_mm
        });
        let step = speed * dt;
        match stop {
            Some(stop_mm) if closing && target < stop_mm && self.opening_mm >= stop_mm => {
                let before = self.opening_mm;
                self.opening_mm = (self.opening_mm - step).max(stop_mm);
                if self.opening_mm <= stop_mm {
                    // On the object: does the grasp hold?
                    let drag = world
                        .scene
                        .effects
                        .fluid_drag
                        .map_or(0.0, |(c, flow)| c * flow * flow);
                    let holds = world.object.is_some_and(|o| grasp_holds(&o, force, drag));
                    if holds {
                        self.object = ObjectStatus::ContactClosing;
                    } else {
                        // The object slips out; the fingers close on for the rest
                        // of the step.
                        world.object = None;
                        let rest = (step - (before - stop_mm)).max(0.0);
                        self.opening_mm = (stop_mm - rest).max(target);
                        self.object = if self.opening_mm <= target {
                            ObjectStatus::AtPosition
                        } else {
                            ObjectStatus::Moving
                        };
                    }
                } else {
                    self.object = ObjectStatus::Moving;
                }
            }
            _ => {
                if closing {
                    self.opening_mm = (self.opening_mm - step).max(target);
                } else {
                    self.opening_mm = (self.opening_mm + step).min(target);
                }
                self.object = if (self.opening_mm - target).abs() < 1e-9 {
                    ObjectStatus::AtPosition
                } else {
                    ObjectStatus::Moving
                };
            }
        }
        Ok(())
    }
}

#[async_trait]
impl Gripper for SimGripper {
    async fn activate(&mut self) -> Result<(), DeviceError> {
        if !self.activated {
            tokio::time::sleep(ACTIVATION).await;
            let now = self.clock.now();
            self.last_t = now;
            self.activated = true;
        }
        Ok(())
    }

    async fn command(&mut self, cmd: GripperCommand) -> Result<(), DeviceError> {
        if !self.activated {
            return Err(DeviceError::InvalidCommand {
                device: DEVICE.into(),
                message: "not activated".into(),
            });
        }
        self.advance(self.clock.now())?;
        self.cmd = cmd;
        Ok(())
    }

    async fn status(&mut self) -> Result<GripperStatus, DeviceError> {
        let now = self.clock.now();
        self.advance(now)?;
        let current_ma = match self.object {
            ObjectStatus::ContactClosing | ObjectStatus::ContactOpening => {
                (100.0 + 500.0 * f64::from(self.cmd.force) / 255.0) as u32
            }
            ObjectStatus::Moving => 150,
            ObjectStatus::AtPosition => 0,
        };
        Ok(GripperStatus {
            t: now,
            activated: self.activated,
            object: self.object,
            fault: 0,
            requested_position: self.cmd.position,
            position: softtouch_drivers::gripper::position_for_opening(self.opening_mm),
            current_ma,
        })
    }
}
