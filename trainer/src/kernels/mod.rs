//! Training's convolutions and batch norms on the flex backend, registered with
//! burn's autodiff as custom operations: convolutions forward and backward as im2col
//! and one `gemm` per block of the batch (`conv.rs`), batch norm with the batch's
//! statistics in a few passes over the map (`norm.rs`).
//!
//! Why: burn-flex converts every convolution's input to channels-last and back,
//! builds its patches image by image, computes the input gradient as a transposed
//! convolution of scalar loops and the weight gradient as a convolution with the
//! batch as channels; on the SVAE's small maps that kept training at about 0.6× the
//! PyTorch peer on the same two cores. `softtouch bench train` measures both paths
//! side by side (`SOFTTOUCH_CONV=burn` selects burn's); the numbers are in
//! `trainer/README.md`.
//!
//! [`conv2d`], [`conv_transpose2d`] and [`batch_norm`] take the burn modules as they
//! are (the same parameters, running statistics and artifacts) and fall back to the
//! module's own `forward` for anything these kernels do not cover: a tensor that is not an autodiff flex tensor
//! (evaluation, inference, the ndarray backend), groups, dilation, asymmetric or
//! `Same` padding, a batch norm that is not training, or a dtype other than f32.

mod conv;
mod gemm;
mod norm;
#[cfg(test)]
mod tests;

use burn::backend::autodiff::NodeId;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::NoCheckpointing;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, NodeGuard, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::{Autodiff, Flex};
use burn::nn::conv::{Conv2d, ConvTranspose2d};
use burn::nn::{BatchNorm, PaddingConfig2d};
use burn::prelude::*;
use burn::tensor::DType;

use conv::Geometry;

/// The environment variable that sends training's convolutions and batch norms back
/// to burn's own kernels (`SOFTTOUCH_CONV=burn`), to compare the two.
pub const ENV: &str = "SOFTTOUCH_CONV";

fn enabled() -> bool {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ON.get_or_init(|| parse_env(std::env::var(ENV).ok().as_deref()).unwrap_or(true))
}

/// Whether [`ENV`]'s value selects these kernels: unset, empty or `softtouch` yes,
/// `burn` no, anything else an error naming the variable.
pub(crate) fn parse_env(value: Option<&str>) -> Result<bool, String> {
    match value.map(str::trim) {
        None | Some("" | "softtouch") => Ok(true),
        Some("burn") => Ok(false),
        Some(other) => Err(format!(
            "{ENV}={other}: expected softtouch (the default) or burn"
        )),
    }
}

/// Which kernels training's convolutions and batch norms run on flex, for a bench's
/// header.
pub fn describe() -> &'static str {
    if enabled() {
        "softtouch's kernels (SOFTTOUCH_CONV=burn for burn's)"
    } else {
        "burn's own (SOFTTOUCH_CONV=burn)"
    }
}

type Ad = Autodiff<Flex>;

/// `conv.forward(x)`, through these kernels where they apply.
pub(crate) fn conv2d(x: Tensor<4>, conv: &Conv2d) -> Tensor<4> {
    let [batch, c_in, h, w] = x.dims();
    let [c_out, c_in_w, kh, kw] = conv.weight.dims();
    let pad = match conv.padding {
        PaddingConfig2d::Valid => Some([0, 0]),
        PaddingConfig2d::Explicit(top, left, bottom, right) if top == bottom && left == right => {
            Some([top, left])
        }
        _ => None,
    };
    let geometry = pad
        .filter(|_| enabled() && conv.groups == 1 && conv.dilation == [1, 1] && c_in == c_in_w)
        .and_then(|pad| Geometry::new([batch, c_in, c_out], [kh, kw], conv.stride, pad, [h, w]));
    let bias = conv.bias.as_ref().map(|b| b.val());
    match geometry.and_then(|g| run(Kind::Conv, g, x.clone(), conv.weight.val(), bias)) {
        Some(y) => y,
        None => conv.forward(x),
    }
}

/// `conv.forward(x)` of a transposed convolution, through these kernels where they
/// apply: the input gradient of the convolution it transposes, whose input is this
/// one's output.
pub(crate) fn conv_transpose2d(x: Tensor<4>, conv: &ConvTranspose2d) -> Tensor<4> {
    let [batch, c_in, h, w] = x.dims();
    let [c_in_w, c_out, kh, kw] = conv.weight.dims();
    let out = |d: usize, size: usize, k: usize| {
        ((size.max(1) - 1) * conv.stride[d] + k + conv.padding_out[d])
            .checked_sub(2 * conv.padding[d])
    };
    let geometry = (enabled()
        && conv.groups == 1
        && conv.dilation == [1, 1]
        && c_in == c_in_w
        && h > 0
        && w > 0)
        .then(|| Some([out(0, h, kh)?, out(1, w, kw)?]))
        .flatten()
        .and_then(|out_hw| {
            Geometry::new(
                [batch, c_out, c_in],
                [kh, kw],
                conv.stride,
                conv.padding,
                out_hw,
            )
        })
        .filter(|g| g.out_hw == [h, w]);
    let bias = conv.bias.as_ref().map(|b| b.val());
    match geometry.and_then(|g| run(Kind::Transposed, g, x.clone(), conv.weight.val(), bias)) {
        Some(y) => y,
        None => conv.forward(x),
    }
}

