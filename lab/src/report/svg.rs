//! The report's figures as inline SVG strings, through plotters' SVG backend.
//!
//! plotters escapes every text it writes (titles, legends, ticks), so names from the
//! database can go into a figure as they are. Axis labels always carry the unit.

use super::ReportError;
use plotters::prelude::*;
use softtouch_collector::plot::legend::{Item, Swatch, split_off};
use softtouch_collector::plot::{
    BarChart, BarLook, BarSeries, BinnedPanel, FONT_FAMILY, HistLook, PALETTE, Series, XyChart,
    XyLook, draw_bars, draw_histograms, draw_xy, finite_bounds, format_tick_in, pad, register_font,
};

/// Width and height of a figure, px.
pub(crate) type Size = (u32, u32);

fn draw_err(what: &str) -> impl Fn(String) -> ReportError + '_ {
    move |why| ReportError::Plot {
        what: what.to_owned(),
        why,
    }
}

/// An x–y figure.
#[derive(Debug, Clone)]
pub(crate) struct Xy<'a> {
    pub title: &'a str,
    /// With the unit.
    pub x_label: &'a str,
    /// With the unit.
    pub y_label: &'a str,
    pub series: &'a [Series],
    /// Draw y = x across the range (predicted against true).
    pub diagonal: bool,
    /// Fixed y range (e.g. R² in [0, 1]); otherwise the data's.
    pub y_range: Option<(f64, f64)>,
    /// Marker radius of point series, px.
    pub marker_px: u32,
}

/// Draws an x–y figure. Non-finite points are left out; `None` when no point is finite.
/// The drawing is the PNG charts' ([`softtouch_collector::plot::draw_xy`]), in the page's look.
pub(crate) fn xy(fig: &Xy<'_>, size: Size) -> Result<Option<String>, ReportError> {
    register_font().map_err(|e| draw_err(fig.title)(e.to_string()))?;
    let Some((x0, x1, y0, y1)) = finite_bounds(fig.series) else {
        return Ok(None);
    };
    let (x0, x1, y0, y1) = if fig.diagonal {
        let (lo, hi) = (x0.min(y0), x1.max(y1));
        (lo, hi, lo, hi)
    } else {
        (x0, x1, y0, y1)
    };
    let (x0, x1) = pad(x0, x1);
    let (y0, y1) = fig.y_range.unwrap_or_else(|| pad(y0, y1));
    let chart = XyChart {
        title: fig.title,
        x_label: fig.x_label,
        y_label: fig.y_label,
        series: fig.series,
    };
    let look = XyLook {
        marker_px: fig.marker_px,
        ..XyLook::PAGE
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw_xy(&root, &chart, &look, (x0, x1, y0, y1), fig.diagonal)
            .map_err(draw_err(fig.title))?;
        root.present()
            .map_err(|e| draw_err(fig.title)(e.to_string()))?;
    }
    Ok(Some(svg))
}

/// One histogram panel: `(low, high, count)` bins and the axis label with its unit.
#[derive(Debug, Clone)]
pub(crate) struct Panel {
    pub x_label: String,
    pub bins: Vec<(f64, f64, u64)>,
}

/// Histogram panels in a grid of `columns`: the PNG grids' drawing
/// ([`softtouch_collector::plot::draw_histograms`]) in the page's look.
pub(crate) fn histograms(
    title: &str,
    panels: &[Panel],
    columns: usize,
    size: Size,
) -> Result<String, ReportError> {
    register_font().map_err(|e| draw_err(title)(e.to_string()))?;
    let binned: Vec<BinnedPanel<'_>> = panels
        .iter()
        .map(|p| BinnedPanel {
            title: "",
            x_label: &p.x_label,
            bins: &p.bins,
        })
        .collect();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw_histograms(&root, Some(title), &binned, columns, &HistLook::PAGE)
            .map_err(draw_err(title))?;
    }
    Ok(svg)
}

/// A series of [`bars`]: its label, a value per category and a note per category.
pub(crate) type BarValues = (String, Vec<f64>, Vec<Option<String>>);

