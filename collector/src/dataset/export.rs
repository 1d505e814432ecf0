//! Export a dataset as files a Python user opens with pandas and PIL, no glue code:
//!
//! ```text
//! DIR/
//!   images/000000.png …   one lossless PNG per sample, named by its position in the dataset
//!   labels.csv            one row per sample, in dataset order (header below)
//!   manifest.json         definition, runs' configs, versions, units, sha256 of every file
//! ```
//!
//! `labels.csv` columns: `image` (path relative to DIR), `fx_n fy_n fz_n` (N),
//! `tx_nmm ty_nmm tz_nmm` (N·mm, as the paper reports torque), `x_m z_m theta_rad`
//! (the commanded contact pose), `rod`, `medium`, `split` (`train`/`val`/`test`), `run`,
//! `index` (the sample's index in its run). Numbers are printed in their shortest form
//! that reads back to the same `f64`; torques are that form of the stored N·m value
//! with the decimal point moved three places (exact, and exact back on import).
//!
//! `run` is the run's id in the database where the sample was collected: for a run
//! that was itself imported it is the id recorded in the original export, so export →
//! import → export writes the same `labels.csv` and images byte for byte. (Should two
//! runs of one dataset share such an original id, the local ids are written instead.)
//!
//! PNG frames are copied verbatim; raw RGB frames are encoded as PNG; JPEG frames are
//! decoded and re-encoded as PNG (lossless from then on).
//!
//! The export streams: one sample's row and image are in memory at a time (plus one
//! checksum line per file for the manifest). It is written into a hidden folder
//! `.NAME.partial-PID` beside DIR and renamed to DIR at the end, so an interrupted
//! export never looks complete.

pub use super::manifest::{
    LABEL_COLUMNS, MANIFEST_FORMAT, Manifest, ManifestColumn, ManifestDataset, ManifestRun,
};

use super::manifest::columns;
use super::{DatasetError, EXPORT_FORMAT_VERSION, Split, csv, get};
use crate::progress::progress_bar;
use crate::store::Store;
use crate::store::rows::seed_from_sql;
use futures_util::TryStreamExt as _;
use sha2::{Digest as _, Sha256};
use softtouch_schemas::FrameFormat;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// What an export wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExportSummary {
    /// The folder.
    pub dir: PathBuf,
    /// Samples (images).
    pub samples: u64,
    /// Bytes of images written.
    pub image_bytes: u64,
}

use crate::store::datasets::ExportRun as RunRow;

/// sha256 as lowercase hex.
#[must_use]
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

