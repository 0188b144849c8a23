//! The WOSAC (Waymo Open Sim Agents Challenge) realism meta-metric, as pure functions
//! (`shared/spec/wosac.md`: the 2025 definition, and the 2024 weights as an option).
//!
//! Main entry points: [`scenario_metrics`] scores 32 joint rollouts ([`Rollouts`]) of one
//! [`Scene`]; [`aggregate`] averages many scenarios. [`sim_agent_ids`] and
//! [`evaluated_agent_ids`] say which objects must be simulated and which are scored;
//! [`log_replay_rollouts`] and [`constant_velocity_rollouts`] are the two reference baselines,
//! and [`reference`] holds the official values of both on the specification's genuine scenario.
//!
//! The computation reproduces the official evaluation code, quirks included (float32 arithmetic,
//! NaN padding of the finite differences, the unwrapped heading difference in the
//! time-to-collision, the road-edge padding quirk for cyclic polylines, the zero-padded lanes and
//! the plus sign of the traffic-light nearest-lane search). Each quirk is documented where it is
//! implemented. Long sums (log-likelihoods, displacement errors) are accumulated in `f64`, which
//! stays within float32 rounding of the official reductions.
//!
//! **Licence note** (from the spec): this is an independent implementation written from the
//! specification; it is not covered by Waymo's patent grant for its metric code.

mod error;
mod estimators;
mod features;
mod geometry;
mod interaction;
mod kinematics;
pub mod reference;
mod road_edge;
pub use road_edge::RoadEdges;
mod scores;
mod traffic_light;

pub use error::WosacError;
pub use scores::{BucketScores, DatasetMetrics, FeatureLikelihoods, ScenarioMetrics, WosacConfig};

#[cfg(test)]
mod scene_tests;
#[cfg(test)]
mod tests;

use std::collections::HashMap;

use scbg_scene::{ObjectType, Scene};
use serde::Serialize;

use estimators::HistogramSpec;
use features::{Features, Objects, Trajectories};
use traffic_light::TrafficLights;

/// Duration of one step, seconds (10 Hz).
pub const STEP_DURATION_S: f32 = 0.1;
/// Index of the current step (the last history step).
pub const CURRENT_STEP: usize = 10;
/// Number of steps of a scored scenario: 11 history steps and 80 future steps.
pub const SCENARIO_STEPS: usize = 91;
/// Number of simulated (future) steps per object: global steps 11..=90.
pub const SIMULATED_STEPS: usize = 80;
/// Number of joint rollouts per scenario.
pub const ROLLOUTS_PER_SCENARIO: usize = 32;
/// Step duration as the official code holds it (a Python double).
const DT_S: f64 = 0.1;
/// First simulated global step.
const FIRST_FUTURE_STEP: usize = CURRENT_STEP + 1;
/// The official "extremely large distance" sentinel (internal only).
const LARGE_DISTANCE_M: f32 = 1e10;

/// One simulated pose: the four values a WOSAC submission carries per object and step.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct SimPose {
    /// Centre x, world frame (the scene's frame), metres.
    pub x_m: f32,
    /// Centre y, world frame, metres.
    pub y_m: f32,
    /// Centre z, world frame, metres.
    pub z_m: f32,
    /// Heading, radians, counter-clockwise from +x (not required to be wrapped).
    pub heading_rad: f32,
}

/// The joint rollouts of one scenario, as a WOSAC submission carries them.
///
/// Every joint scene lists the same objects, in the order of [`Rollouts::object_ids`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Rollouts {
    /// `[objects]` track ids of the simulated objects: every sim agent of the scene
    /// ([`sim_agent_ids`]) exactly once, in any order.
    pub object_ids: Vec<i64>,
    /// `[32 rollouts][objects][80 steps]` simulated poses for global steps 11..=90; the object
    /// axis follows [`Rollouts::object_ids`].
    pub trajectories: Vec<Vec<Vec<SimPose>>>,
}

/// Ids of the objects that must be simulated: every track valid at the current step, in track
/// order.
pub fn sim_agent_ids(scene: &Scene) -> Vec<i64> {
    scene
        .tracks
        .iter()
        .filter(|t| t.states.get(scene.current_step).is_some_and(|s| s.valid))
        .map(|t| t.id)
        .collect()
}

