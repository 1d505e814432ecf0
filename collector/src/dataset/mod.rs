//! Curated datasets: named, fixed selections of samples from one or more runs, split
//! train / val / test, with statistics, an export that Python opens directly, and an
//! import of such exports (and of the paper's published layout).
//!
//! # Tables (migration `20261121010000_datasets.sql`)
//! - `datasets`: name, definition (runs, filters, ratio, seed) as JSON, seed, ratio,
//!   sample count, software and schema version, creation time.
//! - `dataset_members`: `(dataset, position) → (run, sample_index, split)`. The member
//!   rows are the truth: a dataset never changes when filters or code change later.
//! - `run_imports`: where an imported run came from.
//!
//! # Selection
//! Samples of the given runs in `(run, index)` order that pass every filter
//! ([`Filters`]); by default only accepted samples. A sample without a frame (rejected
//! before any frame came) is never selected: it has no image to learn from. The split rule is in [`split`].
//!
//! # Layout
//! - [`split`]: split counts and seeded assignment.
//! - [`export`]: `images/`, `labels.csv`, `manifest.json` (their format: `manifest.rs`).
//! - [`import`]: the export layout back into the store, and the paper's `data_frame.csv`.
//! - [`stats`]: counts, per-axis statistics, histograms.

mod csv;
pub mod export;
pub mod import;
mod manifest;
pub mod split;
pub mod stats;

pub use split::{Split, SplitError, SplitRatio};

use crate::store::datasets::DatasetRow;
use crate::store::{RunId, Store, StoreError};
use futures_util::TryStreamExt as _;
use serde::{Deserialize, Serialize};
use softtouch_schemas::Medium;
use std::path::PathBuf;

/// Version of the export layout written by [`export`] and read by [`import`].
pub const EXPORT_FORMAT_VERSION: u32 = 1;

