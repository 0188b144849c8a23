//! The generator network.

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use scbg_model::blocks::Mlp;
use serde::{Deserialize, Serialize};

use crate::modes::{BModes, slowdown_warp};

/// Widths of the generator decoder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
    #[serde(default = "one")]
    pub psi_scale: f32,
    /// The decoder emits one displacement per `knot_stride` steps (5 = 2 Hz knots), and the
    /// positions between knots are interpolated linearly: futures are smooth by construction
    /// (per-step outputs trained for a few epochs zigzag by decimetres).
    #[serde(default = "one_step")]
    pub knot_stride: usize,
    /// Values of A's context after the embedding (`embedding_width` includes them): 0 for
    /// generators not told who A is (those trained before the option), else
    /// [`crate::data::A_CONTEXT_WIDTH`].
    #[serde(default)]
    pub a_context_width: usize,
    /// B's predicted marginal modes the generator chooses among (0: a plain regression, the
    /// default and every generator trained before the option). With `K > 0` the future is
    /// `Σ_k w_k(x, ψ) · μ_k + Δ(x, ψ)`: the frozen predictor's `K` mode means of B, weighted
    /// by a softmax of learned logits plus the modes' log-probabilities, and the regressed
    /// displacement `Δ` on top ([`Generator::forward`]). `K` must be the predictor's mode count.
    #[serde(default)]
    pub modes: usize,
    /// With `modes > 0`: the selector also scores each mode by its own courtesy ψ_k (J_φ of
    /// the mode mean toward the audience, [`crate::mode_courtesy`]) against the requested ψ:
    /// a shared MLP of `[ψ, ψ_k]` (both ÷ `psi_scale`) adds one logit per mode. Without it
    /// the selector sees B's embedding only and can learn "courteous" only as B's average
    /// behaviour, not which of *this* scene's modes helps A. false for every generator
    /// trained before the option.
    #[serde(default)]
    pub mode_courtesy: bool,
    /// With `mode_courtesy`: the scorer also sees the requested ψ *relative to this scene's
    /// choices*, `(ψ − ψ_k) / (std_j ψ_j + floor)` (all ÷ `psi_scale`, the std over the
    /// scene's choices), with this floor (`None` in [`Self::new`]; the application trains with
    /// [`RELATIVE_COURTESY_FLOOR`]).
    /// J_φ's courtesy spans a scene's choices by 0.1 label spreads in one family and by
    /// several in another (cut-ins against crossings): in units of the pooled `psi_scale`,
    /// one small MLP cannot resolve the narrow scenes, while the relative input ranks the
    /// choices alike in both. The floor keeps a scene whose choices J_φ scores alike from
    /// turning noise into rank. `None` (the pair alone) for every generator trained before
    /// the option.
    #[serde(default)]
    pub relative_courtesy_floor: Option<f32>,
    /// With `modes > 0`: outside training, B's future is the selector's likeliest mode plus
    /// the displacement ([`Generator::forward`]), not the softmax blend of the modes, which
    /// training needs to be differentiable ([`Generator::forward_blend`]). A blend of a
    /// yielding and a going future is neither: half a lane change, creeping into a crossing,
    /// which the other drivers read as a cut-in or a claim on the conflict zone. false (the
    /// blend) for every generator trained before the option.
    #[serde(default)]
    pub likeliest_mode: bool,
    /// With `modes > 0`: each of B's `K` modes also joins the choices slowed down, once per
    /// factor `w` here (in (0, 2], clamped): the same path, travelled at a speed that eases
    /// linearly from the mode's own at the current step to `w` times it at the horizon
    /// ([`slowdown_warp`]; a factor above 1 hurries the mode, an option, never a default).
    /// Yielding — dropping back, letting A merge or cross first — is
    /// the courteous manoeuvre of every interaction family, and a predictor's marginal modes
    /// rarely hold enough of it. The selector then chooses among `K · (1 + S)` candidates
    /// ([`Self::candidates`]); a slowed copy starts with its mode's log-probability. Empty
    /// for every generator trained before the option.
    #[serde(default)]
    pub mode_slowdowns: Vec<f32>,
    /// With `modes > 0` and above 0: each of B's `K` modes also joins the choices with its lane
    /// move completed ([`crate::lane_move`]): a mode that drifts off B's lane path, moved a
    /// full lane over within this many steps, its progress along the lane kept (a mode that
    /// keeps its lane repeats itself). Moving over for a faster A, or out of its way, is the
    /// courteous lane change, and a predictor's mode means rarely complete it. The copies
    /// follow the slowed ones; 0 (none) for every generator trained before the option.
    #[serde(default)]
    pub lane_move_steps: usize,
}

