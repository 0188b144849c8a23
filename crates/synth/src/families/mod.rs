//! The scene families. Each draws its parameters once (`*Params`), then `simulate` runs them
//! with or without vehicle B, so the "A alone" counterfactual shares every random draw.
//!
//! Courtesy `c ∈ [0, 1]` of B acts through a different manoeuvre per family:
//! - **merge**: B on an on-ramp goes ahead of A only when its lead time exceeds an accepted gap
//!   `−0.5 + 3.5c` s; a courteous B that goes first speeds up (`+15 % c` desired speed), one
//!   that yields waits at the end of the acceleration lane until A has passed;
//! - **crossing**: B at a stop-controlled approach crosses before A only when A's time to the
//!   conflict point exceeds B's clearing time by `−2.5 + 5c` s, otherwise waits at the stop line;
//! - **cutin**: either B, blocked by a slow vehicle in the next lane, changes into A's lane
//!   with MOBIL politeness `2c`, accepting that A must brake at up to `7 − 6c` m/s²
//!   (a courteous B drops back to let A pass first), or B, slower
//!   and ahead of A in A's lane, moves out of A's way to the right once A approaches within
//!   `200c` m;
//! - **letin**: the merge turned round: A merges from an on-ramp and B is on the main lane.
//!   B lets A in when A's lead at the merge exceeds `1.5 − 4c` s: it then keeps behind an A
//!   ahead of it at a 1.8 s headway until A is in its lane; otherwise it presses on at 1.05 ×
//!   its desired speed while A is beside or ahead of it. A merges ahead only when B's front, as A sees it, is an accepted
//!   0.8–1.6 s behind A's rear, and otherwise waits at the end of the acceleration lane for B
//!   to pass;
//! - **following**: B leads A in A's lane on a procedural road (1–4 lanes, curves down to a
//!   40 m radius, limits 8–33 m/s) and keeps a steady speed near the limit when courteous,
//!   dawdles at `(base + 0.2c)` × the limit and brakes needlessly at `(1 − c)` × 1.5–3.5 m/s²
//!   when not;
//! - **roundabout**: a single-lane roundabout (radius 15–30 m, 3–4 arms 72–144° apart, joined to
//!   the ring by tangent arcs of 0.6–0.9 × its radius) where A and B meet at one entry. Either B circulates and lets A in when A's
//!   lead at the merge point exceeds `1.2 − 3.5c` s (keeping behind A at a 1.8 s headway; else
//!   it presses on at 1.05 × its desired speed), or B enters ahead of a circulating A only when
//!   its lead exceeds `0.3 + 2.7c` s (then `+15 % c` desired speed), and otherwise waits at the
//!   yield line until A has passed. An entering vehicle yields to every circulating one it
//!   would not be an accepted 0.8–1.6 s ahead of;
//! - **leftturn**: B, oncoming on A's two-lane road, turns left across A's lane into a side
//!   road leaving on A's right at 60–120° (turn radius 9–15 m, taken at 3 m/s² lateral). B
//!   turns before A only when A's time to where B's body is in A's lane exceeds B's time to
//!   clear it by `−2 + 5c` s (then at `+20 % c` desired speed), otherwise it waits 2 m short
//!   of A's lane until A has passed; A reacts as at a crossing. Not in the default world
//!   ([`crate::Family::DEFAULT`]);
//! - **zipper**: the let-in at a lane drop: A's lane of a two-lane road (limit 11–22 m/s) ends
//!   in a 40–80 m taper, B in the through lane beside it, behind a slower queue, lets A in
//!   when A's lead at the merge exceeds `0.6 − 0.8c` s (dropping back behind an A beside it at
//!   up to 3 m/s²) or presses on. Not in the default world.

use rand::Rng;
use rand_pcg::Pcg64Mcg;
use scbg_scene::{Map, MapPoint, ObjectType};

use crate::path::RefPath;
use crate::sim::{Agent, Idm};

/// Steps of a generated scene: 11 history (including current) + 80 future, at 10 Hz.
pub const NUM_STEPS: usize = 91;
/// Track id of vehicle A (the SDC).
pub const A_ID: i64 = 101;
/// Track id of vehicle B.
pub const B_ID: i64 = 202;

