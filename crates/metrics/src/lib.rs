//! Waymo Open Motion Dataset prediction metrics, as pure functions
//! (`shared/spec/waymo-motion-metrics.md`).
//!
//! Main entry points: [`evaluate`] (one [`MetricTable`] over many objects), and the
//! building blocks [`classify_trajectory`], [`average_precision`], [`speed_scale`].
//! Coordinates may be in any frame as long as predictions and ground truth share it; headings
//! are in that frame too (the miss test rotates errors into the ground-truth heading frame).
//!
//! The sim-agents realism meta-metric (WOSAC, `shared/spec/wosac.md`) is in [`wosac`].
//!
//! **Architecture invariant:** no I/O, no tensors, no dataset formats; plain numbers in,
//! plain numbers out.

#![warn(missing_docs)]

use std::collections::BTreeMap;
use std::f32::consts::PI;

use serde::Serialize;

mod stats;
pub use stats::{pearson, ranks, spearman, spearman_if_responsive};

pub mod wosac;

/// Future steps at 10 Hz (8 s).
pub const FUTURE_STEPS: usize = 80;
/// Measurement times in seconds, their last future step index (0-based) and the
/// (lateral, longitudinal) miss thresholds in metres.
pub const MEASUREMENTS: [(u32, usize, f32, f32); 3] =
    [(3, 29, 1.0, 2.0), (5, 49, 1.8, 3.6), (8, 79, 3.0, 6.0)];
/// Predictions beyond the first K do not count.
pub const MAX_PREDICTIONS: usize = 6;

/// Ground truth of one object: current state and the 80 future steps.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundTruth {
    /// Position at the current step, metres.
    pub current_xy_m: [f32; 2],
    /// Heading at the current step, radians.
    pub current_heading_rad: f32,
    /// Velocity at the current step, m/s (its norm sets the miss-threshold [`speed_scale`]).
    pub current_velocity_mps: [f32; 2],
    /// `[80]` positions, headings, velocities and validity of the future steps.
    pub future_xy_m: Vec<[f32; 2]>,
    /// `[80]` headings, radians (the miss test rotates errors into these).
    pub future_heading_rad: Vec<f32>,
    /// `[80]` velocities, m/s.
    pub future_velocity_mps: Vec<[f32; 2]>,
    /// `[80]` validity; steps with `false` are ignored by every metric.
    pub future_valid: Vec<bool>,
}

/// Up to K predicted trajectories of one object.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// Future step index (0-based, 10 Hz) of each predicted point: `0..80` for 10 Hz
    /// predictions, `[4, 9, ..., 79]` for 2 Hz ones.
    pub step_indices: Vec<usize>,
    /// `[K][points]` positions; only the first [`MAX_PREDICTIONS`] count, in the order given.
    pub trajectories: Vec<Vec<[f32; 2]>>,
    /// `[K]` confidences.
    pub scores: Vec<f32>,
}

impl Prediction {
    /// The 2 Hz step indices: prediction point p ↔ future step (p + 1) · 5 − 1.
    pub fn steps_2hz() -> Vec<usize> {
        (0..16).map(|p| (p + 1) * 5 - 1).collect()
    }

    /// The 10 Hz step indices: `0..80`.
    pub fn steps_10hz() -> Vec<usize> {
        (0..FUTURE_STEPS).collect()
    }
}

/// Trajectory buckets for mAP (RIGHT_U_TURN is merged into RIGHT_TURN).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub enum TrajectoryType {
    /// Slow and barely moving.
    Stationary,
    /// Heading about unchanged, small lateral offset.
    Straight,
    /// Heading about unchanged, ending offset to the left.
    StraightLeft,
    /// Heading about unchanged, ending offset to the right.
    StraightRight,
    /// Turned left and ended behind the start (longitudinally).
    LeftUTurn,
    /// Turned left.
    LeftTurn,
    /// Turned right (including right U-turns).
    RightTurn,
}

impl TrajectoryType {
    /// Every bucket, in order.
    pub const ALL: [TrajectoryType; 7] = [
        Self::Stationary,
        Self::Straight,
        Self::StraightLeft,
        Self::StraightRight,
        Self::LeftUTurn,
        Self::LeftTurn,
        Self::RightTurn,
    ];
}

