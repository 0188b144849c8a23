//! Cut-in and make-way on a two-lane road.

use rand::Rng;
use rand_pcg::Pcg64Mcg;
use scbg_scene::{Lane, LaneType, Map, ObjectType, RoadEdge, RoadEdgeType, RoadLine, RoadLineType};

use super::{BPlan, NUM_STEPS, PairSetup, Run, arc_path, idm, noise_track, pts, vehicle_size};
use crate::CURRENT_STEP;
use crate::RefPath;
use crate::sim::{Agent, Idm, STEP_SECS, closer};

/// How far back a fully courteous B looks for a faster A to make way for.
const MAKE_WAY_LOOKBACK_M: f64 = 200.0;

/// The hardest braking the least courteous B (c = 0) asks of A when it cuts in ahead of it,
/// m/s² (MOBIL's safe deceleration; a B of courtesy c accepts `this − 6c`, down to 1 m/s²).
pub const LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2: f64 = 7.0;

/// A's reaction time in B's cut-in safety check, s: B counts on A braking this late.
pub const CUT_IN_REACTION_S: f64 = 0.5;

// ------------------------------------------------------------------------------------ cut-in

/// The random draws of one cut-in / make-way scene (geometry, A and B, slow vehicle, noise).
#[derive(Debug, Clone)]
pub struct CutinParams {
    curvature: f64,
    /// Exposed for diagnostics.
    pub cut_in_variant: bool,
    lane_width_m: f64,
    /// true: B cuts into A's lane from the right; false: B, ahead in A's lane, makes way.
    cut_in: bool,
    pair: PairSetup,
    o_size: (f64, f64),
    o_idm: Idm,
    o_s0: f64,
    lane_change_s: f64,
    noise: Vec<Vec<f64>>,
}

/// Draws the parameters of a cut-in / make-way scene (either variant with probability ½).
pub fn cutin_params(rng: &mut Pcg64Mcg) -> CutinParams {
    let cut_in = rng.random_bool(0.5);
    let a_v_des = rng.random_range(23.0..26.0);
    let a_v0 = a_v_des * rng.random_range(0.93..1.0);
    let a_s0 = 30.0;
    let (b_s0, b_v0, b_v_des) = if cut_in {
        // B just ahead at nearly A's speed, wanting to settle at a lower speed behind the
        // slow vehicle or in A's lane.
        let v = a_v0 - rng.random_range(0.5..3.0);
        (
            a_s0 + rng.random_range(10.0..30.0),
            v,
            rng.random_range(18.0..21.0),
        )
    } else {
        let v = rng.random_range(14.0..18.0);
        (a_s0 + rng.random_range(110.0..150.0), v, v)
    };
    let o_v = rng.random_range(3.0..9.0);
    let o_size = (rng.random_range(6.0..10.0), 2.4);
    let mut o_idm = idm(rng, o_v);
    o_idm.max_accel_mps2 = 0.5;
    // Draw order is part of the data: keep it.
    let curvature = rng.random_range(-1.0 / 1000.0..1.0 / 1000.0);
    let lane_width_m = rng.random_range(3.4..3.8);
    let (a_size, b_size) = (vehicle_size(rng), vehicle_size(rng));
    let (a_idm, b_idm) = (idm(rng, a_v_des), idm(rng, b_v_des));
    let o_s0 = b_s0 + rng.random_range(45.0..75.0);
    let lane_change_s = rng.random_range(3.0..4.5);
    let reaction_steps = rng.random_range(3..8);
    // Everyone starts one history (1 s) back at its speed, so that the situation above is the
    // one at the current step, where B starts deciding.
    let history_s = CURRENT_STEP as f64 * STEP_SECS;
    let o_s0 = o_s0 - o_v * history_s;
    let pair = PairSetup {
        a_size,
        b_size,
        a_idm,
        b_idm,
        a_s0: a_s0 - a_v0 * history_s,
        a_v0,
        b_s0: b_s0 - b_v0 * history_s,
        b_v0,
        reaction_steps,
    };
    CutinParams {
        cut_in_variant: cut_in,
        curvature,
        lane_width_m,
        cut_in,
        pair,
        o_size,
        o_idm,
        o_s0,
        lane_change_s,
        noise: (0..3).map(|_| noise_track(rng, NUM_STEPS)).collect(),
    }
}

