//! Grasp trial sessions (`softtouch grasp trials`): a session row holds the plan
//! (model, scenes, seed, settings as JSON); each trial is written with its packed
//! trace in one transaction, idempotent on its key, so a resume runs exactly the
//! missing trials and a kill -9 loses at most the one in flight.

use super::rows::{now_sql, seed_from_sql, seed_to_sql};
use super::{Appended, Store, StoreError, query_err};
use crate::Dialect;
use sqlx::Row;
use std::collections::HashSet;

/// Encoding of a trace's arrays: little-endian f32 (NaN: none), bytes for counts.
pub const TRACE_ENCODING: &str = "f32le-v1";

/// A trial's place in its session's plan.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct GraspTrialKey {
    /// Index into the session's σ list.
    pub sigma_index: u32,
    /// Index into the session's scenes (one per medium).
    pub scene_index: u32,
    /// Object name.
    pub object: String,
    /// `open` or `closed`.
    pub mode: String,
    /// 0-based trial number of this object.
    pub trial: u32,
}

/// A session as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct GraspSessionRow {
    /// Its id.
    pub session_id: i64,
    /// When it was created (UTC).
    pub created_at: String,
    /// The model's name.
    pub model: String,
    /// sha256 of the model's artifact as run (`None`: a session from before it was
    /// recorded).
    pub model_sha256: Option<String>,
    /// The seed.
    pub seed: u64,
    /// JSON array of the scenes.
    pub scenes_json: String,
    /// JSON of the settings.
    pub config_json: String,
}

/// One trial as stored.
#[derive(Debug, Clone, PartialEq)]
pub struct GraspTrialRow {
    /// Where it sits in the plan.
    pub key: GraspTrialKey,
    /// `air` or `water`.
    pub medium: String,
    /// σ, m.
    pub sigma_m: f64,
    /// The grasp point's offset, m (gripper frame).
    pub offset_m: [f64; 3],
    /// The width the fingers were commanded to at the end, m.
    pub commanded_width_m: f64,
    /// The width measured at the end, m.
    pub final_width_m: f64,
    /// Largest estimated grip force, N.
    pub peak_estimate_n: Option<f64>,
    /// Largest true grip force, N (simulation).
    pub peak_true_n: Option<f64>,
    /// How far past the calibrated first touch the fingers closed at most, mm (the
    /// grip a rig can show without a true force; `None`: stored before it was kept).
    pub past_touch_mm: Option<f64>,
    /// Held after the lift and the hold.
    pub success: bool,
    /// Why not (`slip`, `crush`, `miss`, `timeout`, `device_fault`).
    pub reason: Option<String>,
    /// A device's message, if any.
    pub detail: Option<String>,
    /// When the closed loop confirmed its force, s after the trial's start.
    pub confirmed_after_s: Option<f64>,
    /// Wall-clock time the trial took, s.
    pub wall_s: f64,
}

/// A trial's cycles, as arrays.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GraspTrace {
    /// Time since the trial's first cycle, s.
    pub t_s: Vec<f32>,
    /// F_est, N (NaN: none).
    pub estimate_n: Vec<f32>,
    /// F_true, N (NaN: none).
    pub true_n: Vec<f32>,
    /// P_m, counts.
    pub measured_count: Vec<u8>,
    /// P_ref, counts.
    pub request_count: Vec<u8>,
    /// The finger's frames at the trial's moments, in the order they happened.
    pub frames: Vec<TraceFrame>,
}

/// A frame of a trial's moment, as stored with its trace.
#[derive(Debug, Clone, PartialEq)]
pub struct TraceFrame {
    /// `contact`, `confirmed`, `lifted` or `end`.
    pub moment: String,
    /// Exposure, s after the trial's start.
    pub t_s: f64,
    /// A PNG thumbnail.
    pub png: Vec<u8>,
}

