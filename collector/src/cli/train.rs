//! `softtouch train`, `eval`, `models`, `sweep alpha|latent` and `bench model`.

use super::{Failure, io_failure, open_existing};
use crate::dataset::export::progress_bar;
use crate::models::{self, ModelError};
use crate::plot::{Series, SeriesStyle, XyChart, xy_chart};
use crate::store::Store;
use anyhow::anyhow;
use clap::{Args, Subcommand};
use softtouch_trainer::train::{EpochReport, Observer};
use softtouch_trainer::{
    AXES, Metrics, ModelArtifact, ModelConfig, ModelKind, Predictor, Preprocess, Splits,
    TrainConfig, Trained, evaluate, measure_frame_latency, measure_latency,
};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

impl From<ModelError> for Failure {
    fn from(e: ModelError) -> Self {
        if e.is_bad_input() {
            Self::BadInput(e.into())
        } else {
            Self::Runtime(e.into())
        }
    }
}

impl From<softtouch_trainer::TrainError> for Failure {
    fn from(e: softtouch_trainer::TrainError) -> Self {
        ModelError::from(e).into()
    }
}

/// The model and optimisation settings every training verb takes.
#[derive(Debug, Clone, Args)]
pub struct ModelArgs {
    /// Which model: svae, vae or convnet.
    #[arg(long, default_value_t = ModelConfig::default().kind)]
    pub model: ModelKind,
    /// Reconstruction weight of the SVAE loss: α/(1+α)·recon + 1/(1+α)·pred + β·KL.
    #[arg(long, default_value_t = ModelConfig::default().alpha)]
    pub alpha: f64,
    /// KL weight β.
    #[arg(long, default_value_t = ModelConfig::default().beta)]
    pub beta: f64,
    /// Latent dimensions.
    #[arg(long, default_value_t = ModelConfig::default().latent)]
    pub latent: usize,
    /// Channels of the encoder's stem (stages double it, up to 8×).
    #[arg(long, default_value_t = ModelConfig::default().width)]
    pub width: usize,
    /// Input size in pixels (square, a power of two in 16..=256).
    #[arg(long, default_value_t = Preprocess::default().size_px)]
    pub size: usize,
    /// Input channels: 1 (brightness of the finger's pixels) or 3 (RGB).
    #[arg(long, default_value_t = Preprocess::default().channels)]
    pub channels: usize,
    /// Maximum epochs.
    #[arg(long, default_value_t = TrainConfig::default().epochs)]
    pub epochs: usize,
    /// Batch size.
    #[arg(long, default_value_t = TrainConfig::default().batch_size)]
    pub batch: usize,
    /// Adam's initial learning rate (multiplied by --lr-decay after each epoch).
    #[arg(long, default_value_t = TrainConfig::default().learning_rate)]
    pub lr: f64,
    /// Learning-rate factor per epoch.
    #[arg(long, default_value_t = TrainConfig::default().lr_decay)]
    pub lr_decay: f64,
    /// Early stopping: epochs without a better validation score (0: never stop early).
    #[arg(long, default_value_t = TrainConfig::default().patience)]
    pub patience: usize,
    /// Seed of initialisation, shuffling and latent noise.
    #[arg(long, default_value_t = TrainConfig::default().seed)]
    pub seed: u64,
}

impl ModelArgs {
    fn configs(&self) -> Result<(ModelConfig, TrainConfig), Failure> {
        let model = ModelConfig {
            kind: self.model,
            width: self.width,
            latent: self.latent,
            alpha: self.alpha,
            beta: self.beta,
            preprocess: Preprocess {
                size_px: self.size,
                channels: self.channels,
                ..Preprocess::default()
            },
        };
        let train = TrainConfig {
            epochs: self.epochs,
            batch_size: self.batch,
            learning_rate: self.lr,
            lr_decay: self.lr_decay,
            patience: self.patience,
            seed: self.seed,
        };
        let mut problems = model.problems();
        problems.extend(train.problems());
        if problems.is_empty() {
            Ok((model, train))
        } else {
            Err(Failure::BadInput(anyhow!(
                "invalid settings:\n  {}",
                problems.join("\n  ")
            )))
        }
    }
}

