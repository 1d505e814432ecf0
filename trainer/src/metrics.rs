//! The paper's metrics: R² per axis and averaged (the paper's "accuracy"), image MSE,
//! and the standard deviation of the error per force range [0,2) … [8,10) N and per
//! torque range [0,120) … [480,600) N·mm.
//!
//! R² is `1 − SS_res / SS_tot` with `SS_tot` taken about the **target's** mean. The
//! reference code passes (label, prediction) to torchmetrics' `r2score(preds, target)`,
//! which computes SS_tot about the prediction's mean instead; we do not copy that.
//! When a target axis is constant R² is undefined; we follow scikit-learn and report
//! 1 for a perfect prediction and 0 otherwise, so the value stays finite, and flag
//! the axis as constant. "Constant" and "perfect" follow the one rule the label
//! standardisation uses too, [`is_constant_axis`]: the target's standard deviation
//! (resp. the root-mean-square error) is at most `max(1e-6, 1e-6 · |mean|)`.
//!
//! JSON has no NaN or infinity (serde_json writes them as `null`): every float of the
//! metrics reads `null` back as NaN, so a non-finite metric never makes a stored model
//! unloadable.

use serde::{Deserialize, Serialize};

use crate::TrainError;
use crate::labels::{AXES, WrenchLabel, is_constant_axis};

/// Reads `null` (how serde_json writes NaN and infinity) back as NaN.
pub(crate) mod null_as_nan {
    use serde::{Deserialize, Deserializer};

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    }
}

/// [`null_as_nan`] for an optional array of six.
pub(crate) mod null_as_nan_6 {
    use serde::{Deserialize, Deserializer};

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Option<[f64; 6]>, D::Error> {
        Ok(Option::<[Option<f64>; 6]>::deserialize(d)?.map(|a| a.map(|v| v.unwrap_or(f64::NAN))))
    }
}

/// Upper edges of the force ranges, N (the paper's table; values ≥ 10 N land in an
/// overflow bin).
pub const FORCE_BIN_EDGES_N: [f64; 5] = [2.0, 4.0, 6.0, 8.0, 10.0];
/// Upper edges of the torque ranges, N·mm.
pub const TORQUE_BIN_EDGES_NMM: [f64; 5] = [120.0, 240.0, 360.0, 480.0, 600.0];

/// R² of one axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AxisR2 {
    #[serde(deserialize_with = "null_as_nan::deserialize")]
    pub r2: f64,
    /// The target was constant on this set: R² is the scikit-learn convention.
    pub constant_target: bool,
}

/// Predictions and targets must pair one to one: anything else is an error naming
/// both counts (a silent truncation would score a different set).
fn check_pairs(predictions: &[WrenchLabel], targets: &[WrenchLabel]) -> Result<(), TrainError> {
    if predictions.len() == targets.len() {
        return Ok(());
    }
    Err(TrainError::Input(format!(
        "{} predictions for {} targets: expected one per target",
        predictions.len(),
        targets.len()
    )))
}

/// R² per axis of `predictions` against `targets` (one each). Empty sets give R² = 0
/// on every axis, flagged constant. An axis whose residuals are not finite (an
/// infinite or NaN prediction, or a target that is not finite) is infinitely wrong:
/// `f64::MIN`, finite and below every real R².
///
/// # Errors
/// The two lists differ in length.
pub fn r2_per_axis(
    predictions: &[WrenchLabel],
    targets: &[WrenchLabel],
) -> Result<[AxisR2; 6], TrainError> {
    check_pairs(predictions, targets)?;
    let n = targets.len();
    Ok(std::array::from_fn(|axis| {
        if n == 0 {
            return AxisR2 {
                r2: 0.0,
                constant_target: true,
            };
        }
        let mean = targets[..n].iter().map(|t| f64::from(t[axis])).sum::<f64>() / n as f64;
        let (mut ss_res, mut ss_tot) = (0.0f64, 0.0f64);
        for (p, t) in predictions[..n].iter().zip(&targets[..n]) {
            let (p, t) = (f64::from(p[axis]), f64::from(t[axis]));
            ss_res += (t - p).powi(2);
            ss_tot += (t - mean).powi(2);
        }
        let n = n as f64;
        if !mean.is_finite() {
            // A target that is not finite: no R² can be taken about its mean.
            return AxisR2 {
                r2: f64::MIN,
                constant_target: false,
            };
        }
        if is_constant_axis((ss_tot / n).sqrt(), mean) {
            AxisR2 {
                r2: if is_constant_axis((ss_res / n).sqrt(), mean) {
                    1.0
                } else {
                    0.0
                },
                constant_target: true,
            }
        } else if ss_res.is_finite() {
            AxisR2 {
                r2: 1.0 - ss_res / ss_tot,
                constant_target: false,
            }
        } else {
            // An infinite prediction is infinitely wrong; keep it finite and bad.
            AxisR2 {
                r2: f64::MIN,
                constant_target: false,
            }
        }
    }))
}

