//! The generator network.

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use scbg_model::blocks::Mlp;
use serde::{Deserialize, Serialize};

use crate::modes::{BModes, slowdown_warp};

/// Widths of the generator decoder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeneratorConfig {
    /// Width of the predictor's scene embedding (its `embedding_width()`).
    pub embedding_width: usize,
    /// Width of the ψ embedding.
    pub psi_width: usize,
    /// Hidden widths of the decoder MLP.
    pub hidden: Vec<usize>,
    /// Generated future steps `T` (80 = 8 s at 10 Hz).
    pub future_steps: usize,
    /// ψ is divided by this before the network sees it (the spread of the training labels;
    /// ψ's scale depends on the data and the predictor, from ~0.03 to several m/s).
    pub psi_scale: f32,
    /// The decoder emits one displacement per `knot_stride` steps (5 = 2 Hz knots), and the
    /// positions between knots are interpolated linearly: futures are smooth by construction
    /// (per-step outputs trained for a few epochs zigzag by decimetres).
    pub knot_stride: usize,
    /// B's predicted marginal modes the generator chooses among (`K`, the predictor's mode
    /// count). The future is the chosen candidate — one of B's modes or a slowed copy
    /// ([`Self::mode_slowdowns`]) — plus a regressed displacement `Δ(x, ψ)`
    /// ([`Generator::forward`]). The selector scores each candidate from B's embedding, the
    /// candidate's log-probability and its own courtesy ψ_k (J_φ of the candidate toward the
    /// audience, [`crate::mode_courtesy`]) against the requested ψ, also relative to the
    /// scene's choices ([`relative_courtesy`]).
    pub modes: usize,
    /// Each of B's `K` modes also joins the choices slowed down, once per factor `w` here (in
    /// (0, 2], clamped): the same path, travelled at a speed that eases linearly from the
    /// mode's own at the current step to `w` times it at the horizon ([`slowdown_warp`]).
    /// Yielding — dropping back, letting A merge or cross first — is the courteous manoeuvre
    /// of every interaction family, and a predictor's marginal modes rarely hold enough of
    /// it. The selector then chooses among `K · (1 + S)` candidates ([`Self::candidates`]); a
    /// slowed copy starts with its mode's log-probability.
    pub mode_slowdowns: Vec<f32>,
}

/// Hidden width of the per-candidate courtesy scorer.
const MODE_SCORER_HIDDEN: usize = 32;

/// The floor of [`relative_courtesy`]'s spread, in label spreads (docs/findings.md,
/// *Courtesy relative to the scene's choices*): a scene whose choices J_φ scores alike must
/// not turn noise into rank.
pub const RELATIVE_COURTESY_FLOOR: f32 = 0.1;

/// The slowed copies of B's modes among a new generator's choices
/// ([`GeneratorConfig::mode_slowdowns`]; docs/findings.md, *Slowed copies of B's modes*).
pub const DEFAULT_MODE_SLOWDOWNS: [f32; 2] = [0.75, 0.5];

/// The generator's ψ inputs, in units of the labels' spread (`psi_scale`), are clamped to
/// ± this many spreads (the demo's labels span about ±5.4; a label beyond is rare).
const PSI_INPUT_RANGE: f32 = 20.0;

impl GeneratorConfig {
    /// The generator's choices: B's `modes` and their slowed copies
    /// ([`Self::mode_slowdowns`]).
    pub fn candidates(&self) -> usize {
        self.modes * (1 + self.mode_slowdowns.len())
    }

    /// The default decoder for a predictor embedding of `embedding_width` choosing among
    /// `modes` modes of B: ψ width 32, hidden widths 256, 256, 80 steps, `psi_scale` 1 (set it
    /// from the labels), 2 Hz knots, the [`DEFAULT_MODE_SLOWDOWNS`].
    pub fn new(embedding_width: usize, modes: usize) -> Self {
        Self {
            embedding_width,
            psi_width: 32,
            hidden: vec![256, 256],
            future_steps: 80,
            psi_scale: 1.0,
            knot_stride: 5,
            modes,
            mode_slowdowns: DEFAULT_MODE_SLOWDOWNS.to_vec(),
        }
    }

