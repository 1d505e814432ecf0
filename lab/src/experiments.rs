//! Training experiments: the paper's Table 1 and the latent sweep (Method S2), and the
//! model benchmark over input size, width and latent size.
//!
//! The grids, their rows, the training of one row and the CSV and PNG writers live here
//! rather than in the verbs, so that the `sweep` and `bench model` verbs and a report
//! read the same rows. Nothing here prints: the caller passes a training [`Observer`].

use softtouch_collector::plot::{PlotError, Series, SeriesStyle, XyChart, xy_chart};
use softtouch_trainer::train::Observer;
use softtouch_trainer::{
    AXES, Latency, Metrics, ModelConfig, ModelKind, Predictor, Preprocess, Splits, TrainConfig,
    TrainError, Trained, measure_frame_latency, measure_latency,
};
use std::path::{Path, PathBuf};

/// An experiment failed.
#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    /// The settings asked for are invalid.
    #[error("{0}")]
    Invalid(String),
    /// Training (or measuring) failed.
    #[error(transparent)]
    Train(#[from] TrainError),
    /// A plot could not be drawn.
    #[error(transparent)]
    Plot(#[from] PlotError),
    /// A file could not be written.
    #[error("cannot write {}: {source}", path.display())]
    Write {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A folder could not be created.
    #[error("cannot create {}: {source}", path.display())]
    CreateDir {
        /// The folder.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The trainer returned a model without its training summary (a bug).
    #[error("training returned no summary")]
    NoSummary,
}

/// One trained configuration of a sweep or benchmark.
#[derive(Debug, Clone)]
pub struct Row {
    /// What the row is, e.g. `SVAE α=0.1` or `32px w16 l32`.
    pub label: String,
    /// The model trained.
    pub config: ModelConfig,
    /// Metrics on the test split.
    pub test: Metrics,
    /// Epochs run (early stopping included).
    pub epochs: usize,
    /// Mean wall time of an epoch, s.
    pub seconds_per_epoch: f64,
    /// Training throughput, images/s.
    pub images_per_s: f64,
    /// Median single-image latency on one core: the model on a preprocessed image.
    pub latency_ms: Option<f64>,
    /// The same from a raw camera frame (colour threshold and squash included).
    pub frame_latency_ms: Option<f64>,
}

/// Which sweep a set of rows comes from: it names the files and the plot's x axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sweep {
    /// Table 1: ConvNet, SVAE over α, VAE.
    Alpha,
    /// Method S2: SVAE over latent size.
    Latent,
}

impl Sweep {
    /// The stem of the CSV and PNG files.
    #[must_use]
    pub const fn stem(self) -> &'static str {
        match self {
            Self::Alpha => "sweep-alpha",
            Self::Latent => "sweep-latent",
        }
    }
}

/// The rows of the paper's Table 1: ConvNet, the SVAE at each α, then the VAE; every
/// other setting from `base`.
#[must_use]
pub fn alpha_grid(base: &ModelConfig, alphas: &[f64]) -> Vec<(String, ModelConfig)> {
    let mut rows = vec![(
        "ConvNet".to_owned(),
        ModelConfig {
            kind: ModelKind::Convnet,
            ..*base
        },
    )];
    rows.extend(alphas.iter().map(|&alpha| {
        (
            format!("SVAE α={alpha}"),
            ModelConfig {
                kind: ModelKind::Svae,
                alpha,
                ..*base
            },
        )
    }));
    rows.push((
        "VAE".to_owned(),
        ModelConfig {
            kind: ModelKind::Vae,
            ..*base
        },
    ));
    rows
}

/// The rows of Method S2: the SVAE at each latent size.
#[must_use]
pub fn latent_grid(base: &ModelConfig, latents: &[usize]) -> Vec<(String, ModelConfig)> {
    latents
        .iter()
        .map(|&latent| {
            (
                format!("SVAE latent={latent}"),
                ModelConfig {
                    kind: ModelKind::Svae,
                    latent,
                    ..*base
                },
            )
        })
        .collect()
}

/// The model benchmark's grid: every input size × width × latent size, sizes outermost
/// (so a dataset is preprocessed once per size). Each point is checked.
///
/// # Errors
/// [`ExperimentError::Invalid`] naming the first invalid point, or an empty grid.
pub fn model_grid(
    base: &ModelConfig,
    sizes_px: &[usize],
    widths: &[usize],
    latents: &[usize],
) -> Result<Vec<(String, ModelConfig)>, ExperimentError> {
    let mut wanted = Vec::new();
    for &size_px in sizes_px {
        for &width in widths {
            for &latent in latents {
                let config = ModelConfig {
                    width,
                    latent,
                    preprocess: Preprocess {
                        size_px,
                        ..base.preprocess
                    },
                    ..*base
                };
                let problems = config.problems();
                if !problems.is_empty() {
                    return Err(ExperimentError::Invalid(format!(
                        "size {size_px}, width {width}, latent {latent}: {}",
                        problems.join("; ")
                    )));
                }
                wanted.push((format!("{size_px}px w{width} l{latent}"), config));
            }
        }
    }
    if wanted.is_empty() {
        return Err(ExperimentError::Invalid(
            "nothing to measure: give --sizes, --widths and --latents".to_owned(),
        ));
    }
    Ok(wanted)
}

/// Train one row (no checkpoints) and summarise it; the trained model comes back too.
///
/// # Errors
/// Training failed.
pub fn train_row(
    label: String,
    config: ModelConfig,
    train: &TrainConfig,
    splits: &Splits,
    observer: &mut dyn Observer,
) -> Result<(Row, Trained), ExperimentError> {
    let trained = softtouch_trainer::train(&config, train, splits, None, observer)?;
    let Some(s) = trained.artifact.header.training.clone() else {
        return Err(ExperimentError::NoSummary);
    };
    let seconds: f64 = trained.history.iter().map(|h| h.seconds).sum();
    Ok((
        Row {
            label,
            config,
            test: s.test,
            epochs: s.epochs_run,
            seconds_per_epoch: seconds / s.epochs_run.max(1) as f64,
            images_per_s: s.train_images_per_s,
            latency_ms: None,
            frame_latency_ms: None,
        },
        trained,
    ))
}

/// Single-image latencies of a trained row on one core, model alone (on `image`, a
/// preprocessed test image) and from a raw `(width, height, rgb)` frame; recorded in
/// the row.
///
/// # Errors
/// Inference failed.
pub fn measure_row(
    row: &mut Row,
    trained: Trained,
    image: &[f32],
    frame: (usize, usize, &[u8]),
    runs: usize,
) -> Result<(Latency, Latency), ExperimentError> {
    let mut predictor = Predictor::new(trained.artifact);
    let latency = measure_latency(&predictor, image, runs, 1)?;
    let frame_latency = measure_frame_latency(&mut predictor, frame, runs, 1)?;
    row.latency_ms = Some(latency.median_ms);
    row.frame_latency_ms = Some(frame_latency.median_ms);
    Ok((latency, frame_latency))
}

/// `–` for a missing value, else the value formatted by `f` (a terminal's table).
pub fn fmt_opt(v: Option<f64>, f: impl Fn(f64) -> String) -> String {
    v.map_or_else(|| "–".to_owned(), f)
}

/// A CSV cell: empty for a missing or non-finite value (what pandas and R read as
/// missing; a `–` would make the whole column text), else the value formatted by `f`.
pub fn csv_opt(v: Option<f64>, f: impl Fn(f64) -> String) -> String {
    v.filter(|x| x.is_finite()).map_or_else(String::new, f)
}

/// CSV columns `,r2_fx … ,r2_tz` (header) for [`push_axis_r2`].
pub(crate) fn push_axis_r2_header(s: &mut String) {
    for a in AXES {
        s.push_str(&format!(",r2_{}", a.to_lowercase()));
    }
}

/// The six per-axis R² of `m` as CSV cells, each after a comma (empty when absent).
pub(crate) fn push_axis_r2(s: &mut String, m: &Metrics) {
    for i in 0..6 {
        s.push(',');
        s.push_str(&csv_opt(m.r2.map(|x| x[i].r2), |v| format!("{v:.6}")));
    }
}

/// The rows as CSV: settings, timings, image MSE, mean and per-axis test R².
#[must_use]
pub fn rows_csv(rows: &[Row]) -> String {
    let mut s = String::from(
        "label,model,alpha,beta,latent,width,size_px,epochs,seconds_per_epoch,train_images_per_s,latency_ms,frame_latency_ms,image_mse,r2_mean",
    );
    push_axis_r2_header(&mut s);
    s.push('\n');
    for r in rows {
        let c = &r.config;
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{:.3},{:.1},{},{},{},{}",
            r.label,
            c.kind,
            c.alpha,
            c.beta,
            c.latent,
            c.width,
            c.preprocess.size_px,
            r.epochs,
            r.seconds_per_epoch,
            r.images_per_s,
            csv_opt(r.latency_ms, |v| format!("{v:.4}")),
            csv_opt(r.frame_latency_ms, |v| format!("{v:.4}")),
            csv_opt(r.test.image_mse, |v| format!("{v:.6e}")),
            csv_opt(r.test.r2_mean, |v| format!("{v:.6}")),
        ));
        push_axis_r2(&mut s, &r.test);
        s.push('\n');
    }
    s
}

