//! What the report reads from the database, as typed rows, through a read-only
//! connection ([`ReadOnly`]).
//!
//! The report never writes: the database is opened with `SQLITE_OPEN_READONLY`, so
//! even a bug here cannot change it. No migration runs either; a database older
//! than this build is refused with the command that migrates it.

use crate::DbTarget;
use crate::Dialect;
use crate::{MemberRow, RunSummary, Store, StoreError, run_counts_columns, run_counts_from};
use sqlx::any::AnyPoolOptions;
use sqlx::{AnyPool, Executor as _, FromRow, Row as _};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Reading the report's rows failed.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// No database file.
    #[error("no database at {}: collect with `softtouch collect` (or pass --db PATH)", .0.display())]
    NoDatabase(PathBuf),
    /// The path holds something else, or an empty file (the store's message).
    #[error(transparent)]
    NotADatabase(Box<StoreError>),
    /// The database cannot be opened.
    #[error("cannot open database {db} read-only: {source}")]
    Open {
        /// The database as shown (a URL without its password).
        db: String,
        /// Why.
        #[source]
        source: sqlx::Error,
    },
    /// The database's schema is older than this build's (or it is not a softtouch one).
    #[error(
        "database {db} is at schema {found}, this build reads schema {expected}: migrate it with `softtouch --db {db} db init` (the report itself never writes)"
    )]
    Schema {
        /// The database as shown.
        db: String,
        /// Its newest migration (0: none).
        found: i64,
        /// This build's newest migration.
        expected: i64,
    },
    /// A query failed.
    #[error("database error while {doing}: {source}")]
    Query {
        /// What we were doing.
        doing: &'static str,
        /// Why.
        #[source]
        source: sqlx::Error,
    },
    /// Stored rows that do not read back (a damaged grasp trace, say).
    #[error(transparent)]
    Rows(Box<StoreError>),
    /// `--runs` names a run that is not there.
    #[error("--runs: no run {0} in this database (see `softtouch runs`)")]
    NoSuchRun(i64),
    /// `--models` names a model that is not there.
    #[error("--models: no model named `{0}` in this database (see `softtouch models`)")]
    NoSuchModel(String),
}

impl ReadError {
    /// Whether the user's input is at fault (rather than the machine).
    #[must_use]
    pub const fn is_bad_input(&self) -> bool {
        matches!(
            self,
            Self::NoDatabase(_)
                | Self::NotADatabase(_)
                | Self::Schema { .. }
                | Self::NoSuchRun(_)
                | Self::NoSuchModel(_)
        )
    }
}

fn query(doing: &'static str) -> impl FnOnce(sqlx::Error) -> ReadError {
    move |source| ReadError::Query { doing, source }
}

/// A database opened read-only, for readers that must never write (the report).
#[derive(Debug, Clone)]
pub struct ReadOnly {
    pool: AnyPool,
    dialect: Dialect,
}

impl ReadOnly {
    /// Closes the connections (a reader's last act, on every path).
    pub async fn close(&self) {
        self.pool.close().await;
    }
}

/// What must be at a SQLite path before a reader opens it.
fn check_file(path: &Path) -> Result<(), ReadError> {
    match crate::sqlite_file::inspect(path).map_err(|e| ReadError::NotADatabase(Box::new(e)))? {
        crate::sqlite_file::DbFile::Sqlite => Ok(()),
        crate::sqlite_file::DbFile::Missing => Err(ReadError::NoDatabase(path.to_owned())),
        crate::sqlite_file::DbFile::Empty => {
            Err(ReadError::NotADatabase(Box::new(StoreError::EmptyFile {
                path: path.to_owned(),
            })))
        }
        crate::sqlite_file::DbFile::NotSqlite { starts_with } => Err(ReadError::NotADatabase(
            Box::new(crate::sqlite_file::not_a_database(path, starts_with)),
        )),
    }
}

