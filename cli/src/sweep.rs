//! `softtouch sweep alpha|latent|finetune`: the paper's Table 1, Method S2's latent
//! sweep, and fine-tuning a model on growing subsets of another dataset (issue 18).
//! The grids and rows are [`softtouch_lab::experiments`]'; this verb parses, calls and prints.

use super::train::{ModelArgs, load};
use super::{Failure, io_failure, open_existing};
use anyhow::anyhow;
use clap::{Args, Subcommand};
use softtouch_collector::progress::TrainProgress;
use softtouch_lab::experiments::{self, Row, Sweep, fmt_opt};
use softtouch_lab::finetune::{self, Start};
use softtouch_lab::models;
use softtouch_trainer::{AXES, InitFrom, ModelArtifact, ModelConfig, TrainConfig};
use std::io::Write;
use std::path::PathBuf;

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
    /// Method S2: the SVAE with latent sizes 6 … 256, and each size's decoder
    /// traversal (sweep-latent-traversal-N.png).
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
    /// Fine-tuning: a stored model (say, trained on land) fine-tuned on the first n of
    /// a dataset's training samples (say, water) for each n, and the same model
    /// trained from scratch on them; test R² of each on the dataset's whole test split
    /// and the epochs it took.
    #[command(after_help = "Examples:
  softtouch sweep finetune --init land-svae --dataset water
  softtouch sweep finetune --init land-svae --dataset water --samples 0,300,3000 --no-scratch

n = 0 is the starting model as it is. Subsets are nested (the first n of one seeded
shuffle); validation gets the dataset's ratio of n (at least 2), as a lab with n
samples would have. Writes finetune.csv and finetune.png under --out.")]
    Finetune(FinetuneArgs),
}

