//! The `datasets` and `dataset_members` tables (their one writer, [`insert_dataset`],
//! also used by the import inside its transaction) and the reads of a dataset's
//! members that selection, statistics and export stream.

use crate::Dialect;
use crate::WrenchColumns;
use crate::{Store, StoreError, now_sql, query_err, rows::seed_to_sql};
use futures_util::TryStreamExt as _;
use futures_util::stream::BoxStream;
use sqlx::{AnyConnection, FromRow, Row as _};

/// A sample with its label and what the dataset filters look at.
#[derive(Debug, FromRow)]
pub struct Candidate {
    pub run_id: i64,
    pub sample_index: i64,
    pub rod: String,
    pub medium: String,
    pub status: String,
    /// The label: mean force and torque over the window, sensor frame.
    #[sqlx(flatten)]
    pub wrench: WrenchColumns,
    pub sync_skew_ns: i64,
    pub reading_count: i64,
}

/// A run of a dataset, with its import provenance, as an export records it.
#[derive(Debug, FromRow)]
pub struct ExportRun {
    pub run_id: i64,
    pub seed: i64,
    pub status: String,
    pub scene_name: String,
    pub medium: String,
    pub rig_toml: String,
    pub scene_toml: String,
    pub software_version: String,
    pub schema_version: i64,
    pub created_at: String,
    pub origin_run_id: Option<i64>,
    pub layout: Option<String>,
    pub source_path: Option<String>,
    pub provenance: Option<String>,
}

/// A dataset member with its sample, command, label and frame, as an export writes it.
#[derive(Debug, FromRow)]
pub struct ExportSample {
    pub position: i64,
    pub split: String,
    pub run_id: i64,
    pub sample_index: i64,
    pub rod: String,
    pub medium: String,
    pub cmd_x_m: f64,
    pub cmd_z_m: f64,
    pub cmd_theta_rad: f64,
    /// The label: mean force and torque over the window, sensor frame.
    #[sqlx(flatten)]
    pub wrench: WrenchColumns,
    pub format: String,
    pub width: i64,
    pub height: i64,
    pub data: Vec<u8>,
}

/// A dataset member's split, rod, medium and label, for statistics.
#[derive(Debug, FromRow)]
pub struct LabelRow {
    pub split: String,
    pub rod: String,
    pub medium: String,
    /// The label: mean force and torque over the window, sensor frame.
    #[sqlx(flatten)]
    pub wrench: WrenchColumns,
}

/// A dataset as stored, with its split counts.
#[derive(Debug, Clone)]
pub struct DatasetRow {
    /// Row id.
    pub dataset_id: i64,
    /// Name.
    pub name: String,
    /// Its definition (JSON).
    pub definition_json: String,
    /// Members.
    pub sample_count: i64,
    /// The software that made it.
    pub software_version: String,
    /// The schema it was made at.
    pub schema_version: i64,
    /// When (UTC).
    pub created_at: String,
    /// Members per split: train, val, test.
    pub split_counts: [i64; 3],
}

/// A dataset to insert.
#[derive(Debug, Clone)]
pub struct NewDataset<'a> {
    /// Its name (unique).
    pub name: &'a str,
    /// Its definition (JSON).
    pub definition_json: &'a str,
    /// The split's seed.
    pub seed: u64,
    /// The split ratio as written (`7:1:2`).
    pub split_ratio: &'a str,
    /// Its members in order: `(run, index, split)`.
    pub members: &'a [(i64, i64, &'a str)],
}

