//! Plots as PNG files with plotters, pure Rust (no system font libraries): the bundled
//! DejaVu Sans Mono is registered once as `sans-serif` (see [`register_font`]).
//!
//! Helpers meant for reuse across the collector (dataset statistics, bench results,
//! trainer sweeps):
//! - [`histogram_grid`]: a grid of histogram panels, one per value series.
//! - [`xy_chart`]: several labelled x–y series as lines, points or both; its drawing
//!   ([`draw_xy`]) is generic over the backend, so the report's SVG figures are drawn
//!   by the same code in their own [`XyLook`].
//! - [`bar_chart`]: grouped bars with interval whiskers and reference ticks.
//! - [`two_panel_chart`]: two x–y charts over one time axis, one above the other.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;
use std::sync::OnceLock;

/// The bundled font (DejaVu Sans Mono, license in `assets/DejaVu-LICENSE.txt`).
const FONT: &[u8] = include_bytes!("../assets/DejaVuSansMono.ttf");

/// The font family every chart here uses.
pub const FONT_FAMILY: &str = "sans-serif";

/// Colours for series, in order (a colour-blind-safe palette).
pub const PALETTE: [RGBColor; 6] = [
    RGBColor(0, 114, 178),
    RGBColor(230, 159, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(86, 180, 233),
    RGBColor(213, 94, 0),
];

/// Drawing a plot failed.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The bundled font could not be loaded.
    #[error("cannot load the bundled font")]
    Font,
    /// Drawing or writing the file failed.
    #[error("cannot draw {path}: {why}")]
    Draw {
        /// The output file.
        path: String,
        /// Why.
        why: String,
    },
    /// Nothing to draw, or a bad layout.
    #[error("cannot draw {path}: {why}")]
    Invalid {
        /// The output file.
        path: String,
        /// Why.
        why: String,
    },
}

/// Register the bundled font as [`FONT_FAMILY`] (normal style) once per process.
/// Every helper here calls it; call it yourself before drawing with plotters directly.
pub fn register_font() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, FONT).is_ok()
    });
    if ok { Ok(()) } else { Err(PlotError::Font) }
}

fn draw_err<E: std::fmt::Display>(path: &Path) -> impl Fn(E) -> PlotError + '_ {
    move |e| PlotError::Draw {
        path: path.display().to_string(),
        why: e.to_string(),
    }
}

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

/// Draw histogram panels in a grid of `columns` columns into a PNG of `size` pixels,
/// with an optional title over the whole figure.
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
    let rows = panels.len().div_ceil(columns);
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(draw_err(path))?;
    let body = match title {
        Some(t) => root.titled(t, (FONT_FAMILY, 26)).map_err(draw_err(path))?,
        None => root.clone(),
    };
    let areas = body.split_evenly((rows, columns));
    for (i, (panel, area)) in panels.iter().zip(areas.iter()).enumerate() {
        draw_histogram(path, area, panel, PALETTE[i % PALETTE.len()])?;
    }
    root.present().map_err(draw_err(path))?;
    Ok(())
}

fn draw_histogram(
    path: &Path,
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    panel: &HistogramPanel<'_>,
    colour: RGBColor,
) -> Result<(), PlotError> {
    let bins = bin(panel.values, panel.bins);
    let (x0, x1) = match (bins.first(), bins.last()) {
        (Some(f), Some(l)) => (f.0, l.1),
        _ => (-1.0, 1.0),
    };
    let y1 = bins.iter().map(|b| b.2).max().unwrap_or(1).max(1) as f64 * 1.08;
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, (FONT_FAMILY, 20))
        .margin(8)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(x0..x1, 0.0..y1)
        .map_err(draw_err(path))?;
    chart
        .configure_mesh()
        .x_desc(panel.x_label.as_str())
        .y_desc("samples")
        .x_labels(6)
        .y_labels(5)
        .y_label_formatter(&|v| format!("{v:.0}"))
        .x_label_formatter(&|v| format_tick_in(*v, x1 - x0))
        .label_style((FONT_FAMILY, 13))
        .axis_desc_style((FONT_FAMILY, 15))
        .light_line_style(WHITE)
        .draw()
        .map_err(draw_err(path))?;
    chart
        .draw_series(bins.iter().map(|&(lo, hi, count)| {
            Rectangle::new([(lo, 0.0), (hi, count as f64)], colour.mix(0.85).filled())
        }))
        .map_err(draw_err(path))?;
    Ok(())
}

