//! The one INSERT of each store table, and the encodings rows share.
//!
//! Collection ([`super::Store::append_sample`]) and import
//! ([`crate::dataset::import`]) write the same tables; each table's INSERT lives here
//! once so both write identical rows. Every function takes a connection: the caller
//! owns the transaction (`let mut tx = pool.begin().await?; insert_x(&mut tx, ..)`).

use super::{EventLevel, FrameRecord, RunId, RunStatus, StoreError, WINDOW_ENCODING};
use super::{encode_window, query_err, to_i64};
use crate::Dialect;
use softtouch_schemas::sample::RejectReason;
use softtouch_schemas::{FtReading, Medium, Sample, TimestampNs};
use sqlx::AnyConnection;

/// Wall-clock "now" in SQL, ISO-8601 UTC with milliseconds. A macro, not a const, so
/// queries can `concat!` it and stay `&'static str` (sqlx refuses run-time strings).
#[macro_export]
macro_rules! now_sql {
    () => {
        "strftime('%Y-%m-%dT%H:%M:%fZ', 'now')"
    };
}
pub use crate::now_sql;

/// A seed as stored: SQLite integers are signed, so a `u64` keeps its bit pattern.
#[must_use]
pub const fn seed_to_sql(seed: u64) -> i64 {
    i64::from_ne_bytes(seed.to_ne_bytes())
}

/// A stored seed back as given (inverse of [`seed_to_sql`]).
#[must_use]
pub const fn seed_from_sql(seed: i64) -> u64 {
    u64::from_ne_bytes(seed.to_ne_bytes())
}

/// A rod schedule as stored in `runs.rod_schedule`: a JSON array of the names, so that
/// any name (commas, quotes, unicode, blanks) reads back exactly.
#[must_use]
pub fn rod_schedule_json<S: AsRef<str>>(rods: &[S]) -> String {
    let names: Vec<&str> = rods.iter().map(AsRef::as_ref).collect();
    // A list of strings always serialises.
    serde_json::to_string(&names).unwrap_or_else(|_| String::from("[]"))
}

/// A stored rod schedule back as names (inverse of [`rod_schedule_json`]).
pub fn rod_schedule_from_json(run_id: RunId, stored: &str) -> Result<Vec<String>, StoreError> {
    serde_json::from_str::<Vec<String>>(stored).map_err(|e| StoreError::Damaged {
        what: "rod schedule",
        why: format!("run {run_id}: expected a JSON array of rod names, found `{stored}` ({e})"),
    })
}

/// A row of `runs`, collected or imported.
#[derive(Debug, Clone, Copy)]
pub struct RunRow<'a> {
    /// `running` leaves `finished_at` empty; any other status stamps it now.
    pub status: RunStatus,
    pub seed: u64,
    pub samples_planned: u64,
    /// Rod names, a JSON array ([`rod_schedule_json`]).
    pub rod_schedule: &'a str,
    pub rod_block: u64,
    pub scene_name: &'a str,
    pub medium: Medium,
    pub rig_toml: &'a str,
    pub scene_toml: &'a str,
    pub software_version: &'a str,
    pub schema_version: i64,
    /// `None`: now (an import keeps the original run's time).
    pub created_at: Option<&'a str>,
    /// The run whose poses and rods this one repeats (`collect --poses-from`).
    pub poses_from: Option<RunId>,
}

/// Insert a run; its new id.
pub async fn insert_run(conn: &mut AnyConnection, run: &RunRow<'_>) -> Result<RunId, StoreError> {
    let sql = concat!(
        "INSERT INTO runs (status, seed, samples_planned, rod_schedule, rod_block, scene_name,
                           medium, rig_toml, scene_toml, software_version, schema_version,
                           created_at, poses_from_run_id, updated_at, finished_at)
         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, COALESCE(?12, ",
        now_sql!(),
        "), ?13, ",
        now_sql!(),
        ", CASE WHEN ?1 = 'running' THEN NULL ELSE ",
        now_sql!(),
        " END) RETURNING run_id"
    );
    let run_id: i64 = sqlx::query_scalar(Dialect::of(conn).sql(sql))
        .bind(run.status.as_str())
        .bind(seed_to_sql(run.seed))
        .bind(to_i64("samples_planned", run.samples_planned)?)
        .bind(run.rod_schedule)
        .bind(to_i64("rod_block", run.rod_block)?)
        .bind(run.scene_name)
        .bind(run.medium.as_str())
        .bind(run.rig_toml)
        .bind(run.scene_toml)
        .bind(run.software_version)
        .bind(run.schema_version)
        .bind(run.created_at)
        .bind(run.poses_from)
        .fetch_one(&mut *conn)
        .await
        .map_err(query_err("creating a run"))?;
    Ok(run_id)
}

