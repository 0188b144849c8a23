//! The Multipath++ model: history, interaction and road encoders, the fusion of the
//! conditioning future ([`crate::condition`]) and the anchor decoder.

use burn::module::{Module, Param};
use burn::nn::{Initializer, Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};
use scbg_features::{AGENT_FEATURES, DIFF_FEATURES, ROAD_FEATURES};

use crate::batch::Batch;
use crate::blocks::{FusedLstm, Mcg, Mlp};
pub use crate::condition::{
    CONDITION_SCALE_M, CONDITION_SCALE_MPS, CONDITION_STRIDE, FutureEncoder, LANE_OFFSET_SCALE_M,
    STEPWISE_MODE_POINTS, StepwiseCondition,
};
use crate::config::MultipathConfig;
pub use crate::output::{GmmOutput, Mixture};
/// Encodes agent histories: LSTM over step features ‖ LSTM over step differences ‖ MCG over
/// per-step MLP embeddings (features + one-hot time step).
#[derive(Module, Debug)]
pub struct HistoryEncoder {
    /// LSTM over the per-step agent features (13 → `lstm_hidden`).
    pub lstm_steps: FusedLstm,
    /// LSTM over the step-to-step differences (11 → `lstm_hidden`).
    pub lstm_diffs: FusedLstm,
    /// Per-step MLP of `[features ‖ one-hot step]` (`13 + history_steps →` history width).
    pub step_mlp: Mlp,
    /// MCG over the per-step embeddings (valid steps only, constant context), max-pooled.
    pub step_mcg: Mcg,
    /// History steps the encoder was built for (size of the one-hot step index).
    pub history_steps: usize,
}

impl HistoryEncoder {
    /// Builds the encoder for `config`'s widths.
    pub fn init(config: &MultipathConfig, device: &Device) -> Self {
        let h = config.history_steps;
        let mut dims = vec![AGENT_FEATURES + h];
        dims.extend(&config.step_mlp);
        let w = config.history_width();
        Self {
            lstm_steps: FusedLstm::init(AGENT_FEATURES, config.lstm_hidden, device),
            lstm_diffs: FusedLstm::init(DIFF_FEATURES, config.lstm_hidden, device),
            step_mlp: Mlp::init(&dims, device),
            step_mcg: Mcg::init(w, 1, w, config.mcg_blocks, device),
            history_steps: h,
        }
    }

    /// Encodes `n` agent histories (standardised features; feature 6 is the validity flag)
    /// into `[LSTM(history) ‖ LSTM(diffs) ‖ MCG summary]`.
    ///
    /// # Shapes
    /// `history: [n, steps, 13]`, `diffs: [n, steps - 1, 11]`
    /// `-> [n, 2·lstm_hidden + history_width]`
    pub fn forward(&self, history: Tensor<3>, diffs: Tensor<3>) -> Tensor<2> {
        let [n, steps, _] = history.dims();
        let device = history.device();
        let state_steps = self.lstm_steps.forward(history.clone());
        let state_diffs = self.lstm_diffs.forward(diffs);
        let mut eye = vec![0.0f32; steps * steps];
        for i in 0..steps {
            eye[i * steps + i] = 1.0;
        }
        let time = Tensor::<2>::from_data(TensorData::new(eye, [steps, steps]), &device)
            .reshape([1, steps, steps])
            .expand([n, steps, steps]);
        let valid = history.clone().narrow(2, 6, 1).reshape([n, steps]);
        let step_in = Tensor::cat(vec![history, time], 2);
        let step_embed = self.step_mlp.forward(step_in);
        let (_, summary) = self
            .step_mcg
            .forward(step_embed, Tensor::ones([n, 1], &device), valid);
        Tensor::cat(vec![state_steps, state_diffs, summary], 1)
    }
}

