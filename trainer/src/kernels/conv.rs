//! A 2-D convolution's forward pass and gradients on NCHW `f32` buffers, as im2col
//! and matrix products over blocks of images, the batch split over rayon's threads.
//!
//! The batch is cut into as many chunks as rayon has threads, and each chunk into
//! blocks of images whose patches sit in one matrix `[c_in·kh·kw, images·h_out·w_out]`
//! of about [`BLOCK_VALUES`]; the three products of a convolution (output, weight
//! gradient, input gradient) are then one `gemm` each per block rather than one per
//! image. A weight gradient is summed block after block and chunk after chunk, so a
//! run repeats exactly for a given thread count.

use std::cell::RefCell;

use rayon::prelude::*;

use super::gemm::{View, matmul};

/// Values of a block's patch matrix (256 KiB of f32): a quarter of the 1 MiB L2
/// cache per core of the machine this was measured on, so that the matrix, the
/// output block and `gemm`'s packed panels fit together (+5–10 % against one block
/// per chunk there). A smaller cache gives the same results, maybe more slowly; no
/// other machine was measured.
const BLOCK_VALUES: usize = 1 << 16;

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

    /// Images per block within a chunk: as many as keep a block's patch matrix near
    /// [`BLOCK_VALUES`], so that it is still in the core's cache when `gemm` reads it.
    fn block(&self) -> usize {
        (BLOCK_VALUES / (self.patch() * self.out_px()).max(1)).max(1)
    }

    /// Images per chunk: the batch over rayon's threads.
    fn per_chunk(&self) -> usize {
        self.batch
            .div_ceil(rayon::current_num_threads().max(1))
            .max(1)
    }

    /// For image `b`'s channel `c`: each kernel tap's row start in a patch matrix of
    /// `n` columns, and the tap's first value in [`Phases`] of `layout`.
    fn taps(
        &self,
        layout: PhaseLayout,
        c: usize,
        b: usize,
        n: usize,
    ) -> impl Iterator<Item = (usize, usize)> {
        let ([kh, kw], out_px) = (self.kernel, self.out_px());
        (0..kh).flat_map(move |i| {
            (0..kw).map(move |j| (((c * kh + i) * kw + j) * n + b * out_px, layout.at(i, j)))
        })
    }

    /// The patch matrix `[patch, images·out_px]` of `images` consecutive images of `x`.
    ///
    /// Each input plane is copied once into a zero-padded plane split by phase of the
    /// stride ([`Phases`]); every patch row of it is then a copy of `w_out`
    /// contiguous values, of a length known at compile time for the sizes the models
    /// use. (Rows of 4 to 32 values: per-value bounds tests, strided gathers and a
    /// `memcpy` call per row each took about 15 % of a training step.)
    fn im2col(&self, x: &[f32], images: usize, col: &mut [f32]) {
        let (n, out_px, in_px, w_out) = (
            images * self.out_px(),
            self.out_px(),
            self.in_px(),
            self.out_hw[1],
        );
        let mut phases = Phases::new(self);
        for (c, b) in (0..self.c_in).flat_map(|c| (0..images).map(move |b| (c, b))) {
            phases.load(&x[(b * self.c_in + c) * in_px..][..in_px]);
            for (start, tap) in self.taps(phases.layout, c, b, n) {
                for (o, dst) in col[start..][..out_px].chunks_exact_mut(w_out).enumerate() {
                    copy_row(dst, &phases.values[tap + o * phases.layout.cols..]);
                }
            }
        }
    }

    /// The images whose patch matrix is `col` (the transpose of [`Self::im2col`]):
    /// each patch value added back where it came from.
    fn col2im(&self, col: &[f32], images: usize, x: &mut [f32]) {
        let (n, out_px, in_px, w_out) = (
            images * self.out_px(),
            self.out_px(),
            self.in_px(),
            self.out_hw[1],
        );
        let mut phases = Phases::new(self);
        for (c, b) in (0..self.c_in).flat_map(|c| (0..images).map(move |b| (c, b))) {
            phases.values.fill(0.0);
            for (start, tap) in self.taps(phases.layout, c, b, n) {
                for (o, src) in col[start..][..out_px].chunks_exact(w_out).enumerate() {
                    add_row(&mut phases.values[tap + o * phases.layout.cols..], src);
                }
            }
            phases.store(&mut x[(b * self.c_in + c) * in_px..][..in_px]);
        }
    }
}

