//! B's marginal modes as the generator's choices (with their slowed copies), and the courtesy
//! J_φ gives each of them.

use burn::tensor::Device;
use scbg_model::Multipath;

use crate::audience::{EncodedA, audience_courtesy_with};
use crate::data::Example;
use crate::model::Generator;
use crate::modes::{BModes, slowdown_warp};
use crate::range::stored_embeddings;
use crate::tensors::to_vec;

/// B's marginal modes decoded by the frozen predictor from B's embeddings (`[n, e]`, the
/// predictor's own embedding width), for the generator.
pub fn b_modes_of(predictor: &Multipath, b_embedding: burn::tensor::Tensor<2>) -> BModes {
    let out = predictor.decode_means(b_embedding);
    let mixture_modes = out.logits.dims()[1];
    BModes {
        xy: out.xy.detach(),
        log_prob: burn::tensor::activation::log_softmax(out.logits, 1).detach(),
        psi: None,
        mixture_modes,
    }
}

/// [`b_modes_of`] the examples' stored B embeddings.
pub fn b_modes(predictor: &Multipath, examples: &[&Example], device: &Device) -> BModes {
    b_modes_of(predictor, stored_embeddings(examples, device))
}

/// Each of B's modes' courtesy toward the example's audience: `ψ_k = E[r | x, μ_k] −
/// Σ_j π_j E[r | x, μ_j]`, J_φ of the mode mean `μ_k` against the modes' own
/// probability-weighted mean (the law of total expectation over the mixture's means, the
/// same estimator in training and inference, and independent of how the labels estimated
/// E[r | x]). Slowed copies of the modes ([`BModes::with_slowdowns`]) are scored
/// against the same mean, which only the mixture's own modes form. Detached; run it on any
/// device.
///
/// # Shapes
/// `modes.xy: [n, K, T, 2]` (B's frame), `modes.log_prob: [n, K]` → `[n, K]`
pub fn mode_courtesy(
    predictor: &Multipath,
    examples: &[&Example],
    modes: &BModes,
    reward: scbg_courtesy::Reward,
    device: &Device,
) -> burn::tensor::Tensor<2> {
    mode_courtesy_with(predictor, examples, modes, reward, None, device)
}

/// [`mode_courtesy`] with the examples' A scenes already encoded when `a_encoded` is given.
fn mode_courtesy_with(
    predictor: &Multipath,
    examples: &[&Example],
    modes: &BModes,
    reward: scbg_courtesy::Reward,
    a_encoded: Option<EncodedA>,
    device: &Device,
) -> burn::tensor::Tensor<2> {
    let [n, k, t, _] = modes.xy.dims();
    // Row j·n + i is example i's mode j (the layout J_φ's shared-encoder forward takes).
    let rows = modes.xy.clone().swap_dims(0, 1).reshape([k * n, t, 2]);
    let (_, e_cond) =
        audience_courtesy_with(predictor, rows, examples, k, reward, a_encoded, device);
    let e_cond = e_cond.reshape([k, n]).swap_dims(0, 1);
    let mixture = modes.mixture_modes.clamp(1, k);
    let mean = (e_cond.clone().narrow(1, 0, mixture)
        * modes.log_prob.clone().narrow(1, 0, mixture).exp())
    .sum_dim(1);
    (e_cond - mean).detach()
}

/// B's candidates for `generator` with each one's courtesy: the examples' stored
/// [`Example::mode_psi`] when every one has it, else [`mode_courtesy`] computed here.
pub fn b_modes_for(
    generator: &Generator,
    predictor: &Multipath,
    examples: &[&Example],
    reward: scbg_courtesy::Reward,
    device: &Device,
) -> BModes {
    b_modes_with(generator, predictor, examples, reward, None, device)
}

