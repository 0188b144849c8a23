//! J_φ of B's futures toward B's audience (paper eq. (5)): the courtesy ψ a future of B
//! achieves. Training's courtesy loss, the evaluation and inference all measure it here.

use burn::tensor::{Device, Tensor, TensorData};
use scbg_courtesy::{Reward, expected_reward, expected_reward_shared};
use scbg_features::AgentSample;
use scbg_model::{Batch, BatchAugment, Multipath};

use crate::data::Example;

/// Time between future steps (10 Hz), seconds.
pub(crate) const STEP_SECS: f32 = 0.1;

/// A's samples as a batch without any augmentation (the condition is replaced by the caller).
fn a_batch(examples: &[&Example], device: &Device) -> Batch {
    let samples: Vec<&AgentSample> = examples.iter().map(|e| &e.a).collect();
    let mut rng = rand_pcg::Pcg64Mcg::new(0x5eed);
    Batch::from_samples(&samples, &BatchAugment::default(), &mut rng, device)
}

/// J_φ of B's futures `pred` toward each example's audience (A alone for the paper's pair,
/// see [`scbg_courtesy::audience`]): achieved ψ and the (weighted) E[r | x, ŷ] per row. The
/// marginal terms E[r(Y_j) | x] do not depend on ŷ: they are the labels' values.
///
/// For the pair this is one conditional forward of A's samples; with an audience, every
/// (row, member) goes through the predictor and a constant `[rows, members]` weight matrix
/// sums the members' ψ, so gradients reach ŷ through every member.
///
/// # Shapes
/// `pred: [times · n, T, 2]` (row `k · n + i` belongs to example `i`) `-> ([times · n], [times · n])`
pub(crate) fn audience_courtesy(
    predictor: &Multipath,
    pred: Tensor<3>,
    examples: &[&Example],
    times: usize,
    reward: Reward,
    device: &Device,
) -> (Tensor<1>, Tensor<1>) {
    audience_courtesy_with(predictor, pred, examples, times, reward, None, device)
}

/// A's scenes already encoded ([`Multipath::encode_scene`], one row per example, in order) with
/// their lane paths: what a caller that encodes them together with B's passes to
/// [`audience_courtesy_with`].
pub(crate) type EncodedA = (scbg_model::SceneEncoding, Option<(Tensor<3>, Tensor<2>)>);

