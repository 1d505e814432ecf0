//! Predicted against true (the paper's Figure 2b): a stored model run on an evenly
//! spaced subset of its dataset's test split.
//!
//! Only the subset's frames are read and decoded (a 30 000-sample dataset's test split
//! is 1.3 GB of PNG); preprocessed images are shared between models of one dataset and
//! preprocessing.

use super::ReportError;
use super::data::{self, FrameRow};
use softtouch_schemas::FrameFormat;
use softtouch_trainer::labels::label_from_si;
use softtouch_trainer::{Example, FingerTable, ModelArtifact, Preprocess, WrenchLabel, evaluate};
use sqlx::SqlitePool;
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

/// Decodes a stored frame into RGB8 `(width, height, bytes)`.
fn decode(row: &FrameRow) -> Result<(usize, usize, Vec<u8>), String> {
    let format: FrameFormat = row.format.parse()?;
    let (w, h) = (
        usize::try_from(row.width).map_err(|_| format!("bad width {}", row.width))?,
        usize::try_from(row.height).map_err(|_| format!("bad height {}", row.height))?,
    );
    let image_format = match format {
        FrameFormat::Rgb8 => {
            if row.data.len() != w * h * 3 {
                return Err(format!(
                    "rgb8 frame holds {} bytes, {w}×{h} needs {}",
                    row.data.len(),
                    w * h * 3
                ));
            }
            return Ok((w, h, row.data.clone()));
        }
        FrameFormat::Png => image::ImageFormat::Png,
        FrameFormat::Jpeg => image::ImageFormat::Jpeg,
    };
    let img = image::load_from_memory_with_format(&row.data, image_format)
        .map_err(|e| format!("cannot decode its {} frame: {e}", row.format))?
        .into_rgb8();
    Ok((img.width() as usize, img.height() as usize, img.into_raw()))
}

/// Reads, decodes and preprocesses up to `max` evenly spaced test samples of a dataset.
async fn subset(
    pool: &SqlitePool,
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
    let one = |row: &FrameRow| -> Result<Example, ReportError> {
        let bad = |why: String| ReportError::Frame {
            run: row.run_id,
            index: row.sample_index,
            why,
        };
        let (w, h, rgb) = decode(row).map_err(bad)?;
        let image = table.apply(w, h, &rgb).map_err(|e| bad(e.to_string()))?;
        let label = label_from_si(
            [row.fx_n, row.fy_n, row.fz_n],
            [row.tx_nm, row.ty_nm, row.tz_nm],
        );
        Ok(Example { image, label })
    };
    // PNG decoding dominates: one chunk per core.
    let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    let per = rows.len().div_ceil(threads).max(1);
    let examples = std::thread::scope(|scope| {
        let handles: Vec<_> = rows
            .chunks(per)
            .map(|part| scope.spawn(move || part.iter().map(one).collect::<Result<Vec<_>, _>>()))
            .collect();
        let mut out = Vec::with_capacity(rows.len());
        for h in handles {
            match h.join() {
                Ok(part) => out.extend(part?),
                Err(_) => {
                    return Err(ReportError::Frame {
                        run: 0,
                        index: 0,
                        why: "a decoding thread panicked".into(),
                    });
                }
            }
        }
        Ok(out)
    })?;
    Ok((examples, members.len()))
}

/// Runs model `model_id` (trained on `dataset_id`) on up to `max` test samples.
/// `None` for a model that predicts no wrench (the VAE) or an empty test split.
pub(crate) async fn predict(
    pool: &SqlitePool,
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
    let (_, predicted) = evaluate(&artifact.net, &h.config, &h.norm, examples, &device);
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
