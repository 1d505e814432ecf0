//! Runs: creating one, its status, listing them, and what one recorded for resume.

use super::rows::{self, RunRow, now_sql, seed_from_sql};
use super::{RunId, Store, StoreError, query_err};
use crate::Dialect;
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
    /// The run whose poses and rods this one repeats (`collect --poses-from`).
    pub poses_from: Option<RunId>,
}

/// A run's counts as `runs`, `status` and the report show them: the columns (of `r`, `s`
/// and `e`) and the `FROM` that computes them. One definition, so that what counts as
/// ok, rejected, retried or a fault cannot drift between listings. Macros, because sqlx
/// takes `&'static str` and `concat!` takes literals.
#[macro_export]
macro_rules! run_counts_columns {
    () => {
        "r.run_id, r.status, r.seed, r.scene_name, r.medium, r.samples_planned,
         COALESCE(s.ok, 0) AS ok, COALESCE(s.rejected, 0) AS rejected,
         COALESCE(s.retried, 0) AS retried,
         COALESCE(e.events, 0) AS events, COALESCE(e.faults, 0) AS faults,
         r.created_at, r.updated_at,
         (julianday(r.updated_at) - julianday(r.created_at)) * 24.0 AS hours,
         s.first_t_ns, s.last_t_ns"
    };
}

/// See [`run_counts_columns`]; `s` also carries the first and last frame time.
#[macro_export]
macro_rules! run_counts_from {
    () => {
        " FROM runs r
         LEFT JOIN (SELECT run_id,
                           CAST(SUM(CASE WHEN status = 'ok' THEN 1 ELSE 0 END) AS BIGINT) AS ok,
                           CAST(SUM(CASE WHEN status = 'rejected' THEN 1 ELSE 0 END) AS BIGINT)
                               AS rejected,
                           CAST(SUM(attempts - 1) AS BIGINT) AS retried,
                           MIN(frame_t_ns) AS first_t_ns, MAX(frame_t_ns) AS last_t_ns
                    FROM samples GROUP BY run_id) s ON s.run_id = r.run_id
         LEFT JOIN (SELECT run_id, COUNT(*) AS events,
                           CAST(SUM(CASE WHEN level <> 'info' THEN 1 ELSE 0 END) AS BIGINT) AS faults
                    FROM events GROUP BY run_id) e ON e.run_id = r.run_id"
    };
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
    /// Run clock of the first stored frame, ns.
    pub first_t_ns: Option<i64>,
    /// Run clock of the last stored frame, ns.
    pub last_t_ns: Option<i64>,
}

impl RunSummary {
    /// Accepted samples per hour of run clock, from the first stored frame to the last:
    /// the rig's pace (on the simulated rig, virtual time). `None` before two frames.
    /// `status`, `runs` and the report show this one definition.
    #[must_use]
    pub fn ok_per_run_clock_hour(&self) -> Option<f64> {
        let span_h = (self.last_t_ns? - self.first_t_ns?) as f64 / 3.6e12;
        (span_h > 0.0).then(|| self.ok as f64 / span_h)
    }

    /// Accepted samples per hour of wall clock, from the run's creation to its last
    /// change (pauses, resumes and, on the simulated rig, how fast this computer is,
    /// included). `None` before any time has passed.
    #[must_use]
    pub fn ok_per_wall_hour(&self) -> Option<f64> {
        (self.hours > 0.0).then(|| self.ok as f64 / self.hours)
    }
}

/// What a run recorded about itself: enough to resume or replay it.
#[derive(Debug, Clone, PartialEq)]
pub struct RunRecord {
    /// The run.
    pub run_id: RunId,
    /// Status.
    pub status: String,
    /// Seed, as the bit pattern of a u64.
    pub seed: i64,
    /// Samples planned.
    pub samples_planned: i64,
    /// Rod names in the order they are used, exactly as given.
    pub rod_schedule: Vec<String>,
    /// Samples per rod block.
    pub rod_block: i64,
    /// Resolved rig config.
    pub rig_toml: String,
    /// Resolved scene.
    pub scene_toml: String,
    /// The run whose poses and rods this one repeats (`collect --poses-from`).
    pub poses_from: Option<RunId>,
}