/// `softtouch train`.
#[derive(Debug, Args)]
pub struct TrainArgs {
    /// The dataset to train on (its train split; val for early stopping; test reported).
    #[arg(long)]
    pub dataset: String,
    /// Name the model is stored under (default: DATASET-MODEL).
    #[arg(long)]
    pub name: Option<String>,
    /// Also write the model artifact to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Folder of checkpoints (default: `checkpoints/` beside the database). A training
    /// interrupted there resumes from its last epoch when started again with the same
    /// name and settings.
    #[arg(long)]
    pub checkpoints: Option<PathBuf>,
    /// Discard an existing checkpoint of this name instead of resuming it.
    #[arg(long)]
    pub restart: bool,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// `softtouch sweep`.
#[derive(Debug, Subcommand)]
pub enum SweepCommand {
    /// The paper's Table 1 on a dataset: ConvNet, SVAE α ∈ {0.001 … 100}, VAE; image
    /// MSE and average R² on the test split.
    #[command(after_help = "Examples:
  softtouch sweep alpha --dataset air
  softtouch sweep alpha --dataset air --alphas 0.1,1,10 --epochs 10 --out sweep-out")]
    Alpha {
        #[command(flatten)]
        common: SweepArgs,
        /// The α values of the SVAE rows.
        #[arg(long, value_delimiter = ',', default_value = "0.001,0.01,0.1,1,10,100")]
        alphas: Vec<f64>,
    },
    /// Method S2: the SVAE with latent sizes 6 … 256.
    #[command(after_help = "Examples:
  softtouch sweep latent --dataset air
  softtouch sweep latent --dataset air --latents 6,32,256 --epochs 10")]
    Latent {
        #[command(flatten)]
        common: SweepArgs,
        /// Latent sizes.
        #[arg(long, value_delimiter = ',', default_value = "6,16,32,64,128,256")]
        latents: Vec<usize>,
    },
}

/// What every sweep takes.
#[derive(Debug, Args)]
pub struct SweepArgs {
    /// The dataset.
    #[arg(long)]
    pub dataset: String,
    /// Where the CSV and PNG go.
    #[arg(long, default_value = "sweep-out")]
    pub out: PathBuf,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// `softtouch bench model`.
#[derive(Debug, Args)]
pub struct BenchModelArgs {
    /// The dataset.
    #[arg(long)]
    pub dataset: String,
    /// Input sizes to try, px.
    #[arg(long, value_delimiter = ',', default_value = "32,64")]
    pub sizes: Vec<usize>,
    /// Encoder widths to try.
    #[arg(long, value_delimiter = ',', default_value = "8,12,16")]
    pub widths: Vec<usize>,
    /// Latent sizes to try.
    #[arg(long, value_delimiter = ',', default_value = "32")]
    pub latents: Vec<usize>,
    /// Single-image inferences timed per point.
    #[arg(long, default_value_t = 200)]
    pub runs: usize,
    /// Where the CSV and PNG go.
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
    #[command(flatten)]
    pub model: ModelArgs,
}

/// Prints one line per epoch and drives a progress bar over the batches.
struct Progress<'a> {
    out: &'a mut dyn Write,
    bar: indicatif::ProgressBar,
    epochs: usize,
    started: Instant,
    first_epoch: usize,
    show_bar: bool,
}

impl<'a> Progress<'a> {
    fn new(out: &'a mut dyn Write, epochs: usize, show_bar: bool) -> Self {
        Self {
            out,
            bar: indicatif::ProgressBar::hidden(),
            epochs,
            started: Instant::now(),
            first_epoch: 0,
            show_bar,
        }
    }
}

impl Observer for Progress<'_> {
    fn resumed(&mut self, completed: usize) {
        self.first_epoch = completed;
        let _ = writeln!(
            self.out,
            "resuming from the checkpoint after epoch {completed}"
        );
    }
    fn batch(&mut self, epoch: usize, step: usize, steps: usize) {
        if step == 1 {
            self.bar.finish_and_clear();
            self.bar = progress_bar(steps as u64, self.show_bar, &format!("epoch {epoch}"));
        }
        self.bar.set_position(step as u64);
    }
    fn epoch(&mut self, r: &EpochReport) {
        self.bar.finish_and_clear();
        let done = r.epoch.saturating_sub(self.first_epoch).max(1);
        let per_epoch = self.started.elapsed().as_secs_f64() / done as f64;
        let eta = per_epoch * self.epochs.saturating_sub(r.epoch) as f64;
        let opt = |v: Option<f64>| v.map_or_else(|| "–".to_owned(), |v| format!("{v:.4}"));
        let _ = writeln!(
            self.out,
            "epoch {:>3}/{}  loss {:.4}  val R² mean {} min {}  val image MSE {}  {:.0} img/s  {:.1} s  eta ≤ {:.0} s{}",
            r.epoch,
            self.epochs,
            r.train_loss,
            opt(r.val_r2_mean),
            opt(r.val_r2_min),
            r.val_image_mse
                .map_or_else(|| "–".to_owned(), |v| format!("{v:.2e}")),
            r.train_images_per_s,
            r.seconds,
            eta,
            if r.best { "  (best)" } else { "" }
        );
    }
}

