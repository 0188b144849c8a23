//! Reactive agents for any scene: the Intelligent Driver Model along the agent's own logged
//! path.
//!
//! The path is the polyline of the agent's valid logged positions (history and future),
//! continued straight for 150 m past its last point (an agent with under 1 m of logged motion
//! gets a straight path along its current heading). The agent keeps its lateral offset and
//! moves along the path with IDM (desired speed: its highest logged speed, at least its current
//! one; maximum acceleration 1.5 m/s², comfortable braking 2 m/s², headway 1.2 s, standstill
//! gap 2 m), under the same acceleration and jerk limits as the synthetic world. **Leader
//! rule:** any other valid agent whose centre projects onto the path between 0 and 60 m ahead,
//! within half the two widths plus 0.5 m of it; the gap is bumper to bumper along the path,
//! the leader's speed its velocity along the path (≥ 0). An agent that has never moved faster
//! than 0.5 m/s stays where it is (parked).

use scbg_scene::{AgentState, Track};
use scbg_synth::{Idm, RefPath, closer};

use crate::kinematics::STEP_SECS;

/// How far ahead the leader rule (and the guard's conflicts) look, m.
pub(crate) const LOOKAHEAD_M: f64 = 60.0;
const EXTENSION_M: f64 = 150.0;
const PATH_STEP_M: f64 = 1.0;

/// One agent moving along its logged path under IDM.
#[derive(Debug, Clone)]
pub struct IdmAgent {
    path: RefPath,
    idm: Idm,
    parked: bool,
    /// Arclength along the path, m.
    pub s_m: f64,
    /// Lateral offset from the path, m.
    pub d_m: f64,
    /// Speed, m/s.
    pub speed_mps: f64,
    accel_mps2: f64,
}

/// A path through `points` (closer than 0.1 m merged), continued straight for 150 m; a
/// straight 150 m along `heading_rad` when they span under 1 m.
pub(crate) fn polyline_path(points: &[[f64; 2]], heading_rad: f64) -> RefPath {
    let mut pts: Vec<[f64; 2]> = Vec::with_capacity(points.len() + 1);
    for &p in points {
        if pts
            .last()
            .is_none_or(|q: &[f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]) > 0.1)
        {
            pts.push(p);
        }
    }
    let mut cum = vec![0.0];
    for w in pts.windows(2) {
        cum.push(cum.last().unwrap() + (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]));
    }
    let logged = *cum.last().unwrap();
    if logged < 1.0 {
        let p = pts[0];
        return RefPath::straight(p[0], p[1], heading_rad, EXTENSION_M);
    }
    let n = pts.len();
    let end_dir = {
        let (a, b) = (pts[n - 2], pts[n - 1]);
        let l = (b[0] - a[0]).hypot(b[1] - a[1]);
        [(b[0] - a[0]) / l, (b[1] - a[1]) / l]
    };
    RefPath::from_fn(logged + EXTENSION_M, PATH_STEP_M, move |s| {
        if s >= logged {
            let e = s - logged;
            return (
                pts[n - 1][0] + e * end_dir[0],
                pts[n - 1][1] + e * end_dir[1],
            );
        }
        let i = cum.partition_point(|&c| c <= s).clamp(1, n - 1);
        let t = (s - cum[i - 1]) / (cum[i] - cum[i - 1]);
        (
            pts[i - 1][0] + t * (pts[i][0] - pts[i - 1][0]),
            pts[i - 1][1] + t * (pts[i][1] - pts[i - 1][1]),
        )
    })
}

/// The closest leader of an agent at `(s_m, d_m)` on `path` among `others` (the leader rule
/// of the module docs): `(bumper gap m, speed along the path m/s)`.
pub(crate) fn leader_on_path(
    path: &RefPath,
    s_m: f64,
    d_m: f64,
    me: &AgentState,
    others: &[&AgentState],
) -> Option<(f64, f64)> {
    let mut best: Option<(f64, f64)> = None;
    let (sn, cs) = f64::from(me.heading_rad).sin_cos();
    for o in others {
        let (dx, dy) = (o.x_m - me.x_m, o.y_m - me.y_m);
        // Far away or behind (along the agent's heading): never a leader.
        if dx.hypot(dy) > LOOKAHEAD_M + 10.0 || dx * cs + dy * sn < -5.0 {
            continue;
        }
        // The projection searches ±40 m around its hint: centred so it covers the lookahead.
        let (s, d) = path.project(o.x_m, o.y_m, Some(s_m + 25.0));
        let ahead = s - s_m;
        let half = 0.5 * f64::from(me.width_m + o.width_m) + 0.5;
        if ahead <= 0.0 || ahead > LOOKAHEAD_M || (d - d_m).abs() > half {
            continue;
        }
        let gap = ahead - 0.5 * f64::from(me.length_m + o.length_m);
        let (sn, cs) = path.heading_at(s).sin_cos();
        let v = (f64::from(o.velocity_x_mps) * cs + f64::from(o.velocity_y_mps) * sn).max(0.0);
        best = closer(best, Some((gap, v)));
    }
    best
}

