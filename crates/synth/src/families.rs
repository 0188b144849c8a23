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
//!   `200c` m.

use rand::Rng;
use rand_pcg::Pcg64Mcg;
use scbg_scene::{
    Crosswalk, Lane, LaneType, Map, MapPoint, ObjectType, RoadEdge, RoadEdgeType, RoadLine,
    RoadLineType, StopSign,
};

use crate::path::RefPath;
use crate::sim::{Agent, Idm, STEP_SECS, closer};

pub const NUM_STEPS: usize = 91;
pub const A_ID: i64 = 101;
pub const B_ID: i64 = 202;
/// Length over which the on-ramp's approach angle eases into the parallel lane.
const RAMP_BLEND_M: f64 = 90.0;
/// How far back a fully courteous B looks for a faster A to make way for.
const MAKE_WAY_LOOKBACK_M: f64 = 200.0;

/// The output of one simulation run.
#[derive(Debug)]
pub struct Run {
    pub paths: Vec<RefPath>,
    pub agents: Vec<Agent>,
    pub map: Map,
}

fn mp((x, y): (f64, f64)) -> MapPoint {
    MapPoint {
        x_m: x,
        y_m: y,
        z_m: 0.0,
    }
}

fn pts(v: Vec<(f64, f64)>) -> Vec<MapPoint> {
    v.into_iter().map(mp).collect()
}

