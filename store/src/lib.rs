//! The database: one writer per table, typed rows for every reader, migrations
//! applied; the only crate with SQL, and it must depend on no model, simulator or CLI.
//!
//! The store: SQLite (the embedded default: one file, WAL, foreign keys on) or
//! PostgreSQL (the fleet database: several rigs, one server), through sqlx's `Any`
//! driver, with one set of migrations per engine embedded from the workspace's
//! `migrations/sqlite` and `migrations/postgres`.
//!
//! Why `Any` and one text per query (rather than a trait with an implementation per
//! engine, or generics over sqlx's `Database`): the store's ~100 queries mean the same
//! on both engines, so one text each keeps one place to review them, and the few
//! spellings that differ are rewritten in one tested function ([`dialect`]). Generics
//! over `Database` would have put sqlx's trait bounds on every caller; two
//! implementations would have doubled every query. `Any` costs one copy of each value
//! read (a frame's bytes are copied once more), far below a PNG's decoding.
//!
//! A sample, its frame and its force/torque window are written in one transaction,
//! idempotent on `(run, index)`: they are all there or all absent, and writing a sample
//! that is already there changes nothing. Queries are built at run time (no
//! `DATABASE_URL` needed to compile).
//!
//! Each table's INSERT is in `rows.rs`, shared with the dataset import; runs are in
//! `runs.rs`, the writer thread in `sync/`; grasp sessions, trials, traces and trial
//! frames in `grasp.rs`; the experiment verbs' results with their tables and figures
//! in `results.rs` (the layout documented in their migrations).

pub mod copy;
pub mod datasets;
pub mod dialect;
mod event;
mod grasp;
mod grasp_calibration;
#[cfg(test)]
mod grasp_migrations;
mod models;
pub mod report;
mod rest_frames;
mod results;
pub mod sqlite_file;
pub use event::EventKind;
pub use grasp::{
    GraspSessionRow, GraspTrace, GraspTrialKey, GraspTrialRow, TRACE_ENCODING, TraceFrame,
    unpack_f32,
};
pub use grasp_calibration::GraspCalibrationRow;
pub use rest_frames::RestFrameRow;
pub use results::{NewResult, ResultRow, StoredResult};
pub mod rows;
mod runs;
pub mod target;
pub mod testing;
mod window;
mod writer;
pub use dialect::Dialect;
pub use target::DbTarget;

pub use runs::{
    LEASE_STALE_S, LeaseHolder, LeaseRow, LeaseTaken, NewRun, RunRecord, RunStatus, RunSummary,
    host_name,
};
pub use writer::{LabelRow, OwnedNewRun, SyncStore, WriterStats, encode_for_store};

pub use models::{Members, ModelInfo, NewModel, PairKey};
pub use window::{WINDOW_ENCODING, decode_window, encode_window};

/// A sample's label as its six stored columns (force in N, torque in N·m, in the
/// sensor's frame), flattened into every row type that carries one.
#[derive(Debug, Clone, Copy, PartialEq, FromRow)]
pub struct WrenchColumns {
    /// Force x, N.
    pub fx_n: f64,
    /// Force y, N.
    pub fy_n: f64,
    /// Force z, N.
    pub fz_n: f64,
    /// Torque x, N·m.
    pub tx_nm: f64,
    /// Torque y, N·m.
    pub ty_nm: f64,
    /// Torque z, N·m.
    pub tz_nm: f64,
}

impl WrenchColumns {
    /// Force, N.
    #[must_use]
    pub fn force_n(&self) -> [f64; 3] {
        [self.fx_n, self.fy_n, self.fz_n]
    }
    /// Torque, N·m.
    #[must_use]
    pub fn torque_nm(&self) -> [f64; 3] {
        [self.tx_nm, self.ty_nm, self.tz_nm]
    }
}

/// A dataset member (or any sample) with its label and its frame, as the trainer's
/// readers take it: split, identity, the label (N, N·m) and the stored frame.
#[derive(Debug, Clone, FromRow)]
pub struct MemberRow {
    /// `train`, `val` or `test`.
    pub split: String,
    /// Its run.
    pub run_id: i64,
    /// Its index in the run.
    pub sample_index: i64,
    /// The label: mean force and torque over the window, sensor frame.
    #[sqlx(flatten)]
    pub wrench: WrenchColumns,
    /// The frame's format as stored.
    pub format: String,
    /// Width, px.
    pub width: i64,
    /// Height, px.
    pub height: i64,
    /// The frame's bytes as stored.
    pub data: Vec<u8>,
}