/// Loads a dataset's splits with a progress bar.
async fn load(
    store: &Store,
    dataset: &str,
    preprocess: &Preprocess,
    out: &mut dyn Write,
) -> Result<Splits, Failure> {
    let started = Instant::now();
    let bar = progress_bar(0, true, "loading");
    let splits = models::load_splits(store, dataset, preprocess, &|done, total| {
        bar.set_length(total);
        bar.set_position(done);
    })
    .await?;
    bar.finish_and_clear();
    writeln!(
        out,
        "dataset {dataset}: {} train, {} val, {} test images, preprocessed to {}×{}×{} in {:.1} s",
        splits.train.len(),
        splits.val.len(),
        splits.test.len(),
        preprocess.channels,
        preprocess.size_px,
        preprocess.size_px,
        started.elapsed().as_secs_f64()
    )
    .map_err(io_failure)?;
    Ok(splits)
}

fn default_checkpoints(db: &Path) -> PathBuf {
    match db.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.join("checkpoints"),
        _ => PathBuf::from("checkpoints"),
    }
}

/// `softtouch train`.
pub async fn run_train(args: TrainArgs, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let (model, train) = args.model.configs()?;
    let name = args
        .name
        .clone()
        .unwrap_or_else(|| format!("{}-{}", args.dataset, model.kind));
    crate::dataset::validate_name(&name).map_err(|e| Failure::BadInput(e.into()))?;
    let store = open_existing(db).await?;
    if models::find(&store, &name).await?.is_some() {
        return Err(Failure::BadInput(anyhow!(
            "a model named `{name}` already exists: pass --name to choose another"
        )));
    }
    let splits = load(&store, &args.dataset, &model.preprocess, out).await?;
    let dir = args
        .checkpoints
        .clone()
        .unwrap_or_else(|| default_checkpoints(db))
        .join(&name);
    if args.restart {
        softtouch_trainer::train::discard_checkpoint(&dir)?;
    }
    writeln!(
        out,
        "training {name}: {} width {} latent {} input {}×{}×{} α {} β {}, batch {}, up to {} epochs (checkpoints in {})",
        model.kind,
        model.width,
        model.latent,
        model.preprocess.channels,
        model.preprocess.size_px,
        model.preprocess.size_px,
        model.alpha,
        model.beta,
        train.batch_size,
        train.epochs,
        dir.display()
    )
    .map_err(io_failure)?;
    let trained = {
        let mut progress = Progress::new(out, train.epochs, true);
        softtouch_trainer::train(&model, &train, &splits, Some(&dir), &mut progress)?
    };
    report_trained(&trained, out)?;
    models::record(&store, &name, &args.dataset, &trained).await?;
    if let Some(path) = &args.out {
        trained.artifact.save(path)?;
        writeln!(out, "wrote {}", path.display()).map_err(io_failure)?;
    }
    // Recorded: the checkpoint has served its purpose.
    softtouch_trainer::train::discard_checkpoint(&dir)?;
    writeln!(out, "stored model `{name}` (softtouch eval {name})").map_err(io_failure)?;
    store.close().await;
    Ok(())
}

