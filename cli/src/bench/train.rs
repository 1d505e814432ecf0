//! `softtouch bench train`: training images/s of the SVAE at each input size and
//! width, where the step's time goes and how many cores it kept busy; with
//! `--torch PYTHON`, the PyTorch peer's same step, interleaved, and the ratio.

use crate::train::load;
use crate::{Failure, io_failure};
use anyhow::anyhow;
use clap::Args;
use softtouch_lab::bench_train::{Row, TorchRun, csv_text, median, parse_torch, render};
use softtouch_lab::host::Host;
use softtouch_trainer::train::{TrainBenchConfig, bench_train, synthetic_examples};
use softtouch_trainer::{ModelConfig, Preprocess};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

/// `softtouch bench train`.
#[derive(Debug, Args)]
pub struct BenchTrainArgs {
    /// Input sizes, px.
    #[arg(long, value_delimiter = ',', default_value = "32,64")]
    pub sizes: Vec<usize>,
    /// Encoder widths.
    #[arg(long, value_delimiter = ',', default_value = "16,8")]
    pub widths: Vec<usize>,
    /// Train on this stored dataset's training split (preprocessed at each size);
    /// default: 2240 images of uniform noise, what the PyTorch peer trains on.
    #[arg(long)]
    pub dataset: Option<String>,
    /// Images per step.
    #[arg(long, default_value_t = 64)]
    pub batch: usize,
    /// Untimed steps before each measurement.
    #[arg(long, default_value_t = 5)]
    pub warmup: usize,
    /// Timed steps per measurement.
    #[arg(long, default_value_t = 60)]
    pub steps: usize,
    /// Measurements per configuration (the median is reported); with --torch the
    /// order alternates between softtouch and PyTorch.
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
    /// A Python interpreter with PyTorch: also run the peer's same step.
    #[arg(long)]
    pub torch: Option<PathBuf>,
    /// The PyTorch peer.
    #[arg(long, default_value = "bench/torch_peer.py")]
    pub torch_script: PathBuf,
    /// Threads PyTorch may use (this machine's cores).
    #[arg(long, default_value_t = 2)]
    pub torch_threads: usize,
    /// Where `bench-train.csv` goes.
    #[arg(long, default_value = "bench-out")]
    pub out: PathBuf,
}

fn run_torch(
    args: &BenchTrainArgs,
    python: &Path,
    size: usize,
    width: usize,
) -> Result<TorchRun, Failure> {
    let output = Command::new(python)
        .arg(&args.torch_script)
        .args(["--sizes", &size.to_string(), "--widths", &width.to_string()])
        .args(["--batch", &args.batch.to_string()])
        .args(["--warmup", &args.warmup.to_string()])
        .args(["--steps", &args.steps.to_string()])
        .args(["--train-threads", &args.torch_threads.to_string()])
        .arg("--skip-infer")
        .output()
        .map_err(|e| {
            Failure::BadInput(anyhow!("--torch {}: cannot run it: {e}", python.display()))
        })?;
    if !output.status.success() {
        let err = String::from_utf8_lossy(&output.stderr);
        let tail: Vec<&str> = err.lines().rev().take(5).collect();
        return Err(Failure::Runtime(anyhow!(
            "the PyTorch peer ({} {}) failed ({}): {}",
            python.display(),
            args.torch_script.display(),
            output.status,
            tail.into_iter().rev().collect::<Vec<_>>().join(" | ")
        )));
    }
    parse_torch(&String::from_utf8_lossy(&output.stdout))
        .map_err(|e| Failure::Runtime(anyhow!("the PyTorch peer at {size}×{size}/{width}: {e}")))
}

pub(super) async fn run(
    args: BenchTrainArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    if args.sizes.is_empty() || args.widths.is_empty() || args.repeats == 0 {
        return Err(Failure::BadInput(anyhow!(
            "--sizes, --widths and --repeats: expected at least one of each"
        )));
    }
    if let Some(python) = &args.torch {
        if !args.torch_script.is_file() {
            return Err(Failure::BadInput(anyhow!(
                "--torch-script {}: not a file (the peer is bench/torch_peer.py in the repository: run from its root, or give its path)",
                args.torch_script.display()
            )));
        }
        writeln!(
            out,
            "PyTorch: {} {}",
            python.display(),
            args.torch_script.display()
        )
        .map_err(io_failure)?;
    }
    // A mistyped SOFTTOUCH_BACKEND or SOFTTOUCH_CONV is said before the header.
    softtouch_trainer::backend::device().map_err(|e| Failure::BadInput(anyhow!(e)))?;
    let host = Host::this();
    writeln!(
        out,
        "host: {}\nconvolutions and batch norm: {}",
        host.line(),
        softtouch_trainer::kernels::describe()
    )
    .map_err(io_failure)?;
    let store = match &args.dataset {
        Some(_) => Some(crate::open_existing(db).await?),
        None => None,
    };
    std::fs::create_dir_all(&args.out)
        .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", args.out.display())))?;
    let mut rows = Vec::new();
    for &size in &args.sizes {
        let preprocess = Preprocess {
            size_px: size,
            ..Preprocess::default()
        };
        let examples = match (&store, &args.dataset) {
            (Some(store), Some(name)) => load(store, name, &preprocess, out).await?.train,
            _ => synthetic_examples(
                &ModelConfig {
                    preprocess,
                    ..ModelConfig::default()
                },
                2240,
                1,
            ),
        };
        for &width in &args.widths {
            let config = ModelConfig {
                width,
                preprocess,
                ..ModelConfig::default()
            };
            let bench = TrainBenchConfig {
                batch: args.batch,
                warmup: args.warmup,
                steps: args.steps,
                seed: 1,
            };
            let mut row = Row {
                size,
                width,
                ours: Vec::new(),
                torch: Vec::new(),
            };
            for r in 0..args.repeats {
                // Alternate who goes first: the machine's state drifts.
                let torch_first = r % 2 == 1;
                if torch_first && let Some(python) = &args.torch {
                    row.torch.push(run_torch(&args, python, size, width)?);
                }
                let b = bench_train(&config, &examples, &bench)
                    .map_err(|e| Failure::BadInput(anyhow!("{size}×{size}/{width}: {e}")))?;
                row.ours.push(b);
                if !torch_first && let Some(python) = &args.torch {
                    row.torch.push(run_torch(&args, python, size, width)?);
                }
            }
            let ours = median(row.ours.iter().map(|b| b.images_per_s).collect());
            let torch = median(row.torch.iter().map(|t| t.images_per_s).collect());
            writeln!(
                out,
                "{size}×{size}/{width}: softtouch {:.0} img/s{}",
                ours.unwrap_or(f64::NAN),
                torch.map_or(String::new(), |t| format!(", PyTorch {t:.0} img/s"))
            )
            .map_err(io_failure)?;
            rows.push(row);
        }
    }
    if let Some(store) = store {
        store.close().await;
    }
    let table = render(&rows, args.batch);
    out.write_all(table.as_bytes()).map_err(io_failure)?;
    let csv = args.out.join("bench-train.csv");
    std::fs::write(&csv, csv_text(&rows, &host))
        .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", csv.display())))?;
    writeln!(out, "wrote {}", csv.display()).map_err(io_failure)?;
    Ok(())
}
