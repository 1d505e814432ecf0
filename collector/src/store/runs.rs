//! Runs: creating one, its status, listing them, and what one recorded for resume.

use super::rows::{self, RunRow, now_sql, seed_from_sql};
use super::{RunId, Store, StoreError, query_err};
use softtouch_schemas::Medium;
use sqlx::FromRow;

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
        seed_from_sql(self.seed)
    }
}

impl Store {
    /// Record a new run (status `running`) and return its id.
    pub async fn create_run(&self, run: &NewRun<'_>) -> Result<RunId, StoreError> {
        let mut conn = self
            .pool
            .acquire()
            .await
            .map_err(query_err("creating a run"))?;
        let row = RunRow {
            status: RunStatus::Running,
            seed: run.seed,
            samples_planned: run.samples_planned,
            rod_schedule: &run.rod_schedule.join(","),
            rod_block: run.rod_block,
            scene_name: run.scene_name,
            medium: run.medium,
            rig_toml: run.rig_toml,
            scene_toml: run.scene_toml,
            software_version: softtouch_schemas::SOFTWARE_VERSION,
            schema_version: Self::schema_version(),
            created_at: None,
        };
        rows::insert_run(&mut conn, &row).await
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
