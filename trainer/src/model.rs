//! The networks: a convolutional encoder with residual stages, latent mean and
//! log-variance heads, a decoder that reconstructs the (preprocessed) image from a
//! latent sample, and a regression head (ReLU → Linear → 6) on the latent **mean**.
//!
//! The three models of the paper's Table 1 share these parts:
//! - **SVAE**: all of them; loss `α/(1+α)·recon + 1/(1+α)·pred + β·KL`.
//! - **VAE**: encoder, heads and decoder; loss `recon + β·KL` (the α → ∞ limit).
//! - **ConvNet**: encoder, mean head and regression head; loss `pred` (α = 0, no KL).
//!
//! Shapes, for input size S and width w: a stride-2 stem to S/2 with w channels, then
//! residual stages that halve the size and double the channels (capped at 8w) until
//! the map is 4×4; the decoder mirrors this with stride-2 transposed convolutions.

use burn::module::Param;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, Linear, LinearConfig, PaddingConfig2d};
use burn::prelude::*;
use burn::tensor::activation::{relu, sigmoid};
use serde::{Deserialize, Serialize};

use crate::TrainError;
use crate::im2col::{Feature, FlatConv};
use crate::kernels::{add_relu, batch_norm, batch_norm_relu, conv_transpose2d, conv2d};
use crate::preprocess::{Fork, Preprocess};

/// Which of the paper's models.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    Svae,
    Vae,
    Convnet,
}

impl ModelKind {
    pub fn name(self) -> &'static str {
        match self {
            Self::Svae => "svae",
            Self::Vae => "vae",
            Self::Convnet => "convnet",
        }
    }
    pub fn has_decoder(self) -> bool {
        self != Self::Convnet
    }
    pub fn predicts_wrench(self) -> bool {
        self != Self::Vae
    }
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for ModelKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "svae" => Ok(Self::Svae),
            "vae" => Ok(Self::Vae),
            "convnet" => Ok(Self::Convnet),
            other => Err(format!(
                "unknown model `{other}`: expected svae, vae or convnet"
            )),
        }
    }
}

/// The architecture and loss weights; stored in every model artifact.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    pub kind: ModelKind,
    /// Channels of the stem; stages double it (capped at 8×).
    pub width: usize,
    /// Latent dimensions (the paper: 32).
    pub latent: usize,
    /// Reconstruction vs prediction weight of the SVAE loss (the paper: 1).
    pub alpha: f64,
    /// KL weight (the paper: 0.1).
    pub beta: f64,
    pub preprocess: Preprocess,
}

impl Default for ModelConfig {
    fn default() -> Self {
        Self {
            kind: ModelKind::Svae,
            width: 16,
            latent: 32,
            alpha: 1.0,
            beta: 0.1,
            preprocess: Preprocess::default(),
        }
    }
}

