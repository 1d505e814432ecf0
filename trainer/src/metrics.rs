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

/// R² per axis of `predictions` against `targets` (same length). Empty sets give
/// R² = 0 on every axis, flagged constant.
pub fn r2_per_axis(predictions: &[WrenchLabel], targets: &[WrenchLabel]) -> [AxisR2; 6] {
    let n = predictions.len().min(targets.len());
    std::array::from_fn(|axis| {
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
    })
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
/// 3..6 for torques), with `edges` the upper edges of the ranges.
pub fn error_by_range(
    predictions: &[WrenchLabel],
    targets: &[WrenchLabel],
    axes: std::ops::Range<usize>,
    edges: &[f64],
) -> Vec<RangeError> {
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
            if let Some(bin) = bins.iter_mut().find(|b| magnitude < b.1) {
                bin.2.push(p - t);
            }
        }
    }
    bins.into_iter()
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
        .collect()
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
}

impl Metrics {
    /// Computes the wrench metrics (when `predictions` is given) and carries the
    /// image MSE.
    pub fn compute(
        predictions: Option<&[WrenchLabel]>,
        targets: &[WrenchLabel],
        image_mse: Option<f64>,
    ) -> Self {
        let Some(predictions) = predictions else {
            return Self {
                samples: targets.len(),
                r2: None,
                r2_mean: None,
                image_mse,
                force_error_by_range: Vec::new(),
                torque_error_by_range: Vec::new(),
                rmse: None,
            };
        };
        let r2 = r2_per_axis(predictions, targets);
        let r2_mean = r2.iter().map(|a| a.r2).sum::<f64>() / 6.0;
        let n = predictions.len().min(targets.len()).max(1) as f64;
        let rmse = std::array::from_fn(|axis| {
            (predictions
                .iter()
                .zip(targets)
                .map(|(p, t)| (f64::from(p[axis]) - f64::from(t[axis])).powi(2))
                .sum::<f64>()
                / n)
                .sqrt()
        });
        Self {
            samples: targets.len(),
            r2: Some(r2),
            r2_mean: Some(r2_mean),
            image_mse,
            force_error_by_range: error_by_range(predictions, targets, 0..3, &FORCE_BIN_EDGES_N),
            torque_error_by_range: error_by_range(
                predictions,
                targets,
                3..6,
                &TORQUE_BIN_EDGES_NMM,
            ),
            rmse: Some(rmse),
        }
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
                let _ = writeln!(s, "{title} error std by |{title}| range:");
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
        let r = r2_per_axis(&t, &t);
        assert!(
            r.iter()
                .all(|a| (a.r2 - 1.0).abs() < 1e-12 && !a.constant_target)
        );
        let mean = labels(&[[2.0; 6]; 3]);
        let r = r2_per_axis(&mean, &t);
        assert!(r.iter().all(|a| a.r2.abs() < 1e-12));
    }

    #[test]
    fn argument_order_matters_and_is_prediction_then_target() {
        // Target varies, prediction nearly constant: R² ≈ 0 (taken about the target's
        // mean). Swapping the arguments, as the reference code does, would give a
        // hugely negative value instead.
        let t = labels(&[[0.0; 6], [10.0; 6]]);
        let p = labels(&[[4.9; 6], [5.1; 6]]);
        let r = r2_per_axis(&p, &t);
        assert!((r[0].r2 - (1.0 - (4.9f64.powi(2) * 2.0) / 50.0)).abs() < 1e-4);
        let swapped = r2_per_axis(&t, &p);
        assert!(swapped[0].r2 < -100.0);
    }

    #[test]
    fn constant_empty_and_infinite_cases_stay_finite() {
        let t = labels(&[[5.0; 6]; 4]);
        let r = r2_per_axis(&t, &t);
        assert!(r.iter().all(|a| a.constant_target && a.r2 == 1.0));
        let off = labels(&[[6.0; 6]; 4]);
        let r = r2_per_axis(&off, &t);
        assert!(r.iter().all(|a| a.constant_target && a.r2 == 0.0));
        let r = r2_per_axis(&[], &[]);
        assert!(r.iter().all(|a| a.r2.is_finite()));
        let t = labels(&[[0.0; 6], [1.0; 6]]);
        let inf = labels(&[[f32::INFINITY; 6], [0.0; 6]]);
        assert!(r2_per_axis(&inf, &t).iter().all(|a| a.r2.is_finite()));
        let m = Metrics::compute(Some(&[]), &[], Some(0.0));
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
        let force = error_by_range(&p, &t, 0..3, &FORCE_BIN_EDGES_N);
        assert_eq!(force.len(), 6);
        assert_eq!(force[0].count, 3, "1.0, 0.5, 1.5");
        assert_eq!(force[1].count, 2, "|−3|, 3.5");
        assert_eq!(force[5].count, 1, "11 N overflows");
        assert!(force[5].upper.is_none());
        assert!(force.iter().all(|b| b.error_std.is_finite()));
        let torque = error_by_range(&p, &t, 3..6, &TORQUE_BIN_EDGES_NMM);
        assert_eq!(torque[0].count, 4);
        assert_eq!(torque[1].count, 1);
    }
}
