//! The kernels against burn's own convolutions: outputs and every gradient, on
//! random shapes (batch 1, odd sizes, strides 1 to 3, padding 0–2, 1×1 to 4×4
//! kernels, with and without bias, one block or several per chunk) and on zero inputs.

use burn::module::Param;
use burn::nn::conv::{Conv2d, Conv2dConfig, ConvTranspose2d, ConvTranspose2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, PaddingConfig2d};
use burn::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::gemm::{View, matmul};
use super::{add_relu, batch_norm, batch_norm_relu, conv_transpose2d, conv2d};

fn device() -> Device {
    Device::flex().autodiff()
}

fn random(shape: [usize; 4], rng: &mut ChaCha8Rng, device: &Device) -> Tensor<4> {
    let n = shape.iter().product();
    let values: Vec<f32> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    Tensor::from_data(TensorData::new(values, shape), device)
}

fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().unwrap_or_default()
}

/// Every value of `a` within `tol` of `b`'s, relative to `b`'s largest magnitude.
fn assert_close(what: &str, a: &[f32], b: &[f32], tol: f32) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    let scale = b.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= tol * scale,
            "{what}[{i}]: {x} against burn's {y} (scale {scale})"
        );
    }
}

/// The gradients of `Σ r·op(x)` for a fixed random `r`: output, ∂x, ∂w and ∂b.
struct Run {
    output: Vec<f32>,
    dx: Vec<f32>,
    dw: Vec<f32>,
    db: Option<Vec<f32>>,
}

fn gradients<const W: usize>(
    x: &Tensor<4>,
    weight: &Param<Tensor<W>>,
    bias: Option<&Param<Tensor<1>>>,
    op: impl FnOnce(Tensor<4>) -> Tensor<4>,
    rng_seed: u64,
) -> Run {
    let x = x.clone().detach().require_grad();
    let y = op(x.clone());
    let mut rng = ChaCha8Rng::seed_from_u64(rng_seed);
    let r = random(y.dims(), &mut rng, &y.device());
    let grads = (y.clone() * r).sum().backward();
    Run {
        output: values(y),
        dx: x.grad(&grads).map(values).unwrap_or_default(),
        dw: weight.val().grad(&grads).map(values).unwrap_or_default(),
        db: bias.and_then(|b| b.val().grad(&grads)).map(values),
    }
}

fn compare(what: &str, ours: Run, burns: Run) {
    assert_close(&format!("{what} output"), &ours.output, &burns.output, 1e-5);
    assert_close(&format!("{what} ∂x"), &ours.dx, &burns.dx, 1e-5);
    assert_close(&format!("{what} ∂w"), &ours.dw, &burns.dw, 1e-5);
    match (ours.db, burns.db) {
        (Some(a), Some(b)) => assert_close(&format!("{what} ∂b"), &a, &b, 1e-5),
        (None, None) => {}
        (a, b) => panic!("{what} ∂b: {a:?} against burn's {b:?}"),
    }
}

/// `ours` against `burns` on a random and an all-zero input of `shape`.
fn check(
    what: &str,
    shape: [usize; 4],
    rng: &mut ChaCha8Rng,
    (weight, bias): (&Param<Tensor<4>>, Option<&Param<Tensor<1>>>),
    ours: impl Fn(Tensor<4>) -> Tensor<4>,
    burns: impl Fn(Tensor<4>) -> Tensor<4>,
) {
    let device = device();
    for zero in [false, true] {
        let x = if zero {
            Tensor::zeros(shape, &device)
        } else {
            random(shape, rng, &device)
        };
        let seed = rng.random();
        let a = gradients(&x, weight, bias, &ours, seed);
        let b = gradients(&x, weight, bias, &burns, seed);
        compare(&format!("{what} zero {zero}"), a, b);
    }
}

/// (batch, c_in, c_out, kernel, stride, padding, height, width, bias)
type Case = (usize, usize, usize, usize, usize, usize, usize, usize, bool);

const CONVS: [Case; 10] = [
    (1, 1, 1, 1, 1, 0, 1, 1, false),
    (1, 1, 16, 3, 2, 1, 32, 32, false),
    (3, 5, 7, 3, 1, 1, 9, 7, true),
    (4, 16, 32, 3, 2, 1, 16, 16, false),
    (2, 16, 32, 1, 2, 0, 16, 16, true),
    (5, 3, 4, 3, 2, 2, 7, 5, true),
    (2, 2, 3, 4, 1, 0, 5, 6, false),
    (7, 8, 8, 3, 1, 1, 4, 4, false),
    (2, 4, 2, 3, 3, 1, 11, 10, true),
    // Patches of more than one block per image: each image its own block.
    (3, 16, 8, 3, 1, 1, 32, 32, true),
];