/// The mean of six R². Where their sum overflows (two or more axes at `f64::MIN`) it
/// is taken as a sum of sixths, so six such axes give `f64::MIN` rather than −∞
/// (which JSON would store as null).
#[must_use]
pub fn mean_r2(r2: &[AxisR2; 6]) -> f64 {
    let sum: f64 = r2.iter().map(|a| a.r2).sum();
    if sum.is_finite() {
        sum / 6.0
    } else {
        r2.iter().map(|a| a.r2 / 6.0).sum()
    }
}

/// Standard deviation of the error in one label range.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RangeError {
    /// Range [lower, upper) of |target|; no `upper` for the overflow bin.
    #[serde(deserialize_with = "null_as_nan::deserialize")]
    pub lower: f64,
    pub upper: Option<f64>,
    /// Labels in the range (pooled over the three axes).
    pub count: usize,
    /// Standard deviation of prediction − target; 0 for fewer than two values.
    #[serde(deserialize_with = "null_as_nan::deserialize")]
    pub error_std: f64,
    #[serde(deserialize_with = "null_as_nan::deserialize")]
    pub error_mean: f64,
}

/// The error spread per range of |target|, pooled over axes `axes` (0..3 for forces,
/// 3..6 for torques), with `edges` the upper edges of the ranges, and how many labels
/// fell in no range because the target is not finite (so the ranges and that count
/// add up to the labels). A finite target with a prediction that is not finite stays
/// in its range, whose spread then is not finite either (stored as null, read as NaN).
pub fn error_by_range(
    predictions: &[WrenchLabel],
    targets: &[WrenchLabel],
    axes: std::ops::Range<usize>,
    edges: &[f64],
) -> (Vec<RangeError>, usize) {
    let mut not_finite = 0;
    let mut bins: Vec<(f64, f64, Vec<f64>)> = Vec::with_capacity(edges.len() + 1);
    let mut lower = 0.0;
    for &upper in edges {
        bins.push((lower, upper, Vec::new()));
        lower = upper;
    }
    bins.push((lower, f64::INFINITY, Vec::new()));
    for (p, t) in predictions.iter().zip(targets) {
        for axis in axes.clone() {
            let (p, t) = (f64::from(p[axis]), f64::from(t[axis]));
            let magnitude = t.abs();
            match bins.iter_mut().find(|b| magnitude < b.1) {
                Some(bin) => bin.2.push(p - t),
                // NaN compares below nothing; ∞ is below no edge, the overflow's too.
                None => not_finite += 1,
            }
        }
    }
    let bins = bins
        .into_iter()
        .map(|(lower, upper, errors)| {
            let count = errors.len();
            let mean = if count > 0 {
                errors.iter().sum::<f64>() / count as f64
            } else {
                0.0
            };
            let std = if count > 1 {
                (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (count - 1) as f64).sqrt()
            } else {
                0.0
            };
            RangeError {
                lower,
                upper: upper.is_finite().then_some(upper),
                count,
                error_std: std,
                error_mean: mean,
            }
        })
        .collect();
    (bins, not_finite)
}

