//! Following: B leads A in A's lane on a procedural multi-lane road.
//!
//! The road is drawn per scene: 1–4 lanes in one direction, lanes 2.8–4.0 m wide, a speed limit
//! of 8–33 m/s, and a centre line whose curvature changes piece by piece through linear
//! (clothoid) transitions between straight runs and arcs, down to a 40 m radius where the speed
//! limit allows it (lateral acceleration at the limit ≤ 2 m/s²). A drives in one of the lanes
//! with B ahead of it; other vehicles drive in the other lanes and behind A.
//!
//! Courtesy acts through how B leads: a courteous B keeps a steady speed near the limit, a
//! discourteous one dawdles below it and brakes for no reason (B's desired speed is
//! `(base + 0.2c)` × the limit; 1–3 needless brake taps of 1–2 s at `(1 − c)` × 1.5–3.5 m/s²,
//! at drawn times, some in the history). A follows B by IDM with its reaction delay once B is
//! in A's lane (lane occupancy, B's observable position only), so a replayed B gets the same
//! reaction. Here courtesy means *going*, where at a merge it means *yielding*: a generator
//! that learned "courteous ≈ slow" from the other families fails here.

use rand::Rng;
use rand_pcg::Pcg64Mcg;
use scbg_scene::{
    Lane, LaneNeighbor, Map, ObjectType, RoadEdge, RoadEdgeType, RoadLine, RoadLineType,
};

use super::{BPlan, NUM_STEPS, PairSetup, Run, idm, noise_track, pts, vehicle_size};
use crate::CURRENT_STEP;
use crate::RefPath;
use crate::sim::{Agent, Idm, STEP_SECS, closer};

/// Length of the procedural road's centre line, metres.
const ROAD_M: f64 = 700.0;
/// The tightest radius of the procedural road, metres.
const MIN_RADIUS_M: f64 = 40.0;
/// Beyond this heading (relative to the start) the road's next curve turns back, rad.
const TURN_BACK_RAD: f64 = std::f64::consts::FRAC_PI_3;
/// The most the road's heading turns from its start, rad (a curve stops there).
const MAX_HEADING_RAD: f64 = 1.75;
/// Lateral acceleration at the speed limit that bounds the road's curvature, m/s².
const MAX_LATERAL_MPS2: f64 = 2.0;

/// One needless brake tap of B: start step, length in steps, deceleration at c = 0 (m/s²).
#[derive(Debug, Clone, Copy)]
struct BrakeTap {
    start: usize,
    steps: usize,
    decel_mps2: f64,
}

/// The random draws of one following scene.
#[derive(Debug, Clone)]
pub struct FollowingParams {
    /// Curvature profile: `(arclength, curvature)` knots, linear in between (1/m).
    curvature_knots: Vec<(f64, f64)>,
    lanes: usize,
    /// A's (and B's) lane, counted from the right.
    a_lane: usize,
    lane_width_m: f64,
    speed_limit_mps: f64,
    /// B's desired speed at c = 0, as a share of the limit.
    b_base: f64,
    taps: Vec<BrakeTap>,
    pair: PairSetup,
    /// Other vehicles.
    others: Vec<OtherCar>,
    noise: Vec<Vec<f64>>,
}

/// Another vehicle: lane (from the right), s0, v0, size, IDM.
type OtherCar = (usize, f64, f64, (f64, f64), Idm);