/// The output of one simulation run.
#[derive(Debug)]
pub struct Run {
    /// Reference paths the agents move along (path 0 is A's).
    pub paths: Vec<RefPath>,
    /// Simulated agents with their whole history: A first, then B (when simulated), then others.
    pub agents: Vec<Agent>,
    /// The scene's map.
    pub map: Map,
}

pub(super) fn mp((x, y): (f64, f64)) -> MapPoint {
    MapPoint {
        x_m: x,
        y_m: y,
        z_m: 0.0,
    }
}

pub(super) fn pts(v: Vec<(f64, f64)>) -> Vec<MapPoint> {
    v.into_iter().map(mp).collect()
}

/// A circular arc of curvature `k` (straight when 0) starting at `(x0, y0)` heading `h0`.
pub(super) fn arc_path(x0: f64, y0: f64, h0: f64, k: f64, length_m: f64) -> RefPath {
    RefPath::from_fn(length_m, 1.0, move |s| {
        let (dx, dy) = if k.abs() < 1e-9 {
            (s, 0.0)
        } else {
            ((k * s).sin() / k, (1.0 - (k * s).cos()) / k)
        };
        let (sn, cs) = h0.sin_cos();
        (x0 + cs * dx - sn * dy, y0 + sn * dx + cs * dy)
    })
}

pub(super) fn vehicle_size(rng: &mut Pcg64Mcg) -> (f64, f64) {
    (rng.random_range(4.2..5.2), rng.random_range(1.8..2.1))
}

pub(super) fn idm(rng: &mut Pcg64Mcg, desired_speed_mps: f64) -> Idm {
    Idm {
        desired_speed_mps,
        max_accel_mps2: rng.random_range(1.2..2.0),
        comfort_brake_mps2: rng.random_range(1.8..2.6),
        time_headway_s: rng.random_range(1.0..1.6),
        min_gap_m: rng.random_range(1.5..2.5),
    }
}

/// Small, smooth acceleration noise (an AR(1) process) for every agent and step.
pub(super) fn noise_track(rng: &mut Pcg64Mcg, n: usize) -> Vec<f64> {
    let mut e = 0.0;
    (0..n)
        .map(|_| {
            e = 0.9 * e + 0.08 * (rng.random::<f64>() - 0.5);
            e
        })
        .collect()
}

/// How vehicle B behaves in one run of a scene.
#[derive(Debug, Clone, Copy)]
pub enum BPlan<'a> {
    /// No B: the "A alone" counterfactual.
    Absent,
    /// B simulated with courtesy `history` before the current step ([`crate::CURRENT_STEP`])
    /// and `future` from it on (the logged run has both equal).
    Simulated {
        /// Courtesy while the history is recorded.
        history: f64,
        /// Courtesy from the current step on.
        future: f64,
    },
    /// B replayed: its `(s, d, v)` along its own reference path at every step
    /// ([`NUM_STEPS`] entries, or fewer to simulate only that many steps); B's own decisions
    /// are ignored, everyone else reacts to it.
    Replayed(&'a [(f64, f64, f64)]),
}

impl BPlan<'_> {
    /// Steps a run simulates: [`NUM_STEPS`], or as many as a replayed B has states.
    pub fn steps(&self) -> usize {
        match self {
            Self::Replayed(states) => states.len().clamp(1, NUM_STEPS),
            _ => NUM_STEPS,
        }
    }

    /// Whether B takes part.
    pub fn present(&self) -> bool {
        !matches!(self, Self::Absent)
    }

    /// B's courtesy when commanding step `t` (irrelevant, 0.5, when replayed or absent).
    pub fn courtesy(&self, t: usize) -> f64 {
        match *self {
            Self::Simulated { history, future } => {
                if t < crate::CURRENT_STEP {
                    history
                } else {
                    future
                }
            }
            _ => 0.5,
        }
    }

    /// After every agent stepped to `t + 1`: a replayed B is put where the replay says.
    pub(super) fn after_step(&self, agents: &mut [Agent], t: usize) {
        if let Self::Replayed(states) = self {
            let (s, d, v) = states[t + 1];
            agents[1].replace_state(s, d, v);
        }
    }
}