    /// Builds the generator on `device` (seed the device first for reproducible weights; the
    /// parameter ids come from their paths, [`scbg_model::param_ids`]).
    pub fn init(&self, device: &Device) -> Generator {
        scbg_model::param_ids::with_path_ids(self.init_random_ids(device), "generator")
    }

    fn init_random_ids(&self, device: &Device) -> Generator {
        let mut dims = vec![self.embedding_width + self.psi_width];
        dims.extend(&self.hidden);
        let mut sel = vec![dims[0]];
        sel.extend(self.hidden.first());
        sel.push(self.candidates());
        let selector = Mlp::init(&sel, device);
        let stride = self.knot_stride.max(1);
        let knots = self.future_steps.div_ceil(stride);
        dims.push(2 * knots);
        // interpolation[s][j]: weight of knot j in step s (knot j sits at step (j + 1)·stride,
        // the origin before knot 0 is the current position, zero in B's frame).
        let mut weights = vec![0.0f32; self.future_steps * knots];
        for s in 0..self.future_steps {
            let t = (s + 1) as f32 / stride as f32; // in knot units; knot j at t = j + 1
            let hi = (t.ceil() as usize).clamp(1, knots);
            let frac = t - (hi - 1) as f32;
            weights[s * knots + hi - 1] = frac;
            if hi >= 2 {
                weights[s * knots + hi - 2] = 1.0 - frac;
            }
        }
        // Inputs ψ, ψ_k and ψ relative to the scene's choices.
        let mode_scorer = Mlp::init(&[3, MODE_SCORER_HIDDEN, MODE_SCORER_HIDDEN, 1], device);
        Generator {
            psi_mlp: Mlp::init(&[1, self.psi_width, self.psi_width], device),
            decoder: Mlp::init(&dims, device),
            selector,
            mode_scorer,
            interpolation: burn::module::Param::from_tensor(Tensor::from_data(
                burn::tensor::TensorData::new(weights, [self.future_steps, knots]),
                device,
            ))
            .set_require_grad(false),
            future_steps: self.future_steps,
            knot_stride: stride,
            psi_scale: self.psi_scale,
            mode_warp: slowdown_warp(&self.mode_slowdowns, self.future_steps, device)
                .map(|w| burn::module::Param::from_tensor(w).set_require_grad(false)),
        }
    }
}

/// `g(x, ψ)`: one trajectory of B for a requested courtesy.
#[derive(Module, Debug)]
pub struct Generator {
    /// MLP embedding the scaled ψ (`1 → psi_width → psi_width`).
    pub psi_mlp: Mlp,
    /// MLP of `[embedding ‖ ψ embedding]` → `2 · knots` per-knot displacements (dx, dy).
    pub decoder: Mlp,
    /// MLP of `[embedding ‖ ψ embedding]` → one logit per candidate.
    pub selector: Mlp,
    /// MLP of `[ψ, ψ_k, ψ relative to the choices]` (÷ `psi_scale`) → one more logit for
    /// candidate `k`.
    pub mode_scorer: Mlp,
    /// `[T, knots]` fixed linear interpolation from knots to steps (not trained).
    pub interpolation: burn::module::Param<Tensor<2>>,
    /// Generated future steps `T`.
    pub future_steps: usize,
    /// Steps between knots (see [`GeneratorConfig::knot_stride`]).
    pub knot_stride: usize,
    /// ψ is divided by this before [`Self::psi_mlp`] (see [`GeneratorConfig::psi_scale`]).
    pub psi_scale: f32,
    /// `[S, T, T]` fixed warps of [`GeneratorConfig::mode_slowdowns`] (not trained; `None`
    /// without slowed copies).
    pub mode_warp: Option<burn::module::Param<Tensor<3>>>,
}

impl Generator {
    /// B's modes as this generator chooses among them: with their slowed copies
    /// ([`GeneratorConfig::mode_slowdowns`]), if any.
    pub fn candidates_of(&self, modes: BModes) -> BModes {
        modes.with_slowdowns(self.mode_warp.as_ref().map(|w| w.val()).as_ref())
    }

