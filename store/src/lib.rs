//! The database: one writer per table, typed rows for every reader, migrations
//! applied; the only crate with SQL, and it must depend on no model, simulator or CLI.
//!
//! The store: SQLite through sqlx, WAL, foreign keys on, migrations embedded from the
//! workspace's `migrations/`.
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

pub mod datasets;
mod event;
pub mod file;
mod grasp;
mod grasp_calibration;
mod models;
pub mod report;
mod results;
pub use event::EventKind;
pub use grasp::{
    GraspSessionRow, GraspTrace, GraspTrialKey, GraspTrialRow, TRACE_ENCODING, TraceFrame,
    unpack_f32,
};
pub use grasp_calibration::GraspCalibrationRow;
pub use results::{NewResult, ResultRow, StoredResult};
pub mod rows;
mod runs;
mod sync;
mod window;

pub use runs::{
    LEASE_STALE_S, LeaseHolder, LeaseRow, LeaseTaken, NewRun, RunRecord, RunStatus, RunSummary,
    host_name,
};
pub use sync::{LabelRow, OwnedNewRun, SyncStore, WriterStats, encode_for_store};

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
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};
use sqlx::{FromRow, Row, SqlitePool};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The migrations, embedded at build time.
pub static MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("../migrations");

/// Identifies a run.
pub type RunId = i64;

/// The store failed.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The path holds something other than a SQLite database.
    #[error(
        "{} is not a SQLite database (it starts with \"{starts_with}\", not \"SQLite format 3\"): pass --db with the database's path, or move this file away",
        path.display()
    )]
    NotADatabase {
        /// The file.
        path: PathBuf,
        /// Its first bytes, escaped.
        starts_with: String,
    },
    /// The path is an empty file where a database was expected.
    #[error(
        "{} is an empty file, not a database: `softtouch --db {} db init` sets it up as a new one",
        path.display(), path.display()
    )]
    EmptyFile {
        /// The file.
        path: PathBuf,
    },
    /// The file (not the database in it) cannot be read or asked about.
    #[error("{}: {why}", path.display())]
    File {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// Opening or migrating the database failed.
    #[error("cannot open database {path}: {source}")]
    Open {
        /// The database file.
        path: PathBuf,
        /// Why.
        #[source]
        source: sqlx::Error,
    },
    /// Migrating the database failed.
    #[error("cannot migrate database {path}: {source}")]
    Migrate {
        /// The database file.
        path: PathBuf,
        /// Why.
        #[source]
        source: sqlx::migrate::MigrateError,
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
    /// A value cannot be stored (e.g. an index beyond SQLite's integer range).
    #[error("cannot store {what}: {why}")]
    Invalid {
        /// Which value.
        what: &'static str,
        /// Why.
        why: String,
    },
    /// A stored value does not read back (a damaged database, or one written by
    /// something else).
    #[error("damaged {what} in the database: {why}")]
    Damaged {
        /// Which value.
        what: &'static str,
        /// Where, and what was found instead of what was expected.
        why: String,
    },
    /// No database where one must be.
    #[error("no database at {}: create it with `softtouch db init` (or pass --db PATH)", .0.display())]
    NoDatabase(PathBuf),
    /// No such run.
    #[error("no run {0} in this database")]
    NoSuchRun(RunId),
    /// Another live process is collecting the run.
    #[error(
        "run {run_id} is being collected by {holder}; stop that process first \
         (a lease is taken over once its process is gone, or after {} s without a heartbeat from another host)",
        runs::LEASE_STALE_S
    )]
    Leased {
        /// The run.
        run_id: RunId,
        /// Who holds it.
        holder: LeaseRow,
    },
    /// Another process took this job's lease over (it found ours stale).
    #[error(
        "lost the lease on run {run_id} to another process; stopping so that one writer remains"
    )]
    LeaseLost {
        /// The run.
        run_id: RunId,
    },
    /// A run meant to repeat another's poses (`collect --poses-from`) does not.
    #[error("run {run_id} does not pair with run {from_run}: {why}")]
    Unpaired {
        /// The paired run.
        run_id: RunId,
        /// The run whose poses it should repeat.
        from_run: RunId,
        /// The first difference.
        why: String,
    },
}

impl StoreError {
    /// Whether the user's input is at fault (a path or run that is not there, a file
    /// that is not a database) rather than the machine.
    #[must_use]
    pub const fn is_bad_input(&self) -> bool {
        matches!(
            self,
            Self::NoSuchRun(_)
                | Self::NoDatabase(_)
                | Self::EmptyFile { .. }
                | Self::NotADatabase { .. }
        )
    }
}

/// Maps a query's error to [`StoreError::Query`], saying what was being done.
pub fn query_err(doing: &'static str) -> impl FnOnce(sqlx::Error) -> StoreError {
    move |source| StoreError::Query { doing, source }
}

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
#[derive(Debug, Clone)]
pub struct Store {
    pool: SqlitePool,
    path: PathBuf,
}

fn to_i64(what: &'static str, v: u64) -> Result<i64, StoreError> {
    i64::try_from(v).map_err(|_| StoreError::Invalid {
        what,
        why: format!("{v} exceeds SQLite's integer range"),
    })
}

