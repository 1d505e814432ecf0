//! Results the database does not hold, read from the CSV files the verbs write:
//! sweeps and the model benchmark ([`crate::experiments::rows_csv`]) and the
//! collection benchmark (`collection-sweep.csv` of `softtouch bench collection`).
//!
//! Both formats are plain comma-separated numbers and labels without quoting; a
//! missing value is `–`. Errors name the file, the line and the column.

use super::ReportError;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// One row of a sweep or model-benchmark CSV.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SweepRow {
    pub label: String,
    /// `svae`, `vae` or `convnet`.
    pub model: String,
    pub alpha: f64,
    pub latent: f64,
    pub width: f64,
    pub size_px: f64,
    pub epochs: f64,
    pub image_mse: Option<f64>,
    pub r2_mean: Option<f64>,
    /// Fx … Tz.
    pub r2: [Option<f64>; 6],
    pub latency_ms: Option<f64>,
}

/// What a sweep file holds, from its rows' labels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum SweepKind {
    /// Table 1 (`softtouch sweep alpha`).
    Alpha,
    /// Method S2 (`softtouch sweep latent`).
    Latent,
    /// `softtouch bench model`.
    Model,
}

/// A sweep file.
#[derive(Debug, Clone)]
pub(crate) struct SweepFile {
    pub path: PathBuf,
    pub kind: SweepKind,
    pub rows: Vec<SweepRow>,
    /// SHA-256 prefix of the file, for provenance.
    pub hash: String,
}

/// One point of the collection benchmark.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct CollectionPoint {
    pub settle_s: f64,
    pub window_s: f64,
    pub samples: f64,
    pub accepted: f64,
    pub force_rmse_n: f64,
    pub torque_rmse_nmm: f64,
    pub samples_per_hour: f64,
}

/// The collection benchmark's file.
#[derive(Debug, Clone)]
pub(crate) struct CollectionFile {
    pub path: PathBuf,
    pub points: Vec<CollectionPoint>,
    pub hash: String,
}

fn read(path: &Path) -> Result<String, ReportError> {
    std::fs::read_to_string(path).map_err(|source| ReportError::Read {
        path: path.to_owned(),
        source,
    })
}

/// Lines of a CSV as header-indexed records.
struct Table<'a> {
    path: &'a Path,
    columns: HashMap<&'a str, usize>,
    rows: Vec<(usize, Vec<&'a str>)>,
}

