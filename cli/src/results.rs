//! `softtouch results`: the experiment verbs' stored results and the grasp sessions,
//! listed, shown, and a grasp trial's trace exported; and [`Recorder`], with which
//! each experiment verb stores its result as it ends.

use super::{Failure, io_failure, open_existing};
use anyhow::anyhow;
use clap::Subcommand;
use softtouch_collector::dataset::export::sha256_hex;
use softtouch_store::NewResult;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The commit this binary was built from (cli/build.rs), if known.
pub const SOFTWARE_COMMIT: Option<&str> = option_env!("SOFTTOUCH_COMMIT");

/// `softtouch results …`.
#[derive(Debug, Subcommand)]
pub enum ResultsCommand {
    /// List every stored result (id, verb, model, time, one line) and grasp session.
    #[command(after_help = "Example:\n  softtouch results list")]
    List,
    /// Print one result: what ran, on what, with which software, and its tables (CSV).
    #[command(after_help = "Example:\n  softtouch results show 3")]
    Show {
        /// The result's id (`softtouch results list`).
        id: i64,
        /// Only this table (its file name), as plain CSV.
        #[arg(long)]
        table: Option<String>,
    },
    /// Export one grasp trial's trace as CSV (time, estimate, true force, measured and
    /// requested position), by the trial's id (`softtouch results list` gives each
    /// session's range).
    #[command(
        after_help = "Examples:\n  softtouch results trace 12\n  softtouch results trace 12 --out trial-12.csv"
    )]
    Trace {
        /// The trial's id.
        trial_id: i64,
        /// Write here instead of the terminal.
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

/// Run `softtouch results`.
pub async fn run(
    cmd: Option<ResultsCommand>,
    db: &softtouch_store::DbTarget,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let store = open_existing(db).await?;
    let result = match cmd.unwrap_or(ResultsCommand::List) {
        ResultsCommand::List => list(&store, out).await,
        ResultsCommand::Show { id, table } => show(&store, id, table.as_deref(), out).await,
        ResultsCommand::Trace {
            trial_id,
            out: file,
        } => trace(&store, trial_id, file.as_deref(), out).await,
    };
    store.close().await;
    result
}

async fn list(store: &softtouch_store::Store, out: &mut dyn Write) -> Result<(), Failure> {
    let results = store.results().await?;
    if results.is_empty() {
        writeln!(
            out,
            "no stored results: grasp follow|disturb|twist, bench grasp, transfer, sweep and latent store theirs as they end"
        )
        .map_err(io_failure)?;
    } else {
        writeln!(
            out,
            "{:>4}  {:<14} {:<18} {:<24} summary",
            "id", "verb", "model", "stored (UTC)"
        )
        .map_err(io_failure)?;
        for r in &results {
            writeln!(
                out,
                "{:>4}  {:<14} {:<18} {:<24} {}",
                r.result_id,
                r.verb,
                r.model.as_deref().unwrap_or("-"),
                r.created_at,
                r.summary
            )
            .map_err(io_failure)?;
        }
    }
    let sessions = store.grasp_sessions().await?;
    if sessions.is_empty() {
        return Ok(());
    }
    writeln!(
        out,
        "\ngrasp sessions (softtouch results trace TRIAL_ID exports a trial's trace):"
    )
    .map_err(io_failure)?;
    writeln!(
        out,
        "{:>4}  {:<18} {:<24} {:>7} {:>13}  summary",
        "id", "model", "stored (UTC)", "trials", "trial ids"
    )
    .map_err(io_failure)?;
    for s in &sessions {
        let trials = store.grasp_trials(s.session_id).await?;
        let ids = store.grasp_trial_id_range(s.session_id).await?.map_or_else(
            || "-".into(),
            |(a, b)| softtouch_lab::grasp::trials::table::id_span(a, b),
        );
        writeln!(
            out,
            "{:>4}  {:<18} {:<24} {:>7} {:>13}  {}",
            s.session_id,
            s.model,
            s.created_at,
            trials.len(),
            ids,
            softtouch_lab::grasp::trials::table::session_summary(&trials)
        )
        .map_err(io_failure)?;
    }
    Ok(())
}

async fn show(
    store: &softtouch_store::Store,
    id: i64,
    table: Option<&str>,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let r = store.result(id).await?.ok_or_else(|| {
        Failure::BadInput(anyhow!(
            "no result {id} in this database (see `softtouch results list`)"
        ))
    })?;
    if let Some(name) = table {
        let csv = r.table(name).ok_or_else(|| {
            let names: Vec<&str> = r.tables.iter().map(|(n, _)| n.as_str()).collect();
            Failure::BadInput(anyhow!(
                "--table: result {id} has no table `{name}`; it has: {}",
                names.join(", ")
            ))
        })?;
        return out.write_all(csv.as_bytes()).map_err(io_failure);
    }
    let row = &r.row;
    let dash = |v: &Option<String>| v.clone().unwrap_or_else(|| "-".into());
    writeln!(out, "result {}: {}", row.result_id, row.verb).map_err(io_failure)?;
    writeln!(out, "  stored:    {} (UTC)", row.created_at).map_err(io_failure)?;
    writeln!(out, "  summary:   {}", row.summary).map_err(io_failure)?;
    writeln!(out, "  settings:  {}", row.settings_json).map_err(io_failure)?;
    writeln!(
        out,
        "  model:     {} (artifact sha256 {})",
        dash(&row.model),
        dash(&row.model_sha256)
    )
    .map_err(io_failure)?;
    writeln!(out, "  dataset:   {}", dash(&row.dataset)).map_err(io_failure)?;
    writeln!(out, "  scene:     {}", dash(&row.scene_hash)).map_err(io_failure)?;
    writeln!(out, "  rig:       {}", dash(&row.rig_hash)).map_err(io_failure)?;
    writeln!(
        out,
        "  software:  softtouch {} (commit {})",
        row.software_version,
        dash(&row.software_commit)
    )
    .map_err(io_failure)?;
    for (name, png) in &r.figures {
        writeln!(out, "figure {name}: {} bytes of PNG", png.len()).map_err(io_failure)?;
    }
    for (name, csv) in &r.tables {
        let lines = csv.lines().count().saturating_sub(1);
        writeln!(
            out,
            "\n{name} ({lines} rows; --table {name} prints it alone):"
        )
        .map_err(io_failure)?;
        const SHOWN: usize = 40;
        for line in csv.lines().take(SHOWN + 1) {
            writeln!(out, "{line}").map_err(io_failure)?;
        }
        if lines > SHOWN {
            writeln!(out, "… {} more rows", lines - SHOWN).map_err(io_failure)?;
        }
    }
    Ok(())
}

async fn trace(
    store: &softtouch_store::Store,
    trial_id: i64,
    file: Option<&Path>,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let (session, row, trace) = store.grasp_trial_by_id(trial_id).await?.ok_or_else(|| {
        Failure::BadInput(anyhow!(
            "no grasp trial {trial_id} in this database (`softtouch results list` gives each session's trial ids)"
        ))
    })?;
    let trace = trace.ok_or_else(|| {
        Failure::BadInput(anyhow!(
            "grasp trial {trial_id} (session {session}) has no stored trace (a refused trial moves nothing)"
        ))
    })?;
    let mut csv = String::from("t_s,estimate_n,true_n,measured_count,request_count\n");
    let num = |v: f32| {
        if v.is_finite() {
            v.to_string()
        } else {
            String::new()
        }
    };
    for i in 0..trace.t_s.len() {
        let at = |v: &[f32]| v.get(i).copied().unwrap_or(f32::NAN);
        csv.push_str(&format!(
            "{},{},{},{},{}\n",
            num(trace.t_s[i]),
            num(at(&trace.estimate_n)),
            num(at(&trace.true_n)),
            trace
                .measured_count
                .get(i)
                .map_or(String::new(), u8::to_string),
            trace
                .request_count
                .get(i)
                .map_or(String::new(), u8::to_string),
        ));
    }
    match file {
        Some(path) => {
            std::fs::write(path, &csv)
                .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", path.display())))?;
            writeln!(
                out,
                "trial {trial_id} (session {session}, {} {} {} trial {}, {}): {} cycles written to {}",
                row.medium,
                row.key.object,
                row.key.mode,
                row.key.trial,
                if row.success { "held" } else { row.reason.as_deref().unwrap_or("failed") },
                trace.t_s.len(),
                path.display()
            )
            .map_err(io_failure)
        }
        None => out.write_all(csv.as_bytes()).map_err(io_failure),
    }
}

/// What an experiment verb stores as it ends: its provenance and the CSV files it
/// wrote (read back, so the stored tables are the exports byte for byte).
#[derive(Debug, Default)]
pub(crate) struct Recorder {
    verb: &'static str,
    settings: serde_json::Map<String, serde_json::Value>,
    model: Option<String>,
    dataset: Option<String>,
    scene_hash: Option<String>,
    rig_hash: Option<String>,
    tables: Vec<PathBuf>,
    figures: Vec<PathBuf>,
}

impl Recorder {
    /// A result of `verb`.
    pub(crate) fn new(verb: &'static str) -> Self {
        Self {
            verb,
            ..Self::default()
        }
    }

    /// A setting or seed, by its flag's name.
    pub(crate) fn setting(mut self, name: &str, value: impl Into<serde_json::Value>) -> Self {
        self.settings.insert(name.to_owned(), value.into());
        self
    }

    /// The stored model it ran.
    pub(crate) fn model(mut self, name: &str) -> Self {
        self.model = Some(name.to_owned());
        self
    }

    /// The dataset it read.
    pub(crate) fn dataset(mut self, name: &str) -> Self {
        self.dataset = Some(name.to_owned());
        self
    }

    /// The scene's hash (`grasp::calibration::scene_setup_hash`).
    pub(crate) fn scene_hash(mut self, hash: Option<String>) -> Self {
        self.scene_hash = hash;
        self
    }

    /// The rig's hash (`grasp::calibration::rig_setup_hash`).
    pub(crate) fn rig_hash(mut self, hash: Option<String>) -> Self {
        self.rig_hash = hash;
        self
    }

    /// A CSV the verb wrote.
    pub(crate) fn table(mut self, csv: &Path) -> Self {
        self.tables.push(csv.to_owned());
        self
    }

    /// A PNG the verb wrote that its tables cannot redraw.
    pub(crate) fn figure(mut self, png: &Path) -> Self {
        self.figures.push(png.to_owned());
        self
    }

    /// Stores the result in one transaction and says so; returns its id.
    pub(crate) async fn store(
        self,
        db: &softtouch_store::DbTarget,
        summary: String,
        out: &mut dyn Write,
    ) -> Result<i64, Failure> {
        let file_name = |path: &Path| {
            path.file_name().map_or_else(
                || path.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            )
        };
        let mut figures = Vec::with_capacity(self.figures.len());
        for path in &self.figures {
            let png = std::fs::read(path).map_err(|e| {
                Failure::Runtime(anyhow!("cannot read back {}: {e}", path.display()))
            })?;
            figures.push((file_name(path), png));
        }
        let mut tables = Vec::with_capacity(self.tables.len());
        for path in &self.tables {
            let csv = std::fs::read_to_string(path).map_err(|e| {
                Failure::Runtime(anyhow!("cannot read back {}: {e}", path.display()))
            })?;
            tables.push((file_name(path), csv));
        }
        // On a runtime of its own, in its own thread: the simulated grasp verbs leave
        // tokio's clock paused, under which the pool's timeouts fire at once.
        let new = NewResult {
            verb: self.verb.to_owned(),
            settings_json: serde_json::Value::Object(self.settings).to_string(),
            model: self.model,
            model_sha256: None,
            dataset: self.dataset,
            scene_hash: self.scene_hash,
            rig_hash: self.rig_hash,
            summary,
            software_commit: SOFTWARE_COMMIT.map(str::to_owned),
            tables,
            figures,
        };
        let db = db.to_owned();
        let stored = std::thread::spawn(move || {
            let runtime = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .map_err(|e| Failure::Runtime(anyhow!("cannot start a runtime: {e}")))?;
            runtime.block_on(insert(&db, new))
        })
        .join()
        .map_err(|_| Failure::Runtime(anyhow!("storing the result panicked")))?;
        let id = stored?;
        writeln!(out, "stored as result {id} (softtouch results show {id})").map_err(io_failure)?;
        Ok(id)
    }
}

/// Opens the store, fills in the model's sha256 and inserts.
async fn insert(db: &softtouch_store::DbTarget, mut new: NewResult) -> Result<i64, Failure> {
    let store = open_existing(db).await?;
    let stored = async {
        // A stored model by name, else an artifact file (`eval model.stm`).
        if let Some(name) = &new.model {
            new.model_sha256 = match store.model_artifact(name).await? {
                Some((bytes, _)) => Some(sha256_hex(&bytes)),
                None => std::fs::read(name).ok().map(|bytes| sha256_hex(&bytes)),
            };
        }
        Ok::<_, Failure>(store.insert_result(&new).await?)
    }
    .await;
    store.close().await;
    stored
}
