//! The models that read touch, and their training; it must know no SQL and no device
//! (data comes in as examples, models go out as artifacts).
//!
//! softtouch's learning half: the supervised variational autoencoder (SVAE) that reads
//! a 6-axis wrench from the soft finger's camera image, its VAE and ConvNet baselines,
//! the paper's loss and metrics, training with checkpoints and resume, the model
//! artifact, and real-time inference.
//!
//! The crate knows nothing of SQL or devices: the collector loads datasets and hands
//! [`Splits`] of preprocessed [`Example`]s in. Models run on burn's pure-Rust `flex`
//! CPU backend (see `trainer/README.md` for the measurements behind that choice).

pub mod artifact;
pub mod backend;
mod im2col;
pub mod infer;
pub mod kernels;
pub mod labels;
pub mod loss;
pub mod metrics;
pub mod model;
pub mod preprocess;
pub mod similarity;
pub mod train;

use std::path::Path;

pub use artifact::{ArtifactHeader, ModelArtifact, TrainingSummary};
pub use infer::{Latency, Prediction, Predictor, measure_frame_latency, measure_latency};
pub use labels::{AXES, LabelNorm, UNITS, WrenchLabel};
pub use metrics::Metrics;
pub use model::{ModelConfig, ModelKind};
pub use preprocess::augment::MediaAugment;
pub use preprocess::tare::{
    GainMap, ImageTare, PreparedTare, RestFrame, TareError, TareFit, TareGains, fit_image_tare,
};
pub use preprocess::{FingerTable, Fork, Preprocess, ScopedThread, Signal};
pub use train::{
    EpochReport, Example, InitFrom, Observer, Quiet, Splits, TrainConfig, Trained, evaluate,
    latent_means, train, train_from,
};

/// Everything that can go wrong in this crate.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("invalid model or training settings: {0}")]
    Config(String),
    #[error("bad input: {0}")]
    Input(String),
    /// The loss (or an output) stopped being finite: training is stopped rather than
    /// leaving a NaN model behind.
    #[error("training diverged at epoch {epoch}, step {step}: {detail}")]
    NonFinite {
        epoch: usize,
        step: usize,
        detail: String,
    },
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    #[error("model artifact: {0}")]
    Artifact(String),
    #[error("cannot {action} {path}: {source}")]
    Io {
        action: &'static str,
        path: String,
        source: std::io::Error,
    },
}

impl TrainError {
    pub(crate) fn io(action: &'static str, path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            action,
            path: path.display().to_string(),
            source,
        }
    }

    /// Names the file an artifact error came from.
    pub(crate) fn in_file(self, path: &Path) -> Self {
        match self {
            Self::Artifact(m) => Self::Artifact(format!("{}: {m}", path.display())),
            other => other,
        }
    }

    /// Whether the caller's input (settings, data, file) is at fault, rather than the run.
    pub fn is_bad_input(&self) -> bool {
        matches!(self, Self::Config(_) | Self::Input(_) | Self::Artifact(_))
    }
}

/// Writes `bytes` to `path` through a temporary file in the same folder, renamed into
/// place after an fsync: readers see the old file or the new one, never a torn one.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), TrainError> {
    use std::io::Write as _;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    let write = || -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    };
    write().map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        TrainError::io("write", path, e)
    })
}
