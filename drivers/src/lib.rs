//! Devices: one narrow trait per kind, the clock every reading is stamped with, and
//! the drivers behind them.
//!
//! # Layout
//! - [`clock`]: the injected [`Clock`]; [`TokioClock`] reads tokio's clock, which is
//!   host monotonic time on a rig and virtual (paused, auto-advancing) time in
//!   simulation. No driver reads wall time itself.
//! - [`error`]: [`DeviceError`], which keeps "the device refused or reported a fault"
//!   apart from "the link failed".
//! - [`arm`], [`force`], [`camera`], [`gripper`]: the device traits and their data.
//! - [`sim`]: the simulated scene (finger, contact, lattice, renderer, effects) and the
//!   simulated twin of every device.
//!
//! Traits are async (tokio) and object-safe, so the CLI can build a rig of boxed
//! devices from the rig config, real and simulated alike.

pub mod arm;
pub mod camera;
pub mod clock;
pub mod error;
pub mod force;
pub mod gripper;
pub mod sim;

pub use arm::{Arm, ArmState};
pub use camera::{Camera, Frame};
pub use clock::{Clock, TokioClock};
pub use error::DeviceError;
pub use force::ForceSensor;
pub use gripper::{Gripper, GripperCommand, GripperStatus, ObjectStatus};
