//! Real-time inference: one camera frame → wrench (and the latent mean), what the
//! grasp controller calls at the camera's 120 Hz.

use std::path::Path;
use std::sync::Arc;

use burn::prelude::*;
use softtouch_schemas::Wrench;

use crate::TrainError;
use crate::artifact::{ArtifactHeader, ModelArtifact};
use crate::labels::{WrenchLabel, wrench_from_label};
use crate::model::{FlatNet, InferenceNet};
use crate::preprocess::tare::{ImageTare, PreparedTare};
use crate::preprocess::{FingerTable, Fork};

/// One inference.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// `[Fx, Fy, Fz]` in N, `[Tx, Ty, Tz]` in N·mm (the label units), sensor frame;
    /// `None` for a VAE. [`Prediction::wrench`] gives it in SI.
    pub wrench_n_nmm: Option<WrenchLabel>,
    /// The latent mean μ (the SVAE's touch representation).
    pub latent_mean: Vec<f32>,
}

impl Prediction {
    /// The predicted wrench in SI (N, N·m), sensor frame, as the rest of softtouch
    /// holds wrenches; `None` for a VAE.
    pub fn wrench(&self) -> Option<Wrench> {
        self.wrench_n_nmm.as_ref().map(wrench_from_label)
    }
}

/// A loaded model on the CPU, ready for single images.
#[derive(Debug)]
pub struct Predictor {
    header: ArtifactHeader,
    /// The encoder and heads with batch norm folded in (what one image needs).
    net: InferenceNet,
    /// The net's stem and residual stages with their weights reordered once.
    blocks: FlatNet,
    device: Device,
    input: Vec<f32>,
    /// The model's colour threshold as a lookup table (built once, about 0.1 s).
    table: FingerTable,
    /// Preprocess a frame's halves, and run the larger convolutions' halves,
    /// through this ([`Self::split_frames`]).
    split: Option<Arc<dyn Fork>>,
    /// A medium's image tare, applied to each raw frame before preprocessing (the
    /// model then reads frames of another medium as the ones it learned from).
    tare: Option<ImageTare>,
    /// The tare laid out for the last frame size, and the corrected frame's buffer.
    prepared: Option<PreparedTare>,
    tared: Vec<u8>,
}

impl Predictor {
    /// Wraps an artifact; its weights stay on the device they were loaded on.
    pub fn new(artifact: ModelArtifact) -> Self {
        let device = artifact
            .net
            .devices()
            .first()
            .map_or_else(Device::flex, |d| d.clone().inner());
        let input = vec![0.0; artifact.header.config.preprocess.input_len()];
        let table = FingerTable::new(&artifact.header.config.preprocess);
        let net = InferenceNet::new(&artifact.net);
        let blocks = net.flat();
        Self {
            table,
            net,
            blocks,
            header: artifact.header,
            device,
            input,
            split: None,
            tare: None,
            prepared: None,
            tared: Vec::new(),
        }
    }

    /// Reads every raw frame through `tare` first (`None`, the default: as it comes).
    pub fn set_tare(&mut self, tare: Option<ImageTare>) {
        if tare != self.tare {
            self.prepared = None;
        }
        self.tare = tare;
    }

    /// The image tare frames are read through, if any.
    pub fn tare(&self) -> Option<&ImageTare> {
        self.tare.as_ref()
    }

    /// Preprocess each frame's halves, and run the halves of the model's larger
    /// convolutions, through `fork`, e.g. on two cores (`None`, the default: on the
    /// caller; the control-cycle benchmark measures one core). The same estimates.
    pub fn split_frames(&mut self, fork: Option<Arc<dyn Fork>>) {
        self.split = fork;
    }

    pub fn load(path: &Path) -> Result<Self, TrainError> {
        Ok(Self::new(ModelArtifact::load(
            path,
            &crate::backend::device()?,
        )?))
    }

    pub fn from_bytes(bytes: &[u8]) -> Result<Self, TrainError> {
        Ok(Self::new(ModelArtifact::from_bytes(
            bytes,
            &crate::backend::device()?,
        )?))
    }

    pub fn header(&self) -> &ArtifactHeader {
        &self.header
    }

    /// A raw RGB8 frame → prediction (preprocessing included).
    pub fn predict_rgb(
        &mut self,
        width: usize,
        height: usize,
        rgb: &[u8],
    ) -> Result<Prediction, TrainError> {
        let mut tared = std::mem::take(&mut self.tared);
        if let Err(e) = self.tare_into(width, height, rgb, &mut tared) {
            self.tared = tared;
            return Err(TrainError::Input(format!("the image tare: {e}")));
        }
        let rgb = if self.tare.is_some() { &tared[..] } else { rgb };
        let mut input = std::mem::take(&mut self.input);
        let result = self
            .table
            .apply_into_on(width, height, rgb, &mut input, self.split.as_deref())
            .and_then(|()| self.predict_preprocessed(&input));
        self.input = input;
        self.tared = tared;
        result
    }