fn conv_of(case: Case, device: &Device) -> Conv2d {
    let (_, c_in, c_out, k, stride, pad, _, _, bias) = case;
    Conv2dConfig::new([c_in, c_out], [k, k])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
        .with_bias(bias)
        .init(device)
}

#[test]
fn convolutions_match_burns_values_and_gradients() {
    let device = device();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for case in CONVS {
        let (batch, c_in, _, _, _, _, h, w, _) = case;
        let conv = conv_of(case, &device);
        let (ours, burns) = (|x| conv2d(x, &conv), |x| conv.forward(x));
        let what = format!("conv {case:?}");
        let params = (&conv.weight, conv.bias.as_ref());
        check(&what, [batch, c_in, h, w], &mut rng, params, ours, burns);
    }
}

#[test]
fn transposed_convolutions_match_burns_values_and_gradients() {
    let device = device();
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    // (batch, c_in, c_out, kernel, stride, padding, height, width, bias)
    let cases: [Case; 7] = [
        (1, 1, 1, 1, 1, 0, 1, 1, false),
        (4, 32, 16, 4, 2, 1, 4, 4, false),
        (2, 16, 1, 4, 2, 1, 16, 16, true),
        (3, 5, 3, 3, 1, 1, 7, 6, true),
        (1, 2, 4, 3, 2, 0, 5, 3, false),
        (5, 3, 2, 4, 3, 2, 4, 5, true),
        (3, 8, 16, 4, 2, 1, 16, 16, false),
    ];
    for case in cases {
        let (batch, c_in, c_out, k, stride, pad, h, w, bias) = case;
        let conv: ConvTranspose2d = ConvTranspose2dConfig::new([c_in, c_out], [k, k])
            .with_stride([stride, stride])
            .with_padding([pad, pad])
            .with_bias(bias)
            .init(&device);
        let (ours, burns) = (|x| conv_transpose2d(x, &conv), |x| conv.forward(x));
        let what = format!("transposed {case:?}");
        let params = (&conv.weight, conv.bias.as_ref());
        check(&what, [batch, c_in, h, w], &mut rng, params, ours, burns);
    }
}

#[test]
fn what_the_kernels_do_not_cover_is_burns_own_computation() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    // Without autodiff (evaluation), with `Same` padding, with dilation: burn's bits.
    let plain = Device::flex();
    let conv = conv_of((2, 3, 4, 3, 1, 1, 6, 6, true), &plain);
    let x = random([2, 3, 6, 6], &mut rng, &plain);
    assert_eq!(values(conv2d(x.clone(), &conv)), values(conv.forward(x)));
    let device = device();
    let same = Conv2dConfig::new([3, 4], [3, 3])
        .with_padding(PaddingConfig2d::Same)
        .init(&device);
    let dilated = Conv2dConfig::new([3, 4], [3, 3])
        .with_dilation([2, 2])
        .init(&device);
    let x = random([2, 3, 7, 7], &mut rng, &device);
    for conv in [same, dilated] {
        assert_eq!(
            values(conv2d(x.clone(), &conv)),
            values(conv.forward(x.clone()))
        );
    }
}

#[test]
fn a_batch_split_over_threads_gives_the_same_gradients_as_one_thread() {
    let device = device();
    let case = (9, 4, 6, 3, 2, 1, 9, 9, true);
    let conv = conv_of(case, &device);
    let mut rng = ChaCha8Rng::seed_from_u64(10);
    let x = random([9, 4, 9, 9], &mut rng, &device);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        pool.install(|| {
            gradients(
                &x,
                &conv.weight,
                conv.bias.as_ref(),
                |x| conv2d(x, &conv),
                1,
            )
        })
    };
    let (one, four) = (run(1), run(4));
    // The output and ∂x are per image; ∂w and ∂b are sums whose order follows the
    // chunks, so they agree to rounding.
    assert_eq!(one.output, four.output);
    assert_eq!(one.dx, four.dx);
    assert_close("∂w", &four.dw, &one.dw, 1e-6);
}

