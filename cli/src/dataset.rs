//! `softtouch dataset create | list | stats | export | import`.

use super::{Failure, io_failure, open_existing};
use clap::{Args, Subcommand};
use softtouch_collector::dataset::import::ImportOptions;
use softtouch_collector::dataset::{self, DatasetError, Filters, NewDataset, SplitRatio, stats};
use softtouch_schemas::Medium;
use softtouch_store::Store;
use std::io::Write;
use std::path::PathBuf;

impl From<DatasetError> for Failure {
    fn from(e: DatasetError) -> Self {
        if e.is_bad_input() {
            Self::BadInput(e.into())
        } else {
            Self::Runtime(e.into())
        }
    }
}

/// The `dataset` verbs.
#[derive(Debug, Subcommand)]
pub enum DatasetCommand {
    /// Create a named dataset from runs: filter samples, split them train:val:test.
    #[command(
        after_help = "Splits: largest-remainder counts (each within one sample of its share), \
then a seeded shuffle assigns samples; the same runs, filters, ratio and seed give the same dataset. \
A split with a non-zero part that would get no sample is an error (it names the size needed); give \
it a zero part (e.g. --split 8:2:0) to leave it empty on purpose.\n\n\
Examples:\n  softtouch dataset create land-v1 --runs 1,2\n  \
softtouch dataset create water-small --runs 3 --split 8:1:1 --seed 7 --medium water --rod circle-10 --rod square-10\n  \
softtouch dataset create clean --runs 1 --max-force-n 10 --max-torque-nmm 600 --max-skew-ms 2 --min-readings 20"
    )]
    Create(CreateArgs),
    /// List the datasets with their split counts.
    #[command(after_help = "Example:\n  softtouch dataset list")]
    List,
    /// Counts per split, rod and medium; per-axis statistics; histograms as PNG.
    #[command(after_help = "Examples:\n  softtouch dataset stats land-v1\n  \
softtouch dataset stats land-v1 --out plots/   # writes plots/land-v1-histograms.png")]
    Stats {
        /// The dataset.
        name: String,
        /// Folder for NAME-histograms.png (created if missing).
        #[arg(long, default_value = ".")]
        out: PathBuf,
    },
    /// Export as images/*.png, labels.csv and manifest.json (pandas/PIL-ready).
    #[command(
        after_help = "Layout: images/000000.png ... (lossless PNG), labels.csv \
(image, fx_n fy_n fz_n [N], tx_nmm ty_nmm tz_nmm [N·mm], x_m z_m theta_rad, rod, medium, split, run, index), \
manifest.json (definition, run configs, versions, sha256 of every file). DIR must not exist or be empty; \
the export is written beside it and renamed at the end.\n\n\
Example:\n  softtouch dataset export land-v1 --out exports/land-v1\n\n\
In Python:\n  import pandas as pd; from PIL import Image\n  \
df = pd.read_csv('exports/land-v1/labels.csv')\n  \
img = Image.open('exports/land-v1/' + df.image[0])"
    )]
    Export {
        /// The dataset.
        name: String,
        /// The folder to create.
        #[arg(long)]
        out: PathBuf,
    },
    /// Import a folder (a softtouch export, or the paper's data_frame.csv layout) as new runs and a dataset.
    #[command(
        after_help = "A softtouch export comes back with its runs' configs, labels, order and splits \
(re-exporting it gives the same labels.csv and images). The paper's layout: data_frame.csv with the image \
file (relative to the folder) and Fx Fy Fz [N] Tx Ty Tz [N·mm], seven columns, optional header row; \
split by --split/--seed. All or nothing: any malformed line, missing image or bad value (named by line \
and column) imports nothing.\n\n\
Examples:\n  softtouch dataset import exports/land-v1\n  \
softtouch dataset import exports/land-v1 --name land-v1-copy\n  \
softtouch dataset import paper-data/ --name paper --medium water --rod tube --split 7:1:2 --seed 1"
    )]
    Import(ImportArgs),
}

/// Arguments of `dataset create`.
#[derive(Debug, Args)]
pub struct CreateArgs {
    /// Name (letters, digits, `-`, `_`, `.`).
    pub name: String,
    /// Runs to take samples from, comma-separated.
    #[arg(long, value_delimiter = ',', required = true, num_args = 1..)]
    pub runs: Vec<i64>,
    /// Split ratio train:val:test (whole numbers).
    #[arg(long, default_value = "7:1:2", value_parser = parse_ratio)]
    pub split: SplitRatio,
    /// Seed of the split.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Take rejected samples too (default: accepted only).
    #[arg(long)]
    pub include_rejected: bool,
    /// Only this medium (air or water).
    #[arg(long, value_parser = parse_medium)]
    pub medium: Option<Medium>,
    /// Only this rod (repeat for several).
    #[arg(long = "rod")]
    pub rods: Vec<String>,
    /// Only samples with |Fx|, |Fy|, |Fz| ≤ this, N.
    #[arg(long)]
    pub max_force_n: Option<f64>,
    /// Only samples with |Tx|, |Ty|, |Tz| ≤ this, N·mm.
    #[arg(long)]
    pub max_torque_nmm: Option<f64>,
    /// Only samples whose frame/reading skew is at most this, ms.
    #[arg(long)]
    pub max_skew_ms: Option<f64>,
    /// Only samples with at least this many force/torque readings in their window.
    #[arg(long)]
    pub min_readings: Option<u32>,
}

