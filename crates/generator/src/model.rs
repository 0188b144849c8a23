//! The generator network.

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use scbg_model::blocks::Mlp;
use serde::{Deserialize, Serialize};

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
    /// With `modes > 0`: outside training, B's future is the selector's likeliest mode plus
    /// the displacement ([`Generator::forward`]), not the softmax blend of the modes, which
    /// training needs to be differentiable ([`Generator::forward_blend`]). A blend of a
    /// yielding and a going future is neither: half a lane change, creeping into a crossing,
    /// which the other drivers read as a cut-in or a claim on the conflict zone. false (the
    /// blend) for every generator trained before the option.
    #[serde(default)]
    pub likeliest_mode: bool,
    /// With `modes > 0`: each of B's `K` modes also joins the choices slowed down, once per
    /// factor `w` here (in (0, 1]): the same path, travelled at a speed that eases linearly
    /// from the mode's own at the current step to `w` times it at the horizon
    /// ([`slowdown_warp`]). Yielding — dropping back, letting A merge or cross first — is
    /// the courteous manoeuvre of every interaction family, and a predictor's marginal modes
    /// rarely hold enough of it. The selector then chooses among `K · (1 + S)` candidates
    /// ([`Self::candidates`]); a slowed copy starts with its mode's log-probability. Empty
    /// for every generator trained before the option.
    #[serde(default)]
    pub mode_slowdowns: Vec<f32>,
}

/// The `[S, T, T]` time warps of [`GeneratorConfig::mode_slowdowns`]: row `s` of warp `i`
/// holds the weights of a mode's steps (positions at steps 1‥T, the origin at step 0 is B's
/// current position, zero in B's frame) in its slowed copy's step `s + 1`. With factor `w`
/// the slowed copy is at the mode's fractional step `τ(t) = t − (1 − w) t² / (2T)` at step
/// `t`, linearly interpolated: its speed is the mode's times `1 − (1 − w) t / T`, smooth at
/// the current step (no jump in speed) and `w` times the mode's at the horizon.
pub fn slowdown_warp(slowdowns: &[f32], steps: usize, device: &Device) -> Option<Tensor<3>> {
    if slowdowns.is_empty() || steps == 0 {
        return None;
    }
    let t_max = steps as f32;
    let mut weights = vec![0.0f32; slowdowns.len() * steps * steps];
    for (i, &w) in slowdowns.iter().enumerate() {
        let w = w.clamp(0.0, 1.0);
        for s in 0..steps {
            let t = (s + 1) as f32;
            let tau = (t - (1.0 - w) * t * t / (2.0 * t_max)).clamp(0.0, t_max);
            let lo = tau.floor() as usize; // 0 = the origin
            let frac = tau - lo as f32;
            let row = i * steps * steps + s * steps;
            if lo >= 1 {
                weights[row + lo - 1] += 1.0 - frac;
            }
            if lo < steps && frac > 0.0 {
                weights[row + lo] += frac;
            }
        }
    }
    Some(Tensor::from_data(
        burn::tensor::TensorData::new(weights, [slowdowns.len(), steps, steps]),
        device,
    ))
}

