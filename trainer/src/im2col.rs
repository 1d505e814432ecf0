//! Single-image inference's convolutions on the flex backend without the per-call
//! weight reordering.
//!
//! burn's flex backend runs most convolutions as im2col and one matrix product, and
//! on every call it first reorders the whole weight tensor from `[c_out, c_in, kh,
//! kw]` to `[c_out, kh, kw, c_in]`. For one 32×32 image that reordering was about
//! 40 % of the model's time (the weights outnumber the activations). Here the
//! weights are reordered once, when a model is loaded, and each call repeats the
//! rest of flex's computation step for step (the input in channels-last order, the
//! same im2col tiles, the bias after the product), so that the output is bit for bit
//! flex's. The product is flex's matrix product of the weights and the transposed
//! tile, which calls `gemm` with the very arguments flex's convolution passes it.
//! [`FlatConv::runs`] says when all that holds; anything else (another backend, or a
//! convolution flex sends down another of its paths) stays with burn.

use burn::nn::PaddingConfig2d;
use burn::nn::conv::Conv2d;
use burn::prelude::{Device, Tensor, TensorData};

use crate::TrainError;
use crate::preprocess::Fork;

/// A feature map of one image: `c × h × w`, channel-major.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Feature {
    pub(crate) data: Vec<f32>,
    pub(crate) c: usize,
    pub(crate) h: usize,
    pub(crate) w: usize,
}

impl Feature {
    /// The map of a `[1, c, h, w]` tensor.
    pub(crate) fn from_tensor(t: Tensor<4>) -> Result<Self, TrainError> {
        let [b, c, h, w] = t.dims();
        if b != 1 {
            return Err(TrainError::Input(format!(
                "a batch of {b} images: expected one"
            )));
        }
        let data = t
            .into_data()
            .try_into_vec::<f32>()
            .map_err(|e| TrainError::Artifact(format!("reading a feature map: {e:?}")))?;
        Ok(Self { data, c, h, w })
    }

    pub(crate) fn into_tensor(self, device: &Device) -> Tensor<4> {
        Tensor::from_data(
            TensorData::new(self.data, [1, self.c, self.h, self.w]),
            device,
        )
    }

    /// flex's ReLU: NaN stays NaN.
    pub(crate) fn relu(mut self) -> Self {
        for v in &mut self.data {
            if !(v.is_nan() || *v > 0.0) {
                *v = 0.0;
            }
        }
        self
    }

    /// Element-wise sum with a map of the same shape.
    pub(crate) fn add(mut self, other: &Self) -> Self {
        for (a, b) in self.data.iter_mut().zip(&other.data) {
            *a += b;
        }
        self
    }
}

/// [`FlatConv::few_channels`]'s sums, as a [`pulp::WithSimd`] operation so that its
/// loops are compiled once per instruction set.
struct FewChannels<'a> {
    /// `c_out × oh × ow`, zeroed.
    out: &'a mut [f32],
    /// `[oh, ow]`.
    out_size: [usize; 2],
    /// The input, `c_in × stride_w phases × h × run`.
    phased: &'a [f32],
    run: usize,
    /// `[c_out, c_in, kh, kw]`.
    weights: &'a [f32],
    bias: Option<&'a [f32]>,
    c_in: usize,
    kernel: [usize; 2],
    stride: [usize; 2],
    padding: [usize; 2],
    /// Per kernel row and column, the outputs whose input is inside the image.
    rows: &'a [(usize, usize)],
    columns: &'a [(usize, usize)],
}

