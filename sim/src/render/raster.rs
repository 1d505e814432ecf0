//! Rasterising the lattice's beams and the bubbles: anti-aliased lines blended in lanes of 16 pixels so they vectorise.

use super::*;

/// Blend `c` into pixel `(x, y)` with coverage `a`.
#[inline]
pub(super) fn blend(img: &mut [u8], x: i32, y: i32, c: Rgb, a: f32) {
    if x < 0 || y < 0 || x >= W as i32 || y >= H as i32 || a <= 0.0 {
        return;
    }
    let o = (y as usize * W + x as usize) * 3;
    for i in 0..3 {
        let p = f32::from(img[o + i]);
        // `as u8` saturates; +0.5 rounds.
        img[o + i] = (p + (c[i] - p) * a + 0.5) as u8;
    }
}

/// `x.floor()` as an integer, without the libm call that `floor` is on baseline
/// x86-64 (no SSE4.1). Saturates far outside `i32`, as `as` does.
#[inline]
pub(super) fn floor_i32(x: f32) -> i32 {
    let t = x as i32;
    t.saturating_sub(i32::from((t as f32) > x))
}

/// `x.ceil()` as an integer (see [`floor_i32`]).
#[inline]
pub(super) fn ceil_i32(x: f32) -> i32 {
    let t = x as i32;
    t.saturating_add(i32::from((t as f32) < x))
}

/// Blend `solid` into the pixel at byte offset `o` with coverage `a` in (0, 1), in
/// integers (coverage in 1/256ths): within one level of [`blend`], at a fraction of
/// its cost. The line rasteriser clips to its band, so `o` is always inside it.
#[inline]
pub(super) fn blend_at(img: &mut [u8], o: usize, solid: [u8; 3], a: f32) {
    blend_256(&mut img[o..o + 3], solid, coverage_256(a));
}

/// A coverage in [0, 1] in 1/256ths, as [`blend_at`] works it out (256: the
/// colour itself, 0: no change).
#[inline(always)]
pub(super) fn coverage_256(cov: f32) -> i32 {
    (cov * 256.0) as i32
}

/// Blend `solid` into the pixel `px` (3 bytes) with coverage `a` in 1/256ths.
#[inline(always)]
pub(super) fn blend_256(px: &mut [u8], solid: [u8; 3], a: i32) {
    for (p, &c) in px.iter_mut().zip(&solid) {
        let v = i32::from(*p);
        *p = (v + (((i32::from(c) - v) * a + 128) >> 8)) as u8;
    }
}

/// A thick anti-aliased segment: walks the major axis and, for each column, covers
/// the pixels of the band around the line by their perpendicular distance to it
/// (exact distance to the segment only past its ends). No trigonometry per pixel.
pub(super) fn draw_line(
    band: &mut [u8],
    rows: (i32, i32),
    p0: (f32, f32),
    p1: (f32, f32),
    half_w: f32,
    c: Rgb,
) {
    let (dx, dy) = (p1.0 - p0.0, p1.1 - p0.1);
    if dx.abs() >= dy.abs() {
        draw_line_along::<true>(band, rows, p0, p1, half_w, c);
    } else {
        draw_line_along::<false>(band, rows, p0, p1, half_w, c);
    }
}

