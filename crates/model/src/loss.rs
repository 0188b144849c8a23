//! GMM negative log-likelihood (`shared/spec/multipathpp.md`).

use burn::tensor::Tensor;
use burn::tensor::activation::log_softmax;

use crate::output::GmmOutput;
pub use crate::output::{COV_A_RANGE, COV_B_RANGE, COV_C_RANGE};

fn logsumexp(x: Tensor<2>, dim: usize) -> Tensor<2> {
    let max = x.clone().max_dim(dim).detach();
    (x - max.clone()).exp().sum_dim(dim).log() + max
}

/// `−logsumexp_k [ log_softmax(π)_k + Σ_t v_t (−½ dᵀΣ⁻¹d − ½ log|Σ|) ]`, averaged over the batch.
/// With Σ = e^c·[[e^a cosh b, sinh b], [sinh b, e^−a cosh b]]: log|Σ| = 2c and
/// dᵀΣ⁻¹d = e^−c (e^−a cosh b·dx² − 2 sinh b·dx·dy + e^a cosh b·dy²).
///
/// # Shapes
/// `out` (see [`GmmOutput`]), `target_xy: [batch, T, 2]`, `valid: [batch, T]` `-> [1]`
pub fn gmm_nll(out: &GmmOutput, target_xy: Tensor<3>, valid: Tensor<2>) -> Tensor<1> {
    let [b, k, t, _] = out.xy.dims();
    let target = target_xy.reshape([b, 1, t, 2]).expand([b, k, t, 2]);
    let d = target - out.xy.clone();
    let dx = d.clone().narrow(3, 0, 1).reshape([b, k, t]);
    let dy = d.narrow(3, 1, 1).reshape([b, k, t]);
    let abc = out.cov_abc.clone();
    let a = abc
        .clone()
        .narrow(3, 0, 1)
        .reshape([b, k, t])
        .clamp(COV_A_RANGE.0, COV_A_RANGE.1);
    let bb = abc
        .clone()
        .narrow(3, 1, 1)
        .reshape([b, k, t])
        .clamp(COV_B_RANGE.0, COV_B_RANGE.1);
    let c = abc
        .narrow(3, 2, 1)
        .reshape([b, k, t])
        .clamp(COV_C_RANGE.0, COV_C_RANGE.1);
    let cosh = bb.clone().cosh();
    let sinh = bb.sinh();
    let quad = (a.clone().neg().exp() * cosh.clone() * dx.clone().powf_scalar(2.0)
        - sinh * dx * dy.clone() * 2.0
        + a.exp() * cosh * dy.powf_scalar(2.0))
        * c.clone().neg().exp();
    let ll_t = quad * (-0.5) - c; // −½ dᵀΣ⁻¹d − ½·2c
    let v = valid.reshape([b, 1, t]).expand([b, k, t]);
    let ll = (ll_t * v).sum_dim(2).reshape([b, k]);
    let log_pi = log_softmax(out.logits.clone(), 1);
    let nll = logsumexp(log_pi + ll, 1).neg(); // [b, 1]
    nll.mean()
}