/// A dataset operation failed.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// The store failed (or has no such run).
    #[error(transparent)]
    Store(#[from] StoreError),
    /// A query failed.
    #[error("database error while {doing}: {source}")]
    Query {
        /// What we were doing.
        doing: &'static str,
        /// Why.
        #[source]
        source: sqlx::Error,
    },
    /// The name is taken.
    #[error("a dataset named `{0}` already exists in this database: choose another name")]
    Exists(String),
    /// No dataset of that name.
    #[error("no dataset named `{0}` in this database (see `softtouch dataset list`)")]
    NoSuchDataset(String),
    /// A run named in the definition is not there.
    #[error("no run {0} in this database (see `softtouch runs`)")]
    NoSuchRun(RunId),
    /// The selection cannot be split as asked.
    #[error(transparent)]
    Split(#[from] SplitError),
    /// Bad input that is not about a file's content (a name, a filter, a folder).
    #[error("{0}")]
    Invalid(String),
    /// A file being imported is malformed; `line` and `column` are 1-based, 0 if unknown.
    #[error("{}: {message}", location(path, *line, *column))]
    Malformed {
        /// The file.
        path: PathBuf,
        /// Line, from 1 (0: the whole file).
        line: usize,
        /// Column (field number), from 1 (0: the whole line).
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// Reading or writing a file failed.
    #[error("cannot {doing} {path}: {source}")]
    Io {
        /// What we were doing.
        doing: &'static str,
        /// The path.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// Decoding or encoding an image failed.
    #[error("image {what}: {why}")]
    Image {
        /// Which image.
        what: String,
        /// Why.
        why: String,
    },
    /// Drawing a plot failed.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
}

fn location(path: &std::path::Path, line: usize, column: usize) -> String {
    match (line, column) {
        (0, _) => path.display().to_string(),
        (l, 0) => format!("{}: line {l}", path.display()),
        (l, c) => format!("{}: line {l}, column {c}", path.display()),
    }
}

impl DatasetError {
    /// Whether the user's input is at fault (exit code 2) rather than the machine.
    #[must_use]
    pub fn is_bad_input(&self) -> bool {
        match self {
            Self::Store(e) => matches!(e, StoreError::NoSuchRun(_)),
            Self::Exists(_)
            | Self::NoSuchDataset(_)
            | Self::NoSuchRun(_)
            | Self::Split(_)
            | Self::Invalid(_)
            | Self::Malformed { .. } => true,
            // A stored frame that does not decode: the database's fault, not the user's.
            // (Import reports undecodable files as `Malformed`.)
            Self::Image { .. } | Self::Query { .. } | Self::Io { .. } | Self::Plot(_) => false,
        }
    }

    pub(crate) fn io(
        doing: &'static str,
        path: &std::path::Path,
    ) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.to_owned();
        move |source| Self::Io {
            doing,
            path,
            source,
        }
    }
}

pub(crate) fn query_err(doing: &'static str) -> impl FnOnce(sqlx::Error) -> DatasetError {
    move |source| DatasetError::Query { doing, source }
}

/// Which samples of the runs a dataset takes. Every filter that is set must pass.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Filters {
    /// Take rejected samples too (default: accepted samples only).
    #[serde(default)]
    pub include_rejected: bool,
    /// Only this medium.
    #[serde(default)]
    pub medium: Option<Medium>,
    /// Only these rods (empty: all).
    #[serde(default)]
    pub rods: Vec<String>,
    /// Largest |Fx|, |Fy|, |Fz| allowed, N.
    #[serde(default)]
    pub max_force_n: Option<f64>,
    /// Largest |Tx|, |Ty|, |Tz| allowed, N·mm.
    #[serde(default)]
    pub max_torque_nmm: Option<f64>,
    /// Largest |frame time − nearest reading time| allowed, ms.
    #[serde(default)]
    pub max_skew_ms: Option<f64>,
    /// Fewest force/torque readings in the window.
    #[serde(default)]
    pub min_readings: Option<u32>,
}

impl Filters {
    fn validate(&self) -> Result<(), DatasetError> {
        for (name, v) in [
            ("--max-force-n", self.max_force_n),
            ("--max-torque-nmm", self.max_torque_nmm),
            ("--max-skew-ms", self.max_skew_ms),
        ] {
            if let Some(v) = v
                && !(v.is_finite() && v >= 0.0)
            {
                return Err(DatasetError::Invalid(format!(
                    "{name} must be a finite number ≥ 0, got {v}"
                )));
            }
        }
        if self.rods.iter().any(String::is_empty) {
            return Err(DatasetError::Invalid("--rod must not be empty".into()));
        }
        Ok(())
    }

    fn accepts(&self, s: &Candidate) -> bool {
        let force = s.wrench.force_n();
        let torque_nmm = s.wrench.torque_nm().map(|t| t * 1000.0);
        (self.include_rejected || s.status == "ok")
            && self.medium.is_none_or(|m| s.medium == m.as_str())
            && (self.rods.is_empty() || self.rods.contains(&s.rod))
            && self
                .max_force_n
                .is_none_or(|max| force.iter().all(|f| f.abs() <= max))
            && self
                .max_torque_nmm
                .is_none_or(|max| torque_nmm.iter().all(|t| t.abs() <= max))
            && self
                .max_skew_ms
                .is_none_or(|max| (s.sync_skew_ns as f64).abs() <= max * 1e6)
            && self
                .min_readings
                .is_none_or(|min| s.reading_count >= i64::from(min))
    }
}

/// What a dataset was made from: stored as JSON with it and written into exports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Definition {
    /// The runs, ascending.
    pub runs: Vec<RunId>,
    /// The filters.
    pub filters: Filters,
    /// `train:val:test`.
    pub split: String,
    /// Seed of the split.
    pub seed: u64,
    /// The split algorithm (see [`split`]).
    pub algorithm: String,
    /// For an imported dataset: where it came from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imported_from: Option<serde_json::Value>,
}

/// The split algorithm this build uses.
pub const SPLIT_ALGORITHM: &str = "split-v1";

/// What to create.
#[derive(Debug, Clone)]
pub struct NewDataset {
    /// Unique name.
    pub name: String,
    /// Runs to draw from (order and repeats do not matter).
    pub runs: Vec<RunId>,
    /// Which samples.
    pub filters: Filters,
    /// Ratio of the splits.
    pub ratio: SplitRatio,
    /// Seed of the split.
    pub seed: u64,
}

/// A stored dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct DatasetInfo {
    /// Row id.
    pub dataset_id: i64,
    /// Name.
    pub name: String,
    /// Definition.
    pub definition: Definition,
    /// Samples.
    pub sample_count: i64,
    /// Samples per split (train, val, test).
    pub split_counts: [i64; 3],
    /// Version of the software that created it.
    pub software_version: String,
    /// Schema version it was created under.
    pub schema_version: i64,
    /// When (UTC).
    pub created_at: String,
}

pub(crate) use crate::store::datasets::Candidate;

/// Check a dataset name: non-empty, at most 100 characters, letters, digits, `-_.`,
/// not starting with `.` (it names files: `NAME-histograms.png`).
pub fn validate_name(name: &str) -> Result<(), DatasetError> {
    let ok = !name.is_empty()
        && name.chars().count() <= 100
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | '.'));
    if ok {
        Ok(())
    } else {
        Err(DatasetError::Invalid(format!(
            "bad dataset name `{name}`: use 1 to 100 letters, digits, `-`, `_` or `.`, not starting with `.`"
        )))
    }
}

