//! `softtouch bench collection|ingest|model|train|grasp`: `grasp` in `grasp.rs`, `train`
//! in `train.rs`, the rest here.

mod grasp;
mod train;

pub use grasp::BenchGraspArgs;
pub use train::BenchTrainArgs;

use crate::train::{ModelArgs, load};
use crate::{Failure, io_failure};
use anyhow::anyhow;
use clap::Args;
use clap::Subcommand;
use softtouch_collector::collect::bench::{Breakdown, SweepPoint, sweep, sweep_point};
use softtouch_collector::collect::bench_out::{
    db_size_line, sweep_table, time_ingest, write_sweep_files,
};
use softtouch_collector::configs;
use softtouch_collector::progress::TrainProgress;
use softtouch_lab::experiments::{self, fmt_opt};
use softtouch_store::SyncStore;
use softtouch_trainer::Splits;
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// The force loop on the simulated soft grasp: settling time, overshoot and
    /// steady-state error (estimate and truth) against K (below Λ/2 too), δ, camera
    /// rate and model; a table, CSV and PNG. `--wall-clock` also runs it on real time.
    #[command(after_help = "Examples:
  softtouch bench grasp --model air-svae
  softtouch bench grasp --model air-svae,air-small --gains 0.3,0.75,1.5 --wall-clock")]
    Grasp(BenchGraspArgs),
    /// Accuracy costs time, for the model: over input size, encoder width and latent
    /// size, train on a dataset and report test R², training time per epoch and
    /// inference latency at batch 1 on one core; a table, CSV and a PNG of R² against
    /// latency.
    #[command(after_help = "Examples:
  softtouch bench model --dataset air
  softtouch bench model --dataset air --sizes 32,64 --widths 8,16 --latents 32 --epochs 10")]
    Model(BenchModelArgs),
    /// Training throughput: images/s of the SVAE's training step (batch, forward and
    /// loss, backward, Adam) at each input size and width, where the step's time goes,
    /// the GFLOP/s and the cores kept busy; with `--torch PYTHON`, the PyTorch peer's
    /// same step run interleaved, and softtouch's images/s over PyTorch's.
    #[command(after_help = "Examples:
  softtouch bench train
  softtouch bench train --sizes 32 --widths 16 --steps 30 --repeats 1
  softtouch bench train --torch .venv-torch/bin/python --repeats 5
  SOFTTOUCH_CONV=burn softtouch bench train --torch .venv-torch/bin/python

The PyTorch peer is bench/torch_peer.py (bench/README.md says how to install
PyTorch); --torch-script points elsewhere. CI does not run PyTorch.
SOFTTOUCH_CONV=burn trains with burn's own convolutions and batch norm instead of
softtouch's kernels, to compare the two.")]
    Train(BenchTrainArgs),
    /// Accuracy costs time: sweep settle time and force/torque window on the simulated
    /// scene (whose true wrench is known), each fixed settle and the settle ended by the
    /// signal (bounded by the rig's settle_s); print label error against samples per
    /// hour, and write a CSV and PNG plots. Also reports where a sample's time goes.
    #[command(after_help = "Examples:
  softtouch bench collection
  softtouch bench collection --samples 100 --settle 0,0.1,0.3 --window 0.01,0.05 --out bench-out

Runs on virtual time; the scratch database DIR/bench.db is replaced on each run.")]
    Collection {
        /// Samples per point.
        #[arg(long, default_value_t = 40)]
        samples: u64,
        /// Settle times to try, s.
        #[arg(long, value_delimiter = ',', default_value = "0,0.05,0.1,0.2,0.3,0.5")]
        settle: Vec<f64>,
        /// Window lengths to try, s.
        #[arg(long, value_delimiter = ',', default_value = "0.005,0.02,0.05,0.1")]
        window: Vec<f64>,
        /// Rig config (default: the embedded simulated rig).
        #[arg(long)]
        rig: Option<PathBuf>,
        /// Scene (default: the embedded on-land scene).
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Where the CSV, plots and scratch database go.
        #[arg(long, default_value = "bench-out")]
        out: PathBuf,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Store ingest: samples per second written with 640×480 frames, with and without
    /// PNG encoding; then 1, 2 and 4 rigs writing one store at once (each its own run,
    /// raw frames PNG-encoded on its writer thread), on SQLite and, with `--postgres`, on
    /// a PostgreSQL server beside it.
    #[command(after_help = "Examples:
  softtouch bench ingest --samples 2000
  softtouch bench ingest --samples 500 --rigs 1,2,4 --postgres postgres://lab@db.lab/postgres

--postgres names a server database the user may create databases from: each case writes
a new database of its own (softtouch_bench_PID_RIGS), left there for a look.")]
    Ingest {
        /// Samples to write per case (per rig in the several-rigs table).
        #[arg(long, default_value_t = 2000)]
        samples: u64,
        /// Where the scratch database goes.
        #[arg(long, default_value = "bench-out")]
        out: PathBuf,
        /// Rig counts for the several-rigs table (empty: no table).
        #[arg(long, value_delimiter = ',', default_value = "1,2,4")]
        rigs: Vec<usize>,
        /// A PostgreSQL server to run the several-rigs table on too.
        #[arg(long, value_parser = crate::db::DbTargetParser)]
        postgres: Option<softtouch_store::DbTarget>,
    },
}

