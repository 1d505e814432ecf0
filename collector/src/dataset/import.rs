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

use super::export::{
    LABEL_COLUMNS, MANIFEST_FORMAT, Manifest, encode_png, progress_bar, sha256_hex,
};
use super::{
    DatasetError, Definition, EXPORT_FORMAT_VERSION, Filters, SPLIT_ALGORITHM, Split, SplitRatio,
    csv, insert_dataset, query_err, validate_name,
};
use crate::store::{RunId, Store};
use softtouch_schemas::Medium;
use std::collections::{BTreeMap, HashSet};
use std::path::{Component, Path, PathBuf};

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
    let (layout, items, runs, name, mut definition, checksums, splits) = if dir
        .join("manifest.json")
        .is_file()
    {
        let (manifest, items) = read_export(dir)?;
        let name = options
            .name
            .clone()
            .unwrap_or_else(|| manifest.dataset.name.clone());
        let mut definition = manifest.dataset.definition.clone();
        definition.imported_from = Some(serde_json::json!({
            "layout": Layout::SofttouchExport.as_str(),
            "path": source.display().to_string(),
            "dataset": manifest.dataset.name,
            "runs": definition.runs,
            "exported_at": manifest.exported_at,
            "software_version": manifest.software_version,
        }));
        let runs = manifest_runs(&manifest, &items)?;
        let splits = items
            .iter()
            .map(|i| i.split.unwrap_or(Split::Train))
            .collect();
        (
            Layout::SofttouchExport,
            items,
            runs,
            name,
            definition,
            Some(manifest.sha256),
            splits,
        )
    } else if dir.join(PAPER_CSV).is_file() {
        let items = read_paper(dir, options)?;
        let name = match &options.name {
            Some(n) => n.clone(),
            None => source
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| "imported".into()),
        };
        let splits = super::split::assign(items.len(), options.ratio, options.seed)?;
        let definition = Definition {
            runs: Vec::new(),
            filters: Filters::default(),
            split: options.ratio.to_string(),
            seed: options.seed,
            algorithm: SPLIT_ALGORITHM.into(),
            imported_from: Some(serde_json::json!({
                "layout": Layout::PaperCsv.as_str(),
                "path": source.display().to_string(),
                "units": "Fx Fy Fz in N, Tx Ty Tz in N·mm",
            })),
        };
        let run = NewImportedRun {
            origin: None,
            seed: options.seed,
            scene_name: "paper-import".into(),
            medium: options.medium,
            rig_toml: String::new(),
            scene_toml: String::new(),
            software_version: softtouch_schemas::SOFTWARE_VERSION.into(),
            schema_version: Store::schema_version(),
            created_at: None,
            provenance: serde_json::json!({
                "csv": source.join(PAPER_CSV).display().to_string(),
                "rod": options.rod,
                "medium": options.medium.as_str(),
            }),
        };
        (
            Layout::PaperCsv,
            items,
            vec![run],
            name,
            definition,
            None,
            splits,
        )
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
        let id = insert_run(&mut tx, run, layout, &source, &rods.join(","), count).await?;
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
        let (png, width, height) = load_image(dir, item, layout, checksums.as_ref())?;
        insert_sample(&mut tx, run_id, item, &png, width, height).await?;
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

fn malformed(path: &Path, line: usize, column: usize, message: impl Into<String>) -> DatasetError {
    DatasetError::Malformed {
        path: path.to_owned(),
        line,
        column,
        message: message.into(),
    }
}

fn read_text(path: &Path) -> Result<String, DatasetError> {
    let bytes = std::fs::read(path).map_err(DatasetError::io("read", path))?;
    String::from_utf8(bytes).map_err(|e| malformed(path, 0, 0, format!("not UTF-8 text: {e}")))
}

fn parse_records(path: &Path, text: &str) -> Result<Vec<csv::Record>, DatasetError> {
    csv::parse(text).map_err(|e| malformed(path, e.line, e.column, e.message))
}