/// `softtouch sweep finetune`.
#[derive(Debug, Args)]
pub struct FinetuneArgs {
    /// The stored model to start from (its settings and label normalisation too).
    #[arg(long, value_name = "MODEL")]
    pub init: String,
    /// The dataset to fine-tune on (its train split, subsampled; its test split whole).
    #[arg(long)]
    pub dataset: String,
    /// Training sample counts (0: the starting model untouched) [default:
    /// 0,100,300,1000,3000, those the train split holds]
    #[arg(long, value_delimiter = ',')]
    pub samples: Option<Vec<usize>>,
    /// Leave out the from-scratch rows (half the time).
    #[arg(long)]
    pub no_scratch: bool,
    /// The validation R² every axis must reach for "epochs to target".
    #[arg(long, default_value_t = 0.98)]
    pub target_r2: f64,
    /// Where the CSV and PNG go.
    #[arg(long, default_value = "finetune-out")]
    pub out: PathBuf,
    /// Maximum epochs per row.
    #[arg(long, default_value_t = 30)]
    pub epochs: usize,
    /// Batch size.
    #[arg(long, default_value_t = TrainConfig::default().batch_size)]
    pub batch: usize,
    /// Adam's initial learning rate.
    #[arg(long, default_value_t = TrainConfig::default().learning_rate)]
    pub lr: f64,
    /// Learning-rate factor per epoch.
    #[arg(long, default_value_t = 0.9)]
    pub lr_decay: f64,
    /// Early stopping: epochs without a better validation score (0: never).
    #[arg(long, default_value_t = 8)]
    pub patience: usize,
    /// Seed of the subsets, the shuffles and the scratch rows' initialisation.
    #[arg(long, default_value_t = TrainConfig::default().seed)]
    pub seed: u64,
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

/// `softtouch sweep`.
pub async fn run_sweep(
    cmd: SweepCommand,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let (sweep, common, rows_wanted): (Sweep, SweepArgs, Vec<(String, ModelConfig)>) = match cmd {
        SweepCommand::Finetune(args) => return run_finetune(args, db, out).await,
        SweepCommand::Alpha { common, alphas } => {
            let (base, _) = common.model.configs()?;
            if let Some(a) = alphas.iter().find(|a| !(a.is_finite() && **a >= 0.0)) {
                return Err(Failure::BadInput(anyhow!(
                    "--alphas: {a} is not a finite value ≥ 0"
                )));
            }
            let rows = experiments::alpha_grid(&base, &alphas);
            (Sweep::Alpha, common, rows)
        }
        SweepCommand::Latent { common, latents } => {
            let (base, _) = common.model.configs()?;
            if let Some(l) = latents.iter().find(|l| !(1..=1024).contains(*l)) {
                return Err(Failure::BadInput(anyhow!(
                    "--latents: {l} is not in 1..=1024"
                )));
            }
            let rows = experiments::latent_grid(&base, &latents);
            (Sweep::Latent, common, rows)
        }
    };
    let (base, train) = common.model.configs()?;
    let store = open_existing(db).await?;
    let splits = load(&store, &common.dataset, &base.preprocess, out).await?;
    store.close().await;
    experiments::prepare_out(&common.out)?;
    let mut rows = Vec::new();
    for (label, config) in rows_wanted {
        writeln!(out, "— {label}").map_err(io_failure)?;
        let (row, trained) = {
            let mut progress = TrainProgress::new(out, train.epochs, true);
            experiments::train_row(label, config, &train, &splits, &mut progress)?
        };
        if sweep == Sweep::Latent
            && let Some(png) =
                softtouch_lab::latent::sweep_traversal(&common.out, &trained, &splits)
                    .map_err(|e| Failure::Runtime(e.into()))?
        {
            writeln!(out, "wrote {}", png.display()).map_err(io_failure)?;
        }
        rows.push(row);
    }
    print_table(&rows, out)?;
    let csv = common.out.join(format!("{}.csv", sweep.stem()));
    experiments::write_csv(&csv, &rows)?;
    let png = common.out.join(format!("{}.png", sweep.stem()));
    experiments::plot_sweep(&png, sweep, &rows)?;
    writeln!(out, "wrote {} and {}", csv.display(), png.display()).map_err(io_failure)?;
    let best = rows
        .iter()
        .filter_map(|r| Some((r.label.as_str(), r.test.r2_mean?)))
        .max_by(|a, b| a.1.total_cmp(&b.1));
    let verb = match sweep {
        Sweep::Alpha => "sweep alpha",
        Sweep::Latent => "sweep latent",
    };
    super::results::Recorder::new(verb)
        .dataset(&common.dataset)
        .setting(
            "rows",
            rows.iter().map(|r| r.label.clone()).collect::<Vec<_>>(),
        )
        .setting("config", serde_json::to_value(base).unwrap_or_default())
        .setting("train", serde_json::to_value(train).unwrap_or_default())
        .table(&csv)
        .store(
            db,
            best.map_or_else(
                || format!("{} rows, none reads force", rows.len()),
                |(label, r2)| format!("{} rows; best test R² mean {r2:.4} ({label})", rows.len()),
            ),
            out,
        )
        .await
        .map(drop)
}

async fn run_finetune(
    args: FinetuneArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let train = TrainConfig {
        epochs: args.epochs,
        batch_size: args.batch,
        learning_rate: args.lr,
        lr_decay: args.lr_decay,
        patience: args.patience,
        seed: args.seed,
    };
    let mut problems = train.problems();
    if !(args.target_r2.is_finite() && args.target_r2 <= 1.0) {
        problems.push(format!(
            "--target-r2 {}: expected a finite value ≤ 1",
            args.target_r2
        ));
    }
    if !problems.is_empty() {
        return Err(Failure::BadInput(anyhow!(
            "invalid settings:\n  {}",
            problems.join("\n  ")
        )));
    }
    if let Some(asked) = &args.samples {
        finetune::check_requested(asked)?;
    }
    let store = open_existing(db).await?;
    let device = softtouch_trainer::backend::device()?;
    let bytes = models::artifact(&store, &args.init).await?;
    let artifact = ModelArtifact::from_bytes(&bytes, &device)?;
    let init = InitFrom::from_artifact(&args.init, &artifact)?;
    let splits = load(&store, &args.dataset, &init.config.preprocess, out).await?;
    store.close().await;
    let (sizes, left_out) = finetune::sizes_to_run(args.samples.as_deref(), &splits)?;
    if let Some(line) = left_out {
        writeln!(out, "{line}").map_err(io_failure)?;
    }
    experiments::prepare_out(&args.out)?;
    writeln!(
        out,
        "fine-tuning {} on `{}`: {} (epochs ≤ {}, lr {} × {} per epoch, patience {})",
        init.label,
        args.dataset,
        init.config.describe(),
        train.epochs,
        train.learning_rate,
        train.lr_decay,
        train.patience
    )
    .map_err(io_failure)?;
    let mut rows = Vec::new();
    for &n in &sizes {
        if n == 0 {
            rows.push(finetune::untouched_row(&artifact, &splits)?);
            continue;
        }
        let subset = finetune::subset(&splits, n, args.seed);
        let starts: &[Start] = if args.no_scratch {
            &[Start::FineTuned]
        } else {
            &[Start::FineTuned, Start::Scratch]
        };
        for &start in starts {
            writeln!(
                out,
                "— {n} samples ({} validation), {}",
                subset.val.len(),
                start.name()
            )
            .map_err(io_failure)?;
            let mut progress = TrainProgress::new(out, train.epochs, true);
            rows.push(finetune::train_row(
                &init,
                start,
                &train,
                &subset,
                args.target_r2,
                &mut progress,
            )?);
        }
    }
    writeln!(
        out,
        "\n{:>7} {:<10} {:>9} {:>9} {:>7} {:>5} {:>9} {:>7}   R² per axis ({})",
        "samples",
        "start",
        "R² mean",
        "R² min",
        "epochs",
        "best",
        "to target",
        "s",
        AXES.join(" ")
    )
    .map_err(io_failure)?;
    for r in &rows {
        let axes = r.test.r2.map_or_else(
            || "–".to_owned(),
            |x| {
                x.iter()
                    .map(|a| format!("{:.4}", a.r2))
                    .collect::<Vec<_>>()
                    .join(" ")
            },
        );
        writeln!(
            out,
            "{:>7} {:<10} {:>9} {:>9} {:>7} {:>5} {:>9} {:>7.1}   {axes}",
            r.samples,
            r.start.name(),
            fmt_opt(r.test.r2_mean, |v| format!("{v:.4}")),
            fmt_opt(r.test.r2_min(), |v| format!("{v:.4}")),
            r.epochs_run,
            r.best_epoch,
            r.epochs_to_target
                .map_or_else(|| "–".to_owned(), |e| e.to_string()),
            r.seconds
        )
        .map_err(io_failure)?;
    }
    writeln!(
        out,
        "(\"to target\": the first epoch whose validation R² reached {} on every axis; – never)",
        args.target_r2
    )
    .map_err(io_failure)?;
    let csv = args.out.join("finetune.csv");
    std::fs::write(&csv, finetune::rows_csv(&rows))
        .map_err(|source| Failure::Runtime(anyhow!("cannot write {}: {source}", csv.display())))?;
    if rows.iter().any(|r| r.samples > 0) {
        let png = args.out.join("finetune.png");
        finetune::plot(&png, &rows, -0.5)?;
        writeln!(out, "wrote {} and {}", csv.display(), png.display()).map_err(io_failure)?;
    } else {
        writeln!(out, "wrote {} (nothing trained: no plot)", csv.display()).map_err(io_failure)?;
    }
    let largest = rows
        .iter()
        .filter(|r| r.start.name() != "scratch")
        .max_by_key(|r| r.samples);
    super::results::Recorder::new("sweep finetune")
        .model(&args.init)
        .dataset(&args.dataset)
        .setting("samples", sizes.clone())
        .setting("no_scratch", args.no_scratch)
        .setting("target_r2", args.target_r2)
        .setting("epochs", args.epochs)
        .setting("batch", args.batch)
        .setting("lr", args.lr)
        .setting("lr_decay", args.lr_decay)
        .setting("patience", args.patience)
        .setting("seed", args.seed)
        .table(&csv)
        .store(
            db,
            largest.map_or_else(
                || format!("{} rows", rows.len()),
                |r| {
                    format!(
                        "{} rows; fine-tuned on {} samples: test R² mean {}",
                        rows.len(),
                        r.samples,
                        fmt_opt(r.test.r2_mean, |v| format!("{v:.4}"))
                    )
                },
            ),
            out,
        )
        .await
        .map(drop)
}

fn print_table(rows: &[Row], out: &mut dyn Write) -> Result<(), Failure> {
    writeln!(
        out,
        "\n{:<18} {:>11} {:>9} {:>9}  s/epoch",
        "model", "image MSE", "R² avg", "R² min"
    )
    .map_err(io_failure)?;
    for r in rows {
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
    Ok(())
}
