//! The `softtouch` command line: one module per verb group (a file, or a folder with a
//! file per verb: `grasp/`, `bench/`), each parsing its arguments,
//! calling the collector and lab libraries and printing; exit codes. It holds no
//! experiment, store or device logic of its own.
//!
//! **Verbs stay thin.** A verb parses, builds one settings value, calls one library
//! function and prints; the experiment's branches (simulator or rig, one model or
//! several, new or resumed) are the library's. Verbs grew into experiment hubs twice,
//! so a test (`house_rules`, in every `cargo test` and CI) holds every file here to
//! [`house_rules::LINES_PER_FILE`] lines; an exception must be listed there with its
//! reason.
//!
//! Exit codes: 0 success; 1 runtime failure (a device, the database, I/O); 2 bad input
//! (arguments, config or scene files, a missing database or run).

pub mod bench;
pub mod collect;
pub mod config;
pub mod dataset;
pub mod db;
pub mod eval;
pub mod grasp;
#[cfg(test)]
pub(crate) mod house_rules;
pub mod latent;
pub mod live;
pub mod report;
pub mod results;
pub mod rig;
pub mod runs;
pub(crate) mod signals;
pub mod sim;
pub mod sweep;
pub mod train;
pub mod transfer;

use clap::{Parser, Subcommand};

/// Exit code for success.
pub const EXIT_OK: u8 = 0;
/// Exit code for a runtime failure.
pub const EXIT_RUNTIME: u8 = 1;
/// Exit code for bad input.
pub const EXIT_BAD_INPUT: u8 = 2;

const EXIT_CODES: &str = "Exit codes: 0 success, 1 runtime failure (device, database, I/O), 2 bad input \
(arguments, config or scene file, missing database or run).";

/// softtouch: collect visuo-tactile data with a robot, curate it, and train a soft
/// finger to read force and torque from its camera.
#[derive(Debug, Parser)]
#[command(
    name = "softtouch",
    version,
    about = "softtouch: collect visuo-tactile data with a robot, curate it, and train a soft finger to read force and torque from its camera.",
    after_help = EXIT_CODES
)]
pub struct Cli {
    /// The database: a SQLite file (the default), or a PostgreSQL server as
    /// postgres://USER[:PASSWORD]@HOST[:PORT]/DATABASE[?sslmode=...] (docs/postgres.md).
    #[arg(
        long,
        global = true,
        default_value = "softtouch.db",
        env = "SOFTTOUCH_DB",
        // --help would print the variable's value: a URL may hold a password.
        hide_env_values = true,
        value_parser = db::DbTargetParser
    )]
    pub db: softtouch_store::DbTarget,

    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The verbs.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Show or check rig and scene configs.
    #[command(subcommand)]
    Config(config::ConfigCommand),
    /// Manage the database.
    #[command(subcommand)]
    Db(db::DbCommand),
    /// Curate datasets: create (filters, 7:1:2 splits), list, stats, export, import.
    #[command(subcommand)]
    Dataset(dataset::DatasetCommand),
    /// List runs with their sample counts and status.
    #[command(after_help = "Example:\n  softtouch runs\n  softtouch --db lab.db runs")]
    Runs,
    /// Collect samples: press the finger on rods at random poses, record frames and
    /// force/torque, store each sample as it is taken.
    Collect(collect::CollectArgs),
    /// Show runs in detail: counts, rate and the latest events.
    #[command(after_help = "Examples:\n  softtouch status\n  softtouch status 3")]
    Status {
        /// Only this run (with more of its events).
        run: Option<i64>,
    },
    /// Look at the simulated scene.
    #[command(subcommand)]
    Sim(sim::SimCommand),
    /// Force-controlled grasping with the learned touch (Algorithm 1) on the simulated
    /// soft-finger Hand-E.
    #[command(subcommand)]
    Grasp(grasp::GraspCommand),
    /// Watch the model's estimate at camera rate beside the force/torque sensor; on a
    /// simulated arm (or with `--press`) the arm runs a scripted press. Terminal lines
    /// and a CSV of every frame.
    #[command(after_help = "Examples:
  softtouch live --model air-svae                       # simulated rig: scripted press
  softtouch live --model air-svae --rig lab.toml --duration-s 30   # real rig: watch only")]
    Live(live::LiveArgs),
    /// Check the rig: exercise every configured device briefly, print a pass/fail table.
    #[command(subcommand)]
    Rig(rig::RigCommand),
    /// Measure: what accuracy costs in time, where the time goes, store ingest.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// Train a model (SVAE, VAE or ConvNet) on a dataset; store it with its metrics.
    #[command(after_help = "Examples:
  softtouch train --dataset air
  softtouch train --dataset air --model convnet --epochs 20 --name air-cnn
  softtouch train --dataset air --alpha 10 --beta 0.1 --latent 64 --name air-a10 --out air-a10.stm
  softtouch train --dataset water --init land-svae     # fine-tune a land model on water data