impl pulp::WithSimd for FewChannels<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let [kh, kw] = self.kernel;
        let [sh, sw] = self.stride;
        let [ph, pw] = self.padding;
        let [oh, ow] = self.out_size;
        let phase_plane = self.phased.len() / (self.c_in * sw).max(1);
        for (co, plane) in self.out.chunks_exact_mut((oh * ow).max(1)).enumerate() {
            for ci in 0..self.c_in {
                let planes = &self.phased[ci * sw * phase_plane..(ci + 1) * sw * phase_plane];
                let weights = &self.weights[(co * self.c_in + ci) * kh * kw..][..kh * kw];
                for (a, &(y0, y1)) in self.rows.iter().enumerate() {
                    for (b, &(x0, x1)) in self.columns.iter().enumerate() {
                        let weight = weights[a * kw + b];
                        // Input column of output x0 for this tap, as (phase, index).
                        let ix0 = x0 * sw + b - pw;
                        let input = &planes[(ix0 % sw) * phase_plane..][..phase_plane];
                        let j0 = ix0 / sw;
                        for oy in y0..y1 {
                            let iy = oy * sh + a - ph;
                            let out_row = &mut plane[oy * ow + x0..oy * ow + x1];
                            let in_run = &input[iy * self.run + j0..][..out_row.len()];
                            for (o, &v) in out_row.iter_mut().zip(in_run) {
                                *o += v * weight;
                            }
                        }
                    }
                }
            }
            if let Some(bias) = self.bias {
                for v in plane.iter_mut() {
                    *v += bias[co];
                }
            }
        }
    }
}

/// The paths of flex's convolution that matter here: the two repeated in this file,
/// and the rest, left to burn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FlexPath {
    Im2col,
    FewChannels,
    Other,
}

/// flex's few-channel path takes convolutions of at most this many input and output
/// channels (its `SMALL_CHANNEL_IN_THRESHOLD` and `SMALL_CHANNEL_OUT_THRESHOLD`).
const SMALL_CHANNELS_IN: usize = 4;
const SMALL_CHANNELS_OUT: usize = 16;

/// Output pixels per im2col tile (flex's `TILE_SIZE`).
const TILE: usize = 512;

/// A convolution with its weights in flex's matrix-product order, and the burn
/// module for the calls flex would not run through im2col.
#[derive(Debug, Clone)]
pub(crate) struct FlatConv {
    conv: Conv2d,
    /// `[c_out, kh · kw · c_in]`, each row in `(kh, kw, c_in)` order.
    weight: Option<Tensor<2>>,
    /// `[c_out, c_in, kh, kw]` as stored, for flex's few-channel path (`None` for
    /// other layers, and where a weight is not finite: flex then marks padded
    /// outputs NaN, which is left to it).
    raw: Option<Vec<f32>>,
    bias: Option<Vec<f32>>,
    c_in: usize,
    c_out: usize,
    /// `[top, left]`, when the padding is symmetric and known without the input.
    padding: Option<[usize; 2]>,
    /// The device is flex's (other backends compute otherwise).
    on_flex: bool,
    /// The weights' device, where each call's tensors are made.
    device: Device,
}

impl FlatConv {
    pub(crate) fn new(conv: &Conv2d) -> Self {
        let device = conv.weight.val().device();
        let [c_out, c_in_per_group, kh, kw] = conv.weight.dims();
        let raw = conv.weight.val().into_data().try_into_vec::<f32>().ok();
        let bias = conv
            .bias
            .as_ref()
            .and_then(|b| b.val().into_data().try_into_vec::<f32>().ok());
        let k = kh * kw;
        let few_channels = c_in_per_group * conv.groups <= SMALL_CHANNELS_IN
            && c_out <= SMALL_CHANNELS_OUT
            && conv.groups == 1;
        let raw_kept = raw
            .as_ref()
            .filter(|raw| few_channels && raw.len() == c_out * c_in_per_group * k)
            .filter(|raw| raw.iter().all(|v| v.is_finite()))
            .cloned();
        // As flex reorders it: for each output channel, (c_in, k) → (k, c_in).
        let weight = raw
            .filter(|raw| raw.len() == c_out * c_in_per_group * k)
            .map(|raw| {
                let mut w = vec![0.0; raw.len()];
                for o in 0..c_out {
                    let base = o * c_in_per_group * k;
                    for c in 0..c_in_per_group {
                        for s in 0..k {
                            w[base + s * c_in_per_group + c] = raw[base + c * k + s];
                        }
                    }
                }
                Tensor::from_data(TensorData::new(w, [c_out, c_in_per_group * k]), &device)
            });
        let padding = match conv.padding {
            PaddingConfig2d::Valid => Some([0, 0]),
            PaddingConfig2d::Explicit(top, left, bottom, right)
                if top == bottom && left == right =>
            {
                Some([top, left])
            }
            _ => None,
        };
        Self {
            on_flex: device == Device::flex()
                && weight.is_some()
                && (conv.bias.is_none() || bias.as_ref().is_some_and(|b| b.len() == c_out)),
            conv: conv.clone(),
            weight,
            raw: raw_kept,
            bias,
            c_in: c_in_per_group * conv.groups,
            c_out,
            padding,
            device,
        }
    }

