//! The store: SQLite through sqlx, WAL, foreign keys on, migrations embedded from the
//! workspace's `migrations/`.
//!
//! A sample, its frame and its force/torque window are written in one transaction,
//! idempotent on `(run, index)`: they are all there or all absent, and writing a sample
//! that is already there changes nothing. Queries are built at run time (no
//! `DATABASE_URL` needed to compile).

mod sync;
mod window;

pub use sync::{LabelRow, OwnedNewRun, SyncStore, WriterStats, encode_for_store};

pub use window::{WINDOW_ENCODING, decode_window, encode_window};

use softtouch_schemas::sample::RejectReason;
use softtouch_schemas::{FrameMeta, FtReading, Medium, Sample, SampleStatus};
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
    /// No such run.
    #[error("no run {0} in this database")]
    NoSuchRun(RunId),
}

fn query_err(doing: &'static str) -> impl FnOnce(sqlx::Error) -> StoreError {
    move |source| StoreError::Query { doing, source }
}

/// Status of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RunStatus {
    /// Collecting (or killed while collecting: resume it).
    Running,
    /// All planned samples taken.
    Completed,
    /// Stopped by the operator before the end.
    Stopped,
    /// Stopped by a fault.
    Failed,
}

impl RunStatus {
    /// As stored.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Running => "running",
            Self::Completed => "completed",
            Self::Stopped => "stopped",
            Self::Failed => "failed",
        }
    }
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

/// What a new run records for provenance.
#[derive(Debug, Clone)]
pub struct NewRun<'a> {
    /// Seed of the pose sampler and the simulation.
    pub seed: u64,
    /// Samples planned.
    pub samples_planned: u64,
    /// Rod names in the order they are used.
    pub rod_schedule: &'a [String],
    /// Samples per rod block.
    pub rod_block: u64,
    /// Scene name.
    pub scene_name: &'a str,
    /// Medium.
    pub medium: Medium,
    /// Resolved rig config, as TOML.
    pub rig_toml: &'a str,
    /// Resolved scene spec, as TOML.
    pub scene_toml: &'a str,
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