impl ModelConfig {
    /// A list of what is wrong with this configuration (empty when usable).
    pub fn problems(&self) -> Vec<String> {
        let mut out = self.preprocess.problems();
        if !(1..=256).contains(&self.width) {
            out.push(format!("width {}: expected 1..=256 channels", self.width));
        }
        if !(1..=1024).contains(&self.latent) {
            out.push(format!(
                "latent {}: expected 1..=1024 dimensions",
                self.latent
            ));
        }
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            out.push(format!("alpha {}: expected a finite value ≥ 0", self.alpha));
        }
        if !(self.beta.is_finite() && self.beta >= 0.0) {
            out.push(format!("beta {}: expected a finite value ≥ 0", self.beta));
        }
        out
    }

    /// One line naming the settings, e.g. `svae width 16 latent 32 input 1×32×32 α 1 β 0.1`.
    pub fn describe(&self) -> String {
        format!(
            "{} width {} latent {} input {}×{}×{} α {} β {}",
            self.kind,
            self.width,
            self.latent,
            self.preprocess.channels,
            self.preprocess.size_px,
            self.preprocess.size_px,
            self.alpha,
            self.beta
        )
    }

    /// Channels after the stem and after each residual stage.
    fn stage_channels(&self) -> Vec<usize> {
        let stages = (self.preprocess.size_px / 8).max(1).ilog2() as usize;
        (0..=stages).map(|i| self.width << i.min(3)).collect()
    }

    /// Multiply–adds of one image through the training graph's convolutions and
    /// linear layers, and those of the stem alone. Counted as the PyTorch peer counts
    /// them: a convolution's output elements × inputs per output, a transposed one's
    /// input elements × outputs per input.
    pub fn forward_macs_per_image(&self) -> (u64, u64) {
        let ch = self.stage_channels();
        let c_in = self.preprocess.channels as u64;
        let latent = self.latent as u64;
        let mut n = (self.preprocess.size_px / 2) as u64;
        let c0 = ch[0] as u64;
        let stem = n * n * c0 * c_in * 9;
        let mut total = stem;
        for w in ch.windows(2) {
            let (a, b) = (w[0] as u64, w[1] as u64);
            n /= 2;
            // conv1, conv2 and the 1×1 skip.
            total += n * n * b * (a * 9 + b * 9 + a);
        }
        let features = ch.last().map_or(0, |c| *c as u64 * 16);
        total += features * latent;
        if self.kind != ModelKind::Convnet {
            total += features * latent;
        }
        if self.kind.predicts_wrench() {
            total += latent * 6;
        }
        if self.kind.has_decoder() {
            total += latent * features;
            let mut n = 4u64;
            for w in ch.windows(2).rev() {
                total += n * n * w[1] as u64 * w[0] as u64 * 16;
                n *= 2;
            }
            total += n * n * c0 * c_in * 16;
        }
        (total, stem)
    }

    /// GFLOP of one image's training step: 2 per multiply–add, the backward pass
    /// twice the forward less the stem's input gradient (the PyTorch peer's count).
    pub fn train_gflop_per_image(&self) -> f64 {
        let (forward, stem) = self.forward_macs_per_image();
        2.0 * (3 * forward - stem) as f64 / 1e9
    }

    /// Weights of the three loss terms `(recon, pred, kl)`.
    pub fn loss_weights(&self) -> (f64, f64, f64) {
        match self.kind {
            ModelKind::Svae => (
                self.alpha / (1.0 + self.alpha),
                1.0 / (1.0 + self.alpha),
                self.beta,
            ),
            ModelKind::Vae => (1.0, 0.0, self.beta),
            ModelKind::Convnet => (0.0, 1.0, 0.0),
        }
    }

    pub fn init(&self, device: &Device) -> Net {
        Net::new(self, device)
    }
}

/// Two 3×3 convolutions with batch norm and a skip connection (1×1 when the shape
/// changes).
#[derive(Module, Debug)]
pub struct ResBlock {
    conv1: Conv2d,
    bn1: BatchNorm,
    conv2: Conv2d,
    bn2: BatchNorm,
    skip: Option<Conv2d>,
}

impl ResBlock {
    fn new(c_in: usize, c_out: usize, stride: usize, device: &Device) -> Self {
        let pad = PaddingConfig2d::Explicit(1, 1, 1, 1);
        Self {
            conv1: Conv2dConfig::new([c_in, c_out], [3, 3])
                .with_stride([stride, stride])
                .with_padding(pad.clone())
                .with_bias(false)
                .init(device),
            bn1: BatchNormConfig::new(c_out).init(device),
            conv2: Conv2dConfig::new([c_out, c_out], [3, 3])
                .with_padding(pad)
                .with_bias(false)
                .init(device),
            bn2: BatchNormConfig::new(c_out).init(device),
            skip: (stride != 1 || c_in != c_out).then(|| {
                Conv2dConfig::new([c_in, c_out], [1, 1])
                    .with_stride([stride, stride])
                    .init(device)
            }),
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let h = batch_norm_relu(conv2d(x.clone(), &self.conv1), &self.bn1);
        let h = batch_norm(conv2d(h, &self.conv2), &self.bn2);
        let s = match &self.skip {
            Some(conv) => conv2d(x, conv),
            None => x,
        };
        add_relu(h, s)
    }
}

/// One decoder stage: a stride-2 transposed convolution doubling the size, then
/// batch norm and ReLU.
#[derive(Module, Debug)]
pub struct UpBlock {
    conv: ConvTranspose2d,
    bn: BatchNorm,
}

impl UpBlock {
    fn new(c_in: usize, c_out: usize, device: &Device) -> Self {
        Self {
            conv: ConvTranspose2dConfig::new([c_in, c_out], [4, 4])
                .with_stride([2, 2])
                .with_padding([1, 1])
                .with_bias(false)
                .init(device),
            bn: BatchNormConfig::new(c_out).init(device),
        }
    }
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        batch_norm_relu(conv_transpose2d(x, &self.conv), &self.bn)
    }
}