/// Ids of the objects whose features are scored: the SDC and the tracks to predict, without
/// duplicates, in ascending id order. (Each must also be a sim agent for the scene to be
/// scored.)
pub fn evaluated_agent_ids(scene: &Scene) -> Vec<i64> {
    let mut ids: Vec<i64> = scene
        .sdc_track_index
        .into_iter()
        .chain(scene.tracks_to_predict.iter().map(|t| t.track_index))
        .filter_map(|i| scene.tracks.get(i).map(|t| t.id))
        .collect();
    ids.sort_unstable();
    ids.dedup();
    ids
}

fn check_layout(scene: &Scene) -> Result<(), WosacError> {
    if scene.num_steps() != SCENARIO_STEPS
        || scene.current_step != CURRENT_STEP
        || scene
            .tracks
            .iter()
            .any(|t| t.states.len() != SCENARIO_STEPS)
    {
        return Err(WosacError::SceneLayout {
            scenario_id: scene.scenario_id.clone(),
            num_steps: scene.num_steps(),
            current_step: scene.current_step,
        });
    }
    Ok(())
}

/// Whether `scene` can be scored at all, before any rollout is made: the checks of
/// [`scenario_metrics`] that do not depend on the rollouts (the WOSAC layout of 91 steps with
/// current step 10, an evaluated object, every evaluated object a sim agent, a road edge).
pub fn check_scene(scene: &Scene) -> Result<(), WosacError> {
    check_layout(scene)?;
    Objects::new(scene)?;
    if RoadEdges::new(&scene.map).is_none() {
        return Err(WosacError::NoRoadEdges {
            scenario_id: scene.scenario_id.clone(),
        });
    }
    Ok(())
}

/// `n` copies of the logged future of every sim agent, copied as stored (invalid states
/// included, so their placeholder values are simulated as if valid): the log-replay baseline.
pub fn log_replay_rollouts(scene: &Scene, n: usize) -> Result<Rollouts, WosacError> {
    baseline(scene, n, |track| {
        track.states[FIRST_FUTURE_STEP..SCENARIO_STEPS]
            .iter()
            .map(|s| SimPose {
                x_m: s.x_m as f32,
                y_m: s.y_m as f32,
                z_m: s.z_m as f32,
                heading_rad: s.heading_rad,
            })
            .collect()
    })
}

/// `n` copies of the constant-velocity baseline: from the current state, `x_k = x + v_x·0.1·k`
/// (in `f64`, stored as `f32`), `y` likewise, `z` and heading held, for `k = 1..=80`.
pub fn constant_velocity_rollouts(scene: &Scene, n: usize) -> Result<Rollouts, WosacError> {
    baseline(scene, n, |track| {
        let s = track.states[CURRENT_STEP];
        (1..=SIMULATED_STEPS)
            .map(|k| {
                let k = k as f64;
                SimPose {
                    x_m: (s.x_m + f64::from(s.velocity_x_mps) * 0.1 * k) as f32,
                    y_m: (s.y_m + f64::from(s.velocity_y_mps) * 0.1 * k) as f32,
                    z_m: s.z_m as f32,
                    heading_rad: s.heading_rad,
                }
            })
            .collect()
    })
}

fn baseline(
    scene: &Scene,
    n: usize,
    trajectory: impl Fn(&scbg_scene::Track) -> Vec<SimPose>,
) -> Result<Rollouts, WosacError> {
    check_layout(scene)?;
    let tracks: Vec<&scbg_scene::Track> = scene
        .tracks
        .iter()
        .filter(|t| t.states[CURRENT_STEP].valid)
        .collect();
    let one: Vec<Vec<SimPose>> = tracks.iter().map(|t| trajectory(t)).collect();
    Ok(Rollouts {
        object_ids: tracks.iter().map(|t| t.id).collect(),
        trajectories: vec![one; n],
    })
}

