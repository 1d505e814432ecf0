//! Stiffness calibrations (`grasp_calibrations`): each closing on a reference object
//! written in one statement, and the latest one matching a setup, model and object
//! read back for the grasp verbs' gain and pre-grasp opening.

use super::rows::now_sql;
use super::{Store, StoreError, query_err};
use sqlx::Row;

/// A calibration as stored (the curve as its documented JSON; see the migration).
#[derive(Debug, Clone, PartialEq)]
pub struct GraspCalibrationRow {
    /// Its id (0 before it is stored).
    pub calibration_id: i64,
    /// When it was stored (UTC; empty before).
    pub created_at: String,
    /// `scene` or `rig`.
    pub setup_kind: String,
    /// Fingerprint of the scene (with rate and seed) or rig file.
    pub setup_hash: String,
    /// The model's name.
    pub model: String,
    /// sha256 of its artifact.
    pub model_sha256: String,
    /// The reference object.
    pub object: String,
    /// First touch, P_m counts.
    pub touch_count: u8,
    /// Λ_max, N/mm.
    pub lambda_max_n_per_mm: f64,
    /// Interquartile range of the slopes in Λ_max's window, N/mm.
    pub lambda_iqr_n_per_mm: (f64, f64),
    /// Counts from the touch to the end of the closing.
    pub counts_spanned: u8,
    /// The no-contact estimate, N.
    pub baseline_n: f64,
    /// The stroke's mm per count the slopes were computed with.
    pub mm_per_count: f64,
    /// Why the closing stopped.
    pub ended: String,
    /// `[[request, measured, F_est|null], ...]`.
    pub points_json: String,
    /// `[[centre count, Λ N/mm], ...]`.
    pub lambda_json: String,
    /// The simulator's true Λ_max over the same range (never on a rig).
    pub true_lambda_max_n_per_mm: Option<f64>,
}

macro_rules! columns {
    () => {
        "calibration_id, created_at, setup_kind, setup_hash, model, model_sha256, object, touch_count, lambda_max_n_per_mm, lambda_iqr_lo_n_per_mm, lambda_iqr_hi_n_per_mm, counts_spanned, baseline_n, mm_per_count, ended, points_json, lambda_json, true_lambda_max_n_per_mm"
    };
}

fn count(what: &'static str, v: i64) -> Result<u8, StoreError> {
    u8::try_from(v).map_err(|_| StoreError::Damaged {
        what,
        why: format!("{v}: expected a count in 0..=255"),
    })
}

fn from_row(r: &sqlx::any::AnyRow) -> Result<GraspCalibrationRow, StoreError> {
    Ok(GraspCalibrationRow {
        calibration_id: r.get(0),
        created_at: r.get(1),
        setup_kind: r.get(2),
        setup_hash: r.get(3),
        model: r.get(4),
        model_sha256: r.get(5),
        object: r.get(6),
        touch_count: count("grasp_calibrations.touch_count", r.get(7))?,
        lambda_max_n_per_mm: r.get(8),
        lambda_iqr_n_per_mm: (r.get(9), r.get(10)),
        counts_spanned: count("grasp_calibrations.counts_spanned", r.get(11))?,
        baseline_n: r.get(12),
        mm_per_count: r.get(13),
        ended: r.get(14),
        points_json: r.get(15),
        lambda_json: r.get(16),
        true_lambda_max_n_per_mm: r.get(17),
    })
}

impl Store {
    /// Stores a calibration; returns its id. Non-finite figures are refused (they
    /// would read back as NULL or fail the NOT NULL columns half-way).
    ///
    /// # Errors
    /// A non-finite Λ, spread, baseline or scale, or the database refused the write.
    pub async fn insert_grasp_calibration(
        &self,
        row: &GraspCalibrationRow,
    ) -> Result<i64, StoreError> {
        for (what, v) in [
            ("a grasp calibration's Λ_max", row.lambda_max_n_per_mm),
            ("a grasp calibration's spread", row.lambda_iqr_n_per_mm.0),
            ("a grasp calibration's spread", row.lambda_iqr_n_per_mm.1),
            ("a grasp calibration's baseline", row.baseline_n),
            ("a grasp calibration's mm per count", row.mm_per_count),
        ] {
            if !v.is_finite() {
                return Err(StoreError::Invalid {
                    what,
                    why: format!("{v}: expected a finite number"),
                });
            }
        }
        let r = sqlx::query(self.dialect.sql(concat!(
            "INSERT INTO grasp_calibrations (created_at, setup_kind, setup_hash, model, model_sha256, object, touch_count, lambda_max_n_per_mm, lambda_iqr_lo_n_per_mm, lambda_iqr_hi_n_per_mm, counts_spanned, baseline_n, mm_per_count, ended, points_json, lambda_json, true_lambda_max_n_per_mm, software_version) VALUES (",
            now_sql!(),
            ", ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) RETURNING calibration_id"
        )))
        .bind(&row.setup_kind)
        .bind(&row.setup_hash)
        .bind(&row.model)
        .bind(&row.model_sha256)
        .bind(&row.object)
        .bind(i64::from(row.touch_count))
        .bind(row.lambda_max_n_per_mm)
        .bind(row.lambda_iqr_n_per_mm.0)
        .bind(row.lambda_iqr_n_per_mm.1)
        .bind(i64::from(row.counts_spanned))
        .bind(row.baseline_n)
        .bind(row.mm_per_count)
        .bind(&row.ended)
        .bind(&row.points_json)
        .bind(&row.lambda_json)
        .bind(crate::dialect::NullableF64(row.true_lambda_max_n_per_mm.filter(|v| v.is_finite())))
        .bind(softtouch_schemas::SOFTWARE_VERSION)
        .fetch_one(self.pool())
        .await
        .map_err(query_err("storing a grasp calibration"))?;
        Ok(r.get(0))
    }