/// [`audience_courtesy`], with A's scenes already encoded when `a_encoded` is given (used for
/// the pair; an audience of several members encodes each member's scene here).
pub(crate) fn audience_courtesy_with(
    predictor: &Multipath,
    pred: Tensor<3>,
    examples: &[&Example],
    times: usize,
    reward: Reward,
    a_encoded: Option<EncodedA>,
    device: &Device,
) -> (Tensor<1>, Tensor<1>) {
    let [rows, t, _] = pred.dims();
    let pair_only = examples
        .iter()
        .all(|e| e.others.is_empty() && e.terms.iter().all(|w| w.weight == 1.0));
    if pair_only {
        let e_marg = Tensor::<1>::from_data(
            TensorData::new(
                (0..times)
                    .flat_map(|_| examples.iter().map(|e| e.e_marg))
                    .collect(),
                [rows],
            ),
            device,
        );
        let in_a = b_to_a_frame(pred, examples, times, device);
        // A's scene is encoded once for its `times` futures of B (row k·n + i is example i).
        let example_of_row: Vec<usize> = (0..times).flat_map(|_| 0..examples.len()).collect();
        let condition = Tensor::cat(vec![in_a, Tensor::ones([rows, t, 1], device)], 2);
        let e_cond = match a_encoded {
            Some((scene, lane_path)) => scbg_courtesy::expected_reward_encoded(
                predictor,
                scene,
                lane_path.as_ref(),
                &example_of_row,
                condition,
                reward,
                STEP_SECS,
            ),
            None => expected_reward_shared(
                predictor,
                &a_batch(examples, device),
                &example_of_row,
                condition,
                reward,
                STEP_SECS,
            ),
        };
        return (e_cond.clone() - e_marg, e_cond);
    }
    // One row per (generated row, audience member).
    let mut source = Vec::new();
    let mut samples: Vec<&AgentSample> = Vec::new();
    let mut frames = Vec::new();
    let mut e_marg = Vec::new();
    let mut weights = Vec::new();
    for k in 0..times {
        for (i, e) in examples.iter().enumerate() {
            let members =
                std::iter::once((&e.a, e.a_from_b)).chain(e.others.iter().map(|(s, f)| (s, *f)));
            for ((sample, frame), term) in members.zip(&e.terms) {
                source.push((k * examples.len() + i) as i64);
                samples.push(sample);
                frames.push(frame);
                e_marg.push(term.e_marg);
                weights.push(term.weight);
            }
        }
    }
    let members = source.len();
    let expanded = pred.select(
        0,
        Tensor::<1, burn::tensor::Int>::from_data(
            TensorData::new(source.clone(), [members]),
            device,
        ),
    );
    let in_member = to_frames(expanded, &frames, device);
    let mut rng = rand_pcg::Pcg64Mcg::new(0x5eed);
    let batch = Batch::from_samples(&samples, &BatchAugment::default(), &mut rng, device);
    let e_cond_members = expected_reward(
        predictor,
        &batch,
        Some(Tensor::cat(
            vec![in_member, Tensor::ones([members, t, 1], device)],
            2,
        )),
        reward,
        STEP_SECS,
    );
    let mut sum = vec![0.0f32; rows * members];
    for (r, (&row, &w)) in source.iter().zip(&weights).enumerate() {
        sum[row as usize * members + r] = w;
    }
    let sum = Tensor::<2>::from_data(TensorData::new(sum, [rows, members]), device);
    let e_marg = Tensor::<1>::from_data(TensorData::new(e_marg, [members]), device);
    let psi_members = (e_cond_members.clone() - e_marg).reshape([members, 1]);
    (
        sum.clone().matmul(psi_members).reshape([rows]),
        sum.matmul(e_cond_members.reshape([members, 1]))
            .reshape([rows]),
    )
}

/// Trajectories in B's frame → A's frame, per example (row `k · n + i` belongs to example `i`).
///
/// # Shapes
/// `pred: [times · n, T, 2]` `-> [times · n, T, 2]`
fn b_to_a_frame(
    pred: Tensor<3>,
    examples: &[&Example],
    times: usize,
    device: &Device,
) -> Tensor<3> {
    let frames: Vec<[f32; 3]> = (0..times)
        .flat_map(|_| examples.iter().map(|e| e.a_from_b))
        .collect();
    to_frames(pred, &frames, device)
}

/// Each row's points moved by its frame `[heading difference, x, y]` (B's frame in the
/// other agent's frame, as [`crate::a_from_b`]).
///
/// # Shapes
/// `pred: [rows, T, 2]`, `frames: [rows]` `-> [rows, T, 2]`
fn to_frames(pred: Tensor<3>, frames: &[[f32; 3]], device: &Device) -> Tensor<3> {
    let [rows, t, _] = pred.dims();
    let col = |f: &dyn Fn(&[f32; 3]) -> f32| {
        let v: Vec<f32> = frames.iter().map(f).collect();
        Tensor::<1>::from_data(TensorData::new(v, [rows]), device).reshape([rows, 1])
    };
    let cos = col(&|f| f[0].cos());
    let sin = col(&|f| f[0].sin());
    let tx = col(&|f| f[1]);
    let ty = col(&|f| f[2]);
    let x = pred.clone().narrow(2, 0, 1).reshape([rows, t]);
    let y = pred.narrow(2, 1, 1).reshape([rows, t]);
    let xa = x.clone() * cos.clone() - y.clone() * sin.clone() + tx;
    let ya = x * sin + y * cos + ty;
    Tensor::stack::<3>(vec![xa, ya], 2)
}
