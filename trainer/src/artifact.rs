//! The model artifact: one file holding the weights with everything needed to use
//! them — the model config (which includes the preprocessing parameters), the label
//! normalisation, and a summary of the training that made it.
//!
//! Layout: the 8-byte magic `STMODEL1`, the JSON header's length as a little-endian
//! u64, the JSON header, then burn's burnpack bytes of the weights.

use std::path::Path;

use burn::prelude::*;
use burn::store::ModuleRecord;
use serde::{Deserialize, Serialize};

use crate::TrainError;
use crate::labels::LabelNorm;
use crate::metrics::Metrics;
use crate::model::{ModelConfig, Net};
use crate::train::TrainConfig;

const MAGIC: &[u8; 8] = b"STMODEL1";
/// Version of the header's JSON layout.
pub const FORMAT_VERSION: u32 = 1;

/// How a model was trained, and how well it did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingSummary {
    pub train: TrainConfig,
    pub train_samples: usize,
    pub val_samples: usize,
    pub test_samples: usize,
    pub epochs_run: usize,
    pub best_epoch: usize,
    pub stopped_early: bool,
    #[serde(deserialize_with = "crate::metrics::null_as_nan::deserialize")]
    pub seconds: f64,
    #[serde(deserialize_with = "crate::metrics::null_as_nan::deserialize")]
    pub train_images_per_s: f64,
    pub val: Metrics,
    pub test: Metrics,
    /// The weights the training started from (fine-tuning), as [`crate::InitFrom`]
    /// labels them; absent for a training from the seed's initialisation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init_from: Option<String>,
}

/// The header of a model artifact.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArtifactHeader {
    pub format_version: u32,
    pub software_version: String,
    pub config: ModelConfig,
    pub norm: LabelNorm,
    pub training: Option<TrainingSummary>,
}

/// A model and its header, on any device.
#[derive(Debug)]
pub struct ModelArtifact {
    pub header: ArtifactHeader,
    pub net: Net,
}

impl ModelArtifact {
    /// Serialises to the artifact layout.
    pub fn to_bytes(&self) -> Result<Vec<u8>, TrainError> {
        let json = serde_json::to_vec(&self.header)
            .map_err(|e| TrainError::Artifact(format!("encoding the header: {e}")))?;
        let weights = encode_weights(&self.net).map_err(TrainError::Artifact)?;
        let mut out = Vec::with_capacity(16 + json.len() + weights.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&(json.len() as u64).to_le_bytes());
        out.extend_from_slice(&json);
        out.extend_from_slice(&weights);
        Ok(out)
    }

    /// Reads only the header (cheap: no weights are decoded).
    pub fn header_from_bytes(bytes: &[u8]) -> Result<(ArtifactHeader, &[u8]), TrainError> {
        if bytes.len() < 16 || &bytes[..8] != MAGIC {
            return Err(TrainError::Artifact(
                "not a softtouch model (it does not start with STMODEL1)".into(),
            ));
        }
        let mut len = [0u8; 8];
        len.copy_from_slice(&bytes[8..16]);
        let len = usize::try_from(u64::from_le_bytes(len)).unwrap_or(usize::MAX);
        let Some(json) = bytes.get(16..16usize.saturating_add(len)) else {
            return Err(TrainError::Artifact(format!(
                "truncated: the header claims {len} bytes, the file holds {}",
                bytes.len().saturating_sub(16)
            )));
        };
        let header: ArtifactHeader = serde_json::from_slice(json)
            .map_err(|e| TrainError::Artifact(format!("reading the header: {e}")))?;
        if header.format_version != FORMAT_VERSION {
            return Err(TrainError::Artifact(format!(
                "format version {} (this build reads {FORMAT_VERSION})",
                header.format_version
            )));
        }
        let problems = header.config.problems();
        if !problems.is_empty() {
            return Err(TrainError::Artifact(format!(
                "its config is unusable: {}",
                problems.join("; ")
            )));
        }
        Ok((header, &bytes[16 + len..]))
    }

    /// Parses an artifact and loads its weights onto `device`.
    pub fn from_bytes(bytes: &[u8], device: &Device) -> Result<Self, TrainError> {
        let (header, weights) = Self::header_from_bytes(bytes)?;
        let net = decode_weights(weights.to_vec(), &header.config, device)
            .map_err(TrainError::Artifact)?;
        Ok(Self { header, net })
    }

