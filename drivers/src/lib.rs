//! Devices: one narrow trait per kind, the clock every reading is stamped with, and
//! the real drivers behind them; it must not depend on the simulator, a store or a model.
//!
//! # Layout
//! - [`clock`]: the injected [`Clock`]; [`TokioClock`] reads tokio's clock, which is
//!   host monotonic time on a rig and virtual (paused, auto-advancing) time in
//!   simulation. No driver reads wall time itself.
//! - [`error`]: [`DeviceError`], which keeps "the device refused or reported a fault"
//!   apart from "the link failed".
//! - [`arm`], [`force`], [`camera`], [`gripper`]: the device traits and their data.
//! - Real drivers, each speaking its wire protocol over an injected transport:
//!   [`netft`] (ATI Net F/T RDT over UDP, with a simulated server), [`ati_serial`]
//!   (ATI serial F/T controller, ASCII, with a simulated controller), [`hande`]
//!   (Robotiq Hand-E, Modbus RTU through tokio-modbus, with a simulated Hand-E),
//!   [`franka`] (Panda through franka-rs on its own thread), `v4l_camera` (V4L2,
//!   behind feature `v4l`, which needs libclang to build); [`v4l_controls`], the image
//!   settings it locks, as a plan and a read-back check that build without it.
//! - [`guard`]: [`ForceGuard`], the one force/torque check of every reading wherever an
//!   actuator moves under load.
//! - [`open`]: the real driver of a rig entry (`None` for a simulated one).
//! - [`realtime`]: what the host offers a 1 kHz control loop (PREEMPT_RT, the
//!   priority and locked memory its user may take) and pinning a thread to a core.
//!
//! Traits are async (tokio) and object-safe, so the collector can build a rig of boxed
//! devices from the rig config, real and simulated alike. This crate must not depend
//! on the simulator (`softtouch-sim`, which implements these traits), a store or a
//! model: it is what a rig's hardware needs and nothing more.

pub mod arm;
pub mod ati_serial;
pub mod camera;
pub mod clock;
pub mod error;
pub mod force;
pub mod franka;
pub mod gripper;
pub mod guard;
pub mod hande;
pub mod netft;
pub mod open;
pub mod realtime;
#[cfg(feature = "v4l")]
pub mod v4l_camera;
pub mod v4l_controls;

pub use arm::{Arm, ArmState, PoseFeed};
pub use camera::{Camera, Frame};
pub use clock::{Clock, TokioClock};
pub use error::DeviceError;
pub use force::ForceSensor;
pub use gripper::{Gripper, GripperCommand, GripperStatus, ObjectStatus};
pub use guard::{ForceGuard, GuardTrip};