/// A finite number, or an error naming the line, the column and its header.
fn number(
    path: &Path,
    line: usize,
    column: usize,
    header: &str,
    text: &str,
) -> Result<f64, DatasetError> {
    let v: f64 = text.trim().parse().map_err(|_| {
        malformed(
            path,
            line,
            column,
            format!("{header}: `{text}` is not a number"),
        )
    })?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(malformed(
            path,
            line,
            column,
            format!("{header}: `{text}` is not finite"),
        ))
    }
}

/// A finite torque in N·mm as text, converted exactly to N·m.
fn torque_nm(
    path: &Path,
    line: usize,
    column: usize,
    header: &str,
    text: &str,
) -> Result<f64, DatasetError> {
    number(path, line, column, header, text)?;
    csv::nmm_text_to_nm(text)
        .filter(|v| v.is_finite())
        .ok_or_else(|| {
            malformed(
                path,
                line,
                column,
                format!("{header}: `{text}` is out of range"),
            )
        })
}

fn integer(
    path: &Path,
    line: usize,
    column: usize,
    header: &str,
    text: &str,
) -> Result<i64, DatasetError> {
    text.trim()
        .parse::<i64>()
        .ok()
        .filter(|v| *v >= 0)
        .ok_or_else(|| {
            malformed(
                path,
                line,
                column,
                format!("{header}: `{text}` is not a whole number ≥ 0"),
            )
        })
}

/// An image path inside `dir`: relative, no `..`, and the file exists.
fn check_image(dir: &Path, csv_path: &Path, line: usize, image: &str) -> Result<(), DatasetError> {
    let rel = Path::new(image);
    if image.is_empty()
        || rel.is_absolute()
        || rel
            .components()
            .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir))
    {
        return Err(malformed(
            csv_path,
            line,
            1,
            format!("image path `{image}` must be relative to the folder, without `..`"),
        ));
    }
    if !dir.join(rel).is_file() {
        return Err(malformed(
            csv_path,
            line,
            1,
            format!(
                "image `{image}` is missing ({} not found)",
                dir.join(rel).display()
            ),
        ));
    }
    Ok(())
}