/// A short tick label for `v` on an axis spanning `span` (`-5`, `0.5`, `2.25`,
/// `1.2e-4`: no trailing zeros), with enough decimals that
/// neighbouring ticks (about a tenth of the span apart) read differently: an R² axis
/// from 0.9971 to 0.9983 needs four, where two would label every tick "1".
pub fn format_tick_in(v: f64, span: f64) -> String {
    let a = v.abs();
    let step = span / 10.0;
    let usable = step.is_finite() && step > 0.0;
    if a != 0.0 && a < 0.01 {
        let digits = if usable {
            (a / step).log10().ceil().clamp(1.0, 6.0) as usize
        } else {
            1
        };
        return format!("{v:.digits$e}");
    }
    let needed = if usable {
        (-step.log10()).ceil().clamp(0.0, 8.0) as usize
    } else {
        0
    };
    let decimals = if a >= 100.0 { 0 } else { 2 }.max(needed);
    let text = format!("{v:.decimals$}");
    let text = if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        text
    };
    if text == "-0" { "0".into() } else { text }
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeriesStyle {
    /// Connected by lines.
    Line,
    /// Markers only.
    Points,
    /// Lines and markers.
    LinePoints,
}

/// One labelled x–y series.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// The points, drawn in order (non-finite ones are skipped).
    pub points: Vec<(f64, f64)>,
    /// Lines, points or both.
    pub style: SeriesStyle,
}

/// An x–y chart.
#[derive(Debug, Clone)]
pub struct XyChart<'a> {
    /// Title.
    pub title: &'a str,
    /// Label of the x axis, with the unit.
    pub x_label: &'a str,
    /// Label of the y axis, with the unit.
    pub y_label: &'a str,
    /// The series (each gets a colour from [`PALETTE`] and a legend entry).
    pub series: &'a [Series],
}

/// How an x–y chart looks where it is shown: [`XyLook::PNG`] for files a person opens,
/// [`XyLook::PAGE`] for the report's inline figures (smaller type, a light mesh, a
/// legend only where there are several series).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct XyLook {
    /// Title size, px.
    pub title_px: u32,
    /// Margin around the plot, px.
    pub margin_px: u32,
    /// Room for the x and the y axis labels, px.
    pub label_areas_px: (u32, u32),
    /// Tick label and axis description sizes, px.
    pub text_px: (u32, u32),
    /// Ticks per axis (`None`: plotters' default) and whether the light mesh is hidden.
    pub ticks: Option<usize>,
    /// Marker radius of point series, px.
    pub marker_px: u32,
    /// Legend entries as filled swatches (the page) or as the series' own line or
    /// marker (the PNG).
    pub swatches: bool,
    /// Points of a points-only series drawn translucent (a dense scatter).
    pub translucent_points: bool,
    /// Legend text size, px; its box's border darkness (0–1); whether it sits at the
    /// lower right (else plotters' default); whether a single series gets one.
    pub legend: (u32, f64, bool, bool),
}

impl XyLook {
    /// A PNG file's chart.
    pub const PNG: Self = Self {
        title_px: 22,
        margin_px: 12,
        label_areas_px: (44, 64),
        text_px: (13, 15),
        ticks: None,
        marker_px: 3,
        swatches: false,
        translucent_points: false,
        legend: (14, 1.0, false, true),
    };
    /// The report's inline figure.
    pub const PAGE: Self = Self {
        title_px: 17,
        margin_px: 10,
        label_areas_px: (40, 58),
        text_px: (12, 13),
        ticks: Some(6),
        marker_px: 2,
        swatches: true,
        translucent_points: true,
        legend: (12, 0.3, true, false),
    };
}