/// Everything `softtouch eval` reports about a model on one split.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    pub samples: usize,
    /// Absent for the VAE, which predicts no wrench.
    pub r2: Option<[AxisR2; 6]>,
    pub r2_mean: Option<f64>,
    /// Mean squared pixel error of the image reconstructed from the latent mean;
    /// absent for the ConvNet, which has no decoder.
    pub image_mse: Option<f64>,
    pub force_error_by_range: Vec<RangeError>,
    pub torque_error_by_range: Vec<RangeError>,
    /// Root-mean-square error per axis, in the axis' unit.
    #[serde(default, deserialize_with = "null_as_nan_6::deserialize")]
    pub rmse: Option<[f64; 6]>,
    /// Labels (target values, pooled over the six axes) that are not finite: they fall
    /// in no error range.
    #[serde(default)]
    pub targets_not_finite: usize,
}

impl Metrics {
    /// Computes the wrench metrics (when `predictions` is given) and carries the
    /// image MSE.
    ///
    /// # Errors
    /// Predictions and targets differ in number.
    pub fn compute(
        predictions: Option<&[WrenchLabel]>,
        targets: &[WrenchLabel],
        image_mse: Option<f64>,
    ) -> Result<Self, TrainError> {
        let Some(predictions) = predictions else {
            return Ok(Self {
                samples: targets.len(),
                r2: None,
                r2_mean: None,
                image_mse,
                force_error_by_range: Vec::new(),
                torque_error_by_range: Vec::new(),
                rmse: None,
                targets_not_finite: 0,
            });
        };
        let r2 = r2_per_axis(predictions, targets)?;
        let r2_mean = mean_r2(&r2);
        let n = targets.len().max(1) as f64;
        let rmse = std::array::from_fn(|axis| {
            (predictions
                .iter()
                .zip(targets)
                .map(|(p, t)| (f64::from(p[axis]) - f64::from(t[axis])).powi(2))
                .sum::<f64>()
                / n)
                .sqrt()
        });
        let (force, force_not_finite) =
            error_by_range(predictions, targets, 0..3, &FORCE_BIN_EDGES_N);
        let (torque, torque_not_finite) =
            error_by_range(predictions, targets, 3..6, &TORQUE_BIN_EDGES_NMM);
        Ok(Self {
            samples: targets.len(),
            r2: Some(r2),
            r2_mean: Some(r2_mean),
            image_mse,
            force_error_by_range: force,
            torque_error_by_range: torque,
            rmse: Some(rmse),
            targets_not_finite: force_not_finite + torque_not_finite,
        })
    }

    /// The lowest per-axis R², if there is one.
    pub fn r2_min(&self) -> Option<f64> {
        self.r2
            .map(|r| r.iter().map(|a| a.r2).fold(f64::INFINITY, f64::min))
    }

    /// A human-readable report (what `softtouch eval` prints).
    pub fn render(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::new();
        let _ = writeln!(s, "samples: {}", self.samples);
        if let (Some(r2), Some(mean), Some(rmse)) = (self.r2, self.r2_mean, self.rmse) {
            let _ = writeln!(s, "axis   R²        RMSE");
            for (i, a) in r2.iter().enumerate() {
                let unit = crate::labels::UNITS[i];
                let flag = if a.constant_target {
                    "  (constant target)"
                } else {
                    ""
                };
                let _ = writeln!(
                    s,
                    "{:<5}  {:.5}  {:>8.4} {unit}{flag}",
                    AXES[i], a.r2, rmse[i]
                );
            }
            let _ = writeln!(s, "mean   {mean:.5}");
            for (title, unit, bins) in [
                ("force", "N", &self.force_error_by_range),
                ("torque", "N·mm", &self.torque_error_by_range),
            ] {
                // Each sample gives one value per axis: n counts axis values, pooled
                // over the three axes, not samples.
                let _ = writeln!(
                    s,
                    "{title} error std by |{title}| range (n: axis values, {} samples × 3 axes pooled):",
                    self.samples
                );
                for b in bins.iter() {
                    let range = match b.upper {
                        Some(upper) => format!("[{}, {upper})", b.lower),
                        None => format!("≥ {}", b.lower),
                    };
                    let _ = writeln!(
                        s,
                        "  {range:<12} {unit:<5} n={:<6} std={:.4} mean={:+.4}",
                        b.count, b.error_std, b.error_mean
                    );
                }
            }
        }
        if self.targets_not_finite > 0 {
            let _ = writeln!(
                s,
                "{} label values are not finite: they are in no range above",
                self.targets_not_finite
            );
        }
        if let Some(mse) = self.image_mse {
            let _ = writeln!(s, "image MSE: {mse:.3e}");
        }
        s
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "the compared values are exact by construction"
)]
mod tests {
    use super::*;

