//! `softtouch report`: the page is [`softtouch_lab::report`]'s; this verb parses, calls and
//! writes the file.

use super::{Failure, io_failure};
use anyhow::anyhow;
use clap::Args;
use softtouch_lab::report::{self, DEFAULT_SCATTER_POINTS, ReportError, ReportOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `softtouch report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// The HTML file to write (one self-contained page).
    #[arg(long)]
    pub out: PathBuf,
    /// Only these runs, comma-separated (and the datasets drawing on them).
    #[arg(long, value_delimiter = ',')]
    pub runs: Option<Vec<i64>>,
    /// Only these models, comma-separated names.
    #[arg(long, value_delimiter = ',')]
    pub models: Option<Vec<String>>,
    /// A CSV of `softtouch sweep alpha|latent` or `softtouch bench model` (repeatable).
    #[arg(long)]
    pub sweep: Vec<PathBuf>,
    /// The `collection-sweep.csv` of `softtouch bench collection`.
    #[arg(long)]
    pub bench_collection: Option<PathBuf>,
    /// Test samples per model in the predicted-against-true plots at most (0: none).
    #[arg(long, default_value_t = DEFAULT_SCATTER_POINTS)]
    pub scatter_points: usize,
}

impl From<ReportError> for Failure {
    fn from(e: ReportError) -> Self {
        if e.is_bad_input() {
            Self::BadInput(e.into())
        } else {
            Self::Runtime(e.into())
        }
    }
}

/// `softtouch report`.
pub async fn run_report(
    args: ReportArgs,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    if db.file().is_some_and(|path| same_file(&args.out, path)) {
        return Err(Failure::BadInput(anyhow!(
            "--out {} is the database itself: name another file",
            args.out.display()
        )));
    }
    let started = Instant::now();
    let options = ReportOptions {
        runs: args.runs,
        models: args.models,
        sweeps: args.sweep,
        bench_collection: args.bench_collection,
        scatter_points: args.scatter_points,
    };
    let built = report::build(db, &options).await?;
    std::fs::write(&args.out, &built.html)
        .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", args.out.display())))?;
    let [runs, datasets, models] = built.counts;
    writeln!(
        out,
        "wrote {}: {:.2} MB, {runs} runs, {datasets} datasets, {models} models, in {:.2} s",
        args.out.display(),
        built.html.len() as f64 / 1e6,
        started.elapsed().as_secs_f64()
    )
    .map_err(io_failure)
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}