Interrupted? Run the same command again: it resumes from the last epoch's checkpoint.")]
    Train(train::TrainArgs),
    /// Evaluate a model: R² per axis, image MSE, error spread per force/torque range.
    #[command(after_help = "Examples:
  softtouch eval air-svae
  softtouch eval air-svae --dataset water --split all
  softtouch eval model.stm --dataset air")]
    Eval(eval::EvalArgs),
    /// Land to water: one model's R² and RMSE per axis on a land and a water test
    /// split, how alike its latents are for paired deformations (cosine per pair,
    /// linear CKA, MMD with a permutation p-value), and models trained on land, water
    /// and both, each tested on both; a CSV.
    #[command(after_help = "Examples:
  softtouch collect --samples 6000 --seed 1                                  # run 1, land
  softtouch collect --scene scenes/water.toml --poses-from 1                 # run 2, the same poses underwater
  softtouch dataset create land --runs 1 && softtouch dataset create water --runs 2
  softtouch train --dataset land && softtouch train --dataset water
  softtouch transfer --model land-svae --land land --water water --water-model water-svae

The water runs must be collected with --poses-from a run of the land dataset: pairs are
the water test samples whose partner (same run index) is in the land dataset.")]
    Transfer(transfer::TransferArgs),
    /// Latent figures (Figure 3): the correlation map of the latent dimensions, the
    /// latent-to-wrench correlation map, decoder traversals with one latent varied over
    /// [−5, 5], and with --water the latent values of paired land and water instances.
    #[command(after_help = "Examples:
  softtouch latent land-svae --dataset land
  softtouch latent land-svae --dataset land --water water        # + paired instances
  softtouch latent land-l6 land-l16 land-l32 --dataset land       # one set per latent size
  softtouch latent land-svae --dataset land --dims 0,5,9 --span 3

Writes MODEL-latent-correlation.png, MODEL-latent-wrench.png, MODEL-traversal.png,
MODEL-paired.png (with --water) and MODEL-latent.csv under --out (latent-out).")]
    Latent(latent::LatentArgs),
    /// List stored models with their test metrics.
    #[command(after_help = "Example:\n  softtouch models")]
    Models,
    /// Sweep a setting and train once per value: α (the paper's Table 1), latent size,
    /// or the training samples of a fine-tuning.
    #[command(subcommand)]
    Sweep(sweep::SweepCommand),
    /// Write one self-contained HTML page of the database: runs, datasets, models,
    /// sweeps (read-only).
    #[command(after_help = "Examples:
  softtouch report --out report.html
  softtouch report --out run3.html --runs 3 --models land-v1-svae
  softtouch report --out report.html --sweep sweep-out/sweep-alpha.csv --bench-collection bench-out/collection-sweep.csv")]
    Report(report::ReportArgs),
    /// The experiment verbs' stored results (with what ran, on what, and which
    /// software) and the grasp sessions: list them, show one, export a trial's trace.
    #[command(after_help = "Examples:
  softtouch results                      # the same as `results list`
  softtouch results show 4
  softtouch results show 4 --table grasp-follow.csv > follow.csv
  softtouch results trace 12 --out trial-12.csv")]
    Results {
        /// What to do (default: list).
        #[command(subcommand)]
        command: Option<results::ResultsCommand>,
    },
}

/// A failed command, with its class for the exit code.
#[derive(Debug)]
pub enum Failure {
    /// The user's input is wrong (exit 2).
    BadInput(anyhow::Error),
    /// Something failed while running (exit 1).
    Runtime(anyhow::Error),
}

impl Failure {
    /// The process exit code.
    #[must_use]
    pub const fn exit_code(&self) -> u8 {
        match self {
            Self::BadInput(_) => EXIT_BAD_INPUT,
            Self::Runtime(_) => EXIT_RUNTIME,
        }
    }

    /// The error to print.
    #[must_use]
    pub const fn error(&self) -> &anyhow::Error {
        match self {
            Self::BadInput(e) | Self::Runtime(e) => e,
        }
    }
}