fn report_trained(trained: &Trained, out: &mut dyn Write) -> Result<(), Failure> {
    if let Some(s) = &trained.artifact.header.training {
        writeln!(
            out,
            "best epoch {} of {}{}; {:.0} s in all, {:.0} train images/s",
            s.best_epoch,
            s.epochs_run,
            if s.stopped_early {
                " (stopped early)"
            } else {
                ""
            },
            s.seconds,
            s.train_images_per_s
        )
        .map_err(io_failure)?;
        write!(out, "test split:\n{}", s.test.render()).map_err(io_failure)?;
    }
    Ok(())
}

/// `softtouch eval`.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// A stored model's name, or the path of a model file.
    pub model: String,
    /// The dataset (default: the one a stored model was trained on).
    #[arg(long)]
    pub dataset: Option<String>,
    /// Which split: test, val, train or all.
    #[arg(long, default_value = "test")]
    pub split: String,
}

pub async fn run_eval(args: EvalArgs, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let store = open_existing(db).await?;
    let device = burn_device()?;
    let (artifact, trained_on) = match models::find(&store, &args.model).await? {
        Some(info) => {
            let bytes = models::artifact(&store, &info.name).await?;
            (
                ModelArtifact::from_bytes(&bytes, &device)?,
                Some(info.dataset_name),
            )
        }
        None if Path::new(&args.model).is_file() => {
            if args.dataset.is_none() {
                return Err(Failure::BadInput(anyhow!(
                    "a model file needs --dataset NAME to evaluate on"
                )));
            }
            (ModelArtifact::load(Path::new(&args.model), &device)?, None)
        }
        None => {
            return Err(Failure::BadInput(anyhow!(
                "`{}` is neither a stored model (see `softtouch models`) nor a model file",
                args.model
            )));
        }
    };
    let Some(dataset) = args.dataset.clone().or(trained_on) else {
        return Err(Failure::BadInput(anyhow!(
            "a model file needs --dataset NAME to evaluate on"
        )));
    };
    let splits = load(&store, &dataset, &artifact.header.config.preprocess, out).await?;
    let examples = match args.split.as_str() {
        "test" => splits.test,
        "val" => splits.val,
        "train" => splits.train,
        "all" => [splits.train, splits.val, splits.test].concat(),
        other => {
            return Err(Failure::BadInput(anyhow!(
                "--split {other}: expected test, val, train or all"
            )));
        }
    };
    if examples.is_empty() {
        return Err(Failure::BadInput(anyhow!(
            "the {} split of {dataset} is empty",
            args.split
        )));
    }
    let h = &artifact.header;
    let (metrics, _) = evaluate(&artifact.net, &h.config, &h.norm, &examples, &device);
    writeln!(
        out,
        "model {} ({} width {} latent {} input {}×{}), {dataset} {} split",
        args.model,
        h.config.kind,
        h.config.width,
        h.config.latent,
        h.config.preprocess.size_px,
        h.config.preprocess.size_px,
        args.split
    )
    .map_err(io_failure)?;
    write!(out, "{}", metrics.render()).map_err(io_failure)?;
    store.close().await;
    Ok(())
}

fn burn_device() -> Result<burn::prelude::Device, Failure> {
    Ok(softtouch_trainer::backend::device()?)
}

