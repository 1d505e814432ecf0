//! How much water data buys back a land model's accuracy (issue 18): the model is
//! fine-tuned on nested subsets of a dataset's train split (the first n of one seeded
//! shuffle, so 100 ⊂ 300 ⊂ 1000 …) and, for comparison, the same model is trained
//! from scratch on each subset; every row is tested on the dataset's whole test split.
//!
//! Validation (early stopping and the choice of epoch) sees only as many validation
//! samples as the dataset's split ratio gives n training samples: a lab with 100 water
//! samples does not have the full validation split either.

use crate::experiments::{ExperimentError, csv_opt, fmt_opt, push_axis_r2, push_axis_r2_header};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use softtouch_collector::plot::{Series, SeriesStyle, XyChart, xy_chart};
use softtouch_trainer::train::Observer;
use softtouch_trainer::{
    EpochReport, InitFrom, Metrics, ModelArtifact, Splits, TrainConfig, evaluate,
};
use std::path::Path;

/// Where a row's training started.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Start {
    /// From the starting model's weights.
    FineTuned,
    /// From the seed's initialisation (the same model settings).
    Scratch,
}

impl Start {
    /// As the table and the CSV name it.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::FineTuned => "fine-tuned",
            Self::Scratch => "scratch",
        }
    }
}

/// One row of the curve.
#[derive(Debug, Clone)]
pub struct FinetuneRow {
    /// Training samples used.
    pub samples: usize,
    /// Validation samples used.
    pub val_samples: usize,
    /// Where training started.
    pub start: Start,
    /// On the whole test split.
    pub test: Metrics,
    /// Epochs run (0: the starting model as it is).
    pub epochs_run: usize,
    /// The epoch whose weights were kept (best validation score).
    pub best_epoch: usize,
    /// The first epoch whose validation R² reached the target on every axis, if any.
    pub epochs_to_target: Option<usize>,
    /// Wall time of the training, s.
    pub seconds: f64,
}

/// The first `n` of a seeded shuffle of `examples`.
fn first_of_shuffle<T: Clone>(examples: &[T], n: usize, seed: u64) -> Vec<T> {
    let mut order: Vec<usize> = (0..examples.len()).collect();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    order.truncate(n);
    order.into_iter().map(|i| examples[i].clone()).collect()
}

/// The validation samples that go with `n` training samples: the dataset's ratio,
/// at least 2 (one would make every R² undefined).
#[must_use]
pub fn val_size(n: usize, splits: &Splits) -> usize {
    let ratio = splits.val.len() as f64 / splits.train.len().max(1) as f64;
    ((n as f64 * ratio).ceil() as usize)
        .max(2)
        .min(splits.val.len())
}

/// Checks a list of subset sizes on its own, before any data is loaded.
///
/// # Errors
/// An empty list, or a size of 1 (batch norm needs two).
pub fn check_requested(sizes: &[usize]) -> Result<(), ExperimentError> {
    if sizes.is_empty() {
        return Err(ExperimentError::Invalid(
            "--samples: expected at least one size".into(),
        ));
    }
    if sizes.contains(&1) {
        return Err(ExperimentError::Invalid(
            "--samples 1: training needs at least 2 samples (batch norm); 0 tests the starting model as it is".into(),
        ));
    }
    Ok(())
}

/// `sweep finetune`'s sizes when `--samples` is not given.
pub const DEFAULT_SIZES: [usize; 5] = [0, 100, 300, 1000, 3000];

/// [`DEFAULT_SIZES`] as far as a train split of `train` samples reaches, and the
/// sizes cut: a default that does not fit the dataset is narrowed, not refused (a
/// size the user asked for is checked by [`check_sizes`]).
#[must_use]
pub fn default_sizes_within(train: usize) -> (Vec<usize>, Vec<usize>) {
    DEFAULT_SIZES.iter().partition(|n| **n <= train)
}

/// The sizes a sweep runs, ascending, each once: those asked for (`--samples`), or
/// the [`DEFAULT_SIZES`] the train split holds with a line that names those left out.
///
/// # Errors
/// As [`check_requested`] and [`check_sizes`].
pub fn sizes_to_run(
    asked: Option<&[usize]>,
    splits: &Splits,
) -> Result<(Vec<usize>, Option<String>), ExperimentError> {
    let (mut sizes, left_out) = match asked {
        Some(asked) => {
            check_requested(asked)?;
            (asked.to_vec(), None)
        }
        None => {
            let (kept, cut) = default_sizes_within(splits.train.len());
            let line = (!cut.is_empty()).then(|| {
                format!(
                    "--samples: {cut:?} left out, the train split holds {}",
                    splits.train.len()
                )
            });
            (kept, line)
        }
    };
    sizes.sort_unstable();
    sizes.dedup();
    check_sizes(&sizes, splits)?;
    Ok((sizes, left_out))
}

