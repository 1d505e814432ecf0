//! A 2-D convolution's forward pass and gradients on NCHW `f32` buffers, as im2col
//! and one matrix product per chunk of the batch, the chunks on rayon's threads.
//!
//! The batch is cut into as many chunks as rayon has threads; each chunk's patches
//! sit in one matrix `[c_in·kh·kw, images·h_out·w_out]`, so the three products of a
//! convolution (output, weight gradient, input gradient) are each one large `gemm`
//! per chunk rather than many small ones. The weight gradients of the chunks are
//! added in chunk order, so a run is repeatable for a given thread count.

use rayon::prelude::*;

use super::gemm::{View, matmul};

/// The shape of one convolution `x [batch, c_in, h_in, w_in] → y [batch, c_out,
/// h_out, w_out]` with a weight `[c_out, c_in, kh, kw]`; dilation 1, one group.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Geometry {
    pub batch: usize,
    pub c_in: usize,
    pub c_out: usize,
    pub kernel: [usize; 2],
    pub stride: [usize; 2],
    pub pad: [usize; 2],
    pub in_hw: [usize; 2],
    pub out_hw: [usize; 2],
}

impl Geometry {
    /// The geometry of a convolution over `in_hw`, its output size worked out; `None`
    /// when a size or stride is zero or the padded input is smaller than the kernel.
    pub(crate) fn new(
        [batch, c_in, c_out]: [usize; 3],
        kernel: [usize; 2],
        stride: [usize; 2],
        pad: [usize; 2],
        in_hw: [usize; 2],
    ) -> Option<Self> {
        let out = |d: usize| {
            let span = in_hw[d].checked_add(2 * pad[d])?.checked_sub(kernel[d])?;
            (stride[d] > 0 && kernel[d] > 0).then(|| span / stride[d] + 1)
        };
        let g = Self {
            batch,
            c_in,
            c_out,
            kernel,
            stride,
            pad,
            in_hw,
            out_hw: [out(0)?, out(1)?],
        };
        (g.x_len() > 0 && g.y_len() > 0 && g.w_len() > 0).then_some(g)
    }

    /// Rows of the patch matrix: inputs to one output element.
    pub(crate) fn patch(&self) -> usize {
        self.c_in * self.kernel[0] * self.kernel[1]
    }
    fn in_px(&self) -> usize {
        self.in_hw[0] * self.in_hw[1]
    }
    fn out_px(&self) -> usize {
        self.out_hw[0] * self.out_hw[1]
    }
    pub(crate) fn x_len(&self) -> usize {
        self.batch * self.c_in * self.in_px()
    }
    pub(crate) fn y_len(&self) -> usize {
        self.batch * self.c_out * self.out_px()
    }
    pub(crate) fn w_len(&self) -> usize {
        self.c_out * self.patch()
    }

    /// Images per chunk: the batch over rayon's threads.
    fn per_chunk(&self) -> usize {
        self.batch
            .div_ceil(rayon::current_num_threads().max(1))
            .max(1)
    }

    /// Columns `lo..hi` of a kernel row's output positions whose input column
    /// `o·stride + j − pad` lies inside `0..w_in`, and the first such input column.
    fn valid_cols(&self, j: usize) -> (usize, usize, usize) {
        let (s, p, w_in, w_out) = (self.stride[1], self.pad[1], self.in_hw[1], self.out_hw[1]);
        let lo = p.saturating_sub(j).div_ceil(s).min(w_out);
        let hi = if w_in + p > j {
            ((w_in + p - j - 1) / s + 1).min(w_out)
        } else {
            0
        };
        let hi = hi.max(lo);
        (lo, hi, (lo * s + j).saturating_sub(p))
    }

    /// The input row of output row `o` at kernel row `i`, if inside the image.
    fn in_row(&self, o: usize, i: usize) -> Option<usize> {
        (o * self.stride[0] + i)
            .checked_sub(self.pad[0])
            .filter(|&r| r < self.in_hw[0])
    }

