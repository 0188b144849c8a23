//! Losses of the SCBG generator and the range predictor (paper Sec. III-D, III-E).

use burn::tensor::Tensor;

/// Huber loss of trajectories, averaged over valid steps and both coordinates (the paper's
/// `l(·,·)` in `L_traj`): `½e²` for `|e| ≤ δ`, `δ(|e| − ½δ)` beyond.
///
/// # Shapes
/// `pred, target: [batch, T, 2]`, `valid: [batch, T]` `-> [1]`
pub fn huber_trajectory(
    pred: Tensor<3>,
    target: Tensor<3>,
    valid: Tensor<2>,
    delta: f32,
) -> Tensor<1> {
    let [b, t, _] = pred.dims();
    let e = (pred - target).abs();
    let quadratic = e.clone().clamp_max(delta);
    // ½q² + δ(|e| − q): equals ½e² inside, δ(|e| − ½δ) outside, and is smooth at |e| = δ.
    let loss = quadratic.clone().powf_scalar(2.0) * 0.5 + (e - quadratic) * delta;
    let v = valid.reshape([b, t, 1]);
    let count = v.clone().sum() * 2.0;
    (loss * v).sum() / count.clamp_min(1.0)
}

/// Pinball (quantile) loss for quantile τ (paper eq. 9, `L_τ`), averaged over the batch:
/// `(τ − 1)(ψ − q)` when `ψ < q`, else `τ(ψ − q)`.
///
/// # Shapes
/// `psi, q: [batch]` `-> [1]`
pub fn pinball(psi: Tensor<1>, q: Tensor<1>, tau: f32) -> Tensor<1> {
    let d = psi - q;
    // max(τ·d, (τ − 1)·d) is the same piecewise function.
    let a = d.clone() * tau;
    let b = d * (tau - 1.0);
    a.max_pair(b).mean()
}

/// Courtesy loss `Σ_m (ψ_m − J_φ(x, ŷ^m))²` (paper eq. 7), averaged over the batch.
///
/// # Shapes
/// `target_psi, achieved_psi: [batch]` `-> [1]`
pub fn courtesy_loss(target_psi: Tensor<1>, achieved_psi: Tensor<1>) -> Tensor<1> {
    (target_psi - achieved_psi).powf_scalar(2.0).mean()
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, TensorData};

    fn t1(v: Vec<f32>, d: &Device) -> Tensor<1> {
        let n = v.len();
        Tensor::from_data(TensorData::new(v, [n]), d)
    }

    #[test]
    fn huber_by_hand() {
        let d = Device::flex();
        // Errors per coordinate: 0.5 and 3.0 (δ = 1): ½·0.25 = 0.125 and 1·(3 − 0.5) = 2.5.
        let pred = Tensor::<3>::from_data(
            TensorData::new(vec![0.5f32, 3.0, 100.0, 100.0], [1, 2, 2]),
            &d,
        );
        let target = Tensor::<3>::zeros([1, 2, 2], &d);
        let valid = Tensor::<2>::from_data(TensorData::new(vec![1.0f32, 0.0], [1, 2]), &d);
        let l: f32 = huber_trajectory(pred, target, valid, 1.0).into_scalar();
        assert!((l - (0.125 + 2.5) / 2.0).abs() < 1e-6, "{l}");
    }

    #[test]
    fn pinball_by_hand() {
        let d = Device::flex();
        // τ = 0.9: ψ above q by 2 → 0.9·2 = 1.8; ψ below q by 1 → (0.9 − 1)·(−1) = 0.1.
        let l: f32 = pinball(t1(vec![3.0, 0.0], &d), t1(vec![1.0, 1.0], &d), 0.9).into_scalar();
        assert!((l - (1.8 + 0.1) / 2.0).abs() < 1e-6, "{l}");
        // τ = 0.1 flips the weights: 0.2 and 0.9.
        let l: f32 = pinball(t1(vec![3.0, 0.0], &d), t1(vec![1.0, 1.0], &d), 0.1).into_scalar();
        assert!((l - (0.2 + 0.9) / 2.0).abs() < 1e-6, "{l}");
    }

    #[test]
    fn courtesy_loss_by_hand() {
        let d = Device::flex();
        let l: f32 = courtesy_loss(t1(vec![1.0, -2.0], &d), t1(vec![0.5, 0.0], &d)).into_scalar();
        assert!((l - (0.25 + 4.0) / 2.0).abs() < 1e-6, "{l}");
    }
}