/// Create a dataset: select, split, store. Returns its info.
pub async fn create(store: &Store, new: &NewDataset) -> Result<DatasetInfo, DatasetError> {
    validate_name(&new.name)?;
    new.filters.validate()?;
    let mut runs = new.runs.clone();
    runs.sort_unstable();
    runs.dedup();
    if runs.is_empty() {
        return Err(DatasetError::Invalid(
            "no runs given (--runs 1,2,...)".into(),
        ));
    }
    if find(store, &new.name).await?.is_some() {
        return Err(DatasetError::Exists(new.name.clone()));
    }
    for &run in &runs {
        if !store.run_exists(run).await? {
            return Err(DatasetError::NoSuchRun(run));
        }
    }

    let mut selected: Vec<(i64, i64)> = Vec::new();
    for &run in &runs {
        let mut rows = store.candidates(run);
        while let Some(c) = rows.try_next().await? {
            if new.filters.accepts(&c) {
                selected.push((c.run_id, c.sample_index));
            }
        }
    }
    let splits = split::assign(selected.len(), new.ratio, new.seed)?;
    let definition = Definition {
        runs,
        filters: new.filters.clone(),
        split: new.ratio.to_string(),
        seed: new.seed,
        algorithm: SPLIT_ALGORITHM.into(),
        imported_from: None,
    };
    let members: Vec<(i64, i64, Split)> = selected
        .iter()
        .zip(&splits)
        .map(|(&(r, i), &s)| (r, i, s))
        .collect();
    let mut tx = store
        .pool()
        .begin()
        .await
        .map_err(query_err("starting a transaction"))?;
    insert_dataset(&mut tx, &new.name, &definition, &members).await?;
    tx.commit()
        .await
        .map_err(query_err("committing a dataset"))?;
    find(store, &new.name)
        .await?
        .ok_or_else(|| DatasetError::NoSuchDataset(new.name.clone()))
}

/// Insert a dataset and its members (position = order of `members`) in a transaction.
pub(crate) async fn insert_dataset(
    tx: &mut sqlx::AnyConnection,
    name: &str,
    definition: &Definition,
    members: &[(i64, i64, Split)],
) -> Result<i64, DatasetError> {
    let json = serde_json::to_string(definition)
        .map_err(|e| DatasetError::Invalid(format!("cannot encode the definition: {e}")))?;
    let members: Vec<(i64, i64, &str)> = members
        .iter()
        .map(|&(run, index, split)| (run, index, split.as_str()))
        .collect();
    let new = crate::store::datasets::NewDataset {
        name,
        definition_json: &json,
        seed: definition.seed,
        split_ratio: &definition.split,
        members: &members,
    };
    crate::store::datasets::insert_dataset(tx, &new)
        .await?
        .ok_or_else(|| DatasetError::Exists(name.to_owned()))
}

/// The dataset of that name, if any.
pub async fn find(store: &Store, name: &str) -> Result<Option<DatasetInfo>, DatasetError> {
    store
        .dataset(name)
        .await?
        .map(|row| info_from_row(&row))
        .transpose()
}

/// The dataset of that name, or [`DatasetError::NoSuchDataset`].
pub async fn get(store: &Store, name: &str) -> Result<DatasetInfo, DatasetError> {
    find(store, name)
        .await?
        .ok_or_else(|| DatasetError::NoSuchDataset(name.to_owned()))
}

fn info_from_row(row: &DatasetRow) -> Result<DatasetInfo, DatasetError> {
    let definition = serde_json::from_str(&row.definition_json).map_err(|e| {
        DatasetError::Invalid(format!(
            "dataset `{}` has an unreadable definition: {e}",
            row.name
        ))
    })?;
    Ok(DatasetInfo {
        dataset_id: row.dataset_id,
        name: row.name.clone(),
        definition,
        sample_count: row.sample_count,
        software_version: row.software_version.clone(),
        schema_version: row.schema_version,
        created_at: row.created_at.clone(),
        split_counts: row.split_counts,
    })
}

/// Every dataset, oldest first.
pub async fn list(store: &Store) -> Result<Vec<DatasetInfo>, DatasetError> {
    let names = store.dataset_names().await?;
    let mut out = Vec::with_capacity(names.len());
    for name in names {
        out.push(get(store, &name).await?);
    }
    Ok(out)
}
