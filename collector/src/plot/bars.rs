//! Grouped bar charts: one drawing for the PNG files and the report's figures.

use super::legend::{Item, Swatch, split_off};
use super::{FONT_FAMILY, PALETTE, PlotError, draw_err, format_tick_in, register_font};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;

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
    /// Per group: a short text above the bar (its whisker's top), e.g. its n; may be
    /// shorter than `bars`.
    pub notes: Vec<Option<String>>,
}

/// A grouped bar chart with interval whiskers.
#[derive(Debug, Clone)]
pub struct BarChart<'a> {
    /// Title.
    pub title: &'a str,
    /// Label of the x axis, if any.
    pub x_label: Option<&'a str>,
    /// Label of the y axis, with the unit.
    pub y_label: &'a str,
    /// Group names along x.
    pub groups: &'a [String],
    /// The series (each gets a colour from [`PALETTE`]; bars side by side per group).
    pub series: &'a [BarSeries],
    /// The y range.
    pub y_range: (f64, f64),
    /// Tick labels above this are left blank (the range's headroom holds the notes,
    /// not values: a rate axis labelled only up to 1).
    pub y_labels_up_to: Option<f64>,
}

/// How a bar chart looks where it is shown: [`BarLook::PNG`] for files a person
/// opens, [`BarLook::PAGE`] for the report's inline figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BarLook {
    /// Title size, px.
    pub title_px: u32,
    /// Margin around the plot, px.
    pub margin_px: u32,
    /// Room for the x and the y axis labels, px.
    pub label_areas_px: (u32, u32),
    /// Tick label and axis description sizes, px.
    pub text_px: (u32, u32),
    /// Legend text size, px (the legend is a strip of its own above the plot).
    pub legend_px: u32,
    /// Whether the light mesh lines are drawn.
    pub light_mesh: bool,
}

impl BarLook {
    /// A PNG file's chart.
    pub const PNG: Self = Self {
        title_px: 22,
        margin_px: 12,
        label_areas_px: (40, 64),
        text_px: (13, 15),
        legend_px: 14,
        light_mesh: true,
    };
    /// The report's inline figure.
    pub const PAGE: Self = Self {
        title_px: 17,
        margin_px: 10,
        label_areas_px: (40, 58),
        text_px: (12, 13),
        legend_px: 12,
        light_mesh: false,
    };
}

