//! A tare laid out once for a frame size, so that a control loop pays per frame only
//! the reads and the multiply-adds. The scale about the principal point is separable:
//! each column's horizontal read and each row's vertical read are tabled once; each
//! pixel's gain and offset per channel (the gain map folded in) too. Computing all of
//! it per frame took about 25 ms on a 640×480 frame (2-core AMD EPYC: `grasp trials`
//! ran 26.6 ms a cycle with the tare against 1.2 ms without); `cargo bench -p
//! softtouch-trainer --bench inference -- tare` measures both ways.

use super::{ImageTare, TareError, check_frame};
use crate::preprocess::Fork;

/// One column's or row's bilinear read.
#[derive(Debug, Clone, Copy)]
struct Axis {
    /// Byte offset of the first source column (× 3) or row (× width × 3).
    at: usize,
    /// Bytes to the next one (0 at the last).
    next: usize,
    /// Fraction towards it.
    frac: f32,
    /// Whether the source lies inside the frame along this axis (else black).
    inside: bool,
}

/// An [`ImageTare`] for frames of one size.
#[derive(Debug, Clone)]
pub struct PreparedTare {
    width: usize,
    height: usize,
    columns: Vec<Axis>,
    rows: Vec<Axis>,
    /// Per pixel: the multiplier of each channel, then its addend.
    coeffs: Vec<[f32; 6]>,
}

impl PreparedTare {
    /// Lays `tare` out for `width × height` frames.
    ///
    /// # Errors
    /// An empty frame, a tare whose numbers are not finite, a gain map fitted on
    /// frames of another size.
    pub fn new(tare: &ImageTare, width: usize, height: usize) -> Result<Self, TareError> {
        check_frame(
            width,
            height,
            width.saturating_mul(height).saturating_mul(3),
        )?;
        tare.check()?;
        let map = match &tare.gain_map {
            Some(m) => Some(m.plane(width, height)?),
            None => None,
        };
        let axis = |s: f64, n: usize, stride: usize| {
            let len = n as f64;
            let inside = s >= -0.5 && s <= len - 0.5;
            let c = if inside { s.clamp(0.0, len - 1.0) } else { 0.0 };
            let i0 = c.floor() as usize;
            Axis {
                at: i0 * stride,
                next: if i0 + 1 < n { stride } else { 0 },
                frac: (c - i0 as f64) as f32,
                inside,
            }
        };
        // `source` maps x and y apart: its x does not depend on y, nor its y on x.
        let columns = (0..width)
            .map(|x| axis(tare.source(x, 0, 1.0).0, width, 3))
            .collect();
        let rows = (0..height)
            .map(|y| axis(tare.source(0, y, 1.0).1, height, width * 3))
            .collect();
        let mut coeffs = Vec::with_capacity(width * height);
        for y in 0..height {
            for x in 0..width {
                let m = map.as_ref().map_or([1.0; 3], |(p, k)| {
                    p.bilinear((x as f64 + 0.5) / k - 0.5, (y as f64 + 0.5) / k - 0.5)
                });
                let mut c = [0f32; 6];
                for ch in 0..3 {
                    c[ch] = (tare.gain[ch] * f64::from(m[ch])) as f32;
                    c[3 + ch] = (tare.offset[ch] * f64::from(m[ch])) as f32;
                }
                coeffs.push(c);
            }
        }
        Ok(Self {
            width,
            height,
            columns,
            rows,
            coeffs,
        })
    }

    /// The frame size it was laid out for.
    #[must_use]
    pub const fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Corrects a frame of its size into `out` (resized to fit).
    ///
    /// # Errors
    /// A frame of another size, or a buffer that is not its size.
    pub fn apply_into(
        &self,
        width: usize,
        height: usize,
        rgb: &[u8],
        out: &mut Vec<u8>,
    ) -> Result<(), TareError> {
        self.apply_on(width, height, rgb, out, None)
    }

    /// [`Self::apply_into`], the lower half of the rows through `fork` (on a second
    /// core) where one is given; the same bytes either way.
    ///
    /// # Errors
    /// A frame of another size, or a buffer that is not its size.
    pub fn apply_on(
        &self,
        width: usize,
        height: usize,
        rgb: &[u8],
        out: &mut Vec<u8>,
        fork: Option<&dyn Fork>,
    ) -> Result<(), TareError> {
        check_frame(width, height, rgb.len())?;
        if (width, height) != (self.width, self.height) {
            return Err(TareError::Size(format!(
                "a {width}×{height} frame: the tare was laid out for {}×{}",
                self.width, self.height
            )));
        }
        out.resize(rgb.len(), 0);
        match fork {
            Some(fork) if height >= 2 => {
                let half = height / 2;
                let (top, bottom) = out.split_at_mut(half * width * 3);
                fork.fork(&mut || self.rows_into(rgb, top, 0), &mut || {
                    self.rows_into(rgb, bottom, half)
                });
            }
            _ => self.rows_into(rgb, out, 0),
        }
        Ok(())
    }

    /// Rows from `first` on, into `out` (which holds those rows' bytes).
    fn rows_into(&self, rgb: &[u8], out: &mut [u8], first: usize) {
        // Rounded by adding a half and truncating (the value is clamped to 0–255
        // first): `f32::round` is a library call on a baseline x86-64 target, three a
        // pixel.
        let to_u8 = |v: f32| (v.clamp(0.0, 255.0) + 0.5) as u8;
        let pixel = |at: usize| -> [f32; 3] {
            rgb.get(at..at + 3).map_or([0.0; 3], |p| {
                [f32::from(p[0]), f32::from(p[1]), f32::from(p[2])]
            })
        };
        let row_bytes = self.width * 3;
        for (dy, (out_row, row)) in out
            .chunks_exact_mut(row_bytes)
            .zip(&self.rows[first..])
            .enumerate()
        {
            let coeffs = &self.coeffs[(first + dy) * self.width..(first + dy + 1) * self.width];
            for ((o, col), c) in out_row.chunks_exact_mut(3).zip(&self.columns).zip(coeffs) {
                if !(row.inside && col.inside) {
                    for ch in 0..3 {
                        o[ch] = to_u8(c[3 + ch]);
                    }
                    continue;
                }
                let a = row.at + col.at;
                let (p00, p01) = (pixel(a), pixel(a + col.next));
                let (p10, p11) = (pixel(a + row.next), pixel(a + row.next + col.next));
                for ch in 0..3 {
                    let top = p00[ch] + (p01[ch] - p00[ch]) * col.frac;
                    let bottom = p10[ch] + (p11[ch] - p10[ch]) * col.frac;
                    let v = top + (bottom - top) * row.frac;
                    o[ch] = to_u8(c[ch] * v + c[3 + ch]);
                }
            }
        }
    }
}
