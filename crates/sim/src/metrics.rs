//! Rollout metrics per agent: collision (oriented-box overlap with any other valid agent),
//! off-road (the WOSAC signed distance to the road edges above 0 m), progress, jerk, average
//! speed — over the simulated steps of a rollout.

use scbg_metrics::wosac::RoadEdges;
use scbg_scene::{AgentState, Scene};
use serde::Serialize;

use crate::kinematics::STEP_SECS;

/// The metrics of one agent in one rollout.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AgentRolloutMetrics {
    /// Track id.
    pub id: i64,
    /// Whether its box overlaps another valid agent's at a simulated step.
    pub collision: bool,
    /// The first such overlap (`None` without a collision): when, with whom and how.
    pub first_contact: Option<Contact>,
    /// Whether its box already overlaps another valid agent's at the current step, where the
    /// simulation starts from the log: a contact no action of the rollout could avoid.
    pub starts_in_contact: bool,
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

/// The first box overlap of an agent in a rollout: what a collision diagnosis needs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Contact {
    /// Simulated step of the overlap (1 = the first step after the current one).
    pub step: usize,
    /// Track id of the other agent.
    pub other_id: i64,
    /// The agent's speed at the overlap, m/s.
    pub speed_mps: f64,
    /// The other agent's speed, m/s.
    pub other_speed_mps: f64,
    /// The other's heading minus the agent's, wrapped to (−180, 180], degrees.
    pub relative_heading_deg: f64,
    /// The other's centre along the agent's heading from the agent's centre, m (> 0: ahead).
    pub other_ahead_m: f64,
    /// The other's centre to the left of the agent's heading, m.
    pub other_left_m: f64,
}

impl Contact {
    fn between(step: usize, me: &AgentState, id: i64, other: &AgentState) -> Self {
        let (sn, cs) = f64::from(me.heading_rad).sin_cos();
        let (dx, dy) = (other.x_m - me.x_m, other.y_m - me.y_m);
        let rel = f64::from(other.heading_rad - me.heading_rad).to_degrees();
        Self {
            step,
            other_id: id,
            speed_mps: f64::from(me.speed_mps()),
            other_speed_mps: f64::from(other.speed_mps()),
            relative_heading_deg: 180.0 - (180.0 - rel).rem_euclid(360.0),
            other_ahead_m: dx * cs + dy * sn,
            other_left_m: -dx * sn + dy * cs,
        }
    }
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
    let overlaps_at = |t: usize| {
        let s = &me.states[t];
        scene.tracks.iter().enumerate().find(|&(j, o)| {
            j != track && s.valid && o.states[t].valid && scbg_synth::boxes_overlap(s, &o.states[t])
        })
    };
    let starts_in_contact = overlaps_at(start).is_some();
    let mut first_contact = None;
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
        if first_contact.is_none() {
            first_contact =
                overlaps_at(t).map(|(_, o)| Contact::between(t - start, s, o.id, &o.states[t]));
        }
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
        collision: first_contact.is_some(),
        first_contact,
        starts_in_contact,
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

#[cfg(test)]
mod tests {
    use super::*;
    use scbg_scene::{ObjectType, Track};

    const STEPS: usize = 31;

    /// A car at `(x_m, y_m)` at the current step 10, driving straight at `speed` m/s along
    /// `heading_rad`.
    fn car(id: i64, x_m: f64, y_m: f64, heading_rad: f32, speed: f32) -> Track {
        let (sn, cs) = heading_rad.sin_cos();
        Track {
            id,
            object_type: ObjectType::Vehicle,
            states: (0..STEPS)
                .map(|t| {
                    let dt = (t as f64 - 10.0) * STEP_SECS;
                    AgentState {
                        x_m: x_m + f64::from(speed * cs) * dt,
                        y_m: y_m + f64::from(speed * sn) * dt,
                        heading_rad,
                        length_m: 4.5,
                        width_m: 2.0,
                        height_m: 1.6,
                        velocity_x_mps: speed * cs,
                        velocity_y_mps: speed * sn,
                        valid: true,
                        ..Default::default()
                    }
                })
                .collect(),
        }
    }

    #[test]
    fn the_first_contact_says_when_with_whom_and_where() {
        // Me at 10 m/s catching up with a car 10 m ahead at 5 m/s, turned 10° to the left
        // (closing at about 5.1 m/s); a third car far to the side. The boxes (4.5 m long)
        // first touch about 1 s later, with the slow car about 4.5 m ahead and drifting left.
        let mut scene = Scene {
            scenario_id: "contact".into(),
            timestamps_secs: (0..STEPS).map(|t| t as f64 * STEP_SECS).collect(),
            current_step: 10,
            tracks: vec![
                car(1, 0.0, 0.0, 0.0, 10.0),
                car(7, 0.0, 30.0, 0.0, 10.0),
                car(2, 10.0, 0.0, 10f32.to_radians(), 5.0),
            ],
            ..Default::default()
        };
        let m = agent_metrics(&scene, 0, None);
        assert!(m.collision && !m.starts_in_contact);
        let c = m.first_contact.expect("a contact");
        assert_eq!(c.other_id, 2);
        assert!((8..=12).contains(&c.step), "{c:?}");
        assert!((c.speed_mps - 10.0).abs() < 1e-3 && (c.other_speed_mps - 5.0).abs() < 1e-3);
        assert!((c.relative_heading_deg - 10.0).abs() < 0.01, "{c:?}");
        assert!(c.other_ahead_m > 3.5 && c.other_ahead_m < 5.0, "{c:?}");
        assert!(c.other_left_m > 0.5 && c.other_left_m < 1.5, "{c:?}");
        // The other side of the same contact: me behind, turned −10°.
        let theirs = agent_metrics(&scene, 2, None).first_contact.unwrap();
        assert_eq!((theirs.other_id, theirs.step), (1, c.step));
        assert!((theirs.relative_heading_deg + 10.0).abs() < 0.01);
        assert!(theirs.other_ahead_m < -3.5);
        // Without the slow car nothing touches.
        scene.tracks.pop();
        let m = agent_metrics(&scene, 0, None);
        assert!(!m.collision && m.first_contact.is_none());
        // A car 3 m ahead at the current step already overlaps mine: a contact at the start.
        scene.tracks.push(car(3, 3.0, 0.0, 0.0, 10.0));
        let m = agent_metrics(&scene, 0, None);
        assert!(m.starts_in_contact && m.collision);
        assert_eq!(m.first_contact.map(|c| (c.other_id, c.step)), Some((3, 1)));
    }
}
