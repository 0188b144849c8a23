//! The Multipath++ model: encoders, the conditional future encoder and the anchor decoder.

use burn::module::{Module, Param};
use burn::nn::{Initializer, Linear, LinearConfig, Lstm, LstmConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};
use scbg_features::{AGENT_FEATURES, DIFF_FEATURES, ROAD_FEATURES};

use crate::batch::Batch;
use crate::blocks::{Mcg, Mlp};
use crate::config::MultipathConfig;

/// Scale (metres) dividing the conditioning future's coordinates before the future encoder.
pub const CONDITION_SCALE_M: f32 = 50.0;

/// Encodes agent histories: LSTM over step features ‖ LSTM over step differences ‖ MCG over
/// per-step MLP embeddings (features + one-hot time step).
#[derive(Module, Debug)]
pub struct HistoryEncoder {
    pub lstm_steps: Lstm,
    pub lstm_diffs: Lstm,
    pub step_mlp: Mlp,
    pub step_mcg: Mcg,
    pub history_steps: usize,
}

impl HistoryEncoder {
    pub fn init(config: &MultipathConfig, device: &Device) -> Self {
        let h = config.history_steps;
        let mut dims = vec![AGENT_FEATURES + h];
        dims.extend(&config.step_mlp);
        let w = config.history_width();
        Self {
            lstm_steps: LstmConfig::new(AGENT_FEATURES, config.lstm_hidden, true).init(device),
            lstm_diffs: LstmConfig::new(DIFF_FEATURES, config.lstm_hidden, true).init(device),
            step_mlp: Mlp::init(&dims, device),
            step_mcg: Mcg::init(w, 1, w, config.mcg_blocks, device),
            history_steps: h,
        }
    }

    /// # Shapes
    /// `history: [n, steps, 13]`, `diffs: [n, steps - 1, 11]` `-> [n, 2·lstm_hidden + history_width]`
    pub fn forward(&self, history: Tensor<3>, diffs: Tensor<3>) -> Tensor<2> {
        let [n, steps, _] = history.dims();
        let device = history.device();
        let (_, state_steps) = self.lstm_steps.forward(history.clone(), None);
        let (_, state_diffs) = self.lstm_diffs.forward(diffs, None);
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
        Tensor::cat(vec![state_steps.hidden, state_diffs.hidden, summary], 1)
    }
}

/// Points of the conditioning future kept by the future encoder: every 5th step (2 Hz).
pub const CONDITION_STRIDE: usize = 5;

/// Encodes the other agent's future (CBP-style): its points at 2 Hz — x, y (scaled), validity
/// and time — through a per-point MLP and an MCG whose context is the target embedding, so the
/// encoding is about the future *relative to this target*; max-pooled over valid points.
#[derive(Module, Debug)]
pub struct FutureEncoder {
    pub point_mlp: Mlp,
    pub mcg: Mcg,
}

impl FutureEncoder {
    pub fn init(config: &MultipathConfig, device: &Device) -> Self {
        let h = config.future_hidden;
        Self {
            point_mlp: Mlp::init(&[4, h, h], device),
            mcg: Mcg::init(h, config.target_width, h, config.mcg_blocks, device),
        }
    }

    /// # Shapes
    /// `condition: [batch, T, 3]` (x m, y m, valid), `target: [batch, target_width]`
    /// `-> [batch, future_hidden]` (zeros when no point is valid)
    pub fn forward(&self, condition: &Tensor<3>, target: Tensor<2>, b: usize) -> Tensor<2> {
        let device = condition.device();
        let [_, t, _] = condition.dims();
        let n = t / CONDITION_STRIDE;
        let idx: Vec<i64> = (0..n)
            .map(|i| ((i + 1) * CONDITION_STRIDE - 1) as i64)
            .collect();
        let pts = condition.clone().select(
            1,
            Tensor::<1, burn::tensor::Int>::from_data(TensorData::new(idx, [n]), &device),
        );
        let scale = Tensor::<1>::from_data(
            TensorData::new(
                vec![1.0 / CONDITION_SCALE_M, 1.0 / CONDITION_SCALE_M, 1.0],
                [3],
            ),
            &device,
        );
        let pts = pts * scale.reshape([1, 1, 3]);
        let time: Vec<f32> = (0..n).map(|i| (i + 1) as f32 / n as f32).collect();
        let time = Tensor::<1>::from_data(TensorData::new(time, [n]), &device)
            .reshape([1, n, 1])
            .expand([b, n, 1]);
        let valid = pts.clone().narrow(2, 2, 1).reshape([b, n]);
        let feats = self.point_mlp.forward(Tensor::cat(vec![pts, time], 2));
        let (_, pooled) = self.mcg.forward(feats, target, valid);
        pooled
    }
}

