//! `softtouch report`: one self-contained HTML page of what a database holds, for a
//! lab notebook or a paper draft.
//!
//! - `data.rs`: the content, read through the store's read-only rows (`store::report`:
//!   the report never writes).
//! - `grasp_sessions.rs`: the stored grasp sessions the Grasping section shows, their
//!   tables and the traces its viewer draws.
//! - `predict.rs`: predicted against true on a downsampled test split (Figure 2b).
//! - `results.rs`: the experiment verbs' stored results (Figure 5, land to water,
//!   sweeps), their tables read by column.
//! - `csv.rs`: sweep rows (stored, or from older CSV files given with `--sweep`) and
//!   the collection benchmark's CSV.
//! - `svg.rs`: the figures, inline SVG through plotters.
//! - `page/`: the page, maud templates (type-checked, escaping every value): the frame,
//!   its style and the summary in `mod.rs`, a file per section.
//!
//! Sections: Summary, Runs, Datasets, Models, Sweeps, Land to water, Grasping, Figure 5;
//! each gives its
//! provenance (seeds, config hashes, software versions) and, when it has nothing to
//! show, the command that would give it something.

mod csv;
mod data;
mod grasp_sessions;
mod page;
mod predict;
mod results;
mod svg;

use softtouch_store::DbTarget;
use std::path::PathBuf;

/// The report failed.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Reading the database failed (no file, an old schema, a missing run or
    /// model, a query).
    #[error(transparent)]
    Db(#[from] crate::store::report::ReadError),
    /// A stored model cannot be loaded.
    #[error("model {model_id}: cannot load its artifact: {why}")]
    Model {
        /// Row id.
        model_id: i64,
        /// Why.
        why: String,
    },
    /// A stored frame cannot be used.
    #[error("run {run}, sample {index}: {why}")]
    Frame {
        /// Run id.
        run: i64,
        /// Sample index.
        index: i64,
        /// Why.
        why: String,
    },
    /// A results file cannot be read.
    #[error("cannot read {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A results file is malformed.
    #[error("{}:{line}: {why}", path.display())]
    Csv {
        /// The file.
        path: PathBuf,
        /// Line, from 1.
        line: usize,
        /// What is wrong.
        why: String,
    },
    /// A figure cannot be drawn.
    #[error("cannot draw the figure `{what}`: {why}")]
    Plot {
        /// Which figure.
        what: String,
        /// Why.
        why: String,
    },
}

impl ReportError {
    /// Whether the user's input is at fault (exit code 2).
    #[must_use]
    pub const fn is_bad_input(&self) -> bool {
        match self {
            Self::Db(e) => e.is_bad_input(),
            other => matches!(other, Self::Read { .. } | Self::Csv { .. }),
        }
    }
}

/// What to put in the report.
#[derive(Debug, Clone)]
pub struct ReportOptions {
    /// Only these runs (and the datasets drawing on them); all when `None`.
    pub runs: Option<Vec<i64>>,
    /// Only these models; all when `None`.
    pub models: Option<Vec<String>>,
    /// Sweep and model-benchmark CSVs (`softtouch sweep …`, `softtouch bench model`).
    pub sweeps: Vec<PathBuf>,
    /// `collection-sweep.csv` of `softtouch bench collection`.
    pub bench_collection: Option<PathBuf>,
    /// Test samples per model in the predicted-against-true figures at most.
    pub scatter_points: usize,
}

impl Default for ReportOptions {
    fn default() -> Self {
        Self {
            runs: None,
            models: None,
            sweeps: Vec::new(),
            bench_collection: None,
            scatter_points: DEFAULT_SCATTER_POINTS,
        }
    }
}

/// Test samples per model drawn in Figure 2b by default: enough to see the spread,
/// few enough that ten models stay well under a megabyte each.
pub const DEFAULT_SCATTER_POINTS: usize = 300;

/// A rendered report.
#[derive(Debug, Clone)]
pub struct Report {
    /// The page.
    pub html: String,
    /// Runs, datasets and models shown.
    pub counts: [usize; 3],
}

/// Builds the report of the database at `db`, reading only.
///
/// # Errors
/// The database is missing, of another schema, or unreadable; an option names a run
/// or model that is not there; a results file is unreadable or malformed; a stored
/// model or frame cannot be used.
pub async fn build(db: &DbTarget, options: &ReportOptions) -> Result<Report, ReportError> {
    let pool = data::open_read_only(db).await?;
    let result = gather(&pool, db, options).await;
    pool.close().await;
    let content = result?;
    let counts = [
        content.runs.len(),
        content.datasets.len(),
        content.models.len(),
    ];
    Ok(Report {
        html: page::render(&content)?,
        counts,
    })
}

