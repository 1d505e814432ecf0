//! What single-image inference runs: the encoder with each batch norm folded into
//! the convolution before it ([`InferenceNet`]), and its convolutions with their
//! weights reordered once ([`FlatNet`], through [`crate::im2col`]).

use burn::module::Param;
use burn::nn::conv::Conv2d;
use burn::nn::{BatchNorm, Linear};
use burn::prelude::*;
use burn::tensor::activation::relu;

use super::Net;
use crate::TrainError;
use crate::im2col::{Feature, FlatConv};
use crate::preprocess::Fork;

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
    use super::*;
    use crate::model::{ModelConfig, ModelKind};
    use crate::preprocess::Preprocess;

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
}