/// Grouped bars: one group per category, one bar per series (`(label, values,
/// notes)`, a value per category; non-finite values leave a gap; a note, such as the
/// bar's n, written above it), from zero to a little above the highest value and
/// down to the lowest value or `floor`, whichever is higher (a value below `floor` is
/// drawn to the axis's end and labelled with itself): the PNG charts' drawing
/// ([`softtouch_collector::plot::draw_bars`]) in the page's look.
pub(crate) fn bars(
    title: &str,
    x_label: &str,
    y_label: &str,
    categories: &[String],
    series: &[BarValues],
    floor: f64,
    size: Size,
) -> Result<String, ReportError> {
    register_font().map_err(|e| draw_err(title)(e.to_string()))?;
    let low = series
        .iter()
        .flat_map(|(_, v, _)| v.iter().copied())
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::min)
        .max(floor.min(0.0));
    let bottom = if low < 0.0 { low * 1.1 } else { 0.0 };
    let top = series
        .iter()
        .flat_map(|(_, v, _)| v.iter().copied())
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    // Room above the highest bar for its note and for the legend (a line per series).
    let top = if top > 0.0 {
        top * (1.2 + 0.1 * series.len() as f64)
    } else {
        1.0
    };
    let series: Vec<BarSeries> = series
        .iter()
        .map(|(label, values, notes)| BarSeries {
            label: label.clone(),
            bars: values
                .iter()
                .map(|&v| Some((v, f64::NAN, f64::NAN)))
                .collect(),
            reference: Vec::new(),
            notes: notes.clone(),
        })
        .collect();
    draw_bar_chart(
        &BarChart {
            title,
            x_label: Some(x_label),
            y_label,
            groups: categories,
            series: &series,
            y_range: (bottom, top),
            y_labels_up_to: None,
        },
        size,
    )
}

/// A bar chart in the page's look, as SVG.
fn draw_bar_chart(chart: &BarChart<'_>, size: Size) -> Result<String, ReportError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw_bars(&root, chart, &BarLook::PAGE).map_err(draw_err(chart.title))?;
    }
    Ok(svg)
}

/// A series of [`rate_bars`]: its label, and per category the rate with its interval
/// (`None`: no trials) and a note (the bar's n).
pub(crate) type RateValues = (String, Vec<Option<(f64, f64, f64)>>, Vec<Option<String>>);

/// Success rates (0 to 1) as grouped bars with their intervals as whiskers; the axis is
/// labelled up to 1, the headroom above holds the notes (n).
pub(crate) fn rate_bars(
    title: &str,
    x_label: &str,
    categories: &[String],
    series: &[RateValues],
    size: Size,
) -> Result<String, ReportError> {
    register_font().map_err(|e| draw_err(title)(e.to_string()))?;
    let series: Vec<BarSeries> = series
        .iter()
        .map(|(label, values, notes)| BarSeries {
            label: label.clone(),
            bars: values.clone(),
            reference: Vec::new(),
            notes: notes.clone(),
        })
        .collect();
    draw_bar_chart(
        &BarChart {
            title,
            x_label: Some(x_label),
            y_label: "success rate (Wilson 95 %)",
            groups: categories,
            series: &series,
            // Room above 1 for the bars' notes (n); the legend has a strip of its own.
            y_range: (0.0, 1.08),
            y_labels_up_to: Some(1.0),
        },
        size,
    )
}