/// The thresholds of the trajectory classifier.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ClassifierThresholds {
    /// Stationary if the larger of the current and final speed is below this (m/s)…
    pub max_speed_stationary_mps: f32,
    /// …and the displacement to the final valid step is below this (metres).
    pub max_displacement_stationary_m: f32,
    /// Straight (rather than straight-left/right) if the final lateral offset is below this (m).
    pub max_lateral_straight_m: f32,
    /// Straight-ish if the absolute heading change is below this (radians).
    pub max_abs_heading_diff_straight_rad: f32,
    /// A left turn ending at a longitudinal offset below this (metres) is a left U-turn.
    pub min_longitudinal_u_turn_m: f32,
    /// Whether the heading change is wrapped into (−π, π] before the tests. Waymo's pre-2024
    /// code compares the raw difference of the two headings (a track whose heading crosses
    /// ±π is not straight there); the current code normalises it.
    pub normalize_heading_diff: bool,
}

impl ClassifierThresholds {
    /// The set of Waymo's code before 2024, which 2022–2023 papers report (default).
    pub const PRE_2024: Self = Self {
        max_speed_stationary_mps: 2.0,
        max_displacement_stationary_m: 5.0,
        max_lateral_straight_m: 5.0,
        max_abs_heading_diff_straight_rad: PI / 6.0,
        min_longitudinal_u_turn_m: -5.0,
        normalize_heading_diff: false,
    };
    /// The current Waymo code's set.
    pub const CURRENT: Self = Self {
        max_speed_stationary_mps: 2.0,
        max_displacement_stationary_m: 3.0,
        max_lateral_straight_m: 2.5,
        max_abs_heading_diff_straight_rad: PI / 6.0,
        min_longitudinal_u_turn_m: 0.0,
        normalize_heading_diff: true,
    };
}

impl Default for ClassifierThresholds {
    fn default() -> Self {
        Self::PRE_2024
    }
}

fn wrap(a: f32) -> f32 {
    let mut a = a % (2.0 * PI);
    if a <= -PI {
        a += 2.0 * PI;
    } else if a > PI {
        a -= 2.0 * PI;
    }
    a
}

fn norm(v: [f32; 2]) -> f32 {
    (v[0] * v[0] + v[1] * v[1]).sqrt()
}

/// Classifies the ground truth from the current step to its last valid future step, as Waymo's
/// `ClassifyTrack` does. `None` when no future step is valid.
pub fn classify_trajectory(gt: &GroundTruth, t: &ClassifierThresholds) -> Option<TrajectoryType> {
    let last = (0..gt.future_valid.len())
        .rev()
        .find(|&i| gt.future_valid[i])?;
    let delta = [
        gt.future_xy_m[last][0] - gt.current_xy_m[0],
        gt.future_xy_m[last][1] - gt.current_xy_m[1],
    ];
    let displacement = norm(delta);
    let raw_heading_diff = gt.future_heading_rad[last] - gt.current_heading_rad;
    let heading_diff = if t.normalize_heading_diff {
        wrap(raw_heading_diff)
    } else {
        raw_heading_diff
    };
    let (s, c) = gt.current_heading_rad.sin_cos();
    let lon = c * delta[0] + s * delta[1];
    let lat = -s * delta[0] + c * delta[1];
    let max_speed = norm(gt.current_velocity_mps).max(norm(gt.future_velocity_mps[last]));
    if max_speed < t.max_speed_stationary_mps && displacement < t.max_displacement_stationary_m {
        return Some(TrajectoryType::Stationary);
    }
    if heading_diff.abs() < t.max_abs_heading_diff_straight_rad {
        if lat.abs() < t.max_lateral_straight_m {
            return Some(TrajectoryType::Straight);
        }
        return Some(if lat < 0.0 {
            TrajectoryType::StraightRight
        } else {
            TrajectoryType::StraightLeft
        });
    }
    if heading_diff < -t.max_abs_heading_diff_straight_rad && lat < 0.0 {
        // RIGHT_U_TURN is merged into RIGHT_TURN.
        return Some(TrajectoryType::RightTurn);
    }
    if lon < t.min_longitudinal_u_turn_m {
        return Some(TrajectoryType::LeftUTurn);
    }
    Some(TrajectoryType::LeftTurn)
}