/// An error and its causes on one line, each said once: a cause whose text an outer
/// message already quotes (as `"cannot open …: {source}"` does) is not repeated.
#[must_use]
pub fn error_text(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if text.is_empty() || out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

impl From<softtouch_lab::grasp::trials::TrialsError> for Failure {
    fn from(e: softtouch_lab::grasp::trials::TrialsError) -> Self {
        if e.is_bad_input() {
            Self::BadInput(e.into())
        } else {
            Self::Runtime(e.into())
        }
    }
}

impl From<softtouch_lab::grasp::soft::GraspRunError> for Failure {
    fn from(e: softtouch_lab::grasp::soft::GraspRunError) -> Self {
        if e.is_bad_input() {
            Self::BadInput(e.into())
        } else {
            Self::Runtime(e.into())
        }
    }
}

impl From<softtouch_lab::grasp::settings::SettingError> for Failure {
    fn from(e: softtouch_lab::grasp::settings::SettingError) -> Self {
        Self::BadInput(e.into())
    }
}

impl From<softtouch_schemas::ConfigError> for Failure {
    fn from(e: softtouch_schemas::ConfigError) -> Self {
        Self::BadInput(e.into())
    }
}

impl From<softtouch_store::StoreError> for Failure {
    fn from(e: softtouch_store::StoreError) -> Self {
        if e.is_bad_input() {
            Self::BadInput(e.into())
        } else {
            Self::Runtime(e.into())
        }
    }
}

impl From<softtouch_lab::models::ModelError> for Failure {
    fn from(e: softtouch_lab::models::ModelError) -> Self {
        if e.is_bad_input() {
            Self::BadInput(e.into())
        } else {
            Self::Runtime(e.into())
        }
    }
}

impl From<softtouch_trainer::TrainError> for Failure {
    fn from(e: softtouch_trainer::TrainError) -> Self {
        softtouch_lab::models::ModelError::from(e).into()
    }
}

impl From<softtouch_lab::experiments::ExperimentError> for Failure {
    fn from(e: softtouch_lab::experiments::ExperimentError) -> Self {
        use softtouch_lab::experiments::ExperimentError as E;
        match e {
            E::Invalid(_) => Self::BadInput(e.into()),
            E::Train(t) => t.into(),
            E::Plot(_) | E::Write { .. } | E::CreateDir { .. } | E::NoSummary => {
                Self::Runtime(e.into())
            }
        }
    }
}

/// Run a parsed command line; output goes to `out`.
pub async fn run(cli: Cli, out: &mut dyn std::io::Write) -> Result<(), Failure> {
    match cli.command {
        Command::Config(cmd) => config::run(cmd, out),
        Command::Db(cmd) => db::run(cmd, &cli.db, out).await,
        Command::Dataset(cmd) => dataset::run(cmd, &cli.db, out).await,
        Command::Runs => runs::run(&cli.db, out).await,
        Command::Collect(args) => collect::run_collect(args, &cli.db, out).await,
        Command::Status { run } => collect::run_status(&cli.db, run, out).await,
        Command::Sim(cmd) => sim::run(cmd, out).await,
        Command::Grasp(cmd) => grasp::run(cmd, &cli.db, out).await,
        Command::Bench(cmd) => bench::run(cmd, &cli.db, out).await,
        Command::Live(args) => live::run(args, &cli.db, out).await,
        Command::Rig(cmd) => rig::run(cmd, out).await,
        Command::Train(args) => train::run_train(args, &cli.db, out).await,
        Command::Eval(args) => eval::run_eval(args, &cli.db, out).await,
        Command::Transfer(args) => transfer::run_transfer(args, &cli.db, out).await,
        Command::Latent(args) => latent::run_latent(args, &cli.db, out).await,
        Command::Models => eval::run_models(&cli.db, out).await,
        Command::Sweep(cmd) => sweep::run_sweep(cmd, &cli.db, out).await,
        Command::Report(args) => report::run_report(args, &cli.db, out).await,
        Command::Results { command } => results::run(command, &cli.db, out).await,
    }
}

/// Open an existing database (never creates one: a typo in `--db` should not leave an
/// empty database behind; an empty file or one that is not a database is refused).
pub(crate) async fn open_existing(
    path: &softtouch_store::DbTarget,
) -> Result<softtouch_store::Store, Failure> {
    Ok(softtouch_store::Store::open_existing(path).await?)
}

/// Write to the output, treating a closed pipe (`softtouch runs | head`) as a runtime failure.
pub(crate) fn io_failure(e: std::io::Error) -> Failure {
    Failure::Runtime(anyhow::Error::new(e).context("cannot write output"))
}

#[cfg(test)]
mod tests {
    use super::error_text;

    #[derive(Debug, thiserror::Error)]
    #[error("(code: 26) file is not a database")]
    struct Inner;

    #[derive(Debug, thiserror::Error)]
    #[error("cannot open database t.db: {source}")]
    struct Quoting {
        #[source]
        source: Inner,
    }

    #[derive(Debug, thiserror::Error)]
    #[error("cannot open database")]
    struct Terse {
        #[source]
        source: Inner,
    }

    #[test]
    fn a_cause_is_said_once_whether_or_not_the_message_quotes_it() {
        let quoted = anyhow::Error::new(Quoting { source: Inner });
        assert_eq!(
            error_text(&quoted),
            "cannot open database t.db: (code: 26) file is not a database"
        );
        let terse = anyhow::Error::new(Terse { source: Inner }).context("report");
        assert_eq!(
            error_text(&terse),
            "report: cannot open database: (code: 26) file is not a database"
        );
        assert_eq!(error_text(&anyhow::anyhow!("")), "");
    }
}
