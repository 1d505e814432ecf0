//! A real arm's [`Lift`]: the arm (behind [`Arm`], shared with the rig's other moves)
//! raises the gripper from the grasp pose on a task of its own, so the force loop goes
//! on cycling at camera rate while it moves.

use std::sync::Arc;

use softtouch_drivers::{Arm, ArmState, DeviceError};
use softtouch_schemas::ArmPose;
use softtouch_schemas::rig::{WorkspaceBounds, raised};

use super::{Lift, LiftPlan};
use crate::GraspError;

/// The arm, shared between a trial's lift (its own task) and the rig's moves.
pub type SharedArm = Arc<tokio::sync::Mutex<Box<dyn Arm>>>;

/// Lifts by moving the arm `height_m` straight up (base frame z) from `from` at the
/// plan's speed (the arm's own acceleration limits apply: [`Arm::move_to`] takes no
/// acceleration). The lifted pose is checked against the reach box before anything
/// moves.
pub struct ArmLift {
    arm: SharedArm,
    from: ArmPose,
    workspace: WorkspaceBounds,
    task: Option<tokio::task::JoinHandle<Result<ArmState, DeviceError>>>,
}

impl std::fmt::Debug for ArmLift {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ArmLift")
            .field("from", &self.from)
            .field("started", &self.task.is_some())
            .finish_non_exhaustive()
    }
}

impl ArmLift {
    /// A lift from `from` (where the gripper grasps), inside `workspace`.
    #[must_use]
    pub fn new(arm: SharedArm, from: ArmPose, workspace: WorkspaceBounds) -> Self {
        Self {
            arm,
            from,
            workspace,
            task: None,
        }
    }

    /// Whether the lift was started (the object may be in the air).
    #[must_use]
    pub const fn started(&self) -> bool {
        self.task.is_some()
    }

    /// Waits for the lift's move to end: `None` when it never started, else the arm's
    /// state at the top or the move's error (a reflex leaves the arm faulted).
    pub async fn finish(&mut self) -> Option<Result<ArmState, DeviceError>> {
        let task = self.task.as_mut()?;
        Some(match task.await {
            Ok(r) => r,
            Err(e) => Err(DeviceError::Fault {
                device: "arm".into(),
                code: None,
                message: format!("the lift's task failed: {e}"),
            }),
        })
    }

    /// Drops the lift's move where it is (the caller then stops the arm).
    pub fn abort(&mut self) {
        if let Some(task) = &self.task {
            task.abort();
        }
    }
}

impl Drop for ArmLift {
    fn drop(&mut self) {
        // A lift outliving its trial would move an arm nobody watches.
        self.abort();
    }
}

impl Lift for ArmLift {
    async fn start_lift(&mut self, plan: &LiftPlan) -> Result<(), GraspError> {
        plan.validate()?;
        if self.task.is_some() {
            return Err(GraspError::Config(
                "lift: already started (one lift per grasp)".into(),
            ));
        }
        let top = raised(&self.from, plan.height_m);
        if !self.workspace.contains_arm(&top) {
            return Err(GraspError::Device(DeviceError::InvalidCommand {
                device: "arm".into(),
                message: format!(
                    "the lift's top {:?} m lies outside workspace.reach_in_base_m",
                    top.translation_m
                ),
            }));
        }
        let arm = Arc::clone(&self.arm);
        let speed = plan.speed_m_s;
        self.task = Some(tokio::spawn(async move {
            arm.lock().await.move_to(&top, speed).await
        }));
        Ok(())
    }
}
