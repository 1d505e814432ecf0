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
mod models;
pub mod report;
mod results;
pub mod sqlite_file;
pub use event::EventKind;
pub use grasp::{
    GraspSessionRow, GraspTrace, GraspTrialKey, GraspTrialRow, TRACE_ENCODING, TraceFrame,
    unpack_f32,
};
pub use grasp_calibration::GraspCalibrationRow;
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
    #[error("cannot open database {db}: {source}")]
    Open {
        /// The database, as shown (a URL without its password).
        db: String,
        /// Why.
        #[source]
        source: sqlx::Error,
    },
    /// The server refused the URL: a wrong user or password, a database that is not
    /// there, a malformed option.
    #[error("{db}: {why}")]
    Refused {
        /// The database, as shown (a URL without its password).
        db: String,
        /// The server's words.
        why: String,
    },
    /// Migrating the database failed.
    #[error("cannot migrate database {db}: {source}")]
    Migrate {
        /// The database, as shown.
        db: String,
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
    /// A folder where a database file was expected.
    #[error(
        "{} is a folder, not a database file: pass --db with a file's path (e.g. {}/softtouch.db)",
        .0.display(), .0.display()
    )]
    Folder(PathBuf),
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
                | Self::Folder(_)
                | Self::EmptyFile { .. }
                | Self::NotADatabase { .. }
                | Self::Refused { .. }
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
    /// Open (creating if missing) and migrate the database at `target` (a path, or a
    /// PostgreSQL URL: see [`DbTarget`]). An empty file is set up as a new database,
    /// with a warning saying so; a file that is not a database is refused.
    ///
    /// # Errors
    /// [`StoreError::NotADatabase`], or the engine's refusal to open or migrate it.
    pub async fn open(target: impl Into<DbTarget>) -> Result<Self, StoreError> {
        let target = target.into();
        let DbTarget::File(path) = &target else {
            return Self::connect(target).await;
        };
        match sqlite_file::inspect(path)? {
            sqlite_file::DbFile::NotSqlite { starts_with } => {
                return Err(sqlite_file::not_a_database(path, starts_with));
            }
            sqlite_file::DbFile::Empty => tracing::warn!(
                "{} is an empty file: setting it up as a new database",
                path.display()
            ),
            sqlite_file::DbFile::Missing | sqlite_file::DbFile::Sqlite => {}
        }
        Self::connect(target).await
    }

    /// Open and migrate the database that must already be at `target`: a missing or
    /// empty file is an error (a mistyped `--db` leaves no new database behind). A
    /// PostgreSQL database must exist on its server (this never creates one).
    ///
    /// # Errors
    /// [`StoreError::NoDatabase`], [`StoreError::EmptyFile`],
    /// [`StoreError::NotADatabase`], or the engine's refusal.
    pub async fn open_existing(target: impl Into<DbTarget>) -> Result<Self, StoreError> {
        let target = target.into();
        let DbTarget::File(path) = &target else {
            return Self::connect(target).await;
        };
        match sqlite_file::inspect(path)? {
            sqlite_file::DbFile::Sqlite => Self::connect(target).await,
            sqlite_file::DbFile::Missing => Err(StoreError::NoDatabase(path.clone())),
            sqlite_file::DbFile::Empty => Err(StoreError::EmptyFile { path: path.clone() }),
            sqlite_file::DbFile::NotSqlite { starts_with } => {
                Err(sqlite_file::not_a_database(path, starts_with))
            }
        }
    }

    async fn connect(target: DbTarget) -> Result<Self, StoreError> {
        sqlx::any::install_default_drivers();
        let shown = target.display().to_string();
        let (url, dialect) = target.url_and_dialect("rwc");
        let migrator = match dialect {
            Dialect::Sqlite => &MIGRATOR,
            Dialect::Postgres => &PG_MIGRATOR,
        };
        if dialect == Dialect::Postgres {
            // One connection first, so that a server that is not there, a refused login
            // or a missing database is said at once (the pool would retry for its whole
            // acquire timeout).
            use sqlx::Connection as _;
            let conn = sqlx::AnyConnection::connect(&url)
                .await
                .map_err(|source| connect_error(&shown, source))?;
            let _ = conn.close().await;
        }
        // Two processes opening a new database at once race: switching a new SQLite file
        // to WAL can find it locked, and both try the first migration (the loser fails on
        // a table that now exists; on PostgreSQL sqlx's advisory lock serialises them).
        // Once the winner is done, a second look succeeds.
        let mut attempt = 0u64;
        let pool = loop {
            attempt += 1;
            let result = match pool_options(dialect).connect(&url).await {
                Ok(pool) => match migrator.run(&pool).await {
                    Ok(()) => Ok(pool),
                    Err(source) => Err(StoreError::Migrate {
                        db: shown.clone(),
                        source,
                    }),
                },
                Err(source) => Err(connect_error(&shown, source)),
            };
            match result {
                Ok(pool) => break pool,
                Err(e @ StoreError::Refused { .. }) => return Err(e),
                Err(_) if attempt < 5 => {
                    tokio::time::sleep(Duration::from_millis(40 * attempt)).await
                }
                Err(e) => return Err(e),
            }
        };
        Ok(Self {
            pool,
            dialect,
            target,
        })
    }

    /// Create the database `name` on the PostgreSQL server of `server_url` (a URL of
    /// any database there the user may connect to, usually `postgres`); the new
    /// database's URL. The user needs `CREATEDB`. What a lab runs once per server (and
    /// what the tests run for each test).
    ///
    /// # Errors
    /// The server refuses (the name is taken, no right to create), or cannot be reached.
    pub async fn create_postgres_database(
        server_url: &str,
        name: &str,
    ) -> Result<DbTarget, StoreError> {
        use sqlx::Connection as _;
        let shown = target::redact(server_url);
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        {
            return Err(StoreError::Invalid {
                what: "database name",
                why: format!("`{name}`: use lower-case letters, digits and _"),
            });
        }
        let mut conn = sqlx::PgConnection::connect(server_url)
            .await
            .map_err(|source| connect_error(&shown, source))?;
        sqlx::raw_sql(sqlx::AssertSqlSafe(format!("CREATE DATABASE {name}")))
            .execute(&mut conn)
            .await
            .map_err(query_err("creating a database"))?;
        let _ = conn.close().await;
        Ok(DbTarget::Postgres(
            target::with_database(server_url, name).into(),
        ))
    }

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

