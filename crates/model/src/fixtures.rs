//! Small fixed inputs for tests, benchmarks and backend checks: a hand-made sample and one
//! forward + backward pass on any device.

use burn::tensor::{Device, Tensor};
use rand::SeedableRng;
use scbg_features::{AGENT_FEATURES, AgentSample, DIFF_FEATURES, FeatureConfig, Window};

use crate::loss::gmm_nll;
use crate::{Batch, BatchAugment, MultipathConfig};

/// The small feature setting of the fixtures (4 other agents, 8 road segments).
pub fn small_features() -> FeatureConfig {
    FeatureConfig {
        max_other_agents: 4,
        max_road_segments: 8,
        ..Default::default()
    }
}

/// A sample of a target driving straight at 10 m/s along +x (features as `scbg-features`
/// makes them, unstandardised), conditioned on an agent 3.5 m to its left when
/// `with_condition`.
pub fn straight_sample(cfg: &FeatureConfig, with_condition: bool) -> AgentSample {
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
        world_from_agent: Default::default(),
        target_history,
        target_diffs,
        others_history: vec![0.0; cfg.max_other_agents * h * AGENT_FEATURES],
        others_diffs: vec![0.0; cfg.max_other_agents * (h - 1) * DIFF_FEATURES],
        others_valid: vec![false; cfg.max_other_agents],
        road_segments: vec![0.1; cfg.max_road_segments * scbg_features::ROAD_FEATURES],
        road_valid: vec![true; cfg.max_road_segments],
        condition_future_xy_m: (0..f).flat_map(|i| [i as f32, 3.5]).collect(),
        condition_future_valid: vec![with_condition; f],
        future_xy_m: (0..f).flat_map(|i| [(i + 1) as f32, 0.0]).collect(),
        future_heading_rad: vec![0.0; f],
        future_valid: vec![true; f],
        current_velocity_mps: [10.0, 0.0],
        // The lane straight ahead along x.
        lane_path_xy_m: (0..scbg_features::LANE_PATH_POINTS)
            .flat_map(|k| [scbg_features::lane_path_arc_m(k), 0.0])
            .collect(),
        lane_path_valid: vec![true; scbg_features::LANE_PATH_POINTS],
        lane_path_beside: vec![[false, false]; scbg_features::LANE_PATH_POINTS],
        condition_required: false,
    }
}

/// What [`forward_backward`] measured.
#[derive(Debug, Clone, PartialEq)]
pub struct PassCheck {
    /// The GMM NLL of the batch before the step.
    pub loss: f32,
    /// The loss of the same batch after one Adam step of size 1e-3 (lower when the gradients
    /// are right).
    pub loss_after_step: f32,
    /// `[batch, modes, steps, 2]` of the output means.
    pub xy_dims: [usize; 4],
}

/// One forward and one backward pass of a `cpu-small` model on `device` (an autodiff device)
/// over 4 straight samples (2 conditional, 2 marginal), then one Adam step and the loss again.
/// The weights are drawn on the `flex` CPU backend from a fixed seed and moved to `device`, so
/// every correct backend gives the same numbers up to float rounding.
///
/// Seeds the `flex` backend's random stream: callers running other seeded work in parallel
/// must serialise with it.
pub fn forward_backward(device: &Device) -> PassCheck {
    use burn::module::Module;
    use burn::optim::{AdamConfig, GradientsParams};
    let features = small_features();
    let cpu = Device::flex().autodiff();
    cpu.seed(7);
    let model = MultipathConfig::cpu_small().init(&cpu);
    crate::materialize(&model);
    // `fork`: the parameters become leaves of `device`'s graph (`to_device` would keep them
    // as outputs of the CPU graph, with no gradient of their own).
    let model = model.fork(device);
    let samples: Vec<AgentSample> = (0..4)
        .map(|i| straight_sample(&features, i % 2 == 0))
        .collect();
    let refs: Vec<&AgentSample> = samples.iter().collect();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
    let batch = Batch::from_samples(&refs, &BatchAugment::default(), &mut rng, device);
    let loss_of = |m: &crate::Multipath| -> Tensor<1> {
        let out = m.forward(&batch);
        gmm_nll(&out, batch.future_xy.clone(), batch.future_valid.clone())
    };
    let out = model.forward(&batch);
    let xy_dims = out.xy.dims();
    let loss = loss_of(&model);
    let value: f32 = loss.clone().into_scalar();
    let grads = GradientsParams::from_grads(loss.backward(), &model);
    let mut optim = AdamConfig::new().init();
    let model = optim.step(1e-3, model, grads);
    let after: f32 = loss_of(&model).into_scalar();
    PassCheck {
        loss: value,
        loss_after_step: after,
        xy_dims,
    }
}
