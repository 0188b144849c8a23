//! Longitudinal dynamics (IDM), agents moving along reference paths, and recording to tracks.

use scbg_scene::{AgentState, ObjectType, Track};

use crate::path::RefPath;

/// Seconds per simulation (and scene) step: 10 Hz.
pub const STEP_SECS: f64 = 0.1;
/// Physical limits every agent obeys.
pub const MAX_BRAKE_MPS2: f64 = 7.5;
pub const MAX_ACCEL_MPS2: f64 = 3.0;
pub const MAX_JERK_MPS3: f64 = 25.0;

/// Intelligent Driver Model parameters.
#[derive(Debug, Clone, Copy)]
pub struct Idm {
    /// Speed on a free road, m/s.
    pub desired_speed_mps: f64,
    /// Maximum acceleration, m/s².
    pub max_accel_mps2: f64,
    /// Comfortable deceleration, m/s² (positive).
    pub comfort_brake_mps2: f64,
    /// Desired time headway, s.
    pub time_headway_s: f64,
    /// Standstill gap, m.
    pub min_gap_m: f64,
}

impl Idm {
    /// IDM acceleration; `leader` is `(bumper gap m, leader speed m/s)`.
    pub fn accel(&self, v: f64, leader: Option<(f64, f64)>) -> f64 {
        let free = 1.0 - (v / self.desired_speed_mps.max(0.1)).powi(4);
        let interaction = leader.map_or(0.0, |(gap, v_lead)| {
            let dv = v - v_lead;
            let s_star = self.min_gap_m
                + (v * self.time_headway_s
                    + v * dv / (2.0 * (self.max_accel_mps2 * self.comfort_brake_mps2).sqrt()))
                .max(0.0);
            (s_star / gap.max(0.1)).powi(2)
        });
        self.max_accel_mps2 * (free - interaction)
    }
}

/// The closer of two optional leaders (smaller gap).
pub fn closer(a: Option<(f64, f64)>, b: Option<(f64, f64)>) -> Option<(f64, f64)> {
    match (a, b) {
        (Some(x), Some(y)) => Some(if x.0 <= y.0 { x } else { y }),
        (x, None) => x,
        (None, y) => y,
    }
}

/// One simulated agent: arclength `s` along `path`, lateral offset `d`, speed `v`.
#[derive(Debug, Clone)]
pub struct Agent {
    pub id: i64,
    pub kind: ObjectType,
    pub path: usize,
    pub length_m: f64,
    pub width_m: f64,
    pub idm: Idm,
    pub s: f64,
    pub d: f64,
    pub v: f64,
    pub a: f64,
    /// Per-step history of (s, d, v), including the initial state.
    pub history: Vec<(f64, f64, f64)>,
}

impl Agent {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        id: i64,
        kind: ObjectType,
        path: usize,
        (length_m, width_m): (f64, f64),
        idm: Idm,
        s: f64,
        d: f64,
        v: f64,
    ) -> Self {
        Self {
            id,
            kind,
            path,
            length_m,
            width_m,
            idm,
            s,
            d,
            v,
            a: 0.0,
            history: vec![(s, d, v)],
        }
    }

    /// State `delay` steps ago (clamped to the first).
    pub fn delayed(&self, delay: usize) -> (f64, f64, f64) {
        self.history[self.history.len().saturating_sub(1 + delay)]
    }

    /// Applies a commanded acceleration under jerk and acceleration limits, advances one step.
    pub fn step(&mut self, accel_cmd: f64, d_next: f64) {
        let max_da = MAX_JERK_MPS3 * STEP_SECS;
        let a = accel_cmd
            .clamp(-MAX_BRAKE_MPS2, MAX_ACCEL_MPS2)
            .clamp(self.a - max_da, self.a + max_da);
        let v_next = (self.v + a * STEP_SECS).max(0.0);
        // Exact distance for the (possibly clipped at zero) speed change.
        self.s += 0.5 * (self.v + v_next) * STEP_SECS;
        self.a = (v_next - self.v) / STEP_SECS;
        self.v = v_next;
        self.d = d_next;
        self.history.push((self.s, self.d, self.v));
    }

    /// Puts the agent at a given state instead of the one its last step reached (a replayed
    /// agent): the last history entry is replaced, the acceleration follows from the speeds.
    pub fn replace_state(&mut self, s: f64, d: f64, v: f64) {
        let v_prev = self.history.len().checked_sub(2).map(|i| self.history[i].2);
        self.a = v_prev.map_or(0.0, |vp| (v - vp) / STEP_SECS);
        (self.s, self.d, self.v) = (s, d, v);
        *self.history.last_mut().expect("an agent has a state") = (s, d, v);
    }

    /// Lateral rate of the state `delay` steps ago, m/s (0 at the first step).
    pub fn delayed_lateral_rate(&self, delay: usize) -> f64 {
        let n = self.history.len();
        let i = n.saturating_sub(1 + delay);
        if i == 0 {
            0.0
        } else {
            (self.history[i].1 - self.history[i - 1].1) / STEP_SECS
        }
    }

    /// Bumper-to-bumper gap to an agent ahead on the same path.
    pub fn gap_to(&self, s_other: f64, other_length_m: f64) -> f64 {
        s_other - self.s - 0.5 * (self.length_m + other_length_m)
    }
}

