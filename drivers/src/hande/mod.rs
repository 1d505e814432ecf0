//! Robotiq Hand-E over Modbus RTU (115200 8N1, slave 9), through tokio-modbus.
//!
//! - [`regs`]: the register map, status decoding, fault classes, CRC-16 (pure).
//! - [`client`]: [`HandE`], a [`crate::Gripper`]: activation (rACT 0 then 1, poll
//!   until gSTA = 3), moves, status, major faults cleared by a new activation edge,
//!   at most 200 transactions per second paced on the injected clock, a timeout on
//!   every reply; exception replies are [`crate::DeviceError::Fault`], lost or
//!   corrupted replies [`crate::DeviceError::Timeout`].
//! - [`server`]: a simulated Hand-E (tokio-modbus `Service`) over any [`crate::Gripper`].

pub mod client;
pub mod regs;
pub mod server;

pub use client::{HandE, HandEConfig, HandEStats};
pub use server::{HandEService, serve_rtu, serve_serial};

use crate::error::DeviceError;

/// Open the gripper's serial port: 115200 8N1.
pub fn open_port(path: &str) -> Result<tokio_serial::SerialStream, DeviceError> {
    crate::ati_serial::open_port(path, regs::BAUD)
}