#[derive(Module, Debug)]
pub struct Decoder {
    fc: Linear,
    ups: Vec<UpBlock>,
    out: ConvTranspose2d,
    /// Channels of the 4×4 map the linear layer produces.
    top_channels: usize,
}

impl Decoder {
    fn forward(&self, z: Tensor<2>) -> Tensor<4> {
        let [batch, _] = z.dims();
        let mut x = relu(self.fc.forward(z)).reshape([batch, self.top_channels, 4, 4]);
        for up in &self.ups {
            x = up.forward(x);
        }
        sigmoid(conv_transpose2d(x, &self.out))
    }
}

/// What one forward pass returns.
#[derive(Debug, Clone)]
pub struct Output {
    pub mean: Tensor<2>,
    pub log_var: Option<Tensor<2>>,
    /// Standardised wrench (ConvNet and SVAE).
    pub wrench: Option<Tensor<2>>,
    /// Reconstructed image (VAE and SVAE).
    pub image: Option<Tensor<4>>,
}

/// Any of the three models (what is absent is `None`).
#[derive(Module, Debug)]
pub struct Net {
    stem: Conv2d,
    stem_bn: BatchNorm,
    stages: Vec<ResBlock>,
    fc_mean: Linear,
    fc_log_var: Option<Linear>,
    decoder: Option<Decoder>,
    head: Option<Linear>,
}

impl Net {
    fn new(config: &ModelConfig, device: &Device) -> Self {
        let channels = config.stage_channels();
        let c_in = config.preprocess.channels;
        let top = *channels.last().unwrap_or(&config.width);
        let features = top * 4 * 4;
        let stages = channels
            .windows(2)
            .map(|w| ResBlock::new(w[0], w[1], 2, device))
            .collect();
        let decoder = config.kind.has_decoder().then(|| {
            let ups = channels
                .windows(2)
                .rev()
                .map(|w| UpBlock::new(w[1], w[0], device))
                .collect();
            Decoder {
                fc: LinearConfig::new(config.latent, features).init(device),
                ups,
                out: ConvTranspose2dConfig::new([channels[0], c_in], [4, 4])
                    .with_stride([2, 2])
                    .with_padding([1, 1])
                    .init(device),
                top_channels: top,
            }
        });
        Self {
            stem: Conv2dConfig::new([c_in, channels[0]], [3, 3])
                .with_stride([2, 2])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .with_bias(false)
                .init(device),
            stem_bn: BatchNormConfig::new(channels[0]).init(device),
            stages,
            fc_mean: LinearConfig::new(features, config.latent).init(device),
            fc_log_var: (config.kind != ModelKind::Convnet)
                .then(|| LinearConfig::new(features, config.latent).init(device)),
            decoder,
            head: config
                .kind
                .predicts_wrench()
                .then(|| LinearConfig::new(config.latent, 6).init(device)),
        }
    }

    /// Image → flattened features.
    fn encode(&self, images: Tensor<4>) -> Tensor<2> {
        let mut x = batch_norm_relu(conv2d(images, &self.stem), &self.stem_bn);
        for stage in &self.stages {
            x = stage.forward(x);
        }
        x.flatten(1, 3)
    }

    /// The regression head on the latent mean (ReLU → Linear → 6).
    pub fn predict(&self, mean: Tensor<2>) -> Option<Tensor<2>> {
        self.head.as_ref().map(|h| h.forward(relu(mean)))
    }