impl Store {
    /// Open (creating if missing) and migrate the database at `path`. An empty file
    /// is set up as a new database, with a warning saying so; a file that is not a
    /// database is refused.
    ///
    /// # Errors
    /// [`StoreError::NotADatabase`], or SQLite's refusal to open or migrate it.
    pub async fn open(path: &Path) -> Result<Self, StoreError> {
        match file::inspect(path)? {
            file::DbFile::NotSqlite { starts_with } => {
                return Err(file::not_a_database(path, starts_with));
            }
            file::DbFile::Empty => tracing::warn!(
                "{} is an empty file: setting it up as a new database",
                path.display()
            ),
            file::DbFile::Missing | file::DbFile::Sqlite => {}
        }
        Self::connect(path).await
    }

    /// Open and migrate the database that must already be at `path`: a missing or empty
    /// file is an error (a mistyped `--db` leaves no new database behind).
    ///
    /// # Errors
    /// [`StoreError::NoDatabase`], [`StoreError::EmptyFile`],
    /// [`StoreError::NotADatabase`], or SQLite's refusal.
    pub async fn open_existing(path: &Path) -> Result<Self, StoreError> {
        match file::inspect(path)? {
            file::DbFile::Sqlite => Self::connect(path).await,
            file::DbFile::Missing => Err(StoreError::NoDatabase(path.to_owned())),
            file::DbFile::Empty => Err(StoreError::EmptyFile {
                path: path.to_owned(),
            }),
            file::DbFile::NotSqlite { starts_with } => Err(file::not_a_database(path, starts_with)),
        }
    }

    async fn connect(path: &Path) -> Result<Self, StoreError> {
        let options = SqliteConnectOptions::new()
            .filename(path)
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            // NORMAL in WAL mode: a killed process loses nothing committed; a power cut
            // may lose the last commits but never corrupts the file.
            .synchronous(SqliteSynchronous::Normal)
            .foreign_keys(true)
            .busy_timeout(Duration::from_secs(10));
        // Two processes opening a new database at once race: switching the new file to
        // WAL can find it locked, and both try the first migration (the loser fails on
        // a table that now exists). Once the winner is done, a second look succeeds.
        let mut attempt = 0u64;
        let pool = loop {
            attempt += 1;
            let result = match SqlitePoolOptions::new()
                .max_connections(4)
                .connect_with(options.clone())
                .await
            {
                Ok(pool) => match MIGRATOR.run(&pool).await {
                    Ok(()) => Ok(pool),
                    Err(source) => Err(StoreError::Migrate {
                        path: path.to_owned(),
                        source,
                    }),
                },
                Err(source) => Err(StoreError::Open {
                    path: path.to_owned(),
                    source,
                }),
            };
            match result {
                Ok(pool) => break pool,
                Err(_) if attempt < 5 => {
                    tokio::time::sleep(Duration::from_millis(40 * attempt)).await
                }
                Err(e) => return Err(e),
            }
        };
        Ok(Self {
            pool,
            path: path.to_owned(),
        })
    }

    /// The database file.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The schema version this build writes (the newest migration).
    #[must_use]
    pub fn schema_version() -> i64 {
        MIGRATOR.iter().map(|m| m.version).max().unwrap_or(0)
    }

    /// The underlying pool, for crate-internal queries and tests.
    #[must_use]
    pub fn pool(&self) -> &SqlitePool {
        &self.pool
    }

    /// Close the pool after copying the write-ahead log into the database file
    /// ([`file::checkpoint`]), so that the `.db` file alone holds everything committed
    /// (what another process is still writing stays in the log until it closes).
    pub async fn close(self) {
        if let Err(e) = file::checkpoint_on(&self.pool).await {
            tracing::debug!("checkpoint on close of {}: {e}", self.path.display());
        }
        self.pool.close().await;
    }

    /// How many samples the database holds, over every run.
    ///
    /// # Errors
    /// The query fails.
    pub async fn stored_samples(&self) -> Result<u64, StoreError> {
        let n: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM samples")
            .fetch_one(&self.pool)
            .await
            .map_err(query_err("counting samples"))?;
        Ok(u64::try_from(n).unwrap_or(0))
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
        sqlx::query(concat!(
            "UPDATE runs SET updated_at = ",
            now_sql!(),
            ", time_base_ns = COALESCE(?, time_base_ns) WHERE run_id = ?"
        ))
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
        let mut rows = sqlx::query_as::<_, EventRow>(
            "SELECT event_id, run_id, sample_index, t_ns, created_at, level, kind, message
             FROM events WHERE run_id = ? ORDER BY event_id DESC LIMIT ?",
        )
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
        let row = sqlx::query(
            "SELECT (SELECT COUNT(*) FROM samples WHERE run_id = ?1),
                    (SELECT COUNT(*) FROM frames WHERE run_id = ?1),
                    (SELECT COUNT(*) FROM ft_windows WHERE run_id = ?1)",
        )
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
        let max: Option<i64> =
            sqlx::query_scalar("SELECT MAX(sample_index) FROM samples WHERE run_id = ?")
                .bind(run_id)
                .fetch_one(&self.pool)
                .await
                .map_err(query_err("finding the next sample index"))?;
        Ok(max.map_or(0, |m| u64::try_from(m).unwrap_or(0) + 1))
    }

    /// `PRAGMA integrity_check`: `ok` or the problems SQLite found.
    pub async fn integrity_check(&self) -> Result<String, StoreError> {
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