/// `softtouch models`.
pub async fn run_models(db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let store = open_existing(db).await?;
    let list = models::list(&store).await?;
    if list.is_empty() {
        writeln!(out, "no models yet (softtouch train --dataset NAME)").map_err(io_failure)?;
    } else {
        writeln!(
            out,
            "{:<28} {:<8} {:<20} {:>10} {:>11}  created",
            "name", "kind", "dataset", "test R²", "image MSE"
        )
        .map_err(io_failure)?;
        for m in list {
            writeln!(
                out,
                "{:<28} {:<8} {:<20} {:>10} {:>11}  {}",
                m.name,
                m.kind,
                m.dataset_name,
                m.test_r2_mean
                    .map_or_else(|| "–".into(), |v| format!("{v:.5}")),
                m.test_image_mse
                    .map_or_else(|| "–".into(), |v| format!("{v:.3e}")),
                m.created_at
            )
            .map_err(io_failure)?;
        }
    }
    store.close().await;
    Ok(())
}

/// One trained configuration of a sweep or benchmark.
struct Row {
    label: String,
    config: ModelConfig,
    test: Metrics,
    epochs: usize,
    seconds_per_epoch: f64,
    images_per_s: f64,
    /// Median single-image latency on one core: the model on a preprocessed image.
    latency_ms: Option<f64>,
    /// The same from a raw camera frame (colour threshold and squash included).
    frame_latency_ms: Option<f64>,
}

fn train_row(
    label: String,
    config: ModelConfig,
    train: &TrainConfig,
    splits: &Splits,
    out: &mut dyn Write,
) -> Result<(Row, Trained), Failure> {
    writeln!(out, "— {label}").map_err(io_failure)?;
    let trained = {
        let mut progress = Progress::new(out, train.epochs, true);
        softtouch_trainer::train(&config, train, splits, None, &mut progress)?
    };
    let Some(s) = trained.artifact.header.training.clone() else {
        return Err(Failure::Runtime(anyhow!("training returned no summary")));
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

fn fmt_opt(v: Option<f64>, f: impl Fn(f64) -> String) -> String {
    v.map_or_else(|| "–".to_owned(), f)
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<(), Failure> {
    let mut s = String::from(
        "label,model,alpha,beta,latent,width,size_px,epochs,seconds_per_epoch,train_images_per_s,latency_ms,frame_latency_ms,image_mse,r2_mean",
    );
    for a in AXES {
        s.push_str(&format!(",r2_{}", a.to_lowercase()));
    }
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
            fmt_opt(r.latency_ms, |v| format!("{v:.4}")),
            fmt_opt(r.frame_latency_ms, |v| format!("{v:.4}")),
            fmt_opt(r.test.image_mse, |v| format!("{v:.6e}")),
            fmt_opt(r.test.r2_mean, |v| format!("{v:.6}")),
        ));
        for i in 0..6 {
            s.push(',');
            s.push_str(&fmt_opt(r.test.r2.map(|x| x[i].r2), |v| format!("{v:.6}")));
        }
        s.push('\n');
    }
    std::fs::write(path, s)
        .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", path.display())))
}

fn prepare_out(dir: &Path) -> Result<(), Failure> {
    std::fs::create_dir_all(dir)
        .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", dir.display())))
}

fn plot_err(e: crate::plot::PlotError) -> Failure {
    Failure::Runtime(e.into())
}

