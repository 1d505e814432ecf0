//! The camera inside the finger.

use crate::error::DeviceError;
use async_trait::async_trait;
use softtouch_schemas::{FrameMeta, TimestampNs};

/// One frame: its metadata and its pixels, encoded as `meta.format` says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Time, counter, size and encoding.
    pub meta: FrameMeta,
    /// The pixels (raw RGB8 rows, or an encoded PNG/JPEG).
    pub data: Vec<u8>,
}

/// A camera streaming at a fixed rate.
#[async_trait]
pub trait Camera: Send {
    /// The first frame exposed at or after `t`, waiting for it if need be; frames
    /// exposed earlier are discarded. A frame lost on the way is skipped (its sequence
    /// number shows the gap), and [`DeviceError::Timeout`] comes back if none arrives
    /// within `timeout_ms` of `t`.
    async fn frame_after(&mut self, t: TimestampNs, timeout_ms: u64) -> Result<Frame, DeviceError>;

    /// The newest frame exposed at or after `t`: when frames newer than `t` are
    /// already waiting, the newest of them (the others are skipped, not dropped);
    /// otherwise the next one, as [`Self::frame_after`] waits for it. A control loop
    /// acts on this, never on a queued frame older than the camera's latest: a loop
    /// slower than the camera would otherwise fall behind by up to the queue's length.
    /// Default: [`Self::frame_after`] (a camera that queues nothing).
    async fn latest_frame_after(
        &mut self,
        t: TimestampNs,
        timeout_ms: u64,
    ) -> Result<Frame, DeviceError> {
        self.frame_after(t, timeout_ms).await
    }

    /// Frames known dropped since the camera was opened.
    fn dropped_frames(&self) -> u64;

    /// The mode and image settings the device holds, for `rig check` (`None`: nothing
    /// to report, as for a simulated camera).
    fn settings(&self) -> Option<String> {
        None
    }
}

#[async_trait]
impl<T: Camera + ?Sized> Camera for Box<T> {
    async fn frame_after(&mut self, t: TimestampNs, timeout_ms: u64) -> Result<Frame, DeviceError> {
        (**self).frame_after(t, timeout_ms).await
    }
    async fn latest_frame_after(
        &mut self,
        t: TimestampNs,
        timeout_ms: u64,
    ) -> Result<Frame, DeviceError> {
        (**self).latest_frame_after(t, timeout_ms).await
    }
    fn dropped_frames(&self) -> u64 {
        (**self).dropped_frames()
    }
    fn settings(&self) -> Option<String> {
        (**self).settings()
    }
}

/// A camera lent for a while (one trial of a session that keeps it).
#[async_trait]
impl<T: Camera + ?Sized> Camera for &mut T {
    async fn frame_after(&mut self, t: TimestampNs, timeout_ms: u64) -> Result<Frame, DeviceError> {
        (**self).frame_after(t, timeout_ms).await
    }
    async fn latest_frame_after(
        &mut self,
        t: TimestampNs,
        timeout_ms: u64,
    ) -> Result<Frame, DeviceError> {
        (**self).latest_frame_after(t, timeout_ms).await
    }
    fn dropped_frames(&self) -> u64 {
        (**self).dropped_frames()
    }
    fn settings(&self) -> Option<String> {
        (**self).settings()
    }
}
