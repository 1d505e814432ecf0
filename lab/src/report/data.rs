//! What the report reads: the store's read-only rows ([`crate::store::report`]), the
//! progress curves thinned for the page, and a config's fingerprint.

pub(crate) use crate::store::report::{
    DatasetData, MAX_TIMELINE, ModelRow, ReadOnly, RunData, artifact, datasets, frame, models, now,
    open_read_only, test_members,
};
use softtouch_collector::dataset::export::sha256_hex;

use super::ReportError;

/// Points of a run's progress curve at most.
const PROGRESS_POINTS: usize = 400;

/// The first 12 hex digits of the SHA-256 of `text`: a config's fingerprint.
#[must_use]
pub(crate) fn config_hash(text: &str) -> String {
    sha256_hex(text.as_bytes())[..12].to_owned()
}

/// The runs (all, or those listed), oldest first, each progress curve thinned to at
/// most [`PROGRESS_POINTS`] points (the last is the total).
pub(crate) async fn runs(db: &ReadOnly, only: Option<&[i64]>) -> Result<Vec<RunData>, ReportError> {
    let mut runs = crate::store::report::runs(db, only).await?;
    for r in &mut runs {
        let cumulative = std::mem::take(&mut r.progress);
        let mut progress: Vec<(i64, i64, i64)> =
            super::svg::downsample_indices(cumulative.len(), PROGRESS_POINTS)
                .into_iter()
                .map(|i| cumulative[i])
                .collect();
        if let Some(last) = cumulative.last()
            && progress.last() != Some(last)
        {
            progress.push(*last);
        }
        r.progress = progress;
    }
    Ok(runs)
}
