//! What the report reads from the database, through a read-only connection.
//!
//! The report never writes: the database is opened with `SQLITE_OPEN_READONLY`, so
//! even a bug here cannot change it. No migration runs either; a database older
//! than this build is refused with the command that migrates it.

use super::ReportError;
use crate::dataset::export::sha256_hex;
use crate::models::MemberRow;
use crate::store::Store;
use crate::store::{run_counts_columns, run_counts_from};
use sqlx::sqlite::{SqliteConnectOptions, SqlitePool, SqlitePoolOptions};
use sqlx::{FromRow, Row as _};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

fn query(doing: &'static str) -> impl FnOnce(sqlx::Error) -> ReportError {
    move |source| ReportError::Query { doing, source }
}

/// The first 12 hex digits of the SHA-256 of `text`: a config's fingerprint.
#[must_use]
pub(crate) fn config_hash(text: &str) -> String {
    sha256_hex(text.as_bytes())[..12].to_owned()
}

/// Opens `path` read-only and checks that its schema is this build's.
pub(crate) async fn open_read_only(path: &Path) -> Result<SqlitePool, ReportError> {
    if !path.is_file() {
        return Err(ReportError::NoDatabase(path.to_owned()));
    }
    let options = SqliteConnectOptions::new()
        .filename(path)
        .read_only(true)
        .busy_timeout(Duration::from_secs(10));
    let pool = SqlitePoolOptions::new()
        .max_connections(2)
        .connect_with(options)
        .await
        .map_err(|source| ReportError::Open {
            path: path.to_owned(),
            source,
        })?;
    let applied: Result<Option<i64>, _> =
        sqlx::query_scalar("SELECT MAX(version) FROM _sqlx_migrations WHERE success")
            .fetch_one(&pool)
            .await;
    let expected = Store::schema_version();
    match applied {
        Ok(Some(v)) if v >= expected => Ok(pool),
        Ok(found) => Err(ReportError::Schema {
            path: path.to_owned(),
            found: found.unwrap_or(0),
            expected,
        }),
        Err(_) => Err(ReportError::Schema {
            path: path.to_owned(),
            found: 0,
            expected,
        }),
    }
}

/// A run with its counts and provenance.
#[derive(Debug, Clone, FromRow)]
pub(crate) struct RunRow {
    pub run_id: i64,
    pub status: String,
    pub seed: i64,
    pub scene_name: String,
    pub medium: String,
    pub samples_planned: i64,
    pub ok: i64,
    pub rejected: i64,
    pub retried: i64,
    pub events: i64,
    pub faults: i64,
    pub software_version: String,
    pub rig_toml: String,
    pub scene_toml: String,
    pub created_at: String,
    pub updated_at: String,
    /// Wall-clock hours from creation to the last change.
    pub hours: f64,
    /// Run clock of the first and last frame, ns.
    pub first_t_ns: Option<i64>,
    pub last_t_ns: Option<i64>,
}

/// Everything the Runs section shows of one run.
#[derive(Debug, Clone)]
pub(crate) struct RunData {
    pub row: RunRow,
    /// Rejected samples per reason.
    pub rejects: BTreeMap<String, i64>,
    /// Events per `(kind, level)`.
    pub event_counts: BTreeMap<(String, String), i64>,
    /// Events with a run-clock time: `(t_ns, kind, level)`, at most [`MAX_TIMELINE`].
    pub timeline: Vec<(i64, String, String)>,
    /// The last events, oldest first: `(sample, created_at, level, kind, message)`.
    pub latest: Vec<(Option<i64>, String, String, String, String)>,
    /// Cumulative accepted and rejected samples against the run clock (downsampled):
    /// `(t_ns, ok so far, rejected so far)`.
    pub progress: Vec<(i64, i64, i64)>,
}

/// Events drawn on a run's timeline at most (the counts table has them all).
pub(crate) const MAX_TIMELINE: i64 = 5_000;
/// Latest events listed per run.
pub(crate) const LATEST_EVENTS: i64 = 12;
/// Points of a run's progress curve at most.
const PROGRESS_POINTS: usize = 400;