/// Opens `target` read-only and checks that its schema is this build's. On PostgreSQL
/// every transaction of its connections is read-only (`default_transaction_read_only`).
///
/// # Errors
/// No file, a file that does not open, an older schema.
pub async fn open_read_only(target: &DbTarget) -> Result<ReadOnly, ReadError> {
    sqlx::any::install_default_drivers();
    let shown = target.display().to_string();
    if let Some(path) = target.file() {
        check_file(path)?;
    }
    let (url, dialect) = target.url_and_dialect("ro");
    let pool = AnyPoolOptions::new()
        .max_connections(2)
        .acquire_timeout(Duration::from_secs(10))
        .after_connect(move |conn, _meta| {
            Box::pin(async move {
                let read_only = match dialect {
                    Dialect::Sqlite => "PRAGMA busy_timeout = 10000; PRAGMA query_only = ON;",
                    Dialect::Postgres => "SET default_transaction_read_only = on;",
                };
                conn.execute(read_only).await?;
                Ok(())
            })
        })
        .connect(&url)
        .await
        .map_err(|source| ReadError::Open {
            db: shown.clone(),
            source,
        })?;
    let applied: Result<Option<i64>, _> =
        sqlx::query_scalar("SELECT MAX(version) FROM _sqlx_migrations WHERE success")
            .fetch_one(&pool)
            .await;
    let expected = Store::schema_version();
    match applied {
        Ok(Some(v)) if v >= expected => Ok(ReadOnly { pool, dialect }),
        Ok(found) => Err(ReadError::Schema {
            db: shown,
            found: found.unwrap_or(0),
            expected,
        }),
        Err(_) => Err(ReadError::Schema {
            db: shown,
            found: 0,
            expected,
        }),
    }
}

/// A run with its counts (the listing's [`RunSummary`], one definition of them) and its
/// provenance.
#[derive(Debug, Clone, FromRow)]
pub struct RunRow {
    /// Status, counts and times, as `softtouch runs` lists them.
    #[sqlx(flatten)]
    pub counts: RunSummary,
    /// The software that collected it.
    pub software_version: String,
    /// Its rig, as run (TOML).
    pub rig_toml: String,
    /// Its scene, as run (TOML).
    pub scene_toml: String,
}

/// Everything the Runs section shows of one run.
#[derive(Debug, Clone)]
pub struct RunData {
    pub row: RunRow,
    /// Rejected samples per reason.
    pub rejects: BTreeMap<String, i64>,
    /// Events per `(kind, level)`.
    pub event_counts: BTreeMap<(String, String), i64>,
    /// Events with a run-clock time: `(t_ns, kind, level)`, at most [`MAX_TIMELINE`].
    pub timeline: Vec<(i64, String, String)>,
    /// The last events, oldest first: `(sample, created_at, level, kind, message)`.
    pub latest: Vec<(Option<i64>, String, String, String, String)>,
    /// Cumulative accepted and rejected samples against the run clock, one point per
    /// sample: `(t_ns, ok so far, rejected so far)`.
    pub progress: Vec<(i64, i64, i64)>,
}

/// Events drawn on a run's timeline at most (the counts table has them all).
pub const MAX_TIMELINE: i64 = 5_000;
/// Latest events listed per run.
pub const LATEST_EVENTS: i64 = 12;

/// The runs (all, or those listed), oldest first.
pub async fn runs(db: &ReadOnly, only: Option<&[i64]>) -> Result<Vec<RunData>, ReadError> {
    let rows = sqlx::query_as::<_, RunRow>(db.dialect.sql(concat!(
        "SELECT ",
        run_counts_columns!(),
        ", r.software_version, r.rig_toml, r.scene_toml",
        run_counts_from!(),
        " ORDER BY r.run_id"
    )))
    .fetch_all(&db.pool)
    .await
    .map_err(query("listing runs"))?;
    if let Some(only) = only
        && let Some(missing) = only
            .iter()
            .find(|id| !rows.iter().any(|r| r.counts.run_id == **id))
    {
        return Err(ReadError::NoSuchRun(*missing));
    }
    let mut out = Vec::new();
    for row in rows {
        if only.is_some_and(|ids| !ids.contains(&row.counts.run_id)) {
            continue;
        }
        out.push(run_data(db, row).await?);
    }
    Ok(out)
}