/// The documented reaction of a vehicle on A's road to B merging into its lane (merge family):
/// B counts (as a leader, when ahead) once its centre is within `0.75 w` of the lane centre, or
/// once it has left the acceleration lane's centre line by 0.1 m towards A's lane (`|d| < w −
/// 0.1`) while moving towards it (lateral rate over 0.05 m/s). Only B's observable motion
/// counts, never B's intentions, so a replayed B (any future, logged or generated) gets the same
/// reaction as a simulated one.
pub(super) fn merging_into_lane(d: f64, d_rate: f64, lane_width_m: f64) -> bool {
    d.abs() < 0.75 * lane_width_m || (d.abs() < lane_width_m - 0.1 && d_rate * d.signum() < -0.05)
}

/// Distance from B's stop line to the conflict zone's entry along B's path (crossing family).
pub(super) const STOP_LINE_TO_ZONE_M: f64 = 2.0;

/// The documented reaction of A to B at a crossing (crossing family): B occupies the conflict
/// zone, for A, while B is within 25 m before the zone's entry and has not cleared it, and is
/// either past its stop line (centre 0.5 m beyond it), with its front bumper already in the
/// zone, or too fast to stop at the line comfortably (the deceleration it needs,
/// `v² / 2·distance`, is over 3.5 m/s²). A then treats the zone's entry as a standing obstacle
/// until it is clear (or A is already in it).
pub(super) fn committed_to_cross(s: f64, v: f64, stop_s: f64, half_length_m: f64) -> bool {
    s > stop_s + 0.5
        || s + half_length_m > stop_s + STOP_LINE_TO_ZONE_M
        || v * v / (2.0 * (stop_s - s).max(0.1)) > 3.5
}

/// Where B's path crosses A's way (crossing and left-turn families), and the rules both meet it
/// by. Along B's path: B's front enters A's way at `b_in_s`, B's centre has left it at
/// `b_out_s`; along A's path: A's front reaches B's way at `a_in_s`, and it has passed at
/// `a_out_s`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Conflict {
    pub b_in_s: f64,
    pub b_out_s: f64,
    pub a_in_s: f64,
    pub a_out_s: f64,
}

impl Conflict {
    /// B's stop line, [`STOP_LINE_TO_ZONE_M`] before the zone along B's path.
    pub(super) fn stop_s(&self) -> f64 {
        self.b_in_s - STOP_LINE_TO_ZONE_M
    }

    /// B's gap acceptance: B goes first when A's time to the zone exceeds B's time to clear it
    /// (each at its speed now) by `accept_s`.
    pub(super) fn b_goes_first(&self, a: &Agent, b: &Agent, accept_s: f64) -> bool {
        let tau_a = (self.a_in_s - a.s - a.length_m / 2.0) / a.v.max(1.0);
        let tau_b_clear = (self.b_out_s + b.length_m - b.s) / b.v.max(3.0);
        tau_a - tau_b_clear > accept_s
    }

    /// A's reaction to B, by B's observable motion only (seen `reaction_steps` late): while B
    /// is within 25 m before the zone, committed to it ([`committed_to_cross`]) and not clear
    /// of it, and A has not reached it, A treats the zone's entry as a standing obstacle.
    pub(super) fn a_leader(
        &self,
        a: &Agent,
        b: &Agent,
        reaction_steps: usize,
    ) -> Option<(f64, f64)> {
        let (s_b, _, v_b) = b.delayed(reaction_steps);
        let b_len = b.length_m;
        let b_in_or_coming = s_b > self.b_in_s - b_len - 25.0
            && committed_to_cross(s_b, v_b, self.stop_s(), b_len / 2.0);
        let b_not_cleared = s_b < self.b_out_s + b_len;
        let a_before = a.s + a.length_m / 2.0 < self.a_in_s + 1.0;
        (b_in_or_coming && b_not_cleared && a_before)
            .then(|| (self.a_in_s - 1.0 - a.s - a.length_m / 2.0, 0.0))
    }