/// The runs (all, or those listed), oldest first.
pub(crate) async fn runs(
    pool: &SqlitePool,
    only: Option<&[i64]>,
) -> Result<Vec<RunData>, ReportError> {
    let rows = sqlx::query_as::<_, RunRow>(concat!(
        "SELECT ",
        run_counts_columns!(),
        ", r.software_version, r.rig_toml, r.scene_toml, s.first_t_ns, s.last_t_ns",
        run_counts_from!(),
        " ORDER BY r.run_id"
    ))
    .fetch_all(pool)
    .await
    .map_err(query("listing runs"))?;
    if let Some(only) = only
        && let Some(missing) = only
            .iter()
            .find(|id| !rows.iter().any(|r| r.run_id == **id))
    {
        return Err(ReportError::NoSuchRun(*missing));
    }
    let mut out = Vec::new();
    for row in rows {
        if only.is_some_and(|ids| !ids.contains(&row.run_id)) {
            continue;
        }
        out.push(run_data(pool, row).await?);
    }
    Ok(out)
}

async fn run_data(pool: &SqlitePool, row: RunRow) -> Result<RunData, ReportError> {
    let id = row.run_id;
    let rejects: Vec<(String, i64)> = sqlx::query_as(
        "SELECT COALESCE(reject_reason, '?'), COUNT(*) FROM samples
         WHERE run_id = ? AND status = 'rejected' GROUP BY 1 ORDER BY 2 DESC, 1",
    )
    .bind(id)
    .fetch_all(pool)
    .await
    .map_err(query("counting rejects"))?;
    let counts: Vec<(String, String, i64)> =
        sqlx::query_as("SELECT kind, level, COUNT(*) FROM events WHERE run_id = ? GROUP BY 1, 2")
            .bind(id)
            .fetch_all(pool)
            .await
            .map_err(query("counting events"))?;
    let timeline: Vec<(i64, String, String)> = sqlx::query_as(
        "SELECT t_ns, kind, level FROM events WHERE run_id = ? AND t_ns IS NOT NULL
         ORDER BY event_id LIMIT ?",
    )
    .bind(id)
    .bind(MAX_TIMELINE)
    .fetch_all(pool)
    .await
    .map_err(query("reading events"))?;
    let mut latest: Vec<(Option<i64>, String, String, String, String)> = sqlx::query_as(
        "SELECT sample_index, created_at, level, kind, message FROM events
         WHERE run_id = ? ORDER BY event_id DESC LIMIT ?",
    )
    .bind(id)
    .bind(LATEST_EVENTS)
    .fetch_all(pool)
    .await
    .map_err(query("reading events"))?;
    latest.reverse();
    // Samples in the order they were taken, cumulated, then thinned for the figure.
    let statuses: Vec<(i64, String)> = sqlx::query_as(
        "SELECT frame_t_ns, status FROM samples WHERE run_id = ? ORDER BY frame_t_ns, sample_index",
    )
    .bind(id)
    .fetch_all(pool)
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
    let mut progress: Vec<(i64, i64, i64)> =
        super::svg::downsample_indices(cumulative.len(), PROGRESS_POINTS)
            .into_iter()
            .map(|i| cumulative[i])
            .collect();
    // The last point is the total.
    if let Some(last) = cumulative.last()
        && progress.last() != Some(last)
    {
        progress.push(*last);
    }
    Ok(RunData {
        row,
        rejects: rejects.into_iter().collect(),
        event_counts: counts.into_iter().map(|(k, l, n)| ((k, l), n)).collect(),
        timeline,
        latest,
        progress,
    })
}

