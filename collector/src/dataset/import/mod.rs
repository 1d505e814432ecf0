//! Import a folder of labelled images into the store, as new runs and a dataset.
//!
//! Two layouts, told apart by their files:
//! - **softtouch export** (`manifest.json`, `labels.csv`, `images/`; see [`super::export`]):
//!   one new run per run of the manifest, with its configs, seed and versions, marked
//!   imported (table `run_imports`, with the original run id and the manifest's record
//!   of it); samples keep their run index, pose and labels; a dataset with the same
//!   members, order and splits is created (name: the manifest's, or `--name`). Every
//!   file's sha256 is checked against the manifest.
//! - **the paper's layout** (`data_frame.csv`): first column the image file (relative
//!   to the CSV's folder), the next six the wrench `Fx Fy Fz` in N and `Tx Ty Tz` in
//!   **N·mm** (the paper's units); exactly seven columns; a header row is recognised
//!   by its non-numeric wrench fields and skipped. One new run (medium and rod from the
//!   options, pose unknown and stored as 0), samples indexed in file order, split by
//!   the options' ratio and seed.
//!
//! Fields of imported samples the files do not carry are stored as neutral values:
//! window standard deviations 0, `reading_count` 0, times and sync skew 0, status `ok`,
//! one attempt, no raw force/torque readings (an empty window). (So `--min-readings`
//! and `--max-skew-ms` see zeros for imported runs.)
//!
//! Everything is checked before anything is written (every line, every field, every
//! image's presence); then runs, samples, frames and the dataset are written in one
//! transaction, so an import that fails (an image that does not decode, a checksum
//! that does not match, a kill) leaves nothing behind. PNG images are stored byte for
//! byte; other formats are decoded and stored re-encoded as PNG.

mod export_dir;
mod files;
mod paper_csv;

use super::{
    DatasetError, Definition, Split, SplitRatio, insert_dataset, query_err, validate_name,
};
use crate::progress::progress_bar;
use crate::store::rows::{self, RunRow};
use crate::store::{FrameRecord, RunId, RunStatus, Store};
use softtouch_schemas::{
    ContactPose, FrameFormat, FrameMeta, Medium, Sample, SampleStatus, TimestampNs, Wrench,
};
use sqlx::AnyConnection;
use std::collections::BTreeMap;
use std::path::Path;

/// The paper's CSV file name.
pub const PAPER_CSV: &str = "data_frame.csv";

/// Which layout a folder has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// `manifest.json` + `labels.csv` + `images/`.
    SofttouchExport,
    /// `data_frame.csv` + images.
    PaperCsv,
}

impl Layout {
    /// As stored in `run_imports.layout`.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::SofttouchExport => "softtouch-export",
            Self::PaperCsv => "paper-csv",
        }
    }
}

/// Options of an import.
#[derive(Debug, Clone)]
pub struct ImportOptions {
    /// Name of the dataset to create (default: the manifest's; for the paper's layout,
    /// the folder's name).
    pub name: Option<String>,
    /// Paper layout: the medium of every sample.
    pub medium: Medium,
    /// Paper layout: the rod of every sample.
    pub rod: String,
    /// Paper layout: the split ratio.
    pub ratio: SplitRatio,
    /// Paper layout: the split seed.
    pub seed: u64,
    /// Show a progress bar (on a terminal).
    pub progress: bool,
}

impl Default for ImportOptions {
    fn default() -> Self {
        Self {
            name: None,
            medium: Medium::Air,
            rod: "unknown".into(),
            ratio: SplitRatio::PAPER,
            seed: 0,
            progress: false,
        }
    }
}

/// What an import did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImportSummary {
    /// The layout found.
    pub layout: Layout,
    /// The dataset created.
    pub dataset: String,
    /// The runs created.
    pub runs: Vec<RunId>,
    /// Samples imported.
    pub samples: u64,
}

/// One labelled image, checked.
#[derive(Debug, Clone)]
struct Item {
    line: usize,
    image: String,
    /// Fx Fy Fz (N), Tx Ty Tz (N·m, converted exactly from the file's N·mm).
    wrench: [f64; 6],
    pose: [f64; 3],
    rod: String,
    medium: Medium,
    split: Option<Split>,
    /// Softtouch layout: the run id in the file; paper layout: 0.
    run: i64,
    index: i64,
}

/// A run to create.
#[derive(Debug, Clone)]
struct NewImportedRun {
    origin: Option<i64>,
    seed: u64,
    scene_name: String,
    medium: Medium,
    rig_toml: String,
    scene_toml: String,
    software_version: String,
    schema_version: i64,
    created_at: Option<String>,
    provenance: serde_json::Value,
}

/// What a layout's reader found, checked, ready to write.
struct Plan {
    layout: Layout,
    items: Vec<Item>,
    runs: Vec<NewImportedRun>,
    /// The dataset's name.
    name: String,
    definition: Definition,
    /// Softtouch layout: the manifest's sha256 of every file.
    checksums: Option<BTreeMap<String, String>>,
    /// One per item.
    splits: Vec<Split>,
}