/// Maps each internal object (evaluated first) to its index in `rollouts.object_ids`, after
/// checking ids, counts and finiteness.
fn match_rollouts(objects: &Objects, rollouts: &Rollouts) -> Result<Vec<usize>, WosacError> {
    let internal: HashMap<i64, usize> = objects
        .ids
        .iter()
        .enumerate()
        .map(|(k, &id)| (id, k))
        .collect();
    let mut to_rollout = vec![usize::MAX; objects.ids.len()];
    for (r, &id) in rollouts.object_ids.iter().enumerate() {
        let k = *internal
            .get(&id)
            .ok_or(WosacError::UnknownObject { object_id: id })?;
        if to_rollout[k] != usize::MAX {
            return Err(WosacError::DuplicateObject { object_id: id });
        }
        to_rollout[k] = r;
    }
    if let Some(k) = to_rollout.iter().position(|&r| r == usize::MAX) {
        return Err(WosacError::MissingObject {
            object_id: objects.ids[k],
        });
    }
    if rollouts.trajectories.len() != ROLLOUTS_PER_SCENARIO {
        return Err(WosacError::RolloutCount {
            got: rollouts.trajectories.len(),
        });
    }
    for (rollout, scene) in rollouts.trajectories.iter().enumerate() {
        if scene.len() != rollouts.object_ids.len() {
            return Err(WosacError::TrajectoryCount {
                rollout,
                got: scene.len(),
                expected: rollouts.object_ids.len(),
            });
        }
        for (traj, &object_id) in scene.iter().zip(&rollouts.object_ids) {
            if traj.len() != SIMULATED_STEPS {
                return Err(WosacError::StepCount {
                    rollout,
                    object_id,
                    got: traj.len(),
                });
            }
            for (step, p) in traj.iter().enumerate() {
                let fields = [
                    ("x", p.x_m),
                    ("y", p.y_m),
                    ("z", p.z_m),
                    ("heading", p.heading_rad),
                ];
                if let Some((field, _)) = fields.iter().find(|(_, v)| !v.is_finite()) {
                    return Err(WosacError::NonFinite {
                        rollout,
                        object_id,
                        step,
                        field,
                    });
                }
            }
        }
    }
    Ok(to_rollout)
}

/// Feature histogram configurations (§7): (min, max, bins), pseudocount 0.1.
const SPEED: HistogramSpec = HistogramSpec::new(0.0, 25.0, 10, 0.1);
const ACCELERATION: HistogramSpec = HistogramSpec::new(-12.0, 12.0, 11, 0.1);
const ANGULAR_SPEED: HistogramSpec = HistogramSpec::new(-0.628, 0.628, 11, 0.1);
// The configs give ±3.14 (not π) and ±0.628 (not π/5).
#[allow(clippy::approx_constant)]
const ANGULAR_ACCELERATION: HistogramSpec = HistogramSpec::new(-3.14, 3.14, 11, 0.1);
const NEAREST_OBJECT: HistogramSpec = HistogramSpec::new(-5.0, 40.0, 10, 0.1);
const TIME_TO_COLLISION: HistogramSpec = HistogramSpec::new(0.0, 5.0, 10, 0.1);
const ROAD_EDGE: HistogramSpec = HistogramSpec::new(-20.0, 40.0, 10, 0.1);