use softtouch_schemas::{FrameMeta, FtReading, Sample, SampleStatus};
use sqlx::AnyPool;
use sqlx::any::AnyPoolOptions;
use sqlx::{Executor as _, FromRow, Row};
use std::path::PathBuf;
use std::time::Duration;

/// SQLite's migrations, embedded at build time.
pub static MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("../migrations/sqlite");

/// PostgreSQL's migrations: the same tables, owners and versions in PostgreSQL's types.
pub static PG_MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("../migrations/postgres");

/// Identifies a run.
pub type RunId = i64;

mod error;
mod open;

pub use error::{StoreError, query_err};

/// Level of an event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventLevel {
    /// Worth knowing.
    Info,
    /// Something went wrong and was recovered.
    Warn,
    /// Something went wrong and was not recovered.
    Error,
}

impl EventLevel {
    /// As stored.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Info => "info",
            Self::Warn => "warn",
            Self::Error => "error",
        }
    }
}

/// A frame to store with its sample: metadata and encoded bytes.
#[derive(Debug, Clone, Copy)]
pub struct FrameRecord<'a> {
    /// Time, counter, size, encoding.
    pub meta: FrameMeta,
    /// Encoded pixels.
    pub data: &'a [u8],
}

/// Outcome of [`Store::append_sample`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Appended {
    /// Written.
    Inserted,
    /// A sample with this `(run, index)` was already there; nothing changed.
    AlreadyPresent,
}

/// An event as stored.
#[derive(Debug, Clone, PartialEq, FromRow)]
pub struct EventRow {
    /// Order of logging.
    pub event_id: i64,
    /// The run.
    pub run_id: RunId,
    /// The sample it concerns, if any.
    pub sample_index: Option<i64>,
    /// Run clock, ns, where known.
    pub t_ns: Option<i64>,
    /// Wall clock (UTC).
    pub created_at: String,
    /// `info`, `warn` or `error`.
    pub level: String,
    /// Short machine-readable kind, e.g. `arm_reflex`.
    pub kind: String,
    /// What happened.
    pub message: String,
}

/// The store.
#[derive(Clone)]
pub struct Store {
    pool: AnyPool,
    dialect: Dialect,
    target: DbTarget,
}

/// By hand: the target as shown (no password), and nothing of the pool's settings.
impl std::fmt::Debug for Store {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Store")
            .field("dialect", &self.dialect)
            .field("target", &self.target.display().to_string())
            .finish_non_exhaustive()
    }
}

fn to_i64(what: &'static str, v: u64) -> Result<i64, StoreError> {
    i64::try_from(v).map_err(|_| StoreError::Invalid {
        what,
        why: format!("{v} exceeds SQLite's integer range"),
    })
}

impl Store {
    /// Where the database is.
    #[must_use]
    pub fn target(&self) -> &DbTarget {
        &self.target
    }

    /// The engine's spelling of the store's queries.
    #[must_use]
    pub const fn dialect(&self) -> Dialect {
        self.dialect
    }

    /// The schema version this build writes (the newest migration).
    #[must_use]
    pub fn schema_version() -> i64 {
        MIGRATOR.iter().map(|m| m.version).max().unwrap_or(0)
    }

    /// The underlying pool, for crate-internal queries and tests.
    #[must_use]
    pub fn pool(&self) -> &AnyPool {
        &self.pool
    }

    /// Close the pool. On SQLite, first copy the write-ahead log into the database
    /// file ([`sqlite_file::checkpoint`]), so that the `.db` file alone holds everything
    /// committed (what another process is still writing stays in the log until it
    /// closes); PostgreSQL's commits are the server's from the start.
    pub async fn close(self) {
        if self.dialect == Dialect::Sqlite
            && let Err(e) = sqlite_file::checkpoint_on(&self.pool).await
        {
            tracing::debug!("checkpoint on close of {}: {e}", self.target.display());
        }
        self.pool.close().await;
    }

