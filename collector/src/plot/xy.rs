//! x–y charts: one drawing for the PNG files and the report's figures.

use super::legend::{Item, Swatch, split_off};
use super::{FONT_FAMILY, PALETTE, PlotError, draw_err, format_tick_in, register_font};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeriesStyle {
    /// Connected by lines.
    Line,
    /// Markers only.
    Points,
    /// Lines and markers.
    LinePoints,
    /// A translucent filled area: the points run along its upper edge and back along
    /// its lower edge (a range around a line, where a dense trace would be a solid
    /// block).
    Band,
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
    /// Legend text size, px (0: no legend), and whether a single series gets one. The
    /// legend is a strip of its own above the plot ([`super::legend`]).
    pub legend: (u32, bool),
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
        legend: (14, true),
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
        legend: (12, false),
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
    let titled = root
        .titled(chart.title, (FONT_FAMILY, look.title_px))
        .map_err(e)?;
    let (legend_px, single) = look.legend;
    let items: Vec<Item> = if single || chart.series.len() > 1 {
        chart
            .series
            .iter()
            .enumerate()
            .map(|(i, s)| Item {
                label: s.label.clone(),
                colour: PALETTE[i % PALETTE.len()],
                swatch: match (look.swatches, s.style) {
                    (true, _) | (_, SeriesStyle::Band) => Swatch::Box,
                    (false, SeriesStyle::Points) => Swatch::Dot,
                    (false, _) => Swatch::Line,
                },
            })
            .collect()
    } else {
        Vec::new()
    };
    let left_px = (look.margin_px + look.label_areas_px.1) as i32;
    let plot_area = split_off(&titled, &items, legend_px, left_px).map_err(e)?;
    let mut ctx = ChartBuilder::on(&plot_area)
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
        if s.style == SeriesStyle::Band {
            ctx.draw_series(std::iter::once(Polygon::new(pts, colour.mix(0.3).filled())))
                .map_err(e)?;
            continue;
        }
        if matches!(s.style, SeriesStyle::Line | SeriesStyle::LinePoints) {
            ctx.draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(e)?;
        }
        if matches!(s.style, SeriesStyle::Points | SeriesStyle::LinePoints) {
            let r = look.marker_px;
            let style = if look.translucent_points && s.style == SeriesStyle::Points {
                colour.mix(0.55).filled()
            } else {
                colour.filled()
            };
            if look.swatches {
                ctx.draw_series(pts.into_iter().map(|p| Circle::new(p, r, style)))
                    .map_err(e)?;
            } else {
                ctx.draw_series(PointSeries::of_element(pts, r, style, &|c, s, st| {
                    EmptyElement::at(c) + Circle::new((0, 0), s, st)
                }))
                .map_err(e)?;
            }
        }
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
    let root = super::GlyphFix(BitMapBackend::new(path, size)).into_drawing_area();
    draw_xy(&root, chart, &XyLook::PNG, ranges, false).map_err(draw_err(path))?;
    root.present().map_err(draw_err(path))?;
    Ok(())
}

/// A PNG of `panels` cells of `cell_px` in rows of `columns` under `title`: the
/// titled area (to present once drawn) and its cells, in reading order.
type Grid<'a> = DrawingArea<super::GlyphFix<BitMapBackend<'a>>, Shift>;