/// A circular arc of curvature `k` (straight when 0) starting at `(x0, y0)` heading `h0`.
fn arc_path(x0: f64, y0: f64, h0: f64, k: f64, length_m: f64) -> RefPath {
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

fn vehicle_size(rng: &mut Pcg64Mcg) -> (f64, f64) {
    (rng.random_range(4.2..5.2), rng.random_range(1.8..2.1))
}

fn idm(rng: &mut Pcg64Mcg, desired_speed_mps: f64) -> Idm {
    Idm {
        desired_speed_mps,
        max_accel_mps2: rng.random_range(1.2..2.0),
        comfort_brake_mps2: rng.random_range(1.8..2.6),
        time_headway_s: rng.random_range(1.0..1.6),
        min_gap_m: rng.random_range(1.5..2.5),
    }
}

/// Small, smooth acceleration noise (an AR(1) process) for every agent and step.
fn noise_track(rng: &mut Pcg64Mcg, n: usize) -> Vec<f64> {
    let mut e = 0.0;
    (0..n)
        .map(|_| {
            e = 0.9 * e + 0.08 * (rng.random::<f64>() - 0.5);
            e
        })
        .collect()
}

// ------------------------------------------------------------------------------------ merge

#[derive(Debug, Clone)]
pub struct MergeParams {
    curvature: f64,
    lane_width_m: f64,
    /// Main-path arclength where the taper ends (B fully in A's lane).
    merge_end_s: f64,
    taper_m: f64,
    accel_lane_m: f64,
    ramp_angle_rad: f64,
    a_size: (f64, f64),
    b_size: (f64, f64),
    a_idm: Idm,
    b_idm: Idm,
    a_s0: f64,
    a_v0: f64,
    b_s0: f64,
    b_v0: f64,
    reaction_steps: usize,
    background: Vec<(f64, f64, (f64, f64), Idm)>,
    noise: Vec<Vec<f64>>,
}

pub fn merge_params(rng: &mut Pcg64Mcg) -> MergeParams {
    let lane_width_m = rng.random_range(3.4..3.9);
    let merge_end_s = rng.random_range(260.0..300.0);
    let a_v_des = rng.random_range(23.5..25.5);
    let a_v0 = a_v_des * rng.random_range(0.95..1.0);
    let a_s0 = rng.random_range(20.0..40.0);
    let b_v_des = rng.random_range(20.0..26.0);
    let b_v0 = b_v_des * rng.random_range(0.85..1.0);
    let taper_m = rng.random_range(100.0..140.0);
    // B's lead time at the merge (positive: B arrives first), spread around zero.
    let lead_s: f64 = rng.random_range(-1.5..2.5);
    let merge_mid = merge_end_s - taper_m * 0.5;
    let tau_a = (merge_mid - a_s0) / a_v0;
    let b_s0 = (merge_mid - (tau_a - lead_s) * b_v0).max(5.0);
    let mut background = Vec::new();
    if rng.random_bool(0.6) {
        let size = vehicle_size(rng);
        let v = rng.random_range(25.0..28.0);
        background.push((a_s0 + rng.random_range(60.0..110.0), v, size, idm(rng, v)));
    }
    if rng.random_bool(0.5) {
        let size = vehicle_size(rng);
        let v = rng.random_range(21.0..26.0);
        background.push((
            (a_s0 - rng.random_range(25.0..45.0)).max(-30.0),
            v * 0.95,
            size,
            idm(rng, v),
        ));
    }
    let n_agents = 2 + background.len();
    MergeParams {
        curvature: rng.random_range(-1.0 / 900.0..1.0 / 900.0),
        lane_width_m,
        merge_end_s,
        taper_m,
        accel_lane_m: rng.random_range(20.0..60.0),
        ramp_angle_rad: rng.random_range(5f64..15.0).to_radians(),
        a_size: vehicle_size(rng),
        b_size: vehicle_size(rng),
        a_idm: idm(rng, a_v_des),
        b_idm: idm(rng, b_v_des),
        a_s0,
        a_v0,
        b_s0,
        b_v0,
        reaction_steps: rng.random_range(3..8),
        background,
        noise: (0..n_agents).map(|_| noise_track(rng, NUM_STEPS)).collect(),
    }
}

impl MergeParams {
    /// B's lateral offset along the ramp: approach at an angle, parallel acceleration lane,
    /// cosine taper into A's lane ending at `merge_end_s`.
    fn ramp_d(&self, s: f64) -> f64 {
        let w = self.lane_width_m;
        let taper_start = self.merge_end_s - self.taper_m;
        let parallel_start = taper_start - self.accel_lane_m;
        if s >= self.merge_end_s {
            0.0
        } else if s >= taper_start {
            let u = (s - taper_start) / self.taper_m;
            -w * 0.5 * (1.0 + (std::f64::consts::PI * u).cos())
        } else if s >= parallel_start {
            -w
        } else {
            // Smooth entry into the parallel lane: the slope eases from tan(angle) to 0 over
            // RAMP_BLEND_M, so lateral acceleration stays small at highway speed.
            let x = parallel_start - s;
            let eased = if x < RAMP_BLEND_M {
                x * x / (2.0 * RAMP_BLEND_M)
            } else {
                x - RAMP_BLEND_M / 2.0
            };
            -w - eased * self.ramp_angle_rad.tan()
        }
    }
}

pub fn simulate_merge(p: &MergeParams, c: f64, with_b: bool) -> Run {
    let path = arc_path(0.0, 0.0, 0.0, p.curvature, 700.0);
    let mut agents = vec![Agent::new(
        A_ID,
        ObjectType::Vehicle,
        0,
        p.a_size,
        p.a_idm,
        p.a_s0,
        0.0,
        p.a_v0,
    )];
    let mut b_idm = p.b_idm;
    if with_b {
        agents.push(Agent::new(
            B_ID,
            ObjectType::Vehicle,
            0,
            p.b_size,
            b_idm,
            p.b_s0,
            p.ramp_d(p.b_s0),
            p.b_v0,
        ));
    }
    let bg0 = agents.len();
    for (k, &(s, v, size, m)) in p.background.iter().enumerate() {
        agents.push(Agent::new(
            300 + k as i64,
            ObjectType::Vehicle,
            0,
            size,
            m,
            s,
            0.0,
            v,
        ));
    }
    let w = p.lane_width_m;
    let taper_start = p.merge_end_s - p.taper_m;
    let mut decision: Option<bool> = None; // Some(true) = B goes first
    for t in 0..NUM_STEPS - 1 {
        let mut cmds = vec![0.0; agents.len()];
        // B's decision, latched at the commit point.
        if with_b && decision.is_none() && agents[1].s >= taper_start - 40.0 {
            let (a, b) = (&agents[0], &agents[1]);
            let mid = p.merge_end_s - p.taper_m * 0.5;
            let lead = (mid - a.s) / a.v.max(1.0) - (mid - b.s) / b.v.max(1.0);
            let go = lead > -0.5 + 3.5 * c;
            decision = Some(go);
            if go {
                b_idm.desired_speed_mps *= 1.0 + 0.15 * c;
                agents[1].idm = b_idm;
            } else {
                agents[1].idm.time_headway_s *= 1.0 + c;
            }
        }
        // Even a B that goes first does not enter the taper with A alongside: it waits.
        if with_b && decision == Some(true) && agents[1].s < taper_start {
            let (a, b) = (&agents[0], &agents[1]);
            if (b.s - a.s).abs() < 0.5 * (a.length_m + b.length_m) + 3.0 && a.s < b.s + 8.0 {
                decision = Some(false);
            }
        }
        for i in 0..agents.len() {
            let me = &agents[i];
            let in_lane = |j: usize| agents[j].d.abs() < 0.75 * w;
            // Leaders on the main lane: any agent ahead that is (nearly) in the lane.
            let mut leader = None;
            for (j, other) in agents.iter().enumerate() {
                if j == i {
                    continue;
                }
                let (s_j, d_j, v_j) = if i == 0 && with_b && j == 1 {
                    other.delayed(p.reaction_steps)
                } else {
                    (other.s, other.d, other.v)
                };
                let relevant = if with_b && j == 1 && i != 1 {
                    // B matters to main-lane traffic once it is merging (or committed to go).
                    d_j.abs() < 0.75 * w || (decision == Some(true) && s_j > taper_start - 10.0)
                } else if with_b && i == 1 {
                    // B on the ramp: main-lane agents matter once B is in the taper.
                    in_lane(j) && (me.s > taper_start || me.d.abs() < 0.75 * w)
                } else {
                    in_lane(j) && in_lane(i)
                };
                if relevant && s_j > me.s {
                    leader = closer(leader, Some((me.gap_to(s_j, other.length_m), v_j)));
                }
            }
            if with_b && i == 1 && me.s < taper_start {
                // A yielding B waits in the acceleration lane, before the taper, until A has passed.
                let a_passed = agents[0].s - agents[0].length_m > me.s + 2.0;
                if decision == Some(false) && !a_passed {
                    leader = closer(leader, Some((taper_start - me.s - me.length_m * 0.5, 0.0)));
                }
            }
            cmds[i] = me.idm.accel(me.v, leader) + p.noise[i][t];
        }
        for (i, a) in agents.iter_mut().enumerate() {
            let d_next = if with_b && i == 1 {
                p.ramp_d(a.s + a.v * STEP_SECS)
            } else {
                0.0
            };
            a.step(cmds[i], d_next);
        }
        let _ = bg0;
    }
    // Map: main lane before/after the merge, ramp lane, road lines and edges.
    let ramp_start = (p.b_s0 - 30.0)
        .min(taper_start - p.accel_lane_m - 20.0)
        .max(-50.0);
    let main_lane = |s0: f64, s1: f64| pts(path.offset_points(s0, s1, 1.0, |_| 0.0));
    let end = 650.0;
    let speed = Some(65.0);
    let lane = |id, polyline, entry: Vec<i64>, exit: Vec<i64>| Lane {
        id,
        lane_type: LaneType::Freeway,
        speed_limit_mph: speed,
        polyline,
        entry_lanes: entry,
        exit_lanes: exit,
        ..Default::default()
    };
    let map = Map {
        lanes: vec![
            lane(1, main_lane(-50.0, p.merge_end_s), vec![], vec![2]),
            lane(2, main_lane(p.merge_end_s, end), vec![1, 3], vec![]),
            lane(
                3,
                pts(path.offset_points(ramp_start, p.merge_end_s, 1.0, |s| p.ramp_d(s))),
                vec![],
                vec![2],
            ),
        ],
        road_lines: vec![RoadLine {
            id: 10,
            line_type: RoadLineType::BrokenSingleWhite,
            polyline: pts(path.offset_points(
                taper_start - p.accel_lane_m,
                taper_start,
                1.0,
                |_| -w / 2.0,
            )),
        }],
        road_edges: vec![
            RoadEdge {
                id: 20,
                edge_type: RoadEdgeType::Boundary,
                polyline: pts(path.offset_points(-50.0, end, 2.0, |_| w / 2.0 + 0.5)),
            },
            RoadEdge {
                id: 21,
                edge_type: RoadEdgeType::Boundary,
                polyline: pts(path.offset_points(ramp_start, end, 2.0, |s| {
                    if s < p.merge_end_s {
                        p.ramp_d(s) - w / 2.0 - 0.5
                    } else {
                        -w / 2.0 - 0.5
                    }
                })),
            },
            RoadEdge {
                id: 22,
                edge_type: RoadEdgeType::Boundary,
                polyline: pts(path.offset_points(
                    ramp_start,
                    taper_start - p.accel_lane_m,
                    2.0,
                    |s| p.ramp_d(s) + w / 2.0 + 0.2,
                )),
            },
        ],
        ..Default::default()
    };
    Run {
        paths: vec![path],
        agents,
        map,
    }
}

// --------------------------------------------------------------------------------- crossing

#[derive(Debug, Clone)]
pub struct CrossingParams {
    curvature: f64,
    lane_width_m: f64,
    crossing_angle_rad: f64,
    from_right: bool,
    a_conflict_s: f64,
    b_conflict_s: f64,
    a_size: (f64, f64),
    b_size: (f64, f64),
    a_idm: Idm,
    b_idm: Idm,
    a_s0: f64,
    a_v0: f64,
    b_s0: f64,
    b_v0: f64,
    reaction_steps: usize,
    follower: Option<(f64, f64, (f64, f64), Idm)>,
    pedestrians: Vec<(f64, f64, f64)>,
    noise: Vec<Vec<f64>>,
}

pub fn crossing_params(rng: &mut Pcg64Mcg) -> CrossingParams {
    let a_v_des = rng.random_range(12.5..14.0);
    let a_v0 = a_v_des * rng.random_range(0.95..1.0);
    let a_conflict_s = rng.random_range(110.0..140.0);
    let tau_a: f64 = rng.random_range(3.5..6.0);
    let b_v_des = rng.random_range(10.0..13.0);
    let b_v0 = rng.random_range(5.0..8.0);
    let b_conflict_s = rng.random_range(80.0..110.0);
    // B reaches the conflict point around A's arrival, give or take.
    let tau_b = tau_a + rng.random_range(-3.0..1.5);
    let b_s0 = (b_conflict_s - tau_b.max(1.5) * b_v0).max(2.0);
    let follower = rng.random_bool(0.5).then(|| {
        let size = vehicle_size(rng);
        let v = rng.random_range(11.0..14.0);
        (rng.random_range(15.0..30.0), v * 0.95, size, idm(rng, v))
    });
    let pedestrians = (0..rng.random_range(0..3))
        .map(|_| {
            (
                rng.random_range(40.0..180.0),
                rng.random_range(1.0..1.6),
                if rng.random_bool(0.5) { 1.0 } else { -1.0 },
            )
        })
        .collect();
    CrossingParams {
        curvature: rng.random_range(-1.0 / 1500.0..1.0 / 1500.0),
        lane_width_m: rng.random_range(3.3..3.8),
        crossing_angle_rad: rng.random_range(70f64..110.0).to_radians(),
        from_right: rng.random_bool(0.5),
        a_conflict_s,
        b_conflict_s,
        a_size: vehicle_size(rng),
        b_size: vehicle_size(rng),
        a_idm: idm(rng, a_v_des),
        b_idm: idm(rng, b_v_des),
        a_s0: (a_conflict_s - tau_a * a_v0).max(5.0),
        a_v0,
        b_s0,
        b_v0,
        reaction_steps: rng.random_range(3..8),
        follower,
        pedestrians,
        noise: (0..4).map(|_| noise_track(rng, NUM_STEPS)).collect(),
    }
}

pub fn simulate_crossing(p: &CrossingParams, c: f64, with_b: bool) -> Run {
    let w = p.lane_width_m;
    let a_path = arc_path(0.0, 0.0, 0.0, p.curvature, 400.0);
    let (cx, cy) = a_path.pose(p.a_conflict_s, 0.0);
    let h_a = a_path.heading_at(p.a_conflict_s);
    let h_b = if p.from_right {
        h_a + p.crossing_angle_rad
    } else {
        h_a - p.crossing_angle_rad
    };
    let b_path = RefPath::straight(
        cx - h_b.cos() * p.b_conflict_s,
        cy - h_b.sin() * p.b_conflict_s,
        h_b,
        300.0,
    );
    // Half-width of the crossing road along each path (both roads have two lanes).
    let half_zone = w / p.crossing_angle_rad.sin().abs() + 1.0;
    let stop_s = p.b_conflict_s - half_zone - 2.0;
    let mut agents = vec![Agent::new(
        A_ID,
        ObjectType::Vehicle,
        0,
        p.a_size,
        p.a_idm,
        p.a_s0,
        0.0,
        p.a_v0,
    )];
    if with_b {
        agents.push(Agent::new(
            B_ID,
            ObjectType::Vehicle,
            1,
            p.b_size,
            p.b_idm,
            p.b_s0,
            0.0,
            p.b_v0,
        ));
    }
    let follower_idx = agents.len();
    if let Some((gap, v, size, m)) = p.follower {
        agents.push(Agent::new(
            303,
            ObjectType::Vehicle,
            0,
            size,
            m,
            p.a_s0 - gap,
            0.0,
            v,
        ));
    }
    let ped0 = agents.len();
    let mut ped_paths = Vec::new();
    for (k, &(s, v, side)) in p.pedestrians.iter().enumerate() {
        // Sidewalk beside road 1, walking along it.
        let (x, y) = a_path.pose(s, side * (1.5 * w + 2.5));
        let h = a_path.heading_at(s)
            + if k % 2 == 0 {
                0.0
            } else {
                std::f64::consts::PI
            };
        ped_paths.push(RefPath::straight(x, y, h, 60.0));
        let ped_idm = Idm {
            desired_speed_mps: v,
            max_accel_mps2: 1.0,
            comfort_brake_mps2: 1.0,
            time_headway_s: 1.0,
            min_gap_m: 0.5,
        };
        agents.push(Agent::new(
            400 + k as i64,
            ObjectType::Pedestrian,
            2 + k,
            (0.6, 0.6),
            ped_idm,
            0.0,
            0.0,
            v,
        ));
    }
    let mut decision: Option<bool> = None;
    for t in 0..NUM_STEPS - 1 {
        let mut cmds = vec![0.0; agents.len()];
        if with_b && decision.is_none() && agents[1].s >= stop_s - 20.0 {
            let (a, b) = (&agents[0], &agents[1]);
            let tau_a = (p.a_conflict_s - half_zone - a.s - a.length_m / 2.0) / a.v.max(1.0);
            let tau_b_clear = (p.b_conflict_s + half_zone + b.length_m - b.s) / b.v.max(3.0);
            let go = tau_a - tau_b_clear > -2.5 + 5.0 * c;
            decision = Some(go);
            if go {
                agents[1].idm.desired_speed_mps *= 1.0 + 0.2 * c;
            }
        }
        // A: follows nothing on its road but B occupying (or committed to) the conflict zone.
        {
            let a = &agents[0];
            let mut leader = None;
            if with_b {
                let (s_b, _, _) = agents[1].delayed(p.reaction_steps);
                let b_len = agents[1].length_m;
                let b_in_or_coming = s_b > p.b_conflict_s - half_zone - b_len - 25.0
                    && (decision == Some(true) || s_b > stop_s + 0.5);
                let b_not_cleared = s_b < p.b_conflict_s + half_zone + b_len;
                let a_before = a.s + a.length_m / 2.0 < p.a_conflict_s - half_zone + 1.0;
                if b_in_or_coming && b_not_cleared && a_before {
                    leader = Some((
                        p.a_conflict_s - half_zone - 1.0 - a.s - a.length_m / 2.0,
                        0.0,
                    ));
                }
            }
            cmds[0] = a.idm.accel(a.v, leader) + p.noise[0][t];
        }
        if with_b {
            let b = &agents[1];
            let mut leader = None;
            let a_cleared = agents[0].s - agents[0].length_m > p.a_conflict_s + half_zone;
            if decision != Some(true) && !a_cleared && b.s < stop_s + 0.5 {
                leader = Some((stop_s - b.s - b.length_m / 2.0, 0.0));
            }
            cmds[1] = b.idm.accel(b.v, leader) + p.noise[1][t];
        }
        if p.follower.is_some() {
            let (f, a) = (&agents[follower_idx], &agents[0]);
            cmds[follower_idx] =
                f.idm.accel(f.v, Some((f.gap_to(a.s, a.length_m), a.v))) + p.noise[2][t];
        }
        for (k, ped) in agents[ped0..].iter().enumerate() {
            cmds[ped0 + k] = ped.idm.accel(ped.v, None);
        }
        for (i, a) in agents.iter_mut().enumerate() {
            let _ = i;
            a.step(cmds[i], 0.0);
        }
    }
    let lane_pts =
        |path: &RefPath, s0: f64, s1: f64, d: f64| pts(path.offset_points(s0, s1, 1.0, |_| d));
    let rev = |mut v: Vec<MapPoint>| {
        v.reverse();
        v
    };
    let speed = Some(30.0);
    let lane = |id, polyline| Lane {
        id,
        lane_type: LaneType::SurfaceStreet,
        speed_limit_mph: speed,
        polyline,
        ..Default::default()
    };
    let (a_end, b_end) = (a_path.length_m(), b_path.length_m());
    let mut map = Map {
        lanes: vec![
            lane(1, lane_pts(&a_path, 0.0, a_end, 0.0)),
            lane(2, rev(lane_pts(&a_path, 0.0, a_end, w))),
            lane(3, lane_pts(&b_path, 0.0, b_end, 0.0)),
            lane(4, rev(lane_pts(&b_path, 0.0, b_end, w))),
        ],
        road_lines: vec![
            RoadLine {
                id: 10,
                line_type: RoadLineType::SolidDoubleYellow,
                polyline: lane_pts(&a_path, 0.0, p.a_conflict_s - half_zone, w / 2.0),
            },
            RoadLine {
                id: 11,
                line_type: RoadLineType::SolidDoubleYellow,
                polyline: lane_pts(&a_path, p.a_conflict_s + half_zone, a_end, w / 2.0),
            },
            RoadLine {
                id: 12,
                line_type: RoadLineType::SolidDoubleYellow,
                polyline: lane_pts(&b_path, 0.0, p.b_conflict_s - half_zone, w / 2.0),
            },
            RoadLine {
                id: 13,
                line_type: RoadLineType::SolidDoubleYellow,
                polyline: lane_pts(&b_path, p.b_conflict_s + half_zone, b_end, w / 2.0),
            },
        ],
        stop_signs: vec![StopSign {
            id: 40,
            lanes: vec![3],
            position: mp(b_path.pose(stop_s, -w / 2.0 - 0.5)),
        }],
        ..Default::default()
    };
    let mut edge_id = 20;
    for (path, conflict, end) in [
        (&a_path, p.a_conflict_s, a_end),
        (&b_path, p.b_conflict_s, b_end),
    ] {
        for d in [-w / 2.0 - 0.3, 1.5 * w + 0.3] {
            for (s0, s1) in [
                (0.0, conflict - half_zone - 2.0),
                (conflict + half_zone + 2.0, end),
            ] {
                map.road_edges.push(RoadEdge {
                    id: edge_id,
                    edge_type: RoadEdgeType::Boundary,
                    polyline: pts(path.offset_points(s0, s1, 2.0, |_| d)),
                });
                edge_id += 1;
            }
        }
    }
    let cw = |path: &RefPath, s0: f64| {
        let s1 = s0 + 3.0;
        pts(vec![
            path.pose(s0, -w / 2.0),
            path.pose(s0, 1.5 * w),
            path.pose(s1, 1.5 * w),
            path.pose(s1, -w / 2.0),
        ])
    };
    map.crosswalks.push(Crosswalk {
        id: 50,
        polygon: cw(&b_path, stop_s + 0.5),
    });
    map.crosswalks.push(Crosswalk {
        id: 51,
        polygon: cw(&a_path, p.a_conflict_s + half_zone + 0.5),
    });
    let mut paths = vec![a_path, b_path];
    paths.extend(ped_paths);
    Run { paths, agents, map }
}

// ------------------------------------------------------------------------------------ cut-in

#[derive(Debug, Clone)]
pub struct CutinParams {
    curvature: f64,
    /// Exposed for diagnostics.
    pub cut_in_variant: bool,
    lane_width_m: f64,
    /// true: B cuts into A's lane from the right; false: B, ahead in A's lane, makes way.
    cut_in: bool,
    a_size: (f64, f64),
    b_size: (f64, f64),
    o_size: (f64, f64),
    a_idm: Idm,
    b_idm: Idm,
    o_idm: Idm,
    a_s0: f64,
    a_v0: f64,
    b_s0: f64,
    b_v0: f64,
    o_s0: f64,
    lane_change_s: f64,
    reaction_steps: usize,
    noise: Vec<Vec<f64>>,
}

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
    CutinParams {
        cut_in_variant: cut_in,
        curvature: rng.random_range(-1.0 / 1000.0..1.0 / 1000.0),
        lane_width_m: rng.random_range(3.4..3.8),
        cut_in,
        a_size: vehicle_size(rng),
        b_size: vehicle_size(rng),
        o_size,
        a_idm: idm(rng, a_v_des),
        b_idm: idm(rng, b_v_des),
        o_idm,
        a_s0,
        a_v0,
        b_s0,
        b_v0,
        o_s0: b_s0 + rng.random_range(45.0..75.0),
        lane_change_s: rng.random_range(3.0..4.5),
        reaction_steps: rng.random_range(3..8),
        noise: (0..3).map(|_| noise_track(rng, NUM_STEPS)).collect(),
    }
}