/// Whether the operation is the convolution of [`Geometry`] or its transpose (whose
/// input is the geometry's output and whose output is the geometry's input).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Conv,
    Transposed,
}

/// What the backward pass needs: the operation's input and weight.
#[derive(Debug, Clone)]
struct State {
    kind: Kind,
    geometry: Geometry,
    input: FlexTensor,
    weight: FlexTensor,
}

/// The operation's gradients with respect to its input, weight and bias.
struct Grads {
    input: Option<FlexTensor>,
    weight: Option<FlexTensor>,
    bias: Option<FlexTensor>,
}

fn f32s(t: &FlexTensor) -> Option<FlexTensor> {
    (t.dtype() == DType::F32).then(|| t.to_contiguous())
}

fn slice(t: &FlexTensor) -> &[f32] {
    t.as_slice::<f32>().unwrap_or(&[])
}

fn tensor(values: Vec<f32>, shape: Vec<usize>) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(values, shape))
}

impl State {
    fn grads(&self, grad: FlexTensor, want: [bool; 3]) -> Grads {
        let g = &self.geometry;
        let grad = grad.to_contiguous();
        let (dy, x, w) = (slice(&grad), slice(&self.input), slice(&self.weight));
        let in_shape = self.input.layout().shape().to_vec();
        let w_shape = self.weight.layout().shape().to_vec();
        let [want_input, want_weight, want_bias] = want;
        // The weight's gradient is that of the convolution of the geometry: of this
        // operation's input for a convolution, of its output's gradient for a transposed
        // one, whose input gradient is then that convolution's output.
        let (conv_x, conv_dy, also) = match self.kind {
            Kind::Conv => (x, dy, conv::Also::InputGradient),
            Kind::Transposed => (dy, x, conv::Also::Output),
        };
        let (weight, input) = match (want_weight, want_input) {
            (true, true) => {
                let (dw, dx) = conv::backward(g, conv_x, w, conv_dy, also);
                (Some(dw), dx)
            }
            (true, false) => (
                Some(conv::backward(g, conv_x, w, conv_dy, conv::Also::Nothing).0),
                None,
            ),
            (false, true) => match self.kind {
                Kind::Conv => (None, Some(conv::input_gradient(g, w, dy))),
                Kind::Transposed => (None, Some(conv::forward(g, dy, w, None))),
            },
            (false, false) => (None, None),
        };
        let (c_bias, px) = match self.kind {
            Kind::Conv => (g.c_out, g.out_hw[0] * g.out_hw[1]),
            Kind::Transposed => (g.c_in, g.in_hw[0] * g.in_hw[1]),
        };
        let bias = want_bias.then(|| conv::channel_sums(dy, g.batch, c_bias, px));
        Grads {
            input: input.map(|v| tensor(v, in_shape)),
            weight: weight.map(|v| tensor(v, w_shape)),
            bias: bias.map(|v| tensor(v, vec![c_bias])),
        }
    }
}

/// Hands each gradient that was asked for (a parent that is tracked) to autodiff.
fn register<const K: usize>(
    grads: &mut Gradients,
    pairs: [(Option<NodeId>, Option<FlexTensor>); K],
) {
    for (node, grad) in pairs {
        if let (Some(node), Some(grad)) = (node, grad) {
            grads.register::<Flex>(node, grad);
        }
    }
}

#[derive(Debug)]
struct WithBias;
#[derive(Debug)]
struct NoBias;

impl Backward<Flex, 3> for WithBias {
    type State = State;
    fn backward(self, ops: Ops<State, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [input, weight, bias] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        let [input, weight, bias] = [input, weight, bias].map(|n| n.map(|n| n.id));
        let out = ops
            .state
            .grads(grad, [input, weight, bias].map(|n| n.is_some()));
        register(
            grads,
            [(input, out.input), (weight, out.weight), (bias, out.bias)],
        );
    }
}

impl Backward<Flex, 2> for NoBias {
    type State = State;
    fn backward(self, ops: Ops<State, 2>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [input, weight] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        let [input, weight] = [input, weight].map(|n| n.map(|n| n.id));
        let out = ops
            .state
            .grads(grad, [input.is_some(), weight.is_some(), false]);
        register(grads, [(input, out.input), (weight, out.weight)]);
    }
}

