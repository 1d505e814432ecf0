//! Heatmaps of values in [-1, 1] (correlations).

use super::{FONT_FAMILY, PlotError, draw_err, register_font};
use plotters::prelude::*;
use std::path::Path;

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
    let root = super::GlyphFix(BitMapBackend::new(path, (w as u32, h as u32))).into_drawing_area();
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