    /// A freshly initialised (untrained) model of `config` from `seed`, with identity
    /// label normalisation and no training summary: for timing inference and for
    /// tools that need a net of the right shape before any training.
    pub fn untrained(config: &ModelConfig, seed: u64) -> Result<Self, TrainError> {
        let problems = config.problems();
        if !problems.is_empty() {
            return Err(TrainError::Config(problems.join("; ")));
        }
        let device = crate::backend::device()?;
        Ok(Self {
            header: ArtifactHeader {
                format_version: FORMAT_VERSION,
                software_version: env!("CARGO_PKG_VERSION").to_owned(),
                config: *config,
                norm: LabelNorm {
                    mean: [0.0; 6],
                    std: [1.0; 6],
                },
                training: None,
            },
            net: crate::train::init_net(config, seed, &device),
        })
    }

    /// Writes the artifact atomically (a temporary file renamed into place).
    pub fn save(&self, path: &Path) -> Result<(), TrainError> {
        crate::write_atomic(path, &self.to_bytes()?)
    }

    pub fn load(path: &Path, device: &Device) -> Result<Self, TrainError> {
        let bytes = std::fs::read(path).map_err(|e| TrainError::io("read", path, e))?;
        Self::from_bytes(&bytes, device).map_err(|e| e.in_file(path))
    }
}

/// A module's weights as burnpack bytes (artifacts and checkpoints alike).
pub(crate) fn encode_weights(net: &Net) -> Result<Vec<u8>, String> {
    net.clone()
        .into_record()
        .into_bytes()
        .map(|b| b.to_vec())
        .map_err(|e| format!("encoding the weights: {e}"))
}

/// A model of `config` on `device` with the weights in `bytes`.
pub(crate) fn decode_weights(
    bytes: Vec<u8>,
    config: &ModelConfig,
    device: &Device,
) -> Result<Net, String> {
    let record = ModuleRecord::from_bytes(burn::tensor::Bytes::from_bytes_vec(bytes))
        .map_err(|e| format!("reading the weights: {e}"))?;
    // Loaded parameters replace the lazy ones before they draw anything, but the
    // lock keeps even that off the generator of a training being seeded.
    let _guard = crate::train::init_lock();
    config
        .init(device)
        .try_load_record(record)
        .map_err(|e| format!("the weights do not fit the config: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelConfig;

    /// serde_json writes NaN and infinity as `null`; a model whose metrics were not
    /// finite (a diverged run, an infinite prediction) still loads, with NaN there.
    #[test]
    fn a_model_with_non_finite_metrics_still_loads() {
        let mut artifact = ModelArtifact::untrained(&ModelConfig::default(), 1).expect("model");
        let t = [[0.0f32; 6], [1.0; 6]];
        let p = [[f32::INFINITY; 6], [f32::NAN; 6]];
        let mut test = Metrics::compute(Some(&p), &t, Some(f64::NAN)).expect("pairs");
        if let Some(r2) = test.r2.as_mut() {
            r2[0].r2 = f64::NAN;
        }
        test.r2_mean = Some(f64::NEG_INFINITY);
        assert!(test.rmse.is_some_and(|r| r.iter().any(|v| !v.is_finite())));
        assert!(
            test.force_error_by_range
                .iter()
                .any(|b| !b.error_std.is_finite())
        );
        artifact.header.training = Some(TrainingSummary {
            train: TrainConfig::default(),
            train_samples: 2,
            val_samples: 2,
            test_samples: 2,
            epochs_run: 1,
            best_epoch: 1,
            stopped_early: false,
            seconds: f64::INFINITY,
            train_images_per_s: f64::NAN,
            val: test.clone(),
            test,
            init_from: None,
        });
        let bytes = artifact.to_bytes().expect("encode");
        let (header, _) = ModelArtifact::header_from_bytes(&bytes).expect("loads");
        let summary = header.training.expect("summary");
        assert!(summary.seconds.is_nan() && summary.train_images_per_s.is_nan());
        let r2 = summary.test.r2.expect("r2");
        assert!(r2[0].r2.is_nan());
        assert!(
            summary
                .test
                .rmse
                .is_some_and(|r| r.iter().all(|v| v.is_nan()))
        );
        assert_eq!(summary.test.r2_mean, None, "null reads back as absent");
        let device = crate::backend::device().expect("device");
        ModelArtifact::from_bytes(&bytes, &device).expect("weights load too");
    }
}
