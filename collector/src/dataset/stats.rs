//! Dataset statistics: counts per split, rod and medium; per-axis min / max / mean /
//! standard deviation (force in N, torque in N·mm); histograms of the six axes as a
//! PNG (the paper's Fig. S1e) and as a text sparkline.

use super::{DatasetError, DatasetInfo, Split, get};
use crate::plot::{self, HistogramPanel};
use crate::store::Store;
use futures_util::TryStreamExt as _;
use softtouch_schemas::wrench::AXES;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// Bins of each histogram in the PNG.
pub const PNG_BINS: usize = 40;
/// Bins of each text sparkline.
pub const TEXT_BINS: usize = 16;

/// Summary of one axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisStats {
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (n − 1; 0 for a single sample).
    pub std: f64,
}

/// Statistics of a dataset.
#[derive(Debug, Clone)]
pub struct Stats {
    /// The dataset.
    pub info: DatasetInfo,
    /// Samples per split (train, val, test).
    pub per_split: [u64; 3],
    /// Samples per rod and split.
    pub per_rod: BTreeMap<String, [u64; 3]>,
    /// Samples per medium and split.
    pub per_medium: BTreeMap<String, [u64; 3]>,
    /// Per axis (Fx, Fy, Fz in N; Tx, Ty, Tz in N·mm).
    pub axes: [AxisStats; 6],
    /// The values per axis, in dataset order (for histograms).
    pub values: [Vec<f64>; 6],
}

/// Compute the statistics of a dataset (one streaming pass over its members).
pub async fn compute(store: &Store, name: &str) -> Result<Stats, DatasetError> {
    let info = get(store, name).await?;
    let mut per_split = [0u64; 3];
    let mut per_rod: BTreeMap<String, [u64; 3]> = BTreeMap::new();
    let mut per_medium: BTreeMap<String, [u64; 3]> = BTreeMap::new();
    let capacity = usize::try_from(info.sample_count).unwrap_or(0);
    let mut values: [Vec<f64>; 6] = std::array::from_fn(|_| Vec::with_capacity(capacity));
    let mut rows = store.dataset_labels(info.dataset_id);
    while let Some(r) = rows.try_next().await? {
        let split: Split = r
            .split
            .parse()
            .map_err(|e: String| DatasetError::Invalid(e))?;
        let k = split.ordinal();
        per_split[k] += 1;
        per_rod.entry(r.rod).or_default()[k] += 1;
        per_medium.entry(r.medium).or_default()[k] += 1;
        let row = [
            r.wrench.fx_n,
            r.wrench.fy_n,
            r.wrench.fz_n,
            r.wrench.tx_nm * 1000.0,
            r.wrench.ty_nm * 1000.0,
            r.wrench.tz_nm * 1000.0,
        ];
        for (v, x) in values.iter_mut().zip(row) {
            v.push(x);
        }
    }
    let axes = std::array::from_fn(|i| summarise(&values[i]));
    Ok(Stats {
        info,
        per_split,
        per_rod,
        per_medium,
        axes,
        values,
    })
}

fn summarise(values: &[f64]) -> AxisStats {
    // Welford's running mean and variance.
    let (mut n, mut mean, mut m2) = (0.0f64, 0.0f64, 0.0f64);
    let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
    for &v in values {
        n += 1.0;
        let d = v - mean;
        mean += d / n;
        m2 += d * (v - mean);
        min = min.min(v);
        max = max.max(v);
    }
    if values.is_empty() {
        return AxisStats {
            min: f64::NAN,
            max: f64::NAN,
            mean: f64::NAN,
            std: f64::NAN,
        };
    }
    AxisStats {
        min,
        max,
        mean,
        std: if n > 1.0 {
            (m2 / (n - 1.0)).sqrt()
        } else {
            0.0
        },
    }
}

/// The PNG file name for a dataset's histograms.
#[must_use]
pub fn histogram_file_name(name: &str) -> String {
    format!("{name}-histograms.png")
}