    /// Decodes latent codes into images.
    pub fn decode(&self, z: Tensor<2>) -> Option<Tensor<4>> {
        self.decoder.as_ref().map(|d| d.forward(z))
    }

    /// The full pass. `noise` (same shape as the mean) draws the latent sample the
    /// decoder sees, `z = mean + exp(log_var / 2) · noise`; without it the decoder
    /// sees the mean (evaluation).
    pub fn forward(&self, images: Tensor<4>, noise: Option<Tensor<2>>) -> Output {
        let features = self.encode(images);
        let mean = self.fc_mean.forward(features.clone());
        let log_var = self
            .fc_log_var
            .as_ref()
            .map(|fc| crate::loss::clamp_log_var(fc.forward(features)));
        let wrench = self.predict(mean.clone());
        let image = match (&self.decoder, &log_var, noise) {
            (Some(decoder), Some(lv), Some(eps)) => {
                Some(decoder.forward(mean.clone() + lv.clone().mul_scalar(0.5).exp() * eps))
            }
            (Some(decoder), _, _) => Some(decoder.forward(mean.clone())),
            _ => None,
        };
        Output {
            mean,
            log_var,
            wrench,
            image,
        }
    }

    /// Encoder and regression head only (what inference runs).
    pub fn forward_wrench(&self, images: Tensor<4>) -> (Tensor<2>, Option<Tensor<2>>) {
        let mean = self.fc_mean.forward(self.encode(images));
        let wrench = self.predict(mean.clone());
        (mean, wrench)
    }
}

/// A convolution followed by batch norm in evaluation mode, folded into one
/// convolution: `bn(conv(x)) = conv'(x)` with the weights scaled per output channel by
/// `s = γ / √(σ² + ε)` and the bias `(b − μ)·s + β`. Batch norm in evaluation mode is
/// four broadcast passes over the feature map; folded, it costs nothing.
fn fold(conv: &Conv2d, bn: &BatchNorm) -> Conv2d {
    let [c_out, ..] = conv.weight.dims();
    let scale = bn.gamma.val() / bn.running_var.value().add_scalar(bn.epsilon).sqrt();
    let weight = conv.weight.val() * scale.clone().reshape([c_out, 1, 1, 1]);
    let bias = match &conv.bias {
        Some(b) => b.val(),
        None => Tensor::zeros([c_out], &scale.device()),
    };
    let bias = (bias - bn.running_mean.value()) * scale + bn.beta.val();
    Conv2d {
        weight: Param::from_tensor(weight),
        bias: Some(Param::from_tensor(bias)),
        ..conv.clone()
    }
}

/// A residual stage with its batch norms folded into its convolutions.
#[derive(Module, Debug)]
struct FoldedBlock {
    conv1: Conv2d,
    conv2: Conv2d,
    skip: Option<Conv2d>,
}

impl FoldedBlock {
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let h = relu(self.conv1.forward(x.clone()));
        let h = self.conv2.forward(h);
        let s = match &self.skip {
            Some(conv) => conv.forward(x),
            None => x,
        };
        relu(h + s)
    }
}

/// An [`InferenceNet`]'s convolutions with their weights reordered once, for
/// [`InferenceNet::forward_one`].
#[derive(Debug, Clone)]
pub(crate) struct FlatNet {
    stem: FlatConv,
    blocks: Vec<FlatBlock>,
}

/// A [`FoldedBlock`]'s convolutions with their weights reordered once
/// ([`crate::im2col`]), for one image at a time.
#[derive(Debug, Clone)]
pub(crate) struct FlatBlock {
    conv1: FlatConv,
    conv2: FlatConv,
    skip: Option<FlatConv>,
}