fn scratch_db(out: &Path) -> Result<PathBuf, Failure> {
    std::fs::create_dir_all(out)
        .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", out.display())))?;
    let db = out.join("bench.db");
    for suffix in ["", "-wal", "-shm"] {
        let p = PathBuf::from(format!("{}{suffix}", db.display()));
        if p.exists() {
            std::fs::remove_file(&p)
                .map_err(|e| Failure::Runtime(anyhow!("cannot remove {}: {e}", p.display())))?;
        }
    }
    Ok(db)
}

pub async fn run(
    cmd: BenchCommand,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    match cmd {
        BenchCommand::Grasp(args) => grasp::run(args, db, out).await,
        BenchCommand::Model(args) => run_bench_model(args, db, out).await,
        BenchCommand::Train(args) => train::run(args, db, out).await,
        BenchCommand::Collection {
            samples,
            settle,
            window,
            rig,
            scene,
            out: dir,
            seed,
        } => {
            if samples < 2 {
                return Err(Failure::BadInput(anyhow!("--samples: expected at least 2")));
            }
            for (flag, v) in settle
                .iter()
                .map(|v| ("--settle", v))
                .chain(window.iter().map(|v| ("--window", v)))
            {
                if !(v.is_finite() && *v >= 0.0) || (flag == "--window" && *v <= 0.0) {
                    return Err(Failure::BadInput(anyhow!(
                        "{flag}: {v} is not a valid time in seconds"
                    )));
                }
            }
            let resolved = configs::resolve(rig.as_deref(), scene.as_deref())?;
            let db = scratch_db(&dir)?;
            let store = SyncStore::open(&db)?;
            tokio::time::pause(); // virtual time for the simulated rig
            let default_point = (
                resolved.rig.procedure.settle_s,
                resolved.rig.procedure.ft_window_s,
            );
            let (_, breakdown) = sweep_point(
                &store,
                &resolved.rig,
                &resolved.scene,
                seed,
                default_point.0,
                default_point.1,
                samples.max(100),
            )
            .await
            .map_err(|e| Failure::Runtime(e.into()))?;
            let points = sweep(
                &store,
                &resolved.rig,
                &resolved.scene,
                seed,
                (&settle, &window),
                samples,
                |p| eprintln!("{}", p.line()),
            )
            .await
            .map_err(|e| Failure::Runtime(e.into()))?;
            store.close();
            report_collection(&dir, &points, &breakdown, default_point, out)
        }
        BenchCommand::Ingest {
            samples,
            out: dir,
            rigs,
            postgres,
        } => {
            if samples == 0 || rigs.iter().any(|&r| r == 0 || r > 64) {
                return Err(Failure::BadInput(anyhow!(
                    "--samples and --rigs: expected at least 1 (and at most 64 rigs)"
                )));
            }
            let server = postgres
                .map(|target| match target {
                    softtouch_store::DbTarget::Postgres(url) => Ok(url.expose().to_owned()),
                    softtouch_store::DbTarget::File(_) => Err(Failure::BadInput(anyhow!(
                        "--postgres: expected postgres://USER@HOST[:PORT]/DATABASE"
                    ))),
                })
                .transpose()?;
            let db = scratch_db(&dir)?;
            let store = SyncStore::open(&db)?;
            let timed = time_ingest(&store, samples);
            store.close();
            let mut text = timed.map_err(|e| Failure::Runtime(e.into()))?;
            text.push_str(&db_size_line(&db));
            out.write_all(text.as_bytes()).map_err(io_failure)?;
            if !rigs.is_empty() {
                several_rigs(&dir, &rigs, samples, server.as_deref(), out).await?;
            }
            Ok(())
        }
    }
}

