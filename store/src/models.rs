//! The `models` table (its one writer) and the reads of dataset members with their
//! frames that training and evaluation stream.

use crate::{MemberRow, Store, StoreError, now_sql, query_err};
use futures_util::TryStreamExt as _;
use futures_util::stream::BoxStream;
use sqlx::FromRow;

/// A stored model, without its artifact.
#[derive(Debug, Clone, FromRow)]
pub struct ModelInfo {
    /// Row id.
    pub model_id: i64,
    /// Name.
    pub name: String,
    /// The dataset it was trained on.
    pub dataset_name: String,
    /// svae, vae or convnet.
    pub kind: String,
    /// Model config (JSON).
    pub config_json: String,
    /// Training settings (JSON).
    pub train_json: String,
    /// Mean test R² (absent for the VAE).
    pub test_r2_mean: Option<f64>,
    /// Test image MSE (absent for the ConvNet).
    pub test_image_mse: Option<f64>,
    /// When (UTC).
    pub created_at: String,
}

/// A trained model to record.
#[derive(Debug, Clone)]
pub struct NewModel<'a> {
    /// Its name (unique).
    pub name: &'a str,
    /// The dataset it was trained on.
    pub dataset_id: i64,
    /// That dataset's name.
    pub dataset_name: &'a str,
    /// svae, vae or convnet.
    pub kind: &'a str,
    /// Model config (JSON).
    pub config_json: &'a str,
    /// Training settings (JSON).
    pub train_json: &'a str,
    /// Metrics (JSON).
    pub metrics_json: &'a str,
    /// Per-epoch history (JSON).
    pub history_json: &'a str,
    /// Mean test R².
    pub test_r2_mean: Option<f64>,
    /// Test image MSE.
    pub test_image_mse: Option<f64>,
    /// The artifact's bytes.
    pub artifact: &'a [u8],
    /// The software that trained it.
    pub software_version: &'a str,
}

/// A dataset's members with their labels and frames; the caller adds the order. A
/// macro, because sqlx takes `&'static str` and `concat!` takes literals.
macro_rules! member_rows_sql {
    () => {
        "SELECT m.split, m.run_id, m.sample_index,
                s.fx_n, s.fy_n, s.fz_n, s.tx_nm, s.ty_nm, s.tz_nm,
                f.format, f.width, f.height, f.data
         FROM dataset_members m
         JOIN samples s ON s.run_id = m.run_id AND s.sample_index = m.sample_index
         JOIN frames f ON f.run_id = m.run_id AND f.sample_index = m.sample_index
         WHERE m.dataset_id = ?"
    };
}

macro_rules! info_select {
    ($rest:literal) => {
        concat!(
            "SELECT model_id, name, dataset_name, kind, config_json, train_json, \
             test_r2_mean, test_image_mse, created_at FROM models ",
            $rest
        )
    };
}

/// Which of a dataset's members to stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Members {
    /// Every member.
    All,
    /// The test split.
    Test,
    /// Every member outside the test split.
    NotTest,
}

/// A water test sample whose run repeats the poses of a land run, and that run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, FromRow)]
pub struct PairKey {
    /// The water sample's run.
    pub water_run: i64,
    /// Its index (the same pose's index in the land run).
    pub sample_index: i64,
    /// The land run whose poses it repeats.
    pub land_run: i64,
}

