//! The finger's frames at a trial's moments (first contact, confirmation, lift, end),
//! kept as small PNGs with the trial's trace so that a reader sees what the finger saw.
//!
//! [`SnapCamera`] keeps the newest frame the loop read (one copy a cycle; the frames
//! themselves go on to the loop untouched); the trial takes it at each moment, and
//! the thumbnails are made after the trial, off the timed loop.

use std::sync::{Arc, Mutex, PoisonError};

use async_trait::async_trait;
use softtouch_drivers::{Camera, DeviceError, Frame};
use softtouch_schemas::{FrameFormat, TimestampNs};

/// The widest thumbnail, px (the height keeps the frame's aspect).
pub const SNAPSHOT_WIDTH_PX: u32 = 160;

/// A moment of a trial the viewer shows a frame of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Moment {
    /// The first cycle with contact: the true force above 0.05 N where the simulator
    /// gives one, else the estimate 0.1 N above the trial's first.
    Contact,
    /// The closed loop confirmed its force.
    Confirmed,
    /// The lift started.
    Lifted,
    /// The trial's last cycle.
    End,
}

impl Moment {
    /// As stored.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Contact => "contact",
            Self::Confirmed => "confirmed",
            Self::Lifted => "lifted",
            Self::End => "end",
        }
    }
}

/// A frame of a moment, as a PNG thumbnail.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Snapshot {
    /// Which moment.
    pub moment: Moment,
    /// When the frame was exposed, on the trial's clock (as its trace's times).
    pub t: TimestampNs,
    /// The thumbnail, PNG (at most [`SNAPSHOT_WIDTH_PX`] wide).
    pub png: Vec<u8>,
}

/// A camera that remembers the newest frame it delivered.
#[derive(Debug)]
pub struct SnapCamera<C> {
    inner: C,
    latest: Arc<Mutex<Option<Frame>>>,
}

impl<C> SnapCamera<C> {
    /// Wraps `inner`.
    pub fn new(inner: C) -> Self {
        Self {
            inner,
            latest: Arc::new(Mutex::new(None)),
        }
    }

    /// Where the newest frame is kept.
    #[must_use]
    pub fn latest(&self) -> Arc<Mutex<Option<Frame>>> {
        Arc::clone(&self.latest)
    }

    fn keep(&self, frame: &Frame) {
        *self.latest.lock().unwrap_or_else(PoisonError::into_inner) = Some(frame.clone());
    }
}

#[async_trait]
impl<C: Camera> Camera for SnapCamera<C> {
    async fn frame_after(&mut self, t: TimestampNs, timeout_ms: u64) -> Result<Frame, DeviceError> {
        let frame = self.inner.frame_after(t, timeout_ms).await?;
        self.keep(&frame);
        Ok(frame)
    }

    async fn latest_frame_after(
        &mut self,
        t: TimestampNs,
        timeout_ms: u64,
    ) -> Result<Frame, DeviceError> {
        let frame = self.inner.latest_frame_after(t, timeout_ms).await?;
        self.keep(&frame);
        Ok(frame)
    }

    fn dropped_frames(&self) -> u64 {
        self.inner.dropped_frames()
    }

    fn settings(&self) -> Option<String> {
        self.inner.settings()
    }
}

/// A frame as a PNG thumbnail at most [`SNAPSHOT_WIDTH_PX`] wide.
///
/// # Errors
/// The frame does not decode, or its size does not match its bytes.
pub fn thumbnail_png(frame: &Frame) -> Result<Vec<u8>, String> {
    let (w, h) = (frame.meta.width, frame.meta.height);
    let rgb = match frame.meta.format {
        FrameFormat::Rgb8 => image::RgbImage::from_raw(w, h, frame.data.clone())
            .ok_or_else(|| format!("{} bytes for a {w}×{h} RGB frame", frame.data.len()))?,
        FrameFormat::Png | FrameFormat::Jpeg => image::load_from_memory(&frame.data)
            .map_err(|e| format!("the frame does not decode: {e}"))?
            .to_rgb8(),
    };
    if rgb.width() == 0 || rgb.height() == 0 {
        return Err("an empty frame".into());
    }
    let tw = SNAPSHOT_WIDTH_PX.min(rgb.width());
    let th = ((u64::from(rgb.height()) * u64::from(tw)) / u64::from(rgb.width())).max(1) as u32;
    let small = image::imageops::thumbnail(&rgb, tw, th);
    let mut png = Vec::new();
    small
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .map_err(|e| format!("cannot encode the thumbnail: {e}"))?;
    Ok(png)
}

#[cfg(test)]
mod tests {
    use super::*;
    use softtouch_schemas::FrameMeta;

    fn frame(format: FrameFormat, w: u32, h: u32, data: Vec<u8>) -> Frame {
        Frame {
            meta: FrameMeta {
                t: TimestampNs(0),
                sequence: 0,
                width: w,
                height: h,
                format,
            },
            data,
        }
    }

    #[test]
    fn thumbnails_keep_the_aspect_and_bad_frames_are_errors() {
        let png = thumbnail_png(&frame(FrameFormat::Rgb8, 640, 480, vec![90; 640 * 480 * 3]))
            .expect("a thumbnail");
        let img = image::load_from_memory(&png).expect("a PNG");
        assert_eq!((img.width(), img.height()), (160, 120));
        // Smaller than the thumbnail: kept at its size.
        let png = thumbnail_png(&frame(FrameFormat::Rgb8, 4, 3, vec![0; 36])).expect("small");
        let img = image::load_from_memory(&png).expect("a PNG");
        assert_eq!((img.width(), img.height()), (4, 3));
        // A PNG frame decodes.
        let again = thumbnail_png(&frame(FrameFormat::Png, 4, 3, png)).expect("png frame");
        assert!(!again.is_empty());
        for bad in [
            frame(FrameFormat::Rgb8, 640, 480, vec![0; 10]),
            frame(FrameFormat::Rgb8, 0, 0, Vec::new()),
            frame(FrameFormat::Jpeg, 640, 480, b"not a jpeg".to_vec()),
        ] {
            assert!(thumbnail_png(&bad).is_err());
        }
    }
}
