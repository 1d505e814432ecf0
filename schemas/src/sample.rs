//! Frames and collected samples.

use crate::geometry::ContactPose;
use crate::scene::Medium;
use crate::time::TimestampNs;
use crate::wrench::Wrench;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// How a frame's pixels are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrameFormat {
    /// Lossless PNG.
    Png,
    /// JPEG, as an MJPEG camera delivers it.
    Jpeg,
    /// Raw 8-bit RGB, row-major, no padding.
    Rgb8,
}

impl FrameFormat {
    /// Name used in storage.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Png => "png",
            Self::Jpeg => "jpeg",
            Self::Rgb8 => "rgb8",
        }
    }
}

impl FromStr for FrameFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "png" => Ok(Self::Png),
            "jpeg" => Ok(Self::Jpeg),
            "rgb8" => Ok(Self::Rgb8),
            other => Err(format!(
                "unknown frame format `{other}`, expected png, jpeg or rgb8"
            )),
        }
    }
}

/// What is known of a camera frame besides its pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameMeta {
    /// When the frame was exposed, on the injected clock.
    pub t: TimestampNs,
    /// The camera's frame counter; gaps mean dropped frames.
    pub sequence: u64,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixel encoding.
    pub format: FrameFormat,
}

/// Why a sample was rejected. Stored with the sample; a rejected sample is never a label.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RejectReason {
    /// Fewer readings in the window than the configured minimum.
    ShortWindow,
    /// Sequence gaps: readings lost inside the window.
    MissingReadings,
    /// The sensor's status word reported a fault inside the window.
    SensorFault,
    /// The wrench reached the sensor's range on some axis.
    Saturated,
    /// No frame arrived in time.
    FrameTimeout,
    /// The arm faulted (reflex) and retries ran out.
    ArmFault,
    /// The approach was aborted: contact force or torque over the rig's limit.
    ForceLimit,
    /// The force/torque stream stalled: no reading came in time to fill the window,
    /// or the approach guard saw none within `procedure.ft_stale_s`.
    StreamStalled,
    /// A reading held NaN or infinity: never a label, never stored as one.
    NonFinite,
    /// The frame's time is not covered by readings on both sides of it within
    /// `procedure.max_skew_s`: the label would come from another moment than the image.
    ClockSkew,
}

impl RejectReason {
    /// Name used in storage.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::ShortWindow => "short_window",
            Self::MissingReadings => "missing_readings",
            Self::SensorFault => "sensor_fault",
            Self::Saturated => "saturated",
            Self::FrameTimeout => "frame_timeout",
            Self::ArmFault => "arm_fault",
            Self::ForceLimit => "force_limit",
            Self::StreamStalled => "stream_stalled",
            Self::NonFinite => "non_finite",
            Self::ClockSkew => "clock_skew",
        }
    }
}

impl fmt::Display for RejectReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for RejectReason {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        [
            Self::ShortWindow,
            Self::MissingReadings,
            Self::SensorFault,
            Self::Saturated,
            Self::FrameTimeout,
            Self::ArmFault,
            Self::ForceLimit,
            Self::StreamStalled,
            Self::NonFinite,
            Self::ClockSkew,
        ]
        .into_iter()
        .find(|r| r.as_str() == s)
        .ok_or_else(|| format!("unknown reject reason `{s}`"))
    }
}

/// Whether a sample is a usable label.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SampleStatus {
    /// Accepted: frame and window passed every check.
    Ok,
    /// Rejected, with the reason.
    Rejected(RejectReason),
}

impl SampleStatus {
    /// `ok` or `rejected`, as stored.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::Rejected(_) => "rejected",
        }
    }

    /// The reason, for a rejected sample.
    #[must_use]
    pub const fn reject_reason(self) -> Option<RejectReason> {
        match self {
            Self::Ok => None,
            Self::Rejected(r) => Some(r),
        }
    }
}

/// One collected sample: the contact, the label window and the frame's timing.
/// The frame's pixels and the raw window travel beside it (see the store).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// Index within its run; pose `index` is a pure function of `(seed, index)`.
    pub index: u64,
    /// Name of the rod (from the scene) touched.
    pub rod: String,
    /// Medium the finger was in.
    pub medium: Medium,
    /// The pose commanded to the arm.
    pub commanded: ContactPose,
    /// The pose the arm reported once settled.
    pub measured: Option<ContactPose>,
    /// Mean wrench over the window, in the sensor frame.
    pub wrench_mean_in_sensor: Wrench,
    /// Per-axis standard deviation over the window.
    pub wrench_std_in_sensor: Wrench,
    /// Readings in the window.
    pub reading_count: u32,
    /// When the paired frame was exposed.
    pub frame_t: TimestampNs,
    /// First instant of the force/torque window.
    pub window_start: TimestampNs,
    /// Last instant of the force/torque window.
    pub window_end: TimestampNs,
    /// Frame time minus the time of the nearest reading, ns (signed).
    pub sync_skew_ns: i64,
    /// Accepted or rejected with a reason.
    pub status: SampleStatus,
    /// Attempts it took (1 = first try).
    pub attempts: u32,
}