/// [`draw_line`] along the x axis or the y axis: one copy of the walk for each, so
/// that the step from one pixel of a column to the next is a constant.
#[inline(always)]
pub(super) fn draw_line_along<const X_MAJOR: bool>(
    band: &mut [u8],
    (y0, y1): (i32, i32),
    p0: (f32, f32),
    p1: (f32, f32),
    half_w: f32,
    c: Rgb,
) {
    let x_major = X_MAJOR;
    // Swap axes so the walk is always along the major axis ("a").
    let (a0, b0, a1, b1) = if x_major {
        (p0.0, p0.1, p1.0, p1.1)
    } else {
        (p0.1, p0.0, p1.1, p1.0)
    };
    let (da, db) = (a1 - a0, b1 - b0);
    let len2 = da * da + db * db;
    let inv_len2 = 1.0 / len2;
    // A segment this short is a dot: its caps measure from its first end.
    let degenerate = len2 <= 1e-12;
    let slope = if da.abs() > 1e-6 { db / da } else { 0.0 };
    let norm = (1.0 + slope * slope).sqrt();
    let inv_norm = 1.0 / norm;
    let reach = half_w + 1.0;
    let across = reach * norm + 0.5;
    let (amin, amax) = (a0.min(a1), a0.max(a1));
    // The band holds rows y0..y1: y is b when x is major, a otherwise.
    let (a_range, b_range) = if x_major {
        ((0, W as i32), (y0, y1))
    } else {
        ((y0, y1), (0, W as i32))
    };
    // Byte offset in the band of (a, b).
    let at = |ia: i32, ib: i32| {
        let (x, y) = if x_major { (ia, ib) } else { (ib, ia) };
        ((y - y0) as usize * W + x as usize) * 3
    };
    let step = if x_major { W * 3 } else { 3 };
    let mut lo = floor_i32(amin - reach).max(a_range.0);
    let mut hi = ceil_i32(amax + reach).min(a_range.1 - 1);
    if x_major {
        // A column reaches the rows within `across` of its centre `bc` (less inside
        // the segment): skip a band the line does not reach, and walk only the
        // columns whose centre is within `m` of the band (the band's rows are b).
        let m = across + 2.0;
        let (y0f, y1f) = (y0 as f32, y1 as f32);
        if b0.max(b1) + m < y0f || b0.min(b1) - m > y1f {
            return;
        }
        if slope.abs() > 1e-3 {
            let (e0, e1) = (a0 + (y0f - m - b0) / slope, a0 + (y1f + m - b0) / slope);
            let (c0, c1) = (e0.min(e1), e0.max(e1));
            // Past its ends a column's centre stays at the end's: keep the caps then.
            if c0 > amin {
                lo = lo.max(floor_i32(c0 - 1.0));
            }
            if c1 < amax {
                hi = hi.min(ceil_i32(c1 + 1.0));
            }
        }
    }
    let edge = half_w + 0.5;
    // Distance (and its square) from which coverage rounds to no change (edge ≥ 1).
    let no_change = edge - 0.5 / 256.0;
    let no_change_2 = no_change * no_change;
    // A pixel the band covers fully takes the colour itself, without arithmetic.
    let solid = c.map(|v| (v + 0.5) as u8);
    // A row of solid pixels, copied whole into a y-major line's full run.
    const RUN_PX: usize = 16;
    let mut run = [0u8; 3 * RUN_PX];
    for px in run.chunks_exact_mut(3) {
        px.copy_from_slice(&solid);
    }
    for ia in lo..=hi {
        let ac = ia as f32 + 0.5;
        let inside = ac >= amin && ac <= amax;
        if inside {
            let bc = b0 + (ac - a0) * slope;
            // Across the line: pixels nearer than `edge − 1` (perpendicular) are
            // covered fully, those nearer than `edge` partly, the rest not at all.
            let span = edge * norm;
            let blo = floor_i32(bc - span - 0.5).max(b_range.0);
            let bhi = ceil_i32(bc + span - 0.5).min(b_range.1 - 1);
            if blo > bhi {
                continue;
            }
            let first = at(ia, blo);
            let partial = |band: &mut [u8], ib: i32| {
                let d = (ib as f32 + 0.5 - bc).abs() * inv_norm;
                let cov = (edge - d).clamp(0.0, 1.0);
                if cov > 0.0 {
                    blend_at(band, first + (ib - blo) as usize * step, solid, cov);
                }
            };
            let full = (edge - 1.0) * norm;
            let flo = ceil_i32(bc - full - 0.5).max(blo);
            let fhi = floor_i32(bc + full - 0.5).min(bhi);
            if flo <= fhi {
                (blo..flo).for_each(|ib| partial(band, ib));
                // The fully covered run, one bounds check for all of it: down a
                // column a row apart (x-major), or along a row in one copy.
                let o = first + (flo - blo) as usize * step;
                let n = (fhi - flo) as usize + 1;
                if X_MAJOR {
                    for px in band[o..o + (n - 1) * step + 3].chunks_mut(step) {
                        px[..3].copy_from_slice(&solid);
                    }
                } else if n <= RUN_PX {
                    band[o..o + 3 * n].copy_from_slice(&run[..3 * n]);
                } else {
                    for px in band[o..o + 3 * n].chunks_exact_mut(3) {
                        px.copy_from_slice(&solid);
                    }
                }
                (fhi + 1..=bhi).for_each(|ib| partial(band, ib));
            } else {
                (blo..=bhi).for_each(|ib| partial(band, ib));
            }
            continue;
        }
        // Past an end. A pixel `edge − ½⁄256` or farther from the segment gets a
        // coverage under 1⁄256, which rounds to no change; a column that far beyond
        // the end is skipped whole (every point of the segment is at least that far
        // along the walk).
        if (amin - ac).max(ac - amax) >= no_change {
            continue;
        }
        let bc = b0 + (ac.clamp(amin, amax) - a0) * slope;
        let blo = floor_i32(bc - across).max(b_range.0);
        let bhi = ceil_i32(bc + across).min(b_range.1 - 1);
        if blo > bhi {
            continue;
        }
        blend_lanes(band, at(ia, blo), step, (blo, bhi), solid, |ib| {
            let pb = ib as f32 + 0.5;
            let t = if degenerate {
                0.0
            } else {
                (((ac - a0) * da + (pb - b0) * db) * inv_len2).clamp(0.0, 1.0)
            };
            let (ea, eb) = (a0 + t * da - ac, b0 + t * db - pb);
            let d2 = ea * ea + eb * eb;
            if d2 >= no_change_2 {
                0
            } else {
                coverage_256((edge - d2.sqrt()).clamp(0.0, 1.0))
            }
        });
    }
}