/// Hidden width of the per-mode courtesy scorer ([`GeneratorConfig::mode_courtesy`]).
const MODE_SCORER_HIDDEN: usize = 32;

/// The floor of [`GeneratorConfig::relative_courtesy_floor`] in new generators, in label
/// spreads (docs/findings.md, *Courtesy relative to the scene's choices*).
pub const RELATIVE_COURTESY_FLOOR: f32 = 0.1;

/// The generator's ψ inputs, in units of the labels' spread (`psi_scale`), are clamped to
/// ± this many spreads (the demo's labels span about ±5.4; a label beyond is rare).
const PSI_INPUT_RANGE: f32 = 20.0;

fn one() -> f32 {
    1.0
}

fn one_step() -> usize {
    1
}

impl GeneratorConfig {
    /// The choices of a mode-selecting generator: B's `modes`, their slowed copies
    /// ([`Self::mode_slowdowns`]) and their lane moves ([`Self::lane_move_steps`]); 0 for a
    /// plain regression.
    pub fn candidates(&self) -> usize {
        self.modes * (1 + self.mode_slowdowns.len() + usize::from(self.lane_move_steps > 0))
    }

    /// The default decoder for a predictor embedding of `embedding_width`: ψ width 32, hidden
    /// widths 256, 256, 80 steps, `psi_scale` 1 (set it from the labels), 2 Hz knots.
    pub fn new(embedding_width: usize) -> Self {
        Self {
            embedding_width,
            psi_width: 32,
            hidden: vec![256, 256],
            future_steps: 80,
            psi_scale: 1.0,
            knot_stride: 5,
            a_context_width: 0,
            modes: 0,
            mode_courtesy: false,
            relative_courtesy_floor: None,
            likeliest_mode: false,
            mode_slowdowns: Vec::new(),
            lane_move_steps: 0,
        }
    }

    /// The default decoder for a predictor embedding of `embedding_width` followed by A's
    /// context ([`crate::data::a_context`]).
    pub fn with_a_context(embedding_width: usize) -> Self {
        let w = crate::data::A_CONTEXT_WIDTH;
        Self {
            a_context_width: w,
            ..Self::new(embedding_width + w)
        }
    }

