//! GMM negative log-likelihood (`shared/spec/multipathpp.md`).

use burn::tensor::Tensor;
use burn::tensor::activation::{log_softmax, softmax};

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

/// Average speed (m/s) of each of `n` trajectories of positions in the frame of the agent at
/// the current step (the agent at the origin), sampled every `step_secs` seconds after it: the
/// mean of |y_t − y_{t−1}| / Δt with y_0 = the origin. The courtesy measure's default reward
/// (the paper's r(Y_A)).
///
/// # Shapes
/// `xy: [n, T, 2]` `-> [n]`
pub fn average_speed(xy: Tensor<3>, step_secs: f32) -> Tensor<1> {
    let [n, t, _] = xy.dims();
    let device = xy.device();
    let origin = Tensor::zeros([n, 1, 2], &device);
    let prev = if t > 1 {
        Tensor::cat(vec![origin, xy.clone().narrow(1, 0, t - 1)], 1)
    } else {
        origin
    };
    // sqrt(|d|² + ε): differentiable at standstill.
    let speed = ((xy - prev).powf_scalar(2.0).sum_dim(2) + 1e-6).sqrt() / step_secs;
    speed.mean_dim(1).reshape([n])
}

/// The squared error of the mixture's expected average speed Σ_k π_k r(μ_k) against the
/// target's realised r(y), *centred within each group*: for samples that share an input and
/// differ only in the condition (one scene replayed under several futures of the other
/// agent), what the predictor must get right is how the condition moves the target's speed,
/// the difference the courtesy measure ranks B's futures by, not its level. Each row of
/// `centring` is (the sample's indicator − its group's mean indicator), zero for a sample in no
/// group; the loss is the mean over grouped samples of ((C·(R̂ − r))_i)², in (m/s)².
///
/// # Shapes
/// `out` (see [`GmmOutput`]), `target_xy: [batch, T, 2]`, `centring: [batch, batch]` `-> [1]`
pub fn group_speed_contrast(
    out: &GmmOutput,
    target_xy: Tensor<3>,
    centring: Tensor<2>,
    grouped: usize,
    step_secs: f32,
) -> Tensor<1> {
    let [b, k, t, _] = out.xy.dims();
    let mode_speed =
        average_speed(out.xy.clone().reshape([b * k, t, 2]), step_secs).reshape([b, k]);
    let pi = softmax(out.logits.clone(), 1);
    let expected = (pi * mode_speed).sum_dim(1); // [b, 1]
    let realised = average_speed(target_xy, step_secs).reshape([b, 1]);
    let centred = centring.matmul(expected - realised);
    centred.powf_scalar(2.0).sum().reshape([1]) / grouped.max(1) as f32
}

/// The rows of [`group_speed_contrast`]'s centring matrix for `groups` (a group id per
/// sample, `None` for none) and the number of grouped samples. A group of one has nothing to
/// compare with and counts as no group.
///
/// # Shapes
/// `-> [batch, batch]` (row-major)
pub fn group_centring(groups: &[Option<u64>]) -> (Vec<f32>, usize) {
    let b = groups.len();
    let mut c = vec![0.0f32; b * b];
    let mut grouped = 0;
    for (i, gi) in groups.iter().enumerate() {
        let Some(gi) = gi else { continue };
        let members: Vec<usize> = (0..b).filter(|&j| groups[j] == Some(*gi)).collect();
        if members.len() < 2 {
            continue;
        }
        grouped += 1;
        let share = 1.0 / members.len() as f32;
        for j in members {
            c[i * b + j] -= share;
        }
        c[i * b + i] += 1.0;
    }
    (c, grouped)
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

    #[test]
    fn average_speed_by_hand() {
        // From the origin: 3-4-5 then 1 m in 0.1 s steps: (50 + 10) / 2.
        let d = Device::flex();
        let xy =
            Tensor::<3>::from_data(TensorData::new(vec![3.0f32, 4.0, 4.0, 4.0], [1, 2, 2]), &d);
        let v: f32 = average_speed(xy, 0.1).into_scalar();
        assert!((v - 30.0).abs() < 1e-3, "{v}");
    }

    #[test]
    fn group_contrast_sees_differences_not_levels() {
        let d = Device::flex();
        // One mode each; targets at 1 m and 2 m in one 1 s step (speeds 1 and 2).
        let target = |x: [f32; 3]| {
            Tensor::<3>::from_data(
                TensorData::new(vec![x[0], 0.0, x[1], 0.0, x[2], 0.0], [3, 1, 2]),
                &d,
            )
        };
        let out = |x: [f32; 3]| GmmOutput {
            xy: t4(vec![x[0], 0.0, x[1], 0.0, x[2], 0.0], [3, 1, 1, 2], &d),
            cov_abc: t4(vec![0.0; 9], [3, 1, 1, 3], &d),
            logits: Tensor::zeros([3, 1], &d),
        };
        // Samples 0 and 1 form a group, sample 2 is alone.
        let (c, grouped) = group_centring(&[Some(7), Some(7), None]);
        assert_eq!(grouped, 2);
        assert_eq!(c, vec![0.5, -0.5, 0.0, -0.5, 0.5, 0.0, 0.0, 0.0, 0.0]);
        let c = || Tensor::<2>::from_data(TensorData::new(c.clone(), [3, 3]), &d);
        let contrast = |predicted: [f32; 3]| -> f32 {
            group_speed_contrast(&out(predicted), target([1.0, 2.0, 3.0]), c(), grouped, 1.0)
                .into_scalar()
        };
        // A prediction off by the same 5 m/s for both members, and anything for the loner: 0.
        let level = contrast([6.0, 7.0, 40.0]);
        assert!(level.abs() < 1e-3, "{level}");
        // Equal predictions where the targets differ by 1 m/s: each member off by ½ → ¼.
        let flat = contrast([1.5, 1.5, 3.0]);
        assert!((flat - 0.25).abs() < 1e-3, "{flat}");
        // A group of one is no group.
        assert_eq!(group_centring(&[Some(1), Some(2)]), (vec![0.0; 4], 0));
    }
}
