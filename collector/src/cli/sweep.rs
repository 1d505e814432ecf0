//! `softtouch sweep alpha|latent`: the paper's Table 1 and Method S2's latent sweep.
//! The grids and rows are [`crate::experiments`]'; this verb parses, calls and prints.

use super::train::{ModelArgs, load};
use super::{Failure, io_failure, open_existing};
use crate::experiments::{self, Row, Sweep, fmt_opt};
use crate::progress::TrainProgress;
use anyhow::anyhow;
use clap::{Args, Subcommand};
use softtouch_trainer::ModelConfig;
use std::io::Write;
use std::path::{Path, PathBuf};

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

/// `softtouch sweep`.
pub async fn run_sweep(cmd: SweepCommand, db: &Path, out: &mut dyn Write) -> Result<(), Failure> {
    let (sweep, common, rows_wanted): (Sweep, SweepArgs, Vec<(String, ModelConfig)>) = match cmd {
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
        let mut progress = TrainProgress::new(out, train.epochs, true);
        rows.push(experiments::train_row(label, config, &train, &splits, &mut progress)?.0);
    }
    print_table(&rows, out)?;
    let csv = common.out.join(format!("{}.csv", sweep.stem()));
    experiments::write_csv(&csv, &rows)?;
    let png = common.out.join(format!("{}.png", sweep.stem()));
    experiments::plot_sweep(&png, sweep, &rows)?;
    writeln!(out, "wrote {} and {}", csv.display(), png.display()).map_err(io_failure)?;
    Ok(())
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