/// One sample index of two runs, for [`Store::check_paired_poses`].
#[derive(FromRow)]
struct PairRow {
    sample_index: i64,
    rod_a: String,
    x_a: f64,
    z_a: f64,
    theta_a: f64,
    rod_b: String,
    x_b: f64,
    z_b: f64,
    theta_b: f64,
}

/// [`RunRecord`] as stored (the rod schedule still JSON text).
#[derive(FromRow)]
struct RunRecordRow {
    run_id: RunId,
    status: String,
    seed: i64,
    samples_planned: i64,
    rod_schedule: String,
    rod_block: i64,
    rig_toml: String,
    scene_toml: String,
    poses_from_run_id: Option<RunId>,
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
            rod_schedule: &rows::rod_schedule_json(run.rod_schedule),
            rod_block: run.rod_block,
            scene_name: run.scene_name,
            medium: run.medium,
            rig_toml: run.rig_toml,
            scene_toml: run.scene_toml,
            software_version: softtouch_schemas::SOFTWARE_VERSION,
            schema_version: Self::schema_version(),
            created_at: None,
            poses_from: run.poses_from,
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
        let result = sqlx::query(self.dialect.sql(sql))
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
        sqlx::query_as::<_, RunSummary>(self.dialect.sql(concat!(
            "SELECT ",
            run_counts_columns!(),
            run_counts_from!(),
            " ORDER BY r.run_id"
        )))
        .fetch_all(&self.pool)
        .await
        .map_err(query_err("listing runs"))
    }

    /// The run's provenance, for resume.
    pub async fn run_record(&self, run_id: RunId) -> Result<RunRecord, StoreError> {
        let row = sqlx::query_as::<_, RunRecordRow>(self.dialect.sql(
            "SELECT run_id, status, seed, samples_planned, rod_schedule, rod_block, rig_toml, scene_toml,
                    poses_from_run_id
             FROM runs WHERE run_id = ?"),
        )
        .bind(run_id)
        .fetch_optional(&self.pool)
        .await
        .map_err(query_err("reading a run"))?
        .ok_or(StoreError::NoSuchRun(run_id))?;
        Ok(RunRecord {
            rod_schedule: rows::rod_schedule_from_json(row.run_id, &row.rod_schedule)?,
            run_id: row.run_id,
            status: row.status,
            seed: row.seed,
            samples_planned: row.samples_planned,
            rod_block: row.rod_block,
            rig_toml: row.rig_toml,
            scene_toml: row.scene_toml,
            poses_from: row.poses_from_run_id,
        })
    }

    /// Checks that run `run_id` repeats run `source` pose by pose: every sample index
    /// stored in both has the same rod and bit-identical commanded pose. The number of
    /// such pairs.
    ///
    /// # Errors
    /// The first index whose rod or pose differs, or no common index at all.
    pub async fn check_paired_poses(
        &self,
        run_id: RunId,
        source: RunId,
    ) -> Result<u64, StoreError> {
        let rows: Vec<PairRow> = sqlx::query_as(self.dialect.sql(
            "SELECT a.sample_index, a.rod AS rod_a, a.cmd_x_m AS x_a, a.cmd_z_m AS z_a,
                    a.cmd_theta_rad AS theta_a, b.rod AS rod_b, b.cmd_x_m AS x_b,
                    b.cmd_z_m AS z_b, b.cmd_theta_rad AS theta_b
             FROM samples a JOIN samples b ON b.run_id = ?2 AND b.sample_index = a.sample_index
             WHERE a.run_id = ?1 ORDER BY a.sample_index",
        ))
        .bind(run_id)
        .bind(source)
        .fetch_all(&self.pool)
        .await
        .map_err(query_err("pairing two runs' poses"))?;
        let unpaired = |why: String| StoreError::Unpaired {
            run_id,
            from_run: source,
            why,
        };
        if rows.is_empty() {
            return Err(unpaired("no sample index is stored in both".into()));
        }
        // Bit for bit: both runs drew the pose from the same pure function.
        let bits = |x: f64, z: f64, t: f64| [x.to_bits(), z.to_bits(), t.to_bits()];
        if let Some(r) = rows.iter().find(|r| {
            r.rod_a != r.rod_b || bits(r.x_a, r.z_a, r.theta_a) != bits(r.x_b, r.z_b, r.theta_b)
        }) {
            return Err(unpaired(format!(
                "sample {}: rod `{}` at x {} m, z {} m, θ {} rad against rod `{}` at x {} m, z {} m, θ {} rad",
                r.sample_index, r.rod_a, r.x_a, r.z_a, r.theta_a, r.rod_b, r.x_b, r.z_b, r.theta_b
            )));
        }
        Ok(rows.len() as u64)
    }
}