/// The finite range `(x0, x1, y0, y1)` of every point of `series`; `None` when no
/// point is finite.
#[must_use]
pub fn finite_bounds(series: &[Series]) -> Option<(f64, f64, f64, f64)> {
    series
        .iter()
        .flat_map(|s| s.points.iter().copied())
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .fold(None, |acc, (x, y)| {
            Some(match acc {
                None => (x, x, y, y),
                Some((a, b, c, d)) => (a.min(x), b.max(x), c.min(y), d.max(y)),
            })
        })
}

/// [`finite_bounds`], each side padded by [`pad`].
#[must_use]
pub fn xy_ranges(series: &[Series]) -> Option<(f64, f64, f64, f64)> {
    let (x0, x1, y0, y1) = finite_bounds(series)?;
    let (x0, x1) = pad(x0, x1);
    let (y0, y1) = pad(y0, y1);
    Some((x0, x1, y0, y1))
}

/// Pads a range by 5 % (or ±0.5 for a single value).
#[must_use]
pub fn pad(lo: f64, hi: f64) -> (f64, f64) {
    let m = if hi > lo { (hi - lo) * 0.05 } else { 0.5 };
    (lo - m, hi + m)
}

/// Draws an x–y chart on any plotters backend (a PNG, the report's SVG) over the given
/// ranges, with `look`; `diagonal` adds y = x (predicted against true). Non-finite
/// points are left out.
///
/// # Errors
/// The backend's error, as text.
pub fn draw_xy<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    chart: &XyChart<'_>,
    look: &XyLook,
    (x0, x1, y0, y1): (f64, f64, f64, f64),
    diagonal: bool,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    let mut ctx = ChartBuilder::on(root)
        .caption(chart.title, (FONT_FAMILY, look.title_px))
        .margin(look.margin_px)
        .x_label_area_size(look.label_areas_px.0)
        .y_label_area_size(look.label_areas_px.1)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(e)?;
    let x_tick = |v: &f64| format_tick_in(*v, x1 - x0);
    let y_tick = |v: &f64| format_tick_in(*v, y1 - y0);
    let mut mesh = ctx.configure_mesh();
    mesh.x_desc(chart.x_label)
        .y_desc(chart.y_label)
        .x_label_formatter(&x_tick)
        .y_label_formatter(&y_tick)
        .label_style((FONT_FAMILY, look.text_px.0))
        .axis_desc_style((FONT_FAMILY, look.text_px.1));
    if let Some(n) = look.ticks {
        mesh.x_labels(n).y_labels(n).light_line_style(WHITE);
    }
    mesh.draw().map_err(e)?;
    if diagonal {
        ctx.draw_series(LineSeries::new(
            [(x0, x0), (x1, x1)],
            BLACK.mix(0.4).stroke_width(1),
        ))
        .map_err(e)?;
    }
    for (i, s) in chart.series.iter().enumerate() {
        let colour = PALETTE[i % PALETTE.len()];
        let pts: Vec<(f64, f64)> = s
            .points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        let swatch = move |(x, y): (i32, i32)| {
            Rectangle::new([(x, y - 4), (x + 12, y + 4)], colour.filled())
        };
        if matches!(s.style, SeriesStyle::Line | SeriesStyle::LinePoints) {
            let drawn = ctx
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(e)?
                .label(s.label.as_str());
            if look.swatches {
                drawn.legend(swatch);
            } else {
                drawn.legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                });
            }
        }
        if matches!(s.style, SeriesStyle::Points | SeriesStyle::LinePoints) {
            let r = look.marker_px;
            let style = if look.translucent_points && s.style == SeriesStyle::Points {
                colour.mix(0.55).filled()
            } else {
                colour.filled()
            };
            let drawn = if look.swatches {
                ctx.draw_series(pts.into_iter().map(|p| Circle::new(p, r, style)))
                    .map_err(e)?
            } else {
                ctx.draw_series(PointSeries::of_element(pts, r, style, &|c, s, st| {
                    EmptyElement::at(c) + Circle::new((0, 0), s, st)
                }))
                .map_err(e)?
            };
            if s.style == SeriesStyle::Points {
                let drawn = drawn.label(s.label.as_str());
                if look.swatches {
                    drawn.legend(swatch);
                } else {
                    drawn.legend(move |(x, y)| Circle::new((x + 9, y), 3, colour.filled()));
                }
            }
        }
    }
    let (legend_px, border, lower_right, single) = look.legend;
    if single || chart.series.len() > 1 {
        let mut labels = ctx.configure_series_labels();
        labels
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(border))
            .label_font((FONT_FAMILY, legend_px));
        if lower_right {
            labels.position(SeriesLabelPosition::LowerRight);
        }
        labels.draw().map_err(e)?;
    }
    Ok(())
}