/// Multipath++ with a conditional future encoder (marginal when the condition flag is 0).
#[derive(Module, Debug)]
pub struct Multipath {
    /// History encoder, shared by the target and the other agents.
    pub history: HistoryEncoder,
    /// MCG over the target's history encoding → target embedding (`target_width`).
    pub target_mcg: Mcg,
    /// MCG over the other agents' history encodings with the target embedding as context,
    /// max-pooled → interaction embedding (`interaction_width`).
    pub interaction_mcg: Mcg,
    /// Per-segment road MLP (27 features → road width).
    pub road_mlp: Mlp,
    /// MLP of `[target ‖ interaction]` → the road MCG's context.
    pub road_context: Mlp,
    /// MCG over the valid road segments, max-pooled → road embedding (road width).
    pub road_mcg: Mcg,
    /// Encoder of the other agent's future (the conditional mode).
    pub future_encoder: FutureEncoder,
    /// Fuses `[scene ‖ condition·flag ‖ flag]` back to the embedding width (added to the scene).
    pub fuse: Linear,
    /// The step-wise (interventional) conditioning of the decoder, with
    /// `stepwise_condition`; `None` in the fused (CBP) model.
    pub stepwise: Option<StepwiseCondition>,
    /// Learned anchor embeddings, one per mode: `[num_modes, embedding_width]`.
    pub anchors: Param<Tensor<2>>,
    /// MCG over the anchors with the scene embedding as context (`decoder_width`).
    pub decoder_mcg: Mcg,
    /// Per-mode MLP → `5T + 1` outputs: `T` (dx, dy) displacements, `T` (a, b, c) and a logit.
    pub decoder_mlp: Mlp,
    /// A direct path from the embedding to the mode logits (added to the decoder's).
    pub mode_logits: Linear,
    /// Predicted future steps `T`.
    pub future_steps: usize,
}

impl MultipathConfig {
    /// Builds the model on `device` (seed the device first for reproducible weights).
    pub fn init(&self, device: &Device) -> Multipath {
        let hist_out = 2 * self.lstm_hidden + self.history_width();
        let e = self.embedding_width();
        let mut road_dims = vec![ROAD_FEATURES];
        road_dims.extend(&self.road_mlp);
        Multipath {
            history: HistoryEncoder::init(self, device),
            target_mcg: Mcg::init(hist_out, 1, self.target_width, self.mcg_blocks, device),
            interaction_mcg: Mcg::init(
                hist_out,
                self.target_width,
                self.interaction_width,
                self.mcg_blocks,
                device,
            ),
            road_mlp: Mlp::init(&road_dims, device),
            road_context: Mlp::init(
                &[
                    self.target_width + self.interaction_width,
                    self.road_context_hidden,
                    self.road_width(),
                ],
                device,
            ),
            road_mcg: Mcg::init(
                self.road_width(),
                self.road_width(),
                self.road_width(),
                self.mcg_blocks,
                device,
            ),
            future_encoder: FutureEncoder::init(self, device),
            fuse: LinearConfig::new(e + self.future_hidden + 1, e).init(device),
            stepwise: self
                .stepwise_condition
                .then(|| StepwiseCondition::init(self, device)),
            anchors: Initializer::Normal {
                mean: 0.0,
                std: 1.0,
            }
            .init([self.num_modes, e], device),
            decoder_mcg: Mcg::init(e, e, self.decoder_width, self.mcg_blocks, device),
            mode_logits: LinearConfig::new(e, self.num_modes).init(device),
            decoder_mlp: Mlp::init(
                &[self.decoder_width, self.decoder_hidden, self.mode_outputs()],
                device,
            ),
            future_steps: self.future_steps,
        }
    }
}

impl Multipath {
    /// The scene embedding, fused with the conditioning future where `condition_flag` is 1
    /// (with [`Self::stepwise`], with its first [`STEPWISE_MODE_POINTS`] points only).
    ///
    /// # Shapes
    /// batch tensors (see [`Batch`]) `-> [batch, embedding_width]`
    pub fn encode(&self, batch: &Batch) -> Tensor<2> {
        self.encode_with_prefixes(batch).0
    }

    /// [`Self::encode`], and with [`Self::stepwise`] the conditioning future's prefix
    /// encodings ([`FutureEncoder::forward_prefixes`]).
    ///
    /// # Shapes
    /// batch tensors `-> ([batch, embedding_width], Option<[batch, n, future_hidden]>)`
    fn encode_with_prefixes(&self, batch: &Batch) -> (Tensor<2>, Option<Tensor<3>>) {
        self.condition_scene(
            self.encode_scene(batch),
            &batch.condition,
            batch.lane_path.as_ref(),
            batch.condition_flag.clone(),
        )
    }

    /// [`Self::encode`] of rows whose condition is off (a [`crate::Mode::Marginal`] batch) from
    /// their scene encoding ([`Self::encode_scene`]). The fused condition is the future
    /// encoder's output times the zero flag, so the encoder is skipped and zeros take its
    /// place: the same embedding, one future-encoder pass fewer (what a closed-loop plan
    /// pays for each agent it encodes).
    ///
    /// # Shapes
    /// `SceneEncoding` of `[batch, ·]` `-> [batch, embedding_width]`
    pub fn encode_marginal(&self, scene: SceneEncoding) -> Tensor<2> {
        let SceneEncoding { scene, .. } = scene;
        let [b, w] = scene.dims();
        let fuse_in = self.fuse.weight.dims()[0];
        let off = Tensor::zeros([b, fuse_in - w], &scene.device());
        scene.clone() + self.fuse.forward(Tensor::cat(vec![scene, off], 1))
    }

