//! How the other agent's future enters the model (the conditional mode): the future encoder —
//! B's points at 2 Hz in the target's frame and, as an option, in its lane frame — and the
//! step-wise (interventional) corrections of the decoder.

use burn::module::Module;
use burn::nn::{Initializer, Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};

#[cfg(doc)]
use crate::batch::Batch;
use crate::blocks::{Mlp, on_rows};
use crate::config::MultipathConfig;

/// Scale (metres) dividing the conditioning future's coordinates before the future encoder.
pub const CONDITION_SCALE_M: f32 = 50.0;
/// Velocities of the conditioning future are divided by this (m/s).
pub const CONDITION_SCALE_MPS: f32 = 10.0;
/// Time between steps of the conditioning future (10 Hz).
const CONDITION_STEP_SECS: f32 = 0.1;
/// Per point: x, y, valid, vx, vy.
const CONDITION_POINT_FEATURES: usize = 5;
/// Per point in the target's lane frame: arc length along the lane path, offset from it, and
/// whether the point has a lane (see [`FutureEncoder`]).
const LANE_POINT_FEATURES: usize = 3;
/// Scale (metres) dividing the conditioning future's offset from the target's lane path
/// (a lane width is about 3.5 m).
pub const LANE_OFFSET_SCALE_M: f32 = 5.0;
/// The scaled lane offset is clamped to ±this (far from the lane, the offset no longer matters).
const LANE_OFFSET_CLAMP: f32 = 4.0;

/// Points of the conditioning future kept by the future encoder: every 5th step (2 Hz).
pub const CONDITION_STRIDE: usize = 5;

/// Encodes the other agent's future (CBP-style): its points at 2 Hz — x, y (scaled), validity
/// and velocity (from the 10 Hz step before) — flattened in time order and passed with the
/// target embedding through an MLP, so the encoding is about the future *relative to this
/// target*.
///
/// With `lane_frame_condition` (an option, off in the presets; checkpoints from before it load
/// without), each point also carries its place in the target's *lane frame*: its arc length along the
/// target's lane path (`scbg_features::lane_path`) and its signed offset from it, from the
/// nearest path point and its tangent. On a curved road the target frame cannot tell whether the other agent
/// 150 m ahead drives in the target's lane or the next (a 1/1000 m curvature moves the lane
/// by 11 m there, three lane widths); the lane frame can, and that is what decides whether
/// the target is held up. The nearest point is chosen without gradient; the arc length and
/// offset are linear in the point, so gradients reach the conditioning future (the courtesy
/// loss goes through them).
///
/// Design note: an earlier version treated the points as a set (per-point MLP → MCG →
/// max-pool, like the road encoder). Its output barely depended on the points (0.2 % at
/// initialisation) and training never made the mixture depend on them — the oracle test below
/// failed. An ordered, flattened encoding keeps *when* B is *where*, which is what decides
/// whether A has to yield.
#[derive(Module, Debug)]
pub struct FutureEncoder {
    /// MLP of `[flattened points ‖ target embedding]` (`16·5 + target_width → future_hidden`
    /// for 80 future steps; `16·8 + …` in the lane frame).
    pub mlp: Mlp,
    /// Features per point: 5, or 8 with the lane frame.
    pub point_features: usize,
}

impl FutureEncoder {
    /// Builds the encoder for `config`'s widths (`future_steps / CONDITION_STRIDE` points).
    pub fn init(config: &MultipathConfig, device: &Device) -> Self {
        let h = config.future_hidden;
        let points = config.future_steps / CONDITION_STRIDE;
        let point_features = CONDITION_POINT_FEATURES
            + if config.lane_frame_condition {
                LANE_POINT_FEATURES
            } else {
                0
            };
        Self {
            point_features,
            mlp: Mlp::init(
                &[points * point_features + config.target_width, h, h, h],
                device,
            ),
        }
    }