/// Write [`rows_csv`] to `path`.
///
/// # Errors
/// The file cannot be written.
pub fn write_csv(path: &Path, rows: &[Row]) -> Result<(), ExperimentError> {
    std::fs::write(path, rows_csv(rows)).map_err(|source| ExperimentError::Write {
        path: path.to_owned(),
        source,
    })
}

/// Create the output folder.
///
/// # Errors
/// It cannot be created.
pub fn prepare_out(dir: &Path) -> Result<(), ExperimentError> {
    std::fs::create_dir_all(dir).map_err(|source| ExperimentError::CreateDir {
        path: dir.to_owned(),
        source,
    })
}

/// Plot a sweep's SVAE rows: test R² and image MSE against log α or log₂ latent size.
///
/// # Errors
/// The plot cannot be drawn or written.
pub fn plot_sweep(png: &Path, sweep: Sweep, rows: &[Row]) -> Result<(), ExperimentError> {
    let svae: Vec<&Row> = rows
        .iter()
        .filter(|r| r.config.kind == ModelKind::Svae)
        .collect();
    let x = |r: &Row| match sweep {
        Sweep::Alpha => r.config.alpha.max(1e-9).log10(),
        Sweep::Latent => (r.config.latent as f64).log2(),
    };
    let series = vec![
        Series {
            label: "test R² (mean of 6 axes)".into(),
            points: svae
                .iter()
                .map(|r| (x(r), r.test.r2_mean.unwrap_or(f64::NAN)))
                .collect(),
            style: SeriesStyle::LinePoints,
        },
        Series {
            label: "test image MSE × 10".into(),
            points: svae
                .iter()
                .map(|r| (x(r), r.test.image_mse.map_or(f64::NAN, |v| v * 10.0)))
                .collect(),
            style: SeriesStyle::LinePoints,
        },
    ];
    let (title, x_label) = match sweep {
        Sweep::Alpha => ("SVAE: accuracy and reconstruction against α", "log10 α"),
        Sweep::Latent => (
            "SVAE: accuracy and reconstruction against latent size",
            "log2 latent dimensions",
        ),
    };
    xy_chart(
        png,
        &XyChart {
            title,
            x_label,
            y_label: "R² / image MSE × 10",
            series: &series,
        },
        (900, 560),
    )?;
    Ok(())
}

