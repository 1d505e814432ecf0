//! Plain data of the softtouch domain: poses, wrenches, readings, samples, rig and
//! scene configs with validation. It must depend on no other softtouch crate and do no I/O.
//!
//! Everything here is a value type with its unit and frame in its name: SI units in
//! storage (m, rad, N, N·m, ns), torque shown in N·mm where the paper does.
//!
//! # Layout
//! - [`time`]: timestamps and durations in nanoseconds of one monotonic clock.
//! - [`geometry`]: the contact pose `(x, z, θ)` and the arm's rigid pose with its
//!   SE(3) maths (compose, invert, 4×4 matrices, slerp).
//! - [`wrench`]: force/torque values (and their change of frame), the axis names, and
//!   readings from a sensor.
//! - [`sample`]: frame metadata and one collected sample.
//! - [`rig`]: the rig config (devices, workspace bounds, limits, timings).
//! - [`scene`]: the scene spec (medium, rods, declared effects, pose ranges).
//! - [`config`]: TOML loading with validation and errors that name file and field.
//! - [`defaults`]: the embedded all-simulated rig and on-land scene.

pub mod config;
pub mod defaults;
pub mod geometry;
pub mod overrides;
pub mod rig;
pub mod sample;
pub mod scene;
pub mod time;
pub mod wrench;

pub use config::{ConfigError, ConfigSource};
pub use geometry::{ArmPose, ContactPose, Range};
pub use rig::{
    ArmDevice, CameraDevice, FRANKA_DEFAULT_JOINT_TORQUE_THRESHOLDS_NM,
    FRANKA_DEFAULT_MOTION_MARGIN, FRANKA_JOINT_TORQUE_LIMITS_NM, ForceSensorDevice, GripperDevice,
    Payload, Realtime, RigConfig,
};
pub use sample::{FrameFormat, FrameMeta, Sample, SampleStatus};
pub use scene::{Effect, GustComponent, Medium, RodShape, RodSpec, SceneSpec};
pub use time::{DurationNs, TimestampNs};
pub use wrench::{Axis, DegenerateDirection, FtReading, FtStatus, Wrench};

/// Version of this crate, recorded with every run for provenance.
pub const SOFTWARE_VERSION: &str = env!("CARGO_PKG_VERSION");