/// The operation on autodiff flex tensors; `None` (nothing consumed but clones) when
/// a tensor is of another backend or dtype.
fn run(
    kind: Kind,
    g: Geometry,
    x: Tensor<4>,
    w: Tensor<4>,
    b: Option<Tensor<1>>,
) -> Option<Tensor<4>> {
    let x = x.try_into_primitive::<Ad>().ok()?;
    let w = w.try_into_primitive::<Ad>().ok()?;
    let b = match b {
        Some(b) => Some(b.try_into_primitive::<Ad>().ok()?),
        None => None,
    };
    let input = f32s(x.primitive())?;
    let weight = f32s(w.primitive())?;
    let bias = match &b {
        Some(b) => Some(f32s(b.primitive())?),
        None => None,
    };
    let bias_values = bias.as_ref().map(slice);
    // The geometry was worked out from these tensors' shapes; their values must fill it.
    let (in_len, bias_len) = match kind {
        Kind::Conv => (g.x_len(), g.c_out),
        Kind::Transposed => (g.y_len(), g.c_in),
    };
    if slice(&input).len() != in_len
        || slice(&weight).len() != g.w_len()
        || bias_values.is_some_and(|b| b.len() != bias_len)
    {
        return None;
    }
    let (values, shape) = match kind {
        Kind::Conv => (
            conv::forward(&g, slice(&input), slice(&weight), bias_values),
            [g.batch, g.c_out, g.out_hw[0], g.out_hw[1]],
        ),
        Kind::Transposed => {
            let mut y = conv::input_gradient(&g, slice(&weight), slice(&input));
            if let Some(bias) = bias_values {
                conv::add_channel_bias(&mut y, g.in_hw[0] * g.in_hw[1], bias);
            }
            (y, [g.batch, g.c_in, g.in_hw[0], g.in_hw[1]])
        }
    };
    let output = tensor(values, shape.to_vec());
    let state = State {
        kind,
        geometry: g,
        input,
        weight,
    };
    Some(match b {
        Some(b) => record(WithBias, [x.node(), w.node(), b.node()], state, output),
        None => record(NoBias, [x.node(), w.node()], state, output),
    })
}

/// Records `op` in autodiff's graph over the tensors of `nodes` (with `state` for its
/// backward pass when any of them is tracked) and gives its `output`.
fn record<O, const N: usize>(
    op: O,
    nodes: [NodeGuard; N],
    state: O::State,
    output: FlexTensor,
) -> Tensor<4>
where
    O: Backward<Flex, N>,
{
    let out = match op
        .prepare::<NoCheckpointing>(nodes)
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(prep) => prep.finish(state, output),
        OpsKind::UnTracked(prep) => prep.finish(output),
    };
    Tensor::from_primitive::<Ad>(out)
}

/// `bn.forward(x)` in training mode (the batch's statistics, the running statistics
/// updated as burn's `BatchNorm` updates them), through [`norm`] where it applies.
pub(crate) fn batch_norm(x: Tensor<4>, bn: &BatchNorm) -> Tensor<4> {
    norm_then(x, bn, false)
}

/// `relu(bn.forward(x))`, the two in one operation where [`batch_norm`] runs
/// [`norm`] (the same values: two passes over the activations fewer each way).
pub(crate) fn batch_norm_relu(x: Tensor<4>, bn: &BatchNorm) -> Tensor<4> {
    norm_then(x, bn, true)
}

/// Batch norm, then ReLU when `relu`: through [`norm`] in training, else burn's.
fn norm_then(x: Tensor<4>, bn: &BatchNorm, relu: bool) -> Tensor<4> {
    let training = enabled() && x.device().is_autodiff() && bn.training.is_enabled();
    if let Some(y) = training
        .then(|| batch_norm_train(x.clone(), bn, relu))
        .flatten()
    {
        return y;
    }
    let y = bn.forward(x);
    if relu {
        burn::tensor::activation::relu(y)
    } else {
        y
    }
}

/// `relu(a + b)`, the residual join, as one operation on autodiff flex tensors of one
/// shape (one pass each way where burn makes two; the same values).
pub(crate) fn add_relu(a: Tensor<4>, b: Tensor<4>) -> Tensor<4> {
    let fused = (enabled() && a.dims() == b.dims())
        .then(|| add_relu_tracked(a.clone(), b.clone()))
        .flatten();
    match fused {
        Some(y) => y,
        None => burn::tensor::activation::relu(a + b),
    }
}