/// One run with its counts, for listings.
#[derive(Debug, Clone, PartialEq, FromRow)]
pub struct RunSummary {
    /// The run.
    pub run_id: RunId,
    /// `running`, `completed`, `stopped` or `failed`.
    pub status: String,
    /// Seed.
    pub seed: i64,
    /// Scene name.
    pub scene_name: String,
    /// Medium.
    pub medium: String,
    /// Samples planned.
    pub samples_planned: i64,
    /// Accepted samples.
    pub ok: i64,
    /// Rejected samples.
    pub rejected: i64,
    /// Extra attempts over all samples (retries).
    pub retried: i64,
    /// Events logged.
    pub events: i64,
    /// Warnings and errors among them.
    pub faults: i64,
    /// When it was created (UTC).
    pub created_at: String,
    /// Last change (UTC).
    pub updated_at: String,
    /// Hours from creation to the last change.
    pub hours: f64,
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

/// Wall-clock "now" in SQL, ISO-8601 UTC with milliseconds. A macro so that queries
/// stay `&'static str` literals (sqlx refuses strings built at run time).
macro_rules! now_sql {
    () => {
        "strftime('%Y-%m-%dT%H:%M:%fZ', 'now')"
    };
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
    /// Open (creating if missing) and migrate the database at `path`.
    pub async fn open(path: &Path) -> Result<Self, StoreError> {
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

    /// Close the pool, flushing the WAL.
    pub async fn close(self) {
        self.pool.close().await;
    }

    /// Record a new run (status `running`) and return its id.
    pub async fn create_run(&self, run: &NewRun<'_>) -> Result<RunId, StoreError> {
        let sql = concat!(
            "INSERT INTO runs (status, seed, samples_planned, rod_schedule, rod_block, scene_name, medium,
                               rig_toml, scene_toml, software_version, schema_version, created_at, updated_at)
             VALUES ('running', ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ",
            now_sql!(),
            ", ",
            now_sql!(),
            ")"
        );
        // The seed is stored as its two's-complement bit pattern so every u64 fits.
        let seed = i64::from_ne_bytes(run.seed.to_ne_bytes());
        let result = sqlx::query(sql)
            .bind(seed)
            .bind(to_i64("samples_planned", run.samples_planned)?)
            .bind(run.rod_schedule.join(","))
            .bind(to_i64("rod_block", run.rod_block)?)
            .bind(run.scene_name)
            .bind(run.medium.as_str())
            .bind(run.rig_toml)
            .bind(run.scene_toml)
            .bind(softtouch_schemas::SOFTWARE_VERSION)
            .bind(Self::schema_version())
            .execute(&self.pool)
            .await
            .map_err(query_err("creating a run"))?;
        Ok(result.last_insert_rowid())
    }

    /// Change a run's status (and stamp `finished_at` unless it is `running`).
    pub async fn set_run_status(&self, run_id: RunId, status: RunStatus) -> Result<(), StoreError> {
        let sql = concat!(
            "UPDATE runs SET status = ?1, updated_at = ",
            now_sql!(),
            ", finished_at = CASE WHEN ?1 = 'running' THEN NULL ELSE ",
            now_sql!(),
            " END WHERE run_id = ?2"
        );
        let result = sqlx::query(sql)
            .bind(status.as_str())
            .bind(run_id)
            .execute(&self.pool)
            .await
            .map_err(query_err("updating a run's status"))?;
        if result.rows_affected() == 0 {
            return Err(StoreError::NoSuchRun(run_id));
        }
        Ok(())
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
        let index = to_i64("sample index", sample.index)?;
        let window_blob = encode_window(window);
        let window_count = i64::try_from(window.len()).map_err(|_| StoreError::Invalid {
            what: "window",
            why: "too many readings".into(),
        })?;
        let mut tx = self
            .pool
            .begin()
            .await
            .map_err(query_err("starting a sample transaction"))?;

        let m = sample.wrench_mean_in_sensor.to_array();
        let s = sample.wrench_std_in_sensor.to_array();
        let measured = sample.measured;
        let inserted = sqlx::query(
            "INSERT INTO samples (run_id, sample_index, rod, medium,
                 cmd_x_m, cmd_z_m, cmd_theta_rad, meas_x_m, meas_z_m, meas_theta_rad,
                 fx_n, fy_n, fz_n, tx_nm, ty_nm, tz_nm,
                 fx_std_n, fy_std_n, fz_std_n, tx_std_nm, ty_std_nm, tz_std_nm,
                 reading_count, frame_t_ns, window_start_ns, window_end_ns, sync_skew_ns,
                 status, reject_reason, attempts)
             VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)
             ON CONFLICT (run_id, sample_index) DO NOTHING",
        )
        .bind(run_id)
        .bind(index)
        .bind(&sample.rod)
        .bind(sample.medium.as_str())
        .bind(sample.commanded.x_m)
        .bind(sample.commanded.z_m)
        .bind(sample.commanded.theta_rad)
        .bind(measured.map(|p| p.x_m))
        .bind(measured.map(|p| p.z_m))
        .bind(measured.map(|p| p.theta_rad))
        .bind(m[0])
        .bind(m[1])
        .bind(m[2])
        .bind(m[3])
        .bind(m[4])
        .bind(m[5])
        .bind(s[0])
        .bind(s[1])
        .bind(s[2])
        .bind(s[3])
        .bind(s[4])
        .bind(s[5])
        .bind(i64::from(sample.reading_count))
        .bind(to_i64("frame time", sample.frame_t.0)?)
        .bind(to_i64("window start", sample.window_start.0)?)
        .bind(to_i64("window end", sample.window_end.0)?)
        .bind(sample.sync_skew_ns)
        .bind(sample.status.as_str())
        .bind(sample.status.reject_reason().map(RejectReason::as_str))
        .bind(i64::from(sample.attempts))
        .execute(&mut *tx)
        .await
        .map_err(query_err("inserting a sample"))?;
        if inserted.rows_affected() == 0 {
            tx.rollback()
                .await
                .map_err(query_err("rolling back a duplicate sample"))?;
            return Ok(Appended::AlreadyPresent);
        }

        // A sample rejected before any frame came (frame timeout, arm fault) has none.
        if let Some(frame) = frame {
            sqlx::query(
                "INSERT INTO frames (run_id, sample_index, format, width, height, sequence, t_ns, data)
                 VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            )
            .bind(run_id)
            .bind(index)
            .bind(frame.meta.format.as_str())
            .bind(i64::from(frame.meta.width))
            .bind(i64::from(frame.meta.height))
            .bind(to_i64("frame sequence", frame.meta.sequence)?)
            .bind(to_i64("frame time", frame.meta.t.0)?)
            .bind(frame.data)
            .execute(&mut *tx)
            .await
            .map_err(query_err("inserting a frame"))?;
        }

        sqlx::query(
            "INSERT INTO ft_windows (run_id, sample_index, encoding, reading_count, data) VALUES (?, ?, ?, ?, ?)",
        )
        .bind(run_id)
        .bind(index)
        .bind(WINDOW_ENCODING)
        .bind(window_count)
        .bind(window_blob.as_slice())
        .execute(&mut *tx)
        .await
        .map_err(query_err("inserting a force/torque window"))?;

        sqlx::query(concat!(
            "UPDATE runs SET updated_at = ",
            now_sql!(),
            " WHERE run_id = ?"
        ))
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
        let sql = concat!(
            "INSERT INTO events (run_id, sample_index, t_ns, created_at, level, kind, message) VALUES (?, ?, ?, ",
            now_sql!(),
            ", ?, ?, ?)"
        );
        sqlx::query(sql)
            .bind(run_id)
            .bind(
                sample_index
                    .map(|i| to_i64("sample index", i))
                    .transpose()?,
            )
            .bind(t.map(|t| to_i64("event time", t.0)).transpose()?)
            .bind(level.as_str())
            .bind(kind)
            .bind(message)
            .execute(&self.pool)
            .await
            .map_err(query_err("logging an event"))?;
        Ok(())
    }