/// Scores the 32 joint rollouts of one scenario (§4–§9 of the spec).
///
/// Fails when the scene does not have the WOSAC layout (91 steps, current step 10), has no
/// evaluated object, has an evaluated object that is not a sim agent or has no road edge, and
/// when the rollouts do not list every sim agent exactly once with 32 × 80 finite poses.
pub fn scenario_metrics(
    scene: &Scene,
    rollouts: &Rollouts,
    config: WosacConfig,
) -> Result<ScenarioMetrics, WosacError> {
    check_layout(scene)?;
    let objects = Objects::new(scene)?;
    let to_rollout = match_rollouts(&objects, rollouts)?;
    let road_edges = RoadEdges::new(&scene.map).ok_or_else(|| WosacError::NoRoadEdges {
        scenario_id: scene.scenario_id.clone(),
    })?;
    let lights = TrafficLights::new(scene);

    let mut traj = Trajectories::from_log(scene, &objects);
    let mut scratch = features::Scratch::default();
    let log = features::compute(&traj, &objects, &road_edges, &lights, &mut scratch);
    let log_traj = traj.clone();
    let mut sims = Vec::with_capacity(ROLLOUTS_PER_SCENARIO);
    let mut ade = Vec::with_capacity(ROLLOUTS_PER_SCENARIO);
    for rollout in &rollouts.trajectories {
        traj.set_future(rollout, &to_rollout);
        sims.push(features::compute(
            &traj,
            &objects,
            &road_edges,
            &lights,
            &mut scratch,
        ));
        ade.push(displacement_errors(&traj, &log_traj, objects.num_evaluated));
    }

    let n_eval = objects.num_evaluated;
    let log_valid: Vec<bool> = (0..n_eval)
        .flat_map(|i| (0..SIMULATED_STEPS).map(move |f| (i, f)))
        .map(|(i, f)| log_traj.valid(i, FIRST_FUTURE_STEP + f))
        .collect();
    let speed_mask = shifted_and(&log_valid, n_eval);
    let accel_mask = shifted_and(&speed_mask, n_eval);
    let vehicle: Vec<bool> = (0..n_eval)
        .map(|i| objects.object_type[i] == ObjectType::Vehicle)
        .collect();
    let log_valid_vehicle: Vec<bool> = log_valid
        .iter()
        .enumerate()
        .map(|(k, &v)| v && vehicle[k / SIMULATED_STEPS])
        .collect();
    let ttc_mask = if config.time_to_collision_vehicles_only() {
        &log_valid_vehicle
    } else {
        &log_valid
    };

    let series = |spec: HistogramSpec, get: fn(&Features) -> &[f32], mask: &[bool]| {
        let sim: Vec<&[f32]> = sims.iter().map(get).collect();
        estimators::time_series_likelihood(spec, get(&log), &sim, mask, n_eval)
    };
    let indicator = |get: fn(&Features) -> &[bool], mask: &[bool]| {
        let log_any = any_per_object(get(&log), mask, n_eval);
        let sim_any: Vec<Vec<bool>> = sims
            .iter()
            .map(|s| any_per_object(get(s), mask, n_eval))
            .collect();
        (
            estimators::indicator_likelihood(&log_any, &sim_any),
            rate(&sim_any),
        )
    };
    let (collision, collision_rate) = indicator(|f| &f.collision, &log_valid);
    let (offroad, offroad_rate) = indicator(|f| &f.offroad, &log_valid);
    let (traffic_light, _) = indicator(|f| &f.traffic_light_violation, &log_valid_vehicle);
    let (_, traffic_light_rate) = indicator(|f| &f.traffic_light_violation, &log_valid);
    let likelihoods = FeatureLikelihoods {
        linear_speed: series(SPEED, |f| &f.linear_speed_mps, &speed_mask),
        linear_acceleration: series(ACCELERATION, |f| &f.linear_acceleration_mps2, &accel_mask),
        angular_speed: series(ANGULAR_SPEED, |f| &f.angular_speed_radps, &speed_mask),
        angular_acceleration: series(
            ANGULAR_ACCELERATION,
            |f| &f.angular_acceleration_radps2,
            &accel_mask,
        ),
        distance_to_nearest_object: series(
            NEAREST_OBJECT,
            |f| &f.distance_to_nearest_object_m,
            &log_valid,
        ),
        collision_indication: collision,
        time_to_collision: series(TIME_TO_COLLISION, |f| &f.time_to_collision_s, ttc_mask),
        distance_to_road_edge: series(ROAD_EDGE, |f| &f.distance_to_road_edge_m, &log_valid),
        offroad_indication: offroad,
        traffic_light_violation: traffic_light,
    };

    let per_rollout: Vec<f64> = ade
        .iter()
        .map(|a| a.iter().map(|&e| f64::from(e)).sum::<f64>() / n_eval as f64)
        .collect();
    let mean_ade = per_rollout.iter().sum::<f64>() / per_rollout.len() as f64;
    let min_ade = per_rollout.iter().copied().fold(f64::INFINITY, f64::min);

    Ok(ScenarioMetrics {
        scenario_id: scene.scenario_id.clone(),
        metametric: likelihoods.metametric(config),
        buckets: likelihoods.buckets(config),
        likelihoods,
        average_displacement_error_m: mean_ade as f32,
        min_average_displacement_error_m: min_ade as f32,
        simulated_collision_rate: collision_rate,
        simulated_offroad_rate: offroad_rate,
        simulated_traffic_light_violation_rate: traffic_light_rate,
    })
}

