//! The finger's rest frames of a run (no contact), taken once at its start: what an
//! image tare for a medium compares (see `migrations/*/20261208000000_rest_frames.sql`).

use super::{Dialect, FrameRecord, RunId, Store, StoreError, query_err, to_i64};

/// A rest frame as stored.
#[derive(Debug, Clone, PartialEq, Eq, sqlx::FromRow)]
pub struct RestFrameRow {
    /// Its run.
    pub run_id: i64,
    /// Its place among the run's rest frames (0, 1, …).
    pub rest_index: i64,
    /// `png`, `jpeg` or `rgb8`.
    pub format: String,
    /// Width, px.
    pub width: i64,
    /// Height, px.
    pub height: i64,
    /// The frame's bytes as stored.
    pub data: Vec<u8>,
}

impl Store {
    /// Stores run `run_id`'s rest frames in one transaction; those it has already
    /// keep their place (a resumed run keeps the frames of its first start). How many
    /// were stored. Every statement writes: on SQLite the transaction takes the write
    /// lock at its first statement, waiting for it as any writer does (a read first
    /// would have to upgrade its lock, which SQLite refuses at once while another rig
    /// writes).
    pub async fn insert_rest_frames(
        &self,
        run_id: RunId,
        frames: &[FrameRecord<'_>],
    ) -> Result<u64, StoreError> {
        let mut tx = self
            .pool
            .begin()
            .await
            .map_err(query_err("starting the rest frames' transaction"))?;
        let mut stored = 0;
        for (i, f) in frames.iter().enumerate() {
            stored += sqlx::query(Dialect::of(&tx).sql(
                "INSERT INTO rest_frames (run_id, rest_index, format, width, height, sequence, t_ns, data)
                 VALUES (?, ?, ?, ?, ?, ?, ?, ?) ON CONFLICT (run_id, rest_index) DO NOTHING",
            ))
            .bind(run_id)
            .bind(to_i64("rest frame index", i as u64)?)
            .bind(f.meta.format.as_str())
            .bind(i64::from(f.meta.width))
            .bind(i64::from(f.meta.height))
            .bind(to_i64("frame sequence", f.meta.sequence)?)
            .bind(to_i64("frame time", f.meta.t.0)?)
            .bind(f.data)
            .execute(&mut *tx)
            .await
            .map_err(query_err("inserting a rest frame"))?
            .rows_affected();
        }
        tx.commit()
            .await
            .map_err(query_err("committing the rest frames"))?;
        Ok(stored)
    }

    /// The rest frames of every run with a sample in dataset `dataset_id`, by run and
    /// index (runs stored before rest frames were kept have none).
    pub async fn dataset_rest_frames(
        &self,
        dataset_id: i64,
    ) -> Result<Vec<RestFrameRow>, StoreError> {
        sqlx::query_as(self.dialect.sql(
            "SELECT run_id, rest_index, format, width, height, data FROM rest_frames
             WHERE run_id IN (SELECT DISTINCT run_id FROM dataset_members WHERE dataset_id = ?)
             ORDER BY run_id, rest_index",
        ))
        .bind(dataset_id)
        .fetch_all(&self.pool)
        .await
        .map_err(query_err("reading a dataset's rest frames"))
    }
}