/// Draws grouped bars on any plotters backend (a PNG, the report's SVG): group names
/// under their group, whiskers from `lo` to `hi` where both are finite, reference
/// values as short black ticks across their bar, values clamped to the y range and
/// non-finite ones left out.
///
/// # Errors
/// The backend's error, as text.
pub fn draw_bars<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    chart: &BarChart<'_>,
    look: &BarLook,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let (y0, y1) = chart.y_range;
    let n = chart.groups.len().max(1);
    root.fill(&WHITE).map_err(e)?;
    // The legend sits in a strip of its own between the title and the plot, so that it
    // never covers a bar.
    let below_title = root
        .titled(chart.title, (FONT_FAMILY, look.title_px))
        .map_err(e)?;
    let items: Vec<Item> = chart
        .series
        .iter()
        .enumerate()
        .map(|(i, s)| Item {
            label: s.label.clone(),
            colour: PALETTE[i % PALETTE.len()],
            swatch: Swatch::Box,
        })
        .collect();
    let left_px = (look.margin_px + look.label_areas_px.1) as i32;
    let plot_area = split_off(&below_title, &items, look.legend_px, left_px).map_err(e)?;
    let mut ctx = ChartBuilder::on(&plot_area)
        .margin(look.margin_px)
        .x_label_area_size(look.label_areas_px.0)
        .y_label_area_size(look.label_areas_px.1)
        .build_cartesian_2d(0.0..n as f64, y0..y1)
        .map_err(e)?;
    // Group names at the group centres only.
    let group_name = |v: &f64| {
        let i = v.floor();
        if (v - i - 0.5).abs() < 1e-6 {
            chart.groups.get(i as usize).cloned().unwrap_or_default()
        } else {
            String::new()
        }
    };
    let tick = |v: &f64| {
        if chart
            .y_labels_up_to
            .is_some_and(|top| *v > top + 1e-9 * (y1 - y0).abs())
        {
            String::new()
        } else {
            format_tick_in(*v, y1 - y0)
        }
    };
    let mut mesh = ctx.configure_mesh();
    mesh.disable_x_mesh()
        .x_labels(n * 2 + 1)
        .x_label_formatter(&group_name)
        .y_desc(chart.y_label)
        .y_label_formatter(&tick)
        .label_style((FONT_FAMILY, look.text_px.0))
        .axis_desc_style((FONT_FAMILY, look.text_px.1));
    if let Some(x) = chart.x_label {
        mesh.x_desc(x);
    }
    if !look.light_mesh {
        mesh.light_line_style(WHITE);
    }
    mesh.draw().map_err(e)?;
    let slot = 0.8 / chart.series.len().max(1) as f64;
    for (si, s) in chart.series.iter().enumerate() {
        let colour = PALETTE[si % PALETTE.len()];
        for (gi, bar) in s.bars.iter().enumerate() {
            let x0 = gi as f64 + 0.1 + si as f64 * slot;
            let (x1, xc) = (x0 + slot * 0.9, x0 + slot * 0.45);
            if let Some((v, lo, hi)) = bar.filter(|b| b.0.is_finite()) {
                ctx.draw_series(std::iter::once(Rectangle::new(
                    // From zero (a negative value hangs below it).
                    [(x0, 0.0_f64.clamp(y0, y1)), (x1, v.clamp(y0, y1))],
                    colour.filled(),
                )))
                .map_err(e)?;
                // A value beyond the axis is drawn to its end and labelled with itself.
                if !(y0..=y1).contains(&v) {
                    let (at, anchor) = if v > y1 {
                        (y1 - 0.01 * (y1 - y0), VPos::Top)
                    } else {
                        (y0 + 0.01 * (y1 - y0), VPos::Bottom)
                    };
                    let style = (FONT_FAMILY, look.text_px.0)
                        .into_font()
                        .color(&WHITE)
                        .pos(Pos::new(HPos::Center, anchor));
                    ctx.draw_series(std::iter::once(Text::new(
                        format_tick_in(v, (y1 - y0) / 10.0),
                        (xc, at),
                        style,
                    )))
                    .map_err(e)?;
                }
                if lo.is_finite() && hi.is_finite() {
                    let (lo, hi) = (lo.clamp(y0, y1), hi.clamp(y0, y1));
                    let cap = slot * 0.15;
                    let stroke = BLACK.stroke_width(2);
                    ctx.draw_series([
                        PathElement::new(vec![(xc, lo), (xc, hi)], stroke),
                        PathElement::new(vec![(xc - cap, lo), (xc + cap, lo)], stroke),
                        PathElement::new(vec![(xc - cap, hi), (xc + cap, hi)], stroke),
                    ])
                    .map_err(e)?;
                }
            }
            if let (Some(note), Some((v, _, hi))) = (
                s.notes.get(gi).cloned().flatten(),
                bar.filter(|b| b.0.is_finite()),
            ) {
                let top = if hi.is_finite() { hi.max(v) } else { v };
                let y = top.clamp(y0, y1) + 0.015 * (y1 - y0);
                let style = (FONT_FAMILY, look.text_px.0)
                    .into_font()
                    .color(&BLACK)
                    .pos(Pos::new(HPos::Center, VPos::Bottom));
                ctx.draw_series(std::iter::once(Text::new(note, (xc, y), style)))
                    .map_err(e)?;
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
                    BLACK.stroke_width(4),
                )))
                .map_err(e)?;
            }
        }
    }
    root.present().map_err(e)
}

/// Draw a grouped bar chart (see [`draw_bars`]) into a PNG of `size` pixels.
///
/// # Errors
/// No groups or series, an empty or non-finite y range, the font, the drawing or the
/// file.
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
    let root = super::GlyphFix(BitMapBackend::new(path, size)).into_drawing_area();
    draw_bars(&root, chart, &BarLook::PNG).map_err(draw_err(path))
}