    fn labels(v: &[[f32; 6]]) -> Vec<WrenchLabel> {
        v.to_vec()
    }

    #[test]
    fn perfect_and_mean_predictions() {
        let t = labels(&[[1.0; 6], [2.0; 6], [3.0; 6]]);
        let r = r2_per_axis(&t, &t).expect("pairs");
        assert!(
            r.iter()
                .all(|a| (a.r2 - 1.0).abs() < 1e-12 && !a.constant_target)
        );
        let mean = labels(&[[2.0; 6]; 3]);
        let r = r2_per_axis(&mean, &t).expect("pairs");
        assert!(r.iter().all(|a| a.r2.abs() < 1e-12));
    }

    #[test]
    fn argument_order_matters_and_is_prediction_then_target() {
        // Target varies, prediction nearly constant: R² ≈ 0 (taken about the target's
        // mean). Swapping the arguments, as the reference code does, would give a
        // hugely negative value instead.
        let t = labels(&[[0.0; 6], [10.0; 6]]);
        let p = labels(&[[4.9; 6], [5.1; 6]]);
        let r = r2_per_axis(&p, &t).expect("pairs");
        assert!((r[0].r2 - (1.0 - (4.9f64.powi(2) * 2.0) / 50.0)).abs() < 1e-4);
        let swapped = r2_per_axis(&t, &p).expect("pairs");
        assert!(swapped[0].r2 < -100.0);
    }

    #[test]
    fn constant_empty_and_infinite_cases_stay_finite() {
        let t = labels(&[[5.0; 6]; 4]);
        let r = r2_per_axis(&t, &t).expect("pairs");
        assert!(r.iter().all(|a| a.constant_target && a.r2 == 1.0));
        let off = labels(&[[6.0; 6]; 4]);
        let r = r2_per_axis(&off, &t).expect("pairs");
        assert!(r.iter().all(|a| a.constant_target && a.r2 == 0.0));
        let r = r2_per_axis(&[], &[]).expect("pairs");
        assert!(r.iter().all(|a| a.r2.is_finite()));
        let t = labels(&[[0.0; 6], [1.0; 6]]);
        let inf = labels(&[[f32::INFINITY; 6], [0.0; 6]]);
        assert!(
            r2_per_axis(&inf, &t)
                .expect("pairs")
                .iter()
                .all(|a| a.r2.is_finite())
        );
        let m = Metrics::compute(Some(&[]), &[], Some(0.0)).expect("pairs");
        assert!(m.r2_mean.is_some_and(f64::is_finite));
        assert!(m.render().contains("samples: 0"));
    }

    #[test]
    fn range_bins_pool_axes_by_magnitude() {
        let t = labels(&[
            [1.0, -3.0, 0.5, 100.0, -130.0, 700.0],
            [1.5, 3.5, 11.0, 10.0, 0.0, 5.0],
        ]);
        let p = labels(&[
            [1.1, -3.2, 0.5, 101.0, -128.0, 690.0],
            [1.3, 3.7, 12.0, 10.0, 0.0, 5.0],
        ]);
        let (force, skipped) = error_by_range(&p, &t, 0..3, &FORCE_BIN_EDGES_N);
        assert_eq!(skipped, 0);
        assert_eq!(force.len(), 6);
        assert_eq!(force[0].count, 3, "1.0, 0.5, 1.5");
        assert_eq!(force[1].count, 2, "|−3|, 3.5");
        assert_eq!(force[5].count, 1, "11 N overflows");
        assert!(force[5].upper.is_none());
        assert!(force.iter().all(|b| b.error_std.is_finite()));
        let (torque, _) = error_by_range(&p, &t, 3..6, &TORQUE_BIN_EDGES_NMM);
        assert_eq!(torque[0].count, 4);
        assert_eq!(torque[1].count, 1);
    }

