//! Land to water (issue 18): the test examples of a dataset, and the paired test
//! examples of a water dataset whose runs repeat the poses of a land dataset's runs
//! (`collect --poses-from`), preprocessed for one model. The statistics that compare
//! their latents live in `softtouch_trainer::similarity`; `softtouch transfer` prints
//! them.

use crate::models::{MemberRow, ModelError, preprocess_parallel};
use crate::store::{Members, Store};
use futures_util::TryStreamExt as _;
use softtouch_collector::dataset;
use softtouch_trainer::{
    Example, FingerTable, ImageTare, Preprocess, RestFrame, TareError, TareFit,
};
use std::collections::HashMap;

/// Paired test examples: `land[i]` and `water[i]` are the same pose and rod.
#[derive(Debug, Clone, Default)]
pub struct Pairs {
    /// The land side.
    pub land: Vec<Example>,
    /// The water side.
    pub water: Vec<Example>,
    /// Each `(water run, land run)` the pairs come from, checked pose by pose.
    pub runs: Vec<(i64, i64)>,
}

/// Why pairs could not be made.
#[derive(Debug, thiserror::Error)]
pub enum TransferError {
    /// Loading or decoding failed.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A run pairs with another in name but not pose by pose.
    #[error(transparent)]
    Store(#[from] crate::store::StoreError),
    /// A dataset whose runs kept no rest frame.
    #[error(
        "dataset `{0}` has no rest frames: its runs were collected before softtouch kept them (collect its runs again to fit an image tare)"
    )]
    NoRestFrames(String),
    /// The tare could not be fitted.
    #[error("the image tare of `{water}` against `{land}`: {error}")]
    Tare {
        /// The land dataset.
        land: String,
        /// The water dataset.
        water: String,
        /// Why.
        error: TareError,
    },
    /// Nothing to pair.
    #[error(
        "no test sample of dataset `{water}` pairs with a sample of dataset `{land}`: collect the water run with `collect --poses-from RUN` from a run of `{land}`, and put it in `{water}`"
    )]
    NoPairs {
        /// The land dataset.
        land: String,
        /// The water dataset.
        water: String,
    },
}

impl TransferError {
    /// Whether the user's input is at fault (exit code 2).
    #[must_use]
    pub fn is_bad_input(&self) -> bool {
        match self {
            Self::Model(e) => e.is_bad_input(),
            Self::NoPairs { .. } | Self::NoRestFrames(_) | Self::Tare { .. } => true,
            Self::Store(_) => false,
        }
    }
}

/// A sample's key: (run, index).
type Key = (i64, i64);

/// The member rows of dataset `dataset_id` that `which` keeps, preprocessed for `table` in chunks as they stream in (a
/// 6000-sample split holds about a gigabyte of encoded frames), with their keys.
async fn load_keyed(
    store: &Store,
    dataset_id: i64,
    which: Members,
    table: &FingerTable,
    tare: Option<&ImageTare>,
) -> Result<Vec<(Key, Example)>, ModelError> {
    let mut rows = store.member_rows(dataset_id, which);
    let mut out = Vec::new();
    let mut chunk: Vec<MemberRow> = Vec::with_capacity(256);
    loop {
        let row = rows.try_next().await?;
        let last = row.is_none();
        if let Some(row) = row {
            chunk.push(row);
        }
        if chunk.len() >= 256 || (last && !chunk.is_empty()) {
            let rows = std::mem::take(&mut chunk);
            let keys: Vec<Key> = rows.iter().map(|r| (r.run_id, r.sample_index)).collect();
            let examples = preprocess_parallel(rows, table, tare)?;
            out.extend(keys.into_iter().zip(examples.into_iter().map(|(_, e)| e)));
        }
        if last {
            return Ok(out);
        }
    }
}

/// A dataset's test split, keyed, for [`paired_test`].
#[derive(Debug, Clone)]
pub struct TestSplit {
    /// Dataset name.
    pub name: String,
    /// Row id.
    dataset_id: i64,
    /// Each example's key, in dataset order.
    keys: Vec<Key>,
    /// The examples, in dataset order.
    pub examples: Vec<Example>,
}

/// Dataset `name`'s test split only, preprocessed for `table` (cheaper than loading
/// every split), each frame corrected by `tare` first where one is given.
///
/// # Errors
/// No such dataset, a query, an undecodable frame.
pub async fn test_split(
    store: &Store,
    name: &str,
    table: &FingerTable,
    tare: Option<&ImageTare>,
) -> Result<TestSplit, ModelError> {
    let info = dataset::get(store, name).await?;
    let (keys, examples) = load_keyed(store, info.dataset_id, Members::Test, table, tare)
        .await?
        .into_iter()
        .unzip();
    Ok(TestSplit {
        name: name.to_owned(),
        dataset_id: info.dataset_id,
        keys,
        examples,
    })
}

