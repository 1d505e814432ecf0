//! The legacy ATI serial F/T controller (ASCII protocol, manual 9610-05-1001).
//!
//! - [`codec`]: commands and the record line `err, Fx..Tz` (counts); the parser never
//!   panics on any bytes.
//! - [`client`]: [`AtiSerial`], a [`crate::ForceSensor`] over any
//!   `AsyncRead + AsyncWrite` transport: `CD A`, `CD R`, `QS` streaming and its stop,
//!   `QR`, `SB` bias; a non-zero error field becomes a fault status (bit 31).
//! - [`peer`]: a simulated controller serving any [`crate::ForceSensor`].
//! - [`open_port`]: a real serial port (8N1) through tokio-serial without libudev.

pub mod client;
pub mod codec;
pub mod peer;

pub use client::{AtiSerial, AtiSerialConfig, AtiSerialStats};

use crate::error::DeviceError;

/// Open a serial port at `baud`, 8N1, no flow control.
pub fn open_port(path: &str, baud: u32) -> Result<tokio_serial::SerialStream, DeviceError> {
    use tokio_serial::SerialPortBuilderExt;
    tokio_serial::new(path, baud)
        .data_bits(tokio_serial::DataBits::Eight)
        .parity(tokio_serial::Parity::None)
        .stop_bits(tokio_serial::StopBits::One)
        .flow_control(tokio_serial::FlowControl::None)
        .open_native_async()
        .map_err(|e| DeviceError::Link {
            device: format!("serial {path}"),
            message: e.to_string(),
        })
}
