//! The export's file format: the columns of `labels.csv` and `manifest.json`, written
//! by [`super::export`] and read back by [`super::import`].

use super::Definition;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The columns of `labels.csv`, in order.
pub const LABEL_COLUMNS: [&str; 15] = [
    "image",
    "fx_n",
    "fy_n",
    "fz_n",
    "tx_nmm",
    "ty_nmm",
    "tz_nmm",
    "x_m",
    "z_m",
    "theta_rad",
    "rod",
    "medium",
    "split",
    "run",
    "index",
];

/// Value of `manifest.json`'s `format`.
pub const MANIFEST_FORMAT: &str = "softtouch-dataset";

/// `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`MANIFEST_FORMAT`].
    pub format: String,
    /// [`EXPORT_FORMAT_VERSION`](super::EXPORT_FORMAT_VERSION).
    pub format_version: u32,
    /// Version of the software that exported.
    pub software_version: String,
    /// Schema version of the database it was exported from.
    pub schema_version: i64,
    /// When (UTC).
    pub exported_at: String,
    /// The dataset.
    pub dataset: ManifestDataset,
    /// The runs the samples come from, by the id in the `run` column.
    pub runs: Vec<ManifestRun>,
    /// The columns of `labels.csv` with their units.
    pub columns: Vec<ManifestColumn>,
    /// sha256 (hex) of `labels.csv` and of every image, by path relative to the folder.
    pub sha256: BTreeMap<String, String>,
}

/// The dataset in a manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestDataset {
    /// Name.
    pub name: String,
    /// How it was made.
    pub definition: Definition,
    /// Samples.
    pub sample_count: i64,
    /// Samples per split.
    pub split_counts: BTreeMap<String, i64>,
    /// When it was created (UTC).
    pub created_at: String,
    /// Software version that created it.
    pub software_version: String,
    /// Schema version it was created under.
    pub schema_version: i64,
}

/// A run in a manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestRun {
    /// The id in `labels.csv`'s `run` column.
    pub run: i64,
    /// Seed of the run (pose sampler and simulation).
    pub seed: u64,
    /// Status when exported.
    pub status: String,
    /// Scene name.
    pub scene_name: String,
    /// Medium.
    pub medium: String,
    /// Resolved rig config (TOML).
    pub rig_toml: String,
    /// Resolved scene spec (TOML).
    pub scene_toml: String,
    /// Software version that collected it.
    pub software_version: String,
    /// Schema version it was collected under.
    pub schema_version: i64,
    /// When it was created (UTC).
    pub created_at: String,
    /// For a run that was itself imported: where from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imported: Option<serde_json::Value>,
}

/// A column of `labels.csv`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestColumn {
    /// Header name.
    pub name: String,
    /// Unit, if any.
    pub unit: Option<String>,
    /// What it holds.
    pub description: String,
}

pub(super) fn columns() -> Vec<ManifestColumn> {
    let c = |name: &str, unit: Option<&str>, description: &str| ManifestColumn {
        name: name.into(),
        unit: unit.map(Into::into),
        description: description.into(),
    };
    vec![
        c("image", None, "PNG path relative to the export folder"),
        c(
            "fx_n",
            Some("N"),
            "force x, sensor frame, mean over the window",
        ),
        c(
            "fy_n",
            Some("N"),
            "force y, sensor frame, mean over the window",
        ),
        c(
            "fz_n",
            Some("N"),
            "force z, sensor frame, mean over the window",
        ),
        c(
            "tx_nmm",
            Some("N·mm"),
            "torque x, sensor frame, mean over the window",
        ),
        c(
            "ty_nmm",
            Some("N·mm"),
            "torque y, sensor frame, mean over the window",
        ),
        c(
            "tz_nmm",
            Some("N·mm"),
            "torque z, sensor frame, mean over the window",
        ),
        c(
            "x_m",
            Some("m"),
            "commanded contact pose: offset along the approach axis",
        ),
        c(
            "z_m",
            Some("m"),
            "commanded contact pose: offset along the rod's axis",
        ),
        c(
            "theta_rad",
            Some("rad"),
            "commanded contact pose: rotation about the rod's axis",
        ),
        c("rod", None, "rod name from the scene"),
        c("medium", None, "air or water"),
        c("split", None, "train, val or test"),
        c(
            "run",
            None,
            "run id where the sample was collected (see manifest runs)",
        ),
        c("index", None, "sample index within its run"),
    ]
}
