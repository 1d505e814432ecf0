//! The gripper for grasp trials, with Robotiq Hand-E semantics: position 0 (open) to
//! 255 (closed) over a 50 mm stroke, speed and force as 0–255.

use crate::error::DeviceError;
use async_trait::async_trait;
use softtouch_schemas::TimestampNs;

/// Hand-E stroke (both fingers together), mm.
pub const STROKE_MM: f64 = 50.0;

/// Opening between the fingers, mm, for a position byte (0 open, 255 closed; linear).
#[must_use]
pub fn opening_mm(position: u8) -> f64 {
    STROKE_MM * (1.0 - f64::from(position) / 255.0)
}

/// Position byte for an opening in mm, clamped to the stroke.
#[must_use]
pub fn position_for_opening(opening_mm: f64) -> u8 {
    if !opening_mm.is_finite() {
        return 0;
    }
    let frac = (1.0 - opening_mm / STROKE_MM).clamp(0.0, 1.0);
    (frac * 255.0).round() as u8
}

/// A move command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GripperCommand {
    /// Target position, 0 open … 255 closed.
    pub position: u8,
    /// Speed, 0 slowest … 255 fastest.
    pub speed: u8,
    /// Force, 0 weakest … 255 strongest.
    pub force: u8,
}

/// What the gripper reports about an object (Hand-E gOBJ).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjectStatus {
    /// Fingers moving, no object detected yet.
    Moving,
    /// Stopped on contact while opening.
    ContactOpening,
    /// Stopped on contact while closing: an object is held.
    ContactClosing,
    /// At the requested position, no object.
    AtPosition,
}

/// The gripper's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GripperStatus {
    /// When it was read.
    pub t: TimestampNs,
    /// Activated and ready (gSTA = 3).
    pub activated: bool,
    /// Object detection.
    pub object: ObjectStatus,
    /// The fault byte: gFLT in the low nibble, the controller's kFLT in the high one
    /// (0 = none; [`crate::hande::regs::describe_fault`] names it).
    pub fault: u8,
    /// Requested position echo (gPR).
    pub requested_position: u8,
    /// Actual position (gPO).
    pub position: u8,
    /// Motor current, mA.
    pub current_ma: u32,
}

/// A parallel gripper.
#[async_trait]
pub trait Gripper: Send {
    /// Run the activation sequence and wait until ready.
    async fn activate(&mut self) -> Result<(), DeviceError>;

    /// Send a move command (returns once sent, not once done).
    async fn command(&mut self, cmd: GripperCommand) -> Result<(), DeviceError>;

    /// Read the status.
    async fn status(&mut self) -> Result<GripperStatus, DeviceError>;

    /// Send a move and read the status back, in one exchange where the link has one
    /// (the Hand-E's function 23). The status is read after the write: it echoes the
    /// request (gPR) but the fingers have not moved on it yet. Default: [`Self::command`]
    /// then [`Self::status`].
    async fn command_and_status(
        &mut self,
        cmd: GripperCommand,
    ) -> Result<GripperStatus, DeviceError> {
        self.command(cmd).await?;
        self.status().await
    }
}

#[async_trait]
impl<T: Gripper + ?Sized> Gripper for Box<T> {
    async fn activate(&mut self) -> Result<(), DeviceError> {
        (**self).activate().await
    }
    async fn command(&mut self, cmd: GripperCommand) -> Result<(), DeviceError> {
        (**self).command(cmd).await
    }
    async fn status(&mut self) -> Result<GripperStatus, DeviceError> {
        (**self).status().await
    }
    async fn command_and_status(
        &mut self,
        cmd: GripperCommand,
    ) -> Result<GripperStatus, DeviceError> {
        (**self).command_and_status(cmd).await
    }
}

/// A gripper lent for a while (one trial of a session that keeps it).
#[async_trait]
impl<T: Gripper + ?Sized> Gripper for &mut T {
    async fn activate(&mut self) -> Result<(), DeviceError> {
        (**self).activate().await
    }
    async fn command(&mut self, cmd: GripperCommand) -> Result<(), DeviceError> {
        (**self).command(cmd).await
    }
    async fn status(&mut self) -> Result<GripperStatus, DeviceError> {
        (**self).status().await
    }
    async fn command_and_status(
        &mut self,
        cmd: GripperCommand,
    ) -> Result<GripperStatus, DeviceError> {
        (**self).command_and_status(cmd).await
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn position_and_opening_map_both_ways_within_one_count() {
        assert_eq!(position_for_opening(50.0), 0);
        assert_eq!(position_for_opening(0.0), 255);
        assert_eq!(position_for_opening(-3.0), 255);
        assert_eq!(position_for_opening(f64::NAN), 0);
        for p in 0..=255u8 {
            assert_eq!(position_for_opening(opening_mm(p)), p);
        }
    }
}