    /// [`Self::forward`] of a batch made with [`Batch::for_mode`]`(.., mode, ..)`: the
    /// marginal shortcut ([`Self::forward_marginal`]) for [`crate::Mode::Marginal`].
    pub fn forward_mode(&self, batch: &Batch, mode: crate::Mode) -> GmmOutput {
        match mode {
            crate::Mode::Marginal => self.forward_marginal(batch),
            crate::Mode::Conditional => self.forward(batch),
        }
    }

    /// [`Self::forward`] of a marginal batch ([`crate::Mode::Marginal`]: every condition off)
    /// without the conditioning future's encoder and step-wise corrections, whose outputs the
    /// zero flag discards ([`Self::encode_marginal`]): the same prediction for less work.
    ///
    /// # Shapes
    /// batch tensors `-> GmmOutput` as [`Self::forward`]
    pub fn forward_marginal(&self, batch: &Batch) -> GmmOutput {
        self.decode(self.encode_marginal(self.encode_scene(batch)))
    }

    /// The scene part of the encoder (the target's and the other agents' histories, their
    /// interaction and the road), without the conditioning future: what rows that differ only
    /// in their conditioning share ([`Self::forward_shared`]).
    ///
    /// # Shapes
    /// batch tensors `-> SceneEncoding` of `[batch, ·]`
    pub fn encode_scene(&self, batch: &Batch) -> SceneEncoding {
        let [b, a, steps, f] = batch.others_history.dims();
        let device = batch.target_history.device();
        let target_hist = self
            .history
            .forward(batch.target_history.clone(), batch.target_diffs.clone());
        let d_hist = target_hist.dims()[1];
        let (target, _) = self.target_mcg.forward(
            target_hist.reshape([b, 1, d_hist]),
            Tensor::ones([b, 1], &device),
            Tensor::ones([b, 1], &device),
        );
        let [_, _, w] = target.dims();
        let target = target.reshape([b, w]);
        let others = self.history.forward(
            batch.others_history.clone().reshape([b * a, steps, f]),
            batch
                .others_diffs
                .clone()
                .reshape([b * a, steps - 1, DIFF_FEATURES]),
        );
        let (_, interaction) = self.interaction_mcg.forward(
            others.reshape([b, a, d_hist]),
            target.clone(),
            batch.others_mask.clone(),
        );
        let road = self.road_mlp.forward(batch.road.clone());
        let road_ctx = self
            .road_context
            .forward(Tensor::cat(vec![target.clone(), interaction.clone()], 1));
        let (_, road) = self
            .road_mcg
            .forward(road, road_ctx, batch.road_mask.clone());
        SceneEncoding {
            scene: Tensor::cat(vec![target.clone(), interaction, road], 1),
            target,
        }
    }

    /// The conditioning part of the encoder: `scene` fused with the conditioning future where
    /// `flag` is 1, and with [`Self::stepwise`] the future's prefix encodings.
    ///
    /// # Shapes
    /// `scene: SceneEncoding` of `[batch, ·]`, `condition: [batch, T, 3]`, `lane_path` as
    /// [`Batch::lane_path`], `flag: [batch, 1]`
    /// `-> ([batch, embedding_width], Option<[batch, n, future_hidden]>)`
    fn condition_scene(
        &self,
        scene: SceneEncoding,
        condition: &Tensor<3>,
        lane_path: Option<&(Tensor<3>, Tensor<2>)>,
        flag: Tensor<2>,
    ) -> (Tensor<2>, Option<Tensor<3>>) {
        let SceneEncoding { scene, target } = scene;
        let [b, _] = scene.dims();
        let (condition, prefixes) = if self.stepwise.is_some() {
            let prefixes = self
                .future_encoder
                .forward_prefixes(condition, lane_path, target);
            let [_, n, h] = prefixes.dims();
            let first = prefixes
                .clone()
                .narrow(1, STEPWISE_MODE_POINTS.min(n - 1), 1)
                .reshape([b, h]);
            (first, Some(prefixes))
        } else {
            let condition = self.future_encoder.forward(condition, lane_path, target);
            (condition, None)
        };
        let fused = Tensor::cat(vec![scene.clone(), condition * flag.clone(), flag], 1);
        (scene + self.fuse.forward(fused), prefixes)
    }