/// Arguments of `dataset import`.
#[derive(Debug, Args)]
pub struct ImportArgs {
    /// The folder.
    pub dir: PathBuf,
    /// Name of the new dataset (default: the export's name; for the paper's layout, the folder's name).
    #[arg(long)]
    pub name: Option<String>,
    /// Paper layout: medium of the samples.
    #[arg(long, default_value = "air", value_parser = parse_medium)]
    pub medium: Medium,
    /// Paper layout: rod of the samples.
    #[arg(long, default_value = "unknown")]
    pub rod: String,
    /// Paper layout: split ratio train:val:test.
    #[arg(long, default_value = "7:1:2", value_parser = parse_ratio)]
    pub split: SplitRatio,
    /// Paper layout: seed of the split.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

fn parse_ratio(s: &str) -> Result<SplitRatio, String> {
    s.parse()
}

fn parse_medium(s: &str) -> Result<Medium, String> {
    s.parse()
}

/// Run a `dataset` verb.
pub async fn run(
    cmd: DatasetCommand,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    // Import may fill a new database; every other verb needs an existing one.
    let store = if matches!(cmd, DatasetCommand::Import(_)) {
        Store::open(db).await?
    } else {
        open_existing(db).await?
    };
    let result = run_on(&store, cmd, out).await;
    store.close().await;
    result
}

async fn run_on(store: &Store, cmd: DatasetCommand, out: &mut dyn Write) -> Result<(), Failure> {
    match cmd {
        DatasetCommand::Create(a) => {
            let new = NewDataset {
                name: a.name,
                runs: a.runs,
                filters: Filters {
                    include_rejected: a.include_rejected,
                    medium: a.medium,
                    rods: a.rods,
                    max_force_n: a.max_force_n,
                    max_torque_nmm: a.max_torque_nmm,
                    max_skew_ms: a.max_skew_ms,
                    min_readings: a.min_readings,
                },
                ratio: a.split,
                seed: a.seed,
            };
            let info = dataset::create(store, &new).await?;
            let [tr, va, te] = info.split_counts;
            writeln!(
                out,
                "dataset {}: {} samples (train {tr}, val {va}, test {te}) from run(s) {}",
                info.name,
                info.sample_count,
                join(&info.definition.runs)
            )
            .map_err(io_failure)
        }
        DatasetCommand::List => {
            let all = dataset::list(store).await?;
            if all.is_empty() {
                return writeln!(out, "no datasets").map_err(io_failure);
            }
            let mut text = format!(
                "{:<24} {:>8} {:>8} {:>8} {:>8}  {:<8} {:>20}  {:<12} {}\n",
                "name", "samples", "train", "val", "test", "split", "seed", "runs", "created (UTC)"
            );
            for d in all {
                let [tr, va, te] = d.split_counts;
                text.push_str(&format!(
                    "{:<24} {:>8} {:>8} {:>8} {:>8}  {:<8} {:>20}  {:<12} {}\n",
                    d.name,
                    d.sample_count,
                    tr,
                    va,
                    te,
                    d.definition.split,
                    d.definition.seed,
                    join(&d.definition.runs),
                    d.created_at
                ));
            }
            out.write_all(text.as_bytes()).map_err(io_failure)
        }
        DatasetCommand::Stats { name, out: dir } => {
            let s = stats::compute(store, &name).await?;
            std::fs::create_dir_all(&dir).map_err(|e| {
                Failure::Runtime(
                    anyhow::Error::new(e).context(format!("cannot create {}", dir.display())),
                )
            })?;
            let png = dir.join(stats::histogram_file_name(&name));
            stats::write_histograms(&s, &png)?;
            let mut text = stats::render(&s);
            text.push_str(&format!("\nhistograms: {}\n", png.display()));
            out.write_all(text.as_bytes()).map_err(io_failure)
        }
        DatasetCommand::Export { name, out: dir } => {
            let started = std::time::Instant::now();
            let summary = dataset::export::export(store, &name, &dir, true).await?;
            let secs = started.elapsed().as_secs_f64();
            writeln!(
                out,
                "exported {} samples ({:.1} MB of images) to {} in {secs:.1} s ({:.0} samples/s)",
                summary.samples,
                summary.image_bytes as f64 / 1e6,
                summary.dir.display(),
                summary.samples as f64 / secs.max(1e-9)
            )
            .map_err(io_failure)
        }
        DatasetCommand::Import(a) => import(store, a, out).await,
    }
}

async fn import(store: &Store, a: ImportArgs, out: &mut dyn Write) -> Result<(), Failure> {
    let options = ImportOptions {
        name: a.name,
        medium: a.medium,
        rod: a.rod,
        ratio: a.split,
        seed: a.seed,
        progress: true,
    };
    let s = dataset::import::import(store, &a.dir, &options).await?;
    writeln!(
        out,
        "imported {} samples ({}) as run(s) {} and dataset {}",
        s.samples,
        s.layout.as_str(),
        join(&s.runs),
        s.dataset
    )
    .map_err(io_failure)
}

fn join(runs: &[i64]) -> String {
    runs.iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(",")
}
