//! Histogram grids: one drawing for the PNG files and the report's figures.

use super::{FONT_FAMILY, PALETTE, PlotError, draw_err, format_tick_in, register_font};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// One histogram panel.
#[derive(Debug, Clone)]
pub struct HistogramPanel<'a> {
    /// Title above the panel, e.g. `Fx`.
    pub title: String,
    /// Label of the x axis, with the unit, e.g. `force (N)`.
    pub x_label: String,
    /// The values (non-finite ones are skipped).
    pub values: &'a [f64],
    /// Number of bins (at least 1).
    pub bins: usize,
}

/// Bin finite values into `bins` equal bins over their range: `(low, high, count)`.
#[must_use]
pub fn bin(values: &[f64], bins: usize) -> Vec<(f64, f64, u64)> {
    let bins = bins.max(1);
    let finite = values.iter().copied().filter(|v| v.is_finite());
    let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if lo > hi {
        return Vec::new();
    }
    // A constant series gets a unit-wide range around its value.
    let (lo, hi) = if hi > lo {
        (lo, hi)
    } else {
        (lo - 0.5, hi + 0.5)
    };
    let width = (hi - lo) / bins as f64;
    let mut counts = vec![0u64; bins];
    for v in values.iter().copied().filter(|v| v.is_finite()) {
        let i = (((v - lo) / width) as usize).min(bins - 1);
        if let Some(c) = counts.get_mut(i) {
            *c += 1;
        }
    }
    counts
        .into_iter()
        .enumerate()
        .map(|(i, c)| (lo + width * i as f64, lo + width * (i + 1) as f64, c))
        .collect()
}

/// One panel's bins, ready to draw: `(low, high, count)` from [`bin`].
#[derive(Debug, Clone, Copy)]
pub struct BinnedPanel<'a> {
    /// Title above the panel; empty for none.
    pub title: &'a str,
    /// Label of the x axis, with the unit.
    pub x_label: &'a str,
    /// The bins, in order; none draws empty axes over [-1, 1].
    pub bins: &'a [(f64, f64, u64)],
}

/// How a histogram grid looks where it is shown: [`HistLook::PNG`] for files a person
/// opens, [`HistLook::PAGE`] for the report's inline figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HistLook {
    /// Title size of the whole figure and of each panel, px.
    pub title_px: (u32, u32),
    /// Room for the x and the y axis labels, px.
    pub label_areas_px: (u32, u32),
    /// Ticks on the x and the y axis.
    pub ticks: (usize, usize),
    /// Tick label and axis description sizes, px.
    pub text_px: (u32, u32),
    /// Opacity of the bars' colour.
    pub fill: f64,
}

impl HistLook {
    /// A PNG file's grid.
    pub const PNG: Self = Self {
        title_px: (26, 20),
        label_areas_px: (40, 56),
        ticks: (6, 5),
        text_px: (13, 15),
        fill: 0.85,
    };
    /// The report's inline figure.
    pub const PAGE: Self = Self {
        title_px: (17, 15),
        label_areas_px: (36, 48),
        ticks: (5, 4),
        text_px: (11, 12),
        fill: 0.8,
    };
}

/// Draws histogram panels in a grid of `columns` on any plotters backend (a PNG, the
/// report's SVG), under an optional title over the whole figure.
///
/// # Errors
/// The backend's error, as text.
pub fn draw_histograms<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: Option<&str>,
    panels: &[BinnedPanel<'_>],
    columns: usize,
    look: &HistLook,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let body = match title {
        Some(t) => root.titled(t, (FONT_FAMILY, look.title_px.0)).map_err(e)?,
        None => root.clone(),
    };
    let columns = columns.max(1);
    let rows = panels.len().div_ceil(columns).max(1);
    for (i, (area, panel)) in body
        .split_evenly((rows, columns))
        .iter()
        .zip(panels)
        .enumerate()
    {
        let colour = PALETTE[i % PALETTE.len()];
        let (x0, x1) = match (panel.bins.first(), panel.bins.last()) {
            (Some(f), Some(l)) => (f.0, l.1),
            _ => (-1.0, 1.0),
        };
        let top = panel.bins.iter().map(|b| b.2).max().unwrap_or(1).max(1) as f64 * 1.08;
        let mut builder = ChartBuilder::on(area);
        if !panel.title.is_empty() {
            builder.caption(panel.title, (FONT_FAMILY, look.title_px.1));
        }
        let mut ctx = builder
            .margin(8)
            .x_label_area_size(look.label_areas_px.0)
            .y_label_area_size(look.label_areas_px.1)
            .build_cartesian_2d(x0..x1, 0.0..top)
            .map_err(e)?;
        ctx.configure_mesh()
            .x_desc(panel.x_label)
            .y_desc("samples")
            .x_labels(look.ticks.0)
            .y_labels(look.ticks.1)
            .x_label_formatter(&|v| format_tick_in(*v, x1 - x0))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style((FONT_FAMILY, look.text_px.0))
            .axis_desc_style((FONT_FAMILY, look.text_px.1))
            .light_line_style(WHITE)
            .draw()
            .map_err(e)?;
        ctx.draw_series(panel.bins.iter().map(|&(lo, hi, n)| {
            Rectangle::new([(lo, 0.0), (hi, n as f64)], colour.mix(look.fill).filled())
        }))
        .map_err(e)?;
    }
    root.present().map_err(e)
}

/// Draw histogram panels in a grid of `columns` columns into a PNG of `size` pixels,
/// with an optional title over the whole figure.
///
/// # Errors
/// No panels, the font, the drawing or the file.
pub fn histogram_grid(
    path: &Path,
    title: Option<&str>,
    panels: &[HistogramPanel<'_>],
    columns: usize,
    size: (u32, u32),
) -> Result<(), PlotError> {
    register_font()?;
    if panels.is_empty() || columns == 0 {
        return Err(PlotError::Invalid {
            path: path.display().to_string(),
            why: "no panels".into(),
        });
    }
    let bins: Vec<Vec<(f64, f64, u64)>> = panels.iter().map(|p| bin(p.values, p.bins)).collect();
    let binned: Vec<BinnedPanel<'_>> = panels
        .iter()
        .zip(&bins)
        .map(|(p, b)| BinnedPanel {
            title: &p.title,
            x_label: &p.x_label,
            bins: b,
        })
        .collect();
    let root = super::GlyphFix(BitMapBackend::new(path, size)).into_drawing_area();
    draw_histograms(&root, title, &binned, columns, &HistLook::PNG).map_err(draw_err(path))
}