fn titled_grid<'a>(
    path: &'a Path,
    title: &str,
    panels: usize,
    columns: usize,
    cell_px: (u32, u32),
) -> Result<(Grid<'a>, Vec<Grid<'a>>), PlotError> {
    let fail = draw_err::<String>(path);
    register_font()?;
    if panels == 0 || columns == 0 {
        return Err(PlotError::Invalid {
            path: path.display().to_string(),
            why: "no panels to draw".into(),
        });
    }
    let rows = panels.div_ceil(columns);
    let size = (cell_px.0 * columns as u32, cell_px.1 * rows as u32 + 40);
    let root = super::GlyphFix(BitMapBackend::new(path, size)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
    let root = root
        .titled(title, (FONT_FAMILY, 22))
        .map_err(|e| fail(e.to_string()))?;
    let areas = root.split_evenly((rows, columns));
    Ok((root, areas))
}

/// One panel of [`predicted_grid`]: the axis, its unit, `(true, predicted)` points.
pub type PredictedPanel<'a> = (&'a str, &'a str, Vec<(f64, f64)>);

/// Predicted against true, one panel per `(axis, unit, (true, predicted) points)`, in
/// a grid of `columns`, each square around its own points with y = x drawn: what
/// `eval` prints as R² per axis, to look at. Non-finite points are left out.
///
/// # Errors
/// No panels, a panel with no finite point, the font, the drawing or the file.
pub fn predicted_grid(
    path: &Path,
    title: &str,
    panels: &[PredictedPanel<'_>],
    columns: usize,
) -> Result<(), PlotError> {
    let fail = draw_err::<String>(path);
    let invalid = |why: String| PlotError::Invalid {
        path: path.display().to_string(),
        why,
    };
    let (root, areas) = titled_grid(path, title, panels.len(), columns, (420, 400))?;
    for ((axis, unit, points), area) in panels.iter().zip(areas.iter()) {
        let finite: Vec<(f64, f64)> = points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        let (lo, hi) = finite
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), (x, y)| {
                (l.min(*x).min(*y), h.max(*x).max(*y))
            });
        if !lo.is_finite() {
            return Err(invalid(format!("{axis}: no finite point")));
        }
        let (lo, hi) = pad(lo, hi);
        let x_label = format!("true {axis}, {unit}");
        let y_label = format!("predicted {axis}, {unit}");
        let series = [Series {
            label: format!("{} samples", finite.len()),
            points: finite,
            style: SeriesStyle::Points,
        }];
        let chart = XyChart {
            title: axis,
            x_label: &x_label,
            y_label: &y_label,
            series: &series,
        };
        // One series a panel: no legend box over the points (the title gives n).
        let look = XyLook {
            marker_px: 2,
            translucent_points: true,
            legend: (XyLook::PNG.legend.0, false),
            ..XyLook::PNG
        };
        draw_xy(area, &chart, &look, (lo, hi, lo, hi), true).map_err(&fail)?;
    }
    root.present().map_err(|e| fail(e.to_string()))?;
    Ok(())
}

/// One panel of [`time_grid`]: its title, y label (with the unit) and series.
pub type TimePanel<'a> = (&'a str, &'a str, Vec<Series>);

/// Series against time (s), one panel per [`TimePanel`], in a grid of `columns`, each
/// with its own y range and no legend (the series take the palette's colours in
/// order: say which is which in `title`): what `live` prints, the estimate beside the
/// sensor per axis.
/// A panel with no finite point is drawn empty (its axes at [0, 1]).
///
/// # Errors
/// No panels, the font, the drawing or the file.
pub fn time_grid(
    path: &Path,
    title: &str,
    panels: &[TimePanel<'_>],
    columns: usize,
) -> Result<(), PlotError> {
    let fail = draw_err::<String>(path);
    let (root, areas) = titled_grid(path, title, panels.len(), columns, (520, 340))?;
    for ((name, y_label, series), area) in panels.iter().zip(areas.iter()) {
        let ranges = xy_ranges(series).unwrap_or((0.0, 1.0, 0.0, 1.0));
        let chart = XyChart {
            title: name,
            x_label: "time (s)",
            y_label,
            series,
        };
        // No legend box over the traces: the title names the colours.
        let look = XyLook {
            legend: (0, false),
            ..XyLook::PNG
        };
        draw_xy(area, &chart, &look, ranges, false).map_err(&fail)?;
    }
    root.present().map_err(|e| fail(e.to_string()))?;
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
    let root = super::GlyphFix(BitMapBackend::new(path, (900, 700))).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
    let root = root
        .titled(title, (FONT_FAMILY, 22))
        .map_err(|e| fail(e.to_string()))?;
    let (upper, lower) = root.split_vertically(390);
    for (area, (series, y_label), points) in [(upper, top, &all_top), (lower, bottom, &all_bottom)]
    {
        let (y0, y1) = bounds(points, 1);
        let items: Vec<Item> = series
            .iter()
            .enumerate()
            .map(|(i, s)| Item {
                label: s.label.clone(),
                colour: PALETTE[i % PALETTE.len()],
                swatch: Swatch::Line,
            })
            .collect();
        let area = split_off(&area, &items, 13, 74).map_err(|e| fail(e.to_string()))?;
        let mut ctx = ChartBuilder::on(&area)
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(64)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| fail(e.to_string()))?;
        // The shared tick labels: the font's minus (U+2212), no trailing zeros.
        let x_tick = |v: &f64| format_tick_in(*v, x1 - x0);
        let y_tick = |v: &f64| format_tick_in(*v, y1 - y0);
        ctx.configure_mesh()
            .x_desc("time (s)")
            .y_desc(y_label)
            .x_label_formatter(&x_tick)
            .y_label_formatter(&y_tick)
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
                .map_err(|e| fail(e.to_string()))?;
        }
    }
    root.present().map_err(|e| fail(e.to_string()))?;
    Ok(())
}
