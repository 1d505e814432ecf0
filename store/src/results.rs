//! Experiment results (`results`, `result_tables`): what each experiment verb measured,
//! with its provenance, written in one transaction as the verb ends; the layout is
//! documented in the migration `20261127150000_results.sql`.

use super::rows::now_sql;
use super::{Store, StoreError, query_err};
use crate::Dialect;
use sqlx::Row;

/// A result to store.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NewResult {
    /// The verb, as typed (`grasp follow`, `sweep alpha`, …).
    pub verb: String,
    /// Settings and seeds, a JSON object.
    pub settings_json: String,
    /// The model it ran (a stored model's name or an artifact's path).
    pub model: Option<String>,
    /// sha256 of the model's artifact.
    pub model_sha256: Option<String>,
    /// The dataset it read.
    pub dataset: Option<String>,
    /// sha256 of the scene as run.
    pub scene_hash: Option<String>,
    /// sha256 of the rig's gripper and cameras.
    pub rig_hash: Option<String>,
    /// One line: what it found.
    pub summary: String,
    /// The git commit the binary was built from, if known.
    pub software_commit: Option<String>,
    /// `(file name, CSV text)` per table, as the verb writes them.
    pub tables: Vec<(String, String)>,
    /// `(file name, PNG bytes)` per figure its tables cannot redraw.
    pub figures: Vec<(String, Vec<u8>)>,
}

/// A stored result without its tables (the listing).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ResultRow {
    /// Its id.
    pub result_id: i64,
    /// When it was stored (UTC).
    pub created_at: String,
    /// The verb.
    pub verb: String,
    /// Settings and seeds, a JSON object.
    pub settings_json: String,
    /// The model's name.
    pub model: Option<String>,
    /// sha256 of the model's artifact.
    pub model_sha256: Option<String>,
    /// The dataset's name.
    pub dataset: Option<String>,
    /// sha256 of the scene as run.
    pub scene_hash: Option<String>,
    /// sha256 of the rig's gripper and cameras.
    pub rig_hash: Option<String>,
    /// One line.
    pub summary: String,
    /// softtouch's version.
    pub software_version: String,
    /// Its git commit, if known.
    pub software_commit: Option<String>,
}

/// A stored result with its tables.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StoredResult {
    /// The row.
    pub row: ResultRow,
    /// `(file name, CSV text)`, by name.
    pub tables: Vec<(String, String)>,
    /// `(file name, PNG bytes)`, by name.
    pub figures: Vec<(String, Vec<u8>)>,
}

impl StoredResult {
    /// The table stored under `name`.
    #[must_use]
    pub fn table(&self, name: &str) -> Option<&str> {
        self.tables
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, csv)| csv.as_str())
    }
}

macro_rules! result_columns {
    () => {
        "result_id, created_at, verb, settings_json, model, model_sha256, dataset, scene_hash, rig_hash, summary, software_version, software_commit"
    };
}

fn result_row(r: &sqlx::any::AnyRow) -> ResultRow {
    ResultRow {
        result_id: r.get(0),
        created_at: r.get(1),
        verb: r.get(2),
        settings_json: r.get(3),
        model: r.get(4),
        model_sha256: r.get(5),
        dataset: r.get(6),
        scene_hash: r.get(7),
        rig_hash: r.get(8),
        summary: r.get(9),
        software_version: r.get(10),
        software_commit: r.get(11),
    }
}

