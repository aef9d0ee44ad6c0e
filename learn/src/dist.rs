//! Log-probabilities, entropies and divergences of the policies' distributions, as tensor
//! operations (differentiable under autodiff).
//!
//! Batches are `[batch, act_dim]`; results sum over the action dimensions.

use burn::tensor::activation::softplus;
use burn::tensor::Tensor;

/// `0.5 * ln(2 pi)`.
pub const HALF_LN_2PI: f32 = 0.918_938_5;

/// Log-density of a diagonal Gaussian at `x`: `[batch, act]` inputs, `[batch]` result.
/// `log_std` broadcasts (`[1, act]` for a state-independent standard deviation).
pub fn gaussian_log_prob(x: Tensor<2>, mu: Tensor<2>, log_std: Tensor<2>) -> Tensor<1> {
    let z = (x - mu) / log_std.clone().exp();
    let per_dim = z.square().mul_scalar(-0.5) - log_std - HALF_LN_2PI;
    per_dim.sum_dim(1).squeeze_dim(1)
}

/// Entropy of a diagonal Gaussian per row: `sum(log_std + 0.5 * ln(2 pi e))`.
pub fn gaussian_entropy(log_std: Tensor<2>) -> Tensor<1> {
    (log_std + (HALF_LN_2PI + 0.5)).sum_dim(1).squeeze_dim(1)
}

/// `ln(1 - tanh(u)^2)` computed stably as `2 (ln 2 - u - softplus(-2u))`.
pub fn log_one_minus_tanh_sq(u: Tensor<2>) -> Tensor<2> {
    let sp = softplus(u.clone().mul_scalar(-2.0), 1.0);
    (u + sp)
        .mul_scalar(-2.0)
        .add_scalar(2.0 * std::f32::consts::LN_2)
}

/// Log-density of `a = tanh(u)` where `u ~ N(mu, exp(log_std)^2)`, given the pre-squash `u`:
/// the Gaussian log-density minus the log-determinant of the tanh Jacobian.
pub fn tanh_gaussian_log_prob(u: Tensor<2>, mu: Tensor<2>, log_std: Tensor<2>) -> Tensor<1> {
    let correction = log_one_minus_tanh_sq(u.clone()).sum_dim(1).squeeze_dim(1);
    gaussian_log_prob(u, mu, log_std) - correction
}

/// KL(p0 || p1) between diagonal Gaussians per row, the form rl_games uses for its adaptive
/// learning rate (with its 1e-5 guards): `sum(ln(s1/s0 + 1e-5) + (s0^2 + (mu0-mu1)^2) /
/// (2 s1^2 + 1e-5) - 0.5)`.
pub fn gaussian_kl(
    mu0: Tensor<2>,
    sigma0: Tensor<2>,
    mu1: Tensor<2>,
    sigma1: Tensor<2>,
) -> Tensor<1> {
    let ratio = (sigma1.clone() / sigma0.clone()).add_scalar(1e-5).log();
    let num = sigma0.square() + (mu0 - mu1).square();
    let den = sigma1.square().mul_scalar(2.0).add_scalar(1e-5);
    (ratio + num / den)
        .sub_scalar(0.5)
        .sum_dim(1)
        .squeeze_dim(1)
}

