//! Predicted against true (the paper's Figure 2b): a stored model run on an evenly
//! spaced subset of its dataset's test split.
//!
//! Only the subset's frames are read and decoded (a 30 000-sample dataset's test split
//! is 1.3 GB of PNG); preprocessed images are shared between models of one dataset and
//! preprocessing.

use super::ReportError;
use super::data;
use super::data::ReadOnly;
use crate::models::ModelError;
use softtouch_trainer::{Example, FingerTable, ModelArtifact, Preprocess, WrenchLabel, evaluate};
use std::collections::HashMap;

/// A model's predictions on the subset, in N and N·mm.
#[derive(Debug, Clone)]
pub(crate) struct Predictions {
    /// Test samples in the subset.
    pub samples: usize,
    /// Of the test split's.
    pub of: usize,
    /// `(true, predicted)` per sample.
    pub pairs: Vec<(WrenchLabel, WrenchLabel)>,
}

/// Preprocessed subsets, per dataset and preprocessing.
#[derive(Debug, Default)]
pub(crate) struct Cache {
    subsets: HashMap<(i64, String), (Vec<Example>, usize)>,
}

/// Reads, decodes and preprocesses up to `max` evenly spaced test samples of a dataset.
async fn subset(
    pool: &ReadOnly,
    dataset_id: i64,
    preprocess: &Preprocess,
    max: usize,
) -> Result<(Vec<Example>, usize), ReportError> {
    let members = data::test_members(pool, dataset_id).await?;
    let mut rows = Vec::new();
    for i in super::svg::downsample_indices(members.len(), max) {
        if let Some(row) = data::frame(pool, members[i]).await? {
            rows.push(row);
        }
    }
    let table = FingerTable::new(preprocess);
    let examples = crate::models::preprocess_parallel(rows, &table, None)
        .map_err(|e| match e {
            ModelError::Frame { run, index, why } => ReportError::Frame { run, index, why },
            other => ReportError::Frame {
                run: 0,
                index: 0,
                why: other.to_string(),
            },
        })?
        .into_iter()
        .map(|(_, example)| example)
        .collect();
    Ok((examples, members.len()))
}

/// Runs model `model_id` (trained on `dataset_id`) on up to `max` test samples.
/// `None` for a model that predicts no wrench (the VAE) or an empty test split.
pub(crate) async fn predict(
    pool: &ReadOnly,
    cache: &mut Cache,
    model_id: i64,
    dataset_id: i64,
    max: usize,
) -> Result<Option<Predictions>, ReportError> {
    let device = softtouch_trainer::backend::device().map_err(|e| ReportError::Model {
        model_id,
        why: e.to_string(),
    })?;
    let bytes = data::artifact(pool, model_id).await?;
    let artifact = ModelArtifact::from_bytes(&bytes, &device).map_err(|e| ReportError::Model {
        model_id,
        why: e.to_string(),
    })?;
    let h = &artifact.header;
    if !h.config.kind.predicts_wrench() {
        return Ok(None);
    }
    let key = (
        dataset_id,
        serde_json::to_string(&h.config.preprocess).unwrap_or_default(),
    );
    if !cache.subsets.contains_key(&key) {
        let value = subset(pool, dataset_id, &h.config.preprocess, max).await?;
        cache.subsets.insert(key.clone(), value);
    }
    let Some((examples, of)) = cache.subsets.get(&key) else {
        return Ok(None);
    };
    if examples.is_empty() {
        return Ok(None);
    }
    let (_, predicted) =
        evaluate(&artifact.net, &h.config, &h.norm, examples, &device).map_err(|e| {
            ReportError::Model {
                model_id,
                why: e.to_string(),
            }
        })?;
    let Some(predicted) = predicted else {
        return Ok(None);
    };
    Ok(Some(Predictions {
        samples: examples.len(),
        of: *of,
        pairs: examples
            .iter()
            .zip(predicted)
            .map(|(e, p)| (e.label, p))
            .collect(),
    }))
}