    /// Whether flex would run this convolution on `x` through its im2col path (the
    /// one repeated here): its 1×1, depthwise, few-channel and direct paths, grouped
    /// or dilated convolutions, and padding that flex applies to the input first are
    /// left to burn.
    fn runs(&self, x: &Feature) -> bool {
        self.flex_path(x) == FlexPath::Im2col
    }

    /// Which of flex's convolution paths it would take for `x`, tried in flex's
    /// order: 1×1, depthwise, few channels, direct, im2col.
    fn flex_path(&self, x: &Feature) -> FlexPath {
        let Some([ph, pw]) = self.padding else {
            return FlexPath::Other;
        };
        let [kh, kw] = self.conv.kernel_size;
        let [sh, sw] = self.conv.stride;
        let handled = self.on_flex
            && self.conv.groups == 1
            && self.conv.dilation == [1, 1]
            && x.c == self.c_in
            && x.data.len() == x.c * x.h * x.w
            && self.out_size(x.h, kh, sh, ph).is_some()
            && self.out_size(x.w, kw, sw, pw).is_some();
        let one_by_one = kh == 1 && kw == 1 && sh == 1 && sw == 1 && ph == 0 && pw == 0;
        let depthwise = self.c_in == 1 && self.c_out == 1;
        let few_channels = self.c_in <= SMALL_CHANNELS_IN && self.c_out <= SMALL_CHANNELS_OUT;
        let direct = ph == 0
            && pw == 0
            && kh == 1
            && x.h == 1
            && self.c_in >= 32
            && kw <= 8
            && self.out_size(x.w, kw, sw, pw).is_some_and(|ow| ow <= 800);
        if !handled || one_by_one || depthwise {
            FlexPath::Other
        } else if few_channels {
            FlexPath::FewChannels
        } else if direct {
            FlexPath::Other
        } else {
            FlexPath::Im2col
        }
    }

    fn out_size(&self, size: usize, k: usize, stride: usize, pad: usize) -> Option<usize> {
        let span = size + 2 * pad;
        (stride > 0 && span >= k).then(|| (span - k) / stride + 1)
    }

