//! Batch normalisation with the batch's own statistics (training mode) on NCHW `f32`
//! buffers: the statistics in two read-only passes per channel, the output in one
//! pass, and the backward pass in two. burn's default (which flex uses) builds the
//! same from about ten tensor operations each way, two of them NCHW → CNHW copies.

use rayon::prelude::*;

/// The shape: `batch` images of `channels` planes of `px` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Shape {
    pub batch: usize,
    pub channels: usize,
    pub px: usize,
}

impl Shape {
    fn count(&self) -> f64 {
        (self.batch * self.px) as f64
    }

    /// Each image's plane of channel `ch`.
    fn planes<'a>(&self, t: &'a [f32], ch: usize) -> impl Iterator<Item = &'a [f32]> {
        let (c, px) = (self.channels, self.px);
        (0..self.batch).map(move |b| &t[(b * c + ch) * px..][..px])
    }

    /// `f(channel, plane of x, plane of out)` over every image's planes, images in
    /// parallel.
    fn each_plane(&self, x: &[f32], out: &mut [f32], f: impl Fn(usize, &[f32], &mut [f32]) + Sync) {
        let image = self.channels * self.px;
        out.par_chunks_mut(image)
            .zip(x.par_chunks(image))
            .for_each(|(out, x)| {
                for (ch, (out, x)) in out.chunks_mut(self.px).zip(x.chunks(self.px)).enumerate() {
                    f(ch, x, out);
                }
            });
    }
}

/// Accumulators per plane: 16 independent f32 sums (so the loop vectorises rather
/// than waiting on one add at a time), added up in f64. A plane has at most a few
/// thousand values, so each lane sums a few hundred.
const LANES: usize = 16;

/// `Σ f(v)` over a plane.
fn lanes(plane: &[f32], f: impl Fn(f32) -> f32) -> f64 {
    let mut acc = [0.0f32; LANES];
    let chunks = plane.chunks_exact(LANES);
    let rest: f64 = chunks.remainder().iter().map(|v| f64::from(f(*v))).sum();
    for chunk in chunks {
        for (a, v) in acc.iter_mut().zip(chunk) {
            *a += f(*v);
        }
    }
    acc.iter().map(|a| f64::from(*a)).sum::<f64>() + rest
}

/// `(Σ f(a, b).0, Σ f(a, b).1)` over two planes of one shape.
fn lanes2(a: &[f32], b: &[f32], f: impl Fn(f32, f32) -> (f32, f32)) -> (f64, f64) {
    let (mut acc0, mut acc1) = ([0.0f32; LANES], [0.0f32; LANES]);
    let (ca, cb) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let rest = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .fold((0.0, 0.0), |(s0, s1), (x, y)| {
            let (u, v) = f(*x, *y);
            (s0 + f64::from(u), s1 + f64::from(v))
        });
    for (xa, xb) in ca.zip(cb) {
        for (((a0, a1), x), y) in acc0.iter_mut().zip(acc1.iter_mut()).zip(xa).zip(xb) {
            let (u, v) = f(*x, *y);
            *a0 += u;
            *a1 += v;
        }
    }
    let total = |acc: [f32; LANES]| acc.iter().map(|a| f64::from(*a)).sum::<f64>();
    (total(acc0) + rest.0, total(acc1) + rest.1)
}

/// What the forward pass gives: the output, and per channel the batch mean, the
/// biased variance (what the running statistics follow), `1/√(var + ε)` and the
/// output's scale `γ/√(var + ε)`.
pub(crate) struct Forward {
    pub output: Vec<f32>,
    pub mean: Vec<f32>,
    pub variance: Vec<f32>,
    pub inv_std: Vec<f32>,
    pub scale: Vec<f32>,
}

/// flex's ReLU: NaN passes, as does its gradient where the output was NaN.
#[inline]
fn kept(y: f32) -> bool {
    y.is_nan() || y > 0.0
}

/// Values per parallel job of the element-wise passes below.
const CHUNK: usize = 1 << 14;

/// `out = relu(a + b)` (flex's ReLU), in parallel chunks.
pub(crate) fn add_relu(a: &[f32], b: &[f32], out: &mut [f32]) {
    out.par_chunks_mut(CHUNK)
        .zip(a.par_chunks(CHUNK).zip(b.par_chunks(CHUNK)))
        .for_each(|(out, (a, b))| {
            for (o, (x, y)) in out.iter_mut().zip(a.iter().zip(b)) {
                let v = x + y;
                *o = if kept(v) { v } else { 0.0 };
            }
        });
}

/// A ReLU's input gradient `d` from its `output` and the output's gradient `dy`.
pub(crate) fn relu_gradient(output: &[f32], dy: &[f32], d: &mut [f32]) {
    d.par_chunks_mut(CHUNK)
        .zip(output.par_chunks(CHUNK).zip(dy.par_chunks(CHUNK)))
        .for_each(|(d, (y, g))| {
            for (o, (y, g)) in d.iter_mut().zip(y.iter().zip(g)) {
                *o = if kept(*y) { *g } else { 0.0 };
            }
        });
}

/// A ReLU after the batch norm, its mask worked out again from `x` in the backward
/// pass (the same expression as the forward's, so the same bits) rather than kept.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Relu<'a> {
    pub scale: &'a [f32],
    pub beta: &'a [f32],
}