async fn run_data(db: &ReadOnly, row: RunRow) -> Result<RunData, ReadError> {
    let id = row.counts.run_id;
    let rejects: Vec<(String, i64)> = sqlx::query_as(db.dialect.sql(
        "SELECT COALESCE(reject_reason, '?'), COUNT(*) FROM samples
         WHERE run_id = ? AND status = 'rejected' GROUP BY 1 ORDER BY 2 DESC, COALESCE(reject_reason, '?') COLLATE BINARY",
    ))
    .bind(id)
    .fetch_all(&db.pool)
    .await
    .map_err(query("counting rejects"))?;
    let counts: Vec<(String, String, i64)> = sqlx::query_as(
        db.dialect
            .sql("SELECT kind, level, COUNT(*) FROM events WHERE run_id = ? GROUP BY 1, 2"),
    )
    .bind(id)
    .fetch_all(&db.pool)
    .await
    .map_err(query("counting events"))?;
    let timeline: Vec<(i64, String, String)> = sqlx::query_as(db.dialect.sql(
        "SELECT t_ns, kind, level FROM events WHERE run_id = ? AND t_ns IS NOT NULL
         ORDER BY event_id LIMIT ?",
    ))
    .bind(id)
    .bind(MAX_TIMELINE)
    .fetch_all(&db.pool)
    .await
    .map_err(query("reading events"))?;
    let mut latest: Vec<(Option<i64>, String, String, String, String)> =
        sqlx::query_as(db.dialect.sql(
            "SELECT sample_index, created_at, level, kind, message FROM events
         WHERE run_id = ? ORDER BY event_id DESC LIMIT ?",
        ))
        .bind(id)
        .bind(LATEST_EVENTS)
        .fetch_all(&db.pool)
        .await
        .map_err(query("reading events"))?;
    latest.reverse();
    // Samples in the order they were taken, cumulated, then thinned for the figure.
    let statuses: Vec<(i64, String)> = sqlx::query_as(db.dialect.sql(
        "SELECT frame_t_ns, status FROM samples WHERE run_id = ? ORDER BY frame_t_ns, sample_index",
    ))
    .bind(id)
    .fetch_all(&db.pool)
    .await
    .map_err(query("reading the run's samples"))?;
    let mut cumulative = Vec::with_capacity(statuses.len());
    let (mut ok, mut rejected) = (0i64, 0i64);
    for (t, status) in &statuses {
        if status == "ok" {
            ok += 1;
        } else {
            rejected += 1;
        }
        cumulative.push((*t, ok, rejected));
    }
    Ok(RunData {
        row,
        rejects: rejects.into_iter().collect(),
        event_counts: counts.into_iter().map(|(k, l, n)| ((k, l), n)).collect(),
        timeline,
        latest,
        progress: cumulative,
    })
}

/// A dataset with its splits and label values.
#[derive(Debug, Clone)]
pub struct DatasetData {
    pub dataset_id: i64,
    pub name: String,
    pub definition_json: String,
    pub seed: i64,
    pub split_ratio: String,
    pub sample_count: i64,
    pub software_version: String,
    pub created_at: String,
    /// The runs it draws from.
    pub runs: Vec<i64>,
    /// Members per split: train, val, test.
    pub splits: [i64; 3],
    /// Label values per axis (Fx, Fy, Fz in N; Tx, Ty, Tz in N·mm).
    pub values: [Vec<f64>; 6],
}

