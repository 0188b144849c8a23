//! The courtesy measure of the SCBG paper, computed through the frozen predictor.
//!
//! `ψ = J_φ(x, y_B) = E[r(Y_A) | x, y_B] − E[r(Y_A) | x]` (paper eq. (2)), with the
//! conditional and marginal modes of one Multipath++ model standing in for the two
//! distributions (paper eqs. (3)–(4)).
//!
//! **Estimator.** Under the predicted Gaussian mixture, `E[r(Y)] ≈ Σ_k π_k · r(μ_k)`: the
//! probability-weighted reward of the mode means. It is exact for rewards linear in the
//! trajectory ([`Reward::Progress`]) and a first-order (delta-method) approximation for
//! non-linear ones ([`Reward::AverageSpeed`]); it is deterministic and differentiable in `y_B`
//! through the conditional encoder, which the courtesy loss of the generator needs.
//!
//! **Architecture invariant:** tensors, samples and the model only; no files, no CLI.

#![warn(missing_docs)]

pub mod audience;
pub mod label;
pub mod losses;
mod reward;

pub use audience::{Audience, Weighting};
pub use reward::Reward;

use burn::tensor::activation::softmax;
use burn::tensor::{Tensor, TensorData};
use scbg_model::{Batch, Multipath};

/// The two expectations and their difference for a batch of targets A.
#[derive(Debug, Clone)]
pub struct CourtesyTerms {
    /// `[batch]` ψ = e_cond − e_marg.
    pub psi: Tensor<1>,
    /// `[batch]` E[r(Y_A) | x, y_B].
    pub e_cond: Tensor<1>,
    /// `[batch]` E[r(Y_A) | x].
    pub e_marg: Tensor<1>,
}

/// `E[r(Y_A) | x (, y_B)]` for each target of `batch`: conditional on `condition` (target
/// frame: x m, y m, valid) when given, marginal otherwise.
///
/// # Shapes
/// `condition: Option<[batch, T, 3]>` `-> [batch]`
pub fn expected_reward(
    model: &Multipath,
    batch: &Batch,
    condition: Option<Tensor<3>>,
    reward: Reward,
    step_secs: f32,
) -> Tensor<1> {
    // The means and logits only: the estimator does not read the covariances.
    let out = match condition {
        // The marginal prediction needs no condition (nor its encoder).
        None => model.forward_marginal_means(batch),
        Some(c) => model.forward_means(&batch.clone().with_condition(Some(c))),
    };
    mixture_reward(out, reward, step_secs)
}

/// Σ_k π_k r(μ_k) of each row's predicted mixture.
///
/// # Shapes
/// `out: MixtureMeans` of `[n, ·]` `-> [n]`
fn mixture_reward(out: scbg_model::MixtureMeans, reward: Reward, step_secs: f32) -> Tensor<1> {
    let [n, k, steps, _] = out.xy.dims();
    let probs = softmax(out.logits, 1); // [n, k]
    let r = reward
        .evaluate(out.xy.reshape([n * k, steps, 2]), step_secs)
        .reshape([n, k]);
    (probs * r).sum_dim(1).reshape([n])
}

/// [`expected_reward`] conditional on `condition` for rows that share their scene: row `r`
/// is target `rows[r]` of `base` ([`Multipath::forward_shared`]: the scene is encoded once per
/// target, not once per future).
///
/// # Shapes
/// `base`: batch of `u` targets, `rows: [n]` (each < u), `condition: [n, T, 3]` `-> [n]`
pub fn expected_reward_shared(
    model: &Multipath,
    base: &Batch,
    rows: &[usize],
    condition: Tensor<3>,
    reward: Reward,
    step_secs: f32,
) -> Tensor<1> {
    expected_reward_encoded(
        model,
        model.encode_scene(base),
        base.lane_path.as_ref(),
        rows,
        condition,
        reward,
        step_secs,
    )
}

/// [`expected_reward_shared`] from the base rows' scene encoding
/// ([`Multipath::encode_scene`]) and lane paths, for a caller that encodes them together with
/// other rows ([`Multipath::forward_encoded`]).
///
/// # Shapes
/// `scene` of `[u, ·]`, `lane_path: Option<([u, points, 4], [u, points])>`, `rows: [n]`
/// (each < u), `condition: [n, T, 3]` `-> [n]`
pub fn expected_reward_encoded(
    model: &Multipath,
    scene: scbg_model::SceneEncoding,
    lane_path: Option<&(Tensor<3>, Tensor<2>)>,
    rows: &[usize],
    condition: Tensor<3>,
    reward: Reward,
    step_secs: f32,
) -> Tensor<1> {
    let index = Tensor::<1, burn::tensor::Int>::from_data(
        burn::tensor::TensorData::new(rows.iter().map(|&r| r as i64).collect(), [rows.len()]),
        &condition.device(),
    );
    mixture_reward(
        model.forward_encoded_means(scene, lane_path, index, condition),
        reward,
        step_secs,
    )
}

/// ψ of the futures `y_b` (in each target A's frame) — paper eq. (2).
///
/// # Shapes
/// `y_b: [batch, T, 2]` `-> CourtesyTerms` of `[batch]`
pub fn courtesy(
    model: &Multipath,
    batch: &Batch,
    y_b: Tensor<3>,
    reward: Reward,
    step_secs: f32,
) -> CourtesyTerms {
    let [n, t, _] = y_b.dims();
    let valid = Tensor::ones([n, t, 1], &y_b.device());
    let e_cond = expected_reward(
        model,
        batch,
        Some(Tensor::cat(vec![y_b, valid], 2)),
        reward,
        step_secs,
    );
    let e_marg = expected_reward(model, batch, None, reward, step_secs);
    CourtesyTerms {
        psi: e_cond.clone() - e_marg.clone(),
        e_cond,
        e_marg,
    }
}

/// Converts `[n][T]` points into a `[n, T, 2]` tensor.
pub fn trajectories_tensor(trajs: &[Vec<[f32; 2]>], device: &burn::tensor::Device) -> Tensor<3> {
    let n = trajs.len();
    let t = trajs.first().map_or(0, Vec::len);
    let flat: Vec<f32> = trajs
        .iter()
        .flat_map(|tr| tr.iter().flat_map(|p| [p[0], p[1]]))
        .collect();
    Tensor::from_data(TensorData::new(flat, [n, t, 2]), device)
}

#[cfg(test)]
mod tests;