/// Draw an x–y chart into a PNG of `size` pixels. Axis ranges cover every finite
/// point with a small margin.
pub fn xy_chart(path: &Path, chart: &XyChart<'_>, size: (u32, u32)) -> Result<(), PlotError> {
    register_font()?;
    let Some(ranges) = xy_ranges(chart.series) else {
        return Err(PlotError::Invalid {
            path: path.display().to_string(),
            why: "no finite points".into(),
        });
    };
    let root = BitMapBackend::new(path, size).into_drawing_area();
    draw_xy(&root, chart, &XyLook::PNG, ranges, false).map_err(draw_err(path))?;
    root.present().map_err(draw_err(path))?;
    Ok(())
}

/// One series of bars: a value per group with its interval, and optionally a
/// reference value per group (e.g. a paper's figure) drawn as a black tick.
#[derive(Debug, Clone)]
pub struct BarSeries {
    /// Legend text.
    pub label: String,
    /// Per group: `(value, lo, hi)`; `None` leaves the slot empty.
    pub bars: Vec<Option<(f64, f64, f64)>>,
    /// Per group: a reference value, or `None`.
    pub reference: Vec<Option<f64>>,
}

/// A grouped bar chart with interval whiskers.
#[derive(Debug, Clone)]
pub struct BarChart<'a> {
    /// Title.
    pub title: &'a str,
    /// Label of the y axis, with the unit.
    pub y_label: &'a str,
    /// Group names along x.
    pub groups: &'a [String],
    /// The series (each gets a colour from [`PALETTE`]; bars side by side per group).
    pub series: &'a [BarSeries],
    /// The y range.
    pub y_range: (f64, f64),
}