fn read_export(dir: &Path) -> Result<(Manifest, Vec<Item>), DatasetError> {
    let manifest_path = dir.join("manifest.json");
    let text = read_text(&manifest_path)?;
    let manifest: Manifest = serde_json::from_str(&text)
        .map_err(|e| malformed(&manifest_path, e.line(), e.column(), e.to_string()))?;
    if manifest.format != MANIFEST_FORMAT {
        return Err(malformed(
            &manifest_path,
            0,
            0,
            format!(
                "format is `{}`, expected `{MANIFEST_FORMAT}`",
                manifest.format
            ),
        ));
    }
    if manifest.format_version > EXPORT_FORMAT_VERSION {
        return Err(malformed(
            &manifest_path,
            0,
            0,
            format!(
                "format version {} is newer than this build reads ({EXPORT_FORMAT_VERSION})",
                manifest.format_version
            ),
        ));
    }
    let labels_path = dir.join("labels.csv");
    let text = read_text(&labels_path)?;
    if let Some(expected) = manifest.sha256.get("labels.csv")
        && *expected != sha256_hex(text.as_bytes())
    {
        return Err(malformed(
            &labels_path,
            0,
            0,
            "sha256 does not match the manifest: the file was changed or damaged",
        ));
    }
    let records = parse_records(&labels_path, &text)?;
    let mut records = records.into_iter();
    let header = records
        .next()
        .ok_or_else(|| malformed(&labels_path, 1, 0, "empty file: no header"))?;
    for (i, expected) in LABEL_COLUMNS.iter().enumerate() {
        let got = header.fields.get(i).map(String::as_str);
        if got != Some(expected) {
            return Err(malformed(
                &labels_path,
                header.line,
                i + 1,
                format!(
                    "header: expected `{expected}`, found {}",
                    got.map_or("nothing".into(), |g| format!("`{g}`"))
                ),
            ));
        }
    }
    if header.fields.len() != LABEL_COLUMNS.len() {
        return Err(malformed(
            &labels_path,
            header.line,
            LABEL_COLUMNS.len() + 1,
            format!(
                "header: expected {} columns, found {}",
                LABEL_COLUMNS.len(),
                header.fields.len()
            ),
        ));
    }
    let known_runs: HashSet<i64> = manifest.runs.iter().map(|r| r.run).collect();
    let mut seen = HashSet::new();
    let mut items = Vec::new();
    for r in records {
        let f = &r.fields;
        check_columns(&labels_path, r.line, f.len(), LABEL_COLUMNS.len())?;
        let num = |c: usize| number(&labels_path, r.line, c + 1, LABEL_COLUMNS[c], &f[c]);
        let nm = |c: usize| torque_nm(&labels_path, r.line, c + 1, LABEL_COLUMNS[c], &f[c]);
        let wrench = [num(1)?, num(2)?, num(3)?, nm(4)?, nm(5)?, nm(6)?];
        let pose = [num(7)?, num(8)?, num(9)?];
        let rod = f[10].clone();
        if rod.is_empty() {
            return Err(malformed(&labels_path, r.line, 11, "rod: empty"));
        }
        let medium: Medium = f[11]
            .parse()
            .map_err(|e: String| malformed(&labels_path, r.line, 12, format!("medium: {e}")))?;
        let split: Split = f[12]
            .parse()
            .map_err(|e: String| malformed(&labels_path, r.line, 13, format!("split: {e}")))?;
        let run = integer(&labels_path, r.line, 14, "run", &f[13])?;
        if !known_runs.contains(&run) {
            return Err(malformed(
                &labels_path,
                r.line,
                14,
                format!("run {run} is not among the manifest's runs"),
            ));
        }
        let index = integer(&labels_path, r.line, 15, "index", &f[14])?;
        if !seen.insert((run, index)) {
            return Err(malformed(
                &labels_path,
                r.line,
                15,
                format!("run {run} index {index} appears twice"),
            ));
        }
        check_image(dir, &labels_path, r.line, &f[0])?;
        items.push(Item {
            line: r.line,
            image: f[0].clone(),
            wrench,
            pose,
            rod,
            medium,
            split: Some(split),
            run,
            index,
        });
    }
    if items.is_empty() {
        return Err(malformed(&labels_path, 0, 0, "no samples"));
    }
    Ok((manifest, items))
}

fn check_columns(
    path: &Path,
    line: usize,
    found: usize,
    expected: usize,
) -> Result<(), DatasetError> {
    if found == expected {
        return Ok(());
    }
    Err(malformed(
        path,
        line,
        found.min(expected) + 1,
        format!("expected {expected} columns, found {found}"),
    ))
}

fn manifest_runs(manifest: &Manifest, items: &[Item]) -> Result<Vec<NewImportedRun>, DatasetError> {
    let used: HashSet<i64> = items.iter().map(|i| i.run).collect();
    let mut runs = Vec::new();
    let mut seen = HashSet::new();
    for r in &manifest.runs {
        if !used.contains(&r.run) || !seen.insert(r.run) {
            continue;
        }
        let medium: Medium = r.medium.parse().map_err(DatasetError::Invalid)?;
        runs.push(NewImportedRun {
            origin: Some(r.run),
            seed: r.seed,
            scene_name: r.scene_name.clone(),
            medium,
            rig_toml: r.rig_toml.clone(),
            scene_toml: r.scene_toml.clone(),
            software_version: r.software_version.clone(),
            schema_version: r.schema_version,
            created_at: Some(r.created_at.clone()),
            provenance: serde_json::to_value(r)
                .map(|mut v| {
                    // The configs are in the run row already.
                    if let Some(o) = v.as_object_mut() {
                        o.remove("rig_toml");
                        o.remove("scene_toml");
                    }
                    v
                })
                .unwrap_or(serde_json::Value::Null),
        });
    }
    Ok(runs)
}

