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

use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, Linear, LinearConfig, PaddingConfig2d};
use burn::prelude::*;
use burn::tensor::activation::{relu, sigmoid};
use serde::{Deserialize, Serialize};

use crate::kernels::{add_relu, batch_norm, batch_norm_relu, conv_transpose2d, conv2d};
use crate::preprocess::Preprocess;

mod inference;

pub(crate) use inference::FlatNet;
pub use inference::InferenceNet;

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

    /// One line naming the settings, e.g. `svae width 16 latent 32 input 1×32×32 α 1 β 0.1`
    /// (the input's signal named where it is not brightness: `input 1×32×32 chroma`).
    pub fn describe(&self) -> String {
        let signal = match self.preprocess.signal {
            crate::Signal::Brightness => String::new(),
            other => format!(" {other}"),
        };
        format!(
            "{} width {} latent {} input {}×{}×{}{signal} α {} β {}",
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

#[cfg(test)]
mod tests {

    #[test]
    fn the_training_graph_s_work_is_counted_as_the_pytorch_peer_counts_it() {
        // bench/torch_peer.py's forward_macs_per_image (its JSON's fwd_macs_train_graph_per_img
        // and stem_macs_per_img).
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
