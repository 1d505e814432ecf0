//! Text on the PNG charts, each glyph drawn where the font puts it.
//!
//! plotters 0.3.7 rasterises text through ab_glyph but draws every glyph's ink from
//! the left edge of its advance, leaving out the glyph's left side bearing: its
//! `style/font/ab_glyph.rs` adds the pen position to the outline's pixels but never
//! `px_bounds().min.x` (its main branch still does). In the bundled monospaced font a
//! narrow glyph then sits against the glyph before it and leaves a gap after: the
//! decimal point of "0.5" merges into the 0 ("0 5"), and "N·mm" reads "N- mm" in
//! `dataset stats`' histograms. [`GlyphFix`] wraps a bitmap backend and draws text
//! itself, bearing included; everything else goes to the wrapped backend unchanged.
//! The SVG charts need none of this: their text is SVG text, laid out by the browser.

use plotters::prelude::DrawingBackend;
use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind,
};

use ab_glyph::{Font as _, FontRef, ScaleFont as _};

/// A backend whose text is drawn with each glyph's left side bearing (see the module).
/// Every chart's text is in the bundled font ([`super::FONT`]).
#[derive(Debug)]
pub struct GlyphFix<B>(pub B);

type Failed<B> = DrawingErrorKind<<B as DrawingBackend>::ErrorType>;

impl<B: DrawingBackend> DrawingBackend for GlyphFix<B> {
    type ErrorType = B::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.0.get_size()
    }
    fn ensure_prepared(&mut self) -> Result<(), Failed<B>> {
        self.0.ensure_prepared()
    }
    fn present(&mut self) -> Result<(), Failed<B>> {
        self.0.present()
    }
    fn draw_pixel(&mut self, point: BackendCoord, color: BackendColor) -> Result<(), Failed<B>> {
        self.0.draw_pixel(point, color)
    }
    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), Failed<B>> {
        self.0.draw_line(from, to, style)
    }
    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), Failed<B>> {
        self.0.draw_rect(upper_left, bottom_right, style, fill)
    }
    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), Failed<B>> {
        self.0.draw_path(path, style)
    }
    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), Failed<B>> {
        self.0.draw_circle(center, radius, style, fill)
    }
    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), Failed<B>> {
        self.0.fill_polygon(vert, style)
    }
    fn estimate_text_size<T: BackendTextStyle>(
        &self,
        text: &str,
        style: &T,
    ) -> Result<(u32, u32), Failed<B>> {
        self.0.estimate_text_size(text, style)
    }
    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        size: (u32, u32),
        src: &[u8],
    ) -> Result<(), Failed<B>> {
        self.0.blit_bitmap(pos, size, src)
    }

    /// plotters' own text drawing (layout box, anchor, rotation), with the glyphs
    /// rasterised here.
    fn draw_text<T: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &T,
        pos: BackendCoord,
    ) -> Result<(), Failed<B>> {
        let color = style.color();
        if color.alpha == 0.0 {
            return Ok(());
        }
        let ((min_x, min_y), (max_x, max_y)) = style
            .layout_box(text)
            .map_err(|e| DrawingErrorKind::FontError(Box::new(e)))?;
        let (width, height) = (max_x - min_x, max_y - min_y);
        let dx = match style.anchor().h_pos {
            HPos::Left => 0,
            HPos::Right => -width,
            HPos::Center => -width / 2,
        };
        let dy = match style.anchor().v_pos {
            VPos::Top => 0,
            VPos::Center => -height / 2,
            VPos::Bottom => -height,
        };
        let trans = style.transform();
        let (w, h) = self.get_size();
        for (x, y, coverage) in glyph_pixels(text, style.size())
            .map_err(|e| DrawingErrorKind::FontError(Box::new(e)))?
        {
            let (x, y) = trans.transform(x + dx - min_x, y + dy - min_y);
            let (x, y) = (pos.0 + x, pos.1 + y);
            if x >= 0 && x < w as i32 && y >= 0 && y < h as i32 {
                self.0.draw_pixel(
                    (x, y),
                    BackendColor {
                        alpha: color.alpha * f64::from(coverage),
                        rgb: color.rgb,
                    },
                )?;
            }
        }
        Ok(())
    }
}

/// The pixels of `text` at `size` px in the bundled font, `(x, y, coverage)` from the
/// text's origin: plotters' placement (pen advance and kerning along x, the glyph's
/// top at `size / 2 + px_bounds().min.y`) plus each glyph's left side bearing.
///
/// # Errors
/// The bundled font does not read (never for the font the build embeds).
pub fn glyph_pixels(text: &str, size: f64) -> Result<Vec<(i32, i32, f32)>, ab_glyph::InvalidFont> {
    let font = FontRef::try_from_slice(super::FONT)?;
    let scaled = font.as_scaled(size as f32);
    let mut out = Vec::new();
    let mut pen = 0f32;
    let mut prev = None;
    for c in text.chars() {
        let id = scaled.glyph_id(c);
        if let Some(p) = prev {
            pen += scaled.kern(p, id);
        }
        prev = Some(id);
        if let Some(outline) = scaled.outline_glyph(scaled.scaled_glyph(c)) {
            let bounds = outline.px_bounds();
            let x0 = (pen + bounds.min.x).round() as i32;
            let y0 = ((size as f32) / 2.0 + bounds.min.y) as i32;
            outline.draw(|x, y, coverage| {
                if coverage > 0.0 {
                    out.push((x0 + x as i32, y0 + y as i32, coverage));
                }
            });
        }
        pen += scaled.h_advance(id);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The columns holding ink, as runs `[first, last]`.
    fn ink_runs(pixels: &[(i32, i32, f32)]) -> Vec<(i32, i32)> {
        let mut cols: Vec<i32> = pixels.iter().filter(|p| p.2 > 0.25).map(|p| p.0).collect();
        cols.sort_unstable();
        cols.dedup();
        let mut runs: Vec<(i32, i32)> = Vec::new();
        for c in cols {
            match runs.last_mut() {
                Some(r) if r.1 + 1 == c => r.1 = c,
                _ => runs.push((c, c)),
            }
        }
        runs
    }

    #[test]
    fn a_decimal_point_and_a_middle_dot_stand_apart_from_their_neighbours() {
        // In "0.5" the point is its own run of ink, in the middle of its cell, with
        // clear columns on both sides (plotters' own placement merges it into the 0).
        let runs = ink_runs(&glyph_pixels("0.5", 13.0).expect("the bundled font"));
        assert_eq!(runs.len(), 3, "0, point, 5 apart: {runs:?}");
        let font = FontRef::try_from_slice(super::super::FONT).expect("font");
        let cell = font.as_scaled(13.0).h_advance(font.glyph_id('.'));
        let point_centre = f64::from(runs[1].0 + runs[1].1) / 2.0;
        assert!(
            (point_centre - 1.5 * f64::from(cell)).abs() < 1.5,
            "the point sits mid-cell: {runs:?}, cell {cell}"
        );
        // "N·mm": the dot is apart from the N and from the m.
        let runs = ink_runs(&glyph_pixels("N·m", 13.0).expect("font"));
        assert_eq!(runs.len(), 3, "{runs:?}");
        // Empty text draws nothing; a size of 0 neither panics nor draws much.
        assert!(glyph_pixels("", 13.0).expect("font").is_empty());
        assert!(glyph_pixels("0.5", 0.0).expect("font").len() < 4);
    }
}