impl Store {
    /// Replace the rig stored with run `run_id` (a resume on a rig whose devices are
    /// reached elsewhere; see `CollectPlan::resume_with_rig`).
    pub async fn set_run_rig(&self, run_id: RunId, rig_toml: &str) -> Result<(), StoreError> {
        let result = sqlx::query(self.dialect.sql(concat!(
            "UPDATE runs SET rig_toml = ?, updated_at = ",
            now_sql!(),
            " WHERE run_id = ?"
        )))
        .bind(rig_toml)
        .bind(run_id)
        .execute(&self.pool)
        .await
        .map_err(query_err("updating a run's rig"))?;
        if result.rows_affected() == 0 {
            return Err(StoreError::NoSuchRun(run_id));
        }
        Ok(())
    }
}

/// A lease whose heartbeat is older than this, held by a process on another host, is
/// stale, s. (On the same host the holder's process is looked up instead: a lease is
/// stale as soon as its process is gone, however recent its heartbeat.)
pub const LEASE_STALE_S: f64 = 600.0;

/// Who collects a run: one collection job of one process.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LeaseHolder {
    /// Unique per job: `pid-host-nanos`.
    pub token: String,
    /// The process id.
    pub pid: u32,
    /// The host name.
    pub host: String,
}

impl LeaseHolder {
    /// A new holder for a job of this process.
    #[must_use]
    pub fn this_process() -> Self {
        let pid = std::process::id();
        let host = host_name();
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        Self {
            token: format!("{pid}-{host}-{nanos}"),
            pid,
            host,
        }
    }
}

/// This machine's name (Linux: the kernel's; elsewhere `$HOSTNAME`), or `unknown-host`.
#[must_use]
pub fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|h| h.trim().to_owned())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "unknown-host".into())
}

/// Whether process `pid` of this host is alive; `None` where that cannot be told
/// (no `/proc`).
fn pid_alive(pid: i64) -> Option<bool> {
    let proc = std::path::Path::new("/proc");
    if !proc.join("self").exists() {
        return None;
    }
    Some(pid > 0 && proc.join(pid.to_string()).exists())
}

/// A run's lease as stored.
#[derive(Debug, Clone, PartialEq, FromRow)]
pub struct LeaseRow {
    /// The holder's token.
    pub holder: String,
    /// The holder's process id.
    pub pid: i64,
    /// The holder's host.
    pub host: String,
    /// When it was taken (UTC).
    pub acquired_at: String,
    /// The last heartbeat (UTC).
    pub heartbeat_at: String,
    /// Seconds since the last heartbeat.
    pub age_s: f64,
}

impl std::fmt::Display for LeaseRow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "process {} on host `{}` (lease taken {}, last heartbeat {:.0} s ago)",
            self.pid, self.host, self.acquired_at, self.age_s
        )
    }
}