/// Draw the six histograms (forces on top, torques below) into `path`.
pub fn write_histograms(stats: &Stats, path: &Path) -> Result<(), DatasetError> {
    let panels: Vec<HistogramPanel<'_>> = AXES
        .iter()
        .zip(&stats.values)
        .map(|(axis, values)| HistogramPanel {
            title: axis.name.to_owned(),
            x_label: format!(
                "{} ({})",
                if axis.report_unit == "N" {
                    "force"
                } else {
                    "torque"
                },
                axis.report_unit
            ),
            values,
            bins: PNG_BINS,
        })
        .collect();
    let title = format!(
        "{}: {} samples (train {}, val {}, test {})",
        stats.info.name,
        stats.info.sample_count,
        stats.per_split[0],
        stats.per_split[1],
        stats.per_split[2]
    );
    plot::histogram_grid(path, Some(&title), &panels, 3, (1500, 860))?;
    Ok(())
}

/// A text sparkline of a histogram.
#[must_use]
pub fn sparkline(values: &[f64], bins: usize) -> String {
    const BARS: [char; 8] = ['▁', '▂', '▃', '▄', '▅', '▆', '▇', '█'];
    let binned = plot::bin(values, bins);
    let top = binned.iter().map(|b| b.2).max().unwrap_or(0);
    binned
        .iter()
        .map(|&(_, _, c)| {
            if c == 0 || top == 0 {
                ' '
            } else {
                let i = ((c as f64 / top as f64) * 7.0).round() as usize;
                BARS[i.min(7)]
            }
        })
        .collect()
}

/// The statistics as a compact text table.
#[must_use]
pub fn render(stats: &Stats) -> String {
    let info = &stats.info;
    let d = &info.definition;
    let runs: Vec<String> = d.runs.iter().map(ToString::to_string).collect();
    let mut s = String::new();
    let _ = writeln!(
        s,
        "dataset {}: {} samples from run(s) {}; split {} seed {}; created {}",
        info.name,
        info.sample_count,
        runs.join(","),
        d.split,
        d.seed,
        info.created_at
    );
    let _ = writeln!(
        s,
        "\n{:<24} {:>8} {:>8} {:>8} {:>8}",
        "", "train", "val", "test", "total"
    );
    let mut count_row = |label: String, c: &[u64; 3]| {
        let _ = writeln!(
            s,
            "{:<24} {:>8} {:>8} {:>8} {:>8}",
            label,
            c[0],
            c[1],
            c[2],
            c.iter().sum::<u64>()
        );
    };
    count_row("all".into(), &stats.per_split);
    for (rod, c) in &stats.per_rod {
        count_row(format!("rod {rod}"), c);
    }
    for (medium, c) in &stats.per_medium {
        count_row(format!("medium {medium}"), c);
    }
    let _ = writeln!(
        s,
        "\n{:<4} {:<5} {:>10} {:>10} {:>10} {:>10}  histogram (min → max)",
        "axis", "unit", "min", "max", "mean", "std"
    );
    for ((axis, a), values) in AXES.iter().zip(&stats.axes).zip(&stats.values) {
        let _ = writeln!(
            s,
            "{:<4} {:<5} {:>10.3} {:>10.3} {:>10.3} {:>10.3}  |{}|",
            axis.name,
            axis.report_unit,
            a.min,
            a.max,
            a.mean,
            a.std,
            sparkline(values, TEXT_BINS)
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summaries_match_the_textbook() {
        let a = summarise(&[2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0]);
        assert!((a.mean - 5.0).abs() < 1e-12);
        assert!((a.std - (32.0f64 / 7.0).sqrt()).abs() < 1e-12);
        assert!((a.min - 2.0).abs() < 1e-12 && (a.max - 9.0).abs() < 1e-12);
        assert!(summarise(&[3.0]).std.abs() < 1e-12);
        assert!(summarise(&[]).mean.is_nan());
    }

    #[test]
    fn sparklines_have_one_character_per_bin() {
        let line = sparkline(&[0.0, 1.0, 1.0, 2.0], 4);
        assert_eq!(line.chars().count(), 4);
        assert!(line.contains('█'));
    }
}