impl FlatBlock {
    /// [`FoldedBlock::forward`], the same values (`fork`: see [`FlatConv::forward`]).
    fn forward(&self, x: Feature, fork: Option<&dyn Fork>) -> Result<Feature, TrainError> {
        let h = self.conv1.forward(x.clone(), fork)?.relu();
        let h = self.conv2.forward(h, fork)?;
        let s = match &self.skip {
            Some(conv) => conv.forward(x, fork)?,
            None => x,
        };
        if (h.c, h.h, h.w) != (s.c, s.h, s.w) {
            return Err(TrainError::Input(format!(
                "a residual stage's branches have the shapes {}×{}×{} and {}×{}×{}",
                h.c, h.h, h.w, s.c, s.h, s.w
            )));
        }
        Ok(h.add(&s).relu())
    }
}

/// What single-image inference runs: the encoder with every batch norm folded into
/// the convolution before it, the latent-mean head and the regression head. It gives
/// the evaluation-mode [`Net::forward_wrench`] (to float rounding) in fewer passes.
#[derive(Module, Debug)]
pub struct InferenceNet {
    stem: Conv2d,
    stages: Vec<FoldedBlock>,
    fc_mean: Linear,
    head: Option<Linear>,
}

impl InferenceNet {
    /// Folds an evaluation-mode copy of `net` (its running statistics, not a batch's).
    pub fn new(net: &Net) -> Self {
        let net = net.valid();
        Self {
            stem: fold(&net.stem, &net.stem_bn),
            stages: net
                .stages
                .iter()
                .map(|b| FoldedBlock {
                    conv1: fold(&b.conv1, &b.bn1),
                    conv2: fold(&b.conv2, &b.bn2),
                    skip: b.skip.clone(),
                })
                .collect(),
            fc_mean: net.fc_mean.clone(),
            head: net.head.clone(),
        }
    }

    /// The stem and residual stages for [`Self::forward_one`].
    pub(crate) fn flat(&self) -> FlatNet {
        FlatNet {
            stem: FlatConv::new(&self.stem),
            blocks: self
                .stages
                .iter()
                .map(|b| FlatBlock {
                    conv1: FlatConv::new(&b.conv1),
                    conv2: FlatConv::new(&b.conv2),
                    skip: b.skip.as_ref().map(FlatConv::new),
                })
                .collect(),
        }
    }

    /// [`Self::forward`] of one image (`[1, c, h, w]`), the stem and the residual
    /// stages through `flat` (from [`Self::flat`]): the same values, without
    /// reordering the weights on every call. `fork`: the larger convolutions' output
    /// pixels in two halves through it (the same values).
    pub(crate) fn forward_one(
        &self,
        flat: &FlatNet,
        image: Tensor<4>,
        fork: Option<&dyn Fork>,
    ) -> Result<(Tensor<2>, Option<Tensor<2>>), TrainError> {
        let device = image.device();
        let mut x = flat
            .stem
            .forward(Feature::from_tensor(image)?, fork)?
            .relu();
        for block in &flat.blocks {
            x = block.forward(x, fork)?;
        }
        let mean = self.fc_mean.forward(x.into_tensor(&device).flatten(1, 3));
        let wrench = self.head.as_ref().map(|h| h.forward(relu(mean.clone())));
        Ok((mean, wrench))
    }

    /// Images → (latent mean, standardised wrench if the model predicts one).
    pub fn forward(&self, images: Tensor<4>) -> (Tensor<2>, Option<Tensor<2>>) {
        let mut x = relu(self.stem.forward(images));
        for stage in &self.stages {
            x = stage.forward(x);
        }
        let mean = self.fc_mean.forward(x.flatten(1, 3));
        let wrench = self.head.as_ref().map(|h| h.forward(relu(mean.clone())));
        (mean, wrench)
    }
}

#[cfg(test)]
mod tests {

    #[test]
    fn the_training_graph_s_work_is_counted_as_the_pytorch_peer_counts_it() {
        // torch_light_bench.py's fwd_macs_train_graph_per_img and stem_macs_per_img.
        for (size_px, width, forward, stem) in [
            (32, 16, 3_084_480, 36_864),
            (32, 8, 821_440, 18_432),
            (64, 16, 17_907_904, 147_456),
            (64, 8, 4_628_672, 73_728),
        ] {
            let config = ModelConfig {
                width,
                preprocess: Preprocess {
                    size_px,
                    ..Preprocess::default()
                },
                ..ModelConfig::default()
            };
            assert_eq!(
                config.forward_macs_per_image(),
                (forward, stem),
                "{size_px}/{width}"
            );
        }
        // No decoder, no head: less work.
        let convnet = ModelConfig {
            kind: ModelKind::Convnet,
            ..ModelConfig::default()
        };
        assert!(
            convnet.forward_macs_per_image().0 < ModelConfig::default().forward_macs_per_image().0
        );
    }