/// Record where an imported run came from (`provenance` is JSON text).
pub async fn insert_run_import(
    conn: &mut AnyConnection,
    run_id: RunId,
    layout: &str,
    source_path: &str,
    origin_run_id: Option<i64>,
    provenance: &str,
) -> Result<(), StoreError> {
    sqlx::query(Dialect::of(conn).sql(concat!(
        "INSERT INTO run_imports (run_id, layout, source_path, origin_run_id, provenance, imported_at)
         VALUES (?, ?, ?, ?, ?, ",
        now_sql!(),
        ")"
    )))
    .bind(run_id)
    .bind(layout)
    .bind(source_path)
    .bind(origin_run_id)
    .bind(provenance)
    .execute(&mut *conn)
    .await
    .map_err(query_err("recording an import"))?;
    Ok(())
}

/// Insert a sample; `false` (and nothing written) if `(run, index)` is already there.
pub async fn insert_sample(
    conn: &mut AnyConnection,
    run_id: RunId,
    sample: &Sample,
) -> Result<bool, StoreError> {
    let m = sample.wrench_mean_in_sensor.to_array();
    let s = sample.wrench_std_in_sensor.to_array();
    let measured = sample.measured;
    let inserted = sqlx::query(Dialect::of(conn).sql(
        "INSERT INTO samples (run_id, sample_index, rod, medium,
             cmd_x_m, cmd_z_m, cmd_theta_rad, meas_x_m, meas_z_m, meas_theta_rad,
             fx_n, fy_n, fz_n, tx_nm, ty_nm, tz_nm,
             fx_std_n, fy_std_n, fz_std_n, tx_std_nm, ty_std_nm, tz_std_nm,
             reading_count, frame_t_ns, window_start_ns, window_end_ns, sync_skew_ns,
             status, reject_reason, attempts)
         VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)
         ON CONFLICT (run_id, sample_index) DO NOTHING"),
    )
    .bind(run_id)
    .bind(to_i64("sample index", sample.index)?)
    .bind(&sample.rod)
    .bind(sample.medium.as_str())
    .bind(sample.commanded.x_m)
    .bind(sample.commanded.z_m)
    .bind(sample.commanded.theta_rad)
    .bind(crate::dialect::NullableF64(measured.map(|p| p.x_m)))
    .bind(crate::dialect::NullableF64(measured.map(|p| p.z_m)))
    .bind(crate::dialect::NullableF64(measured.map(|p| p.theta_rad)))
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
    .execute(&mut *conn)
    .await
    .map_err(query_err("inserting a sample"))?;
    Ok(inserted.rows_affected() > 0)
}

/// Insert a sample's frame (the sample must be there).
pub async fn insert_frame(
    conn: &mut AnyConnection,
    run_id: RunId,
    sample_index: u64,
    frame: FrameRecord<'_>,
) -> Result<(), StoreError> {
    sqlx::query(Dialect::of(conn).sql(
        "INSERT INTO frames (run_id, sample_index, format, width, height, sequence, t_ns, data)
         VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
    ))
    .bind(run_id)
    .bind(to_i64("sample index", sample_index)?)
    .bind(frame.meta.format.as_str())
    .bind(i64::from(frame.meta.width))
    .bind(i64::from(frame.meta.height))
    .bind(to_i64("frame sequence", frame.meta.sequence)?)
    .bind(to_i64("frame time", frame.meta.t.0)?)
    .bind(frame.data)
    .execute(&mut *conn)
    .await
    .map_err(query_err("inserting a frame"))?;
    Ok(())
}

/// Insert a sample's raw force/torque window, packed as [`WINDOW_ENCODING`].
pub async fn insert_ft_window(
    conn: &mut AnyConnection,
    run_id: RunId,
    sample_index: u64,
    window: &[FtReading],
) -> Result<(), StoreError> {
    let count = i64::try_from(window.len()).map_err(|_| StoreError::Invalid {
        what: "window",
        why: "too many readings".into(),
    })?;
    sqlx::query(Dialect::of(conn).sql(
        "INSERT INTO ft_windows (run_id, sample_index, encoding, reading_count, data) VALUES (?, ?, ?, ?, ?)"),
    )
    .bind(run_id)
    .bind(to_i64("sample index", sample_index)?)
    .bind(WINDOW_ENCODING)
    .bind(count)
    .bind(encode_window(window))
    .execute(&mut *conn)
    .await
    .map_err(query_err("inserting a force/torque window"))?;
    Ok(())
}

/// Insert an event, stamped now.
pub async fn insert_event(
    conn: &mut AnyConnection,
    run_id: RunId,
    sample_index: Option<u64>,
    t: Option<TimestampNs>,
    level: EventLevel,
    kind: &str,
    message: &str,
) -> Result<(), StoreError> {
    sqlx::query(Dialect::of(conn).sql(concat!(
        "INSERT INTO events (run_id, sample_index, t_ns, created_at, level, kind, message)
         VALUES (?, ?, ?, ",
        now_sql!(),
        ", ?, ?, ?)"
    )))
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
    .execute(&mut *conn)
    .await
    .map_err(query_err("logging an event"))?;
    Ok(())
}
