//! The paper's loss, `α/(1+α)·recon + 1/(1+α)·pred + β·KL`, and its numerically
//! guarded parts.
//!
//! - recon: mean squared pixel error (as the reference code's `mse_loss`).
//! - pred: mean squared error of the standardised wrench (see `labels`).
//! - KL: the closed form of KL(N(μ, σ²) ‖ N(0, 1)), averaged over batch and latent
//!   dimensions, which is the expectation of the reference code's one-sample estimate
//!   `mean(log q(z) − log p(z))` without its sampling noise.
//!
//! The log-variance is clamped to [−[`LOG_VAR_LIMIT`], +[`LOG_VAR_LIMIT`]] where the
//! heads produce it: `exp(±30)` is far from f32's overflow (`exp(88)`), so a runaway
//! head gives a large, finite KL and finite gradients instead of inf and NaN.

use burn::prelude::*;

/// Bound on |log σ²|.
pub const LOG_VAR_LIMIT: f64 = 30.0;

pub fn clamp_log_var(log_var: Tensor<2>) -> Tensor<2> {
    log_var.clamp(-LOG_VAR_LIMIT, LOG_VAR_LIMIT)
}

/// Mean over batch and dimensions of KL(N(mean, exp(log_var)) ‖ N(0, 1)).
pub fn kl_mean(mean: Tensor<2>, log_var: Tensor<2>) -> Tensor<1> {
    let log_var = clamp_log_var(log_var);
    (mean.powi_scalar(2) + log_var.clone().exp() - log_var - 1.0)
        .mul_scalar(0.5)
        .mean()
}

/// Mean squared error.
pub fn mse<const D: usize>(prediction: Tensor<D>, target: Tensor<D>) -> Tensor<1> {
    (prediction - target).powi_scalar(2).mean()
}

/// The terms of one batch's loss (each already a mean), and their weighted sum.
#[derive(Debug, Clone)]
pub struct LossTerms {
    pub total: Tensor<1>,
    pub recon: Option<Tensor<1>>,
    pub pred: Option<Tensor<1>>,
    pub kl: Option<Tensor<1>>,
}

/// Combines the terms with weights `(recon, pred, kl)`; a term with weight 0 is left
/// out of the graph entirely (so β = 0 or α = 0 costs nothing and cannot add NaN).
pub fn combine(
    weights: (f64, f64, f64),
    recon: Option<Tensor<1>>,
    pred: Option<Tensor<1>>,
    kl: Option<Tensor<1>>,
    device: &Device,
) -> LossTerms {
    let mut total = Tensor::<1>::zeros([1], device);
    for (w, term) in [(weights.0, &recon), (weights.1, &pred), (weights.2, &kl)] {
        if let Some(t) = term
            && w > 0.0
        {
            total = total + t.clone().mul_scalar(w);
        }
    }
    LossTerms {
        total,
        recon,
        pred,
        kl,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scalar(t: Tensor<1>) -> f32 {
        t.into_scalar::<f32>()
    }

    #[test]
    fn kl_is_zero_at_the_prior_and_positive_elsewhere() {
        let d = Device::flex();
        let zeros = Tensor::<2>::zeros([4, 8], &d);
        assert!(scalar(kl_mean(zeros.clone(), zeros.clone())).abs() < 1e-7);
        let ones = Tensor::<2>::ones([4, 8], &d);
        // 0.5·(1 + 1 − 0 − 1) = 0.5
        assert!((scalar(kl_mean(ones, zeros)) - 0.5).abs() < 1e-6);
    }

    #[test]
    fn kl_with_extreme_log_variance_stays_finite_with_finite_gradients() {
        let d = Device::flex().autodiff();
        for lv in [1e4f32, 500.0, 89.0, -89.0, -500.0, -1e4, f32::MAX, f32::MIN] {
            let mean = Tensor::<2>::zeros([2, 3], &d).require_grad();
            let log_var = Tensor::<2>::full([2, 3], lv, &d).require_grad();
            let kl = kl_mean(mean.clone(), log_var.clone());
            let value = kl.clone().into_scalar::<f32>();
            assert!(value.is_finite(), "KL at log σ² = {lv}: {value}");
            let grads = kl.backward();
            let g = log_var.grad(&grads).expect("gradient").into_data();
            let g = g.as_slice::<f32>().expect("f32");
            assert!(g.iter().all(|v| v.is_finite()), "gradient at {lv}: {g:?}");
        }
        // Large but in-range values: exact.
        let mean = Tensor::<2>::zeros([1, 1], &Device::flex());
        let lv = Tensor::<2>::full([1, 1], 20.0, &Device::flex());
        let expected = 0.5 * (20f64.exp() - 20.0 - 1.0);
        let got = f64::from(scalar(kl_mean(mean, lv)));
        assert!((got - expected).abs() / expected < 1e-5);
    }

    #[test]
    fn zero_weights_leave_terms_out() {
        let d = Device::flex();
        let nan = Tensor::<1>::full([1], f32::NAN, &d);
        let one = Tensor::<1>::ones([1], &d);
        // β = 0: a NaN KL term does not reach the total.
        let l = combine(
            (0.5, 0.5, 0.0),
            Some(one.clone()),
            Some(one.clone()),
            Some(nan),
            &d,
        );
        assert!((scalar(l.total) - 1.0).abs() < 1e-6);
        // α = 0 (recon weight 0) and very large α (pred weight ~0).
        let l = combine(
            (0.0, 1.0, 0.1),
            Some(one.clone() * 7.0),
            Some(one.clone()),
            None,
            &d,
        );
        assert!((scalar(l.total) - 1.0).abs() < 1e-6);
        let a = 1e12;
        let l = combine(
            (a / (1.0 + a), 1.0 / (1.0 + a), 0.1),
            Some(one.clone()),
            Some(one),
            None,
            &d,
        );
        assert!(scalar(l.total).is_finite());
    }
}