/// A dataset with its splits and label values.
#[derive(Debug, Clone)]
pub(crate) struct DatasetData {
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
pub(crate) async fn datasets(
    pool: &SqlitePool,
    runs: Option<&[i64]>,
) -> Result<Vec<DatasetData>, ReportError> {
    let rows = sqlx::query(
        "SELECT dataset_id, name, definition_json, seed, split_ratio, sample_count,
                software_version, created_at FROM datasets ORDER BY dataset_id",
    )
    .fetch_all(pool)
    .await
    .map_err(query("listing datasets"))?;
    let mut out = Vec::new();
    for r in rows {
        let dataset_id: i64 = r.get(0);
        let member_runs: Vec<i64> = sqlx::query_scalar(
            "SELECT DISTINCT run_id FROM dataset_members WHERE dataset_id = ? ORDER BY run_id",
        )
        .bind(dataset_id)
        .fetch_all(pool)
        .await
        .map_err(query("reading a dataset's runs"))?;
        if runs.is_some_and(|wanted| !member_runs.iter().any(|id| wanted.contains(id))) {
            continue;
        }
        let split_rows: Vec<(String, i64)> = sqlx::query_as(
            "SELECT split, COUNT(*) FROM dataset_members WHERE dataset_id = ? GROUP BY split",
        )
        .bind(dataset_id)
        .fetch_all(pool)
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
        let labels: Vec<(f64, f64, f64, f64, f64, f64)> = sqlx::query_as(
            "SELECT s.fx_n, s.fy_n, s.fz_n, s.tx_nm, s.ty_nm, s.tz_nm
             FROM dataset_members m
             JOIN samples s ON s.run_id = m.run_id AND s.sample_index = m.sample_index
             WHERE m.dataset_id = ? ORDER BY m.position",
        )
        .bind(dataset_id)
        .fetch_all(pool)
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
pub(crate) struct ModelRow {
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
pub(crate) async fn models(
    pool: &SqlitePool,
    only: Option<&[String]>,
) -> Result<Vec<ModelRow>, ReportError> {
    let rows = sqlx::query_as::<_, ModelRow>(
        "SELECT model_id, name, dataset_id, dataset_name, kind, config_json, train_json,
                metrics_json, history_json, test_r2_mean, test_image_mse, software_version,
                created_at
         FROM models ORDER BY model_id",
    )
    .fetch_all(pool)
    .await
    .map_err(query("listing models"))?;
    if let Some(only) = only {
        if let Some(missing) = only.iter().find(|n| !rows.iter().any(|r| &r.name == *n)) {
            return Err(ReportError::NoSuchModel(missing.clone()));
        }
        return Ok(rows
            .into_iter()
            .filter(|r| only.contains(&r.name))
            .collect());
    }
    Ok(rows)
}

/// A model's artifact bytes.
pub(crate) async fn artifact(pool: &SqlitePool, model_id: i64) -> Result<Vec<u8>, ReportError> {
    sqlx::query_scalar("SELECT artifact FROM models WHERE model_id = ?")
        .bind(model_id)
        .fetch_one(pool)
        .await
        .map_err(query("reading a model's artifact"))
}

/// The test members of a dataset, in dataset order: `(run, sample)`.
pub(crate) async fn test_members(
    pool: &SqlitePool,
    dataset_id: i64,
) -> Result<Vec<(i64, i64)>, ReportError> {
    sqlx::query_as(
        "SELECT run_id, sample_index FROM dataset_members
         WHERE dataset_id = ? AND split = 'test' ORDER BY position",
    )
    .bind(dataset_id)
    .fetch_all(pool)
    .await
    .map_err(query("listing a dataset's test split"))
}

/// Test sample `(run, index)`'s label and frame, if it has a frame.
pub(crate) async fn frame(
    pool: &SqlitePool,
    (run, index): (i64, i64),
) -> Result<Option<MemberRow>, ReportError> {
    sqlx::query_as::<_, MemberRow>(
        "SELECT 'test' AS split, s.run_id, s.sample_index,
                s.fx_n, s.fy_n, s.fz_n, s.tx_nm, s.ty_nm, s.tz_nm,
                f.format, f.width, f.height, f.data
         FROM samples s JOIN frames f ON f.run_id = s.run_id AND f.sample_index = s.sample_index
         WHERE s.run_id = ? AND s.sample_index = ?",
    )
    .bind(run)
    .bind(index)
    .fetch_optional(pool)
    .await
    .map_err(query("reading a test frame"))
}

/// The database's clock, as the page's date (UTC).
pub(crate) async fn now(pool: &SqlitePool) -> Result<String, ReportError> {
    sqlx::query_scalar("SELECT strftime('%Y-%m-%d %H:%M:%SZ', 'now')")
        .fetch_one(pool)
        .await
        .map_err(query("reading the clock"))
}
