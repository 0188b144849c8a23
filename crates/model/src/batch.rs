//! Turning [`AgentSample`]s into batch tensors.

use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use scbg_features::{AGENT_FEATURES, AgentSample, DIFF_FEATURES, ROAD_FEATURES};

/// A batch of samples as tensors (inputs already standardised by `FeatureStats`).
#[derive(Debug, Clone)]
pub struct Batch {
    /// `[batch, steps, 13]`
    pub target_history: Tensor<3>,
    /// `[batch, steps - 1, 11]`
    pub target_diffs: Tensor<3>,
    /// `[batch, agents, steps, 13]` (agents: up to the last slot any sample fills)
    pub others_history: Tensor<4>,
    /// `[batch, agents, steps - 1, 11]`
    pub others_diffs: Tensor<4>,
    /// `[batch, agents]`, 1 for a real agent.
    pub others_mask: Tensor<2>,
    /// `[batch, segments, 27]` (segments: up to the last slot any sample fills)
    pub road: Tensor<3>,
    /// `[batch, segments]`
    pub road_mask: Tensor<2>,
    /// `[batch, future_steps, 3]`: the other agent's future (x, y, valid) in the target frame.
    pub condition: Tensor<3>,
    /// `[batch, 1]`: 1 = conditional mode, 0 = marginal.
    pub condition_flag: Tensor<2>,
    /// `[batch]`: `condition_flag` on the host (true = conditional), for per-sample work
    /// outside the graph without reading the tensor back from the device.
    pub condition_kept: Vec<bool>,
    /// `[batch, future_steps, 2]`
    pub future_xy: Tensor<3>,
    /// `[batch, future_steps]`
    pub future_valid: Tensor<2>,
    /// The targets' lane paths when the samples have them (`FeatureConfig::lane_path`):
    /// `[batch, lane points, 4]` (x, y, unit tangent; target frame) and `[batch, lane points]`
    /// (1 for a point on a known lane).
    pub lane_path: Option<(Tensor<3>, Tensor<2>)>,
}

/// Inference mode of the predictor: the one way to ask for either distribution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Mode {
    /// `p(y_A | x)`: the condition is switched off.
    Marginal,
    /// `p(y_A | x, y_B)`: the other agent's logged future is given (samples without one are
    /// necessarily marginal).
    Conditional,
}

/// Training-time randomisation applied while batching.
#[derive(Debug, Clone, Copy, Default)]
pub struct BatchAugment {
    /// Probability of dropping a sample's condition (training both modes with one model).
    pub condition_dropout: f64,
    /// Probability of masking each history step of the target (Multipath++ uses 0.15).
    pub history_mask_prob: f64,
}

fn bools(v: &[bool]) -> impl Iterator<Item = f32> + '_ {
    v.iter().map(|&b| f32::from(u8::from(b)))
}

/// Appends `s`'s lane path as `[points, 4]` rows: x, y and the unit tangent toward the next
/// valid point (from the previous one at the end; zero for an isolated or invalid point).
fn push_lane_path(s: &AgentSample, out: &mut Vec<f32>) {
    let (xy, valid) = (&s.lane_path_xy_m, &s.lane_path_valid);
    let n = valid.len();
    let p = |k: usize| [xy[2 * k], xy[2 * k + 1]];
    for k in 0..n {
        let [x, y] = p(k);
        let dir = if !valid[k] {
            None
        } else if k + 1 < n && valid[k + 1] {
            Some((p(k), p(k + 1)))
        } else if k > 0 && valid[k - 1] {
            Some((p(k - 1), p(k)))
        } else {
            None
        };
        let t = dir
            .map(|(a, b)| [b[0] - a[0], b[1] - a[1]])
            .map(|d| {
                let len = (d[0] * d[0] + d[1] * d[1]).sqrt();
                if len > 1e-6 {
                    [d[0] / len, d[1] / len]
                } else {
                    [0.0, 0.0]
                }
            })
            .unwrap_or([0.0, 0.0]);
        out.extend([x, y, t[0], t[1]]);
    }
}