/// Import the folder `dir`.
pub async fn import(
    store: &Store,
    dir: &Path,
    options: &ImportOptions,
) -> Result<ImportSummary, DatasetError> {
    if !dir.is_dir() {
        return Err(DatasetError::Invalid(format!(
            "{} is not a folder",
            dir.display()
        )));
    }
    let source = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_owned());
    let Plan {
        layout,
        items,
        runs,
        name,
        mut definition,
        checksums,
        splits,
    } = if dir.join("manifest.json").is_file() {
        export_dir::plan(dir, &source, options)?
    } else if dir.join(PAPER_CSV).is_file() {
        paper_csv::plan(dir, &source, options)?
    } else {
        return Err(DatasetError::Invalid(format!(
            "{} holds neither a softtouch export (manifest.json) nor the paper's layout ({PAPER_CSV})",
            dir.display()
        )));
    };
    validate_name(&name)?;
    if super::find(store, &name).await?.is_some() {
        return Err(DatasetError::Exists(name));
    }

    // Everything checked; write it all in one transaction.
    let mut tx = store
        .pool()
        .begin()
        .await
        .map_err(query_err("starting the import transaction"))?;
    let mut local_ids: BTreeMap<Option<i64>, RunId> = BTreeMap::new();
    for run in &runs {
        let rods: Vec<&str> = {
            let mut seen = Vec::new();
            for i in items
                .iter()
                .filter(|i| Some(i.run) == run.origin || run.origin.is_none())
            {
                if !seen.contains(&i.rod.as_str()) {
                    seen.push(i.rod.as_str());
                }
            }
            seen
        };
        let count = items
            .iter()
            .filter(|i| run.origin.is_none() || Some(i.run) == run.origin)
            .count();
        let schedule = rows::rod_schedule_json(&rods);
        let id = write_run(&mut tx, run, layout, &source, &schedule, count).await?;
        local_ids.insert(run.origin, id);
    }
    let bar = progress_bar(items.len() as u64, options.progress, "import");
    let mut members = Vec::with_capacity(items.len());
    for (item, &split) in items.iter().zip(&splits) {
        let run_id = local_ids
            .get(
                &(if layout == Layout::PaperCsv {
                    None
                } else {
                    Some(item.run)
                }),
            )
            .copied()
            .ok_or_else(|| DatasetError::Invalid(format!("no run {} in the manifest", item.run)))?;
        let (png, width, height) = files::load_image(dir, item, layout, checksums.as_ref())?;
        write_sample(&mut tx, run_id, item, &png, width, height).await?;
        members.push((run_id, item.index, split));
        bar.inc(1);
    }
    bar.finish_and_clear();
    definition.runs = local_ids.values().copied().collect();
    definition.runs.sort_unstable();
    insert_dataset(&mut tx, &name, &definition, &members).await?;
    tx.commit()
        .await
        .map_err(query_err("committing the import"))?;
    Ok(ImportSummary {
        layout,
        dataset: name,
        runs: definition.runs,
        samples: items.len() as u64,
    })
}

/// Create an imported run: completed, one rod per block, and its `run_imports` row.
async fn write_run(
    conn: &mut AnyConnection,
    run: &NewImportedRun,
    layout: Layout,
    source: &Path,
    rods: &str,
    count: usize,
) -> Result<RunId, DatasetError> {
    let row = RunRow {
        status: RunStatus::Completed,
        seed: run.seed,
        samples_planned: u64::try_from(count).unwrap_or(u64::MAX),
        rod_schedule: rods,
        rod_block: 1,
        scene_name: &run.scene_name,
        medium: run.medium,
        rig_toml: &run.rig_toml,
        scene_toml: &run.scene_toml,
        poses_from: None,
        software_version: &run.software_version,
        schema_version: run.schema_version,
        created_at: run.created_at.as_deref(),
    };
    let run_id = rows::insert_run(conn, &row).await?;
    rows::insert_run_import(
        conn,
        run_id,
        layout.as_str(),
        &source.display().to_string(),
        run.origin,
        &run.provenance.to_string(),
    )
    .await?;
    Ok(run_id)
}

/// Store an item as a sample with its PNG frame and an empty window; what the files do
/// not carry is neutral (see the module doc).
async fn write_sample(
    conn: &mut AnyConnection,
    run_id: RunId,
    item: &Item,
    png: &[u8],
    width: u32,
    height: u32,
) -> Result<(), DatasetError> {
    // Checked ≥ 0 when read.
    let index = u64::try_from(item.index)
        .map_err(|_| DatasetError::Invalid(format!("bad sample index {}", item.index)))?;
    let [x_m, z_m, theta_rad] = item.pose;
    let sample = Sample {
        index,
        rod: item.rod.clone(),
        medium: item.medium,
        commanded: ContactPose {
            x_m,
            z_m,
            theta_rad,
        },
        measured: None,
        wrench_mean_in_sensor: Wrench::from_array(item.wrench),
        wrench_std_in_sensor: Wrench::from_array([0.0; 6]),
        reading_count: 0,
        frame_t: TimestampNs(0),
        window_start: TimestampNs(0),
        window_end: TimestampNs(0),
        sync_skew_ns: 0,
        status: SampleStatus::Ok,
        attempts: 1,
    };
    // Fresh runs and (run, index) checked unique: never already there.
    rows::insert_sample(conn, run_id, &sample).await?;
    let frame = FrameRecord {
        meta: FrameMeta {
            t: TimestampNs(0),
            sequence: index,
            width,
            height,
            format: FrameFormat::Png,
        },
        data: png,
    };
    rows::insert_frame(conn, run_id, index, frame).await?;
    rows::insert_ft_window(conn, run_id, index, &[]).await?;
    Ok(())
}