    /// Decodes K trajectories from an embedding: positions (metres, target frame) are the
    /// cumulative sums of the predicted per-step displacements; `cov_abc` is unclamped (the
    /// loss and [`GmmOutput::into_mixtures`] clamp it).
    ///
    /// # Shapes
    /// `embedding: [batch, e]`
    /// `-> GmmOutput { xy: [batch, K, T, 2], cov_abc: [batch, K, T, 3], logits: [batch, K] }`
    pub fn decode(&self, embedding: Tensor<2>) -> GmmOutput {
        self.decode_with(embedding, None)
    }

    /// [`Self::decode`] with the step-wise corrections of [`Self::stepwise`] from the
    /// conditioning future's prefix encodings and the rows' condition flags (none: marginal).
    ///
    /// # Shapes
    /// `embedding: [batch, e]`, `stepwise: Option<([batch, n, future_hidden], [batch, 1])>`
    /// `-> GmmOutput` as [`Self::decode`]
    fn decode_with(
        &self,
        embedding: Tensor<2>,
        stepwise: Option<(Tensor<3>, Tensor<2>)>,
    ) -> GmmOutput {
        let [b, e] = embedding.dims();
        let device = embedding.device();
        let [k, _] = self.anchors.dims();
        let anchors = self.anchors.val().reshape([1, k, e]).expand([b, k, e]);
        let (modes, _) =
            self.decoder_mcg
                .forward(anchors, embedding.clone(), Tensor::ones([b, k], &device));
        let modes = relu(modes);
        let out = self.decoder_mlp.forward(modes.clone()); // [b, k, 5T + 1]
        let t = self.future_steps;
        let mut dxy = out.clone().narrow(2, 0, 2 * t).reshape([b, k, t, 2]);
        let mut cov_abc = out.clone().narrow(2, 2 * t, 3 * t).reshape([b, k, t, 3]);
        if let (Some(block), Some((prefixes, flag))) = (&self.stepwise, stepwise) {
            let (d, c) = block.forward(modes, prefixes, flag);
            dxy = dxy + d;
            cov_abc = cov_abc + c;
        }
        // Per-step displacements, integrated: positions are their cumulative sum (paper-era
        // Multipath++ re-implementations predict positions directly; integrating makes smooth,
        // constant-speed futures the easy solution and keeps early training errors small).
        let xy = dxy.cumsum(2);
        let logits = out.narrow(2, 5 * t, 1).reshape([b, k]) + self.mode_logits.forward(embedding);
        GmmOutput {
            xy,
            cov_abc,
            logits,
        }
    }

    /// Predicts each target's future as a Gaussian mixture in its frame: [`Self::encode`] then
    /// [`Self::decode`]. Marginal or conditional per row, as the batch's `condition_flag` says.
    ///
    /// # Shapes
    /// batch tensors (see [`Batch`]) `-> GmmOutput`
    pub fn forward(&self, batch: &Batch) -> GmmOutput {
        let (embedding, prefixes) = self.encode_with_prefixes(batch);
        self.decode_with(
            embedding,
            prefixes.map(|p| (p, batch.condition_flag.clone())),
        )
    }

    /// [`Self::forward`] conditional on `condition` for rows that share their scene: row `r`
    /// is row `rows[r]` of `base` (its histories, road and lane path) conditioned on
    /// `condition[r]`. The scene is encoded once per row of `base` instead of once per row —
    /// the same outputs as [`Self::forward`] of a batch holding row `rows[r]` of `base` as its
    /// row `r`, conditional on `condition`, up to floating-point rounding. For J_φ over many
    /// futures of B toward the same A (the labels, the courtesy loss, sample and rank).
    ///
    /// # Shapes
    /// `base`: batch tensors of `[u, ·]`, `rows: [n]` (indices < u),
    /// `condition: [n, future_steps, 3]` (target frame: x m, y m, valid) `-> GmmOutput` of `[n, ·]`
    pub fn forward_shared(
        &self,
        base: &Batch,
        rows: Tensor<1, burn::tensor::Int>,
        condition: Tensor<3>,
    ) -> GmmOutput {
        let [n, _, _] = condition.dims();
        debug_assert_eq!(rows.dims()[0], n, "one row index per conditioning future");
        self.forward_encoded(
            self.encode_scene(base),
            base.lane_path.as_ref(),
            rows,
            condition,
        )
    }