    /// `y_B = g(x, ψ)` (paper eq. 1): B's future for the requested courtesy ψ, as used
    /// outside training: the selector's likeliest candidate plus the displacement. (A blend
    /// of a yielding and a going future is neither: half a lane change, creeping into a
    /// crossing, which the other drivers read as a cut-in or a claim on the conflict zone.)
    ///
    /// # Shapes
    /// `embedding: [batch, e]` (B's frozen scene embedding), `psi: [batch]`,
    /// `modes`: see [`BModes`] (with `psi` set) `-> [batch, T, 2]` positions in B's frame
    /// (metres)
    ///
    /// # Panics
    /// When `modes.psi` is `None`.
    pub fn forward(&self, embedding: Tensor<2>, psi: Tensor<1>, modes: BModes) -> Tensor<3> {
        let Heads {
            knot_xy,
            logits,
            at_knots,
        } = self.heads(embedding, psi, modes);
        let [b, k, knots, _] = at_knots.dims();
        let device = logits.device();
        let onehot = Tensor::<2>::zeros([b, k], &device).scatter(
            1,
            logits.argmax(1),
            Tensor::ones([b, 1], &device),
            burn::tensor::IndexingUpdateOp::Add,
        );
        let chosen = onehot
            .reshape([b, 1, k])
            .matmul(at_knots.reshape([b, k, knots * 2]))
            .reshape([b, knots, 2]);
        self.interpolate(knot_xy + chosen)
    }

    /// B's future for every candidate the selector can choose, with the selector's logits:
    /// what training needs (differentiable in every weight). The softmax of `logits`
    /// weighting `futures` is the blend the courtesy loss scores; the argmax is
    /// [`Self::forward`].
    ///
    /// # Shapes
    /// As [`Self::forward`] `-> CandidateFutures` (`logits: [batch, K]`,
    /// `futures: [batch, K, T, 2]`)
    ///
    /// # Panics
    /// As [`Self::forward`].
    pub fn forward_candidates(
        &self,
        embedding: Tensor<2>,
        psi: Tensor<1>,
        modes: BModes,
    ) -> CandidateFutures {
        let Heads {
            knot_xy,
            logits,
            at_knots,
        } = self.heads(embedding, psi, modes);
        let [b, k, knots, _] = at_knots.dims();
        let knot_xy = knot_xy.reshape([b, 1, knots, 2]).expand([b, k, knots, 2]) + at_knots;
        let futures = self.interpolate(knot_xy.reshape([b * k, knots, 2]));
        let t = futures.dims()[1];
        CandidateFutures {
            logits,
            futures: futures.reshape([b, k, t, 2]),
        }
    }

    /// Knot positions `[batch, knots, 2]` interpolated to every step `-> [batch, T, 2]`.
    fn interpolate(&self, knot_xy: Tensor<3>) -> Tensor<3> {
        let [b, _, _] = knot_xy.dims();
        let [t, knots] = self.interpolation.dims();
        self.interpolation
            .val()
            .reshape([1, t, knots])
            .expand([b, t, knots])
            .matmul(knot_xy)
    }

