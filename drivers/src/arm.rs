//! The arm that presses the finger on the rod.

use crate::error::DeviceError;
use async_trait::async_trait;
use softtouch_schemas::{ArmPose, TimestampNs, Wrench};

/// What the arm reports about itself.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmState {
    /// When the state was read.
    pub t: TimestampNs,
    /// Measured pose of the finger in the base frame.
    pub base_from_finger: ArmPose,
    /// External wrench the arm estimates at its end effector, where it has one.
    pub external_wrench: Option<Wrench>,
    /// In a reflex (or other error) state: needs [`Arm::recover`] before moving.
    pub faulted: bool,
    /// Share of the last 100 commands of the real-time loop that reached the robot
    /// (libfranka's `control_command_success_rate`), where the arm has one. Below
    /// about 0.95 the host is missing cycles; 20 lost in a row abort the motion. The
    /// robot reports 0 when no motion runs, so only the state a move returns carries
    /// a meaningful value (sampled during that move).
    pub command_success_rate: Option<f64>,
}

/// The measured finger pose as an arm streams it while it moves: when it was measured
/// and where the finger was (base frame). `None` until the first measurement.
pub type PoseFeed = tokio::sync::watch::Receiver<Option<(TimestampNs, ArmPose)>>;

/// A robot arm moving the finger through Cartesian poses.
///
/// Callers check every target against the workspace before calling [`Arm::move_to`];
/// drivers check again and refuse with [`DeviceError::InvalidCommand`].
#[async_trait]
pub trait Arm: Send {
    /// Move to `target` (pose of the finger in the base frame) at up to `speed_m_s`,
    /// returning the state once it is reached. A reflex during the move returns
    /// [`DeviceError::Fault`] and leaves the arm faulted.
    async fn move_to(&mut self, target: &ArmPose, speed_m_s: f64) -> Result<ArmState, DeviceError>;

    /// Move through `legs` (pose of the finger in the base frame, speed m/s) in turn,
    /// returning the state at the end and when each leg ended, on the rig's clock. An
    /// arm that can ([`crate::franka`]) runs legs along one straight line as one
    /// motion: it slows to a slower leg's speed before that leg begins and does not stop
    /// between legs, where one move per leg would start and stop each. The default
    /// moves leg by leg.
    async fn move_through(
        &mut self,
        legs: &[(ArmPose, f64)],
    ) -> Result<(ArmState, Vec<TimestampNs>), DeviceError> {
        let mut ends = Vec::with_capacity(legs.len());
        let mut last = None;
        for (pose, speed_m_s) in legs {
            let s = self.move_to(pose, *speed_m_s).await?;
            ends.push(s.t);
            last = Some(s);
        }
        match last {
            Some(s) => Ok((s, ends)),
            None => self.state().await.map(|s| (s, ends)),
        }
    }

    /// Read the current state.
    async fn state(&mut self) -> Result<ArmState, DeviceError>;

    /// Clear a reflex or error so the arm can move again (automatic error recovery).
    async fn recover(&mut self) -> Result<(), DeviceError>;

    /// The arm's joint positions, rad, where it has joints to report (a robot arm);
    /// `None` for an arm that moves the finger in Cartesian space alone (the simulator).
    async fn joints_rad(&mut self) -> Result<Option<[f64; 7]>, DeviceError> {
        Ok(None)
    }

    /// Move in joint space to `q_rad`, where the arm has joints ([`Arm::joints_rad`]):
    /// a redundant arm's elbow back where it was. `None`: an arm with no joints to
    /// move, nothing moved.
    async fn move_joints(&mut self, q_rad: &[f64; 7]) -> Result<Option<ArmState>, DeviceError> {
        let _ = q_rad;
        Ok(None)
    }

    /// Stop any motion now.
    async fn stop(&mut self) -> Result<(), DeviceError>;

    /// The measured pose while the arm moves, for an arm that streams it (a real arm's
    /// control loop). Lets a simulated sensor and camera follow a real arm.
    fn pose_feed(&self) -> Option<PoseFeed> {
        None
    }

    /// What a real arm found at connect: its mode, and the error recovery run where it
    /// was in reflex (a client that died mid-motion leaves it so). `None`: nothing to
    /// say (a simulated arm).
    fn found_at_connect(&self) -> Option<String> {
        None
    }
}

#[async_trait]
impl<T: Arm + ?Sized> Arm for Box<T> {
    async fn move_to(&mut self, target: &ArmPose, speed_m_s: f64) -> Result<ArmState, DeviceError> {
        (**self).move_to(target, speed_m_s).await
    }
    async fn move_through(
        &mut self,
        legs: &[(ArmPose, f64)],
    ) -> Result<(ArmState, Vec<TimestampNs>), DeviceError> {
        (**self).move_through(legs).await
    }
    async fn state(&mut self) -> Result<ArmState, DeviceError> {
        (**self).state().await
    }
    async fn recover(&mut self) -> Result<(), DeviceError> {
        (**self).recover().await
    }
    async fn joints_rad(&mut self) -> Result<Option<[f64; 7]>, DeviceError> {
        (**self).joints_rad().await
    }
    async fn move_joints(&mut self, q_rad: &[f64; 7]) -> Result<Option<ArmState>, DeviceError> {
        (**self).move_joints(q_rad).await
    }
    async fn stop(&mut self) -> Result<(), DeviceError> {
        (**self).stop().await
    }
    fn pose_feed(&self) -> Option<PoseFeed> {
        (**self).pose_feed()
    }
    fn found_at_connect(&self) -> Option<String> {
        (**self).found_at_connect()
    }
}
