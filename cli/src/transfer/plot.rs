//! What `transfer` writes: its CSV, the cosines beside it, and `transfer.png` (the R²
//! table as bars).

use super::Scored;
use crate::Failure;
use anyhow::anyhow;
use softtouch_schemas::wrench::AXES;
use std::path::{Path, PathBuf};

/// Writes the CSV at `out`, the cosines beside it and the plot; the cosines' and the
/// plot's paths.
pub(super) fn write_files(
    out: &Path,
    csv: &str,
    cosines: &[f64],
    scored: &[Scored],
) -> Result<(PathBuf, PathBuf), Failure> {
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .map_err(|e| Failure::Runtime(anyhow!("cannot create {}: {e}", dir.display())))?;
    }
    std::fs::write(out, csv)
        .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", out.display())))?;
    // The cosine of every pair, for its distribution (the report's histogram).
    let stem = out
        .file_stem()
        .map_or_else(|| "transfer".into(), |s| s.to_string_lossy().into_owned());
    let cos_path = out.with_file_name(format!("{stem}-cosines.csv"));
    let mut cos_csv = String::from("pair,cosine\n");
    for (i, c) in cosines.iter().enumerate() {
        cos_csv.push_str(&format!("{i},{c}\n"));
    }
    std::fs::write(&cos_path, cos_csv)
        .map_err(|e| Failure::Runtime(anyhow!("cannot write {}: {e}", cos_path.display())))?;
    let png = out.with_extension("png");
    plot_r2(&png, scored)?;
    Ok((cos_path, png))
}

/// The table as a plot: R² per axis of every model on each medium's test split.
pub(super) fn plot_r2(png: &Path, scored: &[Scored]) -> Result<(), Failure> {
    use softtouch_collector::plot::{BarChart, BarSeries, bar_chart};
    let groups: Vec<String> = AXES.iter().map(|a| a.name.to_owned()).collect();
    let series: Vec<BarSeries> = scored
        .iter()
        .filter_map(|s| {
            let r2 = s.metrics.r2.as_ref()?;
            Some(BarSeries {
                label: format!("{} on {}", s.model, s.tested_on),
                bars: r2
                    .iter()
                    .map(|a| Some((a.r2, f64::NAN, f64::NAN)))
                    .collect(),
                reference: Vec::new(),
                notes: Vec::new(),
            })
        })
        .collect();
    if series.is_empty() {
        return Ok(());
    }
    // A model that transfers badly has R² below 0: the axis shows how far.
    let lowest = series
        .iter()
        .flat_map(|s| s.bars.iter().flatten().map(|b| b.0))
        .filter(|v| v.is_finite())
        .fold(0.0_f64, f64::min);
    bar_chart(
        png,
        &BarChart {
            title: "Land to water: test R² per axis",
            x_label: Some("axis"),
            y_label: "R², dimensionless",
            groups: &groups,
            series: &series,
            // Beyond −5 a bar ends at the axis, labelled with its value.
            y_range: (lowest.max(-5.0) - 0.05, 1.05),
            y_labels_up_to: Some(1.0),
        },
        (1100, 520),
    )
    .map_err(|e| Failure::Runtime(anyhow!("{e}")))
}