/// Miss-threshold scale from the speed at the current step: 0.5 below 1.4 m/s, 1 above
/// 11 m/s, linear in between.
pub fn speed_scale(speed_mps: f32) -> f32 {
    if speed_mps < 1.4 {
        0.5
    } else if speed_mps > 11.0 {
        1.0
    } else {
        0.5 + 0.5 * (speed_mps - 1.4) / (11.0 - 1.4)
    }
}

/// Average precision of (confidence, is_true_positive) samples against `num_objects`
/// positives: samples sorted by confidence (false positives first on ties), area under the
/// interpolated precision–recall curve.
pub fn average_precision(samples: &[(f32, bool)], num_objects: usize) -> f32 {
    if num_objects == 0 {
        return 0.0;
    }
    let mut sorted = samples.to_vec();
    sorted.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut tp = 0usize;
    let precision: Vec<f32> = sorted
        .iter()
        .enumerate()
        .map(|(i, s)| {
            tp += usize::from(s.1);
            tp as f32 / (i + 1) as f32
        })
        .collect();
    // Interpolated precision: the best precision at this or any higher recall.
    let mut best = vec![0.0f32; precision.len()];
    let mut running = 0.0f32;
    for i in (0..precision.len()).rev() {
        running = running.max(precision[i]);
        best[i] = running;
    }
    sorted
        .iter()
        .zip(&best)
        .filter(|(s, _)| s.1)
        .map(|(_, p)| p / num_objects as f32)
        .sum()
}

/// One bucket's (confidence, TP) samples for mAP and for soft mAP, and its object count.
type BucketSamples = (Vec<(f32, bool)>, Vec<(f32, bool)>, usize);

/// Metrics at one measurement time (or their average); `None` where no object contributed.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Metrics {
    /// Mean displacement of the highest-scoring trajectory over its valid steps up to this time, m.
    pub ade: Option<f32>,
    /// Minimum over the K trajectories of their average displacement error, metres.
    pub min_ade: Option<f32>,
    /// Minimum over the K trajectories of the error at the measurement step, metres.
    pub min_fde: Option<f32>,
    /// Fraction of objects where every trajectory misses at the measurement step.
    pub miss_rate: Option<f32>,
    /// Mean over trajectory buckets of the average precision (later hits count as false positives).
    pub map: Option<f32>,
    /// Like `map`, but hits after the first are dropped instead of counted as false positives.
    pub soft_map: Option<f32>,
}

/// Per-time metrics and their plain mean.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MetricTable {
    /// Metrics at 3, 5 and 8 s.
    pub by_time: Vec<(u32, Metrics)>,
    /// The plain mean of the per-time values that exist.
    pub mean: Metrics,
    /// Number of objects evaluated (including those that contributed to no metric).
    pub num_objects: usize,
}

/// Errors of one prediction at the steps it gives that have valid ground truth, up to `last`.
fn errors_up_to(pred: &Prediction, k: usize, gt: &GroundTruth, last: usize) -> Vec<f32> {
    pred.step_indices
        .iter()
        .enumerate()
        .filter(|&(_, &s)| s <= last && gt.future_valid.get(s).copied().unwrap_or(false))
        .map(|(p, &s)| {
            let q = pred.trajectories[k][p];
            let g = gt.future_xy_m[s];
            norm([q[0] - g[0], q[1] - g[1]])
        })
        .collect()
}

fn mean(v: &[f32]) -> Option<f32> {
    (!v.is_empty()).then(|| v.iter().sum::<f32>() / v.len() as f32)
}

/// Whether prediction `k` misses at future step `step` (which must be valid and predicted).
fn is_miss(
    pred: &Prediction,
    k: usize,
    gt: &GroundTruth,
    step: usize,
    lat_thr: f32,
    lon_thr: f32,
    scale: f32,
) -> Option<bool> {
    let p = pred.step_indices.iter().position(|&s| s == step)?;
    let q = pred.trajectories[k][p];
    let g = gt.future_xy_m[step];
    let d = [q[0] - g[0], q[1] - g[1]];
    let (s, c) = gt.future_heading_rad[step].sin_cos();
    let lon = c * d[0] + s * d[1];
    let lat = -s * d[0] + c * d[1];
    Some(lat.abs() > lat_thr * scale || lon.abs() > lon_thr * scale)
}

