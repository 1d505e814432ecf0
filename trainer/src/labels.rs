//! Labels: the 6-axis wrench in the units the paper reports (force in N, torque in
//! N·mm) and their per-axis standardisation.
//!
//! The model learns standardised labels (zero mean, unit variance per axis, fitted on
//! the training split). The reference code instead divides the torque loss by 1000;
//! that balances forces against torques but not axes against each other, and on the
//! simulated finger Fz (0…3 N) and Tz (±17 N·mm) span a tenth of the other axes, so
//! they would weigh a hundredth as much in the loss. R² is per-axis and scale-free, so
//! standardising makes the loss weigh every axis the way the metric does.

use serde::{Deserialize, Serialize};
use softtouch_schemas::Wrench;

use crate::TrainError;

/// Axis names (`Fx` … `Tz`) and units (N, N·mm) in label order: the schemas' list.
pub use softtouch_schemas::wrench::{AXIS_NAMES as AXES, AXIS_UNITS as UNITS};

/// A wrench label: `[Fx, Fy, Fz]` in N then `[Tx, Ty, Tz]` in N·mm, sensor frame.
pub type WrenchLabel = [f32; 6];

/// The SI wrench (N, N·m) of a label: the inverse of [`label_from_si`].
pub fn wrench_from_label(label: &WrenchLabel) -> Wrench {
    Wrench {
        force_n: [label[0], label[1], label[2]].map(f64::from),
        torque_nm: [label[3], label[4], label[5]].map(|t| f64::from(t) * 1e-3),
    }
}

/// Builds a label from a stored wrench (torque in N·m).
pub fn label_from_si(force_n: [f64; 3], torque_nm: [f64; 3]) -> WrenchLabel {
    [
        force_n[0] as f32,
        force_n[1] as f32,
        force_n[2] as f32,
        (torque_nm[0] * 1e3) as f32,
        (torque_nm[1] * 1e3) as f32,
        (torque_nm[2] * 1e3) as f32,
    ]
}

/// An axis whose spread is at most this, in its label unit (N or N·mm), is constant:
/// far below the sensor's resolution (0.0125 N, 0.0625 N·mm).
pub const CONSTANT_AXIS_ABS: f64 = 1e-6;
/// ... or at most this fraction of its mean's magnitude: labels are `f32`, whose
/// rounding alone spreads a constant value by up to 6e-8 of it.
pub const CONSTANT_AXIS_REL: f64 = 1e-6;

/// The one rule for a constant axis, used by the label standardisation and by R²: its
/// standard deviation `std` (or root-mean-square error, for "a perfect prediction")
/// is at most `max(CONSTANT_AXIS_ABS, CONSTANT_AXIS_REL · |mean|)`. Not finite: not
/// constant.
#[must_use]
pub fn is_constant_axis(std: f64, mean: f64) -> bool {
    let bound = if mean.is_finite() {
        CONSTANT_AXIS_ABS.max(CONSTANT_AXIS_REL * mean.abs())
    } else {
        CONSTANT_AXIS_ABS
    };
    std <= bound
}

/// Per-axis standardisation; stored in every model artifact.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LabelNorm {
    pub mean: [f32; 6],
    /// Never zero: a constant axis gets 1, so it maps to 0 and back unchanged.
    pub std: [f32; 6],
}

impl LabelNorm {
    /// Fits mean and standard deviation per axis. Errors on an empty set or a
    /// non-finite label (naming its position).
    pub fn fit(labels: &[WrenchLabel]) -> Result<Self, TrainError> {
        if labels.is_empty() {
            return Err(TrainError::Input(
                "no training labels to fit the label normalisation on".into(),
            ));
        }
        if let Some(i) = labels.iter().position(|l| l.iter().any(|v| !v.is_finite())) {
            return Err(TrainError::Input(format!(
                "training label {i} is not finite: {:?}",
                labels[i]
            )));
        }
        let n = labels.len() as f64;
        let mut mean = [0.0f32; 6];
        let mut std = [1.0f32; 6];
        for axis in 0..6 {
            let m = labels.iter().map(|l| f64::from(l[axis])).sum::<f64>() / n;
            let var = labels
                .iter()
                .map(|l| (f64::from(l[axis]) - m).powi(2))
                .sum::<f64>()
                / n;
            mean[axis] = m as f32;
            let s = var.sqrt();
            // A constant axis: dividing by its float noise would blow it up.
            std[axis] = if is_constant_axis(s, m) {
                1.0
            } else {
                s as f32
            };
        }
        Ok(Self { mean, std })
    }

    pub fn normalise(&self, label: &WrenchLabel) -> WrenchLabel {
        std::array::from_fn(|i| (label[i] - self.mean[i]) / self.std[i])
    }

    pub fn denormalise(&self, z: &[f32]) -> WrenchLabel {
        std::array::from_fn(|i| z.get(i).copied().unwrap_or(0.0) * self.std[i] + self.mean[i])
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "the compared values are exact by construction"
)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_constant_axes() {
        let labels = vec![
            [1.0, 2.0, 0.5, 100.0, -50.0, 3.0],
            [3.0, -2.0, 0.5, -100.0, 50.0, 3.0],
        ];
        let norm = LabelNorm::fit(&labels).expect("fits");
        assert_eq!(norm.std[2], 1.0, "constant Fz");
        assert_eq!(norm.std[5], 1.0, "constant Tz");
        for l in &labels {
            let z = norm.normalise(l);
            assert!(z.iter().all(|v| v.is_finite()));
            let back = norm.denormalise(&z);
            for i in 0..6 {
                assert!((back[i] - l[i]).abs() < 1e-3, "{back:?} vs {l:?}");
            }
        }
        assert!((norm.normalise(&labels[0])[0] + 1.0).abs() < 1e-6);
    }

    #[test]
    fn empty_and_non_finite_labels_are_errors() {
        assert!(LabelNorm::fit(&[]).is_err());
        let err = LabelNorm::fit(&[[0.0; 6], [f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0]])
            .expect_err("NaN label");
        assert!(err.to_string().contains("label 1"), "{err}");
    }

    #[test]
    fn torque_is_converted_to_newton_millimetres() {
        let l = label_from_si([1.0, 2.0, 3.0], [0.1, -0.2, 0.0125]);
        assert_eq!(l, [1.0, 2.0, 3.0, 100.0, -200.0, 12.5]);
    }

    #[test]
    fn labels_convert_back_to_si() {
        let w = wrench_from_label(&[1.0, 2.0, 3.0, 100.0, -200.0, 12.5]);
        let expect = [1.0, 2.0, 3.0, 0.1, -0.2, 0.0125];
        for (got, want) in w.to_array().iter().zip(&expect) {
            assert!((got - want).abs() < 1e-9, "{w:?}");
        }
        let back = label_from_si(w.force_n, w.torque_nm);
        assert_eq!(back, [1.0, 2.0, 3.0, 100.0, -200.0, 12.5]);
    }

    #[test]
    fn axes_are_the_schemas_names_and_units() {
        assert_eq!(AXES, ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"]);
        assert_eq!(UNITS[3], "N·mm");
    }
}