/// The datasets (all, or those drawing on one of `runs`), oldest first.
pub async fn datasets(db: &ReadOnly, runs: Option<&[i64]>) -> Result<Vec<DatasetData>, ReadError> {
    let rows = sqlx::query(db.dialect.sql(
        "SELECT dataset_id, name, definition_json, seed, split_ratio, sample_count,
                software_version, created_at FROM datasets ORDER BY dataset_id",
    ))
    .fetch_all(&db.pool)
    .await
    .map_err(query("listing datasets"))?;
    let mut out = Vec::new();
    for r in rows {
        let dataset_id: i64 = r.get(0);
        let member_runs: Vec<i64> = sqlx::query_scalar(db.dialect.sql(
            "SELECT DISTINCT run_id FROM dataset_members WHERE dataset_id = ? ORDER BY run_id",
        ))
        .bind(dataset_id)
        .fetch_all(&db.pool)
        .await
        .map_err(query("reading a dataset's runs"))?;
        if runs.is_some_and(|wanted| !member_runs.iter().any(|id| wanted.contains(id))) {
            continue;
        }
        let split_rows: Vec<(String, i64)> = sqlx::query_as(db.dialect.sql(
            "SELECT split, COUNT(*) FROM dataset_members WHERE dataset_id = ? GROUP BY split",
        ))
        .bind(dataset_id)
        .fetch_all(&db.pool)
        .await
        .map_err(query("counting a dataset's splits"))?;
        let mut splits = [0i64; 3];
        for (split, n) in split_rows {
            let i = match split.as_str() {
                "train" => 0,
                "val" => 1,
                _ => 2,
            };
            splits[i] += n;
        }
        let labels: Vec<(f64, f64, f64, f64, f64, f64)> = sqlx::query_as(db.dialect.sql(
            "SELECT s.fx_n, s.fy_n, s.fz_n, s.tx_nm, s.ty_nm, s.tz_nm
             FROM dataset_members m
             JOIN samples s ON s.run_id = m.run_id AND s.sample_index = m.sample_index
             WHERE m.dataset_id = ? ORDER BY m.position",
        ))
        .bind(dataset_id)
        .fetch_all(&db.pool)
        .await
        .map_err(query("reading a dataset's labels"))?;
        let mut values: [Vec<f64>; 6] = std::array::from_fn(|_| Vec::with_capacity(labels.len()));
        for (fx, fy, fz, tx, ty, tz) in labels {
            // Torque shown in N·mm, as the paper does.
            for (axis, v) in [fx, fy, fz, tx * 1e3, ty * 1e3, tz * 1e3]
                .into_iter()
                .enumerate()
            {
                values[axis].push(v);
            }
        }
        out.push(DatasetData {
            dataset_id,
            name: r.get(1),
            definition_json: r.get(2),
            seed: r.get(3),
            split_ratio: r.get(4),
            sample_count: r.get(5),
            software_version: r.get(6),
            created_at: r.get(7),
            runs: member_runs,
            splits,
            values,
        });
    }
    Ok(out)
}

/// A stored model, without its artifact.
#[derive(Debug, Clone, FromRow)]
pub struct ModelRow {
    pub model_id: i64,
    pub name: String,
    pub dataset_id: Option<i64>,
    pub dataset_name: String,
    pub kind: String,
    pub config_json: String,
    pub train_json: String,
    pub metrics_json: String,
    pub history_json: String,
    pub test_r2_mean: Option<f64>,
    pub test_image_mse: Option<f64>,
    pub software_version: String,
    pub created_at: String,
}

/// The models (all, or those named), oldest first.
pub async fn models(db: &ReadOnly, only: Option<&[String]>) -> Result<Vec<ModelRow>, ReadError> {
    let rows = sqlx::query_as::<_, ModelRow>(db.dialect.sql(
        "SELECT model_id, name, dataset_id, dataset_name, kind, config_json, train_json,
                metrics_json, history_json, test_r2_mean, test_image_mse, software_version,
                created_at
         FROM models ORDER BY model_id",
    ))
    .fetch_all(&db.pool)
    .await
    .map_err(query("listing models"))?;
    if let Some(only) = only {
        if let Some(missing) = only.iter().find(|n| !rows.iter().any(|r| &r.name == *n)) {
            return Err(ReadError::NoSuchModel(missing.clone()));
        }
        return Ok(rows
            .into_iter()
            .filter(|r| only.contains(&r.name))
            .collect());
    }
    Ok(rows)
}