/// Averages per-scenario metrics with equal weight (§8, last paragraph); the buckets are
/// recomputed from the averaged likelihoods with `config`'s weights. `None` for no scenarios.
pub fn aggregate(metrics: &[ScenarioMetrics], config: WosacConfig) -> Option<DatasetMetrics> {
    if metrics.is_empty() {
        return None;
    }
    let mean = |get: &dyn Fn(&ScenarioMetrics) -> f32| {
        (metrics.iter().map(|m| f64::from(get(m))).sum::<f64>() / metrics.len() as f64) as f32
    };
    let mut l = [0.0f32; 10];
    for (k, slot) in l.iter_mut().enumerate() {
        *slot = mean(&|m| m.likelihoods.to_array()[k]);
    }
    let likelihoods = FeatureLikelihoods::from_array(l);
    Some(DatasetMetrics {
        num_scenarios: metrics.len(),
        metametric: mean(&|m| m.metametric),
        buckets: likelihoods.buckets(config),
        likelihoods,
        average_displacement_error_m: mean(&|m| m.average_displacement_error_m),
        min_average_displacement_error_m: mean(&|m| m.min_average_displacement_error_m),
        simulated_collision_rate: mean(&|m| m.simulated_collision_rate),
        simulated_offroad_rate: mean(&|m| m.simulated_offroad_rate),
        simulated_traffic_light_violation_rate: mean(&|m| m.simulated_traffic_light_violation_rate),
    })
}

/// Per evaluated object: 3-D displacement to the log summed over the log-valid steps of all 91
/// steps, divided by their number (history steps add 0 but count).
fn displacement_errors(sim: &Trajectories, log: &Trajectories, n_eval: usize) -> Vec<f32> {
    (0..n_eval)
        .map(|i| {
            let mut sum = 0.0f64;
            let mut count = 0usize;
            for t in 0..SCENARIO_STEPS {
                if !log.valid(i, t) {
                    continue;
                }
                count += 1;
                let k = sim.index(i, t);
                let dx = sim.x[k] - log.x[k];
                let dy = sim.y[k] - log.y[k];
                let dz = sim.z[k] - log.z[k];
                sum += f64::from((dx * dx + dy * dy + dz * dz).sqrt());
            }
            (sum / count as f64) as f32
        })
        .collect()
}

/// `out[i, f] = m[i, f − 1] ∧ m[i, f + 1]` for `1 ≤ f ≤ 78`, false at both ends (per object
/// rows of 80 future steps).
fn shifted_and(mask: &[bool], n_eval: usize) -> Vec<bool> {
    let mut out = vec![false; mask.len()];
    for i in 0..n_eval {
        let row = i * SIMULATED_STEPS;
        for f in 1..SIMULATED_STEPS - 1 {
            out[row + f] = mask[row + f - 1] && mask[row + f + 1];
        }
    }
    out
}

/// Per object: whether the feature is true at any step where `mask` holds.
fn any_per_object(feature: &[bool], mask: &[bool], n_eval: usize) -> Vec<bool> {
    (0..n_eval)
        .map(|i| {
            let row = i * SIMULATED_STEPS..(i + 1) * SIMULATED_STEPS;
            feature[row.clone()]
                .iter()
                .zip(&mask[row])
                .any(|(&f, &m)| f && m)
        })
        .collect()
}

/// Fraction of true values over `[rollouts][objects]`.
fn rate(values: &[Vec<bool>]) -> f32 {
    let total: usize = values.iter().map(Vec::len).sum();
    let hits = values.iter().flatten().filter(|&&b| b).count();
    hits as f32 / total as f32
}