pub fn simulate_cutin(p: &CutinParams, c: f64, with_b: bool) -> Run {
    let w = p.lane_width_m;
    let path = arc_path(0.0, 0.0, 0.0, p.curvature, 700.0);
    let b_lane = if p.cut_in { -w } else { 0.0 };
    let b_target = if p.cut_in { 0.0 } else { -w };
    let mut agents = vec![Agent::new(
        A_ID,
        ObjectType::Vehicle,
        0,
        p.a_size,
        p.a_idm,
        p.a_s0,
        0.0,
        p.a_v0,
    )];
    if with_b {
        agents.push(Agent::new(
            B_ID,
            ObjectType::Vehicle,
            0,
            p.b_size,
            p.b_idm,
            p.b_s0,
            b_lane,
            p.b_v0,
        ));
    }
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
    let politeness = 2.0 * c;
    let safe_brake = 7.0 - 6.0 * c;
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
    for t in 0..NUM_STEPS - 1 {
        let mut cmds = vec![0.0; agents.len()];
        if with_b && change_start.is_none() {
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
                let gap = a.gap_to(b.s, b.length_m) - (a.v - b.v).max(0.0) * 0.5;
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
                p.b_idm.desired_speed_mps
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
                leader_in(&agents, i, me.s, me.d, i == 0 && with_b, p.reaction_steps)
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
        let _ = o;
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
    Run {
        paths: vec![path],
        agents,
        map,
    }
}