/// A model's artifact bytes.
pub async fn artifact(db: &ReadOnly, model_id: i64) -> Result<Vec<u8>, ReadError> {
    sqlx::query_scalar(
        db.dialect
            .sql("SELECT artifact FROM models WHERE model_id = ?"),
    )
    .bind(model_id)
    .fetch_one(&db.pool)
    .await
    .map_err(query("reading a model's artifact"))
}

/// The test members of a dataset, in dataset order: `(run, sample)`.
pub async fn test_members(db: &ReadOnly, dataset_id: i64) -> Result<Vec<(i64, i64)>, ReadError> {
    sqlx::query_as(db.dialect.sql(
        "SELECT run_id, sample_index FROM dataset_members
         WHERE dataset_id = ? AND split = 'test' ORDER BY position",
    ))
    .bind(dataset_id)
    .fetch_all(&db.pool)
    .await
    .map_err(query("listing a dataset's test split"))
}

/// Test sample `(run, index)`'s label and frame, if it has a frame.
pub async fn frame(
    db: &ReadOnly,
    (run, index): (i64, i64),
) -> Result<Option<MemberRow>, ReadError> {
    sqlx::query_as::<_, MemberRow>(db.dialect.sql(
        "SELECT 'test' AS split, s.run_id, s.sample_index,
                s.fx_n, s.fy_n, s.fz_n, s.tx_nm, s.ty_nm, s.tz_nm,
                f.format, f.width, f.height, f.data
         FROM samples s JOIN frames f ON f.run_id = s.run_id AND f.sample_index = s.sample_index
         WHERE s.run_id = ? AND s.sample_index = ?",
    ))
    .bind(run)
    .bind(index)
    .fetch_optional(&db.pool)
    .await
    .map_err(query("reading a test frame"))
}

/// The database's clock, as the page's date (UTC).
pub async fn now(db: &ReadOnly) -> Result<String, ReadError> {
    sqlx::query_scalar(
        db.dialect
            .sql("SELECT strftime('%Y-%m-%d %H:%M:%SZ', 'now')"),
    )
    .fetch_one(&db.pool)
    .await
    .map_err(query("reading the clock"))
}

/// Every grasp session with its trials, oldest first.
///
/// # Errors
/// A query failed, or a row does not read back.
pub async fn grasp_sessions(
    db: &ReadOnly,
) -> Result<Vec<(crate::GraspSessionRow, Vec<crate::GraspTrialRow>)>, ReadError> {
    let rows = |e: StoreError| ReadError::Rows(Box::new(e));
    let mut out = Vec::new();
    for session in crate::grasp::sessions_of(&db.pool, db.dialect)
        .await
        .map_err(rows)?
    {
        let trials = crate::grasp::trials_of(&db.pool, db.dialect, session.session_id)
            .await
            .map_err(rows)?;
        out.push((session, trials));
    }
    Ok(out)
}

/// One trial's trace, if stored.
///
/// # Errors
/// A query failed, or the trace does not read back.
pub async fn grasp_trace(
    db: &ReadOnly,
    session_id: i64,
    key: &crate::GraspTrialKey,
) -> Result<Option<crate::GraspTrace>, ReadError> {
    crate::grasp::trace_of(&db.pool, db.dialect, session_id, key)
        .await
        .map_err(|e| ReadError::Rows(Box::new(e)))
}

/// Every stored experiment result with its tables, oldest first.
///
/// # Errors
/// A query failed.
pub async fn results(db: &ReadOnly) -> Result<Vec<crate::StoredResult>, ReadError> {
    let rows = |e: StoreError| ReadError::Rows(Box::new(e));
    let mut out = Vec::new();
    for row in crate::results::results_of(&db.pool, db.dialect)
        .await
        .map_err(rows)?
    {
        let tables = crate::results::tables_of(&db.pool, db.dialect, row.result_id)
            .await
            .map_err(rows)?;
        let figures = crate::results::figures_of(&db.pool, db.dialect, row.result_id)
            .await
            .map_err(rows)?;
        out.push(crate::StoredResult {
            row,
            tables,
            figures,
        });
    }
    Ok(out)
}
