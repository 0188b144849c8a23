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
pub use crate::output::{GmmOutput, Mixture, MixtureMeans};
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
    /// Builds the model on `device` (seed the device first for reproducible weights; the
    /// parameter ids come from their paths, [`crate::param_ids`]).
    pub fn init(&self, device: &Device) -> Multipath {
        crate::param_ids::with_path_ids(self.init_random_ids(device), "multipath")
    }

    fn init_random_ids(&self, device: &Device) -> Multipath {
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

    /// [`Self::decode`] without the covariances ([`MixtureMeans`]).
    ///
    /// # Shapes
    /// `embedding: [batch, e]` `-> MixtureMeans` (`xy: [batch, K, T, 2]`, `logits: [batch, K]`)
    pub fn decode_means(&self, embedding: Tensor<2>) -> MixtureMeans {
        self.decode_parts(embedding, None, false).means()
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
        self.decode_parts(embedding, stepwise, true).gmm()
    }

    /// [`Self::decode_with`]: the means, the covariances when `covariances` (else `None`,
    /// their products skipped) and the mode logits.
    fn decode_parts(
        &self,
        embedding: Tensor<2>,
        stepwise: Option<(Tensor<3>, Tensor<2>)>,
        covariances: bool,
    ) -> Decoded {
        // The anchors are the same for every row: the MCG runs their context-free part once.
        let (modes, _) = self
            .decoder_mcg
            .forward_shared(self.anchors.val(), embedding.clone());
        let [b, k, _] = modes.dims();
        let modes = relu(modes);
        let t = self.future_steps;
        // Per mode: 2T displacements, 3T covariance parameters, one logit.
        let (mut dxy, mut cov_abc, logit) = if covariances {
            let out = self.decoder_mlp.forward(modes.clone()); // [b, k, 5T + 1]
            (
                out.clone().narrow(2, 0, 2 * t).reshape([b, k, t, 2]),
                Some(out.clone().narrow(2, 2 * t, 3 * t).reshape([b, k, t, 3])),
                out.narrow(2, 5 * t, 1),
            )
        } else {
            let out = self
                .decoder_mlp
                .forward_columns(modes.clone(), &[0..2 * t, 5 * t..5 * t + 1]);
            (
                out.clone().narrow(2, 0, 2 * t).reshape([b, k, t, 2]),
                None,
                out.narrow(2, 2 * t, 1),
            )
        };
        if let (Some(block), Some((prefixes, flag))) = (&self.stepwise, stepwise) {
            let (d, c) = block.forward(modes, prefixes, flag, covariances);
            dxy = dxy + d;
            cov_abc = cov_abc.zip(c).map(|(a, c)| a + c);
        }
        // Per-step displacements, integrated: positions are their cumulative sum (paper-era
        // Multipath++ re-implementations predict positions directly; integrating makes smooth,
        // constant-speed futures the easy solution and keeps early training errors small).
        let xy = dxy.cumsum(2);
        let logits = logit.reshape([b, k]) + self.mode_logits.forward(embedding);
        Decoded {
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

    /// [`Self::forward`] without the covariances ([`MixtureMeans`]): the same means and
    /// logits, the covariance outputs not computed. Marginal rows of a
    /// [`crate::Mode::Marginal`] batch may take [`Self::forward_marginal_means`] instead.
    ///
    /// # Shapes
    /// batch tensors `-> MixtureMeans` (`xy: [batch, K, T, 2]`, `logits: [batch, K]`)
    pub fn forward_means(&self, batch: &Batch) -> MixtureMeans {
        let (embedding, prefixes) = self.encode_with_prefixes(batch);
        let stepwise = prefixes.map(|p| (p, batch.condition_flag.clone()));
        self.decode_parts(embedding, stepwise, false).means()
    }

    /// [`Self::forward_marginal`] without the covariances ([`MixtureMeans`]).
    ///
    /// # Shapes
    /// batch tensors `-> MixtureMeans`
    pub fn forward_marginal_means(&self, batch: &Batch) -> MixtureMeans {
        self.decode_means(self.encode_marginal(self.encode_scene(batch)))
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
        self.decode_encoded(scene, lane_path, rows, condition, true)
            .gmm()
    }

    /// [`Self::forward_encoded`] without the covariances ([`MixtureMeans`]): J_φ's
    /// expectation over many futures of B needs only the means and the logits.
    ///
    /// # Shapes
    /// As [`Self::forward_encoded`] `-> MixtureMeans` of `[n, ·]`
    pub fn forward_encoded_means(
        &self,
        scene: SceneEncoding,
        lane_path: Option<&(Tensor<3>, Tensor<2>)>,
        rows: Tensor<1, burn::tensor::Int>,
        condition: Tensor<3>,
    ) -> MixtureMeans {
        self.decode_encoded(scene, lane_path, rows, condition, false)
            .means()
    }

    /// [`Self::forward_encoded`]'s parts ([`Self::decode_parts`]).
    fn decode_encoded(
        &self,
        scene: SceneEncoding,
        lane_path: Option<&(Tensor<3>, Tensor<2>)>,
        rows: Tensor<1, burn::tensor::Int>,
        condition: Tensor<3>,
        covariances: bool,
    ) -> Decoded {
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
        self.decode_parts(embedding, prefixes.map(|p| (p, flag)), covariances)
    }
}

/// What [`Multipath::decode_parts`] computes: the covariances only when asked for.
struct Decoded {
    xy: Tensor<4>,
    cov_abc: Option<Tensor<4>>,
    logits: Tensor<2>,
}

impl Decoded {
    /// The whole mixture (decoded with its covariances).
    fn gmm(self) -> GmmOutput {
        GmmOutput {
            xy: self.xy,
            cov_abc: self.cov_abc.expect("decoded without the covariances"),
            logits: self.logits,
        }
    }

    /// The means and logits.
    fn means(self) -> MixtureMeans {
        MixtureMeans {
            xy: self.xy,
            logits: self.logits,
        }
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
mod tests;
