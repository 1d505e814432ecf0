//! Models in the store: loading a dataset's splits for the trainer, and recording the
//! trained models (artifact, dataset, hyper-parameters, metrics).
//!
//! The trainer knows nothing of SQL; this module is the bridge. Frames are decoded
//! and preprocessed on every core ([`load_splits`]).

use crate::store::{Members, NewModel, Store, StoreError};
use futures_util::TryStreamExt as _;
use softtouch_collector::dataset::{self, DatasetError};
use softtouch_schemas::FrameFormat;
use softtouch_trainer::labels::label_from_si;
use softtouch_trainer::{
    Example, FingerTable, ImageTare, MediaAugment, Preprocess, Splits, Trained,
};

pub use crate::store::ModelInfo;

/// A model operation failed.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The dataset side failed (no such dataset, a query).
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The database failed (boxed: a store error is large, and every verb's result
    /// carries this type).
    #[error(transparent)]
    Store(Box<StoreError>),
    /// A stored frame cannot be used.
    #[error("run {run}, sample {index}: {why}")]
    Frame {
        /// Run id.
        run: i64,
        /// Sample index.
        index: i64,
        /// What is wrong.
        why: String,
    },
    /// The name is taken.
    #[error("a model named `{0}` already exists in this database: choose another name")]
    Exists(String),
    /// No model of that name.
    #[error("no model named `{0}` in this database (see `softtouch models`)")]
    NotFound(String),
    /// A model that reads no force (a VAE) where a force estimate is needed.
    #[error(
        "model `{0}` is a VAE and reads no force: expected an svae or convnet model (see `softtouch models`)"
    )]
    NoForce(String),
    /// The trainer failed.
    #[error(transparent)]
    Train(#[from] softtouch_trainer::TrainError),
}

impl From<StoreError> for ModelError {
    fn from(e: StoreError) -> Self {
        Self::Store(Box::new(e))
    }
}

impl ModelError {
    /// Whether the user's input is at fault (exit code 2).
    #[must_use]
    pub fn is_bad_input(&self) -> bool {
        match self {
            Self::Dataset(e) => e.is_bad_input(),
            Self::Exists(_) | Self::NotFound(_) | Self::NoForce(_) => true,
            Self::Train(e) => e.is_bad_input(),
            Self::Store(_) | Self::Frame { .. } => false,
        }
    }
}

pub(crate) use crate::store::MemberRow;

/// Decodes a stored frame into RGB8.
fn decode(row: &MemberRow) -> Result<(usize, usize, Vec<u8>), String> {
    decode_stored(&row.format, row.width, row.height, &row.data)
}

/// Decodes a frame stored as `format` (`png`, `jpeg`, `rgb8`) into RGB8 `(width,
/// height, bytes)`.
pub(crate) fn decode_stored(
    format: &str,
    width: i64,
    height: i64,
    data: &[u8],
) -> Result<(usize, usize, Vec<u8>), String> {
    match format.parse::<FrameFormat>()? {
        FrameFormat::Rgb8 => {
            let (w, h) = (
                usize::try_from(width).map_err(|_| "bad width")?,
                usize::try_from(height).map_err(|_| "bad height")?,
            );
            if data.len() != w * h * 3 {
                return Err(format!(
                    "rgb8 frame holds {} bytes, {w}×{h} needs {}",
                    data.len(),
                    w * h * 3
                ));
            }
            Ok((w, h, data.to_vec()))
        }
        format @ (FrameFormat::Png | FrameFormat::Jpeg) => {
            let format = if format == FrameFormat::Png {
                image::ImageFormat::Png
            } else {
                image::ImageFormat::Jpeg
            };
            let img = image::load_from_memory_with_format(data, format)
                .map_err(|e| format!("cannot decode its {format:?} frame: {e}"))?
                .into_rgb8();
            let (w, h) = (img.width() as usize, img.height() as usize);
            Ok((w, h, img.into_raw()))
        }
    }
}

