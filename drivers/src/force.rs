//! The force/torque sensor that gives the labels.

use crate::error::DeviceError;
use async_trait::async_trait;
use softtouch_schemas::FtReading;

/// A streaming 6-axis force/torque sensor.
#[async_trait]
pub trait ForceSensor: Send {
    /// Start streaming (idempotent).
    async fn start(&mut self) -> Result<(), DeviceError>;

    /// Wait until at least one reading has arrived, then append every reading received
    /// so far to `out`, oldest first, each stamped on the injected clock. Returns how
    /// many were appended. A reading whose status word reports a fault is still
    /// delivered: the caller decides.
    async fn read(&mut self, out: &mut Vec<FtReading>) -> Result<usize, DeviceError>;

    /// Software bias (tare): readings from now on are relative to the current load.
    async fn bias(&mut self) -> Result<(), DeviceError>;

    /// Stop streaming.
    async fn stop(&mut self) -> Result<(), DeviceError>;

    /// Readings known lost on the link since start (sequence gaps, dropped datagrams).
    fn lost_readings(&self) -> u64;
}

#[async_trait]
impl<T: ForceSensor + ?Sized> ForceSensor for Box<T> {
    async fn start(&mut self) -> Result<(), DeviceError> {
        (**self).start().await
    }
    async fn read(&mut self, out: &mut Vec<FtReading>) -> Result<usize, DeviceError> {
        (**self).read(out).await
    }
    async fn bias(&mut self) -> Result<(), DeviceError> {
        (**self).bias().await
    }
    async fn stop(&mut self) -> Result<(), DeviceError> {
        (**self).stop().await
    }
    fn lost_readings(&self) -> u64 {
        (**self).lost_readings()
    }
}