    /// B's stop line as a standing obstacle, for a B that waits and has not passed it.
    pub(super) fn b_stop_leader(&self, b: &Agent) -> Option<(f64, f64)> {
        let stop_s = self.stop_s();
        (b.s < stop_s + 0.5).then(|| (stop_s - b.s - b.length_m / 2.0, 0.0))
    }
}

/// Orients every road edge the way WOMD does — the road on its left, so that the WOSAC signed
/// distance is negative on the road and positive off it: an edge whose nearest lane-centre
/// point (from the middle of the edge) lies on its right is reversed. Closed polylines (islands)
/// are drawn oriented by their family and left as they are.
pub(crate) fn orient_road_edges(map: &mut Map) {
    let centres: Vec<(f64, f64)> = map
        .lanes
        .iter()
        .flat_map(|l| l.polyline.iter().map(|p| (p.x_m, p.y_m)))
        .collect();
    if centres.is_empty() {
        return;
    }
    for edge in &mut map.road_edges {
        let n = edge.polyline.len();
        if n < 2 {
            continue;
        }
        let (first, last) = (&edge.polyline[0], &edge.polyline[n - 1]);
        if (first.x_m - last.x_m).hypot(first.y_m - last.y_m) < 1.0 {
            continue;
        }
        let (a, b) = (&edge.polyline[(n - 1) / 2], &edge.polyline[(n - 1) / 2 + 1]);
        let mid = (0.5 * (a.x_m + b.x_m), 0.5 * (a.y_m + b.y_m));
        let nearest = centres
            .iter()
            .copied()
            .min_by(|p, q| {
                let d = |r: &(f64, f64)| (r.0 - mid.0).hypot(r.1 - mid.1);
                d(p).total_cmp(&d(q))
            })
            .expect("non-empty");
        let cross = (nearest.0 - a.x_m) * (b.y_m - a.y_m) - (nearest.1 - a.y_m) * (b.x_m - a.x_m);
        if cross > 0.0 {
            edge.polyline.reverse();
        }
    }
}

/// The lateral acceleration (m/s²) drivers keep to on the connectors, turns and rings: each slows
/// for the curves within [`CURVE_LOOKAHEAD_S`] ahead.
pub(super) const LATERAL_MPS2: f64 = 3.0;
/// How far ahead (s, at the current speed, plus 5 m) drivers look for curves.
pub(super) const CURVE_LOOKAHEAD_S: f64 = 2.5;

/// The speed (m/s) at which each metre of `path` is driven at [`LATERAL_MPS2`] (its
/// curvature over ±2 m).
pub(super) fn curve_speeds(path: &RefPath) -> Vec<f64> {
    let n = path.length_m().floor() as usize + 1;
    (0..n)
        .map(|i| {
            let s = i as f64;
            let turn =
                scbg_scene::wrap_angle_rad(path.heading_at(s + 2.0) - path.heading_at(s - 2.0));
            let curvature = turn.abs() / 4.0;
            (LATERAL_MPS2 / curvature.max(1e-6)).sqrt()
        })
        .collect()
}

/// The speed the curves ahead of arclength `s` allow at speed `v` ([`curve_speeds`]).
pub(super) fn curve_limit(speeds: &[f64], s: f64, v: f64) -> f64 {
    let from = (s.max(0.0) as usize).min(speeds.len() - 1);
    let to = ((s + v * CURVE_LOOKAHEAD_S + 5.0).max(0.0) as usize).clamp(from, speeds.len() - 1);
    speeds[from..=to]
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
}

/// The speed limit (m/s) from which a procedural road is typed Freeway (below it SurfaceStreet).
const FREEWAY_FROM_MPS: f64 = 20.0;

/// A procedural road's lane type and speed limit (mph, rounded to 5 as signs are) for its
/// limit in m/s: SurfaceStreet below [`FREEWAY_FROM_MPS`], else Freeway.
pub(super) fn road_class(speed_limit_mps: f64) -> (scbg_scene::LaneType, Option<f64>) {
    let lane_type = if speed_limit_mps < FREEWAY_FROM_MPS {
        scbg_scene::LaneType::SurfaceStreet
    } else {
        scbg_scene::LaneType::Freeway
    };
    (
        lane_type,
        Some((speed_limit_mps / 0.447_04 / 5.0).round() * 5.0),
    )
}