/// The water test samples whose run repeats the poses of a run in the land dataset,
/// with their land partners (any split of the land dataset; partners outside its test
/// split are loaded here, those inside are taken from `land`), preprocessed for
/// `table` as `land` and `water` were. Each pair of runs is checked pose by pose first.
///
/// # Errors
/// No pairs, runs that do not pair pose by pose, a query, an undecodable frame.
pub async fn paired_test(
    store: &Store,
    land: &TestSplit,
    water: &TestSplit,
    table: &FingerTable,
) -> Result<Pairs, TransferError> {
    let keys = store
        .paired_test_keys(land.dataset_id, water.dataset_id)
        .await?;
    if keys.is_empty() {
        return Err(TransferError::NoPairs {
            land: land.name.clone(),
            water: water.name.clone(),
        });
    }
    let mut runs: Vec<(i64, i64)> = keys.iter().map(|k| (k.water_run, k.land_run)).collect();
    runs.sort_unstable();
    runs.dedup();
    for (water_run, land_run) in &runs {
        store.check_paired_poses(*water_run, *land_run).await?;
    }
    let index = |split: &TestSplit| -> HashMap<Key, usize> {
        split
            .keys
            .iter()
            .enumerate()
            .map(|(i, k)| (*k, i))
            .collect()
    };
    let (land_at, water_at) = (index(land), index(water));
    // Partners outside the land test split: load just those.
    let mut extra: HashMap<Key, Example> = HashMap::new();
    if keys
        .iter()
        .any(|k| !land_at.contains_key(&(k.land_run, k.sample_index)))
    {
        let wanted: std::collections::HashSet<Key> = keys
            .iter()
            .map(|k| (k.land_run, k.sample_index))
            .filter(|k| !land_at.contains_key(k))
            .collect();
        for (k, e) in load_keyed(store, land.dataset_id, Members::NotTest, table, None).await? {
            if wanted.contains(&k) {
                extra.insert(k, e);
            }
        }
    }
    let mut pairs = Pairs {
        runs,
        ..Pairs::default()
    };
    for k in &keys {
        let lk = (k.land_run, k.sample_index);
        let land_example = land_at
            .get(&lk)
            .and_then(|&i| land.examples.get(i))
            .or_else(|| extra.get(&lk));
        let water_example = water_at
            .get(&(k.water_run, k.sample_index))
            .and_then(|&i| water.examples.get(i));
        if let (Some(l), Some(w)) = (land_example, water_example) {
            pairs.land.push(l.clone());
            pairs.water.push(w.clone());
        }
    }
    Ok(pairs)
}

/// Dataset `name`'s rest frames (every run with a sample in it), decoded.
pub(crate) async fn rest_frames(
    store: &Store,
    name: &str,
) -> Result<Vec<RestFrame>, TransferError> {
    let info = dataset::get(store, name).await.map_err(ModelError::from)?;
    let rows = store.dataset_rest_frames(info.dataset_id).await?;
    if rows.is_empty() {
        return Err(TransferError::NoRestFrames(name.to_owned()));
    }
    rows.iter()
        .map(|r| {
            let (width, height, rgb) = crate::models::decode_stored(
                &r.format, r.width, r.height, &r.data,
            )
            .map_err(|why| ModelError::Frame {
                run: r.run_id,
                index: r.rest_index,
                why: format!("rest frame: {why}"),
            })?;
            Ok(RestFrame { width, height, rgb })
        })
        .collect()
}

/// The image tare that maps the rest frames of dataset `water`'s runs onto those of
/// dataset `land`'s (no label of either is read), its gain and offset fitted on the
/// pixels `preprocess` keeps as the finger's, as its signal needs ([`TareGains`]).
///
/// [`TareGains`]: softtouch_trainer::TareGains
///
/// # Errors
/// A dataset without rest frames, frames that cannot be decoded or compared.
pub async fn fit_tare(
    store: &Store,
    land: &str,
    water: &str,
    preprocess: &Preprocess,
) -> Result<TareFit, TransferError> {
    let (l, w) = (
        rest_frames(store, land).await?,
        rest_frames(store, water).await?,
    );
    let keep = |r, g, b| preprocess.is_finger(r, g, b);
    softtouch_trainer::fit_image_tare(
        &l,
        &w,
        Some(&keep),
        softtouch_trainer::TareGains::for_signal(preprocess.signal),
    )
    .map_err(|error| TransferError::Tare {
        land: land.to_owned(),
        water: water.to_owned(),
        error,
    })
}