/// Bounds loss of rl_games per row: squared excess of the mean beyond +-`soft_bound`, summed.
pub fn bounds_loss(mu: Tensor<2>, soft_bound: f32) -> Tensor<1> {
    let high = mu.clone().sub_scalar(soft_bound).clamp_min(0.0).square();
    let low = mu.add_scalar(soft_bound).clamp_max(0.0).square();
    (high + low).sum_dim(1).squeeze_dim(1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tensors::{tensor2, to_vec};
    use burn::tensor::Device;

    fn dev() -> Device {
        Device::flex()
    }

    /// The closed form of a diagonal Gaussian, in f64.
    fn normal_logpdf(x: f64, mu: f64, sigma: f64) -> f64 {
        -0.5 * ((x - mu) / sigma).powi(2) - sigma.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln()
    }

    #[test]
    fn gaussian_log_prob_matches_closed_form() {
        let d = dev();
        let xs = [[0.0f32, 0.0], [1.5, -2.0], [-0.3, 4.0]];
        let mus = [[0.0f32, 0.0], [1.0, 0.5], [0.2, -1.0]];
        let log_std = [-0.7f32, 0.4];
        let x = tensor2(&xs.concat(), 3, 2, &d);
        let mu = tensor2(&mus.concat(), 3, 2, &d);
        let ls = tensor2(&log_std, 1, 2, &d);
        let got = to_vec(gaussian_log_prob(x, mu, ls.clone()));
        for r in 0..3 {
            let want: f64 = (0..2)
                .map(|k| {
                    normal_logpdf(xs[r][k] as f64, mus[r][k] as f64, (log_std[k] as f64).exp())
                })
                .sum();
            assert!(
                (got[r] as f64 - want).abs() < 1e-5,
                "row {r}: {} vs {want}",
                got[r]
            );
        }
        // Standard normal at 0, one dimension: -0.5 ln(2 pi).
        let z = tensor2(&[0.0], 1, 1, &d);
        let v = to_vec(gaussian_log_prob(z.clone(), z.clone(), z));
        assert!((v[0] as f64 + 0.918_938_533_204_672_7).abs() < 1e-6);
        // Entropy: 0.5 ln(2 pi e) + log_std per dimension.
        let e = to_vec(gaussian_entropy(ls));
        let want =
            2.0 * (0.5 * (2.0 * std::f64::consts::PI * std::f64::consts::E).ln()) - 0.7 + 0.4;
        assert!((e[0] as f64 - want).abs() < 1e-5);
    }

    #[test]
    fn tanh_gaussian_log_prob_matches_change_of_variables() {
        // Closed form in terms of a = tanh(u): p(a) = N(atanh(a); mu, s) / (1 - a^2).
        let d = dev();
        let us = [0.0f32, 0.8, -1.7, 3.0, -6.0, 0.25];
        let mus = [0.1f32, -0.4, 0.0, 2.0, -1.0, 0.3];
        let log_std = [0.2f32, -1.1];
        let u = tensor2(&us, 3, 2, &d);
        let mu = tensor2(&mus, 3, 2, &d);
        let ls = tensor2(&log_std, 1, 2, &d);
        let got = to_vec(tanh_gaussian_log_prob(u, mu, ls));
        for r in 0..3 {
            let mut want = 0.0f64;
            for k in 0..2 {
                let a = (us[2 * r + k] as f64).tanh();
                let s = (log_std[k] as f64).exp();
                want += normal_logpdf(a.atanh(), mus[2 * r + k] as f64, s) - (1.0 - a * a).ln();
            }
            assert!(
                (got[r] as f64 - want).abs() < 2e-4,
                "row {r}: {} vs {want}",
                got[r]
            );
        }
    }

    #[test]
    fn tanh_gaussian_density_integrates_to_one() {
        // Integrate exp(log p(a)) over a in (-1, 1) by the midpoint rule, via u = atanh(a).
        let d = dev();
        let n = 20_000;
        let us: Vec<f32> = (0..n)
            .map(|k| (((k as f64 + 0.5) / n as f64) * 2.0 - 1.0).atanh() as f32)
            .collect();
        let u = tensor2(&us, n, 1, &d);
        let mu = tensor2(&vec![0.7f32; n], n, 1, &d);
        let ls = tensor2(&[-0.2f32], 1, 1, &d);
        let lp = to_vec(tanh_gaussian_log_prob(u, mu, ls));
        let integral: f64 = lp.iter().map(|l| (*l as f64).exp() * 2.0 / n as f64).sum();
        assert!((integral - 1.0).abs() < 2e-3, "{integral}");
    }

    #[test]
    fn kl_of_identical_gaussians_is_zero_and_positive_otherwise() {
        let d = dev();
        let mu = tensor2(&[0.3, -0.2], 1, 2, &d);
        let s = tensor2(&[0.5, 2.0], 1, 2, &d);
        let kl = to_vec(gaussian_kl(mu.clone(), s.clone(), mu.clone(), s.clone()));
        assert!(kl[0].abs() < 1e-4, "{kl:?}");
        let mu1 = tensor2(&[0.5, -0.2], 1, 2, &d);
        let kl = to_vec(gaussian_kl(mu, s.clone(), mu1, s))[0] as f64;
        // Closed form without the guards: (0.2)^2 / (2 * 0.25) = 0.08.
        assert!((kl - 0.08).abs() < 1e-3, "{kl}");
    }

    #[test]
    fn bounds_loss_penalises_only_outside() {
        let d = dev();
        let mu = tensor2(&[0.5, -1.0, 1.6, -2.1], 2, 2, &d);
        let b = to_vec(bounds_loss(mu, 1.1));
        assert_eq!(b[0], 0.0);
        assert!((b[1] - (0.25 + 1.0)).abs() < 1e-5, "{b:?}");
    }
}
