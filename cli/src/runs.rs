//! `softtouch runs`.

use super::{Failure, io_failure, open_existing};
use std::io::Write;

pub async fn run(db: &softtouch_store::DbTarget, out: &mut dyn Write) -> Result<(), Failure> {
    let store = open_existing(db).await?;
    let runs = store.runs().await?;
    store.close().await;
    if runs.is_empty() {
        return writeln!(out, "no runs in {}", db.display()).map_err(io_failure);
    }
    let mut text = format!(
        "{:>4}  {:<9}  {:<12}  {:<5}  {:>20}  {:>8}  {:>8}  {:>8}  {:>7}  {:>6}  {}\n",
        "run",
        "status",
        "scene",
        "med.",
        "seed",
        "planned",
        "ok",
        "rejected",
        "retried",
        "faults",
        "updated (UTC)"
    );
    for r in &runs {
        let seed = softtouch_store::rows::seed_from_sql(r.seed);
        text.push_str(&format!(
            "{:>4}  {:<9}  {:<12}  {:<5}  {:>20}  {:>8}  {:>8}  {:>8}  {:>7}  {:>6}  {}\n",
            r.run_id,
            r.status,
            r.scene_name,
            r.medium,
            seed,
            r.samples_planned,
            r.ok,
            r.rejected,
            r.retried,
            r.faults,
            r.updated_at
        ));
    }
    out.write_all(text.as_bytes()).map_err(io_failure)
}