    /// [`Self::forward_shared`] from the base rows' scene encoding ([`Self::encode_scene`])
    /// and lane paths, for a caller that encodes them with other rows.
    ///
    /// # Shapes
    /// `scene`: `SceneEncoding` of `[u, ·]`, `lane_path: Option<([u, points, 4], [u, points])>`,
    /// `rows: [n]` (each < u), `condition: [n, T, 3]` `-> GmmOutput` of `[n, ·]`
    pub fn forward_encoded(
        &self,
        scene: SceneEncoding,
        lane_path: Option<&(Tensor<3>, Tensor<2>)>,
        rows: Tensor<1, burn::tensor::Int>,
        condition: Tensor<3>,
    ) -> GmmOutput {
        let [n, _, _] = condition.dims();
        let device = condition.device();
        let scene = scene.select(rows.clone());
        let lane_path = lane_path.map(|(p, m)| {
            (
                p.clone().select(0, rows.clone()),
                m.clone().select(0, rows.clone()),
            )
        });
        let flag = Tensor::ones([n, 1], &device);
        let (embedding, prefixes) =
            self.condition_scene(scene, &condition, lane_path.as_ref(), flag.clone());
        self.decode_with(embedding, prefixes.map(|p| (p, flag)))
    }
}

/// The scene part of the encoder for a batch's rows ([`Multipath::encode_scene`]).
#[derive(Debug, Clone)]
pub struct SceneEncoding {
    /// `[batch, target ‖ interaction ‖ road]`: the scene embedding before conditioning.
    pub scene: Tensor<2>,
    /// `[batch, target width]`: the target's own encoding (the conditioning future's query).
    pub target: Tensor<2>,
}

impl SceneEncoding {
    /// The encodings of `rows` (indices into this encoding's rows), in that order.
    ///
    /// # Shapes
    /// `rows: [n]` `-> SceneEncoding` of `[n, ·]`
    pub fn select(self, rows: burn::tensor::Tensor<1, burn::tensor::Int>) -> Self {
        Self {
            scene: self.scene.select(0, rows.clone()),
            target: self.target.select(0, rows),
        }
    }