/// Output of the model: a Gaussian mixture over future trajectories in the target frame.
#[derive(Debug, Clone)]
pub struct GmmOutput {
    /// `[batch, modes, future_steps, 2]` positions in the target frame (metres).
    pub xy: Tensor<4>,
    /// `[batch, modes, future_steps, 3]`: (a, b, c) of Σ = e^c·[[e^a·cosh b, sinh b], [sinh b, e^−a·cosh b]].
    pub cov_abc: Tensor<4>,
    /// `[batch, modes]` unnormalised mode logits.
    pub logits: Tensor<2>,
}

/// One agent's predicted mixture as plain arrays (for evaluation, labelling, serving).
#[derive(Debug, Clone, PartialEq)]
pub struct Mixture {
    /// `[K][T]` mean positions (target frame, metres).
    pub xy: Vec<Vec<[f32; 2]>>,
    /// `[K][T]` covariance parameters (a, b, c), clamped to the ranges the loss uses.
    pub abc: Vec<Vec<[f32; 3]>>,
    /// `[K]` mode probabilities (softmax of the logits).
    pub probs: Vec<f32>,
}

impl GmmOutput {
    /// Reads the batch back into one [`Mixture`] per target.
    pub fn into_mixtures(self) -> Vec<Mixture> {
        use crate::loss::{COV_A_RANGE, COV_B_RANGE, COV_C_RANGE};
        let [b, k, t, _] = self.xy.dims();
        let xy: Vec<f32> = self.xy.into_data().try_to_vec::<f32>().expect("f32 tensor");
        let abc: Vec<f32> = self
            .cov_abc
            .into_data()
            .try_to_vec::<f32>()
            .expect("f32 tensor");
        let probs: Vec<f32> = burn::tensor::activation::softmax(self.logits, 1)
            .into_data()
            .try_to_vec::<f32>()
            .expect("f32 tensor");
        (0..b)
            .map(|i| Mixture {
                xy: (0..k)
                    .map(|m| {
                        (0..t)
                            .map(|s| {
                                let o = ((i * k + m) * t + s) * 2;
                                [xy[o], xy[o + 1]]
                            })
                            .collect()
                    })
                    .collect(),
                abc: (0..k)
                    .map(|m| {
                        (0..t)
                            .map(|s| {
                                let o = ((i * k + m) * t + s) * 3;
                                [
                                    abc[o].clamp(COV_A_RANGE.0, COV_A_RANGE.1),
                                    abc[o + 1].clamp(COV_B_RANGE.0, COV_B_RANGE.1),
                                    abc[o + 2].clamp(COV_C_RANGE.0, COV_C_RANGE.1),
                                ]
                            })
                            .collect()
                    })
                    .collect(),
                probs: probs[i * k..(i + 1) * k].to_vec(),
            })
            .collect()
    }
}

/// Multipath++ with a conditional future encoder (marginal when the condition flag is 0).
#[derive(Module, Debug)]
pub struct Multipath {
    pub history: HistoryEncoder,
    pub target_mcg: Mcg,
    pub interaction_mcg: Mcg,
    pub road_mlp: Mlp,
    pub road_context: Mlp,
    pub road_mcg: Mcg,
    pub future_encoder: FutureEncoder,
    /// Fuses `[scene ‖ condition·flag ‖ flag]` back to the embedding width (added to the scene).
    pub fuse: Linear,
    pub anchors: Param<Tensor<2>>,
    pub decoder_mcg: Mcg,
    pub decoder_mlp: Mlp,
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
            anchors: Initializer::Normal {
                mean: 0.0,
                std: 1.0,
            }
            .init([self.num_modes, e], device),
            decoder_mcg: Mcg::init(e, e, self.decoder_width, self.mcg_blocks, device),
            decoder_mlp: Mlp::init(
                &[self.decoder_width, self.decoder_hidden, self.mode_outputs()],
                device,
            ),
            future_steps: self.future_steps,
        }
    }
}

impl Multipath {
    /// The scene embedding, fused with the conditioning future where `condition_flag` is 1.
    ///
    /// # Shapes
    /// batch tensors (see [`Batch`]) `-> [batch, embedding_width]`
    pub fn encode(&self, batch: &Batch) -> Tensor<2> {
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
        let target_for_condition = target.clone();
        let scene = Tensor::cat(vec![target, interaction, road], 1);
        let condition = self
            .future_encoder
            .forward(&batch.condition, target_for_condition, b);
        let flag = batch.condition_flag.clone();
        let fused = Tensor::cat(vec![scene.clone(), condition * flag.clone(), flag], 1);
        scene + self.fuse.forward(fused)
    }