pub(crate) fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write as _;
    bytes.iter().fold(String::with_capacity(64), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

/// The image's file name for a position: at least six digits.
pub(crate) fn image_name(position: i64, count: i64) -> String {
    let width = count.saturating_sub(1).max(0).to_string().len().max(6);
    format!("images/{position:0width$}.png")
}

/// Encode a stored frame as PNG bytes (PNG frames come back as they are).
pub(crate) fn frame_to_png(
    format: &str,
    width: i64,
    height: i64,
    data: Vec<u8>,
    what: &dyn Fn() -> String,
) -> Result<Vec<u8>, DatasetError> {
    let img_err = |why: String| DatasetError::Image { what: what(), why };
    let rgb = match format.parse::<FrameFormat>().map_err(img_err)? {
        FrameFormat::Png => return Ok(data),
        FrameFormat::Rgb8 => {
            let w = u32::try_from(width).map_err(|e| img_err(e.to_string()))?;
            let h = u32::try_from(height).map_err(|e| img_err(e.to_string()))?;
            image::RgbImage::from_raw(w, h, data)
                .ok_or_else(|| img_err(format!("rgb8 data does not fill {w}×{h}")))?
        }
        FrameFormat::Jpeg => image::load_from_memory_with_format(&data, image::ImageFormat::Jpeg)
            .map_err(|e| img_err(e.to_string()))?
            .to_rgb8(),
    };
    encode_png(&rgb).map_err(img_err)
}

pub(crate) fn encode_png(rgb: &image::RgbImage) -> Result<Vec<u8>, String> {
    use image::ImageEncoder as _;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(
            rgb.as_raw(),
            rgb.width(),
            rgb.height(),
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| e.to_string())?;
    Ok(out)
}

/// Writes through to a file while hashing.
struct HashingWriter {
    inner: std::io::BufWriter<std::fs::File>,
    hash: Sha256,
}

impl std::io::Write for HashingWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.hash.update(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// Export dataset `name` into folder `out` (which must not exist, or be empty).
pub async fn export(
    store: &Store,
    name: &str,
    out: &Path,
    progress: bool,
) -> Result<ExportSummary, DatasetError> {
    let info = get(store, name).await?;
    if out.exists() {
        let empty_dir = out.is_dir()
            && std::fs::read_dir(out)
                .map_err(DatasetError::io("read", out))?
                .next()
                .is_none();
        if !empty_dir {
            return Err(DatasetError::Invalid(format!(
                "{} already exists: export into a new (or empty) folder",
                out.display()
            )));
        }
    }
    let file_name = out
        .file_name()
        .ok_or_else(|| DatasetError::Invalid(format!("bad output folder {}", out.display())))?;
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_owned(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(DatasetError::io("create", &parent))?;
    let tmp = parent.join(format!(
        ".{}.partial-{}",
        file_name.to_string_lossy(),
        std::process::id()
    ));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(DatasetError::io("remove", &tmp))?;
    }
    let result = write_into(store, &info, &tmp, progress).await;
    let finish = || -> Result<(), DatasetError> {
        if out.exists() {
            std::fs::remove_dir(out).map_err(DatasetError::io("replace", out))?;
        }
        std::fs::rename(&tmp, out).map_err(DatasetError::io("rename into place", out))
    };
    match result.and_then(|summary| finish().map(|()| summary)) {
        Ok((samples, image_bytes)) => Ok(ExportSummary {
            dir: out.to_owned(),
            samples,
            image_bytes,
        }),
        Err(e) => {
            let _ = std::fs::remove_dir_all(&tmp);
            Err(e)
        }
    }
}

async fn write_into(
    store: &Store,
    info: &super::DatasetInfo,
    dir: &Path,
    progress: bool,
) -> Result<(u64, u64), DatasetError> {
    let images = dir.join("images");
    std::fs::create_dir_all(&images).map_err(DatasetError::io("create", &images))?;

    // The runs, and the id each shows in the `run` column.
    let runs: Vec<RunRow> = store.dataset_runs(info.dataset_id).await?;
    let origin: Vec<i64> = runs
        .iter()
        .map(|r| r.origin_run_id.unwrap_or(r.run_id))
        .collect();
    let unique = origin.iter().collect::<HashSet<_>>().len() == origin.len();
    let shown: HashMap<i64, i64> = runs
        .iter()
        .zip(&origin)
        .map(|(r, &o)| (r.run_id, if unique { o } else { r.run_id }))
        .collect();

    let labels_path = dir.join("labels.csv");
    let file =
        std::fs::File::create(&labels_path).map_err(DatasetError::io("create", &labels_path))?;
    let mut labels = HashingWriter {
        inner: std::io::BufWriter::new(file),
        hash: Sha256::new(),
    };
    let mut line = LABEL_COLUMNS.join(",");
    line.push('\n');
    labels
        .write_all(line.as_bytes())
        .map_err(DatasetError::io("write", &labels_path))?;

    let mut sha256 = BTreeMap::new();
    let bar = progress_bar(
        u64::try_from(info.sample_count).unwrap_or(0),
        progress,
        "export",
    );
    let (mut samples, mut image_bytes) = (0u64, 0u64);
    let mut rows = store.dataset_samples(info.dataset_id);
    while let Some(r) = rows.try_next().await? {
        let image = image_name(r.position, info.sample_count);
        let (run, index) = (r.run_id, r.sample_index);
        let png = frame_to_png(&r.format, r.width, r.height, r.data, &|| {
            format!("of run {run} sample {index}")
        })?;
        let path = dir.join(&image);
        std::fs::write(&path, &png).map_err(DatasetError::io("write", &path))?;
        sha256.insert(image.clone(), sha256_hex(&png));
        image_bytes += png.len() as u64;

        let split: Split = r.split.parse().map_err(DatasetError::Invalid)?;
        let mut line = String::with_capacity(200);
        csv::push_field(&mut line, &image);
        for v in r.wrench.force_n() {
            line.push(',');
            line.push_str(&csv::number(v));
        }
        for v in r.wrench.torque_nm() {
            line.push(',');
            line.push_str(&csv::nm_to_nmm_text(v));
        }
        for v in [r.cmd_x_m, r.cmd_z_m, r.cmd_theta_rad] {
            line.push(',');
            line.push_str(&csv::number(v));
        }
        for text in [r.rod.as_str(), r.medium.as_str(), split.as_str()] {
            line.push(',');
            csv::push_field(&mut line, text);
        }
        let shown_run = shown.get(&r.run_id).copied().unwrap_or(r.run_id);
        line.push_str(&format!(",{shown_run},{}\n", r.sample_index));
        labels
            .write_all(line.as_bytes())
            .map_err(DatasetError::io("write", &labels_path))?;
        samples += 1;
        bar.inc(1);
    }
    drop(rows);
    bar.finish_and_clear();
    labels
        .flush()
        .map_err(DatasetError::io("write", &labels_path))?;
    let HashingWriter { inner, hash } = labels;
    let file = inner.into_inner().map_err(|e| DatasetError::Io {
        doing: "write",
        path: labels_path.clone(),
        source: e.into_error(),
    })?;
    file.sync_all()
        .map_err(DatasetError::io("sync", &labels_path))?;
    sha256.insert("labels.csv".to_owned(), hex(&hash.finalize()));

    let exported_at: String = store.now().await?;
    let manifest = Manifest {
        format: MANIFEST_FORMAT.into(),
        format_version: EXPORT_FORMAT_VERSION,
        software_version: softtouch_schemas::SOFTWARE_VERSION.into(),
        schema_version: Store::schema_version(),
        exported_at,
        dataset: ManifestDataset {
            name: info.name.clone(),
            definition: info.definition.clone(),
            sample_count: info.sample_count,
            split_counts: Split::ALL
                .iter()
                .map(|s| (s.as_str().to_owned(), info.split_counts[s.ordinal()]))
                .collect(),
            created_at: info.created_at.clone(),
            software_version: info.software_version.clone(),
            schema_version: info.schema_version,
        },
        runs: runs
            .into_iter()
            .map(|r| ManifestRun {
                run: shown.get(&r.run_id).copied().unwrap_or(r.run_id),
                seed: seed_from_sql(r.seed),
                status: r.status,
                scene_name: r.scene_name,
                medium: r.medium,
                rig_toml: r.rig_toml,
                scene_toml: r.scene_toml,
                software_version: r.software_version,
                schema_version: r.schema_version,
                created_at: r.created_at,
                imported: r.layout.map(|layout| {
                    serde_json::json!({
                        "layout": layout,
                        "source_path": r.source_path,
                        "provenance": r.provenance
                            .and_then(|p| serde_json::from_str::<serde_json::Value>(&p).ok()),
                    })
                }),
            })
            .collect(),
        columns: columns(),
        sha256,
    };
    let manifest_path = dir.join("manifest.json");
    let mut json = serde_json::to_vec_pretty(&manifest)
        .map_err(|e| DatasetError::Invalid(format!("cannot encode the manifest: {e}")))?;
    json.push(b'\n');
    std::fs::write(&manifest_path, json).map_err(DatasetError::io("write", &manifest_path))?;
    Ok((samples, image_bytes))
}