    /// The latest calibration of `object` with the model of artifact `model_sha256` on
    /// the setup `setup_hash`, if any.
    ///
    /// # Errors
    /// The query failed, or the row does not read back.
    pub async fn latest_grasp_calibration(
        &self,
        setup_hash: &str,
        model_sha256: &str,
        object: &str,
    ) -> Result<Option<GraspCalibrationRow>, StoreError> {
        let row = sqlx::query(self.dialect.sql(concat!(
            "SELECT ",
            columns!(),
            " FROM grasp_calibrations WHERE setup_hash = ? AND model_sha256 = ? AND object = ? ORDER BY calibration_id DESC LIMIT 1"
        )))
            .bind(setup_hash)
            .bind(model_sha256)
            .bind(object)
            .fetch_optional(self.pool())
            .await
            .map_err(query_err("reading a grasp calibration"))?;
        row.as_ref().map(from_row).transpose()
    }

    /// Every calibration, newest first.
    ///
    /// # Errors
    /// The query failed, or a row does not read back.
    pub async fn grasp_calibrations(&self) -> Result<Vec<GraspCalibrationRow>, StoreError> {
        let rows = sqlx::query(self.dialect.sql(concat!(
            "SELECT ",
            columns!(),
            " FROM grasp_calibrations ORDER BY calibration_id DESC"
        )))
        .fetch_all(self.pool())
        .await
        .map_err(query_err("listing grasp calibrations"))?;
        rows.iter().map(from_row).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(object: &str, lambda: f64) -> GraspCalibrationRow {
        GraspCalibrationRow {
            calibration_id: 0,
            created_at: String::new(),
            setup_kind: "scene".into(),
            setup_hash: "abc".into(),
            model: "m".into(),
            model_sha256: "sha".into(),
            object: object.into(),
            touch_count: 120,
            lambda_max_n_per_mm: lambda,
            lambda_iqr_n_per_mm: (lambda * 0.9, lambda * 1.1),
            counts_spanned: 12,
            baseline_n: 0.01,
            mm_per_count: 0.196,
            ended: "reached_top".into(),
            points_json: "[[100,100,0.01]]".into(),
            lambda_json: "[[121,2.5]]".into(),
            true_lambda_max_n_per_mm: Some(2.4),
        }
    }

    #[tokio::test]
    async fn the_latest_matching_calibration_reads_back_and_others_do_not_match() {
        let dir = tempfile::tempdir().expect("tmp");
        let store = Store::open(crate::testing::fresh_target(dir.path(), "c.db").await)
            .await
            .expect("open");
        assert!(
            store
                .latest_grasp_calibration("abc", "sha", "ball")
                .await
                .expect("q")
                .is_none()
        );
        let first = store
            .insert_grasp_calibration(&row("ball", 2.0))
            .await
            .expect("insert");
        let second = store
            .insert_grasp_calibration(&row("ball", 3.0))
            .await
            .expect("insert");
        store
            .insert_grasp_calibration(&row("cake", 9.0))
            .await
            .expect("insert");
        assert!(second > first);
        let got = store
            .latest_grasp_calibration("abc", "sha", "ball")
            .await
            .expect("q")
            .expect("found");
        assert_eq!(got.calibration_id, second);
        assert_eq!(
            GraspCalibrationRow {
                calibration_id: 0,
                created_at: String::new(),
                ..got.clone()
            },
            row("ball", 3.0)
        );
        assert!(!got.created_at.is_empty());
        // Another model's artifact, another setup: no match.
        assert!(
            store
                .latest_grasp_calibration("abc", "other", "ball")
                .await
                .expect("q")
                .is_none()
        );
        assert!(
            store
                .latest_grasp_calibration("xyz", "sha", "ball")
                .await
                .expect("q")
                .is_none()
        );
        assert_eq!(store.grasp_calibrations().await.expect("all").len(), 3);
        // A NaN Λ is refused before anything is written.
        let e = store
            .insert_grasp_calibration(&row("ball", f64::NAN))
            .await
            .expect_err("nan");
        assert!(e.to_string().contains("Λ_max"), "{e}");
        assert_eq!(store.grasp_calibrations().await.expect("all").len(), 3);
        store.close().await;
    }
}
