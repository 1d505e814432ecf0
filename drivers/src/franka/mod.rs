//! The Franka Emika Panda (FER, FCI v5) and Franka Research 3 (FCI v10) through
//! franka-rs (library `franka`), which connects as v10 and falls back to v5 when the
//! robot answers so; any other version is refused with both versions named.
//!
//! franka-rs is synchronous and runs a 1 kHz loop, so the robot lives on its own
//! thread; [`FrankaArm`] talks to it over channels. A move is a straight line in
//! Cartesian space (translation interpolated, rotation slerped) along one path
//! parameter driven by franka-rs's jerk-limited OTG, with limits chosen so the
//! translation stays within the velocity/acceleration/jerk of [`MotionLimits`] and
//! the rotation within its rotational limits (docs/PROTOCOLS.md §3). The first setpoint is
//! seeded from the commanded pose `O_T_EE_c`. Dropping a move's future (a timeout, a
//! cancelled task) or [`Arm::stop`] aborts the motion: it brakes to rest within the
//! acceleration and jerk limits ([`Brake`]), then ends.
//!
//! The finger's pose is the robot's end-effector frame `O_T_EE`: the rig's
//! `end_effector` is applied with `set_ee` at connect (else Desk's end effector must be
//! the finger), and its `payload` with `set_load`, so that the unmodelled finger, mount
//! and sensor do not bias the robot's external-force estimate.
//!
//! The stiffness frame `K` is set to the end effector (`EE_T_K` = identity, read back
//! at connect), so the robot's external wrench estimate is taken at the finger whatever
//! Desk left there.
//!
//! A move is cancelled by generation: each move sent gets the next number, and
//! dropping its future or [`Arm::stop`] cancels every move up to that number. A move
//! still queued behind another when it is cancelled never reaches the robot; one
//! running brakes to rest. (A single abort flag, cleared when a move was taken from the
//! queue, let a cancelled queued move run in full with nobody waiting on it.)
//!
//! `control_command_success_rate` is zero whenever no motion runs (libfranka's
//! documentation), so the share of commands that reached the robot is sampled inside
//! the move's control loop and returned with the move's state.
//!
//! Real time: by default the control thread must get SCHED_FIFO on a PREEMPT_RT
//! kernel (franka-rs's `RealtimeConfig::Enforce`), or the connection is refused with
//! the reason; a rig may relax this (`realtime = "ignore"`), warned about at every
//! connect.

use crate::arm::{Arm, ArmState, PoseFeed};
use crate::clock::Clock;
use crate::error::DeviceError;
use async_trait::async_trait;
use softtouch_schemas::{ArmPose, TimestampNs, Wrench};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use tokio::sync::{oneshot, watch};

/// The measured pose's publisher (every [`FEED_EVERY`] control cycles, and every state
/// read).
type FeedTx = Arc<watch::Sender<Option<(TimestampNs, ArmPose)>>>;

/// Control cycles between two poses published on the feed (4 ms at 1 kHz).
const FEED_EVERY: usize = 4;

const DEVICE: &str = "franka";

mod arm;
pub mod blend;
mod brake;
mod connect;
pub mod joints;
mod limits;
mod worker;

pub use arm::FrankaArm;
pub use brake::Brake;
pub use connect::{FrankaConfig, check_configured, check_stiffness_frame, joint_thresholds};
use connect::{check_reach, configure, robot_kinematics};
pub use limits::{MAX_SPEED_M_S, MotionLimits, cartesian_limits, path_limits};
pub use worker::{Cancel, SuccessRate, lower};
use worker::{Cmd, Reply, err, gone, worker};

pub mod reach;
pub mod signal;
use reach::IDENTITY;

#[cfg(test)]
mod tests;