/// `dst = src[..dst.len()]`, inlined for the row lengths of the models.
fn copy_row(dst: &mut [f32], src: &[f32]) {
    fn fixed<const N: usize>(dst: &mut [f32], src: &[f32]) {
        if let (Some(d), Some(s)) = (dst.first_chunk_mut::<N>(), src.first_chunk::<N>()) {
            *d = *s;
        }
    }
    match dst.len() {
        4 => fixed::<4>(dst, src),
        8 => fixed::<8>(dst, src),
        16 => fixed::<16>(dst, src),
        32 => fixed::<32>(dst, src),
        len => dst.copy_from_slice(&src[..len]),
    }
}

/// `dst += src`, inlined for the row lengths of the models.
fn add_row(dst: &mut [f32], src: &[f32]) {
    fn fixed<const N: usize>(dst: &mut [f32], src: &[f32]) {
        if let (Some(d), Some(s)) = (dst.first_chunk_mut::<N>(), src.first_chunk::<N>()) {
            for (d, s) in d.iter_mut().zip(s) {
                *d += s;
            }
        }
    }
    match src.len() {
        4 => fixed::<4>(dst, src),
        8 => fixed::<8>(dst, src),
        16 => fixed::<16>(dst, src),
        32 => fixed::<32>(dst, src),
        _ => dst.iter_mut().zip(src).for_each(|(d, s)| *d += s),
    }
}

/// One input plane, zero-padded by `pad` and split by phase of the stride: padded
/// value `(y, x)` is at `[(y % sy, x % sx)][y / sy][x / sx]`. Kernel tap `(i, j)`'s
/// values for output row `o` (padded `(o·sy + i, o'·sx + j)`) are then `w_out`
/// contiguous values of phase `(i % sy, j % sx)`, row `o + i / sy`, from column
/// `j / sx`. The padding is never written, so it stays zero between loads.
struct Phases {
    values: Vec<f32>,
    layout: PhaseLayout,
    pad: [usize; 2],
    in_hw: [usize; 2],
}

/// Where [`Phases`] keeps each padded value.
#[derive(Debug, Clone, Copy)]
struct PhaseLayout {
    rows: usize,
    cols: usize,
    stride: [usize; 2],
}

impl PhaseLayout {
    fn new(g: &Geometry) -> Self {
        let [sy, sx] = g.stride;
        Self {
            rows: (g.in_hw[0] + 2 * g.pad[0]).div_ceil(sy),
            cols: (g.in_hw[1] + 2 * g.pad[1]).div_ceil(sx),
            stride: g.stride,
        }
    }

    /// Where padded value `(y, x)` is; `(y + stride, x)` is `cols` further.
    fn at(&self, y: usize, x: usize) -> usize {
        let [sy, sx] = self.stride;
        (((y % sy) * sx + x % sx) * self.rows + y / sy) * self.cols + x / sx
    }
}

impl Phases {
    fn new(g: &Geometry) -> Self {
        let layout = PhaseLayout::new(g);
        Self {
            values: vec![0.0; layout.stride[0] * layout.stride[1] * layout.rows * layout.cols],
            layout,
            pad: g.pad,
            in_hw: g.in_hw,
        }
    }

    fn at(&self, y: usize, x: usize) -> usize {
        self.layout.at(y, x)
    }

    /// The phase rows that padded row `y`'s columns `q, q + 2, …` and `q + 1, q + 3, …`
    /// go to (stride 2 across), `w` values in all: two disjoint slices.
    fn two_phases(&mut self, y: usize, q: usize, w: usize) -> (&mut [f32], &mut [f32]) {
        let (e, o) = (self.at(y, q), self.at(y, q + 1));
        let (ne, no) = (w.div_ceil(2), w / 2);
        if e < o {
            let (first, second) = self.values.split_at_mut(o);
            (&mut first[e..][..ne], &mut second[..no])
        } else {
            let (first, second) = self.values.split_at_mut(e);
            (&mut second[..ne], &mut first[o..][..no])
        }
    }

    /// Loads `plane` (`h_in × w_in`) into the unpadded part.
    fn load(&mut self, plane: &[f32]) {
        let [p, q] = self.pad;
        let (w, sx) = (self.in_hw[1], self.layout.stride[1]);
        for (y, src) in plane.chunks_exact(w).enumerate() {
            if sx == 1 {
                let at = self.at(y + p, q);
                self.values[at..][..w].copy_from_slice(src);
                continue;
            }
            if sx == 2 {
                let (even, odd) = self.two_phases(y + p, q, w);
                for ((pair, e), o) in src.chunks_exact(2).zip(even.iter_mut()).zip(odd) {
                    *e = pair[0];
                    *o = pair[1];
                }
                if let (Some(last), Some(e)) = (src.last(), even.last_mut())
                    && w % 2 == 1
                {
                    *e = *last;
                }
                continue;
            }
            for x0 in 0..sx.min(w) {
                let at = self.at(y + p, x0 + q);
                let dst = &mut self.values[at..];
                for (d, v) in dst.iter_mut().zip(src[x0..].iter().step_by(sx)) {
                    *d = *v;
                }
            }
        }
    }