/// Hidden width of the per-mode courtesy scorer ([`GeneratorConfig::mode_courtesy`]).
const MODE_SCORER_HIDDEN: usize = 32;

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
    /// The choices of a mode-selecting generator: B's `modes` and their slowed copies
    /// ([`Self::mode_slowdowns`]); 0 for a plain regression.
    pub fn candidates(&self) -> usize {
        self.modes * (1 + self.mode_slowdowns.len())
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
            likeliest_mode: false,
            mode_slowdowns: Vec::new(),
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
        let mode_scorer = (self.modes > 0 && self.mode_courtesy)
            .then(|| Mlp::init(&[2, MODE_SCORER_HIDDEN, MODE_SCORER_HIDDEN, 1], device));
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
            mode_warp: if self.modes > 0 {
                slowdown_warp(&self.mode_slowdowns, self.future_steps, device)
                    .map(|w| burn::module::Param::from_tensor(w).set_require_grad(false))
            } else {
                None
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
    /// MLP of `[ψ, ψ_k]` (÷ `psi_scale`) → one more logit for mode `k` (see
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
    /// `[S, T, T]` fixed warps of [`GeneratorConfig::mode_slowdowns`] (not trained; `None`
    /// without slowed copies).
    pub mode_warp: Option<burn::module::Param<Tensor<3>>>,
}

/// B's predicted marginal modes, the choices of a mode-selecting generator
/// ([`GeneratorConfig::modes`]); see [`crate::b_modes`].
#[derive(Debug, Clone)]
pub struct BModes {
    /// `[batch, K, T, 2]` mode means in B's frame (metres).
    pub xy: Tensor<4>,
    /// `[batch, K]` log-probabilities of the modes.
    pub log_prob: Tensor<2>,
    /// `[batch, K]` each mode's courtesy ψ_k ([`crate::mode_courtesy`]); required by a
    /// generator that scores them ([`Generator::scores_mode_courtesy`]).
    pub psi: Option<Tensor<2>>,
    /// The leading modes that form the predicted mixture (their probabilities sum to 1);
    /// the rest are copies derived from them ([`BModes::with_slowdowns`]).
    pub mixture_modes: usize,
}

impl BModes {
    /// The rows repeated `times` times (row `r` of repetition `j` is row `j·batch + r`).
    pub fn repeat_rows(self, times: usize) -> Self {
        if times == 1 {
            return self;
        }
        Self {
            xy: Tensor::cat(vec![self.xy; times], 0),
            log_prob: Tensor::cat(vec![self.log_prob; times], 0),
            psi: self.psi.map(|p| Tensor::cat(vec![p; times], 0)),
            mixture_modes: self.mixture_modes,
        }
    }

    /// The modes followed by their slowed copies ([`GeneratorConfig::mode_slowdowns`]),
    /// warp by warp, each with its mode's log-probability; unchanged without `warp`. Call it
    /// before the modes' courtesy is measured.
    ///
    /// # Shapes
    /// `warp: [S, T, T]`; `xy: [batch, K, T, 2]` → `[batch, K · (1 + S), T, 2]`
    ///
    /// # Panics
    /// If the modes' courtesy is already set (it would not cover the copies).
    pub fn with_slowdowns(self, warp: Option<&Tensor<3>>) -> Self {
        let Some(warp) = warp else {
            return self;
        };
        assert!(self.psi.is_none(), "slow the modes before scoring them");
        let [b, k, t, _] = self.xy.dims();
        let [s, _, _] = warp.dims();
        let flat = self.xy.clone().reshape([b * k, t, 2]);
        let mut xy = vec![self.xy];
        for i in 0..s {
            let w = warp.clone().narrow(0, i, 1).expand([b * k, t, t]);
            xy.push(w.matmul(flat.clone()).reshape([b, k, t, 2]));
        }
        Self {
            xy: Tensor::cat(xy, 1),
            log_prob: Tensor::cat(vec![self.log_prob; 1 + s], 1),
            psi: None,
            mixture_modes: self.mixture_modes,
        }
    }
}

impl Generator {
    /// Whether [`Self::forward`] needs B's modes.
    pub fn selects_modes(&self) -> bool {
        self.selector.is_some()
    }

    /// B's modes as this generator chooses among them: with their slowed copies
    /// ([`GeneratorConfig::mode_slowdowns`]), if any.
    pub fn candidates_of(&self, modes: BModes) -> BModes {
        modes.with_slowdowns(self.mode_warp.as_ref().map(|w| w.val()).as_ref())
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

    /// [`Self::forward_blend`], or with `likeliest` the one-hot of the selector's argmax in
    /// place of its softmax weights.
    fn forward_with(
        &self,
        embedding: Tensor<2>,
        psi: Tensor<1>,
        modes: Option<BModes>,
        likeliest: bool,
    ) -> Tensor<3> {
        let [b, _] = embedding.dims();
        // In units of the labels' spread, clamped: a ψ far outside every label (a range
        // predictor's extrapolation on a tiny model, a typo) must not drive the MLPs into
        // metres-per-step displacements or saturate the modes' softmax by its value alone.
        let psi_scaled = (psi.reshape([b, 1]) / self.psi_scale.max(1e-12))
            .clamp(-PSI_INPUT_RANGE, PSI_INPUT_RANGE);
        let psi = self.psi_mlp.forward(psi_scaled.clone());
        let input = Tensor::cat(vec![embedding, psi], 1);
        let out = self.decoder.forward(input.clone());
        let [t, knots] = self.interpolation.dims();
        let mut knot_xy = out.reshape([b, knots, 2]).cumsum(1);
        if let Some(selector) = &self.selector {
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
                // Clamped like ψ: a mode J_φ scores far outside the labels (an off-data
                // mode of a weak predictor) must not saturate the softmax by its value alone.
                let pair = Tensor::cat(
                    vec![
                        psi_scaled.expand([b, k]).reshape([b, k, 1]),
                        mode_psi.reshape([b, k, 1]),
                    ],
                    2,
                )
                .clamp(-PSI_INPUT_RANGE, PSI_INPUT_RANGE);
                logits = logits + scorer.forward(pair).reshape([b, k]);
            }
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
        self.interpolation
            .val()
            .reshape([1, t, knots])
            .expand([b, t, knots])
            .matmul(knot_xy)
    }
}

#[cfg(test)]
mod tests {
    use burn::optim::AdamConfig;

    use super::*;

    #[test]
    fn knots_are_interpolated_linearly() {
        let _guard = crate::tests::SEED_LOCK
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        let device = Device::flex();
        let g = GeneratorConfig::new(24).init(&device);
        let w: Vec<f32> = g.interpolation.val().into_data().try_to_vec().unwrap();
        let knots = 16;
        let row = |s: usize| &w[s * knots..(s + 1) * knots];
        // Step 1 (index 0) is a fifth of the way from the origin to knot 0.
        assert!((row(0)[0] - 0.2).abs() < 1e-6 && row(0)[1..].iter().all(|v| *v == 0.0));
        // Step 5 is knot 0; step 8 is 40 % knot 0 + 60 % knot 1; step 80 is the last knot.
        assert!((row(4)[0] - 1.0).abs() < 1e-6);
        assert!((row(7)[0] - 0.4).abs() < 1e-6 && (row(7)[1] - 0.6).abs() < 1e-6);
        assert!((row(79)[15] - 1.0).abs() < 1e-6);
        // Every row's weights sum to at most 1 (the origin takes the rest).
        assert!((0..80).all(|s| row(s).iter().sum::<f32>() <= 1.0 + 1e-6));
    }

    #[test]
    fn forward_shape() {
        let device = Device::flex();
        let g = GeneratorConfig::new(24).init(&device);
        let out = g.forward(
            Tensor::zeros([3, 24], &device),
            Tensor::zeros([3], &device),
            None,
        );
        assert_eq!(out.dims(), [3, 80, 2]);
    }

    /// Zeroes the decoder's last layer: the regressed displacement is 0, so a mode-selecting
    /// generator's future is its (weighted) modes alone.
    fn zero_displacement(g: &mut Generator) {
        let last = g.decoder.layers.last_mut().unwrap();
        last.weight = last.weight.clone().map(|w| w.zeros_like());
        if let Some(bias) = &mut last.bias {
            *bias = bias.clone().map(|b| b.zeros_like());
        }
    }

    /// Two modes of B in a row: a straight one along x and one turning to +y (`[2, 80, 2]`).
    fn two_modes(device: &Device) -> Tensor<3> {
        let xy: Vec<f32> = (0..2)
            .flat_map(|k| {
                (1..=80).flat_map(move |s| [s as f32, if k == 1 { 0.1 * s as f32 } else { 0.0 }])
            })
            .collect();
        Tensor::from_data(burn::tensor::TensorData::new(xy, [2, 80, 2]), device)
    }

    /// The mode-selecting generator's future is the softmax-weighted modes plus the regressed
    /// displacement: with the displacement's last layer zeroed and a mode log-probability far
    /// below the other, it is the likelier mode, whatever ψ and the learned logits say.
    #[test]
    fn mode_selection_weights_the_modes() {
        let device = Device::flex();
        let mut config = GeneratorConfig::new(24);
        config.modes = 2;
        let mut g = config.init(&device);
        assert!(g.selects_modes());
        zero_displacement(&mut g);
        let modes = |favoured: usize| BModes {
            xy: two_modes(&device).reshape([1, 2, 80, 2]),
            log_prob: Tensor::from_data(
                [[
                    if favoured == 0 { 0.0f32 } else { -60.0 },
                    if favoured == 1 { 0.0 } else { -60.0 },
                ]],
                &device,
            ),
            psi: None,
            mixture_modes: 2,
        };
        let want: Vec<f32> = two_modes(&device).into_data().try_to_vec().unwrap();
        for favoured in [0, 1] {
            for psi in [-3.0f32, 0.0, 3.0] {
                let out: Vec<f32> = g
                    .forward(
                        Tensor::ones([1, 24], &device),
                        Tensor::from_data([psi], &device),
                        Some(modes(favoured)),
                    )
                    .into_data()
                    .try_to_vec()
                    .unwrap();
                let want = &want[favoured * 160..(favoured + 1) * 160];
                assert!(
                    out.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-4),
                    "mode {favoured}, psi {psi}: {:?} vs {:?}",
                    &out[150..],
                    &want[150..]
                );
            }
        }
    }

    /// Trained on "ψ −1 → the straight mode, ψ +1 → the turning mode" from equally likely modes,
    /// the selector learns to pick by ψ (the end points differ by 8 m; a regression without the
    /// modes would have to learn both shapes).
    #[test]
    fn mode_selection_learns_to_pick_by_psi() {
        use burn::optim::GradientsParams;
        let device = scbg_model::device::training_device("flex").unwrap();
        let _lock = crate::tests::SEED_LOCK
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        device.seed(5);
        let mut config = GeneratorConfig::new(8);
        config.modes = 2;
        config.hidden = vec![32, 32];
        let mut g = config.init(&device);
        let mut optim = AdamConfig::new().init();
        let n = 16;
        let psi: Vec<f32> = (0..n)
            .map(|i| if i % 2 == 0 { -1.0 } else { 1.0 })
            .collect();
        let modes = || BModes {
            xy: two_modes(&device).reshape([1, 2, 80, 2]).repeat_dim(0, n),
            log_prob: Tensor::from_data([[0.0f32, 0.0]], &device).repeat_dim(0, n),
            psi: None,
            mixture_modes: 2,
        };
        let all = two_modes(&device);
        let target = Tensor::cat((0..n).map(|i| all.clone().narrow(0, i % 2, 1)).collect(), 0);
        let embedding = Tensor::<2>::ones([n, 8], &device);
        let error = |g: &Generator| -> f32 {
            let out = g.forward(
                embedding.clone(),
                Tensor::from_data(psi.as_slice(), &device),
                Some(modes()),
            );
            (out - target.clone()).abs().max().into_scalar()
        };
        let before = error(&g);
        for _ in 0..150 {
            let out = g.forward(
                embedding.clone(),
                Tensor::from_data(psi.as_slice(), &device),
                Some(modes()),
            );
            let loss = (out - target.clone()).powi_scalar(2).mean();
            let grads = GradientsParams::from_grads(loss.backward(), &g);
            g = optim.step(1e-2, g, grads);
        }
        let after = error(&g);
        assert!(
            after < 0.5 && after < 0.1 * before,
            "max error {before} m → {after} m"
        );
    }

    /// The same request (ψ +1) and the same embedding in every example, but which of B's two
    /// modes is the courteous one (ψ_k +1 against −1) alternates between examples: a selector
    /// that sees the embedding alone cannot tell them apart and ends between the modes (its
    /// error stays metres), one that scores the modes' courtesy picks the right one.
    #[test]
    fn scoring_the_modes_courtesy_tells_which_mode_helps() {
        use burn::optim::GradientsParams;
        let device = scbg_model::device::training_device("flex").unwrap();
        let _lock = crate::tests::SEED_LOCK
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let n = 16;
        let mode_psi: Vec<f32> = (0..n)
            .flat_map(|i| {
                if i % 2 == 0 {
                    [1.0f32, -1.0]
                } else {
                    [-1.0, 1.0]
                }
            })
            .collect();
        let all = two_modes(&device);
        let target = Tensor::cat((0..n).map(|i| all.clone().narrow(0, i % 2, 1)).collect(), 0);
        let embedding = Tensor::<2>::ones([n, 8], &device);
        let psi = || Tensor::<1>::ones([n], &device);
        let train = |mode_courtesy: bool| -> f32 {
            device.seed(5);
            let mut config = GeneratorConfig::new(8);
            config.modes = 2;
            config.mode_courtesy = mode_courtesy;
            config.hidden = vec![32, 32];
            let mut g = config.init(&device);
            assert_eq!(g.scores_mode_courtesy(), mode_courtesy);
            let modes = || BModes {
                xy: two_modes(&device).reshape([1, 2, 80, 2]).repeat_dim(0, n),
                log_prob: Tensor::from_data([[0.0f32, 0.0]], &device).repeat_dim(0, n),
                psi: Some(Tensor::from_data(
                    burn::tensor::TensorData::new(mode_psi.clone(), [n, 2]),
                    &device,
                )),
                mixture_modes: 2,
            };
            let mut optim = AdamConfig::new().init();
            for _ in 0..200 {
                let out = g.forward(embedding.clone(), psi(), Some(modes()));
                let loss = (out - target.clone()).powi_scalar(2).mean();
                let grads = GradientsParams::from_grads(loss.backward(), &g);
                g = optim.step(1e-2, g, grads);
            }
            let out = g.forward(embedding.clone(), psi(), Some(modes()));
            (out - target.clone()).abs().max().into_scalar()
        };
        let (blind, scored) = (train(false), train(true));
        assert!(
            blind > 2.0,
            "the embedding alone cannot tell: max error {blind} m"
        );
        assert!(scored < 0.5, "scored by courtesy: max error {scored} m");
    }

    /// Outside training a generator with `likeliest_mode` gives exactly one of B's modes (the
    /// displacement zeroed), where the blend it trains with lies between them.
    #[test]
    fn the_likeliest_mode_is_one_mode_not_a_blend() {
        let device = Device::flex();
        let mut config = GeneratorConfig::new(24);
        config.modes = 2;
        config.likeliest_mode = true;
        let mut g = config.init(&device);
        zero_displacement(&mut g);
        let modes = || BModes {
            xy: two_modes(&device).reshape([1, 2, 80, 2]),
            log_prob: Tensor::from_data([[0.0f32, 0.0]], &device),
            psi: None,
            mixture_modes: 2,
        };
        let end_y = |out: Tensor<3>| -> f32 {
            let v: Vec<f32> = out.into_data().try_to_vec().unwrap();
            v[159]
        };
        let (embedding, psi) = (
            Tensor::ones([1, 24], &device),
            Tensor::from_data([0.5f32], &device),
        );
        // The modes end at y = 0 (straight) and y = 8 (turning).
        let likeliest = end_y(g.forward(embedding.clone(), psi.clone(), Some(modes())));
        assert!(
            likeliest.abs() < 1e-4 || (likeliest - 8.0).abs() < 1e-4,
            "{likeliest}"
        );
        let blend = end_y(g.forward_blend(embedding, psi, Some(modes())));
        assert!(blend > 1e-3 && blend < 8.0 - 1e-3, "{blend}");
    }

    /// A slowed copy keeps its mode's path and eases off smoothly: on a straight mode at
    /// 1 m a step, factor ½ starts at the mode's speed, ends at half of it and covers
    /// `T (1 + w) / 2` = 60 m of the mode's 80; factor 1 is the mode itself.
    #[test]
    fn slowed_copies_ease_off_along_the_modes_path() {
        let device = Device::flex();
        let warp = slowdown_warp(&[1.0, 0.5], 80, &device).unwrap();
        assert_eq!(warp.dims(), [2, 80, 80]);
        let modes = BModes {
            xy: two_modes(&device).reshape([1, 2, 80, 2]),
            log_prob: Tensor::from_data([[-0.1f32, -2.0]], &device),
            psi: None,
            mixture_modes: 2,
        };
        let out = modes.with_slowdowns(Some(&warp));
        assert_eq!(out.xy.dims(), [1, 6, 80, 2]);
        assert_eq!(out.mixture_modes, 2);
        let lp: Vec<f32> = out.log_prob.into_data().try_to_vec().unwrap();
        assert_eq!(lp, vec![-0.1, -2.0, -0.1, -2.0, -0.1, -2.0]);
        let xy: Vec<f32> = out.xy.into_data().try_to_vec().unwrap();
        let at = |c: usize, s: usize| [xy[(c * 80 + s) * 2], xy[(c * 80 + s) * 2 + 1]];
        for s in 0..80 {
            // Factor 1: the modes themselves.
            for k in 0..2 {
                let (a, b) = (at(k, s), at(2 + k, s));
                assert!((a[0] - b[0]).abs() < 1e-4 && (a[1] - b[1]).abs() < 1e-4);
            }
            // Factor ½ of the turning mode stays on its line y = 0.1 x.
            let p = at(5, s);
            assert!((p[1] - 0.1 * p[0]).abs() < 1e-4, "{p:?}");
        }
        let x = |s: usize| at(4, s)[0];
        assert!((x(79) - 60.0).abs() < 1e-3, "{}", x(79));
        assert!((x(0) - (1.0 - 0.5 / 160.0)).abs() < 1e-4, "{}", x(0));
        let speeds: Vec<f32> = (1..80).map(|s| x(s) - x(s - 1)).collect();
        assert!(speeds.windows(2).all(|w| w[1] <= w[0] + 1e-4), "eases off");
        assert!((speeds[78] - 0.5).abs() < 0.02, "{}", speeds[78]);
    }

    /// A generator with slowed copies chooses among `K · (1 + S)` candidates, and outside
    /// training its future is one of them (the displacement zeroed).
    #[test]
    fn a_generator_chooses_among_the_slowed_copies_too() {
        let device = Device::flex();
        let mut config = GeneratorConfig::new(24);
        config.modes = 2;
        config.likeliest_mode = true;
        config.mode_slowdowns = vec![0.5];
        assert_eq!(config.candidates(), 4);
        let mut g = config.init(&device);
        zero_displacement(&mut g);
        let modes = g.candidates_of(BModes {
            xy: two_modes(&device).reshape([1, 2, 80, 2]),
            log_prob: Tensor::from_data([[0.0f32, 0.0]], &device),
            psi: None,
            mixture_modes: 2,
        });
        let all: Vec<f32> = modes.xy.clone().into_data().try_to_vec().unwrap();
        let out: Vec<f32> = g
            .forward(
                Tensor::ones([1, 24], &device),
                Tensor::from_data([0.3f32], &device),
                Some(modes),
            )
            .into_data()
            .try_to_vec()
            .unwrap();
        // At the knots (every 5th step; linear between them, and a slowed copy is not).
        let at_knots = |v: &[f32]| -> Vec<f32> {
            (4..80)
                .step_by(5)
                .flat_map(|s| [v[2 * s], v[2 * s + 1]])
                .collect()
        };
        let out = at_knots(&out);
        assert!(
            all.chunks_exact(160).any(|c| at_knots(c)
                .iter()
                .zip(&out)
                .all(|(a, b)| (a - b).abs() < 1e-4)),
            "one of the four candidates"
        );
        // Generators saved before the option have no slowed copies.
        let mut json = serde_json::to_value(&config).unwrap();
        json.as_object_mut().unwrap().remove("mode_slowdowns");
        let old: GeneratorConfig = serde_json::from_value(json).unwrap();
        assert_eq!(old.candidates(), 2);
        assert!(old.init(&device).mode_warp.is_none());
    }

    /// A ψ far outside the labels (here 1000 spreads) is read as the clamp's 20 spreads, so a
    /// wild request or range extrapolation cannot drive the decoder into metres per step.
    #[test]
    fn a_psi_far_outside_the_labels_is_clamped() {
        let device = Device::flex();
        let mut config = GeneratorConfig::new(24);
        config.psi_scale = 0.5;
        let g = config.init(&device);
        let future = |psi: f32| -> Vec<f32> {
            g.forward(
                Tensor::ones([1, 24], &device),
                Tensor::from_data([psi], &device),
                None,
            )
            .into_data()
            .try_to_vec()
            .unwrap()
        };
        assert_eq!(future(500.0), future(0.5 * PSI_INPUT_RANGE));
        assert_eq!(future(-500.0), future(-0.5 * PSI_INPUT_RANGE));
        assert_ne!(future(0.5 * PSI_INPUT_RANGE), future(0.0));
    }

    #[test]
    fn generators_saved_before_the_a_context_are_not_told_who_a_is() {
        let mut json = serde_json::to_value(GeneratorConfig::new(24)).unwrap();
        json.as_object_mut().unwrap().remove("a_context_width");
        json.as_object_mut().unwrap().remove("modes");
        let old: GeneratorConfig = serde_json::from_value(json).unwrap();
        assert_eq!(old.a_context_width, 0);
        // Nor do they select among B's modes.
        assert_eq!(old.modes, 0);
        assert!(!old.init(&Device::flex()).selects_modes());
        let new = GeneratorConfig::with_a_context(24);
        assert_eq!(
            (new.embedding_width, new.a_context_width),
            (24 + crate::A_CONTEXT_WIDTH, crate::A_CONTEXT_WIDTH)
        );
    }
}