impl Batch {
    /// Stacks samples. Condition dropout and history masking draw from `rng`, so a seeded
    /// generator gives reproducible batches. The current step (last history row) is never
    /// masked.
    pub fn from_samples(
        samples: &[&AgentSample],
        augment: &BatchAugment,
        rng: &mut impl Rng,
        device: &Device,
    ) -> Self {
        let b = samples.len();
        assert!(b > 0, "empty batch");
        let s0 = samples[0];
        let steps = s0.target_history.len() / AGENT_FEATURES;
        // Trailing agent and road-segment slots that no sample of the batch fills are left
        // out: every operation over them is masked (per-agent encoders, masked gating and
        // max-pooling), so they change nothing but the cost — a synthetic scene fills 1–4 of
        // the 16 agent slots. At least one slot stays (all masked when none is valid).
        let used = |valid: fn(&AgentSample) -> &[bool]| {
            samples
                .iter()
                .map(|s| valid(s).iter().rposition(|&v| v).map_or(0, |i| i + 1))
                .max()
                .unwrap_or(0)
                .max(1)
                .min(valid(s0).len())
        };
        let agents = used(|s| &s.others_valid);
        let segments = used(|s| &s.road_valid);
        let future = s0.future_valid.len();
        let mut th = Vec::with_capacity(b * steps * AGENT_FEATURES);
        let mut td = Vec::with_capacity(b * (steps - 1) * DIFF_FEATURES);
        let (mut oh, mut od, mut om) = (Vec::new(), Vec::new(), Vec::new());
        let (mut road, mut rm) = (Vec::new(), Vec::new());
        let (mut cond, mut kept) = (Vec::with_capacity(b * future * 3), Vec::with_capacity(b));
        let (mut fxy, mut fv) = (
            Vec::with_capacity(b * future * 2),
            Vec::with_capacity(b * future),
        );
        let lane_points = s0.lane_path_valid.len();
        let with_lanes = lane_points > 0;
        let (mut lane, mut lm) = (
            Vec::with_capacity(b * lane_points * 4),
            Vec::with_capacity(b * lane_points),
        );
        for s in samples {
            if with_lanes {
                push_lane_path(s, &mut lane);
                lm.extend(bools(&s.lane_path_valid));
            }
            let mut hist = s.target_history.clone();
            let mut diffs = s.target_diffs.clone();
            if augment.history_mask_prob > 0.0 {
                for h in 0..steps - 1 {
                    if rng.random_bool(augment.history_mask_prob) {
                        hist[h * AGENT_FEATURES..(h + 1) * AGENT_FEATURES].fill(0.0);
                        diffs[h * DIFF_FEATURES..(h + 1) * DIFF_FEATURES].fill(0.0);
                        if h > 0 {
                            diffs[(h - 1) * DIFF_FEATURES..h * DIFF_FEATURES].fill(0.0);
                        }
                    }
                }
            }
            th.extend(hist);
            td.extend(diffs);
            oh.extend_from_slice(&s.others_history[..agents * steps * AGENT_FEATURES]);
            od.extend_from_slice(&s.others_diffs[..agents * (steps - 1) * DIFF_FEATURES]);
            om.extend(bools(&s.others_valid[..agents]));
            road.extend_from_slice(&s.road_segments[..segments * ROAD_FEATURES]);
            rm.extend(bools(&s.road_valid[..segments]));
            let keep = s.has_condition()
                && (s.condition_required
                    || !(augment.condition_dropout > 0.0
                        && rng.random_bool(augment.condition_dropout)));
            for f in 0..future {
                let v = keep && s.condition_future_valid[f];
                cond.push(if v {
                    s.condition_future_xy_m[2 * f]
                } else {
                    0.0
                });
                cond.push(if v {
                    s.condition_future_xy_m[2 * f + 1]
                } else {
                    0.0
                });
                cond.push(f32::from(u8::from(v)));
            }
            kept.push(keep);
            fxy.extend_from_slice(&s.future_xy_m);
            fv.extend(bools(&s.future_valid));
        }
        let t3 = |v: Vec<f32>, s: [usize; 3]| Tensor::<3>::from_data(TensorData::new(v, s), device);
        let t2 = |v: Vec<f32>, s: [usize; 2]| Tensor::<2>::from_data(TensorData::new(v, s), device);
        let t4 = |v: Vec<f32>, s: [usize; 4]| Tensor::<4>::from_data(TensorData::new(v, s), device);
        Self {
            target_history: t3(th, [b, steps, AGENT_FEATURES]),
            target_diffs: t3(td, [b, steps - 1, DIFF_FEATURES]),
            others_history: t4(oh, [b, agents, steps, AGENT_FEATURES]),
            others_diffs: t4(od, [b, agents, steps - 1, DIFF_FEATURES]),
            others_mask: t2(om, [b, agents]),
            road: t3(road, [b, segments, ROAD_FEATURES]),
            road_mask: t2(rm, [b, segments]),
            condition: t3(cond, [b, future, 3]),
            condition_flag: t2(bools(&kept).collect(), [b, 1]),
            condition_kept: kept,
            future_xy: t3(fxy, [b, future, 2]),
            future_valid: t2(fv, [b, future]),
            lane_path: with_lanes
                .then(|| (t3(lane, [b, lane_points, 4]), t2(lm, [b, lane_points]))),
        }
    }