    /// The database's bytes on disk: the file and its write-ahead log (SQLite), or the
    /// database's size on its server (PostgreSQL's `pg_database_size`).
    ///
    /// # Errors
    /// The query fails.
    pub async fn database_bytes(&self) -> Result<u64, StoreError> {
        match &self.target {
            DbTarget::File(path) => Ok(sqlite_file::db_size(path).total()),
            DbTarget::Postgres(_) => {
                let n: i64 = sqlx::query_scalar("SELECT pg_database_size(current_database())")
                    .fetch_one(&self.pool)
                    .await
                    .map_err(query_err("measuring the database"))?;
                Ok(u64::try_from(n).unwrap_or(0))
            }
        }
    }

    /// How many samples the database holds, over every run.
    ///
    /// # Errors
    /// The query fails.
    pub async fn stored_samples(&self) -> Result<u64, StoreError> {
        let n: i64 = sqlx::query_scalar(self.dialect.sql("SELECT COUNT(*) FROM samples"))
            .fetch_one(&self.pool)
            .await
            .map_err(query_err("counting samples"))?;
        Ok(u64::try_from(n).unwrap_or(0))
    }

    /// Frames stored and their bytes: over every run, or over the runs of the scene
    /// named `scene_name` (what a sample of that scene will take, for the disk estimate).
    ///
    /// # Errors
    /// The query fails.
    pub async fn frame_bytes(&self, scene_name: Option<&str>) -> Result<(u64, u64), StoreError> {
        // LENGTH of a blob reads its size, not its bytes, on both engines.
        let (n, bytes): (i64, i64) =
            match scene_name {
                None => sqlx::query_as(self.dialect.sql(
                    "SELECT COUNT(*), CAST(COALESCE(SUM(LENGTH(data)), 0) AS BIGINT) FROM frames",
                ))
                .fetch_one(&self.pool)
                .await,
                Some(scene) => {
                    sqlx::query_as(self.dialect.sql(
                        "SELECT COUNT(*), CAST(COALESCE(SUM(LENGTH(f.data)), 0) AS BIGINT)
                 FROM frames f JOIN runs r ON r.run_id = f.run_id WHERE r.scene_name = ?",
                    ))
                    .bind(scene)
                    .fetch_one(&self.pool)
                    .await
                }
            }
            .map_err(query_err("measuring the stored frames"))?;
        Ok((
            u64::try_from(n).unwrap_or(0),
            u64::try_from(bytes).unwrap_or(0),
        ))
    }

    /// Append a sample with its frame and raw window, in one transaction.
    ///
    /// Idempotent on `(run, sample.index)`: if that sample is already stored nothing
    /// is written and [`Appended::AlreadyPresent`] comes back. If any part fails,
    /// nothing of the sample is stored.
    pub async fn append_sample(
        &self,
        run_id: RunId,
        sample: &Sample,
        frame: Option<FrameRecord<'_>>,
        window: &[FtReading],
    ) -> Result<Appended, StoreError> {
        self.append_sample_at(run_id, sample, frame, window, None)
            .await
    }

    /// [`Store::append_sample`], also recording the run's time base (its clock when
    /// this sample was done, where the next sample begins) in the same transaction:
    /// a resume then continues the run's device time exactly, whenever it was killed.
    pub async fn append_sample_at(
        &self,
        run_id: RunId,
        sample: &Sample,
        frame: Option<FrameRecord<'_>>,
        window: &[FtReading],
        time_base: Option<softtouch_schemas::TimestampNs>,
    ) -> Result<Appended, StoreError> {
        let time_base_ns = time_base.map(|t| to_i64("time_base_ns", t.0)).transpose()?;
        let mut tx = self
            .pool
            .begin()
            .await
            .map_err(query_err("starting a sample transaction"))?;
        if !rows::insert_sample(&mut tx, run_id, sample).await? {
            tx.rollback()
                .await
                .map_err(query_err("rolling back a duplicate sample"))?;
            return Ok(Appended::AlreadyPresent);
        }
        // A sample rejected before any frame came (frame timeout, arm fault) has none.
        if let Some(frame) = frame {
            rows::insert_frame(&mut tx, run_id, sample.index, frame).await?;
        }
        rows::insert_ft_window(&mut tx, run_id, sample.index, window).await?;
        sqlx::query(Dialect::of(&tx).sql(concat!(
            "UPDATE runs SET updated_at = ",
            now_sql!(),
            ", time_base_ns = COALESCE(?, time_base_ns) WHERE run_id = ?"
        )))
        .bind(time_base_ns)
        .bind(run_id)
        .execute(&mut *tx)
        .await
        .map_err(query_err("touching the run"))?;
        tx.commit()
            .await
            .map_err(query_err("committing a sample"))?;
        Ok(Appended::Inserted)
    }

