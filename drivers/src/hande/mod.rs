//! Robotiq Hand-E over Modbus RTU (115200 8N1, slave 9), through tokio-modbus.
//!
//! - [`regs`]: the register map, status decoding, fault classes, CRC-16 (pure).
//! - [`client`]: [`HandE`], a [`crate::Gripper`]: activation (rACT 0 then 1, poll
//!   until gSTA = 3), moves, status, major faults cleared by a new activation edge,
//!   at most 200 transactions per second paced on the injected clock, a timeout on
//!   every reply; exception replies are [`crate::DeviceError::Fault`], lost or
//!   corrupted replies [`crate::DeviceError::Timeout`]; after a timeout (or a reply
//!   that does not match its request) the port is flushed before the next request,
//!   so that a late reply is never taken for the next one's.
//! - [`link`]: the transport wrapper that does that flush.
//! - [`server`]: a simulated Hand-E (tokio-modbus `Service`) over any [`crate::Gripper`].

pub mod client;
pub mod link;
pub mod regs;
pub mod server;

pub use client::{HandE, HandEConfig, HandEStats};
pub use server::{HandEService, serve_rtu, serve_serial};

use crate::error::DeviceError;

/// Open the gripper's serial port: 115200 8N1.
pub fn open_port(path: &str) -> Result<tokio_serial::SerialStream, DeviceError> {
    crate::ati_serial::open_port(path, regs::BAUD)
}

/// The USB-serial adapter's latency timer behind `port`, ms: how long an FTDI adapter
/// holds received bytes before passing them on (16 by default; every Modbus reply
/// waits that long). `None` when the port is not a USB-serial adapter with such a
/// timer (a pty, a built-in UART) or cannot be resolved.
#[must_use]
pub fn latency_timer_ms(port: &str) -> Option<u32> {
    latency_timer_ms_in(std::path::Path::new("/sys/bus/usb-serial/devices"), port)
}

/// [`latency_timer_ms`] under another sysfs folder (tests).
#[must_use]
pub fn latency_timer_ms_in(usb_serial_devices: &std::path::Path, port: &str) -> Option<u32> {
    // `/dev/serial/by-id/...` names are links to `/dev/ttyUSBn`.
    let device = std::fs::canonicalize(port).unwrap_or_else(|_| port.into());
    let name = device.file_name()?;
    let text = std::fs::read_to_string(usb_serial_devices.join(name).join("latency_timer")).ok()?;
    text.trim().parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_latency_timer_is_read_through_by_id_links_and_absent_elsewhere() {
        let root = tempfile::tempdir().expect("tmp");
        let sys = root.path().join("sys");
        std::fs::create_dir_all(sys.join("ttyUSB1")).expect("mkdir");
        std::fs::write(sys.join("ttyUSB1/latency_timer"), "16\n").expect("write");
        let dev = root.path().join("ttyUSB1");
        std::fs::write(&dev, "").expect("device stand-in");
        let by_id = root.path().join("usb-FTDI_USB_RS485-if00-port0");
        std::os::unix::fs::symlink(&dev, &by_id).expect("link");
        let path = |p: &std::path::Path| p.to_string_lossy().into_owned();
        assert_eq!(latency_timer_ms_in(&sys, &path(&dev)), Some(16));
        assert_eq!(latency_timer_ms_in(&sys, &path(&by_id)), Some(16));
        // Not a USB adapter (a pty), a missing port, garbage in the file.
        assert_eq!(latency_timer_ms_in(&sys, "/dev/pts/3"), None);
        assert_eq!(latency_timer_ms_in(&sys, ""), None);
        std::fs::write(sys.join("ttyUSB1/latency_timer"), "fast").expect("write");
        assert_eq!(latency_timer_ms_in(&sys, &path(&dev)), None);
    }
}