/// Draw a grouped bar chart with whiskers from `lo` to `hi` into a PNG of `size`
/// pixels. Reference values are short black ticks across their bar.
pub fn bar_chart(path: &Path, chart: &BarChart<'_>, size: (u32, u32)) -> Result<(), PlotError> {
    register_font()?;
    let invalid = |why: &str| PlotError::Invalid {
        path: path.display().to_string(),
        why: why.to_owned(),
    };
    if chart.groups.is_empty() || chart.series.is_empty() {
        return Err(invalid("no groups or no series"));
    }
    let (y0, y1) = chart.y_range;
    if !(y0.is_finite() && y1.is_finite() && y1 > y0) {
        return Err(invalid("the y range is empty or not finite"));
    }
    let n = chart.groups.len() as f64;
    // Room below the axis for the group names.
    let label_y = y0 - 0.08 * (y1 - y0);
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(draw_err(path))?;
    let mut ctx = ChartBuilder::on(&root)
        .caption(chart.title, (FONT_FAMILY, 22))
        .margin(12)
        .x_label_area_size(10)
        .y_label_area_size(64)
        .build_cartesian_2d(0f64..n, (label_y - 0.04 * (y1 - y0))..y1)
        .map_err(draw_err(path))?;
    ctx.configure_mesh()
        .disable_x_mesh()
        .x_labels(2)
        .x_label_formatter(&|_| String::new())
        .y_desc(chart.y_label)
        .y_label_formatter(&|v| {
            if *v < y0 - 1e-9 {
                String::new()
            } else {
                format_tick_in(*v, y1 - y0)
            }
        })
        .label_style((FONT_FAMILY, 13))
        .axis_desc_style((FONT_FAMILY, 15))
        .draw()
        .map_err(draw_err(path))?;
    let k = chart.series.len() as f64;
    let slot = 0.8 / k;
    for (si, s) in chart.series.iter().enumerate() {
        let colour = PALETTE[si % PALETTE.len()];
        let mut labelled = false;
        for (gi, bar) in s.bars.iter().enumerate() {
            let x0 = gi as f64 + 0.1 + si as f64 * slot;
            let (x1, xc) = (x0 + slot * 0.9, x0 + slot * 0.45);
            if let Some((v, lo, hi)) = bar.filter(|b| b.0.is_finite()) {
                let drawn = ctx
                    .draw_series(std::iter::once(Rectangle::new(
                        [(x0, y0), (x1, v.clamp(y0, y1))],
                        colour.filled(),
                    )))
                    .map_err(draw_err(path))?;
                if !labelled {
                    labelled = true;
                    drawn.label(s.label.as_str()).legend(move |(x, y)| {
                        Rectangle::new([(x, y - 5), (x + 14, y + 5)], colour.filled())
                    });
                }
                if lo.is_finite() && hi.is_finite() {
                    let (lo, hi) = (lo.clamp(y0, y1), hi.clamp(y0, y1));
                    let cap = slot * 0.15;
                    ctx.draw_series([
                        PathElement::new(vec![(xc, lo), (xc, hi)], BLACK.stroke_width(2)),
                        PathElement::new(
                            vec![(xc - cap, lo), (xc + cap, lo)],
                            BLACK.stroke_width(2),
                        ),
                        PathElement::new(
                            vec![(xc - cap, hi), (xc + cap, hi)],
                            BLACK.stroke_width(2),
                        ),
                    ])
                    .map_err(draw_err(path))?;
                }
            }
            if let Some(r) = s
                .reference
                .get(gi)
                .copied()
                .flatten()
                .filter(|r| r.is_finite())
            {
                let r = r.clamp(y0, y1);
                ctx.draw_series(std::iter::once(PathElement::new(
                    vec![(x0 - slot * 0.05, r), (x1 + slot * 0.05, r)],
                    RGBColor(0, 0, 0).stroke_width(4),
                )))
                .map_err(draw_err(path))?;
            }
        }
    }
    for (gi, g) in chart.groups.iter().enumerate() {
        ctx.draw_series(std::iter::once(Text::new(
            g.clone(),
            (gi as f64 + 0.1, label_y),
            (FONT_FAMILY, 13),
        )))
        .map_err(draw_err(path))?;
    }
    ctx.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT_FAMILY, 14))
        .draw()
        .map_err(draw_err(path))?;
    root.present().map_err(draw_err(path))?;
    Ok(())
}