/// The reference path of a cutin scene (every agent moves along it).
pub fn cutin_paths(p: &CutinParams) -> Vec<RefPath> {
    vec![arc_path(0.0, 0.0, 0.0, p.curvature, 700.0)]
}

/// Simulates a cut-in scene on its `paths` ([`cutin_paths`]) with B as `b` says; the map is
/// built only when `with_map`.
pub fn simulate_cutin(p: &CutinParams, paths: Vec<RefPath>, b: BPlan<'_>, with_map: bool) -> Run {
    let with_b = b.present();
    let w = p.lane_width_m;
    let path = &paths[0];
    let b_lane = if p.cut_in { -w } else { 0.0 };
    let b_target = if p.cut_in { 0.0 } else { -w };
    let mut agents = p.pair.agents(0, b_lane, with_b);
    let o = agents.len();
    // The slow vehicle in the right lane: B's reason to cut in, or the one B lets A avoid.
    agents.push(Agent::new(
        303,
        ObjectType::Vehicle,
        0,
        p.o_size,
        p.o_idm,
        if p.cut_in { p.o_s0 } else { p.o_s0 + 10.0 },
        -w,
        p.o_idm.desired_speed_mps,
    ));
    let mut change_start: Option<usize> = None;
    let lc_steps = (p.lane_change_s / STEP_SECS).round() as usize;
    let d_of = |start: Option<usize>, t: usize| match start {
        None => b_lane,
        Some(t0) => {
            let u = ((t - t0) as f64 / lc_steps as f64).min(1.0);
            b_lane + (b_target - b_lane) * 0.5 * (1.0 - (std::f64::consts::PI * u).cos())
        }
    };
    // Leader of an agent in lane `d` among others (by lane occupancy, within half a lane).
    let leader_in = |agents: &[Agent], me: usize, s: f64, d: f64, delayed_b: bool, delay: usize| {
        let mut best = None;
        for (j, other) in agents.iter().enumerate() {
            if j == me {
                continue;
            }
            let (s_j, d_j, v_j) = if delayed_b && j == 1 {
                other.delayed(delay)
            } else {
                (other.s, other.d, other.v)
            };
            // In my lane as soon as any part of its body is (half a lane plus half a car).
            if (d_j - d).abs() < 0.8 * w && s_j > s {
                best = closer(
                    best,
                    Some((s_j - s - 0.5 * (agents[me].length_m + other.length_m), v_j)),
                );
            }
        }
        best
    };
    for t in 0..b.steps() - 1 {
        let mut cmds = vec![0.0; agents.len()];
        let c = b.courtesy(t);
        let politeness = 2.0 * c;
        let safe_brake = LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2 - 6.0 * c;
        // B decides from the current step on, so its courtesy shows in the future to predict.
        if with_b && change_start.is_none() && t >= CURRENT_STEP {
            // MOBIL: B's advantage minus politeness × A's disadvantage, with A's safety.
            let (a, b) = (&agents[0], &agents[1]);
            let b_now = b
                .idm
                .accel(b.v, leader_in(&agents, 1, b.s, b_lane, false, 0));
            let b_new = b
                .idm
                .accel(b.v, leader_in(&agents, 1, b.s, b_target, false, 0));
            let a_now = a.idm.accel(a.v, leader_in(&agents, 0, a.s, 0.0, false, 0));
            let a_new = if p.cut_in {
                // A behind B in the target lane after the change.
                if b.s > a.s {
                    a.idm.accel(a.v, Some((a.gap_to(b.s, b.length_m), b.v)))
                } else {
                    a_now
                }
            } else {
                // B leaves A's lane: A follows whoever else is ahead.
                let mut others = agents.clone();
                others[1].d = b_target;
                a.idm.accel(a.v, leader_in(&others, 0, a.s, 0.0, false, 0))
            };
            let gap_ok = (b.s - a.s).abs() > 0.5 * (a.length_m + b.length_m) + (0.6 * a.v).max(3.0)
                && (!p.cut_in || b.s < a.s || c < 0.5 || b.s - a.s > 60.0 * c);
            // Safety: the constant deceleration A would need behind B, allowing A half a second
            // to react (IDM's own prediction is far harsher than what A really needs).
            let a_needs = if p.cut_in && b.s > a.s {
                let gap = a.gap_to(b.s, b.length_m) - (a.v - b.v).max(0.0) * CUT_IN_REACTION_S;
                (a.v - b.v).max(0.0).powi(2) / (2.0 * gap.max(0.5))
            } else {
                0.0
            };
            let safe = a_needs <= safe_brake && gap_ok;
            let incentive = (b_new - b_now) + politeness * (a_new.max(-9.0) - a_now);
            let change = if p.cut_in {
                safe && incentive > 0.3
            } else {
                // Making way: B anticipates a faster A approaching from behind within a
                // look-back distance that grows with courtesy, if the right lane has room.
                let room = leader_in(&agents, 1, b.s, b_target, false, 0)
                    .is_none_or(|(gap, _)| gap > 25.0);
                a.s < b.s && b.s - a.s < MAKE_WAY_LOOKBACK_M * c && a.v > b.v + 1.0 && room
            };
            if change {
                change_start = Some(t);
            }
        }
        if with_b && p.cut_in && change_start.is_none() {
            // A courteous B about to cut in drops back so that A can pass first.
            let (a, b) = (&agents[0], &agents[1]);
            let drop_back = c >= 0.5 && b.s > a.s - a.length_m && b.s - a.s < 60.0 * c;
            agents[1].idm.desired_speed_mps = if drop_back {
                (a.v * (1.0 - 0.4 * c)).max(5.0)
            } else {
                p.pair.b_idm.desired_speed_mps
            };
        }
        for i in 0..agents.len() {
            let me = &agents[i];
            let leader = if i == 1 {
                // B follows its own lane, and the target lane only once it has committed.
                match change_start {
                    None => leader_in(&agents, 1, me.s, b_lane, false, 0),
                    Some(_) => leader_in(&agents, 1, me.s, b_target, false, 0),
                }
            } else {
                leader_in(
                    &agents,
                    i,
                    me.s,
                    me.d,
                    i == 0 && with_b,
                    p.pair.reaction_steps,
                )
            };
            cmds[i] = me.idm.accel(me.v, leader) + p.noise[i.min(2)][t];
        }
        for (i, a) in agents.iter_mut().enumerate() {
            let d_next = if with_b && i == 1 {
                d_of(change_start, t + 1)
            } else {
                a.d
            };
            a.step(cmds[i], d_next);
        }
        b.after_step(&mut agents, t);
        let _ = o;
    }
    if !with_map {
        return Run {
            paths,
            agents,
            map: Map::default(),
        };
    }
    let lane = |id, d: f64| Lane {
        id,
        lane_type: LaneType::Freeway,
        speed_limit_mph: Some(60.0),
        polyline: pts(path.offset_points(0.0, 650.0, 1.0, |_| d)),
        left_neighbors: vec![],
        ..Default::default()
    };
    let mut l1 = lane(1, 0.0);
    let mut l2 = lane(2, -w);
    let last = l1.polyline.len() as i32 - 1;
    l1.right_neighbors.push(scbg_scene::LaneNeighbor {
        feature_id: 2,
        self_end_index: last,
        neighbor_end_index: last,
        ..Default::default()
    });
    l2.left_neighbors.push(scbg_scene::LaneNeighbor {
        feature_id: 1,
        self_end_index: last,
        neighbor_end_index: last,
        ..Default::default()
    });
    let map = Map {
        lanes: vec![l1, l2],
        road_lines: vec![RoadLine {
            id: 10,
            line_type: RoadLineType::BrokenSingleWhite,
            polyline: pts(path.offset_points(0.0, 650.0, 1.0, |_| -w / 2.0)),
        }],
        road_edges: vec![
            RoadEdge {
                id: 20,
                edge_type: RoadEdgeType::Median,
                polyline: pts(path.offset_points(0.0, 650.0, 2.0, |_| w / 2.0 + 0.5)),
            },
            RoadEdge {
                id: 21,
                edge_type: RoadEdgeType::Boundary,
                polyline: pts(path.offset_points(0.0, 650.0, 2.0, |_| -1.5 * w - 0.5)),
            },
        ],
        ..Default::default()
    };
    Run { paths, agents, map }
}