/// Checks a list of subset sizes against the dataset (after [`check_requested`]).
///
/// # Errors
/// A size beyond the train split, or a validation split of fewer than 2 samples.
pub fn check_sizes(sizes: &[usize], splits: &Splits) -> Result<(), ExperimentError> {
    if let Some(n) = sizes.iter().find(|n| **n > splits.train.len()) {
        return Err(ExperimentError::Invalid(format!(
            "--samples {n}: the dataset's train split holds {}",
            splits.train.len()
        )));
    }
    if splits.val.len() < 2 {
        return Err(ExperimentError::Invalid(format!(
            "the dataset's validation split holds {} samples: at least 2 are needed",
            splits.val.len()
        )));
    }
    Ok(())
}

/// The subsets for `n` training samples: train and validation drawn as above, the
/// whole test split.
#[must_use]
pub fn subset(splits: &Splits, n: usize, seed: u64) -> Splits {
    Splits {
        train: first_of_shuffle(&splits.train, n, seed),
        val: first_of_shuffle(&splits.val, val_size(n, splits), seed ^ 0x5a5a),
        test: splits.test.clone(),
    }
}

/// The first epoch whose validation R² reached `target` on every axis.
#[must_use]
pub fn epochs_to_target(history: &[EpochReport], target: f64) -> Option<usize> {
    history
        .iter()
        .find(|h| h.val_r2_min.is_some_and(|v| v >= target))
        .map(|h| h.epoch)
}

/// The starting model on the test split, untouched: the curve's n = 0.
///
/// # Errors
/// The backend is unavailable.
pub fn untouched_row(
    artifact: &ModelArtifact,
    splits: &Splits,
) -> Result<FinetuneRow, ExperimentError> {
    let h = &artifact.header;
    let device = softtouch_trainer::backend::device()?;
    let (test, _) = evaluate(&artifact.net, &h.config, &h.norm, &splits.test, &device)?;
    Ok(FinetuneRow {
        samples: 0,
        val_samples: 0,
        start: Start::FineTuned,
        test,
        epochs_run: 0,
        best_epoch: 0,
        epochs_to_target: None,
        seconds: 0.0,
    })
}

/// Trains one row on `subset` (no checkpoints): from `init` (fine-tuned) or from the
/// seed with `init`'s model settings (scratch).
///
/// # Errors
/// Training failed.
pub fn train_row(
    init: &InitFrom,
    start: Start,
    train: &TrainConfig,
    subset: &Splits,
    target: f64,
    observer: &mut dyn Observer,
) -> Result<FinetuneRow, ExperimentError> {
    let from = (start == Start::FineTuned).then_some(init);
    let trained = softtouch_trainer::train_from(&init.config, train, subset, None, from, observer)?;
    let Some(s) = trained.artifact.header.training else {
        return Err(ExperimentError::NoSummary);
    };
    Ok(FinetuneRow {
        samples: subset.train.len(),
        val_samples: subset.val.len(),
        start,
        test: s.test,
        epochs_run: s.epochs_run,
        best_epoch: s.best_epoch,
        epochs_to_target: epochs_to_target(&trained.history, target),
        seconds: s.seconds,
    })
}

/// The rows as CSV.
#[must_use]
pub fn rows_csv(rows: &[FinetuneRow]) -> String {
    let mut s = String::from(
        "samples,val_samples,start,epochs_run,best_epoch,epochs_to_target,seconds,r2_mean,r2_min",
    );
    push_axis_r2_header(&mut s);
    s.push('\n');
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{},{},{},{:.1},{},{}",
            r.samples,
            r.val_samples,
            r.start.name(),
            r.epochs_run,
            r.best_epoch,
            r.epochs_to_target.map_or(String::new(), |e| e.to_string()),
            r.seconds,
            csv_opt(r.test.r2_mean, |v| format!("{v:.6}")),
            csv_opt(r.test.r2_min(), |v| format!("{v:.6}")),
        ));
        push_axis_r2(&mut s, &r.test);
        s.push('\n');
    }
    s
}