    /// Builds the generator on `device` (seed the device first for reproducible weights).
    pub fn init(&self, device: &Device) -> Generator {
        let mut dims = vec![self.embedding_width + self.psi_width];
        dims.extend(&self.hidden);
        let selector = (self.modes > 0).then(|| {
            let mut sel = vec![dims[0]];
            sel.extend(self.hidden.first());
            sel.push(self.candidates());
            Mlp::init(&sel, device)
        });
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
        let relative_courtesy_floor = self
            .relative_courtesy_floor
            .filter(|_| self.modes > 0 && self.mode_courtesy);
        let mode_scorer = (self.modes > 0 && self.mode_courtesy).then(|| {
            let inputs = 2 + usize::from(relative_courtesy_floor.is_some());
            Mlp::init(&[inputs, MODE_SCORER_HIDDEN, MODE_SCORER_HIDDEN, 1], device)
        });
        Generator {
            mode_scorer,
            psi_mlp: Mlp::init(&[1, self.psi_width, self.psi_width], device),
            decoder: Mlp::init(&dims, device),
            selector,
            interpolation: burn::module::Param::from_tensor(Tensor::from_data(
                burn::tensor::TensorData::new(weights, [self.future_steps, knots]),
                device,
            ))
            .set_require_grad(false),
            future_steps: self.future_steps,
            knot_stride: stride,
            psi_scale: self.psi_scale,
            a_context_width: self.a_context_width,
            likeliest_mode: self.modes > 0 && self.likeliest_mode,
            relative_courtesy_floor,
            mode_warp: if self.modes > 0 {
                slowdown_warp(&self.mode_slowdowns, self.future_steps, device)
                    .map(|w| burn::module::Param::from_tensor(w).set_require_grad(false))
            } else {
                None
            },
            lane_move_steps: if self.modes > 0 {
                self.lane_move_steps
            } else {
                0
            },
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
    /// MLP of `[embedding ‖ ψ embedding]` → `K` mode logits (see [`GeneratorConfig::modes`]).
    pub selector: Option<Mlp>,
    /// MLP of `[ψ, ψ_k]` (÷ `psi_scale`), and with [`Self::relative_courtesy_floor`] ψ
    /// relative to the scene's choices, → one more logit for mode `k` (see
    /// [`GeneratorConfig::mode_courtesy`]).
    pub mode_scorer: Option<Mlp>,
    /// `[T, knots]` fixed linear interpolation from knots to steps (not trained).
    pub interpolation: burn::module::Param<Tensor<2>>,
    /// Generated future steps `T`.
    pub future_steps: usize,
    /// Steps between knots (see [`GeneratorConfig::knot_stride`]).
    pub knot_stride: usize,
    /// ψ is divided by this before [`Self::psi_mlp`] (see [`GeneratorConfig::psi_scale`]).
    pub psi_scale: f32,
    /// See [`GeneratorConfig::a_context_width`].
    pub a_context_width: usize,
    /// See [`GeneratorConfig::likeliest_mode`].
    pub likeliest_mode: bool,
    /// See [`GeneratorConfig::relative_courtesy_floor`] (`None` without a mode scorer).
    pub relative_courtesy_floor: Option<f32>,
    /// `[S, T, T]` fixed warps of [`GeneratorConfig::mode_slowdowns`] (not trained; `None`
    /// without slowed copies).
    pub mode_warp: Option<burn::module::Param<Tensor<3>>>,
    /// [`GeneratorConfig::lane_move_steps`] (0: no lane moves among the choices).
    pub lane_move_steps: usize,
}

impl Generator {
    /// Whether [`Self::forward`] needs B's modes.
    pub fn selects_modes(&self) -> bool {
        self.selector.is_some()
    }

    /// B's modes as this generator chooses among them: with their slowed copies
    /// ([`GeneratorConfig::mode_slowdowns`]) and their lane moves
    /// ([`GeneratorConfig::lane_move_steps`], along `lane_paths[row]`, B's lane path in B's
    /// frame, [`crate::lane_path_points`]; a row without one repeats its modes), if any.
    pub fn candidates_of(&self, modes: BModes, lane_paths: &[Vec<[f32; 2]>]) -> BModes {
        modes
            .with_slowdowns(self.mode_warp.as_ref().map(|w| w.val()).as_ref())
            .with_lane_moves(lane_paths, self.lane_move_steps)
    }

    /// Whether [`Self::forward`] needs each mode's courtesy ([`BModes::psi`]).
    pub fn scores_mode_courtesy(&self) -> bool {
        self.mode_scorer.is_some()
    }

    /// `y_B = g(x, ψ)` (paper eq. 1): B's future for the requested courtesy ψ, as used
    /// outside training: a generator with [`GeneratorConfig::likeliest_mode`] takes its
    /// likeliest mode of B, every other one is [`Self::forward_blend`].
    ///
    /// # Shapes
    /// As [`Self::forward_blend`].
    ///
    /// # Panics
    /// As [`Self::forward_blend`].
    pub fn forward(
        &self,
        embedding: Tensor<2>,
        psi: Tensor<1>,
        modes: Option<BModes>,
    ) -> Tensor<3> {
        self.forward_with(embedding, psi, modes, self.likeliest_mode)
    }

    /// `y_B = g(x, ψ)` as trained (differentiable in every weight). The knot
    /// displacements are summed into knot positions and interpolated to every step; a
    /// mode-selecting generator adds the knot positions to its softmax-weighted mixture of B's
    /// modes taken at the knots' steps, before the interpolation.
    ///
    /// # Shapes
    /// `embedding: [batch, e]` (B's frozen scene embedding), `psi: [batch]`,
    /// `modes`: see [`BModes`] (required when [`Self::selects_modes`], ignored otherwise)
    /// `-> [batch, T, 2]` positions in B's frame (metres)
    ///
    /// # Panics
    /// When the generator selects modes and `modes` is `None`, or scores the modes' courtesy
    /// and `modes.psi` is `None`.
    pub fn forward_blend(
        &self,
        embedding: Tensor<2>,
        psi: Tensor<1>,
        modes: Option<BModes>,
    ) -> Tensor<3> {
        self.forward_with(embedding, psi, modes, false)
    }

    /// B's future for every candidate the selector can choose, with the selector's logits:
    /// what training with the classification loss needs ([`crate::SelectorLoss::Classify`]).
    /// The softmax of `logits` weighting `futures` is [`Self::forward_blend`] (the knots'
    /// interpolation is linear).
    ///
    /// # Shapes
    /// As [`Self::forward_blend`] `-> CandidateFutures` (`logits: [batch, K]`,
    /// `futures: [batch, K, T, 2]`)
    ///
    /// # Panics
    /// When the generator does not select modes, or as [`Self::forward_blend`].
    pub fn forward_candidates(
        &self,
        embedding: Tensor<2>,
        psi: Tensor<1>,
        modes: BModes,
    ) -> CandidateFutures {
        let heads = self.heads(embedding, psi, Some(modes));
        let (logits, at_knots) = heads
            .choice
            .expect("forward_candidates needs a mode-selecting generator");
        let [b, k, knots, _] = at_knots.dims();
        let knot_xy = heads
            .knot_xy
            .reshape([b, 1, knots, 2])
            .expand([b, k, knots, 2])
            + at_knots;
        let futures = self.interpolate(knot_xy.reshape([b * k, knots, 2]));
        let t = futures.dims()[1];
        CandidateFutures {
            logits,
            futures: futures.reshape([b, k, t, 2]),
        }
    }

    /// [`Self::forward_blend`], or with `likeliest` the one-hot of the selector's argmax in
    /// place of its softmax weights.
    fn forward_with(
        &self,
        embedding: Tensor<2>,
        psi: Tensor<1>,
        modes: Option<BModes>,
        likeliest: bool,
    ) -> Tensor<3> {
        let Heads {
            mut knot_xy,
            choice,
        } = self.heads(embedding, psi, modes);
        if let Some((logits, at_knots)) = choice {
            let [b, k, knots, _] = at_knots.dims();
            let weights = if likeliest {
                let device = logits.device();
                Tensor::<2>::zeros([b, k], &device).scatter(
                    1,
                    logits.argmax(1),
                    Tensor::ones([b, 1], &device),
                    burn::tensor::IndexingUpdateOp::Add,
                )
            } else {
                burn::tensor::activation::softmax(logits, 1)
            };
            let mixed = weights
                .reshape([b, 1, k])
                .matmul(at_knots.reshape([b, k, knots * 2]))
                .reshape([b, knots, 2]);
            knot_xy = knot_xy + mixed;
        }
        self.interpolate(knot_xy)
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

    /// The displacement's knot positions and, for a mode-selecting generator, the selector's
    /// logits and the candidates at the knots' steps.
    fn heads(&self, embedding: Tensor<2>, psi: Tensor<1>, modes: Option<BModes>) -> Heads {
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
        let choice = self.selector.as_ref().map(|selector| {
            let modes = modes.expect("a mode-selecting generator needs B's modes");
            let [_, k, tm, _] = modes.xy.dims();
            // The modes at the knots' steps, so that the mixture is interpolated like the
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
            let mut logits = selector.forward(input) + modes.log_prob;
            if let Some(scorer) = &self.mode_scorer {
                let mode_psi = modes
                    .psi
                    .expect("a generator scoring the modes' courtesy needs their ψ")
                    / self.psi_scale.max(1e-12);
                let mut inputs = vec![
                    psi_scaled.clone().expand([b, k]).reshape([b, k, 1]),
                    mode_psi.clone().reshape([b, k, 1]),
                ];
                if let Some(floor) = self.relative_courtesy_floor {
                    inputs.push(relative_courtesy(psi_scaled, mode_psi, floor).reshape([b, k, 1]));
                }
                // Clamped like ψ: a mode J_φ scores far outside the labels (an off-data
                // mode of a weak predictor) must not saturate the softmax by its value alone.
                let inputs = Tensor::cat(inputs, 2).clamp(-PSI_INPUT_RANGE, PSI_INPUT_RANGE);
                logits = logits + scorer.forward(inputs).reshape([b, k]);
            }
            (logits, at_knots)
        });
        Heads { knot_xy, choice }
    }
}

/// The requested courtesy relative to each row's choices
/// ([`GeneratorConfig::relative_courtesy_floor`]): `(ψ − ψ_k) / (std_j ψ_j + floor)`, with
/// both inputs first clamped to ± [`PSI_INPUT_RANGE`] like the scorer's other inputs.
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
/// positions, and for a mode-selecting generator the `[batch, K]` logits and the
/// `[batch, K, knots, 2]` candidates at the knots' steps.
struct Heads {
    knot_xy: Tensor<3>,
    choice: Option<(Tensor<2>, Tensor<4>)>,
}

#[cfg(test)]
mod tests;