    /// The convolution of `x`: flex's im2col computation, or burn's call. `fork`:
    /// the output pixels in two halves through it (e.g. on two cores) when the
    /// layer is large enough to gain from it; the same values either way.
    pub(crate) fn forward(
        &self,
        x: Feature,
        fork: Option<&dyn Fork>,
    ) -> Result<Feature, TrainError> {
        let weight = match &self.weight {
            Some(w) if self.runs(&x) => w,
            _ => {
                if let Some(out) = self.few_channels(&x) {
                    return Ok(out);
                }
                return Feature::from_tensor(self.conv.forward(x.into_tensor(&self.device)));
            }
        };
        let [kh, kw] = self.conv.kernel_size;
        let [sh, sw] = self.conv.stride;
        let [ph, pw] = self.padding.unwrap_or_default();
        let (oh, ow) = (
            self.out_size(x.h, kh, sh, ph).unwrap_or(0),
            self.out_size(x.w, kw, sw, pw).unwrap_or(0),
        );
        // Channels last.
        let (c_in, h, w) = (self.c_in, x.h, x.w);
        let mut nhwc = vec![0.0f32; c_in * h * w];
        for y in 0..h {
            for xx in 0..w {
                for c in 0..c_in {
                    nhwc[(y * w + xx) * c_in + c] = x.data[c * h * w + y * w + xx];
                }
            }
        }
        let spatial = oh * ow;
        let im2col = Im2col {
            nhwc: &nhwc,
            h,
            w,
            ow,
            kernel: [kh, kw],
            stride: [sh, sw],
            padding: [ph, pw],
            c_in,
        };
        // The whole range's products are the output itself; halves are placed in it.
        let mut out = match fork.filter(|_| self.splits(spatial)) {
            Some(fork) => {
                let half = spatial / 2;
                let (mut first, mut second) = (None, None);
                fork.fork(
                    &mut || first = Some(self.product(weight, &im2col, 0..half)),
                    &mut || second = Some(self.product(weight, &im2col, half..spatial)),
                );
                let mut out = vec![0.0f32; self.c_out * spatial];
                for (range, part) in [(0..half, first), (half..spatial, second)] {
                    let part = part.ok_or_else(|| {
                        TrainError::Artifact("a convolution's half was not computed".into())
                    })??;
                    self.place(&mut out, spatial, range, &part);
                }
                out
            }
            None => self.product(weight, &im2col, 0..spatial)?,
        };
        if let Some(bias) = &self.bias {
            for (o, b) in bias.iter().enumerate() {
                for v in &mut out[o * spatial..(o + 1) * spatial] {
                    *v += b;
                }
            }
        }
        Ok(Feature {
            data: out,
            c: self.c_out,
            h: oh,
            w: ow,
        })
    }

    /// flex's few-channel convolution (`c_in ≤ 4`, `c_out ≤ 16`: the stem), term for
    /// term: each output starts at 0 and adds `input · weight` for each input
    /// channel, kernel row and kernel column in that order, skipping padded
    /// positions, then the bias. flex runs it as one job per output channel through
    /// rayon and its own vector dispatch, about 10 µs for the default 1→16 stem on
    /// 32×32 px; here the same sums take a plain loop the compiler vectorises.
    /// `None` where flex would take another path or its conditions are not met.
    fn few_channels(&self, x: &Feature) -> Option<Feature> {
        let raw = self.raw.as_ref()?;
        if self.flex_path(x) != FlexPath::FewChannels {
            return None;
        }
        let [ph, pw] = self.padding?;
        let [kh, kw] = self.conv.kernel_size;
        let [sh, sw] = self.conv.stride;
        let (oh, ow) = (
            self.out_size(x.h, kh, sh, ph)?,
            self.out_size(x.w, kw, sw, pw)?,
        );
        // For kernel offset k, the outputs whose input lies inside the image.
        let valid = |k: usize, pad: usize, stride: usize, size: usize, out: usize| {
            let start = if k >= pad {
                0
            } else {
                (pad - k).div_ceil(stride)
            };
            let end = if k >= size + pad {
                0
            } else {
                (size + pad - k).div_ceil(stride).min(out)
            };
            (start, end.max(start))
        };
        let rows: Vec<_> = (0..kh).map(|k| valid(k, ph, sh, x.h, oh)).collect();
        let columns: Vec<_> = (0..kw).map(|k| valid(k, pw, sw, x.w, ow)).collect();
        // Each input row split by column phase of the stride, so that every kernel
        // tap reads a contiguous run: `phased[ci][phase][y][j]` is column
        // `j·stride + phase` of row `y`.
        let run = x.w.div_ceil(sw);
        let phase_plane = x.h * run;
        let mut phased = vec![0.0f32; self.c_in * sw * phase_plane];
        for (ci, planes) in phased.chunks_exact_mut(sw * phase_plane).enumerate() {
            let input = &x.data[ci * x.h * x.w..(ci + 1) * x.h * x.w];
            for (phase, plane) in planes.chunks_exact_mut(phase_plane).enumerate() {
                for (row, in_row) in plane.chunks_exact_mut(run).zip(input.chunks_exact(x.w)) {
                    for (v, &u) in row.iter_mut().zip(in_row.iter().skip(phase).step_by(sw)) {
                        *v = u;
                    }
                }
            }
        }
        let mut out = vec![0.0f32; self.c_out * oh * ow];
        // The loops compiled for the vector unit found at run time (AVX-512 here).
        pulp::Arch::new().dispatch(FewChannels {
            out: &mut out,
            out_size: [oh, ow],
            phased: &phased,
            run,
            weights: raw,
            bias: self.bias.as_deref(),
            c_in: self.c_in,
            kernel: [kh, kw],
            stride: [sh, sw],
            padding: [ph, pw],
            rows: &rows,
            columns: &columns,
        });
        Some(Feature {
            data: out,
            c: self.c_out,
            h: oh,
            w: ow,
        })
    }