/// Evaluates predictions against ground truth, object by object (`preds[i]` ↔ `gts[i]`).
pub fn evaluate(
    preds: &[Prediction],
    gts: &[GroundTruth],
    thresholds: &ClassifierThresholds,
) -> MetricTable {
    assert_eq!(preds.len(), gts.len(), "one prediction per ground truth");
    let mut by_time = Vec::new();
    for &(secs, last, lat_thr, lon_thr) in &MEASUREMENTS {
        let (mut ade, mut min_ade, mut min_fde, mut miss) = (vec![], vec![], vec![], vec![]);
        let mut ap_samples: BTreeMap<TrajectoryType, BucketSamples> = Default::default();
        for (pred, gt) in preds.iter().zip(gts) {
            let k_max = pred
                .trajectories
                .len()
                .min(MAX_PREDICTIONS)
                .min(pred.scores.len());
            if k_max == 0 {
                continue;
            }
            let errors: Vec<Vec<f32>> = (0..k_max)
                .map(|k| errors_up_to(pred, k, gt, last))
                .collect();
            if errors[0].is_empty() {
                continue; // no valid ground truth at the predicted steps up to this time
            }
            let top = (0..k_max)
                .max_by(|&a, &b| pred.scores[a].total_cmp(&pred.scores[b]).then(b.cmp(&a)))
                .expect("k_max > 0");
            ade.push(mean(&errors[top]).expect("non-empty"));
            min_ade.push(
                errors
                    .iter()
                    .filter_map(|e| mean(e))
                    .fold(f32::INFINITY, f32::min),
            );
            // FDE, miss rate and mAP need valid ground truth at the measurement step.
            if !gt.future_valid.get(last).copied().unwrap_or(false)
                || !pred.step_indices.contains(&last)
            {
                continue;
            }
            let p_last = pred
                .step_indices
                .iter()
                .position(|&s| s == last)
                .expect("contains");
            min_fde.push(
                (0..k_max)
                    .map(|k| {
                        let q = pred.trajectories[k][p_last];
                        let g = gt.future_xy_m[last];
                        norm([q[0] - g[0], q[1] - g[1]])
                    })
                    .fold(f32::INFINITY, f32::min),
            );
            let scale = speed_scale(norm(gt.current_velocity_mps));
            let misses: Vec<bool> = (0..k_max)
                .map(|k| is_miss(pred, k, gt, last, lat_thr, lon_thr, scale).expect("predicted"))
                .collect();
            miss.push(if misses.iter().all(|&m| m) { 1.0 } else { 0.0 });
            if let Some(bucket) = classify_trajectory(gt, thresholds) {
                let entry = ap_samples.entry(bucket).or_default();
                entry.2 += 1;
                let mut order: Vec<usize> = (0..k_max).collect();
                order.sort_by(|&a, &b| pred.scores[b].total_cmp(&pred.scores[a]).then(a.cmp(&b)));
                let mut seen_tp = false;
                for k in order {
                    let tp = !misses[k];
                    // mAP: only the first TP counts, later ones are FPs; soft mAP drops them.
                    entry.0.push((pred.scores[k], tp && !seen_tp));
                    if !(tp && seen_tp) {
                        entry.1.push((pred.scores[k], tp && !seen_tp));
                    }
                    seen_tp |= tp;
                }
            }
        }
        let aps: Vec<f32> = ap_samples
            .values()
            .map(|(s, _, n)| average_precision(s, *n))
            .collect();
        let soft: Vec<f32> = ap_samples
            .values()
            .map(|(_, s, n)| average_precision(s, *n))
            .collect();
        by_time.push((
            secs,
            Metrics {
                ade: mean(&ade),
                min_ade: mean(&min_ade),
                min_fde: mean(&min_fde),
                miss_rate: mean(&miss),
                map: mean(&aps),
                soft_map: mean(&soft),
            },
        ));
    }
    let avg = |f: fn(&Metrics) -> Option<f32>| {
        mean(&by_time.iter().filter_map(|(_, m)| f(m)).collect::<Vec<_>>())
    };
    let mean_metrics = Metrics {
        ade: avg(|m| m.ade),
        min_ade: avg(|m| m.min_ade),
        min_fde: avg(|m| m.min_fde),
        miss_rate: avg(|m| m.miss_rate),
        map: avg(|m| m.map),
        soft_map: avg(|m| m.soft_map),
    };
    MetricTable {
        by_time,
        mean: mean_metrics,
        num_objects: preds.len(),
    }
}

#[cfg(test)]
mod tests;