/// The pool's settings per engine. SQLite: WAL, NORMAL sync, foreign keys, a 10 s busy
/// wait, on every connection. PostgreSQL: the URL's settings; up to 4 connections per
/// process (a collector writes from one thread), 10 s to get one.
fn pool_options(dialect: Dialect) -> AnyPoolOptions {
    let options = AnyPoolOptions::new()
        .max_connections(4)
        .acquire_timeout(Duration::from_secs(10));
    match dialect {
        Dialect::Postgres => options,
        Dialect::Sqlite => options.after_connect(|conn, _meta| {
            Box::pin(async move {
                // NORMAL in WAL mode: a killed process loses nothing committed; a power
                // cut may lose the last commits but never corrupts the file.
                conn.execute(
                    "PRAGMA busy_timeout = 10000; PRAGMA journal_mode = WAL; \
                     PRAGMA synchronous = NORMAL; PRAGMA foreign_keys = ON;",
                )
                .await?;
                Ok(())
            })
        }),
    }
}

/// A failed connection as the user should read it: a wrong password, an unknown user
/// or database, a malformed URL is bad input ([`StoreError::Refused`]); a server that
/// does not answer is a runtime failure ([`StoreError::Open`]).
fn connect_error(shown: &str, source: sqlx::Error) -> StoreError {
    let refused = match &source {
        sqlx::Error::Configuration(e) => Some(format!("bad connection settings: {e}")),
        sqlx::Error::Database(e) => match e.code().as_deref() {
            // invalid_password, invalid_authorization_specification
            Some("28P01" | "28000") => {
                Some(format!("the server refused the login: {}", e.message()))
            }
            // invalid_catalog_name
            Some("3D000") => Some(format!(
                "{} (create it on the server first: `createdb NAME`)",
                e.message()
            )),
            _ => None,
        },
        _ => None,
    };
    match refused {
        Some(why) => StoreError::Refused {
            db: shown.to_owned(),
            why,
        },
        None => StoreError::Open {
            db: shown.to_owned(),
            source,
        },
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