    /// Stacks samples for inference in `mode`, without training-time randomisation.
    pub fn for_mode(samples: &[&AgentSample], mode: Mode, device: &Device) -> Self {
        // Nothing is drawn with the default augmentation: the generator is a placeholder.
        let mut rng = rand_pcg::Pcg64Mcg::new(0);
        let batch = Self::from_samples(samples, &BatchAugment::default(), &mut rng, device);
        match mode {
            Mode::Marginal => batch.with_condition(None),
            Mode::Conditional => batch,
        }
    }

    /// The same batch with another condition: `Some(c)` = conditional on `c` (target frame:
    /// x m, y m, valid), `None` = marginal (condition and flag zero).
    ///
    /// # Shapes
    /// `condition: Option<[batch, future_steps, 3]>`
    pub fn with_condition(mut self, condition: Option<Tensor<3>>) -> Self {
        let [n, _, _] = self.condition.dims();
        let device = self.condition.device();
        match condition {
            Some(c) => {
                self.condition = c;
                self.condition_flag = Tensor::ones([n, 1], &device);
                self.condition_kept = vec![true; n];
            }
            None => {
                self.condition = self.condition.zeros_like();
                self.condition_flag = Tensor::zeros([n, 1], &device);
                self.condition_kept = vec![false; n];
            }
        }
        self
    }

    /// The batch `times` times over, block after block: row `k · batch + i` is sample `i`.
    pub fn repeat(&self, times: usize) -> Self {
        fn rep<const D: usize>(t: &Tensor<D>, times: usize) -> Tensor<D> {
            if times == 1 {
                t.clone()
            } else {
                Tensor::cat(vec![t.clone(); times], 0)
            }
        }
        Self {
            target_history: rep(&self.target_history, times),
            target_diffs: rep(&self.target_diffs, times),
            others_history: rep(&self.others_history, times),
            others_diffs: rep(&self.others_diffs, times),
            others_mask: rep(&self.others_mask, times),
            road: rep(&self.road, times),
            road_mask: rep(&self.road_mask, times),
            condition: rep(&self.condition, times),
            condition_flag: rep(&self.condition_flag, times),
            condition_kept: self.condition_kept.repeat(times),
            future_xy: rep(&self.future_xy, times),
            future_valid: rep(&self.future_valid, times),
            lane_path: self
                .lane_path
                .as_ref()
                .map(|(p, m)| (rep(p, times), rep(m, times))),
        }
    }
}