impl IdmAgent {
    /// The agent of `track` at step `current` (`None` when it is not valid there).
    pub fn new(track: &Track, current: usize) -> Option<Self> {
        let now = track.states.get(current).filter(|s| s.valid)?;
        let points: Vec<[f64; 2]> = track
            .states
            .iter()
            .filter(|s| s.valid)
            .map(|s| [s.x_m, s.y_m])
            .collect();
        let path = polyline_path(&points, f64::from(now.heading_rad));
        let top = track
            .states
            .iter()
            .filter(|s| s.valid)
            .map(|s| f64::from(s.speed_mps()))
            .fold(0.0, f64::max);
        let speed = f64::from(now.speed_mps());
        let (s_m, d_m) = path.project(now.x_m, now.y_m, None);
        Some(Self {
            path,
            idm: Idm {
                desired_speed_mps: top.max(speed).min(40.0),
                max_accel_mps2: 1.5,
                comfort_brake_mps2: 2.0,
                time_headway_s: 1.2,
                min_gap_m: 2.0,
            },
            parked: top < 0.5,
            s_m,
            d_m,
            speed_mps: speed,
            accel_mps2: 0.0,
        })
    }

    /// One step: reacts to `others` (every other valid agent's current state), returns the
    /// new state (box from `me`).
    pub fn step(&mut self, me: &AgentState, others: &[&AgentState]) -> AgentState {
        if !self.parked {
            let leader = leader_on_path(&self.path, self.s_m, self.d_m, me, others);
            let max_da = 25.0 * STEP_SECS;
            let a = self
                .idm
                .accel(self.speed_mps, leader)
                .clamp(-7.5, 3.0)
                .clamp(self.accel_mps2 - max_da, self.accel_mps2 + max_da);
            let v_next = (self.speed_mps + a * STEP_SECS).max(0.0);
            self.s_m += 0.5 * (self.speed_mps + v_next) * STEP_SECS;
            self.accel_mps2 = (v_next - self.speed_mps) / STEP_SECS;
            self.speed_mps = v_next;
        }
        let (x, y) = self.path.pose(self.s_m, self.d_m);
        let heading = if self.parked {
            f64::from(me.heading_rad)
        } else {
            self.path.heading_at(self.s_m)
        };
        let (sn, cs) = heading.sin_cos();
        AgentState {
            x_m: x,
            y_m: y,
            heading_rad: heading as f32,
            velocity_x_mps: (self.speed_mps * cs) as f32,
            velocity_y_mps: (self.speed_mps * sn) as f32,
            valid: true,
            ..*me
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn straight_track(id: i64, x0: f64, speed: f32, steps: usize) -> Track {
        Track {
            id,
            object_type: scbg_scene::ObjectType::Vehicle,
            states: (0..steps)
                .map(|t| AgentState {
                    x_m: x0 + f64::from(speed) * t as f64 * STEP_SECS,
                    length_m: 4.5,
                    width_m: 1.9,
                    height_m: 1.6,
                    velocity_x_mps: speed,
                    valid: true,
                    ..Default::default()
                })
                .collect(),
        }
    }

    #[test]
    fn brakes_for_a_stopped_leader_and_cruises_on_a_free_road() {
        let follower = straight_track(1, 0.0, 15.0, 91);
        let mut agent = IdmAgent::new(&follower, 10).unwrap();
        let stopped = AgentState {
            x_m: 60.0,
            ..follower.states[0]
        };
        let stopped = AgentState {
            velocity_x_mps: 0.0,
            ..stopped
        };
        let mut me = follower.states[10];
        for _ in 0..120 {
            me = agent.step(&me, &[&stopped]);
        }
        assert!(agent.speed_mps < 0.2, "still moving at {}", agent.speed_mps);
        let gap = stopped.x_m - me.x_m - 4.5;
        assert!((0.5..8.0).contains(&gap), "gap {gap}");
        // Alone, it keeps its logged speed along its path.
        let mut free = IdmAgent::new(&follower, 10).unwrap();
        let mut me = follower.states[10];
        for _ in 0..30 {
            me = free.step(&me, &[]);
        }
        assert!((free.speed_mps - 15.0).abs() < 0.5);
        assert!(me.y_m.abs() < 1e-6);
    }

    #[test]
    fn parked_agents_stay_and_invalid_ones_are_none() {
        let mut parked = straight_track(2, 5.0, 0.0, 91);
        let mut agent = IdmAgent::new(&parked, 10).unwrap();
        let me = agent.step(&parked.states[10], &[]);
        assert_eq!((me.x_m, me.y_m), (5.0, 0.0));
        parked.states[10].valid = false;
        assert!(IdmAgent::new(&parked, 10).is_none());
    }
}