    use super::*;

    #[test]
    fn shapes_for_every_kind_and_size() {
        let device = Device::flex();
        for kind in [ModelKind::Svae, ModelKind::Vae, ModelKind::Convnet] {
            for size_px in [16, 32, 64] {
                let config = ModelConfig {
                    kind,
                    width: 4,
                    latent: 6,
                    preprocess: Preprocess {
                        size_px,
                        ..Preprocess::default()
                    },
                    ..ModelConfig::default()
                };
                assert!(config.problems().is_empty());
                let net = config.init(&device);
                let x = Tensor::<4>::zeros([2, 1, size_px, size_px], &device);
                let out = net.forward(x.clone(), Some(Tensor::zeros([2, 6], &device)));
                assert_eq!(out.mean.dims(), [2, 6]);
                assert_eq!(
                    out.wrench.map(|w| w.dims()),
                    kind.predicts_wrench().then_some([2, 6])
                );
                assert_eq!(
                    out.image.map(|i| i.dims()),
                    kind.has_decoder().then_some([2, 1, size_px, size_px])
                );
                let (mean, _) = net.forward_wrench(x);
                assert_eq!(mean.dims(), [2, 6]);
            }
        }
    }

    /// Batch norm with statistics far from the identity (as after training), drawn
    /// from `seed`.
    fn randomise(bn: &mut BatchNorm, seed: u64, device: &Device) {
        use burn::module::RunningState;
        use burn::tensor::Distribution;
        let [c] = bn.gamma.dims();
        device.seed(seed);
        let uniform = |lo, hi| Tensor::<1>::random([c], Distribution::Uniform(lo, hi), device);
        bn.gamma = Param::from_tensor(uniform(0.2, 3.0));
        bn.beta = Param::from_tensor(uniform(-1.0, 1.0));
        bn.running_mean = RunningState::new(uniform(-2.0, 2.0));
        // Down to ~ε, where the scale is largest.
        bn.running_var = RunningState::new(uniform(1e-5, 4.0));
    }

    /// A net of `config` whose batch norms all have statistics from [`randomise`],
    /// drawn from `seed` on (the caller holds `init_lock`).
    fn with_random_statistics(config: &ModelConfig, mut seed: u64, device: &Device) -> Net {
        let mut net = config.init(device);
        randomise(&mut net.stem_bn, seed, device);
        for stage in &mut net.stages {
            for bn in [&mut stage.bn1, &mut stage.bn2] {
                seed += 1;
                randomise(bn, seed, device);
            }
        }
        net
    }