/// Background traffic as the families draw it: `(s, v, size, idm)` per vehicle.
pub(super) type Background = (f64, f64, (f64, f64), Idm);

/// The background vehicles (ids 300, 301, …) on reference path `path`, at lateral offset 0.
pub(super) fn background_agents(
    background: &[Background],
    path: usize,
) -> impl Iterator<Item = Agent> + '_ {
    background
        .iter()
        .enumerate()
        .map(move |(k, &(s, v, size, m))| {
            Agent::new(
                300 + k as i64,
                ObjectType::Vehicle,
                path,
                size,
                m,
                s,
                0.0,
                v,
            )
        })
}

/// Vehicles A and B as every family sets them up (values drawn by the family, in its order).
#[derive(Debug, Clone)]
pub(super) struct PairSetup {
    pub a_size: (f64, f64),
    pub b_size: (f64, f64),
    pub a_idm: Idm,
    pub b_idm: Idm,
    pub a_s0: f64,
    pub a_v0: f64,
    pub b_s0: f64,
    pub b_v0: f64,
    /// A's reaction delay to B, steps.
    pub reaction_steps: usize,
}

impl PairSetup {
    /// A and B starting at `(s0, v0)` on their paths, with drawn sizes, IDM parameters for
    /// their desired speeds `v_des`, and A's reaction delay (drawn in that order: the draw
    /// order is part of the data).
    pub(super) fn draw(
        rng: &mut Pcg64Mcg,
        (a_v_des, a_s0, a_v0): (f64, f64, f64),
        (b_v_des, b_s0, b_v0): (f64, f64, f64),
    ) -> Self {
        let (a_size, b_size) = (vehicle_size(rng), vehicle_size(rng));
        let (a_idm, b_idm) = (idm(rng, a_v_des), idm(rng, b_v_des));
        Self {
            a_size,
            b_size,
            a_idm,
            b_idm,
            a_s0,
            a_v0,
            b_s0,
            b_v0,
            reaction_steps: rng.random_range(3..8),
        }
    }

    /// A on path 0 at lateral offset 0, then (with B) B on `b_path` at offset `b_d0`.
    pub(super) fn agents(&self, b_path: usize, b_d0: f64, with_b: bool) -> Vec<Agent> {
        let mut agents = vec![Agent::new(
            A_ID,
            ObjectType::Vehicle,
            0,
            self.a_size,
            self.a_idm,
            self.a_s0,
            0.0,
            self.a_v0,
        )];
        if with_b {
            agents.push(Agent::new(
                B_ID,
                ObjectType::Vehicle,
                b_path,
                self.b_size,
                self.b_idm,
                self.b_s0,
                b_d0,
                self.b_v0,
            ));
        }
        agents
    }
}

mod crossing;
mod cutin;
mod following;
mod leftturn;
mod letin;
mod merge;
mod roundabout;
mod zipper;

pub use crossing::{CrossingParams, crossing_params, crossing_paths, simulate_crossing};
pub use cutin::{
    CUT_IN_REACTION_S, CutinParams, LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2, cutin_params, cutin_paths,
    simulate_cutin,
};
pub use following::{FollowingParams, following_params, following_paths, simulate_following};
pub use leftturn::{LeftTurnParams, leftturn_params, leftturn_paths, simulate_leftturn};
pub use letin::{
    LETIN_HEADWAY_S, LETIN_RULE, LetInRule, LetinParams, PRESS_ON_SHARE, letin_params, letin_paths,
    simulate_letin,
};
pub use merge::{MergeParams, merge_params, merge_paths, simulate_merge};
pub use roundabout::{
    RoundaboutParams, roundabout_enters_first, roundabout_lets_in, roundabout_params,
    roundabout_paths, simulate_roundabout,
};
pub use zipper::{ZIPPER_RULE, zipper_params};