/// Inserts a dataset and its members (position = order) on `conn`, inside the
/// caller's transaction; `None` when the name is taken.
///
/// # Errors
/// A query failure, or more members than an SQLite integer counts.
pub async fn insert_dataset(
    conn: &mut AnyConnection,
    d: &NewDataset<'_>,
) -> Result<Option<i64>, StoreError> {
    let count = i64::try_from(d.members.len()).map_err(|_| StoreError::Invalid {
        what: "dataset",
        why: "too many samples".into(),
    })?;
    let inserted: Option<i64> = sqlx::query_scalar(Dialect::of(conn).sql(concat!(
        "INSERT INTO datasets (name, definition_json, seed, split_ratio, sample_count,
                               software_version, schema_version, created_at)
         VALUES (?, ?, ?, ?, ?, ?, ?, ",
        now_sql!(),
        ") ON CONFLICT (name) DO NOTHING RETURNING dataset_id"
    )))
    .bind(d.name)
    .bind(d.definition_json)
    .bind(seed_to_sql(d.seed))
    .bind(d.split_ratio)
    .bind(count)
    .bind(softtouch_schemas::SOFTWARE_VERSION)
    .bind(Store::schema_version())
    .fetch_optional(&mut *conn)
    .await
    .map_err(query_err("inserting a dataset"))?;
    let Some(dataset_id) = inserted else {
        return Ok(None);
    };
    for (position, &(run, index, split)) in d.members.iter().enumerate() {
        sqlx::query(Dialect::of(conn).sql(
            "INSERT INTO dataset_members (dataset_id, position, run_id, sample_index, split)
             VALUES (?, ?, ?, ?, ?)",
        ))
        .bind(dataset_id)
        .bind(i64::try_from(position).unwrap_or(i64::MAX))
        .bind(run)
        .bind(index)
        .bind(split)
        .execute(&mut *conn)
        .await
        .map_err(query_err("inserting dataset members"))?;
    }
    Ok(Some(dataset_id))
}

impl Store {
    /// Whether run `run` exists.
    ///
    /// # Errors
    /// A query failure.
    pub async fn run_exists(&self, run: i64) -> Result<bool, StoreError> {
        let found: Option<i64> =
            sqlx::query_scalar(self.dialect.sql("SELECT run_id FROM runs WHERE run_id = ?"))
                .bind(run)
                .fetch_optional(self.pool())
                .await
                .map_err(query_err("looking up a run"))?;
        Ok(found.is_some())
    }

    /// Run `run`'s samples that have a frame, in index order, with what the dataset
    /// filters look at.
    pub fn candidates(&self, run: i64) -> BoxStream<'_, Result<Candidate, StoreError>> {
        Box::pin(
            sqlx::query_as::<_, Candidate>(self.dialect.sql(
                "SELECT s.run_id, s.sample_index, s.rod, s.medium, s.status,
                        s.fx_n, s.fy_n, s.fz_n, s.tx_nm, s.ty_nm, s.tz_nm, s.sync_skew_ns, s.reading_count
                 FROM samples s
                 WHERE s.run_id = ?
                   AND EXISTS (SELECT 1 FROM frames f
                               WHERE f.run_id = s.run_id AND f.sample_index = s.sample_index)
                 ORDER BY s.sample_index"),
            )
            .bind(run)
            .fetch(self.pool())
            .map_err(|e| query_err("selecting samples")(e)),
        )
    }