/// Draws the parameters of a following scene.
pub fn following_params(rng: &mut Pcg64Mcg) -> FollowingParams {
    let lanes = rng.random_range(1..=4usize);
    let a_lane = rng.random_range(0..lanes);
    let lane_width_m = rng.random_range(2.8..4.0);
    let speed_limit_mps: f64 = rng.random_range(8.0..33.0);
    let k_max = (1.0 / MIN_RADIUS_M).min(MAX_LATERAL_MPS2 / speed_limit_mps.powi(2));
    let mut curvature_knots = vec![(0.0, 0.0)];
    let mut s = rng.random_range(0.0..80.0);
    curvature_knots.push((s, 0.0));
    // The road's heading relative to its start: curves turn back towards it beyond
    // [`TURN_BACK_RAD`] and stop at [`MAX_HEADING_RAD`], so the road never crosses itself.
    let (mut heading, mut k_prev) = (0.0f64, 0.0);
    while s < ROAD_M {
        let transition = rng.random_range(20.0..60.0);
        let k = if rng.random_bool(0.35) {
            0.0
        } else {
            let mut sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            if heading.abs() > TURN_BACK_RAD {
                sign = -heading.signum();
            }
            sign * rng.random_range(0.3..1.0) * k_max
        };
        s += transition;
        heading += 0.5 * (k_prev + k) * transition;
        curvature_knots.push((s, k));
        let mut plateau_m = rng.random_range(30.0..160.0);
        if k != 0.0 {
            let room = (MAX_HEADING_RAD - (heading + k * plateau_m).abs()).min(0.0);
            plateau_m = (plateau_m + room / k.abs()).max(0.0);
        }
        heading += k * plateau_m;
        s += plateau_m;
        curvature_knots.push((s, k));
        k_prev = k;
    }
    let b_base = rng.random_range(0.65..0.85);
    let taps = (0..rng.random_range(1..=3))
        .map(|_| BrakeTap {
            start: rng.random_range(0..NUM_STEPS - 10),
            steps: rng.random_range(10..=20),
            decel_mps2: rng.random_range(1.5..3.5),
        })
        .collect();
    let a_v_des = speed_limit_mps * rng.random_range(1.0..1.1);
    let b_v0 = speed_limit_mps * rng.random_range(0.7..0.95);
    let a_v0 = (b_v0 * rng.random_range(1.0..1.15)).min(a_v_des);
    let history_s = CURRENT_STEP as f64 * STEP_SECS;
    // The situation at the current step: A 30 m along, B 8–40 m (bumper to bumper) ahead.
    let a_s = 30.0 + speed_limit_mps * history_s;
    let gap = rng.random_range(8.0..40.0);
    let (a_size, b_size) = (vehicle_size(rng), vehicle_size(rng));
    let b_s = a_s + gap + 0.5 * (a_size.0 + b_size.0);
    let (a_idm, b_idm) = (idm(rng, a_v_des), idm(rng, speed_limit_mps));
    let reaction_steps = rng.random_range(3..8);
    let pair = PairSetup {
        a_size,
        b_size,
        a_idm,
        b_idm,
        a_s0: a_s - a_v0 * history_s,
        a_v0,
        b_s0: b_s - b_v0 * history_s,
        b_v0,
        reaction_steps,
    };
    let mut others = Vec::new();
    if rng.random_bool(0.4) {
        // A follower behind A.
        let v = a_v0 * rng.random_range(0.95..1.05);
        let size = vehicle_size(rng);
        let s0 = pair.a_s0 - rng.random_range(15.0..40.0);
        others.push((a_lane, s0, v, size, idm(rng, a_v_des)));
    }
    for lane in (0..lanes).filter(|&l| l != a_lane) {
        for _ in 0..rng.random_range(0..=2) {
            let v = speed_limit_mps * rng.random_range(0.75..1.0);
            let size = vehicle_size(rng);
            let s0 = pair.a_s0 + rng.random_range(-40.0..120.0);
            others.push((lane, s0, v, size, idm(rng, v)));
        }
    }
    // Keep other vehicles in the same lane apart.
    others.sort_by(|x, y| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1)));
    for k in 1..others.len() {
        if others[k].0 == others[k - 1].0 && others[k].1 - others[k - 1].1 < 15.0 {
            others[k].1 = others[k - 1].1 + 15.0;
        }
    }
    let n_agents = 2 + others.len();
    FollowingParams {
        curvature_knots,
        lanes,
        a_lane,
        lane_width_m,
        speed_limit_mps,
        b_base,
        taps,
        pair,
        others,
        noise: (0..n_agents).map(|_| noise_track(rng, NUM_STEPS)).collect(),
    }
}

impl FollowingParams {
    fn curvature(&self, s: f64) -> f64 {
        let k = &self.curvature_knots;
        match k.iter().position(|&(s1, _)| s1 > s) {
            None => k.last().map_or(0.0, |p| p.1),
            Some(0) => k[0].1,
            Some(i) => {
                let ((s0, k0), (s1, k1)) = (k[i - 1], k[i]);
                k0 + (k1 - k0) * (s - s0) / (s1 - s0).max(1e-9)
            }
        }
    }

    /// Lateral offset of lane `lane` (from the right) from A's lane, positive to the left.
    fn lane_d(&self, lane: usize) -> f64 {
        (lane as f64 - self.a_lane as f64) * self.lane_width_m
    }

    /// B's deceleration from needless braking at step `t` under courtesy `c` (0 when none).
    fn tap_decel(&self, t: usize, c: f64) -> f64 {
        self.taps
            .iter()
            .filter(|tap| (tap.start..tap.start + tap.steps).contains(&t))
            .map(|tap| tap.decel_mps2 * (1.0 - c))
            .fold(0.0, f64::max)
    }
}

/// The reference path of a following scene: the centre of A's lane, integrated from the
/// curvature profile every 0.5 m.
pub fn following_paths(p: &FollowingParams) -> Vec<RefPath> {
    let ds = 0.5;
    let n = (ROAD_M / ds) as usize + 1;
    let mut xy = Vec::with_capacity(n);
    let (mut x, mut y, mut h) = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..n {
        xy.push((x, y));
        let s = i as f64 * ds;
        // Midpoint rule for the heading over the step.
        let h_mid = h + 0.5 * ds * p.curvature(s + 0.25 * ds);
        x += ds * h_mid.cos();
        y += ds * h_mid.sin();
        h += ds * p.curvature(s + 0.5 * ds);
    }
    let at = move |s: f64| {
        let u = (s / ds).clamp(0.0, (n - 1) as f64);
        let i = (u.floor() as usize).min(n - 2);
        let t = u - i as f64;
        let ((x0, y0), (x1, y1)) = (xy[i], xy[i + 1]);
        (x0 + t * (x1 - x0), y0 + t * (y1 - y0))
    };
    vec![RefPath::from_fn(ROAD_M, 1.0, at)]
}