    /// The per-point features of the conditioning future (2 Hz): position (scaled), validity
    /// and velocity, and in the lane frame the point's place along the target's lane path.
    ///
    /// # Shapes
    /// `condition: [batch, T, 3]` (x m, y m, valid), `lane_path: Option<([batch, L, 4],
    /// [batch, L])>` (x m, y m, unit tangent; mask — [`Batch::lane_path`], needed in the lane
    /// frame) `-> [batch, T / CONDITION_STRIDE, point_features]`
    pub fn point_features(
        &self,
        condition: &Tensor<3>,
        lane_path: Option<&(Tensor<3>, Tensor<2>)>,
    ) -> Tensor<3> {
        let device = condition.device();
        let [_, t, _] = condition.dims();
        let n = t / CONDITION_STRIDE;
        let select = |offset: usize| {
            let idx: Vec<i64> = (0..n)
                .map(|i| ((i + 1) * CONDITION_STRIDE - 1 - offset) as i64)
                .collect();
            condition.clone().select(
                1,
                Tensor::<1, burn::tensor::Int>::from_data(TensorData::new(idx, [n]), &device),
            )
        };
        let (pts, prev) = (select(0), select(1));
        // Velocity at each kept point from the step before it (10 Hz), where both are valid:
        // whether B is stopped, yielding or pressing on is in its speed more than in its place.
        let valid = pts.clone().narrow(2, 2, 1);
        let both = valid.clone() * prev.clone().narrow(2, 2, 1);
        let velocity = (pts.clone().narrow(2, 0, 2) - prev.narrow(2, 0, 2))
            * (both / (CONDITION_STEP_SECS * CONDITION_SCALE_MPS));
        let xy = pts.narrow(2, 0, 2);
        let mut parts = vec![xy.clone() / CONDITION_SCALE_M, valid.clone(), velocity];
        if self.point_features > CONDITION_POINT_FEATURES {
            let (path, mask) = lane_path.expect(
                "a model in the lane frame needs samples with lane paths \
                 (FeatureConfig::lane_path, set by TrainConfig::feature_config)",
            );
            parts.push(lane_frame(xy, valid, path, mask));
        }
        Tensor::cat(parts, 2)
    }

    /// Encodes the conditioning future of each target in the target's frame, together with that target's embedding. Invalid points enter as
    /// zeros with their validity flag; velocities are zero unless both points are valid.
    ///
    /// # Shapes
    /// as [`Self::point_features`], `target: [batch, target_width]` `-> [batch, future_hidden]`
    pub fn forward(
        &self,
        condition: &Tensor<3>,
        lane_path: Option<&(Tensor<3>, Tensor<2>)>,
        target: Tensor<2>,
    ) -> Tensor<2> {
        let feats = self.point_features(condition, lane_path);
        let [b, n, f] = feats.dims();
        self.mlp
            .forward(Tensor::cat(vec![feats.reshape([b, n * f]), target], 1))
    }

    /// The encodings of every *prefix* of the conditioning future: entry `m` sees only the
    /// first `m` points (2 Hz), the later ones entering as zeros (as invalid points do), so
    /// nothing in it depends on where the other agent is after point `m` (for
    /// [`StepwiseCondition`]).
    ///
    /// # Shapes
    /// as [`Self::forward`] `-> [batch, points, future_hidden]` (prefixes of 0 … points − 1)
    pub fn forward_prefixes(
        &self,
        condition: &Tensor<3>,
        lane_path: Option<&(Tensor<3>, Tensor<2>)>,
        target: Tensor<2>,
    ) -> Tensor<3> {
        let feats = self.point_features(condition, lane_path);
        let [b, n, f] = feats.dims();
        let device = feats.device();
        // The MLP's first layer is linear in the flattened points, so prefix `m`'s first
        // layer is the sum of points `j < m`'s own contributions (each point has its own block
        // of the weight) plus the target's and the bias: computed so, rather than as the
        // first layer of `n` masked copies of every point (the same numbers up to rounding,
        // a 16th of the products).
        let (first, rest) = self
            .mlp
            .layers
            .split_first()
            .expect("an MLP has at least one layer");
        let weight = first.weight.val(); // [n·f + target_width, h]
        let [_, h] = weight.dims();
        let per_point = feats
            .swap_dims(0, 1)
            .matmul(weight.clone().narrow(0, 0, n * f).reshape([n, f, h]))
            .swap_dims(0, 1); // [b, n, h]: point j's contribution
        let mut before = vec![Tensor::zeros([b, 1, h], &device)]; // entry m: the points j < m
        if n > 1 {
            before.push(per_point.cumsum(1).narrow(1, 0, n - 1));
        }
        let before = Tensor::cat(before, 1);
        let [_, w] = target.dims();
        let mut fixed = target.matmul(weight.narrow(0, n * f, w));
        if let Some(bias) = &first.bias {
            fixed = fixed + bias.val().reshape([1, h]);
        }
        let mut x = before + fixed.reshape([b, 1, h]);
        for layer in rest {
            x = on_rows(relu(x), |x| layer.forward(x));
        }
        x
    }
}