/// Two charts over the same time axis (seconds), one above the other, in one PNG of
/// 900×700: `top` and `bottom` are their series and y labels.
///
/// # Errors
/// The font, the drawing or the file.
pub fn two_panel_chart(
    path: &Path,
    title: &str,
    top: (&[Series], &str),
    bottom: (&[Series], &str),
) -> Result<(), PlotError> {
    let fail = draw_err::<String>(path);
    register_font()?;
    let finite = |s: &[Series]| -> Vec<(f64, f64)> {
        s.iter()
            .flat_map(|s| s.points.iter().copied())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect()
    };
    let (all_top, all_bottom) = (finite(top.0), finite(bottom.0));
    let bounds = |p: &[(f64, f64)], axis: usize| {
        let v = p.iter().map(|q| if axis == 0 { q.0 } else { q.1 });
        let (lo, hi) = v.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
            (l.min(x), h.max(x))
        });
        if !lo.is_finite() {
            return (0.0, 1.0);
        }
        pad(lo, hi)
    };
    let both: Vec<(f64, f64)> = all_top.iter().chain(&all_bottom).copied().collect();
    let (x0, x1) = bounds(&both, 0);
    let root = BitMapBackend::new(path, (900, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
    let root = root
        .titled(title, (FONT_FAMILY, 22))
        .map_err(|e| fail(e.to_string()))?;
    let (upper, lower) = root.split_vertically(390);
    for (area, (series, y_label), points) in [(upper, top, &all_top), (lower, bottom, &all_bottom)]
    {
        let (y0, y1) = bounds(points, 1);
        let mut ctx = ChartBuilder::on(&area)
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(64)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| fail(e.to_string()))?;
        ctx.configure_mesh()
            .x_desc("time (s)")
            .y_desc(y_label)
            .label_style((FONT_FAMILY, 13))
            .axis_desc_style((FONT_FAMILY, 15))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
        for (i, s) in series.iter().enumerate() {
            let colour = PALETTE[i % PALETTE.len()];
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .copied()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect();
            ctx.draw_series(LineSeries::new(pts, colour.stroke_width(2)))
                .map_err(|e| fail(e.to_string()))?
                .label(s.label.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                });
        }
        ctx.configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((FONT_FAMILY, 13))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
    }
    root.present().map_err(|e| fail(e.to_string()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_cover_every_finite_value_once() {
        let values = [0.0, 0.1, 0.5, 1.0, f64::NAN, f64::INFINITY];
        let bins = bin(&values, 4);
        assert_eq!(bins.len(), 4);
        assert_eq!(bins.iter().map(|b| b.2).sum::<u64>(), 4);
        assert_eq!(bins.last().map(|b| b.2), Some(1)); // the maximum lands in the last bin
        assert!(bin(&[], 4).is_empty());
        assert_eq!(bin(&[2.0, 2.0], 3).iter().map(|b| b.2).sum::<u64>(), 2);
    }

    #[test]
    fn ticks_are_short() {
        let got: Vec<String> = [-5.0, 0.5, 2.25, 0.0, -0.0001, 150.0, 12.5]
            .into_iter()
            .map(|v| format_tick_in(v, f64::INFINITY))
            .collect();
        assert_eq!(got, ["-5", "0.5", "2.25", "0", "-1.0e-4", "150", "12.5"]);
    }

    #[test]
    fn ticks_on_a_narrow_axis_differ() {
        // An R² axis of a model benchmark, and an image-MSE axis.
        let r2: Vec<String> = [0.9970, 0.9972, 0.9974, 0.9976]
            .into_iter()
            .map(|v| format_tick_in(v, 0.0014))
            .collect();
        assert_eq!(r2, ["0.997", "0.9972", "0.9974", "0.9976"]);
        let mse: Vec<String> = [1.5e-3, 2.0e-3, 2.5e-3]
            .into_iter()
            .map(|v| format_tick_in(v, 6e-3))
            .collect();
        assert_eq!(mse, ["1.5e-3", "2.0e-3", "2.5e-3"]);
        // A wide axis keeps its short labels; a degenerate span falls back to them.
        assert_eq!(format_tick_in(150.0, 400.0), "150");
        assert_eq!(format_tick_in(0.5, 0.0), "0.5");
        assert_eq!(format_tick_in(0.5, f64::NAN), "0.5");
    }

    #[test]
    fn both_helpers_write_png_files() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let values: Vec<f64> = (0..500)
            .map(|i| (f64::from(i) * 0.37).sin() * 5.0)
            .collect();
        let panels: Vec<HistogramPanel<'_>> = ["a", "b", "c", "d"]
            .iter()
            .map(|t| HistogramPanel {
                title: (*t).into(),
                x_label: "value (N)".into(),
                values: &values,
                bins: 20,
            })
            .collect();
        let hist = dir.path().join("h.png");
        histogram_grid(&hist, Some("test"), &panels, 2, (640, 480))
            .unwrap_or_else(|e| panic!("{e}"));
        let chart = dir.path().join("c.png");
        let series = [
            Series {
                label: "line".into(),
                points: (0..10).map(|i| (f64::from(i), f64::from(i * i))).collect(),
                style: SeriesStyle::LinePoints,
            },
            Series {
                label: "points".into(),
                points: (0..10).map(|i| (f64::from(i), f64::from(50 - i))).collect(),
                style: SeriesStyle::Points,
            },
        ];
        let spec = XyChart {
            title: "t",
            x_label: "x (s)",
            y_label: "y (N)",
            series: &series,
        };
        xy_chart(&chart, &spec, (480, 360)).unwrap_or_else(|e| panic!("{e}"));
        for p in [hist, chart] {
            let img = image::open(&p).unwrap_or_else(|e| panic!("{e}"));
            assert!(img.width() > 100);
        }
        assert!(histogram_grid(&dir.path().join("x.png"), None, &[], 2, (10, 10)).is_err());
        let bars = dir.path().join("b.png");
        let groups = ["a".to_owned(), "b".to_owned()];
        let series = [BarSeries {
            label: "rate".into(),
            bars: vec![Some((0.5, 0.2, 0.8)), None],
            reference: vec![Some(0.44), None],
        }];
        let chart = BarChart {
            title: "t",
            y_label: "success rate",
            groups: &groups,
            series: &series,
            y_range: (0.0, 1.0),
        };
        bar_chart(&bars, &chart, (480, 360)).unwrap_or_else(|e| panic!("{e}"));
        assert!(image::open(&bars).is_ok_and(|i| i.width() == 480));
        let empty = BarChart {
            groups: &[],
            ..chart
        };
        assert!(bar_chart(&dir.path().join("y.png"), &empty, (10, 10)).is_err());
    }
}