impl LeaseRow {
    /// Why this lease may be taken over by `me`, or `None` while its holder lives.
    fn stale_because(&self, me: &LeaseHolder) -> Option<String> {
        if self.host == me.host
            && let Some(alive) = pid_alive(self.pid)
        {
            return (!alive).then(|| format!("process {} is no longer running", self.pid));
        }
        (self.age_s > LEASE_STALE_S).then(|| {
            format!(
                "no heartbeat for {:.0} s (stale after {LEASE_STALE_S} s)",
                self.age_s
            )
        })
    }
}

/// How a lease was taken.
#[derive(Debug, Clone, PartialEq)]
pub enum LeaseTaken {
    /// Nobody held it (or we already did).
    Free,
    /// A stale lease was taken over.
    TakenOver {
        /// The previous holder.
        previous: LeaseRow,
        /// Why it was stale.
        why: String,
    },
}

const LEASE_SELECT: &str = "SELECT holder, pid, host, acquired_at, heartbeat_at,
            (julianday('now') - julianday(heartbeat_at)) * 86400.0 AS age_s
     FROM run_leases WHERE run_id = ?";

impl Store {
    /// Take run `run_id`'s lease for `me`: refused with [`StoreError::Leased`] while
    /// another live process holds it; a stale one is taken over (see [`LEASE_STALE_S`]).
    /// One transaction that holds the lease's lock from its start, so two processes
    /// (on any hosts) cannot both win: SQLite's `BEGIN IMMEDIATE` (the database's write
    /// lock), PostgreSQL's transaction-scoped advisory lock on the run.
    pub async fn acquire_lease(
        &self,
        run_id: RunId,
        me: &LeaseHolder,
    ) -> Result<LeaseTaken, StoreError> {
        let mut tx = match self.dialect {
            Dialect::Sqlite => self.pool.begin_with("BEGIN IMMEDIATE").await,
            Dialect::Postgres => self.pool.begin().await,
        }
        .map_err(query_err("locking the run's lease"))?;
        if self.dialect == Dialect::Postgres {
            // Two keys: this lock's namespace, and the run. Released at commit or rollback,
            // or when a killed holder's connection drops.
            sqlx::query(
                "SELECT CAST(pg_advisory_xact_lock(hashtext('softtouch.run_lease'), CAST($1 AS INTEGER)) AS TEXT)",
            )
            .bind(run_id)
            .fetch_one(&mut *tx)
            .await
            .map_err(query_err("locking the run's lease"))?;
        }
        let existing = sqlx::query_as::<_, LeaseRow>(Dialect::of(&tx).sql(LEASE_SELECT))
            .bind(run_id)
            .fetch_optional(&mut *tx)
            .await
            .map_err(query_err("reading the run's lease"))?;
        let taken = match existing {
            None => LeaseTaken::Free,
            Some(l) if l.holder == me.token => LeaseTaken::Free,
            Some(l) => match l.stale_because(me) {
                Some(why) => LeaseTaken::TakenOver { previous: l, why },
                None => return Err(StoreError::Leased { run_id, holder: l }),
            },
        };
        let sql = concat!(
            "INSERT INTO run_leases (run_id, holder, pid, host, acquired_at, heartbeat_at)
             VALUES (?1, ?2, ?3, ?4, ",
            now_sql!(),
            ", ",
            now_sql!(),
            ") ON CONFLICT (run_id) DO UPDATE SET holder = excluded.holder, pid = excluded.pid,
               host = excluded.host, acquired_at = excluded.acquired_at,
               heartbeat_at = excluded.heartbeat_at"
        );
        sqlx::query(Dialect::of(&tx).sql(sql))
            .bind(run_id)
            .bind(&me.token)
            .bind(i64::from(me.pid))
            .bind(&me.host)
            .execute(&mut *tx)
            .await
            .map_err(query_err("taking the run's lease"))?;
        tx.commit()
            .await
            .map_err(query_err("committing the run's lease"))?;
        Ok(taken)
    }

    /// Renew `me`'s lease on `run_id`; [`StoreError::LeaseLost`] if another process
    /// has taken it over meanwhile.
    pub async fn heartbeat(&self, run_id: RunId, me: &LeaseHolder) -> Result<(), StoreError> {
        let sql = concat!(
            "UPDATE run_leases SET heartbeat_at = ",
            now_sql!(),
            " WHERE run_id = ? AND holder = ?"
        );
        let done = sqlx::query(self.dialect.sql(sql))
            .bind(run_id)
            .bind(&me.token)
            .execute(&self.pool)
            .await
            .map_err(query_err("renewing the run's lease"))?;
        if done.rows_affected() == 0 {
            return Err(StoreError::LeaseLost { run_id });
        }
        Ok(())
    }

    /// Give `me`'s lease on `run_id` back (nothing if it is not ours).
    pub async fn release_lease(&self, run_id: RunId, me: &LeaseHolder) -> Result<(), StoreError> {
        sqlx::query(
            self.dialect
                .sql("DELETE FROM run_leases WHERE run_id = ? AND holder = ?"),
        )
        .bind(run_id)
        .bind(&me.token)
        .execute(&self.pool)
        .await
        .map_err(query_err("releasing the run's lease"))?;
        Ok(())
    }

    /// The lease on `run_id`, if any.
    pub async fn lease(&self, run_id: RunId) -> Result<Option<LeaseRow>, StoreError> {
        sqlx::query_as::<_, LeaseRow>(self.dialect.sql(LEASE_SELECT))
            .bind(run_id)
            .fetch_optional(&self.pool)
            .await
            .map_err(query_err("reading the run's lease"))
    }

    /// The indices below `planned` with no stored sample, ascending: what a resume
    /// must take, gaps included.
    pub async fn missing_indices(
        &self,
        run_id: RunId,
        planned: u64,
    ) -> Result<Vec<u64>, StoreError> {
        let stored: Vec<i64> = sqlx::query_scalar(self.dialect.sql(
            "SELECT sample_index FROM samples WHERE run_id = ? AND sample_index < ?
             ORDER BY sample_index",
        ))
        .bind(run_id)
        .bind(super::to_i64("samples_planned", planned)?)
        .fetch_all(&self.pool)
        .await
        .map_err(query_err("finding missing samples"))?;
        let mut present = stored
            .into_iter()
            .filter_map(|i| u64::try_from(i).ok())
            .peekable();
        let mut missing = Vec::new();
        for i in 0..planned {
            if present.next_if_eq(&i).is_some() {
                continue;
            }
            missing.push(i);
        }
        Ok(missing)
    }
    /// Where a resumed run's device time continues: the run's time base (its clock
    /// when its latest stored sample was done), and never before any stored sample's
    /// window or frame (a run stored before time bases were recorded). `None`: nothing
    /// stored yet, the run starts at 0.
    pub async fn run_time_base(
        &self,
        run_id: RunId,
    ) -> Result<Option<softtouch_schemas::TimestampNs>, StoreError> {
        let row: Option<(Option<i64>, Option<i64>)> = sqlx::query_as(self.dialect.sql(
            "SELECT r.time_base_ns,
                    (SELECT MAX(CASE WHEN s.window_end_ns > s.frame_t_ns
                                     THEN s.window_end_ns ELSE s.frame_t_ns END) FROM samples s
                     WHERE s.run_id = r.run_id)
             FROM runs r WHERE r.run_id = ?",
        ))
        .bind(run_id)
        .fetch_optional(&self.pool)
        .await
        .map_err(query_err("reading the run's time base"))?;
        let (base, latest) = row.ok_or(StoreError::NoSuchRun(run_id))?;
        let Some(ns) = base.into_iter().chain(latest).max() else {
            return Ok(None);
        };
        u64::try_from(ns)
            .map(|ns| Some(softtouch_schemas::TimestampNs(ns)))
            .map_err(|_| StoreError::Invalid {
                what: "time base",
                why: format!("run {run_id}: negative device time {ns} ns in the store"),
            })
    }
}