/// Points of the conditioning future (2 Hz) that the scene embedding — and so the mode
/// probabilities — of the step-wise conditioning sees: its first second. With only the first
/// point the mixture did not learn in the oracle test (`model::tests::
/// stepwise_conditional_mode_uses_the_content_of_the_condition`) which of two futures the other
/// agent's crossing decides (600 steps: 27.3 m error against 4.1 m with two points and 0.9 m
/// with four).
pub const STEPWISE_MODE_POINTS: usize = 2;

/// Interventional, step-wise conditioning (an option, `MultipathConfig::stepwise_condition`;
/// after Tang et al., *Interventional Behavior Prediction*, IROS 2022 — the causality issue the
/// SCBG paper names as its limitation). The fused conditioning lets the target's whole future
/// depend on the other agent's whole future, so the model can read the other's *later* moves
/// as evidence about the scene (a B that slows late is one that made way) rather than as a
/// cause; under an intervention the target at time t can only react to where the other agent
/// has been up to t. Here the decoder's per-step displacements and covariances in each 0.5 s
/// block `j` of the future get a correction from the mode's decoder state and the encoding of
/// the other agent's first `j` points (its future up to the block's start,
/// [`FutureEncoder::forward_prefixes`]); the scene embedding is fused with the first
/// [`STEPWISE_MODE_POINTS`] points only (1 s, about a reaction time and a half), so the mode
/// probabilities see no more than that.
/// Marginal rows (`condition_flag` 0) get no correction: the marginal mode is unchanged.
#[derive(Module, Debug)]
pub struct StepwiseCondition {
    /// Projects a mode's decoder state (`decoder_width → hidden`).
    pub mode_proj: Linear,
    /// Projects a prefix encoding (`future_hidden → hidden`).
    pub prefix_proj: Linear,
    /// `hidden → hidden → 5 · CONDITION_STRIDE`: per step of the block, (dx, dy) and (a, b, c).
    pub out: Mlp,
}

impl StepwiseCondition {
    /// Builds the block for `config`'s widths.
    ///
    /// # Panics
    /// When `config.future_steps` is not a multiple of [`CONDITION_STRIDE`] (the corrections
    /// come in blocks of that many steps; `TrainConfig::validate` refuses such a config).
    pub fn init(config: &MultipathConfig, device: &Device) -> Self {
        assert!(
            config.future_steps.is_multiple_of(CONDITION_STRIDE),
            "step-wise conditioning needs future_steps divisible by {CONDITION_STRIDE}, got {}",
            config.future_steps
        );
        let h = config.future_hidden;
        Self {
            mode_proj: LinearConfig::new(config.decoder_width, h).init(device),
            prefix_proj: LinearConfig::new(config.future_hidden, h).init(device),
            // The last layer starts at zero: the conditional mode starts as the marginal one
            // and the corrections grow from there (large random corrections of the per-step
            // covariances made the first training steps diverge).
            out: Mlp {
                layers: vec![
                    LinearConfig::new(h, h).init(device),
                    LinearConfig::new(h, 5 * CONDITION_STRIDE)
                        .with_initializer(Initializer::Zeros)
                        .init(device),
                ],
            },
        }
    }

    /// The corrections of each mode's per-step outputs; with `covariances` false, those of
    /// the displacements only (what the mixture's means need).
    ///
    /// # Shapes
    /// `modes: [batch, K, decoder_width]` (after the ReLU), `prefixes: [batch, n, future_hidden]`,
    /// `flag: [batch, 1]`
    /// `-> (dxy: [batch, K, n·STRIDE, 2], cov_abc: Option<[batch, K, n·STRIDE, 3]>)`
    pub fn forward(
        &self,
        modes: Tensor<3>,
        prefixes: Tensor<3>,
        flag: Tensor<2>,
        covariances: bool,
    ) -> (Tensor<4>, Option<Tensor<4>>) {
        let [b, k, _] = modes.dims();
        let [_, n, _] = prefixes.dims();
        let hm = on_rows(modes, |x| self.mode_proj.forward(x));
        let hp = on_rows(prefixes, |x| self.prefix_proj.forward(x));
        let [_, _, h] = hm.dims();
        let z = relu(
            hm.reshape([b, k, 1, h]).expand([b, k, n, h])
                + hp.reshape([b, 1, n, h]).expand([b, k, n, h]),
        );
        let flag = flag.reshape([b, 1, 1, 1]);
        let t = n * CONDITION_STRIDE;
        if !covariances {
            #[allow(clippy::single_range_in_vec_init)] // one range of columns, not a Vec
            let dxy = self.out.forward_columns(z, &[0..2 * CONDITION_STRIDE]) * flag;
            return (dxy.reshape([b, k, t, 2]), None);
        }
        let out = self.out.forward(z) * flag; // [b, k, n, 5·STRIDE]
        let dxy = out
            .clone()
            .narrow(3, 0, 2 * CONDITION_STRIDE)
            .reshape([b, k, t, 2]);
        let cov = out
            .narrow(3, 2 * CONDITION_STRIDE, 3 * CONDITION_STRIDE)
            .reshape([b, k, t, 3]);
        (dxy, Some(cov))
    }
}