impl Store {
    /// Records a trained model; its id.
    ///
    /// # Errors
    /// A query failure (a taken name among them: callers check first).
    pub async fn insert_model(&self, m: &NewModel<'_>) -> Result<i64, StoreError> {
        let model_id: i64 = sqlx::query_scalar(self.dialect.sql(concat!(
            "INSERT INTO models (name, dataset_id, dataset_name, kind, config_json, train_json,
                                 metrics_json, history_json, test_r2_mean, test_image_mse, artifact,
                                 software_version, created_at)
             VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ",
            now_sql!(),
            ") RETURNING model_id"
        )))
        .bind(m.name)
        .bind(m.dataset_id)
        .bind(m.dataset_name)
        .bind(m.kind)
        .bind(m.config_json)
        .bind(m.train_json)
        .bind(m.metrics_json)
        .bind(m.history_json)
        .bind(crate::dialect::NullableF64(m.test_r2_mean))
        .bind(crate::dialect::NullableF64(m.test_image_mse))
        .bind(m.artifact)
        .bind(m.software_version)
        .fetch_one(self.pool())
        .await
        .map_err(query_err("recording the model"))?;
        Ok(model_id)
    }

    /// The model called `name`, if any.
    ///
    /// # Errors
    /// A query failure.
    pub async fn model(&self, name: &str) -> Result<Option<ModelInfo>, StoreError> {
        sqlx::query_as::<_, ModelInfo>(self.dialect.sql(info_select!("WHERE name = ?")))
            .bind(name)
            .fetch_optional(self.pool())
            .await
            .map_err(query_err("looking up a model"))
    }

    /// Every model, oldest first.
    ///
    /// # Errors
    /// A query failure.
    pub async fn models(&self) -> Result<Vec<ModelInfo>, StoreError> {
        sqlx::query_as::<_, ModelInfo>(self.dialect.sql(info_select!("ORDER BY model_id")))
            .fetch_all(self.pool())
            .await
            .map_err(query_err("listing models"))
    }

    /// Model `name`'s artifact and kind, if there is such a model.
    ///
    /// # Errors
    /// A query failure.
    pub async fn model_artifact(
        &self,
        name: &str,
    ) -> Result<Option<(Vec<u8>, String)>, StoreError> {
        sqlx::query_as(
            self.dialect
                .sql("SELECT artifact, kind FROM models WHERE name = ?"),
        )
        .bind(name)
        .fetch_optional(self.pool())
        .await
        .map_err(query_err("reading a model"))
    }

    /// Dataset `dataset_id`'s members with labels and frames, in dataset order, as a
    /// stream (a dataset's frames need not fit in memory).
    pub fn member_rows(
        &self,
        dataset_id: i64,
        which: Members,
    ) -> BoxStream<'_, Result<MemberRow, StoreError>> {
        let sql = match which {
            Members::All => concat!(member_rows_sql!(), " ORDER BY m.position"),
            Members::Test => concat!(
                member_rows_sql!(),
                " AND m.split = 'test' ORDER BY m.position"
            ),
            Members::NotTest => {
                concat!(
                    member_rows_sql!(),
                    " AND m.split <> 'test' ORDER BY m.position"
                )
            }
        };
        Box::pin(
            sqlx::query_as::<_, MemberRow>(self.dialect.sql(sql))
                .bind(dataset_id)
                .fetch(self.pool())
                .map_err(|e| query_err("reading the dataset's frames")(e)),
        )
    }

    /// The press of the collection runs model `name` was trained on: each accepted
    /// training sample's commanded x (m, rod frame: how far the finger was pressed
    /// in) and its label's force magnitude (N), in the dataset's order, at most
    /// `limit`. Empty when the model or its dataset is gone.
    ///
    /// # Errors
    /// A query failure.
    pub async fn training_press(
        &self,
        name: &str,
        limit: i64,
    ) -> Result<Vec<(f64, f64)>, StoreError> {
        let rows: Vec<(f64, f64, f64, f64)> = sqlx::query_as(self.dialect.sql(
            "SELECT s.cmd_x_m, s.fx_n, s.fy_n, s.fz_n
             FROM models mo
             JOIN dataset_members m ON m.dataset_id = mo.dataset_id
             JOIN samples s ON s.run_id = m.run_id AND s.sample_index = m.sample_index
             WHERE mo.name = ?1 AND m.split = 'train' AND s.status = 'ok'
             ORDER BY m.position
             LIMIT ?2",
        ))
        .bind(name)
        .bind(limit)
        .fetch_all(self.pool())
        .await
        .map_err(query_err(
            "reading the press of the model's training samples",
        ))?;
        Ok(rows
            .into_iter()
            .map(|(x, fx, fy, fz)| (x, (fx * fx + fy * fy + fz * fz).sqrt()))
            .collect())
    }

    /// The test samples of water dataset `water_id` whose run repeats the poses of a
    /// run in land dataset `land_id` (`collect --poses-from`), with that run, in the
    /// water dataset's order.
    ///
    /// # Errors
    /// A query failure.
    pub async fn paired_test_keys(
        &self,
        land_id: i64,
        water_id: i64,
    ) -> Result<Vec<PairKey>, StoreError> {
        sqlx::query_as(self.dialect.sql(
            "SELECT w.run_id AS water_run, w.sample_index, r.poses_from_run_id AS land_run
             FROM dataset_members w
             JOIN runs r ON r.run_id = w.run_id
             JOIN dataset_members l ON l.dataset_id = ?1 AND l.run_id = r.poses_from_run_id
                                   AND l.sample_index = w.sample_index
             WHERE w.dataset_id = ?2 AND w.split = 'test'
             ORDER BY w.position",
        ))
        .bind(land_id)
        .bind(water_id)
        .fetch_all(self.pool())
        .await
        .map_err(query_err("finding paired samples"))
    }

    /// Dataset `dataset_id`'s first test member with its frame (or its first member
    /// when it has no test split), if it holds any frame.
    ///
    /// # Errors
    /// A query failure.
    pub async fn first_test_member(
        &self,
        dataset_id: i64,
    ) -> Result<Option<MemberRow>, StoreError> {
        sqlx::query_as::<_, MemberRow>(self.dialect.sql(concat!(
            member_rows_sql!(),
            " ORDER BY m.split = 'test' DESC, m.position LIMIT 1"
        )))
        .bind(dataset_id)
        .fetch_optional(self.pool())
        .await
        .map_err(query_err("reading a frame of the dataset"))
    }
}