/// A heatmap of values in `[-1, 1]` (correlations): rows top to bottom, columns left
/// to right, blue for −1, white for 0, red for +1, grey for a missing value.
#[derive(Debug, Clone)]
pub struct Heatmap<'a> {
    /// Title.
    pub title: &'a str,
    /// One label per row (drawn left of the rows).
    pub row_labels: &'a [String],
    /// One label per column (drawn under the columns).
    pub column_labels: &'a [String],
    /// `values[row][column]`; `None` (or a non-finite value) is drawn grey.
    pub values: &'a [Vec<Option<f64>>],
}

/// The diverging colour of `v` in `[-1, 1]` (clamped): blue, white, red.
#[must_use]
pub fn diverging(v: f64) -> RGBColor {
    let v = if v.is_finite() {
        v.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let (end, t) = if v < 0.0 {
        ((33.0, 102.0, 172.0), -v)
    } else {
        ((178.0, 24.0, 43.0), v)
    };
    let mix = |e: f64| (255.0 + (e - 255.0) * t).round().clamp(0.0, 255.0) as u8;
    RGBColor(mix(end.0), mix(end.1), mix(end.2))
}

/// Draw a [`Heatmap`] with a colour bar into a PNG of at least `size` pixels (wider
/// when the title needs it). Cells are square; every row and column is labelled
/// when its cell is large enough for the label, else every k-th. Cell values are
/// printed in the cells when the cells can hold them.
pub fn heatmap(path: &Path, map: &Heatmap<'_>, size: (u32, u32)) -> Result<(), PlotError> {
    register_font()?;
    let rows = map.values.len();
    let cols = map.values.first().map_or(0, Vec::len);
    if rows == 0 || cols == 0 || map.values.iter().any(|r| r.len() != cols) {
        return Err(PlotError::Invalid {
            path: path.display().to_string(),
            why: format!("a heatmap needs equal non-empty rows ({rows} rows)"),
        });
    }
    let err = draw_err(path);
    let chars = |labels: &[String]| labels.iter().map(|l| l.chars().count()).max().unwrap_or(1);
    // DejaVu Sans Mono at 12 px: about 7.3 px per character.
    let (char_px, font_px) = (7.5f64, 12u32);
    let left = (chars(map.row_labels) as f64 * char_px) as i32 + 16;
    let (top, bottom, right) = (46i32, 34i32, 90i32);
    let width = (size.0 as i32).max((map.title.chars().count() as f64 * 10.0) as i32 + 24);
    let height = size.1 as i32;
    let cw = ((width - left - right) / cols as i32).max(2);
    let ch = ((height - top - bottom) / rows as i32).max(2);
    let (w, h) = (
        (left + cw * cols as i32 + right).max(width),
        top + ch * rows as i32 + bottom,
    );
    let root = BitMapBackend::new(path, (w as u32, h as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(&err)?;
    let font = |px: u32| (FONT_FAMILY, px).into_font();
    root.draw(&Text::new(map.title.to_owned(), (12, 12), font(18)))
        .map_err(&err)?;
    let grey = RGBColor(190, 190, 190);
    for (r, row) in map.values.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            let (x, y) = (left + c as i32 * cw, top + r as i32 * ch);
            let fill = match v {
                Some(v) if v.is_finite() => diverging(*v),
                _ => grey,
            };
            root.draw(&Rectangle::new([(x, y), (x + cw, y + ch)], fill.filled()))
                .map_err(&err)?;
            if let Some(v) = v.filter(|v| v.is_finite())
                && cw >= 44
                && ch >= 14
            {
                let colour = if v.abs() > 0.6 { WHITE } else { BLACK };
                root.draw(&Text::new(
                    format!("{v:+.2}"),
                    (x + cw / 2 - 18, y + ch / 2 - 6),
                    font(font_px).color(&colour),
                ))
                .map_err(&err)?;
            }
        }
    }
    // Labels: every k-th where a cell is narrower than its label.
    let every = |label_px: f64, cell: i32| ((label_px / f64::from(cell)).ceil() as usize).max(1);
    let ey = every(f64::from(font_px) + 2.0, ch);
    for r in (0..rows).step_by(ey) {
        let label = map.row_labels.get(r).cloned().unwrap_or_default();
        let y = top + r as i32 * ch + ch / 2 - font_px as i32 / 2;
        root.draw(&Text::new(label, (6, y), font(font_px)))
            .map_err(&err)?;
    }
    let ex = every(chars(map.column_labels) as f64 * char_px + 4.0, cw);
    for c in (0..cols).step_by(ex) {
        let label = map.column_labels.get(c).cloned().unwrap_or_default();
        let x =
            left + c as i32 * cw + cw / 2 - (label.chars().count() as f64 * char_px / 2.0) as i32;
        root.draw(&Text::new(
            label,
            (x, top + rows as i32 * ch + 8),
            font(font_px),
        ))
        .map_err(&err)?;
    }
    // The colour bar: +1 at the top, −1 at the bottom, over the cells' height.
    let (bx, bh) = (left + cw * cols as i32 + 20, ch * rows as i32);
    for i in 0..bh {
        let v = 1.0 - 2.0 * (f64::from(i) + 0.5) / f64::from(bh);
        root.draw(&Rectangle::new(
            [(bx, top + i), (bx + 18, top + i + 1)],
            diverging(v).filled(),
        ))
        .map_err(&err)?;
    }
    for v in [1.0f64, 0.5, 0.0, -0.5, -1.0] {
        let y = top + ((1.0 - v) / 2.0 * f64::from(bh)) as i32;
        root.draw(&PathElement::new(vec![(bx + 18, y), (bx + 23, y)], BLACK))
            .map_err(&err)?;
        root.draw(&Text::new(format!("{v:+.1}"), (bx + 26, y - 6), font(11)))
            .map_err(&err)?;
    }
    root.present().map_err(&err)?;
    Ok(())
}