    /// Whether a layer of `spatial` output pixels is worth splitting in two (a
    /// handover costs a few microseconds), and each half's product still takes the
    /// path the whole one takes: `gemm` works out a product of at most 16 × 16
    /// outputs as dot products, in another order.
    fn splits(&self, spatial: usize) -> bool {
        spatial >= MIN_SPLIT_PIXELS && self.c_out * (spatial / 2) > GEMM_DOT_OUTPUTS
    }

    /// The products of the output pixels `range` (`c_out × range.len()`, channel
    /// major), in flex's tiles of [`TILE`] pixels.
    fn product(
        &self,
        weight: &Tensor<2>,
        im2col: &Im2col<'_>,
        range: std::ops::Range<usize>,
    ) -> Result<Vec<f32>, TrainError> {
        let c_out = self.c_out;
        let col_len = im2col.col_len();
        let len = range.len();
        let mut out = vec![0.0f32; c_out * len];
        for tile_start in range.clone().step_by(TILE) {
            let tile_end = (tile_start + TILE).min(range.end);
            let tile = tile_end - tile_start;
            let mut col = vec![0.0f32; col_len * tile];
            for (row, at) in col.chunks_exact_mut(col_len).zip(tile_start..tile_end) {
                im2col.fill(row, at);
            }
            let col = Tensor::<2>::from_data(TensorData::new(col, [tile, col_len]), &self.device);
            let product = weight
                .clone()
                .matmul(col.transpose())
                .into_data()
                .try_into_vec::<f32>()
                .map_err(|e| TrainError::Artifact(format!("reading a convolution: {e:?}")))?;
            let at = tile_start - range.start;
            for o in 0..c_out {
                out[o * len + at..o * len + at + tile]
                    .copy_from_slice(&product[o * tile..(o + 1) * tile]);
            }
        }
        Ok(out)
    }

    /// Copies `part` (the products of the output pixels `range`) into `out`.
    fn place(&self, out: &mut [f32], spatial: usize, range: std::ops::Range<usize>, part: &[f32]) {
        let len = range.len();
        for o in 0..self.c_out {
            out[o * spatial + range.start..o * spatial + range.end]
                .copy_from_slice(&part[o * len..(o + 1) * len]);
        }
    }
}

/// Output pixels below which a convolution is not split.
const MIN_SPLIT_PIXELS: usize = 64;

/// `gemm` (0.19) computes a product of at most this many outputs with its dot
/// product kernels when both operands are stored as ours are.
const GEMM_DOT_OUTPUTS: usize = 16 * 16;