/// Plots test R² (mean and worst axis) against log10 of the training samples, for
/// both starts. The untouched model (n = 0) cannot sit on a log axis: its figures
/// go in the title. R² below `floor` is drawn at `floor` so that one very negative
/// value does not flatten the rest (the CSV holds the true values).
///
/// # Errors
/// The plot cannot be drawn or written.
pub fn plot(png: &Path, rows: &[FinetuneRow], floor: f64) -> Result<(), ExperimentError> {
    let series_of = |start: Start, worst: bool| Series {
        label: format!(
            "{}: test R² {}",
            start.name(),
            if worst { "worst axis" } else { "mean" }
        ),
        points: rows
            .iter()
            .filter(|r| r.start == start && r.samples > 0)
            .map(|r| {
                let v = if worst {
                    r.test.r2_min()
                } else {
                    r.test.r2_mean
                };
                ((r.samples as f64).log10(), v.unwrap_or(f64::NAN).max(floor))
            })
            .collect(),
        style: SeriesStyle::LinePoints,
    };
    let series: Vec<Series> = [
        series_of(Start::FineTuned, false),
        series_of(Start::FineTuned, true),
        series_of(Start::Scratch, false),
        series_of(Start::Scratch, true),
    ]
    .into_iter()
    .filter(|s| !s.points.is_empty())
    .collect();
    let title = match rows.iter().find(|r| r.samples == 0) {
        Some(r) => format!(
            "Fine-tuning on water: with no water data, R² mean {} worst {}",
            fmt_opt(r.test.r2_mean, |v| format!("{v:.3}")),
            fmt_opt(r.test.r2_min(), |v| format!("{v:.3}"))
        ),
        None => "Fine-tuning: test R² against training samples".to_owned(),
    };
    xy_chart(
        png,
        &XyChart {
            title: &title,
            x_label: "log10 training samples",
            y_label: &format!("test R² (floored at {floor})"),
            series: &series,
        },
        (960, 580),
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use softtouch_trainer::Example;

    fn ex(i: usize) -> Example {
        Example {
            image: vec![0.0; 4],
            label: [i as f32; 6],
        }
    }

    fn splits(train: usize, val: usize) -> Splits {
        Splits {
            train: (0..train).map(ex).collect(),
            val: (0..val).map(ex).collect(),
            test: (0..3).map(ex).collect(),
        }
    }

    #[test]
    fn the_default_sizes_narrow_to_the_train_split() {
        assert_eq!(
            super::default_sizes_within(210),
            (vec![0, 100], vec![300, 1000, 3000])
        );
        assert_eq!(
            super::default_sizes_within(3000),
            (super::DEFAULT_SIZES.to_vec(), vec![])
        );
        assert_eq!(
            super::default_sizes_within(0),
            (vec![0], vec![100, 300, 1000, 3000])
        );
        // Without --samples: narrowed and said; asked for: sorted, once each, checked.
        let small = splits(210, 30);
        assert_eq!(
            sizes_to_run(None, &small).ok(),
            Some((
                vec![0, 100],
                Some("--samples: [300, 1000, 3000] left out, the train split holds 210".into())
            ))
        );
        assert_eq!(
            sizes_to_run(Some(&[100, 0, 100]), &small).ok(),
            Some((vec![0, 100], None))
        );
        assert!(sizes_to_run(Some(&[0, 300]), &small).is_err());
        assert!(sizes_to_run(Some(&[1]), &small).is_err());
        assert!(sizes_to_run(Some(&[]), &small).is_err());
        assert!(
            sizes_to_run(None, &splits(210, 1)).is_err(),
            "validation of 1"
        );
    }

    #[test]
    fn subsets_are_nested_and_validation_follows_the_ratio() {
        let s = splits(700, 100);
        let small = subset(&s, 100, 7);
        let large = subset(&s, 300, 7);
        assert_eq!(small.train[..], large.train[..100]);
        assert_eq!((small.val.len(), large.val.len()), (15, 43));
        assert_eq!(val_size(0, &s), 2, "never fewer than two");
        assert_eq!(val_size(700, &s), 100);
        let other_seed = subset(&s, 100, 8);
        assert_ne!(small.train, other_seed.train);
    }

    #[test]
    fn sizes_beyond_the_split_or_of_one_are_refused() {
        let s = splits(10, 4);
        let check = |sizes: &[usize], s: &Splits| {
            check_requested(sizes).and_then(|()| check_sizes(sizes, s))
        };
        assert!(check(&[0, 2, 10], &s).is_ok());
        for bad in [&[][..], &[11][..], &[1][..]] {
            let e = check(bad, &s).expect_err("refused");
            assert!(e.to_string().contains("--samples"), "{e}");
        }
        assert!(check(&[2], &splits(10, 1)).is_err());
    }

    #[test]
    fn epochs_to_target_is_the_first_epoch_at_or_over_it() {
        let report = |epoch, min| EpochReport {
            epoch,
            learning_rate: 1e-3,
            train_loss: 1.0,
            train_recon: None,
            train_pred: None,
            train_kl: None,
            val_r2_mean: min,
            val_r2_min: min,
            val_image_mse: None,
            val_score: 0.0,
            best: false,
            seconds: 1.0,
            train_images_per_s: 1.0,
        };
        let h = [
            report(1, Some(0.5)),
            report(2, None),
            report(3, Some(0.98)),
            report(4, Some(0.99)),
        ];
        assert_eq!(epochs_to_target(&h, 0.98), Some(3));
        assert_eq!(epochs_to_target(&h, 0.995), None);
        assert_eq!(epochs_to_target(&[], 0.5), None);
    }
}