/// A model with what the page shows of it beyond its row.
#[derive(Debug, Clone)]
pub(crate) struct ModelData {
    pub row: data::ModelRow,
    pub summary: Option<softtouch_trainer::TrainingSummary>,
    pub history: Vec<softtouch_trainer::train::EpochReport>,
    /// Predicted against true on a test subset (None: the VAE, no dataset, or no
    /// test frames).
    pub predictions: Option<predict::Predictions>,
    /// What could not be read or run (stored JSON, the artifact, a test frame).
    pub problems: Vec<String>,
}

/// Everything on the page.
#[derive(Debug, Clone)]
pub(crate) struct Content {
    /// The database as shown (a URL without its password).
    pub db: String,
    pub generated_at: String,
    pub schema_version: i64,
    pub options: ReportOptions,
    pub runs: Vec<data::RunData>,
    pub datasets: Vec<data::DatasetData>,
    pub models: Vec<ModelData>,
    pub sweeps: Vec<csv::SweepFile>,
    pub collection: Option<csv::CollectionFile>,
    pub grasp: Vec<grasp_sessions::GraspData>,
    /// The experiment verbs' stored results.
    pub results: results::Results,
    /// Stored results that could not be read (each costs its part, not the page).
    pub result_problems: Vec<String>,
}

async fn gather(
    pool: &data::ReadOnly,
    db: &DbTarget,
    options: &ReportOptions,
) -> Result<Content, ReportError> {
    // Files first: a typo in a path fails before any slow work.
    let sweeps = options
        .sweeps
        .iter()
        .map(|p| csv::read_sweep(p))
        .collect::<Result<Vec<_>, _>>()?;
    let collection = options
        .bench_collection
        .as_deref()
        .map(csv::read_collection)
        .transpose()?;
    // Stored sweeps first, then the CSV files given (the order the page's note says).
    let files = sweeps;
    let mut sweeps = Vec::new();
    let results = results::Results {
        all: crate::store::report::results(pool).await?,
    };
    let mut result_problems = Vec::new();
    for r in results.of("sweep alpha").chain(results.of("sweep latent")) {
        for (name, text) in &r.tables {
            let source = PathBuf::from(format!("result {} ({name})", r.row.result_id));
            match csv::parse_sweep(&source, text) {
                Ok(file) => sweeps.push(file),
                Err(e) => result_problems.push(e.to_string()),
            }
        }
    }
    sweeps.extend(files);
    let runs = data::runs(pool, options.runs.as_deref()).await?;
    let datasets = data::datasets(pool, options.runs.as_deref()).await?;
    let rows = data::models(pool, options.models.as_deref()).await?;
    let mut cache = predict::Cache::default();
    let mut models = Vec::with_capacity(rows.len());
    for row in rows {
        let mut problems = Vec::new();
        let summary =
            serde_json::from_str::<Option<softtouch_trainer::TrainingSummary>>(&row.metrics_json)
                .unwrap_or_else(|e| {
                    problems.push(format!("metrics_json: {e}"));
                    None
                });
        let history =
            serde_json::from_str::<Vec<softtouch_trainer::train::EpochReport>>(&row.history_json)
                .unwrap_or_else(|e| {
                    problems.push(format!("history_json: {e}"));
                    Vec::new()
                });
        let predictions = match row.dataset_id {
            Some(dataset_id) if options.scatter_points > 0 => {
                match predict::predict(
                    pool,
                    &mut cache,
                    row.model_id,
                    dataset_id,
                    options.scatter_points,
                )
                .await
                {
                    Ok(p) => p,
                    // One damaged model or frame costs its figure, not the page.
                    Err(e @ (ReportError::Model { .. } | ReportError::Frame { .. })) => {
                        problems.push(e.to_string());
                        None
                    }
                    Err(e) => return Err(e),
                }
            }
            _ => None,
        };
        models.push(ModelData {
            row,
            summary,
            history,
            predictions,
            problems,
        });
    }
    Ok(Content {
        db: db.display().to_string(),
        generated_at: data::now(pool).await?,
        schema_version: crate::store::Store::schema_version(),
        options: options.clone(),
        runs,
        datasets,
        models,
        sweeps,
        collection,
        grasp: grasp_sessions::gather(pool).await?,
        results,
        result_problems,
    })
}