/// Converts an agent's history into a track: positions from (path, s, d), velocity by finite
/// differences of positions, heading along the motion (the path's heading when nearly still).
pub fn record_track(agent: &Agent, paths: &[RefPath], num_steps: usize) -> Track {
    let n = agent.history.len().min(num_steps);
    Track {
        id: agent.id,
        object_type: agent.kind,
        states: (0..n)
            .map(|t| recorded_state(agent, paths, num_steps, t))
            .collect(),
    }
}

/// State `t` of [`record_track`]`(agent, paths, num_steps)`, computed alone.
pub fn recorded_state(agent: &Agent, paths: &[RefPath], num_steps: usize, t: usize) -> AgentState {
    let path = &paths[agent.path];
    let n = agent.history.len().min(num_steps);
    let pos = |i: usize| {
        let (s, d, _) = agent.history[i];
        path.pose(s, d)
    };
    let (a, b) = if t == 0 {
        (0, 1)
    } else if t + 1 == n {
        (n - 2, n - 1)
    } else {
        (t - 1, t + 1)
    };
    let k = (b - a) as f64 * STEP_SECS;
    let ((xa, ya), (xb, yb)) = (pos(a), pos(b));
    let (vx, vy) = ((xb - xa) / k, (yb - ya) / k);
    let heading = if vx.hypot(vy) > 0.5 {
        vy.atan2(vx)
    } else {
        path.heading_at(agent.history[t].0)
    };
    let (x, y) = pos(t);
    AgentState {
        x_m: x,
        y_m: y,
        z_m: 0.0,
        length_m: agent.length_m as f32,
        width_m: agent.width_m as f32,
        height_m: if agent.kind == ObjectType::Pedestrian {
            1.75
        } else {
            1.6
        },
        heading_rad: heading as f32,
        velocity_x_mps: vx as f32,
        velocity_y_mps: vy as f32,
        valid: true,
    }
}

/// Whether two oriented boxes overlap (separating-axis test).
pub fn boxes_overlap(a: &AgentState, b: &AgentState) -> bool {
    let corners = |s: &AgentState| {
        let (sn, cs) = f64::from(s.heading_rad).sin_cos();
        let (hl, hw) = (f64::from(s.length_m) / 2.0, f64::from(s.width_m) / 2.0);
        [(1.0, 1.0), (1.0, -1.0), (-1.0, -1.0), (-1.0, 1.0)].map(|(u, w)| {
            (
                s.x_m + u * hl * cs - w * hw * sn,
                s.y_m + u * hl * sn + w * hw * cs,
            )
        })
    };
    let (ca, cb) = (corners(a), corners(b));
    for s in [a, b] {
        let (sn, cs) = f64::from(s.heading_rad).sin_cos();
        for axis in [(cs, sn), (-sn, cs)] {
            let proj = |c: &[(f64, f64); 4]| {
                let p = c.map(|(x, y)| x * axis.0 + y * axis.1);
                (
                    p.iter().copied().fold(f64::INFINITY, f64::min),
                    p.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                )
            };
            let ((a0, a1), (b0, b1)) = (proj(&ca), proj(&cb));
            if a1 < b0 || b1 < a0 {
                return false;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn idm_free_road_and_braking() {
        let idm = Idm {
            desired_speed_mps: 20.0,
            max_accel_mps2: 1.5,
            comfort_brake_mps2: 2.0,
            time_headway_s: 1.5,
            min_gap_m: 2.0,
        };
        assert!((idm.accel(0.0, None) - 1.5).abs() < 1e-9);
        assert!(idm.accel(20.0, None).abs() < 1e-9);
        assert!(idm.accel(20.0, Some((5.0, 0.0))) < -7.5);
    }

    #[test]
    fn overlap_test() {
        let s = |x: f64, h: f32| AgentState {
            x_m: x,
            length_m: 4.0,
            width_m: 2.0,
            heading_rad: h,
            valid: true,
            ..Default::default()
        };
        assert!(boxes_overlap(&s(0.0, 0.0), &s(3.9, 0.0)));
        assert!(!boxes_overlap(&s(0.0, 0.0), &s(4.1, 0.0)));
        assert!(boxes_overlap(
            &s(0.0, 0.0),
            &s(2.9, std::f32::consts::FRAC_PI_2)
        ));
        assert!(!boxes_overlap(
            &s(0.0, 0.0),
            &s(3.1, std::f32::consts::FRAC_PI_2)
        ));
    }
}
