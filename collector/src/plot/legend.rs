//! Legends in a strip of their own between a chart's title and its plot, so that a
//! legend never covers data (a box over the plot hid bars and traces wherever the data
//! happened to be). Items flow left to right and wrap to the strip's width.

use super::FONT_FAMILY;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// How an item shows its series.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Swatch {
    /// A filled box (bars, and the page's swatches).
    Box,
    /// A short line (a trace).
    Line,
    /// A dot (points).
    Dot,
}

/// One legend entry.
#[derive(Debug, Clone, PartialEq)]
pub struct Item {
    /// Its text.
    pub label: String,
    /// Its series' colour.
    pub colour: RGBColor,
    /// How it is drawn.
    pub swatch: Swatch,
}

const SWATCH_PX: i32 = 18;
const GAP_PX: i32 = 24;

/// Splits `area` into a legend strip, drawn, and the rest, returned: the items laid
/// out from `left_px` (where the plot's y axis is, so the legend lines up with the
/// plot) in `font_px` text. No items or a size of 0: `area` itself.
///
/// # Errors
/// The backend's.
pub fn split_off<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    items: &[Item],
    font_px: u32,
    left_px: i32,
) -> Result<DrawingArea<DB, Shift>, DrawingAreaErrorKind<DB::ErrorType>> {
    if items.is_empty() || font_px == 0 {
        return Ok(area.clone());
    }
    let style = (FONT_FAMILY, font_px).into_text_style(area);
    let width = area.dim_in_pixel().0 as i32;
    let mut rows: Vec<Vec<(usize, i32)>> = vec![Vec::new()];
    let mut x = left_px;
    for (i, item) in items.iter().enumerate() {
        let w = SWATCH_PX + 6 + area.estimate_text_size(&item.label, &style)?.0 as i32 + GAP_PX;
        if x + w > width && x > left_px {
            rows.push(Vec::new());
            x = left_px;
        }
        if let Some(row) = rows.last_mut() {
            row.push((i, x));
        }
        x += w;
    }
    let row_px = font_px as i32 + 8;
    let (strip, rest) = area.split_vertically(rows.len() as i32 * row_px + 6);
    let half = font_px as i32 / 2;
    for (r, row) in rows.iter().enumerate() {
        let y = 3 + r as i32 * row_px + row_px / 2;
        for &(i, x) in row {
            let item = &items[i];
            match item.swatch {
                Swatch::Box => strip.draw(&Rectangle::new(
                    [(x, y - half + 1), (x + SWATCH_PX - 4, y + half - 1)],
                    item.colour.filled(),
                ))?,
                Swatch::Line => strip.draw(&PathElement::new(
                    vec![(x, y), (x + SWATCH_PX, y)],
                    item.colour.stroke_width(2),
                ))?,
                Swatch::Dot => strip.draw(&Circle::new(
                    (x + SWATCH_PX / 2, y),
                    4,
                    item.colour.filled(),
                ))?,
            }
            let text = (FONT_FAMILY, font_px)
                .into_font()
                .color(&BLACK)
                .pos(Pos::new(HPos::Left, VPos::Center));
            strip.draw(&Text::new(item.label.clone(), (x + SWATCH_PX + 6, y), text))?;
        }
    }
    Ok(rest)
}