    /// The patch matrix `[patch, images·out_px]` of `images` consecutive images of `x`.
    fn im2col(&self, x: &[f32], images: usize, col: &mut [f32]) {
        let (kh, kw) = (self.kernel[0], self.kernel[1]);
        let (n, out_px, in_px) = (images * self.out_px(), self.out_px(), self.in_px());
        let (h_out, w_out, w_in, s) = (
            self.out_hw[0],
            self.out_hw[1],
            self.in_hw[1],
            self.stride[1],
        );
        for c in 0..self.c_in {
            for i in 0..kh {
                for j in 0..kw {
                    let row = &mut col[((c * kh + i) * kw + j) * n..][..n];
                    let (lo, hi, first) = self.valid_cols(j);
                    for b in 0..images {
                        let image = &x[(b * self.c_in + c) * in_px..][..in_px];
                        for o in 0..h_out {
                            let dst = &mut row[b * out_px + o * w_out..][..w_out];
                            let Some(r) = self.in_row(o, i) else {
                                dst.fill(0.0);
                                continue;
                            };
                            dst[..lo].fill(0.0);
                            dst[hi..].fill(0.0);
                            if hi == lo {
                                continue;
                            }
                            let src = &image[r * w_in + first..(r + 1) * w_in];
                            if s == 1 {
                                dst[lo..hi].copy_from_slice(&src[..hi - lo]);
                            } else {
                                for (d, v) in dst[lo..hi].iter_mut().zip(src.iter().step_by(s)) {
                                    *d = *v;
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// Adds the patch matrix `col` back onto `images` consecutive images of `x` (the
    /// transpose of [`Self::im2col`]); `x` is zeroed first.
    fn col2im(&self, col: &[f32], images: usize, x: &mut [f32]) {
        x.fill(0.0);
        let (kh, kw) = (self.kernel[0], self.kernel[1]);
        let (n, out_px, in_px) = (images * self.out_px(), self.out_px(), self.in_px());
        let (h_out, w_out, w_in, s) = (
            self.out_hw[0],
            self.out_hw[1],
            self.in_hw[1],
            self.stride[1],
        );
        for c in 0..self.c_in {
            for i in 0..kh {
                for j in 0..kw {
                    let row = &col[((c * kh + i) * kw + j) * n..][..n];
                    let (lo, hi, first) = self.valid_cols(j);
                    for b in 0..images {
                        let image = &mut x[(b * self.c_in + c) * in_px..][..in_px];
                        for o in 0..h_out {
                            let Some(r) = self.in_row(o, i).filter(|_| hi > lo) else {
                                continue;
                            };
                            let src = &row[b * out_px + o * w_out..][lo..hi];
                            let dst = &mut image[r * w_in + first..(r + 1) * w_in];
                            for (d, v) in dst.iter_mut().step_by(s).zip(src) {
                                *d += *v;
                            }
                        }
                    }
                }
            }
        }
    }
}

/// `y [images, c, px]` ↔ `m [c, images·px]`.
fn to_channel_major(y: &[f32], images: usize, c: usize, px: usize, m: &mut [f32]) {
    let n = images * px;
    for b in 0..images {
        for ch in 0..c {
            m[ch * n + b * px..][..px].copy_from_slice(&y[(b * c + ch) * px..][..px]);
        }
    }
}

/// The convolution's output, plus `bias[c_out]` when given.
pub(crate) fn forward(g: &Geometry, x: &[f32], w: &[f32], bias: Option<&[f32]>) -> Vec<f32> {
    let (per, patch, out_px) = (g.per_chunk(), g.patch(), g.out_px());
    let mut y = vec![0.0f32; g.y_len()];
    y.par_chunks_mut(per * g.c_out * out_px)
        .zip(x.par_chunks(per * g.c_in * g.in_px()))
        .for_each(|(y, x)| {
            let images = x.len() / (g.c_in * g.in_px());
            let n = images * out_px;
            let mut col = vec![0.0f32; patch * n];
            g.im2col(x, images, &mut col);
            let mut m = vec![0.0f32; g.c_out * n];
            matmul(
                &mut m,
                false,
                View::rows(w, g.c_out, patch),
                View::rows(&col, patch, n),
            );
            for b in 0..images {
                for ch in 0..g.c_out {
                    let src = &m[ch * n + b * out_px..][..out_px];
                    let dst = &mut y[(b * g.c_out + ch) * out_px..][..out_px];
                    let add = bias.map_or(0.0, |bias| bias[ch]);
                    for (d, v) in dst.iter_mut().zip(src) {
                        *d = v + add;
                    }
                }
            }
        });
    y
}

/// Gradients of a convolution with respect to its weight and (when `want_x`) its
/// input, from the output's gradient `dy`; [`input_gradient`] for the input's alone.
pub(crate) fn backward(
    g: &Geometry,
    x: &[f32],
    w: &[f32],
    dy: &[f32],
    want_x: bool,
) -> (Vec<f32>, Option<Vec<f32>>) {
    let (per, patch, out_px) = (g.per_chunk(), g.patch(), g.out_px());
    let chunk = |x_chunk: &[f32], dy: &[f32], dx: Option<&mut [f32]>| {
        let images = dy.len() / (g.c_out * out_px);
        let n = images * out_px;
        let mut m = vec![0.0f32; g.c_out * n];
        to_channel_major(dy, images, g.c_out, out_px, &mut m);
        let dy = View::rows(&m, g.c_out, n);
        let mut col = vec![0.0f32; patch * n];
        g.im2col(x_chunk, images, &mut col);
        let mut dw = vec![0.0f32; g.w_len()];
        matmul(&mut dw, false, dy, View::rows(&col, patch, n).t());
        if let Some(dx) = dx {
            scatter_input_gradient(g, w, dy, images, dx);
        }
        dw
    };
    let (x_step, y_step) = (per * g.c_in * g.in_px(), per * g.c_out * out_px);
    let (dx, parts): (Option<Vec<f32>>, Vec<Vec<f32>>) = if want_x {
        let mut dx = vec![0.0f32; g.x_len()];
        let parts = dx
            .par_chunks_mut(x_step)
            .zip(x.par_chunks(x_step).zip(dy.par_chunks(y_step)))
            .map(|(dx, (x, dy))| chunk(x, dy, Some(dx)))
            .collect();
        (Some(dx), parts)
    } else {
        let parts = x
            .par_chunks(x_step)
            .zip(dy.par_chunks(y_step))
            .map(|(x, dy)| chunk(x, dy, None))
            .collect();
        (None, parts)
    };
    let mut parts = parts.into_iter();
    let mut dw = parts.next().unwrap_or_else(|| vec![0.0; g.w_len()]);
    for part in parts {
        for (a, b) in dw.iter_mut().zip(part) {
            *a += b;
        }
    }
    (dw, dx)
}

/// The gradient of the input alone: the transposed convolution of `dy` (what a
/// transposed convolution's forward pass computes).
pub(crate) fn input_gradient(g: &Geometry, w: &[f32], dy: &[f32]) -> Vec<f32> {
    let (per, out_px, in_px) = (g.per_chunk(), g.out_px(), g.in_px());
    let mut dx = vec![0.0f32; g.x_len()];
    dx.par_chunks_mut(per * g.c_in * in_px)
        .zip(dy.par_chunks(per * g.c_out * out_px))
        .for_each(|(dx, dy)| {
            let images = dy.len() / (g.c_out * out_px);
            let n = images * out_px;
            let mut m = vec![0.0f32; g.c_out * n];
            to_channel_major(dy, images, g.c_out, out_px, &mut m);
            scatter_input_gradient(g, w, View::rows(&m, g.c_out, n), images, dx);
        });
    dx
}

/// `images` images' input gradient from their output gradient `dy [c_out, images·out_px]`.
fn scatter_input_gradient(g: &Geometry, w: &[f32], dy: View<'_>, images: usize, dx: &mut [f32]) {
    let mut col = vec![0.0f32; g.patch() * images * g.out_px()];
    matmul(&mut col, false, View::rows(w, g.c_out, g.patch()).t(), dy);
    g.col2im(&col, images, dx);
}

/// Per-channel sums of an NCHW buffer `[batch, c, px]` (a bias's gradient), summed
/// image by image in order.
pub(crate) fn channel_sums(t: &[f32], batch: usize, c: usize, px: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; c];
    for b in 0..batch {
        for (ch, o) in out.iter_mut().enumerate() {
            *o += t[(b * c + ch) * px..][..px].iter().sum::<f32>();
        }
    }
    out
}