/// One image in channels-last order and a convolution's geometry: the rows of the
/// im2col matrix.
struct Im2col<'a> {
    nhwc: &'a [f32],
    h: usize,
    w: usize,
    ow: usize,
    kernel: [usize; 2],
    stride: [usize; 2],
    padding: [usize; 2],
    c_in: usize,
}

impl Im2col<'_> {
    fn col_len(&self) -> usize {
        self.c_in * self.kernel[0] * self.kernel[1]
    }

    /// The row of output pixel `at`: its receptive field, `(ky, kx, c_in)` order,
    /// zeros outside the image (`row` starts zeroed).
    fn fill(&self, row: &mut [f32], at: usize) {
        let (oy, ox) = (at / self.ow, at % self.ow);
        let [kh, kw] = self.kernel;
        let [sh, sw] = self.stride;
        let [ph, pw] = self.padding;
        let c_in = self.c_in;
        let mut offset = 0;
        for ky in 0..kh {
            let iy = (oy * sh + ky) as isize - ph as isize;
            for kx in 0..kw {
                let ix = (ox * sw + kx) as isize - pw as isize;
                if iy >= 0 && iy < self.h as isize && ix >= 0 && ix < self.w as isize {
                    let from = (iy as usize * self.w + ix as usize) * c_in;
                    row[offset..offset + c_in].copy_from_slice(&self.nhwc[from..from + c_in]);
                }
                offset += c_in;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::preprocess::ScopedThread;
    use burn::nn::conv::Conv2dConfig;
    use burn::tensor::Distribution;

    /// A square-kernel convolution with burn's random weights.
    fn conv_of(
        channels: [usize; 2],
        k: usize,
        stride: usize,
        padding: PaddingConfig2d,
        bias: bool,
        device: &Device,
    ) -> Conv2d {
        Conv2dConfig::new(channels, [k, k])
            .with_stride([stride, stride])
            .with_padding(padding)
            .with_bias(bias)
            .init(device)
    }

    fn feature(c: usize, h: usize, w: usize, device: &Device) -> Feature {
        let t = Tensor::<4>::random([1, c, h, w], Distribution::Uniform(-1.0, 1.0), device);
        Feature::from_tensor(t).expect("one image")
    }

    /// flex's few-channel path (the stem's), repeated here: the same bits on strides,
    /// paddings, kernel sizes, odd sizes and an all-zero input, and burn's own call
    /// where flex would take another path.
    #[test]
    fn the_few_channel_path_gives_burns_values_bit_for_bit() {
        let device = Device::flex();
        let pad = |p| PaddingConfig2d::Explicit(p, p, p, p);
        // (c_in, c_out, kernel, stride, padding, bias, input size, repeated here)
        let cases = [
            (1, 16, 3, 1, pad(1), true, 32, true),
            (1, 16, 3, 2, pad(1), false, 32, true),
            (3, 8, 3, 1, pad(1), true, 17, true),
            (4, 16, 5, 2, pad(2), true, 15, true),
            (2, 4, 3, 3, PaddingConfig2d::Valid, true, 10, true),
            (1, 16, 4, 1, pad(1), true, 9, true),
            (3, 2, 3, 1, pad(3), true, 2, true),
            // More channels than the path takes (im2col, burn), a 1×1 and a 1→1.
            (1, 17, 3, 1, pad(1), true, 8, false),
            (5, 4, 3, 1, pad(1), true, 8, false),
            (2, 4, 1, 1, PaddingConfig2d::Valid, true, 8, false),
            (1, 1, 3, 1, pad(1), true, 8, false),
        ];
        for (i, (c_in, c_out, k, stride, padding, bias, size, here)) in
            cases.into_iter().enumerate()
        {
            let _guard = crate::train::init_lock();
            let conv = conv_of([c_in, c_out], k, stride, padding, bias, &device);
            let flat = FlatConv::new(&conv);
            for zeros in [false, true] {
                let x = feature(c_in, size, size, &device);
                let x = if zeros {
                    Feature {
                        data: vec![0.0; x.data.len()],
                        ..x
                    }
                } else {
                    x
                };
                // flex's few-channel path is not its im2col one.
                assert!(!(here && flat.runs(&x)), "case {i}: not im2col");
                assert_eq!(flat.few_channels(&x).is_some(), here, "case {i}: path");
                let expected = Feature::from_tensor(conv.forward(x.clone().into_tensor(&device)))
                    .expect("burn");
                let got = flat.forward(x, None).expect("flat");
                assert_eq!(got, expected, "case {i} zeros {zeros}: values");
            }
        }
    }

    #[test]
    fn each_path_gives_burns_values_bit_for_bit() {
        let device = Device::flex();
        let pad1 = PaddingConfig2d::Explicit(1, 1, 1, 1);
        // (c_in, c_out, kernel, stride, padding, bias, input size, through im2col here)
        let cases = [
            (16, 32, 3, 2, pad1.clone(), false, 16, true),
            (32, 32, 3, 1, pad1.clone(), false, 8, true),
            (64, 64, 3, 1, pad1.clone(), true, 2, true),
            // A strided 1×1 skip with its bias.
            (16, 32, 1, 2, PaddingConfig2d::Valid, true, 16, true),
            // More output pixels than one tile (512).
            (8, 8, 3, 1, pad1.clone(), true, 24, true),
            // flex's own paths: 1×1 stride 1, few channels, and padding it applies
            // to the input first (asymmetric): burn runs them.
            (16, 32, 1, 1, PaddingConfig2d::Valid, true, 8, false),
            (1, 16, 3, 2, pad1, false, 32, false),
            (
                16,
                16,
                3,
                1,
                PaddingConfig2d::Explicit(1, 0, 0, 1),
                false,
                8,
                false,
            ),
            (16, 16, 3, 1, PaddingConfig2d::Same, false, 8, false),
        ];
        for (i, (c_in, c_out, k, stride, padding, bias, size, im2col)) in
            cases.into_iter().enumerate()
        {
            let _guard = crate::train::init_lock();
            let conv = conv_of([c_in, c_out], k, stride, padding, bias, &device);
            let flat = FlatConv::new(&conv);
            let x = feature(c_in, size, size, &device);
            assert_eq!(flat.runs(&x), im2col, "case {i}: path");
            let expected =
                Feature::from_tensor(conv.forward(x.clone().into_tensor(&device))).expect("burn");
            let got = flat.forward(x.clone(), None).expect("flat");
            assert_eq!(got, expected, "case {i}: values");
            // In two halves, on two threads: the same values.
            let got = flat.forward(x, Some(&ScopedThread)).expect("flat, split");
            assert_eq!(got, expected, "case {i}: values in halves");
        }
    }

    #[test]
    fn a_map_of_the_wrong_channels_is_left_to_burn() {
        // burn then reports it; the reordered weights never read out of range.
        let device = Device::flex();
        let conv = Conv2dConfig::new([16, 32], [3, 3])
            .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
            .init(&device);
        let flat = FlatConv::new(&conv);
        let mut x = feature(16, 8, 8, &device);
        x.data.truncate(10);
        assert!(!flat.runs(&x));
        let x = feature(8, 8, 8, &device);
        assert!(!flat.runs(&x));
    }

    #[test]
    fn relu_keeps_nan_and_zeroes_the_rest_below_zero() {
        let f = Feature {
            data: vec![
                f32::NAN,
                -1.0,
                -0.0,
                0.0,
                2.5,
                f32::INFINITY,
                f32::NEG_INFINITY,
            ],
            c: 1,
            h: 1,
            w: 7,
        }
        .relu();
        assert!(f.data[0].is_nan());
        assert_eq!(&f.data[1..], &[0.0, 0.0, 0.0, 2.5, f32::INFINITY, 0.0]);
        assert!(f.data[2].is_sign_positive());
    }
}