/// Coverages [`blend_lanes`] works out together.
pub(super) const LANES: usize = 16;

/// Blend `solid` into the pixels `blo..=bhi` of one column, `step` bytes apart from
/// byte `first`, pixel `ib` with coverage `coverage(ib)` in 1/256ths (256: the
/// colour itself). The coverages come [`LANES`] at a time, with no branch between
/// pixels, so the compiler works them out side by side (a cap's pixel takes a
/// projection, a square root and several compares); only the pixels they touch are
/// then blended. The same bytes as [`blend_at`] pixel by pixel.
#[inline(always)]
pub(super) fn blend_lanes(
    band: &mut [u8],
    first: usize,
    step: usize,
    (blo, bhi): (i32, i32),
    solid: [u8; 3],
    coverage: impl Fn(i32) -> i32,
) {
    let mut from = blo;
    while from <= bhi {
        let n = ((bhi - from) as usize + 1).min(LANES);
        let mut lanes = [0i32; LANES];
        for (k, a) in lanes.iter_mut().enumerate() {
            *a = coverage(from + k as i32);
        }
        let o = first + (from - blo) as usize * step;
        let pixels = band[o..o + (n - 1) * step + 3].chunks_mut(step);
        for (px, &a) in pixels.zip(&lanes[..n]) {
            if a != 0 {
                blend_256(&mut px[..3], solid, a);
            }
        }
        from += LANES as i32;
    }
}

/// A bubble: a bright anti-aliased rim with a faint fill, on the rows `y0..y1` of
/// the frame that `band` holds.
pub(super) fn draw_bubble(band: &mut [u8], (y0, y1): (usize, usize), cx: f32, cy: f32, r: f32) {
    let rim = [235.0, 245.0, 255.0];
    let lo_x = (cx - r - 2.0).floor() as i32;
    let hi_x = (cx + r + 2.0).ceil() as i32;
    let lo_y = ((cy - r - 2.0).floor() as i32).max(y0 as i32);
    let hi_y = ((cy + r + 2.0).ceil() as i32).min(y1 as i32 - 1);
    for y in lo_y..=hi_y {
        for x in lo_x..=hi_x {
            let (ddx, ddy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
            let d = (ddx * ddx + ddy * ddy).sqrt();
            let ring = (1.2 - (d - r).abs()).clamp(0.0, 1.0) * 0.8;
            let fill = if d < r { 0.12 } else { 0.0 };
            blend(band, x, y - y0 as i32, rim, ring.max(fill));
        }
    }
}