impl Store {
    /// Stores a result and its tables in one transaction; returns its id.
    ///
    /// # Errors
    /// An empty verb, settings that are not a JSON object, two tables of one name, or
    /// the database refused the write (then nothing of it is stored).
    pub async fn insert_result(&self, r: &NewResult) -> Result<i64, StoreError> {
        if r.verb.trim().is_empty() {
            return Err(StoreError::Invalid {
                what: "a result's verb",
                why: "empty".into(),
            });
        }
        match serde_json::from_str::<serde_json::Value>(&r.settings_json) {
            Ok(serde_json::Value::Object(_)) => {}
            _ => {
                return Err(StoreError::Invalid {
                    what: "a result's settings",
                    why: format!("expected a JSON object, found `{}`", r.settings_json),
                });
            }
        }
        for (i, (name, _)) in r.tables.iter().enumerate() {
            if name.is_empty() || r.tables[..i].iter().any(|(n, _)| n == name) {
                return Err(StoreError::Invalid {
                    what: "a result's table name",
                    why: format!("`{name}`: expected a unique, non-empty file name"),
                });
            }
        }
        for (i, (name, png)) in r.figures.iter().enumerate() {
            if name.is_empty() || r.figures[..i].iter().any(|(n, _)| n == name) {
                return Err(StoreError::Invalid {
                    what: "a result's figure name",
                    why: format!("`{name}`: expected a unique, non-empty file name"),
                });
            }
            if !png.starts_with(b"\x89PNG\r\n\x1a\n") {
                return Err(StoreError::Invalid {
                    what: "a result's figure",
                    why: format!("`{name}` is not a PNG"),
                });
            }
        }
        let mut tx = self
            .pool()
            .begin()
            .await
            .map_err(query_err("starting a result's transaction"))?;
        let id: i64 = sqlx::query(Dialect::of(&tx).sql(concat!(
            "INSERT INTO results (created_at, verb, settings_json, model, model_sha256, dataset, scene_hash, rig_hash, summary, software_version, software_commit) VALUES (",
            now_sql!(),
            ", ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) RETURNING result_id"
        )))
        .bind(&r.verb)
        .bind(&r.settings_json)
        .bind(&r.model)
        .bind(&r.model_sha256)
        .bind(&r.dataset)
        .bind(&r.scene_hash)
        .bind(&r.rig_hash)
        .bind(&r.summary)
        .bind(softtouch_schemas::SOFTWARE_VERSION)
        .bind(&r.software_commit)
        .fetch_one(&mut *tx)
        .await
        .map_err(query_err("storing a result"))?
        .get(0);
        for (name, csv) in &r.tables {
            sqlx::query(
                Dialect::of(&tx)
                    .sql("INSERT INTO result_tables (result_id, name, csv) VALUES (?, ?, ?)"),
            )
            .bind(id)
            .bind(name)
            .bind(csv)
            .execute(&mut *tx)
            .await
            .map_err(query_err("storing a result's table"))?;
        }
        for (name, png) in &r.figures {
            sqlx::query(
                Dialect::of(&tx)
                    .sql("INSERT INTO result_figures (result_id, name, png) VALUES (?, ?, ?)"),
            )
            .bind(id)
            .bind(name)
            .bind(png)
            .execute(&mut *tx)
            .await
            .map_err(query_err("storing a result's figure"))?;
        }
        tx.commit()
            .await
            .map_err(query_err("committing a result"))?;
        Ok(id)
    }

    /// Every stored result, oldest first, without tables.
    ///
    /// # Errors
    /// The query failed.
    pub async fn results(&self) -> Result<Vec<ResultRow>, StoreError> {
        results_of(self.pool(), self.dialect).await
    }

    /// One result with its tables, if it exists.
    ///
    /// # Errors
    /// The query failed.
    pub async fn result(&self, result_id: i64) -> Result<Option<StoredResult>, StoreError> {
        let row = sqlx::query(self.dialect.sql(concat!(
            "SELECT ",
            result_columns!(),
            " FROM results WHERE result_id = ?"
        )))
        .bind(result_id)
        .fetch_optional(self.pool())
        .await
        .map_err(query_err("reading a result"))?;
        let Some(row) = row.as_ref().map(result_row) else {
            return Ok(None);
        };
        let tables = tables_of(self.pool(), self.dialect, result_id).await?;
        let figures = figures_of(self.pool(), self.dialect, result_id).await?;
        Ok(Some(StoredResult {
            row,
            tables,
            figures,
        }))
    }
}

/// Every result, oldest first.
pub(crate) async fn results_of(
    pool: &sqlx::AnyPool,
    d: Dialect,
) -> Result<Vec<ResultRow>, StoreError> {
    let rows = sqlx::query(d.sql(concat!(
        "SELECT ",
        result_columns!(),
        " FROM results ORDER BY result_id"
    )))
    .fetch_all(pool)
    .await
    .map_err(query_err("reading results"))?;
    Ok(rows.iter().map(result_row).collect())
}