    /// Writes the unpadded part into `plane` (`h_in × w_in`).
    fn store(&self, plane: &mut [f32]) {
        let [p, q] = self.pad;
        let (w, sx) = (self.in_hw[1], self.layout.stride[1]);
        for (y, dst) in plane.chunks_exact_mut(w).enumerate() {
            if sx == 1 {
                dst.copy_from_slice(&self.values[self.at(y + p, q)..][..w]);
                continue;
            }
            if sx == 2 {
                let (e, o) = (self.at(y + p, q), self.at(y + p, q + 1));
                let (even, odd) = (
                    &self.values[e..][..w.div_ceil(2)],
                    &self.values[o..][..w / 2],
                );
                for ((pair, e), o) in dst.chunks_exact_mut(2).zip(even).zip(odd) {
                    pair[0] = *e;
                    pair[1] = *o;
                }
                if let (Some(last), Some(e)) = (dst.last_mut(), even.last())
                    && w % 2 == 1
                {
                    *last = *e;
                }
                continue;
            }
            for x0 in 0..sx.min(w) {
                let src = &self.values[self.at(y + p, x0 + q)..];
                for (d, v) in dst[x0..].iter_mut().step_by(sx).zip(src) {
                    *d = *v;
                }
            }
        }
    }
}

/// `y [images, c, px]` → `m [c, images·px]`.
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
    let (patch, out_px, block) = (g.patch(), g.out_px(), g.block());
    let mut y = vec![0.0f32; g.y_len()];
    let (x_image, y_image) = (g.c_in * g.in_px(), g.c_out * out_px);
    y.par_chunks_mut(g.per_chunk() * y_image)
        .zip(x.par_chunks(g.per_chunk() * x_image))
        .for_each(|(y, x)| {
            for (y, x) in y.chunks_mut(block * y_image).zip(x.chunks(block * x_image)) {
                let images = x.len() / x_image;
                let n = images * out_px;
                with_scratch(patch * n, g.c_out * n, |col, m| {
                    g.im2col(x, images, col);
                    let (w, col) = (View::rows(w, g.c_out, patch), View::rows(col, patch, n));
                    matmul(m, false, w, col);
                    place(m, images, g.c_out, out_px, bias, y);
                });
            }
        });
    y
}

/// What [`backward`] computes beside the weight gradient, from the same patches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Also {
    Nothing,
    /// The gradient of the input `x`.
    InputGradient,
    /// The convolution of `x` itself (what a transposed convolution's input gradient
    /// is, while its weight gradient is this one's).
    Output,
}