fn add_relu_tracked(a: Tensor<4>, b: Tensor<4>) -> Option<Tensor<4>> {
    let shape = a.dims().to_vec();
    let a = a.try_into_primitive::<Ad>().ok()?;
    let b = b.try_into_primitive::<Ad>().ok()?;
    let (va, vb) = (f32s(a.primitive())?, f32s(b.primitive())?);
    let (sa, sb) = (slice(&va), slice(&vb));
    if sa.len() != sb.len() || sa.len() != shape.iter().product::<usize>() {
        return None;
    }
    let mut out = vec![0.0f32; sa.len()];
    norm::add_relu(sa, sb, &mut out);
    let output = tensor(out, shape);
    Some(record(
        AddRelu,
        [a.node(), b.node()],
        output.clone(),
        output,
    ))
}

/// [`add_relu`]'s backward pass: the output's gradient where the output was kept,
/// to both terms. Its state is the output (a shared buffer, not a copy).
#[derive(Debug)]
struct AddRelu;

impl Backward<Flex, 2> for AddRelu {
    type State = FlexTensor;
    fn backward(self, ops: Ops<FlexTensor, 2>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [a, b] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node).to_contiguous();
        let output = &ops.state;
        let mut d = vec![0.0f32; slice(&grad).len()];
        norm::relu_gradient(slice(output), slice(&grad), &mut d);
        let d = tensor(d, output.layout().shape().to_vec());
        register(
            grads,
            [
                (a.map(|n| n.id), Some(d.clone())),
                (b.map(|n| n.id), Some(d)),
            ],
        );
    }
}

/// What batch norm's backward pass needs.
#[derive(Debug, Clone)]
struct NormState {
    shape: norm::Shape,
    input: FlexTensor,
    gamma: Vec<f32>,
    mean: Vec<f32>,
    inv_std: Vec<f32>,
    /// With a ReLU after it: the output's scale and shift per channel.
    relu: Option<(Vec<f32>, Vec<f32>)>,
}

#[derive(Debug)]
struct NormOp;

impl Backward<Flex, 3> for NormOp {
    type State = NormState;
    fn backward(self, ops: Ops<NormState, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [input, gamma, beta] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node).to_contiguous();
        let st = &ops.state;
        let (dx, d_gamma, d_beta) = norm::backward(
            st.shape,
            slice(&st.input),
            slice(&grad),
            &st.gamma,
            &st.mean,
            &st.inv_std,
            input.is_some(),
            st.relu
                .as_ref()
                .map(|(scale, beta)| norm::Relu { scale, beta }),
        );
        let shape = st.input.layout().shape().to_vec();
        let c = st.shape.channels;
        let out = [
            (input.map(|n| n.id), dx.map(|v| tensor(v, shape))),
            (gamma.map(|n| n.id), Some(tensor(d_gamma, vec![c]))),
            (beta.map(|n| n.id), Some(tensor(d_beta, vec![c]))),
        ];
        register(grads, out);
    }
}

fn batch_norm_train(x: Tensor<4>, bn: &BatchNorm, relu: bool) -> Option<Tensor<4>> {
    let device = x.device();
    let [batch, channels, h, w] = x.dims();
    let x = x.try_into_primitive::<Ad>().ok()?;
    let gamma = bn.gamma.val().try_into_primitive::<Ad>().ok()?;
    let beta = bn.beta.val().try_into_primitive::<Ad>().ok()?;
    let input = f32s(x.primitive())?;
    let (g, b) = (f32s(gamma.primitive())?, f32s(beta.primitive())?);
    if slice(&g).len() != channels
        || slice(&b).len() != channels
        || slice(&input).len() != batch * channels * h * w
        || batch * h * w == 0
    {
        return None;
    }
    let shape = norm::Shape {
        batch,
        channels,
        px: h * w,
    };
    let out = norm::forward(shape, slice(&input), slice(&g), slice(&b), bn.epsilon, relu);
    let state = NormState {
        shape,
        input,
        gamma: slice(&g).to_vec(),
        mean: out.mean.clone(),
        inv_std: out.inv_std,
        relu: relu.then(|| (out.scale, slice(&b).to_vec())),
    };
    let output = tensor(out.output, vec![batch, channels, h, w]);
    let y = record(NormOp, [x.node(), gamma.node(), beta.node()], state, output);
    // The running statistics, as `BatchNorm::forward` keeps them.
    let stat = |v: Vec<f32>| Tensor::<1>::from_data(TensorData::new(v, [channels]), &device);
    let m = bn.momentum;
    let follow = |running: Tensor<1>, batch: Vec<f32>| {
        running
            .to_device(&device)
            .mul_scalar(1.0 - m)
            .add(stat(batch).mul_scalar(m))
            .detach()
    };
    bn.running_mean
        .update(follow(bn.running_mean.value_sync(), out.mean));
    bn.running_var
        .update(follow(bn.running_var.value_sync(), out.variance));
    Some(y)
}