/// Each point's place in the target's lane frame: `[s / 50 m, offset / 5 m (clamped), has
/// lane]`, from the nearest valid lane-path point (chosen without gradient) and its tangent.
/// Zero where the point is invalid or the target has no lane path.
///
/// # Shapes
/// `xy: [b, n, 2]`, `valid: [b, n, 1]`, `lane_path: [b, L, 4]`, `lane_mask: [b, L]`
/// `-> [b, n, 3]`
fn lane_frame(
    xy: Tensor<3>,
    valid: Tensor<3>,
    lane_path: &Tensor<3>,
    lane_mask: &Tensor<2>,
) -> Tensor<3> {
    let [b, n, _] = xy.dims();
    let [_, l, _] = lane_path.dims();
    // Squared distances [b, n, L] as |c|² − 2 p·c (|p|² does not change the argmin), on
    // detached values: the choice of the nearest point carries no gradient, and the generator's
    // courtesy loss would otherwise record a [b, n, L] graph on every step. Invalid path points
    // are pushed out of reach.
    let centres = lane_path.clone().narrow(2, 0, 2).detach(); // [b, L, 2]
    let c2 = (centres.clone() * centres.clone())
        .sum_dim(2)
        .reshape([b, 1, l]);
    let pc = xy.clone().detach().matmul(centres.swap_dims(1, 2)); // [b, n, L]
    let far = (lane_mask.clone().detach().neg() + 1.0).reshape([b, 1, l]) * 1e9;
    let dist2 = pc * (-2.0) + c2.expand([b, n, l]) + far.expand([b, n, l]);
    let nearest = dist2.argmin(2); // [b, n, 1]
    let pick = |t: Tensor<3>, w: usize| t.gather(1, nearest.clone().expand([b, n, w]));
    let at = pick(lane_path.clone(), 4); // [b, n, 4]
    let rel = xy - at.clone().narrow(2, 0, 2);
    let (tx, ty) = (at.clone().narrow(2, 2, 1), at.narrow(2, 3, 1));
    let (rx, ry) = (rel.clone().narrow(2, 0, 1), rel.narrow(2, 1, 1));
    let along = rx.clone() * tx.clone() + ry.clone() * ty.clone();
    let offset = ry * tx - rx * ty; // left of the path is positive
    let arc = nearest.float().reshape([b, n, 1]) * scbg_features::LANE_PATH_SPACING_M
        - scbg_features::LANE_PATH_BEHIND_M;
    let has_lane = lane_mask
        .clone()
        .max_dim(1)
        .reshape([b, 1, 1])
        .expand([b, n, 1])
        * valid;
    Tensor::cat(
        vec![
            (arc + along) / CONDITION_SCALE_M * has_lane.clone(),
            (offset / LANE_OFFSET_SCALE_M).clamp(-LANE_OFFSET_CLAMP, LANE_OFFSET_CLAMP)
                * has_lane.clone(),
            has_lane,
        ],
        2,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Prefix `m`'s encoding is the encoding of the future with its points from `m` on
    /// invalid (zeroed from step `5m` on, so that no later point nor its velocity shows):
    /// the per-point first layer computes the masked MLP.
    #[test]
    fn each_prefix_encodes_the_future_cut_after_its_points() {
        let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let device = Device::flex();
        device.seed(3);
        let config = MultipathConfig::cpu_small();
        let encoder = FutureEncoder::init(&config, &device);
        let (b, t) = (3, config.future_steps);
        let xy = Tensor::<3>::random(
            [b, t, 2],
            burn::tensor::Distribution::Normal(0.0, 20.0),
            &device,
        );
        // Row 1 is invalid after 6 s.
        let valid: Vec<f32> = (0..b * t)
            .map(|i| if i / t == 1 && i % t >= 60 { 0.0 } else { 1.0 })
            .collect();
        let valid = Tensor::<3>::from_data(TensorData::new(valid, [b, t, 1]), &device);
        let condition = Tensor::cat(vec![xy * valid.clone(), valid], 2);
        let target = Tensor::<2>::random(
            [b, config.target_width],
            burn::tensor::Distribution::Default,
            &device,
        );
        let prefixes = encoder.forward_prefixes(&condition, None, target.clone());
        let n = t / CONDITION_STRIDE;
        assert_eq!(prefixes.dims(), [b, n, config.future_hidden]);
        for m in [0, 1, 7, n - 1] {
            let keep: Vec<f32> = (0..t)
                .map(|s| if s < m * CONDITION_STRIDE { 1.0 } else { 0.0 })
                .collect();
            let keep = Tensor::<1>::from_data(TensorData::new(keep, [t]), &device);
            let cut = condition.clone() * keep.reshape([1, t, 1]);
            let want: Vec<f32> = encoder
                .forward(&cut, None, target.clone())
                .into_data()
                .try_to_vec()
                .unwrap();
            let got: Vec<f32> = prefixes
                .clone()
                .narrow(1, m, 1)
                .into_data()
                .try_to_vec()
                .unwrap();
            assert!(want.iter().any(|v| v.abs() > 1e-3));
            for (w, g) in want.iter().zip(&got) {
                assert!(
                    (w - g).abs() <= 1e-4 * (1.0 + w.abs()),
                    "prefix {m}: {w} vs {g}"
                );
            }
        }
    }

    /// On a lane curving left (radius 200 m), a point 3.5 m right of the lane 145 m along is
    /// at arc length 145 m and offset −3.5 m in the lane frame, although the target frame puts
    /// it 47 m to the left of the x axis; the offset's gradient w.r.t. the point is the lane's
    /// left normal there. Invalid points and targets without a lane path give zeros.
    #[test]
    fn the_lane_frame_places_points_by_arc_length_and_offset() {
        let device = Device::flex().autodiff();
        let (radius, l) = (200.0f32, scbg_features::LANE_PATH_POINTS);
        let mut lane = Vec::new();
        for k in 0..l {
            let phi = scbg_features::lane_path_arc_m(k) / radius;
            lane.extend([
                radius * phi.sin(),
                radius * (1.0 - phi.cos()),
                phi.cos(),
                phi.sin(),
            ]);
        }
        let lane = Tensor::<3>::from_data(TensorData::new(lane.clone(), [1, l, 4]), &device)
            .repeat_dim(0, 2);
        let mask = Tensor::<2>::from_data(
            TensorData::new([vec![1.0f32; l], vec![0.0; l]].concat(), [2, l]),
            &device,
        );
        let phi = 145.0 / radius;
        let (x, y) = (
            (radius + 3.5) * phi.sin(),
            radius - (radius + 3.5) * phi.cos(),
        );
        assert!(y > 45.0);
        let xy = Tensor::<3>::from_data(
            TensorData::new(vec![x, y, 0.0, 0.0, x, y, x, y], [2, 2, 2]),
            &device,
        )
        .require_grad();
        let valid = Tensor::<3>::from_data(
            TensorData::new(vec![1.0f32, 0.0, 1.0, 1.0], [2, 2, 1]),
            &device,
        );
        let out = lane_frame(xy.clone(), valid, &lane, &mask);
        let v: Vec<f32> = out.clone().into_data().try_to_vec::<f32>().unwrap();
        assert!((v[0] * CONDITION_SCALE_M - 145.0).abs() < 0.1, "{v:?}");
        assert!((v[1] * LANE_OFFSET_SCALE_M + 3.5).abs() < 0.05, "{v:?}");
        assert_eq!(v[2], 1.0);
        assert!(v[3..].iter().all(|&x| x == 0.0), "{v:?}");
        let grads = out.narrow(1, 0, 1).narrow(2, 1, 1).sum().backward();
        let g: Vec<f32> = xy
            .grad(&grads)
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let n = [
            -phi.sin() / LANE_OFFSET_SCALE_M,
            phi.cos() / LANE_OFFSET_SCALE_M,
        ];
        assert!(
            (g[0] - n[0]).abs() < 2e-3 && (g[1] - n[1]).abs() < 2e-3,
            "{g:?} vs {n:?}"
        );
    }
}