    #[test]
    fn infinite_predictions_on_any_number_of_axes_keep_the_mean_finite() {
        let t = labels(&[[0.0; 6], [1.0; 6], [2.0; 6]]);
        for bad_axes in 0..=6 {
            let mut p = t.clone();
            for (axis, v) in p[1].iter_mut().enumerate().take(bad_axes) {
                *v = if axis % 2 == 0 {
                    f32::INFINITY
                } else {
                    f32::NAN
                };
            }
            let m = Metrics::compute(Some(&p), &t, None).expect("pairs");
            let mean = m.r2_mean.expect("a mean");
            assert!(mean.is_finite(), "{bad_axes} axes: {mean}");
            if bad_axes == 0 {
                assert_eq!(mean, 1.0);
            } else {
                // Below every real R², and the worst axis says which.
                assert!(
                    mean < -1e300 && m.r2_min() == Some(f64::MIN),
                    "{bad_axes}: {mean}"
                );
            }
            // And it survives JSON (no null for a finite value; serde_json reads the
            // last bit of a double back only to its fast parser's precision).
            let back: Metrics = serde_json::from_str(&serde_json::to_string(&m).expect("json"))
                .expect("reads back");
            let read = back.r2_mean.expect("a mean");
            assert!(
                read.is_finite() && (read - mean).abs() <= 1e-15 * mean.abs(),
                "{read} vs {mean}"
            );
        }
        assert_eq!(
            mean_r2(
                &[AxisR2 {
                    r2: f64::MIN,
                    constant_target: false
                }; 6]
            ),
            f64::MIN
        );
    }

    #[test]
    fn targets_that_are_not_finite_are_counted_not_lost() {
        let t = labels(&[
            [1.0, f32::NAN, 0.5, 10.0, f32::INFINITY, 5.0],
            [1.5, 3.5, f32::NEG_INFINITY, 10.0, 0.0, f32::NAN],
        ]);
        let p = labels(&[[1.0; 6], [1.0; 6]]);
        let m = Metrics::compute(Some(&p), &t, None).expect("pairs");
        assert_eq!(m.targets_not_finite, 4);
        let binned: usize = m
            .force_error_by_range
            .iter()
            .chain(&m.torque_error_by_range)
            .map(|b| b.count)
            .sum();
        assert_eq!(
            binned + m.targets_not_finite,
            2 * 6,
            "every label accounted for"
        );
        assert!(m.render().contains("4 label values are not finite"));
        // R² of an axis with a target that is not finite: infinitely wrong, finite.
        let r2 = m.r2.expect("r2");
        assert_eq!(r2[1].r2, f64::MIN);
        assert_eq!(r2[2].r2, f64::MIN);
        assert!(r2[0].r2.is_finite() && r2[0].r2 > f64::MIN);
        // An infinite prediction of a finite target stays in its range, not finite.
        let (bins, skipped) = error_by_range(
            &labels(&[[f32::INFINITY; 6], [0.0; 6]]),
            &labels(&[[1.0; 6], [1.0; 6]]),
            0..3,
            &FORCE_BIN_EDGES_N,
        );
        assert_eq!((skipped, bins[0].count), (0, 6));
        assert!(!bins[0].error_std.is_finite());
    }

    #[test]
    fn predictions_and_targets_must_pair_one_to_one() {
        let t = labels(&[[0.0; 6], [1.0; 6], [2.0; 6]]);
        for p in [&t[..2], &[][..]] {
            let Err(e) = r2_per_axis(p, &t) else {
                panic!("{} for 3 accepted", p.len());
            };
            assert!(
                e.to_string()
                    .contains(&format!("{} predictions for 3 targets", p.len())),
                "{e}"
            );
            assert!(Metrics::compute(Some(p), &t, None).is_err());
        }
        // No predictions at all (the VAE) is not a mismatch.
        assert!(Metrics::compute(None, &t, None).is_ok());
    }
}