/// One result's tables, by name.
pub(crate) async fn tables_of(
    pool: &sqlx::AnyPool,
    d: Dialect,
    result_id: i64,
) -> Result<Vec<(String, String)>, StoreError> {
    let rows = sqlx::query(d.sql(
        "SELECT name, csv FROM result_tables WHERE result_id = ? ORDER BY name COLLATE BINARY",
    ))
    .bind(result_id)
    .fetch_all(pool)
    .await
    .map_err(query_err("reading a result's tables"))?;
    Ok(rows.iter().map(|r| (r.get(0), r.get(1))).collect())
}

/// One result's figures, by name.
pub(crate) async fn figures_of(
    pool: &sqlx::AnyPool,
    d: Dialect,
    result_id: i64,
) -> Result<Vec<(String, Vec<u8>)>, StoreError> {
    let rows = sqlx::query(d.sql(
        "SELECT name, png FROM result_figures WHERE result_id = ? ORDER BY name COLLATE BINARY",
    ))
    .bind(result_id)
    .fetch_all(pool)
    .await
    .map_err(query_err("reading a result's figures"))?;
    Ok(rows.iter().map(|r| (r.get(0), r.get(1))).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(verb: &str) -> NewResult {
        NewResult {
            verb: verb.into(),
            settings_json: r#"{"seed":7}"#.into(),
            model: Some("land-svae".into()),
            model_sha256: Some("ab".repeat(32)),
            dataset: Some("land-v1".into()),
            summary: "one line".into(),
            tables: vec![
                ("a.csv".into(), "x,y\n1,2\n".into()),
                ("b.csv".into(), "z\n3\n".into()),
            ],
            figures: vec![("f.png".into(), b"\x89PNG\r\n\x1a\nrest".to_vec())],
            ..NewResult::default()
        }
    }

    #[tokio::test]
    async fn a_result_reads_back_whole_and_reruns_add_rows() {
        let dir = tempfile::tempdir().expect("test step");
        let store = Store::open(crate::testing::fresh_target(dir.path(), "r.db").await)
            .await
            .expect("test step");
        let a = store
            .insert_result(&result("grasp follow"))
            .await
            .expect("test step");
        let b = store
            .insert_result(&result("grasp follow"))
            .await
            .expect("test step");
        assert_ne!(a, b);
        let listed = store.results().await.expect("test step");
        assert_eq!(listed.len(), 2);
        let got = store
            .result(a)
            .await
            .expect("test step")
            .expect("test step");
        assert_eq!(got.row.verb, "grasp follow");
        assert_eq!(got.row.model.as_deref(), Some("land-svae"));
        assert_eq!(
            got.row.software_version,
            softtouch_schemas::SOFTWARE_VERSION
        );
        assert_eq!(got.table("a.csv"), Some("x,y\n1,2\n"));
        assert_eq!(got.table("b.csv"), Some("z\n3\n"));
        assert_eq!(got.figures, result("x").figures);
        assert!(store.result(b + 1).await.expect("test step").is_none());
        store.close().await;
    }

    #[tokio::test]
    async fn bad_results_store_nothing() {
        let dir = tempfile::tempdir().expect("test step");
        let store = Store::open(crate::testing::fresh_target(dir.path(), "r.db").await)
            .await
            .expect("test step");
        let mut empty_verb = result("x");
        empty_verb.verb = " ".into();
        let mut not_object = result("x");
        not_object.settings_json = "[1]".into();
        let mut not_json = result("x");
        not_json.settings_json = "{".into();
        let mut twice = result("x");
        twice.tables.push(("a.csv".into(), String::new()));
        let mut not_png = result("x");
        not_png.figures[0].1 = b"GIF89a".to_vec();
        for bad in [empty_verb, not_object, not_json, twice, not_png] {
            let e = store.insert_result(&bad).await.expect_err("must fail");
            assert!(matches!(e, StoreError::Invalid { .. }), "{e}");
        }
        assert!(store.results().await.expect("test step").is_empty());
        let n: i64 = sqlx::query_scalar(store.dialect().sql("SELECT COUNT(*) FROM result_tables"))
            .fetch_one(store.pool())
            .await
            .expect("test step");
        assert_eq!(n, 0);
        store.close().await;
    }
}