    /// The dataset called `name`, if any.
    ///
    /// # Errors
    /// A query failure.
    pub async fn dataset(&self, name: &str) -> Result<Option<DatasetRow>, StoreError> {
        let row = sqlx::query(self.dialect.sql(
            "SELECT d.dataset_id, d.name, d.definition_json, d.sample_count, d.software_version,
                    d.schema_version, d.created_at,
                    (SELECT COUNT(*) FROM dataset_members m WHERE m.dataset_id = d.dataset_id AND m.split = 'train'),
                    (SELECT COUNT(*) FROM dataset_members m WHERE m.dataset_id = d.dataset_id AND m.split = 'val'),
                    (SELECT COUNT(*) FROM dataset_members m WHERE m.dataset_id = d.dataset_id AND m.split = 'test')
             FROM datasets d WHERE d.name = ?"),
        )
        .bind(name)
        .fetch_optional(self.pool())
        .await
        .map_err(query_err("looking up a dataset"))?;
        Ok(row.map(|row| DatasetRow {
            dataset_id: row.get(0),
            name: row.get(1),
            definition_json: row.get(2),
            sample_count: row.get(3),
            software_version: row.get(4),
            schema_version: row.get(5),
            created_at: row.get(6),
            split_counts: [row.get(7), row.get(8), row.get(9)],
        }))
    }

    /// Every dataset's name, oldest first.
    ///
    /// # Errors
    /// A query failure.
    pub async fn dataset_names(&self) -> Result<Vec<String>, StoreError> {
        sqlx::query_scalar(
            self.dialect
                .sql("SELECT name FROM datasets ORDER BY dataset_id"),
        )
        .fetch_all(self.pool())
        .await
        .map_err(query_err("listing datasets"))
    }

    /// The runs dataset `dataset_id` draws on, with their import provenance.
    ///
    /// # Errors
    /// A query failure.
    pub async fn dataset_runs(&self, dataset_id: i64) -> Result<Vec<ExportRun>, StoreError> {
        sqlx::query_as::<_, ExportRun>(self.dialect.sql(
            "SELECT r.run_id, r.seed, r.status, r.scene_name, r.medium, r.rig_toml, r.scene_toml,
                    r.software_version, r.schema_version, r.created_at,
                    i.origin_run_id, i.layout, i.source_path, i.provenance
             FROM runs r LEFT JOIN run_imports i ON i.run_id = r.run_id
             WHERE r.run_id IN (SELECT DISTINCT run_id FROM dataset_members WHERE dataset_id = ?)
             ORDER BY r.run_id",
        ))
        .bind(dataset_id)
        .fetch_all(self.pool())
        .await
        .map_err(query_err("reading the dataset's runs"))
    }

    /// Dataset `dataset_id`'s members with their samples and frames, in order.
    pub fn dataset_samples(
        &self,
        dataset_id: i64,
    ) -> BoxStream<'_, Result<ExportSample, StoreError>> {
        Box::pin(
            sqlx::query_as::<_, ExportSample>(self.dialect.sql(
                "SELECT m.position, m.split, m.run_id, m.sample_index, s.rod, s.medium,
                        s.cmd_x_m, s.cmd_z_m, s.cmd_theta_rad,
                        s.fx_n, s.fy_n, s.fz_n, s.tx_nm, s.ty_nm, s.tz_nm,
                        f.format, f.width, f.height, f.data
                 FROM dataset_members m
                 JOIN samples s ON s.run_id = m.run_id AND s.sample_index = m.sample_index
                 JOIN frames f ON f.run_id = m.run_id AND f.sample_index = m.sample_index
                 WHERE m.dataset_id = ? ORDER BY m.position",
            ))
            .bind(dataset_id)
            .fetch(self.pool())
            .map_err(|e| query_err("reading dataset samples")(e)),
        )
    }

    /// Dataset `dataset_id`'s members' splits, rods, media and labels, in order.
    pub fn dataset_labels(&self, dataset_id: i64) -> BoxStream<'_, Result<LabelRow, StoreError>> {
        Box::pin(
            sqlx::query_as::<_, LabelRow>(self.dialect.sql(
                "SELECT m.split, s.rod, s.medium, s.fx_n, s.fy_n, s.fz_n, s.tx_nm, s.ty_nm, s.tz_nm
                 FROM dataset_members m
                 JOIN samples s ON s.run_id = m.run_id AND s.sample_index = m.sample_index
                 WHERE m.dataset_id = ? ORDER BY m.position",
            ))
            .bind(dataset_id)
            .fetch(self.pool())
            .map_err(|e| query_err("reading dataset samples")(e)),
        )
    }

    /// The database's clock, ISO-8601 UTC with milliseconds.
    ///
    /// # Errors
    /// A query failure.
    pub async fn now(&self) -> Result<String, StoreError> {
        sqlx::query_scalar(self.dialect.sql(concat!("SELECT ", now_sql!())))
            .fetch_one(self.pool())
            .await
            .map_err(query_err("reading the clock"))
    }
}