fn read_paper(dir: &Path, options: &ImportOptions) -> Result<Vec<Item>, DatasetError> {
    if options.rod.is_empty() {
        return Err(DatasetError::Invalid("--rod must not be empty".into()));
    }
    let path = dir.join(PAPER_CSV);
    let text = read_text(&path)?;
    let records = parse_records(&path, &text)?;
    const HEADERS: [&str; 7] = [
        "image",
        "Fx (N)",
        "Fy (N)",
        "Fz (N)",
        "Tx (N·mm)",
        "Ty (N·mm)",
        "Tz (N·mm)",
    ];
    let mut items = Vec::new();
    for (k, r) in records.iter().enumerate() {
        let f = &r.fields;
        // A first row whose wrench fields are not numbers is a header.
        if k == 0
            && f.iter()
                .skip(1)
                .take(6)
                .all(|x| x.trim().parse::<f64>().is_err())
        {
            check_columns(&path, r.line, f.len(), 7)?;
            continue;
        }
        check_columns(&path, r.line, f.len(), 7)?;
        let mut wrench = [0.0; 6];
        for (c, w) in wrench.iter_mut().enumerate() {
            let (column, header, text) = (c + 2, HEADERS[c + 1], &f[c + 1]);
            *w = if c < 3 {
                number(&path, r.line, column, header, text)?
            } else {
                torque_nm(&path, r.line, column, header, text)?
            };
        }
        check_image(dir, &path, r.line, &f[0])?;
        items.push(Item {
            line: r.line,
            image: f[0].clone(),
            wrench,
            pose: [0.0; 3],
            rod: options.rod.clone(),
            medium: options.medium,
            split: None,
            run: 0,
            index: i64::try_from(items.len()).unwrap_or(i64::MAX),
        });
    }
    if items.is_empty() {
        return Err(malformed(&path, 0, 0, "no samples"));
    }
    Ok(items)
}

const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];

/// Read an item's image: PNG bytes as they are (dimensions from the header), anything
/// else decoded and re-encoded as PNG. Checks the manifest's sha256 where given.
fn load_image(
    dir: &Path,
    item: &Item,
    layout: Layout,
    checksums: Option<&BTreeMap<String, String>>,
) -> Result<(Vec<u8>, u32, u32), DatasetError> {
    let path: PathBuf = dir.join(&item.image);
    let csv_name = match layout {
        Layout::SofttouchExport => dir.join("labels.csv"),
        Layout::PaperCsv => dir.join(PAPER_CSV),
    };
    let bad = |message: String| malformed(&csv_name, item.line, 1, message);
    let bytes = std::fs::read(&path).map_err(DatasetError::io("read", &path))?;
    if let Some(sums) = checksums {
        match sums.get(&item.image) {
            Some(expected) if *expected == sha256_hex(&bytes) => {}
            Some(_) => {
                return Err(bad(format!(
                    "image `{}`: sha256 does not match the manifest",
                    item.image
                )));
            }
            None => {
                return Err(bad(format!(
                    "image `{}` has no sha256 in the manifest",
                    item.image
                )));
            }
        }
    }
    if bytes.starts_with(&PNG_SIGNATURE) {
        let (w, h) =
            image::ImageReader::with_format(std::io::Cursor::new(&bytes), image::ImageFormat::Png)
                .into_dimensions()
                .map_err(|e| bad(format!("image `{}`: {e}", item.image)))?;
        return Ok((bytes, w, h));
    }
    let rgb = image::load_from_memory(&bytes)
        .map_err(|e| bad(format!("image `{}` does not decode: {e}", item.image)))?
        .to_rgb8();
    let (w, h) = rgb.dimensions();
    let png = encode_png(&rgb).map_err(|e| bad(format!("image `{}`: {e}", item.image)))?;
    Ok((png, w, h))
}