    /// The encodings of rows `start..start + len`.
    ///
    /// # Shapes
    /// `-> SceneEncoding` of `[len, ·]`
    pub fn narrow(self, start: usize, len: usize) -> Self {
        Self {
            scene: self.scene.narrow(0, start, len),
            target: self.target.narrow(0, start, len),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch::{Batch, BatchAugment};
    use crate::loss::gmm_nll;
    use burn::optim::{AdamConfig, GradientsParams};
    use rand::SeedableRng;
    use scbg_features::AgentSample;

    use crate::fixtures::{small_features, straight_sample};

    /// The step-wise corrections' last layer starts at zero; these tests need it as after some
    /// training.
    fn with_random_corrections(model: &mut Multipath, device: &Device) {
        let block = model.stepwise.as_mut().expect("a step-wise model");
        let h = block.out.layers[0].weight.dims()[1];
        block.out.layers[1] = LinearConfig::new(h, 5 * CONDITION_STRIDE).init(device);
    }

    /// A cpu-small model with the given conditioning, seeded with `seed`, its step-wise
    /// corrections (when it has them) as after some training.
    fn seeded_model(stepwise: bool, lane_frame: bool, seed: u64, device: &Device) -> Multipath {
        device.seed(seed);
        let mut model = MultipathConfig {
            stepwise_condition: stepwise,
            lane_frame_condition: lane_frame,
            ..MultipathConfig::cpu_small()
        }
        .init(device);
        if stepwise {
            with_random_corrections(&mut model, device);
        }
        model
    }

    #[test]
    fn shapes_param_counts_and_a_learning_step() {
        let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let device = Device::flex().autodiff();
        device.seed(1);
        let config = MultipathConfig::cpu_small();
        let features = small_features();
        let model = config.init(&device);
        let samples = [
            straight_sample(&features, true),
            straight_sample(&features, false),
        ];
        let refs: Vec<&AgentSample> = samples.iter().collect();
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
        let batch = Batch::from_samples(&refs, &BatchAugment::default(), &mut rng, &device);
        let out = model.forward(&batch);
        assert_eq!(out.xy.dims(), [2, 6, 80, 2]);
        assert_eq!(out.cov_abc.dims(), [2, 6, 80, 3]);
        assert_eq!(out.logits.dims(), [2, 6]);
        let loss = gmm_nll(&out, batch.future_xy.clone(), batch.future_valid.clone());
        let before: f32 = loss.clone().into_scalar();
        assert!(before.is_finite());
        let mut optim = AdamConfig::new().init();
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        let model = optim.step(1e-3, model, grads);
        let after: f32 = gmm_nll(
            &model.forward(&batch),
            batch.future_xy.clone(),
            batch.future_valid.clone(),
        )
        .into_scalar();
        assert!(after < before, "{after} !< {before}");
        // The conditional input changes the prediction.
        let diff: f32 = (out.xy.clone().narrow(0, 0, 1) - out.xy.narrow(0, 1, 1))
            .abs()
            .sum()
            .into_scalar();
        assert!(diff > 0.0);
        let small = config.init(&Device::flex()).num_params();
        let paper = MultipathConfig::paper().init(&Device::flex()).num_params();
        eprintln!("parameters: cpu-small {small}, paper {paper}");
        assert!(
            small < paper && paper > 10_000_000,
            "paper preset has {paper} parameters"
        );
    }

    /// Under the step-wise conditioning, changing the other agent's future from step 40 on
    /// changes nothing of the target's prediction before step 45 (the 0.5 s block that starts
    /// at step 45 is the first to see it: B's point at step 44) and leaves the mode
    /// probabilities alone, while it does change the later steps; the fused (CBP) model lets
    /// the same change move every step. Marginal rows are not corrected.
    #[test]
    fn stepwise_conditioning_is_temporally_causal() {
        let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let features = small_features();
        let device = Device::flex();
        let base = straight_sample(&features, true);
        let mut late = base.clone();
        for t in 40..80 {
            late.condition_future_xy_m[2 * t + 1] += 3.0 + 0.2 * (t - 40) as f32;
        }
        let marginal = straight_sample(&features, false);
        let refs = [&base, &late, &marginal];
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
        let batch = Batch::from_samples(&refs, &BatchAugment::default(), &mut rng, &device);
        let max_diff = |out: &GmmOutput, steps: std::ops::Range<usize>| -> f32 {
            let xy = out.xy.clone().narrow(2, steps.start, steps.len());
            let (a, b) = (xy.clone().narrow(0, 0, 1), xy.narrow(0, 1, 1));
            (a - b).abs().max().into_scalar()
        };
        for stepwise in [true, false] {
            device.seed(7);
            let mut model = MultipathConfig {
                stepwise_condition: stepwise,
                ..MultipathConfig::cpu_small()
            }
            .init(&device);
            if stepwise {
                with_random_corrections(&mut model, &device);
            }
            let out = model.forward(&batch);
            let (early, later) = (max_diff(&out, 0..45), max_diff(&out, 45..80));
            let logits = out.logits.clone();
            let logit_diff: f32 = (logits.clone().narrow(0, 0, 1) - logits.narrow(0, 1, 1))
                .abs()
                .max()
                .into_scalar();
            eprintln!(
                "stepwise {stepwise}: early {early:e}, later {later:e}, logits {logit_diff:e}"
            );
            assert!(later > 1e-7, "the late change must reach the late steps");
            if stepwise {
                assert!(early < 1e-7 && logit_diff < 1e-7, "{early} {logit_diff}");
                // The marginal row is the plain decode of the marginal embedding.
                let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
                let alone =
                    Batch::from_samples(&[&marginal], &BatchAugment::default(), &mut rng, &device);
                let plain = model.decode(model.encode(&alone));
                let d: f32 = (plain.xy - out.xy.clone().narrow(0, 2, 1))
                    .abs()
                    .max()
                    .into_scalar();
                assert!(d < 1e-5, "{d}");
            } else {
                assert!(early > 1e-7, "the fused model anticipates: {early}");
            }
        }
    }

    /// The marginal embedding from the scene encoding, without the future encoder, is the
    /// embedding `encode` gives a marginal batch (the zero flag discards that encoder's output),
    /// and `forward_marginal` is `forward` of that batch, to the bit.
    #[test]
    fn marginal_shortcuts_equal_encode_and_forward_of_a_marginal_batch() {
        let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let features = small_features();
        let device = Device::flex();
        let first = straight_sample(&features, true);
        let mut second = first.clone();
        for v in second.target_history.iter_mut().step_by(3) {
            *v += 0.7;
        }
        for (stepwise, lane_frame) in [(false, false), (true, true)] {
            let model = seeded_model(stepwise, lane_frame, 12, &device);
            let batch = Batch::for_mode(&[&first, &second], crate::Mode::Marginal, &device);
            let expected: Vec<f32> = model
                .encode(&batch)
                .into_data()
                .try_to_vec::<f32>()
                .unwrap();
            let got: Vec<f32> = model
                .encode_marginal(model.encode_scene(&batch))
                .into_data()
                .try_to_vec::<f32>()
                .unwrap();
            assert_eq!(got, expected, "stepwise {stepwise}");
            let (full, fast) = (model.forward(&batch), model.forward_marginal(&batch));
            let v = |t: Tensor<4>| -> Vec<f32> { t.into_data().try_to_vec::<f32>().unwrap() };
            assert_eq!(v(fast.xy), v(full.xy), "stepwise {stepwise}");
            assert_eq!(v(fast.cov_abc), v(full.cov_abc));
            let logits = |t: Tensor<2>| -> Vec<f32> { t.into_data().try_to_vec::<f32>().unwrap() };
            assert_eq!(logits(fast.logits), logits(full.logits));
            // A conditional batch's embedding is another one: the test can tell them apart.
            let conditional =
                Batch::for_mode(&[&first, &second], crate::Mode::Conditional, &device);
            let other: Vec<f32> = model
                .encode(&conditional)
                .into_data()
                .try_to_vec::<f32>()
                .unwrap();
            assert_ne!(got, other);
        }
    }

    /// Rows that share their scene give the same prediction through `forward_shared` (the
    /// scene encoded once per target) as through `forward` of the repeated rows, for the fused
    /// and the step-wise model, with and without the lane frame.
    #[test]
    fn forward_shared_matches_forward_of_the_repeated_rows() {
        let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let features = small_features();
        let device = Device::flex();
        let first = straight_sample(&features, true);
        let mut second = first.clone();
        for v in second.target_history.iter_mut().step_by(3) {
            *v += 0.7;
        }
        for k in 0..second.lane_path_xy_m.len() / 2 {
            second.lane_path_xy_m[2 * k + 1] += 1.5;
        }
        let targets = [&first, &second];
        let rows = [1usize, 0, 1, 1, 0];
        // Each row its own future of the other agent.
        let repeated: Vec<AgentSample> = rows
            .iter()
            .enumerate()
            .map(|(r, &t)| {
                let mut s = targets[t].clone();
                for (k, v) in s.condition_future_xy_m.iter_mut().enumerate() {
                    *v += 0.3 * r as f32 * (k % 2) as f32 + 0.01 * (k / 2) as f32 * r as f32;
                }
                s
            })
            .collect();
        let repeated_refs: Vec<&AgentSample> = repeated.iter().collect();
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
        let full = Batch::from_samples(&repeated_refs, &BatchAugment::default(), &mut rng, &device);
        let base = Batch::from_samples(&targets, &BatchAugment::default(), &mut rng, &device);
        let index = Tensor::<1, burn::tensor::Int>::from_data(
            TensorData::new(rows.iter().map(|&r| r as i64).collect(), [rows.len()]),
            &device,
        );
        for (stepwise, lane_frame) in [(false, false), (false, true), (true, false), (true, true)] {
            let model = seeded_model(stepwise, lane_frame, 11, &device);
            let expected = model.forward(&full);
            let shared = model.forward_shared(&base, index.clone(), full.condition.clone());
            let diff = |a: Tensor<4>, b: Tensor<4>| -> f32 { (a - b).abs().max().into_scalar() };
            let (dxy, dcov) = (
                diff(expected.xy.clone(), shared.xy.clone()),
                diff(expected.cov_abc.clone(), shared.cov_abc.clone()),
            );
            let dlogits: f32 = (expected.logits.clone() - shared.logits.clone())
                .abs()
                .max()
                .into_scalar();
            assert!(
                dxy < 1e-4 && dcov < 1e-4 && dlogits < 1e-4,
                "stepwise {stepwise}, lane frame {lane_frame}: {dxy} {dcov} {dlogits}"
            );
            // The rows do differ: the test would notice a row taken from the wrong target.
            let rows_differ: f32 = (expected.xy.clone().narrow(0, 0, 1)
                - expected.xy.clone().narrow(0, 1, 1))
            .abs()
            .max()
            .into_scalar();
            assert!(rows_differ > 1e-3, "{rows_differ}");
        }
    }

    /// The courtesy loss back-propagates through the conditional prediction into B's future:
    /// the step-wise model must pass gradients to every conditioning point but the last
    /// (which no block of A's steps sees).
    #[test]
    fn stepwise_conditioning_passes_gradients_to_the_condition() {
        let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let features = small_features();
        let device = Device::flex().autodiff();
        device.seed(9);
        let mut model = MultipathConfig {
            stepwise_condition: true,
            ..MultipathConfig::cpu_small()
        }
        .init(&device);
        with_random_corrections(&mut model, &device);
        let sample = straight_sample(&features, true);
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
        let batch = Batch::from_samples(&[&sample], &BatchAugment::default(), &mut rng, &device);
        let condition = batch.condition.clone().detach().require_grad();
        let out = model.forward(&batch.with_condition(Some(condition.clone())));
        let grads = out.xy.sum().backward();
        let g = condition.grad(&grads).unwrap(); // [1, 80, 3]
        let per_step: Vec<f32> = g
            .narrow(2, 0, 2)
            .abs()
            .sum_dim(2)
            .reshape([80])
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        // Points at steps 4, 9, …, 74 (and the steps before them, for the velocities) are
        // seen by some block; the last point (step 79, with step 78) by none.
        for t in [3, 4, 8, 9, 73, 74] {
            assert!(per_step[t] > 0.0, "no gradient at step {t}: {per_step:?}");
        }
        assert_eq!(per_step[78] + per_step[79], 0.0, "{per_step:?}");
    }

    /// The conditional mode must be able to use the *content* of y_B: here the target's future
    /// (brake to a stop or keep 1 m/step) is decided only by whether the other agent crosses in
    /// front or stays where it is; histories are identical. After a short training the
    /// conditional mixture must put its weight on the right mode. (Without the direct
    /// embedding → logits head this stayed at 50/50 for 1,500 steps; without the mode
    /// classification term it took about twice as many steps. 600 steps pass for seeds 3, 4, 5.)
    #[test]
    fn conditional_mode_uses_the_content_of_the_condition() {
        conditional_mode_learns_the_oracle(false);
    }

    /// The same with the step-wise (interventional) conditioning: the target's steps react to
    /// where the other agent has been, which here shows from its first point on.
    #[test]
    fn stepwise_conditional_mode_uses_the_content_of_the_condition() {
        conditional_mode_learns_the_oracle(true);
    }

    fn conditional_mode_learns_the_oracle(stepwise: bool) {
        let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let device = Device::flex().autodiff();
        device.seed(3);
        let config = MultipathConfig {
            stepwise_condition: stepwise,
            ..MultipathConfig::cpu_small()
        };
        let features = small_features();
        let f = config.future_steps;
        let samples: Vec<AgentSample> = (0..32usize)
            .map(|i| {
                let mut s = straight_sample(&features, true);
                let crosses = i.is_multiple_of(2);
                // The other agent starts 30 m ahead, 10 m to the left; it either drives across
                // the target's path at 5 m/s or stays where it is.
                s.condition_future_xy_m = (0..f)
                    .flat_map(|t| {
                        let y = if crosses {
                            10.0 - 0.5 * (t + 1) as f32
                        } else {
                            10.0
                        };
                        [30.0, y]
                    })
                    .collect();
                // The target brakes to a stop at 25 m when the other crosses, else keeps 1 m/step.
                s.future_xy_m = (0..f)
                    .flat_map(|t| {
                        let x = (t + 1) as f32;
                        [if crosses { x.min(25.0) } else { x }, 0.0]
                    })
                    .collect();
                s
            })
            .collect();
        let refs: Vec<&AgentSample> = samples.iter().collect();
        let mut model = config.init(&device);
        let mut optim = AdamConfig::new().init();
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
        let train = BatchAugment {
            condition_dropout: 0.5,
            history_mask_prob: 0.0,
        };
        for _ in 0..600 {
            let batch = Batch::from_samples(&refs, &train, &mut rng, &device);
            let out = model.forward(&batch);
            let loss = gmm_nll(&out, batch.future_xy.clone(), batch.future_valid.clone())
                + crate::loss::mode_classification_loss(
                    &out,
                    batch.future_xy.clone(),
                    batch.future_valid.clone(),
                );
            let raw = loss.backward();
            let grads = GradientsParams::from_grads(raw, &model);
            model = optim.step(3e-3, model, grads);
        }
        // Error of the expected final position Σ_k π_k μ_k(T) along the road: the mixture can
        // only get it right when the condition moves the mode probabilities.
        let error = |dropout: f64| -> f32 {
            let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
            let augment = BatchAugment {
                condition_dropout: dropout,
                history_mask_prob: 0.0,
            };
            let batch = Batch::from_samples(&refs, &augment, &mut rng, &device);
            let out = model.forward(&batch);
            let [b, k, t, _] = out.xy.dims();
            let pi = burn::tensor::activation::softmax(out.logits, 1);
            let last_x = out.xy.narrow(2, t - 1, 1).narrow(3, 0, 1).reshape([b, k]);
            let expected: Vec<f32> = (pi * last_x)
                .sum_dim(1)
                .into_data()
                .try_to_vec::<f32>()
                .unwrap();
            let truth = |i: usize| if i.is_multiple_of(2) { 25.0 } else { t as f32 };
            expected
                .iter()
                .enumerate()
                .map(|(i, e)| (e - truth(i)).abs())
                .sum::<f32>()
                / b as f32
        };
        let (conditional, marginal) = (error(0.0), error(1.0));
        eprintln!(
            "oracle: |E[x_T] − x_T| conditional {conditional:.2} m, marginal {marginal:.2} m"
        );
        assert!(
            conditional < 0.5 * marginal,
            "the condition barely moves the prediction: {conditional} vs {marginal} m"
        );
    }
}