    /// With a tare, `rgb` corrected into `out` (laid out again for a new frame size).
    fn tare_into(
        &mut self,
        width: usize,
        height: usize,
        rgb: &[u8],
        out: &mut Vec<u8>,
    ) -> Result<(), crate::TareError> {
        let Some(tare) = &self.tare else {
            return Ok(());
        };
        let prepared = match self.prepared.take() {
            Some(p) if p.size() == (width, height) => p,
            _ => PreparedTare::new(tare, width, height)?,
        };
        let done = prepared.apply_on(width, height, rgb, out, self.split.as_deref());
        self.prepared = Some(prepared);
        done
    }

    /// An already preprocessed image (`channels × size × size`) → prediction.
    pub fn predict_preprocessed(&self, image: &[f32]) -> Result<Prediction, TrainError> {
        let p = &self.header.config.preprocess;
        if image.len() != p.input_len() {
            return Err(TrainError::Input(format!(
                "preprocessed image holds {} values: the model needs {}",
                image.len(),
                p.input_len()
            )));
        }
        let x = Tensor::<4>::from_data(
            TensorData::new(image.to_vec(), [1, p.channels, p.size_px, p.size_px]),
            &self.device,
        );
        let (mean, wrench) = self
            .net
            .forward_one(&self.blocks, x, self.split.as_deref())?;
        let read = |t: Tensor<2>| {
            t.into_data()
                .as_slice::<f32>()
                .map(<[f32]>::to_vec)
                .map_err(|e| TrainError::Artifact(format!("reading the output: {e:?}")))
        };
        let latent_mean = read(mean)?;
        let wrench = match wrench {
            Some(w) => Some(self.header.norm.denormalise(&read(w)?)),
            None => None,
        };
        if let Some(w) = &wrench
            && w.iter().any(|v| !v.is_finite())
        {
            return Err(TrainError::NonFinite {
                epoch: 0,
                step: 0,
                detail: format!("inference produced {w:?}"),
            });
        }
        Ok(Prediction {
            wrench_n_nmm: wrench,
            latent_mean,
        })
    }
}

/// Latency of single-image inference (batch 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Latency {
    pub runs: usize,
    pub threads: usize,
    pub median_ms: f64,
    pub p95_ms: f64,
    pub mean_ms: f64,
}

/// Times `runs` single-image inferences of an already preprocessed image (after 10
/// warm-up runs) on a pool of `threads` threads (1: one core): the model alone.
pub fn measure_latency(
    predictor: &Predictor,
    image: &[f32],
    runs: usize,
    threads: usize,
) -> Result<Latency, TrainError> {
    time_calls(runs, threads, || {
        predictor.predict_preprocessed(image).map(drop)
    })
}

/// Times `runs` calls of [`Predictor::predict_rgb`] on a raw RGB8 camera frame: the
/// colour threshold, the squash and the model, which is what a controller pays per
/// frame.
pub fn measure_frame_latency(
    predictor: &mut Predictor,
    frame: (usize, usize, &[u8]),
    runs: usize,
    threads: usize,
) -> Result<Latency, TrainError> {
    let (width, height, rgb) = frame;
    time_calls(runs, threads, || {
        predictor.predict_rgb(width, height, rgb).map(drop)
    })
}

fn time_calls(
    runs: usize,
    threads: usize,
    mut call: impl FnMut() -> Result<(), TrainError> + Send,
) -> Result<Latency, TrainError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .map_err(|e| TrainError::Config(format!("cannot build a thread pool: {e}")))?;
    pool.install(|| {
        for _ in 0..10 {
            call()?;
        }
        let mut ms = Vec::with_capacity(runs.max(1));
        for _ in 0..runs.max(1) {
            let t = std::time::Instant::now();
            call()?;
            ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        ms.sort_by(f64::total_cmp);
        let at = |q: f64| ms[((ms.len() - 1) as f64 * q).round() as usize];
        Ok(Latency {
            runs: ms.len(),
            threads: threads.max(1),
            median_ms: at(0.5),
            p95_ms: at(0.95),
            mean_ms: ms.iter().sum::<f64>() / ms.len() as f64,
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_prediction_gives_its_wrench_in_si() {
        let p = Prediction {
            wrench_n_nmm: Some([1.0, -2.0, 0.5, 100.0, -250.0, 12.5]),
            latent_mean: vec![0.0; 4],
        };
        let w = p.wrench().expect("an SVAE prediction");
        let expect = Wrench::from_array([1.0, -2.0, 0.5, 0.1, -0.25, 0.0125]);
        for (got, want) in w.to_array().iter().zip(&expect.to_array()) {
            assert!((got - want).abs() < 1e-9, "{w:?}");
        }
        let vae = Prediction {
            wrench_n_nmm: None,
            ..p
        };
        assert!(vae.wrench().is_none());
    }
}
