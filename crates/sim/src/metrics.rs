//! Rollout metrics per agent: collision (oriented-box overlap with any other valid agent),
//! off-road (the WOSAC signed distance to the road edges above 0 m), progress, jerk, average
//! speed — over the simulated steps of a rollout.

use scbg_metrics::wosac::RoadEdges;
use scbg_scene::Scene;
use serde::Serialize;

use crate::kinematics::STEP_SECS;

/// The metrics of one agent in one rollout.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AgentRolloutMetrics {
    /// Track id.
    pub id: i64,
    /// Whether its box overlaps another valid agent's at a simulated step.
    pub collision: bool,
    /// Whether it is off the road (signed road-edge distance > 0) at a simulated step;
    /// `None` when the map has no road edge.
    pub offroad: Option<bool>,
    /// Distance travelled over the simulated steps, m.
    pub progress_m: f64,
    /// Mean speed over the simulated steps, m/s (the default reward when the agent is A).
    pub avg_speed_mps: f64,
    /// Largest |longitudinal jerk|, m/s³ (speed differenced twice).
    pub max_abs_jerk_mps3: f64,
    /// Mean |longitudinal jerk|, m/s³.
    pub mean_abs_jerk_mps3: f64,
    /// Simulated steps at which the agent is valid.
    pub valid_steps: usize,
}

/// Metrics of track `track` of a simulated scene (`scene.current_step` is where the
/// simulation started; every later step is simulated). `road_edges`: the map's, built once.
pub fn agent_metrics(
    scene: &Scene,
    track: usize,
    road_edges: Option<&RoadEdges>,
) -> AgentRolloutMetrics {
    let start = scene.current_step;
    let me = &scene.tracks[track];
    let steps = start + 1..scene.num_steps();
    let mut collision = false;
    let mut offroad = road_edges.map(|_| false);
    let mut scratch = Vec::new();
    let (mut progress, mut speed_sum, mut valid_steps) = (0.0, 0.0, 0usize);
    let mut speeds = vec![f64::from(me.states[start].speed_mps())];
    for t in steps {
        let s = &me.states[t];
        if !s.valid {
            continue;
        }
        valid_steps += 1;
        let prev = &me.states[t - 1];
        if prev.valid {
            progress += (s.x_m - prev.x_m).hypot(s.y_m - prev.y_m);
        }
        speed_sum += f64::from(s.speed_mps());
        speeds.push(f64::from(s.speed_mps()));
        collision = collision
            || scene.tracks.iter().enumerate().any(|(j, o)| {
                j != track && o.states[t].valid && scbg_synth::boxes_overlap(s, &o.states[t])
            });
        if let (Some(edges), Some(off)) = (road_edges, offroad.as_mut()) {
            *off = *off
                || edges.signed_distance([s.x_m as f32, s.y_m as f32, s.z_m as f32], &mut scratch)
                    > 0.0;
        }
    }
    let accel: Vec<f64> = speeds
        .windows(2)
        .map(|w| (w[1] - w[0]) / STEP_SECS)
        .collect();
    let jerk: Vec<f64> = accel
        .windows(2)
        .map(|w| ((w[1] - w[0]) / STEP_SECS).abs())
        .collect();
    AgentRolloutMetrics {
        id: me.id,
        collision,
        offroad,
        progress_m: progress,
        avg_speed_mps: if valid_steps > 0 {
            speed_sum / valid_steps as f64
        } else {
            0.0
        },
        max_abs_jerk_mps3: jerk.iter().copied().fold(0.0, f64::max),
        mean_abs_jerk_mps3: if jerk.is_empty() {
            0.0
        } else {
            jerk.iter().sum::<f64>() / jerk.len() as f64
        },
        valid_steps,
    }
}