/// Cross-entropy of the mode probabilities against the mode closest to the ground truth (mean
/// distance over valid steps), averaged over the batch — the classification term of MultiPath-
/// style losses. In the mixture NLL alone, choosing the right mode is worth at most `log K`
/// nats against hundreds from the regression, so mode probabilities (and with them anything
/// the conditioning future should decide) learn slowly; this term gives them an O(1) signal.
///
/// # Shapes
/// `out` (see [`GmmOutput`]), `target_xy: [batch, T, 2]`, `valid: [batch, T]` `-> [1]`
pub fn mode_classification_loss(
    out: &GmmOutput,
    target_xy: Tensor<3>,
    valid: Tensor<2>,
) -> Tensor<1> {
    let [b, k, t, _] = out.xy.dims();
    let target = target_xy.reshape([b, 1, t, 2]).expand([b, k, t, 2]);
    let dist = (target - out.xy.clone().detach())
        .powf_scalar(2.0)
        .sum_dim(3)
        .sqrt()
        .reshape([b, k, t]);
    let v = valid.reshape([b, 1, t]).expand([b, k, t]);
    let closest = (dist * v).sum_dim(2).reshape([b, k]).argmin(1); // [b, 1]
    let log_pi = log_softmax(out.logits.clone(), 1);
    log_pi.gather(1, closest).neg().mean()
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, TensorData};

    fn t4(v: Vec<f32>, s: [usize; 4], d: &Device) -> Tensor<4> {
        Tensor::from_data(TensorData::new(v, s), d)
    }

    #[test]
    fn single_mode_isotropic_matches_hand_computed() {
        // K = 1, T = 2, a = b = 0, c = ln 4 (σ² = 4): per step −½·|d|²/4 − ½·ln 16.
        let d = Device::flex();
        let c = 4f32.ln();
        let out = GmmOutput {
            xy: t4(vec![0.0, 0.0, 1.0, 1.0], [1, 1, 2, 2], &d),
            cov_abc: t4(vec![0.0, 0.0, c, 0.0, 0.0, c], [1, 1, 2, 3], &d),
            logits: Tensor::from_data(TensorData::new(vec![0.3f32], [1, 1]), &d),
        };
        let target =
            Tensor::<3>::from_data(TensorData::new(vec![2.0f32, 0.0, 1.0, 1.0], [1, 2, 2]), &d);
        let valid = Tensor::<2>::ones([1, 2], &d);
        let nll: f32 = gmm_nll(&out, target, valid).into_scalar();
        let expected = -((-0.5 * 4.0 / 4.0 - c) + (0.0 - c));
        assert!((nll - expected).abs() < 1e-5, "{nll} vs {expected}");
    }

    #[test]
    fn invalid_steps_do_not_count_and_modes_mix() {
        let d = Device::flex();
        // K = 2 identical modes with equal logits: mixture equals one mode.
        let out = GmmOutput {
            xy: t4(vec![0.0; 8], [1, 2, 2, 2], &d),
            cov_abc: t4(vec![0.0; 12], [1, 2, 2, 3], &d),
            logits: Tensor::from_data(TensorData::new(vec![0.0f32, 0.0], [1, 2]), &d),
        };
        let target = Tensor::<3>::from_data(
            TensorData::new(vec![1.0f32, 0.0, 100.0, 100.0], [1, 2, 2]),
            &d,
        );
        let valid = Tensor::<2>::from_data(TensorData::new(vec![1.0f32, 0.0], [1, 2]), &d);
        let nll: f32 = gmm_nll(&out, target, valid).into_scalar();
        assert!((nll - 0.5).abs() < 1e-5, "{nll}");
    }

    #[test]
    fn correlated_covariance() {
        // a = 0, b = asinh(0.5) → cosh b = √1.25, sinh b = 0.5; c = 0; d = (1, 1):
        // quad = √1.25 − 1 + √1.25.
        let d = Device::flex();
        let b = 0.5f32.asinh();
        let out = GmmOutput {
            xy: t4(vec![0.0, 0.0], [1, 1, 1, 2], &d),
            cov_abc: t4(vec![0.0, b, 0.0], [1, 1, 1, 3], &d),
            logits: Tensor::from_data(TensorData::new(vec![0.0f32], [1, 1]), &d),
        };
        let target = Tensor::<3>::from_data(TensorData::new(vec![1.0f32, 1.0], [1, 1, 2]), &d);
        let nll: f32 = gmm_nll(&out, target, Tensor::<2>::ones([1, 1], &d)).into_scalar();
        let quad = 2.0 * 1.25f32.sqrt() - 1.0;
        assert!((nll - 0.5 * quad).abs() < 1e-5, "{nll}");
    }

    #[test]
    fn mode_classification_by_hand() {
        // Two modes, two steps; target at the origin; mode 0 is 1 m away, mode 1 is 5 m away,
        // except at an invalid step where mode 1 would be closer. π = (1/4, 3/4): CE = ln 4.
        let d = Device::flex();
        let out = GmmOutput {
            xy: t4(
                vec![1.0, 0.0, 100.0, 0.0, 5.0, 0.0, 0.0, 0.0],
                [1, 2, 2, 2],
                &d,
            ),
            cov_abc: t4(vec![0.0; 12], [1, 2, 2, 3], &d),
            logits: Tensor::from_data(TensorData::new(vec![0.0f32, 3f32.ln()], [1, 2]), &d),
        };
        let target = Tensor::<3>::zeros([1, 2, 2], &d);
        let valid = Tensor::<2>::from_data(TensorData::new(vec![1.0f32, 0.0], [1, 2]), &d);
        let ce: f32 = mode_classification_loss(&out, target, valid).into_scalar();
        assert!((ce - 4f32.ln()).abs() < 1e-5, "{ce}");
    }
}