    #[test]
    fn the_folded_inference_net_gives_the_evaluation_mode_output() {
        let device = Device::flex();
        for kind in [ModelKind::Svae, ModelKind::Convnet, ModelKind::Vae] {
            let config = ModelConfig {
                kind,
                width: 4,
                latent: 6,
                preprocess: Preprocess {
                    size_px: 32,
                    ..Preprocess::default()
                },
                ..ModelConfig::default()
            };
            let _guard = crate::train::init_lock();
            let net = with_random_statistics(&config, 10, &device);
            let folded = InferenceNet::new(&net);
            let x = Tensor::<4>::random(
                [3, 1, 32, 32],
                burn::tensor::Distribution::Uniform(0.0, 1.0),
                &device,
            );
            let (mean, wrench) = net.valid().forward_wrench(x.clone());
            let (f_mean, f_wrench) = folded.forward(x);
            let values = |t: Tensor<2>| t.into_data().as_slice::<f32>().expect("f32").to_vec();
            let close = |a: Vec<f32>, b: Vec<f32>| {
                let scale = a.iter().fold(1.0f32, |m, v| m.max(v.abs()));
                a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= 1e-4 * scale)
            };
            assert!(close(values(mean), values(f_mean)), "{kind}: latent mean");
            assert_eq!(wrench.is_some(), f_wrench.is_some());
            if let (Some(w), Some(f)) = (wrench, f_wrench) {
                assert!(close(values(w), values(f)), "{kind}: wrench");
            }
        }
    }

    #[test]
    fn one_image_through_the_reordered_weights_is_bit_for_bit_the_burn_forward() {
        // The stages' convolutions with their weights reordered once must give flex's
        // values exactly, not nearly: estimates, and so grasp trials, stay the same.
        // Widths and sizes cover stages through im2col (3×3, strided 1×1 skips) and
        // a stem through flex's few-channel path; 64 px has 2×2 and 4×4 maps.
        let device = Device::flex();
        for (kind, width, size_px, channels) in [
            (ModelKind::Svae, 16, 32, 1),
            (ModelKind::Convnet, 4, 16, 1),
            (ModelKind::Vae, 8, 64, 3),
            (ModelKind::Svae, 32, 32, 3),
        ] {
            let config = ModelConfig {
                kind,
                width,
                latent: 6,
                preprocess: Preprocess {
                    size_px,
                    channels,
                    ..Preprocess::default()
                },
                ..ModelConfig::default()
            };
            let _guard = crate::train::init_lock();
            let net = with_random_statistics(&config, 40, &device);
            let folded = InferenceNet::new(&net);
            let blocks = folded.flat();
            let values = |t: Tensor<2>| t.into_data().as_slice::<f32>().expect("f32").to_vec();
            for round in 0..3 {
                let x = Tensor::<4>::random(
                    [1, channels, size_px, size_px],
                    burn::tensor::Distribution::Uniform(0.0, 1.0),
                    &device,
                );
                let x = if round == 2 { x.zeros_like() } else { x };
                let (mean, wrench) = folded.forward(x.clone());
                let (mean, wrench) = (values(mean), wrench.map(values));
                // On the caller, and with the larger convolutions in halves on two
                // threads: the same values.
                let forks: [Option<&dyn Fork>; 2] = [None, Some(&crate::preprocess::ScopedThread)];
                for fork in forks {
                    let (f_mean, f_wrench) = folded
                        .forward_one(&blocks, x.clone(), fork)
                        .expect("one image");
                    let what = format!(
                        "{kind} width {width} size {size_px} round {round} split {}",
                        fork.is_some()
                    );
                    assert_eq!(mean, values(f_mean), "{what}: latent mean");
                    assert_eq!(wrench, f_wrench.map(values), "{what}: wrench");
                }
            }
            // A batch is not one image: a clear error, no panic.
            let two = Tensor::<4>::zeros([2, channels, size_px, size_px], &device);
            assert!(folded.forward_one(&blocks, two, None).is_err());
        }
    }

    #[test]
    fn loss_weights_follow_the_paper() {
        let w = |kind, alpha| {
            ModelConfig {
                kind,
                alpha,
                ..ModelConfig::default()
            }
            .loss_weights()
        };
        assert_eq!(w(ModelKind::Svae, 1.0), (0.5, 0.5, 0.1));
        assert_eq!(w(ModelKind::Svae, 0.0), (0.0, 1.0, 0.1));
        let (r, p, _) = w(ModelKind::Svae, 1e12);
        assert!(r > 0.999_999 && p < 1e-9 && p > 0.0);
        assert_eq!(w(ModelKind::Vae, 1.0), (1.0, 0.0, 0.1));
        assert_eq!(w(ModelKind::Convnet, 1.0), (0.0, 1.0, 0.0));
    }

    #[test]
    fn bad_configs_are_listed() {
        let bad = ModelConfig {
            width: 0,
            latent: 0,
            alpha: -1.0,
            beta: f64::NAN,
            ..ModelConfig::default()
        };
        assert_eq!(bad.problems().len(), 4, "{:?}", bad.problems());
        assert!("svae".parse::<ModelKind>().is_ok());
        assert!("resnet".parse::<ModelKind>().is_err());
    }
}