/// The gradient of a convolution's weight from its input `x` and its output's
/// gradient `dy`, and what `also` asks for (`None` for [`Also::Nothing`]).
pub(crate) fn backward(
    g: &Geometry,
    x: &[f32],
    w: &[f32],
    dy: &[f32],
    also: Also,
) -> (Vec<f32>, Option<Vec<f32>>) {
    let (patch, out_px, block) = (g.patch(), g.out_px(), g.block());
    let (x_image, y_image) = (g.c_in * g.in_px(), g.c_out * out_px);
    let extra_image = match also {
        Also::Nothing => 0,
        Also::InputGradient => x_image,
        Also::Output => y_image,
    };
    // One chunk: its weight gradient, and what `also` asks for into `extra`.
    let chunk = |x: &[f32], dy: &[f32], mut extra: Option<&mut [f32]>| {
        let mut dw = vec![0.0f32; g.w_len()];
        let blocks = x.chunks(block * x_image).zip(dy.chunks(block * y_image));
        for (i, (x, dy)) in blocks.enumerate() {
            let images = x.len() / x_image;
            let n = images * out_px;
            let extra = extra
                .as_deref_mut()
                .map(|e| &mut e[i * block * extra_image..][..images * extra_image]);
            with_scratch(patch * n, g.c_out * n, |col, m| {
                to_channel_major(dy, images, g.c_out, out_px, m);
                g.im2col(x, images, col);
                let dy = View::rows(m, g.c_out, n);
                matmul(&mut dw, i > 0, dy, View::rows(col, patch, n).t());
                match (also, extra) {
                    (Also::InputGradient, Some(dx)) => {
                        scatter_input_gradient(g, w, dy, images, col, dx);
                    }
                    (Also::Output, Some(y)) => {
                        let (w, col) = (View::rows(w, g.c_out, patch), View::rows(col, patch, n));
                        matmul(m, false, w, col);
                        place(m, images, g.c_out, out_px, None, y);
                    }
                    _ => {}
                }
            });
        }
        dw
    };
    let (x_step, y_step) = (g.per_chunk() * x_image, g.per_chunk() * y_image);
    let (extra, parts): (Option<Vec<f32>>, Vec<Vec<f32>>) = if extra_image > 0 {
        let mut extra = vec![0.0f32; g.batch * extra_image];
        let parts = extra
            .par_chunks_mut(g.per_chunk() * extra_image)
            .zip(x.par_chunks(x_step).zip(dy.par_chunks(y_step)))
            .map(|(e, (x, dy))| chunk(x, dy, Some(e)))
            .collect();
        (Some(extra), parts)
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
    (dw, extra)
}

/// `m [c, images·px]` into `y [images, c, px]`, plus `bias[c]` when given.
fn place(m: &[f32], images: usize, c: usize, px: usize, bias: Option<&[f32]>, y: &mut [f32]) {
    let n = images * px;
    for b in 0..images {
        for ch in 0..c {
            let src = &m[ch * n + b * px..][..px];
            let dst = &mut y[(b * c + ch) * px..][..px];
            let add = bias.map_or(0.0, |bias| bias[ch]);
            for (d, v) in dst.iter_mut().zip(src) {
                *d = v + add;
            }
        }
    }
}

/// The gradient of the input alone: the transposed convolution of `dy` (what a
/// transposed convolution's forward pass computes).
pub(crate) fn input_gradient(g: &Geometry, w: &[f32], dy: &[f32]) -> Vec<f32> {
    let (out_px, block) = (g.out_px(), g.block());
    let (x_image, y_image) = (g.c_in * g.in_px(), g.c_out * out_px);
    let mut dx = vec![0.0f32; g.x_len()];
    dx.par_chunks_mut(g.per_chunk() * x_image)
        .zip(dy.par_chunks(g.per_chunk() * y_image))
        .for_each(|(dx, dy)| {
            for (dx, dy) in dx
                .chunks_mut(block * x_image)
                .zip(dy.chunks(block * y_image))
            {
                let images = dy.len() / y_image;
                let n = images * out_px;
                with_scratch(g.patch() * n, g.c_out * n, |col, m| {
                    to_channel_major(dy, images, g.c_out, out_px, m);
                    scatter_input_gradient(g, w, View::rows(m, g.c_out, n), images, col, dx);
                });
            }
        });
    dx
}

/// `images` images' input gradient from their output gradient `dy [c_out, images·out_px]`,
/// through `col` (`patch × images·out_px`, overwritten).
fn scatter_input_gradient(
    g: &Geometry,
    w: &[f32],
    dy: View<'_>,
    images: usize,
    col: &mut [f32],
    dx: &mut [f32],
) {
    matmul(col, false, View::rows(w, g.c_out, g.patch()).t(), dy);
    g.col2im(col, images, dx);
}

thread_local! {
    /// Each thread's two working matrices, kept between calls: a training step asks
    /// for the same sizes again and again, and fresh ones cost page faults and zeroing
    /// (a tenth of the step, measured with `perf`). They keep the largest block's
    /// patches and products until the thread ends: about [`BLOCK_VALUES`], or one
    /// image's when that is more (300 KiB at 64×64/16).
    static SCRATCH: RefCell<(Vec<f32>, Vec<f32>)> = const { RefCell::new((Vec::new(), Vec::new())) };
}

/// `f` on two working buffers of `a` and `b` values, their contents unspecified.
fn with_scratch<R>(a: usize, b: usize, f: impl FnOnce(&mut [f32], &mut [f32]) -> R) -> R {
    SCRATCH.with(|cell| match cell.try_borrow_mut() {
        Ok(mut pair) => {
            let (va, vb) = &mut *pair;
            for (v, len) in [(&mut *va, a), (&mut *vb, b)] {
                if v.len() < len {
                    v.resize(len, 0.0);
                }
            }
            f(&mut va[..a], &mut vb[..b])
        }
        // Only if `f` re-entered on this thread (it does not): fresh buffers.
        Err(_) => f(&mut vec![0.0; a], &mut vec![0.0; b]),
    })
}

/// Adds `bias[c]` to every value of channel `c` of an NCHW buffer of `c` channels
/// of `px` values (the transpose of [`channel_sums`]).
pub(crate) fn add_channel_bias(t: &mut [f32], px: usize, bias: &[f32]) {
    for (plane, b) in t.chunks_exact_mut(px).zip(bias.iter().cycle()) {
        plane.iter_mut().for_each(|v| *v += b);
    }
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