/// `softtouch sweep`.
pub async fn run_sweep(cmd: SweepCommand, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let (common, rows_wanted): (SweepArgs, Vec<(String, ModelConfig)>) = match cmd {
        SweepCommand::Alpha { common, alphas } => {
            let (base, _) = common.model.configs()?;
            if let Some(a) = alphas.iter().find(|a| !(a.is_finite() && **a >= 0.0)) {
                return Err(Failure::BadInput(anyhow!(
                    "--alphas: {a} is not a finite value ≥ 0"
                )));
            }
            let mut rows = vec![(
                "ConvNet".to_owned(),
                ModelConfig {
                    kind: ModelKind::Convnet,
                    ..base
                },
            )];
            rows.extend(alphas.iter().map(|&alpha| {
                (
                    format!("SVAE α={alpha}"),
                    ModelConfig {
                        kind: ModelKind::Svae,
                        alpha,
                        ..base
                    },
                )
            }));
            rows.push((
                "VAE".to_owned(),
                ModelConfig {
                    kind: ModelKind::Vae,
                    ..base
                },
            ));
            (common, rows)
        }
        SweepCommand::Latent { common, latents } => {
            let (base, _) = common.model.configs()?;
            if let Some(l) = latents.iter().find(|l| !(1..=1024).contains(*l)) {
                return Err(Failure::BadInput(anyhow!(
                    "--latents: {l} is not in 1..=1024"
                )));
            }
            let rows = latents
                .iter()
                .map(|&latent| {
                    (
                        format!("SVAE latent={latent}"),
                        ModelConfig {
                            kind: ModelKind::Svae,
                            latent,
                            ..base
                        },
                    )
                })
                .collect();
            (common, rows)
        }
    };
    let (base, train) = common.model.configs()?;
    let store = open_existing(db).await?;
    let splits = load(&store, &common.dataset, &base.preprocess, out).await?;
    store.close().await;
    prepare_out(&common.out)?;
    let mut rows = Vec::new();
    for (label, config) in rows_wanted {
        rows.push(train_row(label, config, &train, &splits, out)?.0);
    }
    writeln!(
        out,
        "\n{:<18} {:>11} {:>9} {:>9}  s/epoch",
        "model", "image MSE", "R² avg", "R² min"
    )
    .map_err(io_failure)?;
    for r in &rows {
        writeln!(
            out,
            "{:<18} {:>11} {:>9} {:>9}  {:.1}",
            r.label,
            fmt_opt(r.test.image_mse, |v| format!("{v:.3e}")),
            fmt_opt(r.test.r2_mean, |v| format!("{:.2}%", v * 100.0)),
            fmt_opt(r.test.r2_min(), |v| format!("{:.2}%", v * 100.0)),
            r.seconds_per_epoch
        )
        .map_err(io_failure)?;
    }
    let is_alpha = rows.iter().any(|r| r.config.kind == ModelKind::Convnet);
    let stem = if is_alpha {
        "sweep-alpha"
    } else {
        "sweep-latent"
    };
    let csv = common.out.join(format!("{stem}.csv"));
    write_csv(&csv, &rows)?;
    let png = common.out.join(format!("{stem}.png"));
    let svae: Vec<&Row> = rows
        .iter()
        .filter(|r| r.config.kind == ModelKind::Svae)
        .collect();
    let x = |r: &Row| {
        if is_alpha {
            r.config.alpha.max(1e-9).log10()
        } else {
            (r.config.latent as f64).log2()
        }
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
    xy_chart(
        &png,
        &XyChart {
            title: if is_alpha {
                "SVAE: accuracy and reconstruction against α"
            } else {
                "SVAE: accuracy and reconstruction against latent size"
            },
            x_label: if is_alpha {
                "log10 α"
            } else {
                "log2 latent dimensions"
            },
            y_label: "R² / image MSE × 10",
            series: &series,
        },
        (900, 560),
    )
    .map_err(plot_err)?;
    writeln!(out, "wrote {} and {}", csv.display(), png.display()).map_err(io_failure)?;
    Ok(())
}

/// `softtouch bench model`.
pub async fn run_bench_model(
    args: BenchModelArgs,
    db: &Path,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let (base, train) = args.model.configs()?;
    let mut wanted = Vec::new();
    for &size_px in &args.sizes {
        for &width in &args.widths {
            for &latent in &args.latents {
                let config = ModelConfig {
                    width,
                    latent,
                    preprocess: Preprocess {
                        size_px,
                        ..base.preprocess
                    },
                    ..base
                };
                let problems = config.problems();
                if !problems.is_empty() {
                    return Err(Failure::BadInput(anyhow!(
                        "size {size_px}, width {width}, latent {latent}: {}",
                        problems.join("; ")
                    )));
                }
                wanted.push(config);
            }
        }
    }
    if wanted.is_empty() {
        return Err(Failure::BadInput(anyhow!(
            "nothing to measure: give --sizes, --widths and --latents"
        )));
    }
    let store = open_existing(db).await?;
    prepare_out(&args.out)?;
    let frame = models::first_test_frame(&store, &args.dataset).await?;
    let mut rows = Vec::new();
    let mut loaded: Option<(usize, Splits)> = None;
    for config in wanted {
        let size = config.preprocess.size_px;
        if loaded.as_ref().is_none_or(|(s, _)| *s != size) {
            loaded = Some((
                size,
                load(&store, &args.dataset, &config.preprocess, out).await?,
            ));
        }
        let Some((_, splits)) = loaded.as_ref() else {
            continue;
        };
        let label = format!("{size}px w{} l{}", config.width, config.latent);
        let (mut row, trained) = train_row(label, config, &train, splits, out)?;
        let image = splits
            .test
            .first()
            .map(|e| e.image.clone())
            .unwrap_or_default();
        let mut predictor = Predictor::new(trained.artifact);
        let latency = measure_latency(&predictor, &image, args.runs, 1)?;
        let (w, h, rgb) = &frame;
        let frame_latency = measure_frame_latency(&mut predictor, (*w, *h, rgb), args.runs, 1)?;
        row.latency_ms = Some(latency.median_ms);
        row.frame_latency_ms = Some(frame_latency.median_ms);
        writeln!(
            out,
            "   test R² {:.5} (min {:.5}), {:.1} s/epoch, {:.0} img/s, on one core: model {:.3} ms median / {:.3} ms p95, {w}×{h} frame → wrench {:.3} ms median / {:.3} ms p95",
            row.test.r2_mean.unwrap_or(f64::NAN),
            row.test.r2_min().unwrap_or(f64::NAN),
            row.seconds_per_epoch,
            row.images_per_s,
            latency.median_ms,
            latency.p95_ms,
            frame_latency.median_ms,
            frame_latency.p95_ms
        )
        .map_err(io_failure)?;
        rows.push(row);
    }
    store.close().await;
    writeln!(
        out,
        "\n{:<16} {:>9} {:>9} {:>9} {:>9} {:>11} {:>11}",
        "input/width/lat", "R² avg", "R² min", "s/epoch", "img/s", "model ms", "frame ms"
    )
    .map_err(io_failure)?;
    for r in &rows {
        writeln!(
            out,
            "{:<16} {:>9} {:>9} {:>9.1} {:>9.0} {:>11} {:>11}",
            r.label,
            fmt_opt(r.test.r2_mean, |v| format!("{v:.5}")),
            fmt_opt(r.test.r2_min(), |v| format!("{v:.5}")),
            r.seconds_per_epoch,
            r.images_per_s,
            fmt_opt(r.latency_ms, |v| format!("{v:.3}")),
            fmt_opt(r.frame_latency_ms, |v| format!("{v:.3}"))
        )
        .map_err(io_failure)?;
    }
    let csv = args.out.join("bench-model.csv");
    write_csv(&csv, &rows)?;
    let png = args.out.join("bench-model.png");
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
        &png,
        &XyChart {
            title: "Accuracy costs time: test R² against inference latency (batch 1, one core)",
            x_label: "latency, ms",
            y_label: "test R² (mean of 6 axes)",
            series: &series,
        },
        (900, 560),
    )
    .map_err(plot_err)?;
    writeln!(out, "wrote {} and {}", csv.display(), png.display()).map_err(io_failure)?;
    Ok(())
}
