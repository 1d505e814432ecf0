//! Errors of every driver.
//!
//! The first question after a failure is "did the device say no, or did we lose it?":
//! a reflex or a gripper fault is handled by recovery, a dead link by reconnecting or
//! stopping. The variants keep the two apart.

/// A device operation failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DeviceError {
    /// The device answered, and refused or reported a fault (reflex, gripper fault,
    /// sensor status fault). `code` is the device's own code where it has one.
    #[error("{device} reported a fault{}: {message}", code.map(|c| format!(" (code 0x{c:X})")).unwrap_or_default())]
    Fault {
        /// Which device.
        device: String,
        /// The device's fault code, if any.
        code: Option<u32>,
        /// What it said.
        message: String,
    },
    /// The link to the device failed (socket, serial port, USB): nothing reliable came back.
    #[error("{device}: link failed: {message}")]
    Link {
        /// Which device.
        device: String,
        /// What failed.
        message: String,
    },
    /// The device stopped answering.
    #[error("{device}: no answer within {timeout_ms} ms")]
    Timeout {
        /// Which device.
        device: String,
        /// How long we waited.
        timeout_ms: u64,
    },
    /// Bytes arrived that do not follow the protocol (garbled, truncated, wrong header).
    #[error("{device}: protocol error: {message}")]
    Protocol {
        /// Which device.
        device: String,
        /// What was wrong with the bytes.
        message: String,
    },
    /// The command was not sent: it is unsafe or invalid (e.g. outside the workspace).
    #[error("{device}: command rejected before sending: {message}")]
    InvalidCommand {
        /// Which device.
        device: String,
        /// Why.
        message: String,
    },
}

impl DeviceError {
    /// The device itself reported a fault (recoverable by the device's own recovery).
    #[must_use]
    pub const fn is_fault(&self) -> bool {
        matches!(self, Self::Fault { .. })
    }

    /// The link failed, timed out or carried garbage.
    #[must_use]
    pub const fn is_link(&self) -> bool {
        matches!(
            self,
            Self::Link { .. } | Self::Timeout { .. } | Self::Protocol { .. }
        )
    }
}
