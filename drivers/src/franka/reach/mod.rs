//! Whether the arm can reach a rig's poses within the robot's limits, checked before
//! anything moves (`config check`, and at connect from the joints the arm is at).
//!
//! Each pose is solved for the joints by damped least squares on franka-rs's
//! kinematics (the FER's, which the FR3 shares), and every straight move between the
//! poses is followed in small steps as the robot's own Cartesian motion follows it:
//! each joint against its range, and its velocity at the move's speed against the
//! position-dependent velocity limits. On an FR3 those limits shrink toward both ends
//! of each joint's range (`v ≤ √(2·a·(q_max − q)) − offset`), so a move that turns a
//! joint quickly toward its end is aborted by the robot with
//! `joint_velocity_violation`; this names it first.
//!
//! The robot's own inverse kinematics is not published: a redundant arm may take
//! another elbow than the one found here. A pose refused here is out of reach or too
//! fast on the way found from the arm's joints; one accepted is very likely fine, and
//! the robot remains the last judge.

use nalgebra::{Matrix6, SMatrix, Vector3, Vector6};
use softtouch_schemas::ArmPose;
use softtouch_schemas::rig::WorkspaceBounds;

mod kinematics;
mod route;
mod scale;

pub use kinematics::*;
pub use route::*;
pub use scale::*;

#[cfg(test)]
mod tests;
