//! Simulated scenes out: WOSAC rollouts, Scenario TFRecords and WOSAC submission shards.

use std::path::Path;

use anyhow::Context;
use scbg_metrics::wosac::{Rollouts, SimPose};
use scbg_scene::Scene;
use serde::Serialize;

use super::HORIZON_STEPS;

/// The WOSAC form of simulated scenes of one scenario: every sim agent of `log` (valid at the
/// current step), 80 poses per rollout; a pose the simulation left invalid (an agent replayed
/// past the end of its log) repeats the last valid one.
pub fn wosac_rollouts(log: &Scene, simulated: &[Scene]) -> Rollouts {
    let object_ids = scbg_metrics::wosac::sim_agent_ids(log);
    let start = log.current_step;
    let trajectories = simulated
        .iter()
        .map(|scene| {
            object_ids
                .iter()
                .map(|&id| {
                    let states = scene
                        .track_index(id)
                        .map(|i| &scene.tracks[i].states[..])
                        .unwrap_or_default();
                    let mut last = states.get(start).copied().unwrap_or_default();
                    (start + 1..=start + HORIZON_STEPS)
                        .map(|t| {
                            if let Some(s) = states.get(t).filter(|s| s.valid) {
                                last = *s;
                            }
                            SimPose {
                                x_m: last.x_m as f32,
                                y_m: last.y_m as f32,
                                z_m: last.z_m as f32,
                                heading_rad: last.heading_rad,
                            }
                        })
                        .collect()
                })
                .collect()
        })
        .collect();
    Rollouts {
        object_ids,
        trajectories,
    }
}

/// `log` with one rollout's poses as its future (velocities by finite differences), for the
/// rollout metrics of a baseline given as WOSAC rollouts.
pub fn scene_of_rollout(log: &Scene, rollouts: &Rollouts, r: usize) -> Scene {
    let start = log.current_step;
    let mut scene = log.clone();
    let len = start + 1 + HORIZON_STEPS;
    for tr in &mut scene.tracks {
        tr.states.truncate(start + 1);
        tr.states.resize(len, scbg_scene::AgentState::default());
    }
    scene.timestamps_secs = (0..len)
        .map(|k| log.timestamps_secs.first().copied().unwrap_or(0.0) + k as f64 * 0.1)
        .collect();
    if !scene.signals_per_step.is_empty() {
        scene.signals_per_step.resize(len, Vec::new());
    }
    for (o, &id) in rollouts.object_ids.iter().enumerate() {
        let Some(i) = scene.track_index(id) else {
            continue;
        };
        let tr = &mut scene.tracks[i];
        for (k, p) in rollouts.trajectories[r][o].iter().enumerate() {
            let prev = tr.states[start + k];
            let (x, y) = (f64::from(p.x_m), f64::from(p.y_m));
            tr.states[start + k + 1] = scbg_scene::AgentState {
                x_m: x,
                y_m: y,
                z_m: f64::from(p.z_m),
                heading_rad: p.heading_rad,
                velocity_x_mps: ((x - prev.x_m) / 0.1) as f32,
                velocity_y_mps: ((y - prev.y_m) / 0.1) as f32,
                valid: true,
                ..prev
            };
        }
    }
    scene
}

/// Writes simulated scenes as WOMD Scenario TFRecords (the simulated future in place of the
/// logged one), atomically.
pub fn write_scenarios(path: &Path, scenes: &[Scene]) -> anyhow::Result<usize> {
    scbg_womd::write_scenes(path, scenes).with_context(|| format!("writing {}", path.display()))
}

/// Writes WOSAC submission shards (`name.binproto-0000i-of-0000N` in `dir`) for scenarios with
/// 32 rollouts each, after checking each against the challenge's rules.
pub fn write_wosac(
    dir: &Path,
    name: &str,
    header: &scbg_womd::wosac::SubmissionHeader,
    scenarios: &[(Scene, Rollouts)],
    shards: usize,
) -> anyhow::Result<Vec<std::path::PathBuf>> {
    let inputs = scenarios
        .iter()
        .map(|(log, r)| {
            let input = crate::wosac::submission_input(&log.scenario_id, r);
            scbg_womd::wosac::validate_rollouts(log, &input)
                .with_context(|| format!("rollouts of {}", log.scenario_id))?;
            Ok(input)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    scbg_womd::wosac::write_submission_shards(dir, name, header, &inputs, shards)
        .with_context(|| format!("writing WOSAC shards into {}", dir.display()))
}

/// What `scbg sim` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum ExportFormat {
    /// WOMD Scenario TFRecord (`rollouts.tfrecord`, one scenario per rollout).
    #[default]
    Scenario,
    /// WOSAC submission shard (`NAME.binproto-00000-of-00001`, 32 rollouts).
    Wosac,
}