/// The several-rigs table: total and per-rig samples/s for each rig count, SQLite
/// (a new file per case) and PostgreSQL (a new database per case) side by side.
async fn several_rigs(
    dir: &Path,
    rigs: &[usize],
    samples: u64,
    server: Option<&str>,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    use softtouch_collector::collect::bench_out::time_rigs;
    use softtouch_store::{DbTarget, Store};
    let mut text = format!(
        "\nseveral rigs into one store ({samples} samples of 640×480 each, raw RGB → PNG):\n\
         engine      rigs   samples   seconds   samples/s   per rig/s\n"
    );
    for &n in rigs {
        let mut targets = vec![("SQLite", DbTarget::File(scratch_db(dir)?))];
        if let Some(server) = server {
            let name = format!("softtouch_bench_{}_{n}", std::process::id());
            targets.push((
                "PostgreSQL",
                Store::create_postgres_database(server, &name).await?,
            ));
        }
        for (engine, target) in targets {
            let t = target.clone();
            // The error as text: it crosses a thread.
            let secs = tokio::task::spawn_blocking(move || {
                time_rigs(&t, n, samples).map_err(|e| e.to_string())
            })
            .await
            .map_err(|e| Failure::Runtime(anyhow!("the bench's thread: {e}")))?
            .map_err(|e| Failure::Runtime(anyhow!("{engine}, {n} rigs: {e}")))?;
            let total = samples * n as u64;
            let line = format!(
                "{engine:<10}  {n:>4}  {total:>8}  {secs:>8.2}  {:>10.0}  {:>10.0}\n",
                total as f64 / secs,
                samples as f64 / secs
            );
            eprint!("{line}");
            text.push_str(&line);
        }
    }
    out.write_all(text.as_bytes()).map_err(io_failure)
}

fn report_collection(
    dir: &Path,
    points: &[SweepPoint],
    b: &Breakdown,
    default_point: (f64, f64),
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let mut table = sweep_table(points, b, default_point);
    let written = write_sweep_files(dir, points).map_err(|e| Failure::Runtime(e.into()))?;
    for p in written {
        table.push_str(&format!("wrote {}\n", p.display()));
    }
    out.write_all(table.as_bytes()).map_err(io_failure)
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

/// `softtouch bench model`: train each point of the grid, then time it on one core.
async fn run_bench_model(
    args: BenchModelArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let (base, train) = args.model.configs()?;
    let wanted = experiments::model_grid(&base, &args.sizes, &args.widths, &args.latents)?;
    let store = crate::open_existing(db).await?;
    experiments::prepare_out(&args.out)?;
    let (w, h, rgb) = softtouch_lab::models::first_test_frame(&store, &args.dataset).await?;
    let mut rows = Vec::new();
    let mut loaded: Option<(usize, Splits)> = None;
    for (label, config) in wanted {
        let size = config.preprocess.size_px;
        if loaded.as_ref().is_none_or(|(s, _)| *s != size) {
            let splits = load(&store, &args.dataset, &config.preprocess, out).await?;
            loaded = Some((size, splits));
        }
        let Some((_, splits)) = loaded.as_ref() else {
            continue;
        };
        writeln!(out, "— {label}").map_err(io_failure)?;
        let (mut row, trained) = {
            let mut progress = TrainProgress::new(out, train.epochs, true);
            experiments::train_row(label, config, &train, splits, &mut progress)?
        };
        let image = splits
            .test
            .first()
            .map(|e| e.image.clone())
            .unwrap_or_default();
        let (latency, frame_latency) =
            experiments::measure_row(&mut row, trained, &image, (w, h, &rgb), args.runs)?;
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
    experiments::write_csv(&csv, &rows)?;
    let png = args.out.join("bench-model.png");
    experiments::plot_bench_model(&png, &rows)?;
    writeln!(out, "wrote {} and {}", csv.display(), png.display()).map_err(io_failure)?;
    Ok(())
}