    /// Log an event for a run.
    pub async fn log_event(
        &self,
        run_id: RunId,
        sample_index: Option<u64>,
        t: Option<softtouch_schemas::TimestampNs>,
        level: EventLevel,
        kind: &str,
        message: &str,
    ) -> Result<(), StoreError> {
        let mut conn = self
            .pool
            .acquire()
            .await
            .map_err(query_err("logging an event"))?;
        rows::insert_event(&mut conn, run_id, sample_index, t, level, kind, message).await
    }

    /// The last `limit` events of a run, oldest first.
    pub async fn events(&self, run_id: RunId, limit: u32) -> Result<Vec<EventRow>, StoreError> {
        let mut rows = sqlx::query_as::<_, EventRow>(self.dialect.sql(
            "SELECT event_id, run_id, sample_index, t_ns, created_at, level, kind, message
             FROM events WHERE run_id = ? ORDER BY event_id DESC LIMIT ?",
        ))
        .bind(run_id)
        .bind(i64::from(limit))
        .fetch_all(&self.pool)
        .await
        .map_err(query_err("reading events"))?;
        rows.reverse();
        Ok(rows)
    }

    /// Counts of samples, frames and windows stored for a run (a consistency check).
    pub async fn row_counts(&self, run_id: RunId) -> Result<RowCounts, StoreError> {
        let row = sqlx::query(self.dialect.sql(
            "SELECT (SELECT COUNT(*) FROM samples WHERE run_id = ?1),
                    (SELECT COUNT(*) FROM frames WHERE run_id = ?1),
                    (SELECT COUNT(*) FROM ft_windows WHERE run_id = ?1)",
        ))
        .bind(run_id)
        .fetch_one(&self.pool)
        .await
        .map_err(query_err("counting rows"))?;
        Ok(RowCounts {
            samples: row.get(0),
            frames: row.get(1),
            windows: row.get(2),
        })
    }

    /// The next sample index to take in a run (one past the highest stored), for resume.
    pub async fn next_index(&self, run_id: RunId) -> Result<u64, StoreError> {
        let max: Option<i64> = sqlx::query_scalar(
            self.dialect
                .sql("SELECT MAX(sample_index) FROM samples WHERE run_id = ?"),
        )
        .bind(run_id)
        .fetch_one(&self.pool)
        .await
        .map_err(query_err("finding the next sample index"))?;
        Ok(max.map_or(0, |m| u64::try_from(m).unwrap_or(0) + 1))
    }

    /// SQLite's `PRAGMA integrity_check`: `ok` or the problems SQLite found. On
    /// PostgreSQL (whose server checks its own pages) `ok` once the server answers.
    pub async fn integrity_check(&self) -> Result<String, StoreError> {
        if self.dialect == Dialect::Postgres {
            sqlx::query("SELECT 1")
                .fetch_one(&self.pool)
                .await
                .map_err(query_err("checking integrity"))?;
            return Ok("ok".to_owned());
        }
        let rows: Vec<String> = sqlx::query_scalar("PRAGMA integrity_check")
            .fetch_all(&self.pool)
            .await
            .map_err(query_err("checking integrity"))?;
        Ok(rows.join("; "))
    }
}

/// Counts of a run's rows per table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RowCounts {
    /// Samples.
    pub samples: i64,
    /// Frames.
    pub frames: i64,
    /// Force/torque windows.
    pub windows: i64,
}

/// Parse a stored sample status back (used by readers of the store).
pub fn parse_status(status: &str, reason: Option<&str>) -> Result<SampleStatus, String> {
    match (status, reason) {
        ("ok", None) => Ok(SampleStatus::Ok),
        ("rejected", Some(r)) => Ok(SampleStatus::Rejected(r.parse()?)),
        (s, r) => Err(format!(
            "inconsistent sample status `{s}` with reason {r:?}"
        )),
    }
}
