//! Charts with plotters, pure Rust (no system font libraries): the bundled DejaVu
//! Sans Mono is registered once as `sans-serif` (see [`register_font`]). Each kind of
//! chart is drawn by one function generic over plotters' backend, so a PNG file and
//! the report's inline SVG of the same figure come from one place, each in its look:
//! - [`draw_histograms`] ([`histogram_grid`] for a PNG): a grid of histogram panels.
//! - [`draw_xy`] ([`xy_chart`]): labelled x–y series as lines, points or both.
//! - [`draw_bars`] ([`bar_chart`]): grouped bars with interval whiskers and reference
//!   ticks.
//! - [`two_panel_chart`]: two x–y charts over one time axis, one above the other.
//! - [`heatmap`]: values in [-1, 1] as a diverging colour grid.
//!
//! Every axis's ticks are labelled by [`format_tick_in`].

mod bars;
mod heatmap;
mod histogram;
pub mod legend;
#[cfg(test)]
mod tests;
mod text;
mod xy;

pub use bars::{BarChart, BarLook, BarSeries, bar_chart, draw_bars};
pub use heatmap::{Heatmap, diverging, heatmap};
pub use histogram::{BinnedPanel, HistLook, HistogramPanel, bin, draw_histograms, histogram_grid};
pub use text::{GlyphFix, glyph_pixels};
pub use xy::{
    PredictedPanel, Series, SeriesStyle, TimePanel, XyChart, XyLook, draw_xy, finite_bounds, pad,
    predicted_grid, time_grid, two_panel_chart, xy_chart, xy_ranges,
};

use plotters::style::{FontStyle, RGBColor};
use std::path::Path;
use std::sync::OnceLock;

/// The bundled font (DejaVu Sans Mono, license in `assets/DejaVu-LICENSE.txt`).
const FONT: &[u8] = include_bytes!("../../assets/DejaVuSansMono.ttf");

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

pub(crate) fn draw_err<E: std::fmt::Display>(path: &Path) -> impl Fn(E) -> PlotError + '_ {
    move |e| PlotError::Draw {
        path: path.display().to_string(),
        why: e.to_string(),
    }
}

/// A short tick label for `v` on an axis spanning `span` (`−5`, `0.5`, `2.25`,
/// `1.2e−4`: no trailing zeros, minus signs as U+2212), with enough decimals that
/// neighbouring ticks (about a tenth of the span apart) read differently: an R² axis
/// from 0.9971 to 0.9983 needs four, where two would label every tick "1".
pub fn format_tick_in(v: f64, span: f64) -> String {
    let a = v.abs();
    let step = span / 10.0;
    let usable = step.is_finite() && step > 0.0;
    // A tick at zero that the axis arithmetic left at 1e-17 reads "0".
    if usable && a < step * 1e-9 {
        return "0".to_owned();
    }
    if a != 0.0 && a < 0.01 {
        let digits = if usable {
            (a / step).log10().ceil().clamp(1.0, 6.0) as usize
        } else {
            1
        };
        return format!("{v:.digits$e}").replace('-', "\u{2212}");
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
    if text == "-0" {
        "0".into()
    } else {
        // The typographic minus (U+2212, in the bundled font): a hyphen is shorter and
        // thinner, and a row of negative ticks ("-500 -400 -300") reads like ranges.
        text.replace('-', "\u{2212}")
    }
}