impl<'a> Table<'a> {
    fn parse(path: &'a Path, text: &'a str, required: &[&str]) -> Result<Self, ReportError> {
        let bad = |line: usize, why: String| ReportError::Csv {
            path: path.to_owned(),
            line,
            why,
        };
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty());
        let Some((_, header)) = lines.next() else {
            return Err(bad(1, "empty file: expected a header line".into()));
        };
        let columns: HashMap<&str, usize> = header
            .split(',')
            .map(str::trim)
            .enumerate()
            .map(|(i, c)| (c, i))
            .collect();
        if let Some(missing) = required.iter().find(|c| !columns.contains_key(*c)) {
            return Err(bad(
                1,
                format!(
                    "no column `{missing}` (expected the columns {})",
                    required.join(",")
                ),
            ));
        }
        let width = header.split(',').count();
        let mut rows = Vec::new();
        for (i, line) in lines {
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            if fields.len() != width {
                return Err(bad(
                    i + 1,
                    format!("{} fields, expected {width} as in the header", fields.len()),
                ));
            }
            rows.push((i + 1, fields));
        }
        Ok(Self {
            path,
            columns,
            rows,
        })
    }

    fn text(&self, row: &[&'a str], column: &str) -> &'a str {
        self.columns
            .get(column)
            .and_then(|&i| row.get(i))
            .copied()
            .unwrap_or("")
    }

    /// A number, `None` for `–` or an absent optional column.
    fn opt(&self, line: usize, row: &[&str], column: &str) -> Result<Option<f64>, ReportError> {
        let Some(&i) = self.columns.get(column) else {
            return Ok(None);
        };
        let field = row.get(i).copied().unwrap_or("");
        if field == "–" || field == "-" || field.is_empty() {
            return Ok(None);
        }
        field
            .parse::<f64>()
            .map(Some)
            .map_err(|_| ReportError::Csv {
                path: self.path.to_owned(),
                line,
                why: format!("column `{column}`: `{field}` is not a number"),
            })
    }

    fn num(&self, line: usize, row: &[&str], column: &str) -> Result<f64, ReportError> {
        self.opt(line, row, column)?
            .ok_or_else(|| ReportError::Csv {
                path: self.path.to_owned(),
                line,
                why: format!("column `{column}`: a number is required"),
            })
    }
}

const SWEEP_COLUMNS: [&str; 9] = [
    "label",
    "model",
    "alpha",
    "latent",
    "width",
    "size_px",
    "epochs",
    "image_mse",
    "r2_mean",
];
const AXIS_COLUMNS: [&str; 6] = ["r2_fx", "r2_fy", "r2_fz", "r2_tx", "r2_ty", "r2_tz"];

/// Reads a sweep or model-benchmark CSV.
pub(crate) fn read_sweep(path: &Path) -> Result<SweepFile, ReportError> {
    parse_sweep(path, &read(path)?)
}

/// Parses a sweep or model-benchmark CSV's text; `path` names where it came from (a
/// file, or a stored result's table).
pub(crate) fn parse_sweep(path: &Path, text: &str) -> Result<SweepFile, ReportError> {
    let table = Table::parse(path, text, &SWEEP_COLUMNS)?;
    let mut rows = Vec::new();
    for (line, r) in &table.rows {
        let model = table.text(r, "model");
        if !matches!(model, "svae" | "vae" | "convnet") {
            return Err(ReportError::Csv {
                path: path.to_owned(),
                line: *line,
                why: format!("column `model`: `{model}`, expected svae, vae or convnet"),
            });
        }
        let mut r2 = [None; 6];
        for (slot, column) in r2.iter_mut().zip(AXIS_COLUMNS) {
            *slot = table.opt(*line, r, column)?;
        }
        rows.push(SweepRow {
            label: table.text(r, "label").to_owned(),
            model: model.to_owned(),
            alpha: table.num(*line, r, "alpha")?,
            latent: table.num(*line, r, "latent")?,
            width: table.num(*line, r, "width")?,
            size_px: table.num(*line, r, "size_px")?,
            epochs: table.num(*line, r, "epochs")?,
            image_mse: table.opt(*line, r, "image_mse")?,
            r2_mean: table.opt(*line, r, "r2_mean")?,
            r2,
            latency_ms: table.opt(*line, r, "latency_ms")?,
        });
    }
    // The verbs label their rows; the labels say which experiment this was.
    let kind = if rows
        .iter()
        .any(|r| r.label.starts_with("SVAE α=") || r.model != "svae")
    {
        SweepKind::Alpha
    } else if !rows.is_empty() && rows.iter().all(|r| r.label.starts_with("SVAE latent=")) {
        SweepKind::Latent
    } else {
        SweepKind::Model
    };
    Ok(SweepFile {
        path: path.to_owned(),
        kind,
        rows,
        hash: super::data::config_hash(text),
    })
}

const COLLECTION_COLUMNS: [&str; 7] = [
    "settle_s",
    "window_s",
    "samples",
    "accepted",
    "force_rmse_n",
    "torque_rmse_nmm",
    "samples_per_hour",
];

/// Reads `collection-sweep.csv`.
pub(crate) fn read_collection(path: &Path) -> Result<CollectionFile, ReportError> {
    let text = read(path)?;
    let table = Table::parse(path, &text, &COLLECTION_COLUMNS)?;
    let mut points = Vec::new();
    for (line, r) in &table.rows {
        let n = |c| table.num(*line, r, c);
        points.push(CollectionPoint {
            settle_s: n("settle_s")?,
            window_s: n("window_s")?,
            samples: n("samples")?,
            accepted: n("accepted")?,
            force_rmse_n: n("force_rmse_n")?,
            torque_rmse_nmm: n("torque_rmse_nmm")?,
            samples_per_hour: n("samples_per_hour")?,
        });
    }
    Ok(CollectionFile {
        path: path.to_owned(),
        points,
        hash: super::data::config_hash(&text),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = softtouch_collector::testing::tempdir();
        let path = dir.path().join("x.csv");
        std::fs::write(&path, text).expect("write");
        (dir, path)
    }

    const HEADER: &str = "label,model,alpha,beta,latent,width,size_px,epochs,seconds_per_epoch,train_images_per_s,latency_ms,frame_latency_ms,image_mse,r2_mean,r2_fx,r2_fy,r2_fz,r2_tx,r2_ty,r2_tz";

    #[test]
    fn a_sweep_file_is_read_and_recognised() {
        let (_d, path) = write(&format!(
            "{HEADER}\nConvNet,convnet,1,0.1,32,16,32,12,1,1,–,–,–,0.99,0.9,0.9,0.9,0.9,0.9,0.9\n\
             SVAE α=0.1,svae,0.1,0.1,32,16,32,12,1,1,–,–,2e-2,0.98,0.9,0.9,0.9,0.9,0.9,0.9\n"
        ));
        let file = read_sweep(&path).expect("reads");
        assert_eq!(file.kind, SweepKind::Alpha);
        assert_eq!(file.rows.len(), 2);
        assert_eq!(file.rows[0].image_mse, None);
        assert_eq!(file.rows[1].image_mse, Some(2e-2));
        let (_d, path) = write(&format!(
            "{HEADER}\nSVAE latent=6,svae,1,0.1,6,16,32,12,1,1,–,–,1e-3,0.98,0.9,0.9,0.9,0.9,0.9,0.9\n"
        ));
        assert_eq!(read_sweep(&path).expect("reads").kind, SweepKind::Latent);
    }

    #[test]
    fn bad_sweep_files_name_the_line_and_column() {
        let (_d, path) = write(&format!(
            "{HEADER}\nx,svae,abc,0.1,6,16,32,12,1,1,–,–,1e-3,0.98,0.9,0.9,0.9,0.9,0.9,0.9\n"
        ));
        let msg = read_sweep(&path).expect_err("bad alpha").to_string();
        assert!(msg.contains("x.csv:2") && msg.contains("`alpha`"), "{msg}");
        let (_d, path) = write("label,model\nx,svae\n");
        let msg = read_sweep(&path).expect_err("columns").to_string();
        assert!(
            msg.contains("x.csv:1") && msg.contains("no column `alpha`"),
            "{msg}"
        );
        let (_d, path) = write(&format!("{HEADER}\nx,svae,1\n"));
        let msg = read_sweep(&path).expect_err("short line").to_string();
        assert!(msg.contains("x.csv:2") && msg.contains("3 fields"), "{msg}");
        let (_d, path) = write("");
        assert!(read_sweep(&path).is_err());
    }

    #[test]
    fn the_collection_benchmark_file_is_read() {
        let (_d, path) = write(
            "settle_s,window_s,samples,accepted,force_rmse_n,torque_rmse_nmm,samples_per_hour,wall_s\n\
             0,0.005,40,40,0.15,6.7,912.9,0.18\n",
        );
        let file = read_collection(&path).expect("reads");
        assert_eq!(file.points.len(), 1);
        assert!((file.points[0].samples_per_hour - 912.9).abs() < 1e-9);
    }
}
