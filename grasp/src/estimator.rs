//! Camera frame → wrench on the finger, in the finger-base (sensor) frame, SI.

use softtouch_drivers::Frame;
use softtouch_schemas::{FrameFormat, Wrench};
use softtouch_trainer::Predictor;

use crate::GraspError;

/// What reads a force from a frame. The controller knows nothing else about the model.
pub trait ForceEstimator: Send {
    /// The wrench on the finger in its base frame (N, N·m), or `None` when the model
    /// predicts none (a VAE). A frame it cannot read is an error.
    fn estimate(&mut self, frame: &Frame) -> Result<Option<Wrench>, GraspError>;
}

impl ForceEstimator for Predictor {
    fn estimate(&mut self, frame: &Frame) -> Result<Option<Wrench>, GraspError> {
        let (w, h) = (frame.meta.width as usize, frame.meta.height as usize);
        let prediction = match frame.meta.format {
            FrameFormat::Rgb8 => self.predict_rgb(w, h, &frame.data),
            FrameFormat::Png | FrameFormat::Jpeg => {
                let rgb = image::load_from_memory(&frame.data)
                    .map_err(|e| {
                        GraspError::Estimate(format!(
                            "frame {} ({:?}) does not decode: {e}",
                            frame.meta.sequence, frame.meta.format
                        ))
                    })?
                    .to_rgb8();
                self.predict_rgb(rgb.width() as usize, rgb.height() as usize, rgb.as_raw())
            }
        };
        match prediction {
            Ok(p) => Ok(p.wrench()),
            // A non-finite output is an unusable estimate, not a broken loop: it holds.
            Err(softtouch_trainer::TrainError::NonFinite { .. }) => {
                Ok(Some(Wrench::from_array([f64::NAN; 6])))
            }
            Err(e) => Err(GraspError::Estimate(format!(
                "frame {}: {e}",
                frame.meta.sequence
            ))),
        }
    }
}

impl<T: ForceEstimator + ?Sized> ForceEstimator for Box<T> {
    fn estimate(&mut self, frame: &Frame) -> Result<Option<Wrench>, GraspError> {
        (**self).estimate(frame)
    }
}