/// Loads dataset `name`'s frames and labels, preprocessed for the model, split as the
/// dataset says. `progress` is told the examples done so far.
pub async fn load_splits(
    store: &Store,
    name: &str,
    preprocess: &Preprocess,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<Splits, ModelError> {
    load_splits_where(store, name, preprocess, &|_| true, progress).await
}

/// [`load_splits`] of the members whose split (`train`, `val`, `test`) `keep` takes:
/// the others are read past, never decoded (`eval` of the test split preprocesses a
/// fifth of the dataset, not all of it).
pub async fn load_splits_where(
    store: &Store,
    name: &str,
    preprocess: &Preprocess,
    keep: &(dyn Fn(&str) -> bool + Sync),
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<Splits, ModelError> {
    let info = dataset::get(store, name).await?;
    let total = u64::try_from(info.sample_count).unwrap_or(0);
    let mut rows = store.member_rows(info.dataset_id, Members::All);
    // The colour threshold as a lookup, built once for the whole dataset.
    let table = FingerTable::new(preprocess);
    let mut splits = Splits::default();
    let mut chunk = Vec::with_capacity(256);
    let mut done = 0u64;
    loop {
        let row = rows.try_next().await?;
        let last = row.is_none();
        if let Some(row) = row {
            if keep(&row.split) {
                chunk.push(row);
            } else {
                done += 1;
            }
        }
        if chunk.len() >= 256 || (last && !chunk.is_empty()) {
            let rows = std::mem::take(&mut chunk);
            done += rows.len() as u64;
            for (split, example) in preprocess_parallel(rows, &table, None)? {
                match split.as_str() {
                    "train" => splits.train.push(example),
                    "val" => splits.val.push(example),
                    _ => splits.test.push(example),
                }
            }
            progress(done, total);
        }
        if last {
            break;
        }
    }
    Ok(splits)
}

/// Augmented copies of dataset `name`'s training frames (`augment.copies` of each, see
/// [`MediaAugment`]), preprocessed, for a training to learn beside the frames
/// themselves. `progress` is told the frames done so far.
pub async fn augmented_train(
    store: &Store,
    name: &str,
    preprocess: &Preprocess,
    augment: &MediaAugment,
    progress: &(dyn Fn(u64, u64) + Sync),
) -> Result<Vec<Example>, ModelError> {
    let info = dataset::get(store, name).await?;
    let total = u64::try_from(info.sample_count).unwrap_or(0);
    let mut rows = store.member_rows(info.dataset_id, Members::NotTest);
    let table = FingerTable::new(preprocess);
    let (mut out, mut chunk, mut done) = (Vec::new(), Vec::with_capacity(256), 0u64);
    loop {
        let row = rows.try_next().await?;
        let last = row.is_none();
        if let Some(row) = row.filter(|r| r.split == "train") {
            chunk.push(row);
        }
        if chunk.len() >= 256 || (last && !chunk.is_empty()) {
            let rows = std::mem::take(&mut chunk);
            done += rows.len() as u64;
            for copy in 0..augment.copies {
                let one = |row: &MemberRow| -> Result<Example, ModelError> {
                    let (w, h, rgb) = decode(row).map_err(|why| ModelError::Frame {
                        run: row.run_id,
                        index: row.sample_index,
                        why,
                    })?;
                    let rgb = augment.frame((row.run_id, row.sample_index), copy, w, h, &rgb);
                    let image = table.apply(w, h, &rgb)?;
                    let label = label_from_si(row.wrench.force_n(), row.wrench.torque_nm());
                    Ok(Example { image, label })
                };
                let part: Result<Vec<Example>, ModelError> = std::thread::scope(|scope| {
                    let per = rows.len().div_ceil(2).max(1);
                    let handles: Vec<_> = rows
                        .chunks(per)
                        .map(|p| {
                            scope.spawn(move || p.iter().map(one).collect::<Result<Vec<_>, _>>())
                        })
                        .collect();
                    let mut all = Vec::new();
                    for h in handles {
                        all.extend(h.join().map_err(|_| ModelError::Frame {
                            run: 0,
                            index: 0,
                            why: "an augmentation thread panicked".into(),
                        })??);
                    }
                    Ok(all)
                });
                out.extend(part?);
            }
            progress(done, total);
        }
        if last {
            return Ok(out);
        }
    }
}

/// Dataset `name`'s first test frame as stored, decoded to RGB8 `(width, height,
/// bytes)`: a real camera frame to time inference on, preprocessing included.
pub async fn first_test_frame(
    store: &Store,
    name: &str,
) -> Result<(usize, usize, Vec<u8>), ModelError> {
    let info = dataset::get(store, name).await?;
    let row = store.first_test_member(info.dataset_id).await?;
    let Some(row) = row else {
        return Err(ModelError::Frame {
            run: 0,
            index: 0,
            why: format!("dataset `{name}` holds no frames"),
        });
    };
    decode(&row).map_err(|why| ModelError::Frame {
        run: row.run_id,
        index: row.sample_index,
        why,
    })
}

/// Decodes and preprocesses rows on every core, keeping their order. Training and the
/// report's predicted-against-true figures both read frames through here.
pub(crate) fn preprocess_parallel(
    rows: Vec<MemberRow>,
    table: &FingerTable,
    tare: Option<&ImageTare>,
) -> Result<Vec<(String, Example)>, ModelError> {
    let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    let per = rows.len().div_ceil(threads).max(1);
    let one = |row: &MemberRow| -> Result<(String, Example), ModelError> {
        let frame_err = |why: String| ModelError::Frame {
            run: row.run_id,
            index: row.sample_index,
            why,
        };
        let (w, h, mut rgb) = decode(row).map_err(frame_err)?;
        if let Some(t) = tare {
            rgb = t.apply(w, h, &rgb).map_err(|e| frame_err(e.to_string()))?;
        }
        let image = table.apply(w, h, &rgb)?;
        let label = label_from_si(row.wrench.force_n(), row.wrench.torque_nm());
        if label.iter().any(|v| !v.is_finite()) {
            return Err(frame_err(format!("its label is not finite: {label:?}")));
        }
        Ok((row.split.clone(), Example { image, label }))
    };
    std::thread::scope(|scope| {
        let handles: Vec<_> = rows
            .chunks(per)
            .map(|part| scope.spawn(move || part.iter().map(one).collect::<Result<Vec<_>, _>>()))
            .collect();
        let mut out = Vec::with_capacity(rows.len());
        for h in handles {
            match h.join() {
                Ok(part) => out.extend(part?),
                Err(_) => {
                    return Err(ModelError::Frame {
                        run: 0,
                        index: 0,
                        why: "a preprocessing thread panicked".into(),
                    });
                }
            }
        }
        Ok(out)
    })
}

/// Records a trained model. Fails if the name is taken.
pub async fn record(
    store: &Store,
    name: &str,
    dataset_name: &str,
    trained: &Trained,
) -> Result<i64, ModelError> {
    dataset::validate_name(name)?;
    if find(store, name).await?.is_some() {
        return Err(ModelError::Exists(name.to_owned()));
    }
    let info = dataset::get(store, dataset_name).await?;
    let header = &trained.artifact.header;
    let json = |v: serde_json::Result<String>| {
        v.map_err(|e| ModelError::Train(softtouch_trainer::TrainError::Artifact(e.to_string())))
    };
    let config_json = json(serde_json::to_string(&header.config))?;
    let summary = header.training.as_ref();
    let train_json = json(serde_json::to_string(&summary.map(|s| s.train)))?;
    let metrics_json = json(serde_json::to_string(&summary))?;
    let history_json = json(serde_json::to_string(&trained.history))?;
    let artifact = trained.artifact.to_bytes()?;
    Ok(store
        .insert_model(&NewModel {
            name,
            dataset_id: info.dataset_id,
            dataset_name: &info.name,
            kind: header.config.kind.name(),
            config_json: &config_json,
            train_json: &train_json,
            metrics_json: &metrics_json,
            history_json: &history_json,
            test_r2_mean: summary.and_then(|s| s.test.r2_mean),
            test_image_mse: summary.and_then(|s| s.test.image_mse),
            artifact: &artifact,
            software_version: env!("CARGO_PKG_VERSION"),
        })
        .await?)
}

/// The model called `name`, if any.
pub async fn find(store: &Store, name: &str) -> Result<Option<ModelInfo>, ModelError> {
    Ok(store.model(name).await?)
}

/// Every model, oldest first.
pub async fn list(store: &Store) -> Result<Vec<ModelInfo>, ModelError> {
    Ok(store.models().await?)
}

/// A stored model's artifact for a verb that acts on its force estimate (`live`, the
/// grasp verbs): a VAE, which reads no force, is refused up front, before any device
/// opens, rather than holding the loop on a missing estimate forever.
///
/// # Errors
/// No such model, a VAE, or a query failure.
pub async fn force_artifact(store: &Store, name: &str) -> Result<Vec<u8>, ModelError> {
    match store.model_artifact(name).await? {
        None => Err(ModelError::NotFound(name.to_owned())),
        Some((_, kind)) if kind == "vae" => Err(ModelError::NoForce(name.to_owned())),
        Some((artifact, _)) => Ok(artifact),
    }
}

/// The artifact bytes of model `name`.
pub async fn artifact(store: &Store, name: &str) -> Result<Vec<u8>, ModelError> {
    store
        .model_artifact(name)
        .await?
        .map(|(a, _)| a)
        .ok_or_else(|| ModelError::NotFound(name.to_owned()))
}