fn pack(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Unpacks a little-endian f32 blob.
///
/// # Errors
/// A length that is not a multiple of 4.
pub fn unpack_f32(what: &'static str, bytes: &[u8]) -> Result<Vec<f32>, StoreError> {
    if !bytes.len().is_multiple_of(4) {
        return Err(StoreError::Damaged {
            what,
            why: format!("{} bytes: expected a multiple of 4 (f32 LE)", bytes.len()),
        });
    }
    Ok(bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect())
}

fn int(what: &'static str, v: i64) -> Result<u32, StoreError> {
    u32::try_from(v).map_err(|_| StoreError::Damaged {
        what,
        why: format!("{v}: expected a non-negative index"),
    })
}

/// The columns [`session_row`] reads, in its order.
macro_rules! session_columns {
    () => {
        "session_id, created_at, model, seed, scenes_json, config_json, model_sha256"
    };
}

/// A session row as [`session_columns`] selects it.
fn session_row(r: &sqlx::any::AnyRow) -> GraspSessionRow {
    GraspSessionRow {
        session_id: r.get(0),
        created_at: r.get(1),
        model: r.get(2),
        seed: seed_from_sql(r.get(3)),
        scenes_json: r.get(4),
        config_json: r.get(5),
        model_sha256: r.get(6),
    }
}

impl Store {
    /// Creates a grasp session; returns its id.
    ///
    /// # Errors
    /// The database refused the write.
    pub async fn create_grasp_session(
        &self,
        model: &str,
        model_sha256: &str,
        seed: u64,
        scenes_json: &str,
        config_json: &str,
    ) -> Result<i64, StoreError> {
        let row = sqlx::query(self.dialect.sql(concat!(
            "INSERT INTO grasp_sessions (created_at, model, model_sha256, seed, scenes_json, config_json, software_version) VALUES (",
            now_sql!(),
            ", ?, ?, ?, ?, ?, ?) RETURNING session_id"
        )))
        .bind(model)
        .bind(model_sha256)
        .bind(seed_to_sql(seed))
        .bind(scenes_json)
        .bind(config_json)
        .bind(softtouch_schemas::SOFTWARE_VERSION)
        .fetch_one(self.pool())
        .await
        .map_err(query_err("creating a grasp session"))?;
        Ok(row.get(0))
    }

    /// A session, if it exists.
    ///
    /// # Errors
    /// The query failed.
    pub async fn grasp_session(
        &self,
        session_id: i64,
    ) -> Result<Option<GraspSessionRow>, StoreError> {
        let row = sqlx::query(self.dialect.sql(concat!(
            "SELECT ",
            session_columns!(),
            " FROM grasp_sessions WHERE session_id = ?"
        )))
        .bind(session_id)
        .fetch_optional(self.pool())
        .await
        .map_err(query_err("reading a grasp session"))?;
        Ok(row.as_ref().map(session_row))
    }

    /// The keys of a session's stored trials.
    ///
    /// # Errors
    /// The query failed, or a stored index is negative.
    pub async fn grasp_trial_keys(
        &self,
        session_id: i64,
    ) -> Result<HashSet<GraspTrialKey>, StoreError> {
        let rows = sqlx::query(self.dialect.sql(
            "SELECT sigma_index, scene_index, object, mode, trial FROM grasp_trials WHERE session_id = ?"),
        )
        .bind(session_id)
        .fetch_all(self.pool())
        .await
        .map_err(query_err("reading grasp trial keys"))?;
        rows.iter()
            .map(|r| {
                Ok(GraspTrialKey {
                    sigma_index: int("grasp_trials.sigma_index", r.get(0))?,
                    scene_index: int("grasp_trials.scene_index", r.get(1))?,
                    object: r.get(2),
                    mode: r.get(3),
                    trial: int("grasp_trials.trial", r.get(4))?,
                })
            })
            .collect()
    }

    /// Writes a trial and its trace in one transaction. A trial already stored under
    /// the same key is left as it is.
    ///
    /// # Errors
    /// Mismatched trace arrays, or the database refused the write.
    pub async fn append_grasp_trial(
        &self,
        session_id: i64,
        trial: &GraspTrialRow,
        trace: &GraspTrace,
    ) -> Result<Appended, StoreError> {
        let n = trace.t_s.len();
        if [
            trace.estimate_n.len(),
            trace.true_n.len(),
            trace.measured_count.len(),
            trace.request_count.len(),
        ]
        .iter()
        .any(|l| *l != n)
        {
            return Err(StoreError::Invalid {
                what: "grasp trace",
                why: format!("arrays of different lengths (t_s has {n})"),
            });
        }
        let mut tx = self
            .pool()
            .begin()
            .await
            .map_err(query_err("starting a grasp trial transaction"))?;
        let k = &trial.key;
        let inserted = sqlx::query(Dialect::of(&tx).sql(concat!(
            "INSERT INTO grasp_trials (session_id, sigma_index, scene_index, object, mode, trial, medium, sigma_m, dx_m, dy_m, dz_m, ",
            "commanded_width_m, final_width_m, peak_estimate_n, peak_true_n, past_touch_mm, success, reason, detail, confirmed_after_s, wall_s, created_at) ",
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ",
            now_sql!(),
            ") ON CONFLICT (session_id, sigma_index, scene_index, object, mode, trial) DO NOTHING RETURNING trial_id"
        )))
        .bind(session_id)
        .bind(i64::from(k.sigma_index))
        .bind(i64::from(k.scene_index))
        .bind(&k.object)
        .bind(&k.mode)
        .bind(i64::from(k.trial))
        .bind(&trial.medium)
        .bind(trial.sigma_m)
        .bind(trial.offset_m[0])
        .bind(trial.offset_m[1])
        .bind(trial.offset_m[2])
        .bind(trial.commanded_width_m)
        .bind(trial.final_width_m)
        .bind(crate::dialect::NullableF64(trial.peak_estimate_n))
        .bind(crate::dialect::NullableF64(trial.peak_true_n))
        .bind(crate::dialect::NullableF64(trial.past_touch_mm))
        .bind(i64::from(trial.success))
        .bind(trial.reason.as_deref())
        .bind(trial.detail.as_deref())
        .bind(crate::dialect::NullableF64(trial.confirmed_after_s))
        .bind(trial.wall_s)
        .fetch_optional(&mut *tx)
        .await
        .map_err(query_err("writing a grasp trial"))?;
        let Some(row) = inserted else {
            return Ok(Appended::AlreadyPresent);
        };
        let trial_id: i64 = row.get(0);
        sqlx::query(Dialect::of(&tx).sql(
            "INSERT INTO grasp_traces (trial_id, cycles, encoding, t_s, estimate_n, true_n, measured_count, request_count) VALUES (?, ?, ?, ?, ?, ?, ?, ?)"),
        )
        .bind(trial_id)
        .bind(n as i64)
        .bind(TRACE_ENCODING)
        .bind(pack(&trace.t_s))
        .bind(pack(&trace.estimate_n))
        .bind(pack(&trace.true_n))
        .bind(&trace.measured_count)
        .bind(&trace.request_count)
        .execute(&mut *tx)
        .await
        .map_err(query_err("writing a grasp trace"))?;
        for f in &trace.frames {
            sqlx::query(Dialect::of(&tx).sql(
                "INSERT INTO grasp_trial_frames (trial_id, moment, t_s, png) VALUES (?, ?, ?, ?)",
            ))
            .bind(trial_id)
            .bind(&f.moment)
            .bind(if f.t_s.is_finite() { f.t_s } else { 0.0 })
            .bind(&f.png)
            .execute(&mut *tx)
            .await
            .map_err(query_err("writing a grasp trial's frame"))?;
        }
        tx.commit()
            .await
            .map_err(query_err("committing a grasp trial"))?;
        Ok(Appended::Inserted)
    }

    /// A session's trials, in plan order.
    ///
    /// # Errors
    /// The query failed or a row does not read back.
    pub async fn grasp_trials(&self, session_id: i64) -> Result<Vec<GraspTrialRow>, StoreError> {
        trials_of(self.pool(), self.dialect, session_id).await
    }

    /// The trace of a session's trial, if stored.
    ///
    /// # Errors
    /// The query failed or the blobs do not read back.
    pub async fn grasp_trace(
        &self,
        session_id: i64,
        key: &GraspTrialKey,
    ) -> Result<Option<GraspTrace>, StoreError> {
        trace_of(self.pool(), self.dialect, session_id, key).await
    }

    /// Every grasp session, oldest first.
    ///
    /// # Errors
    /// The query failed.
    pub async fn grasp_sessions(&self) -> Result<Vec<GraspSessionRow>, StoreError> {
        sessions_of(self.pool(), self.dialect).await
    }

    /// The ids of a session's first and last stored trials (`None`: none stored), for
    /// `softtouch results trace TRIAL_ID`.
    ///
    /// # Errors
    /// The query failed.
    pub async fn grasp_trial_id_range(
        &self,
        session_id: i64,
    ) -> Result<Option<(i64, i64)>, StoreError> {
        let r = sqlx::query(
            self.dialect
                .sql("SELECT MIN(trial_id), MAX(trial_id) FROM grasp_trials WHERE session_id = ?"),
        )
        .bind(session_id)
        .fetch_one(self.pool())
        .await
        .map_err(query_err("reading a session's trial ids"))?;
        Ok(r.get::<Option<i64>, _>(0).zip(r.get::<Option<i64>, _>(1)))
    }

    /// A trial by its id: its session, its row and its trace (if stored).
    ///
    /// # Errors
    /// The query failed or the row does not read back.
    pub async fn grasp_trial_by_id(
        &self,
        trial_id: i64,
    ) -> Result<Option<(i64, GraspTrialRow, Option<GraspTrace>)>, StoreError> {
        let session: Option<i64> = sqlx::query_scalar(
            self.dialect
                .sql("SELECT session_id FROM grasp_trials WHERE trial_id = ?"),
        )
        .bind(trial_id)
        .fetch_optional(self.pool())
        .await
        .map_err(query_err("finding a grasp trial"))?;
        let Some(session_id) = session else {
            return Ok(None);
        };
        let ids: Vec<i64> = sqlx::query_scalar(
            self.dialect
                .sql("SELECT trial_id FROM grasp_trials WHERE session_id = ? ORDER BY trial_id"),
        )
        .bind(session_id)
        .fetch_all(self.pool())
        .await
        .map_err(query_err("finding a grasp trial"))?;
        let trials = trials_of(self.pool(), self.dialect, session_id).await?;
        let Some(row) = ids
            .iter()
            .position(|id| *id == trial_id)
            .and_then(|i| trials.get(i).cloned())
        else {
            return Ok(None);
        };
        let trace = trace_of(self.pool(), self.dialect, session_id, &row.key).await?;
        Ok(Some((session_id, row, trace)))
    }
}

/// A session's trials in the order they were stored (the store's and the report's
/// reader).
pub(crate) async fn trials_of(
    pool: &sqlx::AnyPool,
    d: Dialect,
    session_id: i64,
) -> Result<Vec<GraspTrialRow>, StoreError> {
    let rows = sqlx::query(d.sql(
        "SELECT sigma_index, scene_index, object, mode, trial, medium, sigma_m, dx_m, dy_m, dz_m, commanded_width_m, final_width_m, \
         peak_estimate_n, peak_true_n, success, reason, detail, confirmed_after_s, wall_s, past_touch_mm \
         FROM grasp_trials WHERE session_id = ? ORDER BY trial_id"),
    )
    .bind(session_id)
    .fetch_all(pool)
    .await
    .map_err(query_err("reading grasp trials"))?;
    rows.iter()
        .map(|r| {
            Ok(GraspTrialRow {
                key: GraspTrialKey {
                    sigma_index: int("grasp_trials.sigma_index", r.get(0))?,
                    scene_index: int("grasp_trials.scene_index", r.get(1))?,
                    object: r.get(2),
                    mode: r.get(3),
                    trial: int("grasp_trials.trial", r.get(4))?,
                },
                medium: r.get(5),
                sigma_m: r.get(6),
                offset_m: [r.get(7), r.get(8), r.get(9)],
                commanded_width_m: r.get(10),
                final_width_m: r.get(11),
                peak_estimate_n: r.get(12),
                peak_true_n: r.get(13),
                success: r.get::<i64, _>(14) == 1,
                reason: r.get(15),
                detail: r.get(16),
                confirmed_after_s: r.get(17),
                wall_s: r.get(18),
                past_touch_mm: r.get(19),
            })
        })
        .collect()
}

/// A session's trial's trace, if stored (the store's and the report's reader).
pub(crate) async fn trace_of(
    pool: &sqlx::AnyPool,
    d: Dialect,
    session_id: i64,
    key: &GraspTrialKey,
) -> Result<Option<GraspTrace>, StoreError> {
    let row = sqlx::query(d.sql(
        "SELECT c.encoding, c.t_s, c.estimate_n, c.true_n, c.measured_count, c.request_count, c.trial_id \
         FROM grasp_traces c JOIN grasp_trials t ON t.trial_id = c.trial_id \
         WHERE t.session_id = ? AND t.sigma_index = ? AND t.scene_index = ? AND t.object = ? AND t.mode = ? AND t.trial = ?"),
    )
    .bind(session_id)
    .bind(i64::from(key.sigma_index))
    .bind(i64::from(key.scene_index))
    .bind(&key.object)
    .bind(&key.mode)
    .bind(i64::from(key.trial))
    .fetch_optional(pool)
    .await
    .map_err(query_err("reading a grasp trace"))?;
    let Some(r) = row else { return Ok(None) };
    let encoding: String = r.get(0);
    if encoding != TRACE_ENCODING {
        return Err(StoreError::Damaged {
            what: "grasp_traces.encoding",
            why: format!("`{encoding}`: expected `{TRACE_ENCODING}`"),
        });
    }
    let frames = sqlx::query(d.sql(
        "SELECT moment, t_s, png FROM grasp_trial_frames WHERE trial_id = ? ORDER BY t_s, moment",
    ))
    .bind(r.get::<i64, _>(6))
    .fetch_all(pool)
    .await
    .map_err(query_err("reading a grasp trial's frames"))?
    .iter()
    .map(|f| TraceFrame {
        moment: f.get(0),
        t_s: f.get(1),
        png: f.get(2),
    })
    .collect();
    Ok(Some(GraspTrace {
        t_s: unpack_f32("grasp_traces.t_s", &r.get::<Vec<u8>, _>(1))?,
        estimate_n: unpack_f32("grasp_traces.estimate_n", &r.get::<Vec<u8>, _>(2))?,
        true_n: unpack_f32("grasp_traces.true_n", &r.get::<Vec<u8>, _>(3))?,
        measured_count: r.get(4),
        request_count: r.get(5),
        frames,
    }))
}

/// Every grasp session, oldest first (the report's reader).
pub(crate) async fn sessions_of(
    pool: &sqlx::AnyPool,
    d: Dialect,
) -> Result<Vec<GraspSessionRow>, StoreError> {
    let rows = sqlx::query(d.sql(concat!(
        "SELECT ",
        session_columns!(),
        " FROM grasp_sessions ORDER BY session_id"
    )))
    .fetch_all(pool)
    .await
    .map_err(query_err("reading grasp sessions"))?;
    Ok(rows.iter().map(session_row).collect())
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact stored and published values
mod tests {
    use super::*;

    fn row(trial: u32, success: bool) -> GraspTrialRow {
        GraspTrialRow {
            key: GraspTrialKey {
                sigma_index: 0,
                scene_index: 1,
                object: "cake".into(),
                mode: "closed".into(),
                trial,
            },
            medium: "water".into(),
            sigma_m: 0.005,
            offset_m: [0.001, -0.002, 0.003],
            commanded_width_m: 0.028,
            final_width_m: 0.0285,
            peak_estimate_n: Some(1.5),
            peak_true_n: None,
            past_touch_mm: Some(1.2),
            success,
            reason: (!success).then(|| "slip".to_owned()),
            detail: None,
            confirmed_after_s: Some(0.8),
            wall_s: 0.4,
        }
    }

    #[tokio::test]
    async fn a_trial_and_its_trace_store_once_and_read_back() {
        let dir = tempfile::tempdir().expect("temp dir");
        let store = Store::open(crate::testing::fresh_target(dir.path(), "g.db").await)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        let id = store
            .create_grasp_session("m", "ab12", u64::MAX, "[]", "{}")
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        let s = store.grasp_session(id).await.ok().flatten();
        assert_eq!(
            s.map(|s| (s.model, s.model_sha256, s.seed)),
            Some(("m".to_owned(), Some("ab12".to_owned()), u64::MAX))
        );
        let trace = GraspTrace {
            t_s: vec![0.0, 0.0083],
            estimate_n: vec![f32::NAN, 1.25],
            true_n: vec![0.5, 1.0],
            measured_count: vec![100, 101],
            request_count: vec![101, 102],
            frames: vec![
                TraceFrame {
                    moment: "contact".into(),
                    t_s: 0.0,
                    png: b"\x89PNG\r\n\x1a\n-contact".to_vec(),
                },
                TraceFrame {
                    moment: "end".into(),
                    t_s: 0.0083,
                    png: b"\x89PNG\r\n\x1a\n-end".to_vec(),
                },
            ],
        };
        for _ in 0..2 {
            store
                .append_grasp_trial(id, &row(0, true), &trace)
                .await
                .unwrap_or_else(|e| panic!("{e}"));
        }
        let again = store
            .append_grasp_trial(id, &row(0, false), &trace)
            .await
            .ok();
        assert_eq!(again, Some(Appended::AlreadyPresent));
        store
            .append_grasp_trial(id, &row(1, false), &trace)
            .await
            .unwrap_or_else(|e| panic!("{e}"));
        let rows = store.grasp_trials(id).await.unwrap_or_default();
        assert_eq!(rows, vec![row(0, true), row(1, false)]);
        assert_eq!(
            store.grasp_trial_keys(id).await.map(|k| k.len()).ok(),
            Some(2)
        );
        let back = store
            .grasp_trace(id, &row(0, true).key)
            .await
            .ok()
            .flatten()
            .unwrap_or_default();
        assert!(back.estimate_n[0].is_nan());
        assert_eq!(back.estimate_n[1], 1.25);
        assert_eq!(back.measured_count, trace.measured_count);
        // The frames come back in the order they happened, with the trace.
        assert_eq!(back.frames, trace.frames);
        // A moment the table does not know is refused, and the trial with it.
        let mut odd = trace.clone();
        odd.frames[0].moment = "lunch".into();
        assert!(
            store
                .append_grasp_trial(id, &row(4, true), &odd)
                .await
                .is_err()
        );
        assert!(
            store
                .grasp_trace(id, &row(4, true).key)
                .await
                .ok()
                .flatten()
                .is_none()
        );
        assert_eq!(store.grasp_trials(id).await.map(|r| r.len()).ok(), Some(2));
        // Mismatched arrays are refused before anything is written.
        let bad = GraspTrace {
            t_s: vec![0.0],
            ..GraspTrace::default()
        };
        assert!(
            store
                .append_grasp_trial(id, &row(2, true), &bad)
                .await
                .is_err()
        );
        assert!(unpack_f32("x", &[0, 0, 0]).is_err());
        // Success and reason must agree.
        let mut wrong = row(3, true);
        wrong.reason = Some("slip".into());
        assert!(store.append_grasp_trial(id, &wrong, &trace).await.is_err());
    }
}