/// [`b_modes_for`], with the examples' A scenes already encoded when `a_encoded` is given (a
/// plan that encoded them together with B's).
pub(crate) fn b_modes_with(
    generator: &Generator,
    predictor: &Multipath,
    examples: &[&Example],
    reward: scbg_courtesy::Reward,
    a_encoded: Option<EncodedA>,
    device: &Device,
) -> BModes {
    let mut modes = generator.candidates_of(b_modes(predictor, examples, device));
    let [n, k, _, _] = modes.xy.dims();
    let stored = examples.iter().all(|e| e.mode_psi.len() == k);
    modes.psi = Some(if stored {
        burn::tensor::Tensor::from_data(
            burn::tensor::TensorData::new(
                examples
                    .iter()
                    .flat_map(|e| e.mode_psi.iter().copied())
                    .collect(),
                [n, k],
            ),
            device,
        )
    } else {
        mode_courtesy_with(predictor, examples, &modes, reward, a_encoded, device)
    });
    modes
}

/// Stores every example's [`Example::mode_psi`] (in chunks of 64 pair roles), so that
/// training does not recompute J_φ of B's modes at every step: of the modes and their copies
/// slowed by `slowdowns` ([`crate::GeneratorConfig::mode_slowdowns`]; empty: none), the
/// generator's choices in [`crate::Generator::candidates_of`]'s order. Run it on a plain
/// device.
pub fn fill_mode_courtesy(
    predictor: &Multipath,
    examples: &mut [Example],
    reward: scbg_courtesy::Reward,
    slowdowns: &[f32],
    device: &Device,
) {
    for chunk in examples.chunks_mut(64) {
        let refs: Vec<&Example> = chunk.iter().collect();
        let modes = b_modes(predictor, &refs, device);
        let warp = slowdown_warp(slowdowns, modes.xy.dims()[2], device);
        let modes = modes.with_slowdowns(warp.as_ref());
        let k = modes.log_prob.dims()[1];
        let psi = to_vec(mode_courtesy(predictor, &refs, &modes, reward, device));
        for (e, psi) in chunk.iter_mut().zip(psi.chunks_exact(k)) {
            e.mode_psi = psi.to_vec();
        }
    }
}

/// One choice of the generator: a future of B in B's frame and its courtesy.
#[derive(Debug, Clone, PartialEq)]
pub struct ScoredCandidate {
    /// `[T]` positions in B's frame (metres), the steps after the current one.
    pub xy: Vec<[f32; 2]>,
    /// Its courtesy by J_φ ([`mode_courtesy`], against the mixture's own mean).
    pub psi: f32,
}

/// Every choice `generator` has for each example — B's modes and their slowed copies, as
/// [`b_modes_for`] gives them — with J_φ's courtesy of each (the examples' stored
/// [`Example::mode_psi`] when there is one, else measured here; in chunks of 64 examples).
/// What a selector among them could reach is what the generator's choice can.
pub fn scored_candidates(
    generator: &Generator,
    predictor: &Multipath,
    examples: &[&Example],
    reward: scbg_courtesy::Reward,
    device: &Device,
) -> Vec<Vec<ScoredCandidate>> {
    let mut out = Vec::with_capacity(examples.len());
    for chunk in examples.chunks(64) {
        let mut modes = b_modes_for(generator, predictor, chunk, reward, device);
        let [_, k, t, _] = modes.xy.dims();
        let psi = match modes.psi.take() {
            Some(psi) => psi,
            None => mode_courtesy(predictor, chunk, &modes, reward, device),
        };
        let psi = to_vec(psi);
        let xy = to_vec(modes.xy);
        for (i, _) in chunk.iter().enumerate() {
            out.push(
                (0..k)
                    .map(|j| {
                        let base = (i * k + j) * t * 2;
                        ScoredCandidate {
                            xy: (0..t)
                                .map(|s| [xy[base + 2 * s], xy[base + 2 * s + 1]])
                                .collect(),
                            psi: psi[i * k + j],
                        }
                    })
                    .collect(),
            );
        }
    }
    out
}
