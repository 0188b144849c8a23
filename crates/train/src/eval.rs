//! Predictions of the model and of the baselines, scored with the Waymo metrics.
//!
//! Everything is in the target's frame at the current step (the metrics are invariant to the
//! frame as long as predictions and ground truth share it).

use burn::tensor::Device;
use rayon::prelude::*;
use scbg_features::{AGENT_FEATURES, AgentSample};
use scbg_metrics::{ClassifierThresholds, GroundTruth, MetricTable, Prediction};
use scbg_model::{Batch, Multipath};

pub use scbg_model::Mode;

/// K trajectories with probabilities, target frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Modes {
    /// `[K][T]` positions.
    pub xy: Vec<Vec<[f32; 2]>>,
    /// `[K]`, summing to 1.
    pub probs: Vec<f32>,
}

/// Runs the model on samples (already standardised) in batches of `batch_size`, the batches
/// in parallel (each batch's result does not depend on the threads), in sample order.
pub fn predict(
    model: &Multipath,
    samples: &[&AgentSample],
    mode: Mode,
    batch_size: usize,
    device: &Device,
) -> Vec<Modes> {
    samples
        .par_chunks(batch_size.max(1))
        .flat_map_iter(|chunk| {
            let batch = Batch::for_mode(chunk, mode, device);
            model
                .forward_mode(&batch, mode)
                .into_mixtures()
                .into_iter()
                .map(|m| Modes {
                    xy: m.xy,
                    probs: m.probs,
                })
        })
        .collect()
}

/// Ground truth of a (raw, unstandardised) sample for the metrics; future velocities are
/// finite differences of the positions.
pub fn ground_truth(sample: &AgentSample) -> GroundTruth {
    let t = sample.future_valid.len();
    let xy: Vec<[f32; 2]> = (0..t)
        .map(|i| [sample.future_xy_m[2 * i], sample.future_xy_m[2 * i + 1]])
        .collect();
    let velocity = (0..t)
        .map(|i| {
            let prev = if i == 0 {
                Some([0.0, 0.0])
            } else {
                sample.future_valid[i - 1].then(|| xy[i - 1])
            };
            match (sample.future_valid[i], prev) {
                (true, Some(p)) => [(xy[i][0] - p[0]) / 0.1, (xy[i][1] - p[1]) / 0.1],
                _ => [0.0, 0.0],
            }
        })
        .collect();
    GroundTruth {
        current_xy_m: [0.0, 0.0],
        current_heading_rad: 0.0,
        current_velocity_mps: sample.current_velocity_mps,
        future_xy_m: xy,
        future_heading_rad: sample.future_heading_rad.clone(),
        future_velocity_mps: velocity,
        future_valid: sample.future_valid.clone(),
    }
}

/// Constant velocity from the current velocity (one trajectory).
pub fn constant_velocity(sample: &AgentSample, future_steps: usize) -> Modes {
    let [vx, vy] = sample.current_velocity_mps;
    Modes {
        xy: vec![
            (1..=future_steps)
                .map(|i| [vx * 0.1 * i as f32, vy * 0.1 * i as f32])
                .collect(),
        ],
        probs: vec![1.0],
    }
}

/// Constant yaw rate and acceleration, estimated from the last second of (raw) history.
pub fn constant_yaw_rate_accel(sample: &AgentSample, future_steps: usize) -> Modes {
    let h = sample.target_history.len() / AGENT_FEATURES;
    let row = |s: usize| &sample.target_history[s * AGENT_FEATURES..(s + 1) * AGENT_FEATURES];
    let now = row(h - 1);
    let first = (0..h - 1).find(|&s| row(s)[6] > 0.0);
    let (mut yaw_rate, mut accel) = (0.0f32, 0.0f32);
    if let Some(f) = first {
        let dt = (h - 1 - f) as f32 * 0.1;
        yaw_rate = scbg_scene_wrap(now[2] - row(f)[2]) / dt;
        accel = (now[3] - row(f)[3]) / dt;
    }
    let (mut x, mut y, mut yaw, mut v) = (0.0f32, 0.0f32, 0.0f32, now[3]);
    let traj = (0..future_steps)
        .map(|_| {
            v = (v + accel * 0.1).max(0.0);
            yaw += yaw_rate * 0.1;
            x += v * yaw.cos() * 0.1;
            y += v * yaw.sin() * 0.1;
            [x, y]
        })
        .collect();
    Modes {
        xy: vec![traj],
        probs: vec![1.0],
    }
}

fn scbg_scene_wrap(a: f32) -> f32 {
    let mut a = a % (2.0 * std::f32::consts::PI);
    if a > std::f32::consts::PI {
        a -= 2.0 * std::f32::consts::PI;
    } else if a <= -std::f32::consts::PI {
        a += 2.0 * std::f32::consts::PI;
    }
    a
}

/// Scores predictions against raw samples' ground truth.
pub fn score(
    modes: &[Modes],
    raw: &[&AgentSample],
    thresholds: &ClassifierThresholds,
) -> MetricTable {
    let preds: Vec<Prediction> = modes
        .iter()
        .map(|m| Prediction {
            step_indices: Prediction::steps_10hz(),
            trajectories: m.xy.clone(),
            scores: m.probs.clone(),
        })
        .collect();
    let gts: Vec<GroundTruth> = raw.iter().map(|s| ground_truth(s)).collect();
    scbg_metrics::evaluate(&preds, &gts, thresholds)
}

/// Mean GMM NLL of standardised samples in `mode` (nats per sample, summed over steps).
pub fn mean_nll(
    model: &Multipath,
    samples: &[&AgentSample],
    mode: Mode,
    batch_size: usize,
    device: &Device,
) -> Option<f64> {
    // Batches in parallel, summed in batch order (the same sum on any number of threads).
    let losses: Vec<(f32, usize)> = samples
        .par_chunks(batch_size.max(1))
        .map(|chunk| {
            let batch = Batch::for_mode(chunk, mode, device);
            let loss: f32 = scbg_model::gmm_nll(
                &model.forward_mode(&batch, mode),
                batch.future_xy.clone(),
                batch.future_valid.clone(),
            )
            .into_scalar();
            (loss, chunk.len())
        })
        .collect();
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (loss, len) in losses {
        if loss.is_finite() {
            sum += f64::from(loss) * len as f64;
            n += len;
        }
    }
    (n > 0).then(|| sum / n as f64)
}