#[test]
#[allow(clippy::float_cmp)] // small integers: exact in f32
fn matmul_multiplies_transposes_and_accumulates() {
    // [1 2 3; 4 5 6] · [1 0; 0 1; 1 1] = [4 5; 10 11]
    let a = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    let b = [1.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    let mut c = [9.0f32; 4];
    matmul(&mut c, false, View::rows(&a, 2, 3), View::rows(&b, 3, 2));
    assert_eq!(c, [4.0, 5.0, 10.0, 11.0]);
    matmul(&mut c, true, View::rows(&a, 2, 3), View::rows(&b, 3, 2));
    assert_eq!(c, [8.0, 10.0, 20.0, 22.0]);
    // aᵀ·a through a transposed view: [17 22 27; 22 29 36; 27 36 45]
    let mut d = [0.0f32; 9];
    matmul(
        &mut d,
        false,
        View::rows(&a, 2, 3).t(),
        View::rows(&a, 2, 3),
    );
    assert_eq!(d, [17.0, 22.0, 27.0, 22.0, 29.0, 36.0, 27.0, 36.0, 45.0]);
    // An empty inner dimension: zero, or unchanged when accumulating.
    let mut e = [3.0f32; 4];
    matmul(&mut e, true, View::rows(&[], 2, 0), View::rows(&[], 0, 2));
    assert_eq!(e, [3.0; 4]);
    matmul(&mut e, false, View::rows(&[], 2, 0), View::rows(&[], 0, 2));
    assert_eq!(e, [0.0; 4]);
}

#[test]
#[should_panic(expected = "outside its data")]
fn a_view_past_its_slice_is_refused_before_gemm_reads_it() {
    let mut c = [0.0f32; 4];
    matmul(
        &mut c,
        false,
        View::rows(&[1.0; 5], 2, 3),
        View::rows(&[1.0; 6], 3, 2),
    );
}

#[test]
#[should_panic(expected = "matmul: 2×3 by 2×2")]
fn mismatched_inner_dimensions_are_refused() {
    let mut c = [0.0f32; 4];
    matmul(
        &mut c,
        false,
        View::rows(&[1.0; 6], 2, 3),
        View::rows(&[1.0; 4], 2, 2),
    );
}

/// A training-mode batch norm of `c` channels with random γ and β.
fn norm_of(c: usize, seed: u64, device: &Device) -> BatchNorm {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut bn = BatchNormConfig::new(c).init(device);
    let mut param = |lo: f32, hi: f32| {
        let v: Vec<f32> = (0..c).map(|_| rng.random_range(lo..hi)).collect();
        Param::from_tensor(Tensor::<1>::from_data(TensorData::new(v, [c]), device))
    };
    bn.gamma = param(0.5, 1.5);
    bn.beta = param(-0.5, 0.5);
    bn
}

#[test]
fn batch_norm_matches_burns_values_gradients_and_running_statistics() {
    let device = device();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    // (batch, channels, height, width, how the input is filled)
    let cases = [
        (4, 3, 5, 5, "random"),
        (1, 2, 1, 1, "random"), // one value per channel: variance 0
        (3, 16, 8, 8, "random"),
        (2, 4, 3, 3, "zero"),
        (2, 4, 3, 3, "constant"),
        (5, 2, 4, 3, "large"),
    ];
    for (i, (batch, c, h, w, fill)) in cases.into_iter().enumerate() {
        let shape = [batch, c, h, w];
        let x = match fill {
            "zero" => Tensor::zeros(shape, &device),
            "constant" => Tensor::full(shape, 3.25, &device),
            "large" => random(shape, &mut rng, &device)
                .mul_scalar(1e4)
                .add_scalar(5e4),
            _ => random(shape, &mut rng, &device),
        };
        // Alone, and with the ReLU after it fused in.
        for relu in [false, true] {
            batch_norm_case(
                &x,
                c,
                i as u64,
                relu,
                &format!("{shape:?} {fill}"),
                fill == "large",
            );
        }
    }
}

/// One batch-norm case of [`batch_norm_matches_burns_values_gradients_and_running_statistics`].
fn batch_norm_case(x: &Tensor<4>, c: usize, seed: u64, relu: bool, what: &str, large: bool) {
    let device = x.device();
    let (ours_bn, burns_bn) = (norm_of(c, seed, &device), norm_of(c, seed, &device));
    let ours = gradients(
        x,
        &ours_bn.gamma,
        Some(&ours_bn.beta),
        |x| {
            if relu {
                batch_norm_relu(x, &ours_bn)
            } else {
                batch_norm(x, &ours_bn)
            }
        },
        seed,
    );
    let burns = gradients(
        x,
        &burns_bn.gamma,
        Some(&burns_bn.beta),
        |x| {
            let y = burns_bn.forward(x);
            if relu {
                burn::tensor::activation::relu(y)
            } else {
                y
            }
        },
        seed,
    );
    let what = format!("batch norm{} {what}", if relu { " + ReLU" } else { "" });
    if relu {
        // Fused, the same bits as the kernel's batch norm followed by burn's ReLU.
        let apart_bn = norm_of(c, seed, &device);
        let apart = gradients(
            x,
            &apart_bn.gamma,
            Some(&apart_bn.beta),
            |x| burn::tensor::activation::relu(batch_norm(x, &apart_bn)),
            seed,
        );
        assert_eq!(ours.output, apart.output, "{what}: output, fused and apart");
        assert_eq!(ours.dx, apart.dx, "{what}: ∂x, fused and apart");
        assert_eq!(ours.dw, apart.dw, "{what}: ∂γ, fused and apart");
        assert_eq!(ours.db, apart.db, "{what}: ∂β, fused and apart");
    }
    assert!(
        ours.output.iter().chain(&ours.dx).all(|v| v.is_finite()),
        "{what}: not finite"
    );
    // burn's f32 sums against these f64 ones: the large inputs' variance differs in
    // the last bits, which the gradient (a difference of nearly equal terms) shows.
    let tol = if large { 2e-3 } else { 2e-5 };
    assert_close(&format!("{what} output"), &ours.output, &burns.output, tol);
    assert_close(&format!("{what} ∂x"), &ours.dx, &burns.dx, tol);
    assert_close(&format!("{what} ∂γ"), &ours.dw, &burns.dw, tol);
    let (a, b) = (ours.db.unwrap_or_default(), burns.db.unwrap_or_default());
    assert_close(&format!("{what} ∂β"), &a, &b, tol);
    for (name, a, b) in [
        (
            "running mean",
            &ours_bn.running_mean,
            &burns_bn.running_mean,
        ),
        (
            "running variance",
            &ours_bn.running_var,
            &burns_bn.running_var,
        ),
    ] {
        assert_close(
            &format!("{what} {name}"),
            &values(a.value()),
            &values(b.value()),
            1e-5,
        );
    }
}

/// The residual join `relu(a + b)` in one operation: burn's values and both terms'
/// gradients bit for bit, on random terms, on terms that cancel to exactly 0 (the
/// ReLU's edge) and with one term not tracked; burn's own outside autodiff.
#[test]
fn add_relu_is_burns_relu_of_the_sum() {
    let device = device();
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let shape = [3, 4, 5, 5];
    let a = random(shape, &mut rng, &device);
    for (name, b) in [
        ("random", random(shape, &mut rng, &device)),
        ("cancelling", a.clone().neg()),
    ] {
        for track_b in [true, false] {
            let run = |fused: bool| {
                let a = a.clone().detach().require_grad();
                let b = if track_b {
                    b.clone().detach().require_grad()
                } else {
                    b.clone().detach()
                };
                let y = if fused {
                    add_relu(a.clone(), b.clone())
                } else {
                    burn::tensor::activation::relu(a.clone() + b.clone())
                };
                let r = random(shape, &mut ChaCha8Rng::seed_from_u64(5), &device);
                let grads = (y.clone() * r).sum().backward();
                let da = a.grad(&grads).map(values);
                let db = b.grad(&grads).map(values);
                (values(y), da, db)
            };
            assert_eq!(run(true), run(false), "{name}, b tracked {track_b}");
        }
    }
    let plain = Device::flex();
    let (a, b) = (
        random(shape, &mut rng, &plain),
        random(shape, &mut rng, &plain),
    );
    assert_eq!(
        values(add_relu(a.clone(), b.clone())),
        values(burn::tensor::activation::relu(a + b))
    );
}

#[test]
fn batch_norm_outside_training_is_burns_own() {
    let plain = Device::flex();
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let bn = norm_of(3, 1, &plain);
    let x = random([2, 3, 4, 4], &mut rng, &plain);
    assert_eq!(
        values(batch_norm(x.clone(), &bn)),
        values(bn.forward(x.clone()))
    );
    assert_eq!(
        values(batch_norm_relu(x.clone(), &bn)),
        values(burn::tensor::activation::relu(bn.forward(x)))
    );
}

#[test]
fn the_kernels_variable_is_read_or_refused_by_name() {
    use super::parse_env;
    for on in [None, Some(""), Some("softtouch"), Some(" softtouch ")] {
        assert_eq!(parse_env(on), Ok(true), "{on:?}");
    }
    assert_eq!(parse_env(Some("burn")), Ok(false));
    let err = parse_env(Some("flex")).expect_err("unknown value");
    assert!(
        err.contains("SOFTTOUCH_CONV=flex") && err.contains("burn"),
        "{err}"
    );
}