/// Simulates a following scene on its `paths` ([`following_paths`]) with B as `b` says; the
/// map is built only when `with_map`.
pub fn simulate_following(
    p: &FollowingParams,
    paths: Vec<RefPath>,
    b: BPlan<'_>,
    with_map: bool,
) -> Run {
    let with_b = b.present();
    let w = p.lane_width_m;
    let mut agents = p.pair.agents(0, 0.0, with_b);
    for (k, &(lane, s0, v0, size, m)) in p.others.iter().enumerate() {
        agents.push(Agent::new(
            300 + k as i64,
            ObjectType::Vehicle,
            0,
            size,
            m,
            s0,
            p.lane_d(lane),
            v0,
        ));
    }
    let noise_of = |i: usize| {
        if with_b {
            i
        } else if i == 0 {
            0
        } else {
            i + 1
        }
    };
    for t in 0..b.steps() - 1 {
        let c = b.courtesy(t);
        if with_b {
            agents[1].idm.desired_speed_mps = p.speed_limit_mps * (p.b_base + 0.2 * c);
        }
        let mut cmds = vec![0.0; agents.len()];
        for i in 0..agents.len() {
            let me = &agents[i];
            let mut leader = None;
            for (j, other) in agents.iter().enumerate() {
                // A sees B with its reaction delay; everyone else is seen as it is.
                let delay = if i == 0 && with_b && j == 1 {
                    p.pair.reaction_steps
                } else {
                    0
                };
                let (s_j, d_j, v_j) = other.delayed(delay);
                if j != i && (d_j - me.d).abs() < 0.8 * w && s_j > me.s {
                    leader = closer(leader, Some((me.gap_to(s_j, other.length_m), v_j)));
                }
            }
            let mut cmd = me.idm.accel(me.v, leader) + p.noise[noise_of(i)][t];
            if with_b && i == 1 {
                let tap = p.tap_decel(t, c);
                if tap > 0.0 {
                    cmd = cmd.min(-tap);
                }
            }
            cmds[i] = cmd;
        }
        for (i, a) in agents.iter_mut().enumerate() {
            let d = a.d;
            a.step(cmds[i], d);
        }
        b.after_step(&mut agents, t);
    }
    if !with_map {
        return Run {
            paths,
            agents,
            map: Map::default(),
        };
    }
    let map = following_map(p, &paths[0]);
    Run { paths, agents, map }
}

/// The procedural road's map: a lane per lane with its neighbours, broken lines between lanes,
/// solid edge lines, and a road edge on each side.
fn following_map(p: &FollowingParams, path: &RefPath) -> Map {
    let w = p.lane_width_m;
    let end = ROAD_M - 20.0;
    let (lane_type, speed_limit_mph) = super::road_class(p.speed_limit_mps);
    let lane_id = |l: usize| 1 + l as i64;
    let mut lanes: Vec<Lane> = (0..p.lanes)
        .map(|l| Lane {
            id: lane_id(l),
            lane_type,
            speed_limit_mph,
            polyline: pts(path.offset_points(-60.0, end, 1.0, |_| p.lane_d(l))),
            ..Default::default()
        })
        .collect();
    let last = lanes[0].polyline.len() as i32 - 1;
    let neighbour = |id| LaneNeighbor {
        feature_id: id,
        self_end_index: last,
        neighbor_end_index: last,
        ..Default::default()
    };
    for l in 0..p.lanes {
        if l + 1 < p.lanes {
            lanes[l].left_neighbors.push(neighbour(lane_id(l + 1)));
        }
        if l > 0 {
            lanes[l].right_neighbors.push(neighbour(lane_id(l - 1)));
        }
    }
    let line = |id, line_type, d: f64| RoadLine {
        id,
        line_type,
        polyline: pts(path.offset_points(-60.0, end, 1.0, |_| d)),
    };
    let (right, left) = (p.lane_d(0) - w / 2.0, p.lane_d(p.lanes - 1) + w / 2.0);
    let mut road_lines = vec![
        line(10, RoadLineType::SolidSingleWhite, right),
        line(11, RoadLineType::SolidSingleYellow, left),
    ];
    for l in 1..p.lanes {
        road_lines.push(line(
            11 + l as i64,
            RoadLineType::BrokenSingleWhite,
            p.lane_d(l) - w / 2.0,
        ));
    }
    let edge = |id, d: f64| RoadEdge {
        id,
        edge_type: RoadEdgeType::Boundary,
        polyline: pts(path.offset_points(-60.0, end, 2.0, |_| d)),
    };
    Map {
        lanes,
        road_lines,
        road_edges: vec![edge(20, right - 0.5), edge(21, left + 0.5)],
        ..Default::default()
    }
}