/// `γ·(x − mean)/√(var + ε) + β` with the batch's mean and biased variance per
/// channel, summed in f32 lanes and f64 (see [`lanes`]); then ReLU when `relu`
/// (one pass rather than burn's two, and its own in the backward pass).
pub(crate) fn forward(
    s: Shape,
    x: &[f32],
    gamma: &[f32],
    beta: &[f32],
    epsilon: f64,
    relu: bool,
) -> Forward {
    let stats: Vec<(f64, f64)> = (0..s.channels)
        .into_par_iter()
        .map(|ch| {
            let sum: f64 = s.planes(x, ch).map(|p| lanes(p, |v| v)).sum();
            let mean = sum / s.count();
            let m = mean as f32;
            let sq: f64 = s
                .planes(x, ch)
                .map(|p| lanes(p, |v| (v - m) * (v - m)))
                .sum();
            (mean, sq / s.count())
        })
        .collect();
    let inv_std: Vec<f64> = stats
        .iter()
        .map(|(_, var)| 1.0 / (var + epsilon).sqrt())
        .collect();
    let scale: Vec<f32> = (0..s.channels)
        .map(|c| (f64::from(gamma[c]) * inv_std[c]) as f32)
        .collect();
    let mean: Vec<f32> = stats.iter().map(|(m, _)| *m as f32).collect();
    let mut output = vec![0.0f32; x.len()];
    // (x − mean)·scale + β rather than x·scale + shift: with a variance near 0 the scale
    // is large, and the folded shift would cancel to the last bits of x·scale.
    s.each_plane(x, &mut output, |ch, x, out| {
        let (m, a, b) = (mean[ch], scale[ch], beta[ch]);
        for (o, v) in out.iter_mut().zip(x) {
            let y = (v - m) * a + b;
            *o = if !relu || kept(y) { y } else { 0.0 };
        }
    });
    Forward {
        output,
        mean,
        variance: stats.iter().map(|(_, v)| *v as f32).collect(),
        inv_std: inv_std.iter().map(|v| *v as f32).collect(),
        scale,
    }
}

/// Gradients with respect to `x`, γ and β from the output's gradient `dy`, for the
/// statistics [`forward`] returned: with `x̂ = (x − mean)·inv_std`,
/// `∂β = Σ dy`, `∂γ = Σ dy·x̂`, `∂x = γ·inv_std·(dy − ∂β/N − x̂·∂γ/N)`. With `relu`,
/// `dy` is the ReLU's output gradient, zeroed first where the ReLU dropped its input.
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward(
    s: Shape,
    x: &[f32],
    dy: &[f32],
    gamma: &[f32],
    mean: &[f32],
    inv_std: &[f32],
    want_x: bool,
    relu: Option<Relu<'_>>,
) -> (Option<Vec<f32>>, Vec<f32>, Vec<f32>) {
    // The gradient reaching the batch norm's output, for channel `ch`.
    let through = |ch: usize| {
        let (m, on) = (mean[ch], relu.is_some());
        let (a, b) = relu.map_or((0.0, 0.0), |r| (r.scale[ch], r.beta[ch]));
        move |d: f32, v: f32| if !on || kept((v - m) * a + b) { d } else { 0.0 }
    };
    let sums: Vec<(f64, f64)> = (0..s.channels)
        .into_par_iter()
        .map(|ch| {
            let (m, pass) = (mean[ch], through(ch));
            let (sdy, sdyx) =
                s.planes(dy, ch)
                    .zip(s.planes(x, ch))
                    .fold((0.0, 0.0), |(a, b), (dy, x)| {
                        let (da, db) = lanes2(dy, x, |d, v| {
                            let d = pass(d, v);
                            (d, d * (v - m))
                        });
                        (a + da, b + db)
                    });
            (sdy, sdyx * f64::from(inv_std[ch]))
        })
        .collect();
    let d_beta: Vec<f32> = sums.iter().map(|(a, _)| *a as f32).collect();
    let d_gamma: Vec<f32> = sums.iter().map(|(_, b)| *b as f32).collect();
    let dx = want_x.then(|| {
        // ∂x = A·dy + B·(x − mean) + C per channel (centred for the reason in `forward`).
        let n = s.count();
        let coef: Vec<(f32, f32, f32)> = (0..s.channels)
            .map(|c| {
                let (g, is) = (f64::from(gamma[c]), f64::from(inv_std[c]));
                let (sdy, sdx) = sums[c];
                let a = g * is;
                (a as f32, (-a * is * sdx / n) as f32, (-a * sdy / n) as f32)
            })
            .collect();
        let mut dx = vec![0.0f32; x.len()];
        // `dy` and `x` share the layout: walk them image by image together.
        let image = s.channels * s.px;
        dx.par_chunks_mut(image)
            .zip(dy.par_chunks(image).zip(x.par_chunks(image)))
            .for_each(|(dx, (dy, x))| {
                let planes = dx.chunks_mut(s.px).zip(dy.chunks(s.px).zip(x.chunks(s.px)));
                for (ch, (dx, (dy, x))) in planes.enumerate() {
                    let ((a, b, c), m, pass) = (coef[ch], mean[ch], through(ch));
                    for (o, (d, v)) in dx.iter_mut().zip(dy.iter().zip(x)) {
                        *o = a * pass(*d, *v) + b * (v - m) + c;
                    }
                }
            });
        dx
    });
    (dx, d_gamma, d_beta)
}