/// Events on the run clock: one row per kind, a mark per event coloured by level
/// (`info`, `warn`, `error`). `events` are `(t_h, kind index, level)`.
pub(crate) fn timeline(
    title: &str,
    kinds: &[String],
    events: &[(f64, usize, String)],
    span_h: (f64, f64),
    size: Size,
) -> Result<String, ReportError> {
    register_font().map_err(|e| draw_err(title)(e.to_string()))?;
    let (x0, x1) = pad(span_h.0, span_h.1);
    let rows = kinds.len().max(1) as f64;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        let e = |e: DrawingAreaErrorKind<_>| e.to_string();
        let draw = || -> Result<(), String> {
            root.fill(&WHITE).map_err(e)?;
            let titled = root.titled(title, (FONT_FAMILY, 17)).map_err(e)?;
            let items: Vec<Item> = LEVELS
                .iter()
                .map(|(level, colour)| Item {
                    label: (*level).to_owned(),
                    colour: *colour,
                    swatch: Swatch::Box,
                })
                .collect();
            let plot = split_off(&titled, &items, 12, 160).map_err(e)?;
            let mut ctx = ChartBuilder::on(&plot)
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(150)
                .build_cartesian_2d(x0..x1, -0.5..rows - 0.5)
                .map_err(e)?;
            ctx.configure_mesh()
                .x_desc("run clock, h")
                .x_labels(6)
                .y_labels(kinds.len() * 2 + 1)
                .x_label_formatter(&|v| format_tick_in(*v, x1 - x0))
                .y_label_formatter(&|v| {
                    let i = v.round();
                    if (v - i).abs() < 1e-6 && i >= 0.0 {
                        kinds.get(i as usize).cloned().unwrap_or_default()
                    } else {
                        String::new()
                    }
                })
                .disable_y_mesh()
                .label_style((FONT_FAMILY, 12))
                .axis_desc_style((FONT_FAMILY, 13))
                .light_line_style(WHITE)
                .draw()
                .map_err(e)?;
            for &(level, colour) in &LEVELS {
                ctx.draw_series(
                    events
                        .iter()
                        .filter(|ev| ev.2 == level && ev.0.is_finite())
                        .map(|ev| {
                            let y = ev.1 as f64;
                            PathElement::new(
                                vec![(ev.0, y - 0.3), (ev.0, y + 0.3)],
                                colour.stroke_width(2),
                            )
                        }),
                )
                .map_err(e)?;
            }
            root.present().map_err(|e| e.to_string())
        };
        draw().map_err(draw_err(title))?;
    }
    Ok(svg)
}

/// The timeline's event levels and their colours.
const LEVELS: [(&str, RGBColor); 3] = [
    ("info", PALETTE[0]),
    ("warn", PALETTE[1]),
    ("error", PALETTE[5]),
];

/// Evenly spaced picks of at most `max` out of `n` (all when `n ≤ max`), in order.
#[must_use]
pub(crate) fn downsample_indices(n: usize, max: usize) -> Vec<usize> {
    if n <= max {
        return (0..n).collect();
    }
    if max == 0 {
        return Vec::new();
    }
    (0..max).map(|i| i * n / max).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use softtouch_collector::plot::SeriesStyle;

    #[test]
    fn downsampling_keeps_order_bounds_and_the_first_point() {
        assert_eq!(downsample_indices(3, 10), vec![0, 1, 2]);
        let picks = downsample_indices(30_000, 300);
        assert_eq!(picks.len(), 300);
        assert_eq!(picks[0], 0);
        assert!(picks.windows(2).all(|w| w[0] < w[1]));
        assert!(*picks.last().unwrap_or(&usize::MAX) < 30_000);
        assert!(downsample_indices(5, 0).is_empty());
    }

    #[test]
    fn an_xy_figure_is_svg_with_escaped_text_and_none_without_points() {
        let series = [
            Series {
                label: "a<b & \"c\"".into(),
                points: vec![(0.0, 1.0), (1.0, f64::NAN), (2.0, 3.0)],
                style: SeriesStyle::LinePoints,
            },
            Series {
                label: "other".into(),
                points: vec![(0.5, 2.0)],
                style: SeriesStyle::Points,
            },
        ];
        let fig = Xy {
            title: "t",
            x_label: "x, s",
            y_label: "y, N",
            series: &series,
            diagonal: false,
            y_range: None,
            marker_px: 2,
        };
        let svg = xy(&fig, (300, 200)).expect("draws").expect("has points");
        assert!(svg.starts_with("<svg"), "{}", &svg[..40.min(svg.len())]);
        assert!(svg.contains("a&lt;b &amp;"), "legend escaped");
        assert!(!svg.contains("a<b"));
        let empty = [Series {
            label: String::new(),
            points: vec![(f64::NAN, 1.0)],
            style: SeriesStyle::Points,
        }];
        let none = xy(
            &Xy {
                series: &empty,
                ..fig
            },
            (300, 200),
        )
        .expect("no error");
        assert!(none.is_none());
    }

    #[test]
    fn the_page_and_the_png_label_ticks_alike() {
        // One formatter (`plot::format_tick_in`) for both; these were the page's own.
        assert_eq!(format_tick_in(0.5, 1.0), "0.5");
        assert_eq!(format_tick_in(-0.0, 1.0), "0");
        assert_eq!(format_tick_in(1234.0, 2000.0), "1234");
        assert_eq!(format_tick_in(0.0001, 0.001), "1.0e−4");
    }
}