    /// Decodes K trajectories from an embedding.
    ///
    /// # Shapes
    /// `embedding: [batch, e]` `-> GmmOutput { xy: [batch, K, T, 2], cov_abc: [batch, K, T, 3], logits: [batch, K] }`
    pub fn decode(&self, embedding: Tensor<2>) -> GmmOutput {
        let [b, e] = embedding.dims();
        let device = embedding.device();
        let [k, _] = self.anchors.dims();
        let anchors = self.anchors.val().reshape([1, k, e]).expand([b, k, e]);
        let (modes, _) =
            self.decoder_mcg
                .forward(anchors, embedding, Tensor::ones([b, k], &device));
        let out = self.decoder_mlp.forward(relu(modes)); // [b, k, 5T + 1]
        let t = self.future_steps;
        // Per-step displacements, integrated: positions are their cumulative sum (paper-era
        // Multipath++ re-implementations predict positions directly; integrating makes smooth,
        // constant-speed futures the easy solution and keeps early training errors small).
        let xy = out
            .clone()
            .narrow(2, 0, 2 * t)
            .reshape([b, k, t, 2])
            .cumsum(2);
        let cov_abc = out.clone().narrow(2, 2 * t, 3 * t).reshape([b, k, t, 3]);
        let logits = out.narrow(2, 5 * t, 1).reshape([b, k]);
        GmmOutput {
            xy,
            cov_abc,
            logits,
        }
    }

    /// # Shapes
    /// batch tensors (see [`Batch`]) `-> GmmOutput`
    pub fn forward(&self, batch: &Batch) -> GmmOutput {
        self.decode(self.encode(batch))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::batch::{Batch, BatchAugment};
    use crate::loss::gmm_nll;
    use burn::optim::{AdamConfig, GradientsParams};
    use rand::SeedableRng;
    use scbg_features::{AgentSample, FeatureConfig, Window};

    /// A sample of a target driving straight at 10 m/s (features as `scbg-features` makes them).
    pub(crate) fn straight_sample(cfg: &FeatureConfig, with_condition: bool) -> AgentSample {
        let h = cfg.history_steps;
        let mut target_history = vec![0.0; h * AGENT_FEATURES];
        for s in 0..h {
            let row = &mut target_history[s * AGENT_FEATURES..(s + 1) * AGENT_FEATURES];
            row[0] = (s as f32 - (h - 1) as f32) * 1.0;
            row[3] = 10.0;
            row[6] = 1.0;
            row[8] = 1.0;
        }
        let mut target_diffs = vec![0.0; (h - 1) * DIFF_FEATURES];
        for s in 0..h - 1 {
            target_diffs[s * DIFF_FEATURES] = 1.0;
            target_diffs[s * DIFF_FEATURES + 4] = 1.0;
        }
        let f = cfg.future_steps;
        AgentSample {
            scenario_id: "t".into(),
            window: Window {
                current_step: h - 1,
            },
            target_track_id: 1,
            condition_track_id: with_condition.then_some(2),
            world_from_agent: scbg_scene::Pose2::default(),
            target_history,
            target_diffs,
            others_history: vec![0.0; cfg.max_other_agents * h * AGENT_FEATURES],
            others_diffs: vec![0.0; cfg.max_other_agents * (h - 1) * DIFF_FEATURES],
            others_valid: vec![false; cfg.max_other_agents],
            road_segments: vec![0.1; cfg.max_road_segments * ROAD_FEATURES],
            road_valid: vec![true; cfg.max_road_segments],
            condition_future_xy_m: (0..f).flat_map(|i| [i as f32, 3.5]).collect(),
            condition_future_valid: vec![with_condition; f],
            future_xy_m: (0..f).flat_map(|i| [(i + 1) as f32, 0.0]).collect(),
            future_heading_rad: vec![0.0; f],
            future_valid: vec![true; f],
            current_velocity_mps: [10.0, 0.0],
        }
    }

    #[test]
    fn shapes_param_counts_and_a_learning_step() {
        let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let device = Device::flex().autodiff();
        device.seed(1);
        let config = MultipathConfig::cpu_small();
        let features = FeatureConfig {
            max_other_agents: 4,
            max_road_segments: 8,
            ..Default::default()
        };
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
}