async fn insert_run(
    tx: &mut sqlx::SqliteConnection,
    run: &NewImportedRun,
    layout: Layout,
    source: &Path,
    rods: &str,
    count: usize,
) -> Result<RunId, DatasetError> {
    let result = sqlx::query(
        "INSERT INTO runs (status, seed, samples_planned, rod_schedule, rod_block, scene_name, medium,
                           rig_toml, scene_toml, software_version, schema_version,
                           created_at, updated_at, finished_at)
         VALUES ('completed', ?, ?, ?, 1, ?, ?, ?, ?, ?, ?,
                 COALESCE(?, strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
                 strftime('%Y-%m-%dT%H:%M:%fZ', 'now'), strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))",
    )
    .bind(super::seed_to_sql(run.seed))
    .bind(i64::try_from(count).unwrap_or(i64::MAX))
    .bind(rods)
    .bind(&run.scene_name)
    .bind(run.medium.as_str())
    .bind(&run.rig_toml)
    .bind(&run.scene_toml)
    .bind(&run.software_version)
    .bind(run.schema_version)
    .bind(run.created_at.as_deref())
    .execute(&mut *tx)
    .await
    .map_err(query_err("creating an imported run"))?;
    let run_id = result.last_insert_rowid();
    sqlx::query(
        "INSERT INTO run_imports (run_id, layout, source_path, origin_run_id, provenance, imported_at)
         VALUES (?, ?, ?, ?, ?, strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))",
    )
    .bind(run_id)
    .bind(layout.as_str())
    .bind(source.display().to_string())
    .bind(run.origin)
    .bind(run.provenance.to_string())
    .execute(&mut *tx)
    .await
    .map_err(query_err("recording an import"))?;
    Ok(run_id)
}

async fn insert_sample(
    tx: &mut sqlx::SqliteConnection,
    run_id: RunId,
    item: &Item,
    png: &[u8],
    width: u32,
    height: u32,
) -> Result<(), DatasetError> {
    let w = item.wrench;
    sqlx::query(
        "INSERT INTO samples (run_id, sample_index, rod, medium,
             cmd_x_m, cmd_z_m, cmd_theta_rad, meas_x_m, meas_z_m, meas_theta_rad,
             fx_n, fy_n, fz_n, tx_nm, ty_nm, tz_nm,
             fx_std_n, fy_std_n, fz_std_n, tx_std_nm, ty_std_nm, tz_std_nm,
             reading_count, frame_t_ns, window_start_ns, window_end_ns, sync_skew_ns,
             status, reject_reason, attempts)
         VALUES (?, ?, ?, ?, ?, ?, ?, NULL, NULL, NULL, ?, ?, ?, ?, ?, ?,
                 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 'ok', NULL, 1)",
    )
    .bind(run_id)
    .bind(item.index)
    .bind(&item.rod)
    .bind(item.medium.as_str())
    .bind(item.pose[0])
    .bind(item.pose[1])
    .bind(item.pose[2])
    .bind(w[0])
    .bind(w[1])
    .bind(w[2])
    .bind(w[3])
    .bind(w[4])
    .bind(w[5])
    .execute(&mut *tx)
    .await
    .map_err(query_err("inserting an imported sample"))?;
    sqlx::query(
        "INSERT INTO frames (run_id, sample_index, format, width, height, sequence, t_ns, data)
         VALUES (?, ?, 'png', ?, ?, ?, 0, ?)",
    )
    .bind(run_id)
    .bind(item.index)
    .bind(i64::from(width))
    .bind(i64::from(height))
    .bind(item.index)
    .bind(png)
    .execute(&mut *tx)
    .await
    .map_err(query_err("inserting an imported frame"))?;
    sqlx::query(
        "INSERT INTO ft_windows (run_id, sample_index, encoding, reading_count, data)
         VALUES (?, ?, ?, 0, x'')",
    )
    .bind(run_id)
    .bind(item.index)
    .bind(crate::store::WINDOW_ENCODING)
    .execute(&mut *tx)
    .await
    .map_err(query_err("inserting an imported window"))?;
    Ok(())
}