/// Plot the model benchmark: one point per row, test R² against model latency.
///
/// # Errors
/// The plot cannot be drawn or written.
pub fn plot_bench_model(png: &Path, rows: &[Row]) -> Result<(), ExperimentError> {
    let series: Vec<Series> = rows
        .iter()
        .map(|r| Series {
            label: r.label.clone(),
            points: vec![(
                r.latency_ms.unwrap_or(f64::NAN),
                r.test.r2_mean.unwrap_or(f64::NAN),
            )],
            style: SeriesStyle::Points,
        })
        .collect();
    xy_chart(
        png,
        &XyChart {
            title: "Accuracy costs time: test R² against inference latency (batch 1, one core)",
            x_label: "latency, ms",
            y_label: "test R² (mean of 6 axes)",
            series: &series,
        },
        (900, 560),
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_alpha_grid_is_convnet_then_each_svae_then_vae() {
        let base = ModelConfig::default();
        let rows = alpha_grid(&base, &[0.1, 10.0]);
        let labels: Vec<&str> = rows.iter().map(|(l, _)| l.as_str()).collect();
        assert_eq!(labels, ["ConvNet", "SVAE α=0.1", "SVAE α=10", "VAE"]);
        assert_eq!(rows[0].1.kind, ModelKind::Convnet);
        assert!((rows[2].1.alpha - 10.0).abs() < 1e-12);
        assert_eq!(rows[3].1.kind, ModelKind::Vae);
    }

    #[test]
    fn the_latent_grid_keeps_every_other_setting() {
        let base = ModelConfig::default();
        let rows = latent_grid(&base, &[6, 256]);
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].1.latent, 256);
        assert_eq!(rows[1].1.width, base.width);
        assert_eq!(rows[1].1.kind, ModelKind::Svae);
    }

    #[test]
    fn an_invalid_or_empty_model_grid_is_refused_with_the_point() {
        let base = ModelConfig::default();
        let Err(ExperimentError::Invalid(msg)) = model_grid(&base, &[33], &[8], &[32]) else {
            panic!("size 33 must be refused");
        };
        assert!(msg.starts_with("size 33, width 8, latent 32:"), "{msg}");
        assert!(matches!(
            model_grid(&base, &[], &[8], &[32]),
            Err(ExperimentError::Invalid(_))
        ));
        let grid = model_grid(&base, &[16, 32], &[4, 8], &[32]).expect("valid grid");
        let labels: Vec<&str> = grid.iter().map(|(l, _)| l.as_str()).collect();
        assert_eq!(
            labels,
            ["16px w4 l32", "16px w8 l32", "32px w4 l32", "32px w8 l32"]
        );
    }

    #[test]
    fn the_csv_has_a_header_and_one_line_per_row_with_empty_cells_for_missing_values() {
        let row = Row {
            label: "x".into(),
            config: ModelConfig::default(),
            test: Metrics::compute(None, &[], None).expect("no predictions"),
            epochs: 2,
            seconds_per_epoch: 1.5,
            images_per_s: 100.0,
            latency_ms: None,
            frame_latency_ms: Some(0.25),
        };
        let csv = rows_csv(&[row]);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 2);
        assert!(lines[0].ends_with(",r2_fx,r2_fy,r2_fz,r2_tx,r2_ty,r2_tz"));
        assert_eq!(
            lines[0].split(',').count(),
            lines[1].split(',').count(),
            "{csv}"
        );
        // Missing values are empty cells (pandas reads them as NaN; a `–` would make
        // the column text), every other cell a number.
        assert!(lines[1].contains(",,0.2500,"), "{csv}");
        assert!(!csv.contains('–'), "{csv}");
        for cell in lines[1].split(',').skip(2) {
            assert!(
                cell.is_empty() || cell.parse::<f64>().is_ok(),
                "`{cell}` in {csv}"
            );
        }
    }
}