    /// Every run with its counts, oldest first.
    pub async fn runs(&self) -> Result<Vec<RunSummary>, StoreError> {
        sqlx::query_as::<_, RunSummary>(
            "SELECT r.run_id, r.status, r.seed, r.scene_name, r.medium, r.samples_planned,
                    COALESCE(s.ok, 0) AS ok, COALESCE(s.rejected, 0) AS rejected,
                    COALESCE(s.retried, 0) AS retried,
                    COALESCE(e.events, 0) AS events, COALESCE(e.faults, 0) AS faults,
                    r.created_at, r.updated_at,
                    (julianday(r.updated_at) - julianday(r.created_at)) * 24.0 AS hours
             FROM runs r
             LEFT JOIN (SELECT run_id,
                               SUM(status = 'ok') AS ok,
                               SUM(status = 'rejected') AS rejected,
                               SUM(attempts - 1) AS retried
                        FROM samples GROUP BY run_id) s ON s.run_id = r.run_id
             LEFT JOIN (SELECT run_id, COUNT(*) AS events, SUM(level <> 'info') AS faults
                        FROM events GROUP BY run_id) e ON e.run_id = r.run_id
             ORDER BY r.run_id",
        )
        .fetch_all(&self.pool)
        .await
        .map_err(query_err("listing runs"))
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

/// What a run recorded about itself: enough to resume or replay it.
#[derive(Debug, Clone, PartialEq, FromRow)]
pub struct RunRecord {
    /// The run.
    pub run_id: RunId,
    /// Status.
    pub status: String,
    /// Seed, as the bit pattern of a u64.
    pub seed: i64,
    /// Samples planned.
    pub samples_planned: i64,
    /// Rod names, comma-separated.
    pub rod_schedule: String,
    /// Samples per rod block.
    pub rod_block: i64,
    /// Resolved rig config.
    pub rig_toml: String,
    /// Resolved scene.
    pub scene_toml: String,
}

impl RunRecord {
    /// The seed as given.
    #[must_use]
    pub fn seed_u64(&self) -> u64 {
        u64::from_ne_bytes(self.seed.to_ne_bytes())
    }
}

impl Store {
    /// The run's provenance, for resume.
    pub async fn run_record(&self, run_id: RunId) -> Result<RunRecord, StoreError> {
        sqlx::query_as::<_, RunRecord>(
            "SELECT run_id, status, seed, samples_planned, rod_schedule, rod_block, rig_toml, scene_toml
             FROM runs WHERE run_id = ?",
        )
        .bind(run_id)
        .fetch_optional(&self.pool)
        .await
        .map_err(query_err("reading a run"))?
        .ok_or(StoreError::NoSuchRun(run_id))
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

#[cfg(test)]
mod tests;