    /// The displacement's knot positions, the selector's logits and the candidates at the
    /// knots' steps.
    fn heads(&self, embedding: Tensor<2>, psi: Tensor<1>, modes: BModes) -> Heads {
        let [b, _] = embedding.dims();
        // In units of the labels' spread, clamped: a ψ far outside every label (a range
        // predictor's extrapolation on a tiny model, a typo) must not drive the MLPs into
        // metres-per-step displacements or saturate the modes' softmax by its value alone.
        let psi_scaled = (psi.reshape([b, 1]) / self.psi_scale.max(1e-12))
            .clamp(-PSI_INPUT_RANGE, PSI_INPUT_RANGE);
        let psi = self.psi_mlp.forward(psi_scaled.clone());
        let input = Tensor::cat(vec![embedding, psi], 1);
        let out = self.decoder.forward(input.clone());
        let [_, knots] = self.interpolation.dims();
        let knot_xy = out.reshape([b, knots, 2]).cumsum(1);
        let [_, k, tm, _] = modes.xy.dims();
        // The modes at the knots' steps, so that the choice is interpolated like the
        // displacement: smooth by construction (the predictor's per-step means are not).
        let stride = self.knot_stride.max(1);
        let idx: Vec<i64> = (0..knots)
            .map(|j| ((j + 1) * stride).min(tm).saturating_sub(1) as i64)
            .collect();
        let at_knots = modes.xy.select(
            2,
            Tensor::<1, burn::tensor::Int>::from_data(
                burn::tensor::TensorData::new(idx, [knots]),
                &knot_xy.device(),
            ),
        );
        let mode_psi = modes
            .psi
            .expect("the generator needs its candidates' courtesy (BModes::psi)")
            / self.psi_scale.max(1e-12);
        let inputs = vec![
            psi_scaled.clone().expand([b, k]).reshape([b, k, 1]),
            mode_psi.clone().reshape([b, k, 1]),
            relative_courtesy(psi_scaled, mode_psi, RELATIVE_COURTESY_FLOOR).reshape([b, k, 1]),
        ];
        // Clamped like ψ: a mode J_φ scores far outside the labels (an off-data mode of a
        // weak predictor) must not saturate the softmax by its value alone.
        let inputs = Tensor::cat(inputs, 2).clamp(-PSI_INPUT_RANGE, PSI_INPUT_RANGE);
        let logits = self.selector.forward(input)
            + modes.log_prob
            + self.mode_scorer.forward(inputs).reshape([b, k]);
        Heads {
            knot_xy,
            logits,
            at_knots,
        }
    }
}

/// The requested courtesy relative to each row's choices: `(ψ − ψ_k) / (std_j ψ_j + floor)`,
/// with both inputs first clamped to ± [`PSI_INPUT_RANGE`] like the scorer's other inputs.
/// J_φ's courtesy spans a scene's choices by 0.1 label spreads in one family and by several
/// in another (cut-ins against crossings): in units of the pooled `psi_scale`, one small MLP
/// cannot resolve the narrow scenes, while the relative input ranks the choices alike in both.
///
/// # Shapes
/// `psi: [batch, 1]`, `choices: [batch, K]` (both in label spreads) → `[batch, K]`
pub fn relative_courtesy(psi: Tensor<2>, choices: Tensor<2>, floor: f32) -> Tensor<2> {
    let [b, k] = choices.dims();
    let choices = choices.clamp(-PSI_INPUT_RANGE, PSI_INPUT_RANGE);
    let psi = psi.clamp(-PSI_INPUT_RANGE, PSI_INPUT_RANGE).expand([b, k]);
    let mean = choices.clone().mean_dim(1);
    let spread = (choices.clone() - mean).powf_scalar(2.0).mean_dim(1).sqrt() + floor.max(1e-6);
    (psi - choices) / spread.expand([b, k])
}

/// What [`Generator::forward_candidates`] returns.
#[derive(Debug, Clone)]
pub struct CandidateFutures {
    /// `[batch, K]` the selector's logits (the softmax gives the blend's weights).
    pub logits: Tensor<2>,
    /// `[batch, K, T, 2]` B's future (positions in B's frame, metres) if the selector chose
    /// candidate `k`: the candidate plus the displacement.
    pub futures: Tensor<4>,
}

impl CandidateFutures {
    /// Each row's likeliest candidate (the argmax of its logits): the one
    /// [`Generator::forward`] commits to.
    pub fn likeliest(&self) -> Vec<usize> {
        self.logits
            .clone()
            .argmax(1)
            .into_data()
            .convert::<i64>()
            .try_to_vec::<i64>()
            .unwrap_or_default()
            .into_iter()
            .map(|k| k as usize)
            .collect()
    }
}

/// The generator's heads before the choice: the displacement's `[batch, knots, 2]` knot
/// positions, the `[batch, K]` logits and the `[batch, K, knots, 2]` candidates at the knots'
/// steps.
struct Heads {
    knot_xy: Tensor<3>,
    logits: Tensor<2>,
    at_knots: Tensor<4>,
}

#[cfg(test)]
mod tests;
