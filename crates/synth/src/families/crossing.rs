//! Stop-controlled crossing at an intersection.

use rand::Rng;
use rand_pcg::Pcg64Mcg;
use scbg_scene::{
    Crosswalk, Lane, LaneType, Map, MapPoint, ObjectType, RoadEdge, RoadEdgeType, RoadLine,
    RoadLineType, StopSign,
};

use super::{
    BPlan, Background, Conflict, NUM_STEPS, PairSetup, Run, arc_path, idm, mp, noise_track, pts,
    vehicle_size,
};
use crate::CURRENT_STEP;
use crate::path::RefPath;
use crate::sim::{Agent, Idm};

// --------------------------------------------------------------------------------- crossing

/// The random draws of one crossing scene (geometry, A and B, other traffic, noise).
#[derive(Debug, Clone)]
pub struct CrossingParams {
    curvature: f64,
    lane_width_m: f64,
    crossing_angle_rad: f64,
    from_right: bool,
    a_conflict_s: f64,
    b_conflict_s: f64,
    pair: PairSetup,
    follower: Option<Background>,
    pedestrians: Vec<(f64, f64, f64)>,
    noise: Vec<Vec<f64>>,
}

/// Draws the parameters of a crossing scene.
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
    // Both start one history (1 s) earlier than these arrival times say, so that B reaches
    // its decision after the current step, with the history showing its approach.
    let history_s = CURRENT_STEP as f64 * 0.1;
    let b_s0 = (b_conflict_s - (tau_b.max(1.5) + history_s) * b_v0).max(2.0);
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
    // Draw order is part of the data: keep it.
    let curvature = rng.random_range(-1.0 / 1500.0..1.0 / 1500.0);
    let lane_width_m = rng.random_range(3.3..3.8);
    let crossing_angle_rad = rng.random_range(70f64..110.0).to_radians();
    let from_right = rng.random_bool(0.5);
    let a_s0 = (a_conflict_s - (tau_a + history_s) * a_v0).max(5.0);
    let pair = PairSetup::draw(rng, (a_v_des, a_s0, a_v0), (b_v_des, b_s0, b_v0));
    CrossingParams {
        curvature,
        lane_width_m,
        crossing_angle_rad,
        from_right,
        a_conflict_s,
        b_conflict_s,
        pair,
        follower,
        pedestrians,
        noise: (0..4).map(|_| noise_track(rng, NUM_STEPS)).collect(),
    }
}

/// The reference paths of a crossing scene: A's road, B's, then one per pedestrian.
pub fn crossing_paths(p: &CrossingParams) -> Vec<RefPath> {
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
    let mut paths = vec![a_path, b_path];
    for (k, &(s, _, side)) in p.pedestrians.iter().enumerate() {
        // Sidewalk beside road 1, walking along it.
        let (x, y) = paths[0].pose(s, side * (1.5 * w + 2.5));
        let h = paths[0].heading_at(s)
            + if k % 2 == 0 {
                0.0
            } else {
                std::f64::consts::PI
            };
        paths.push(RefPath::straight(x, y, h, 60.0));
    }
    paths
}

/// Simulates a crossing scene on its `paths` ([`crossing_paths`]) with B as `b` says; the map
/// is built only when `with_map`.
pub fn simulate_crossing(
    p: &CrossingParams,
    paths: Vec<RefPath>,
    b: BPlan<'_>,
    with_map: bool,
) -> Run {
    let with_b = b.present();
    let w = p.lane_width_m;
    let (a_path, b_path) = (&paths[0], &paths[1]);
    // Half-width of the crossing road along each path (both roads have two lanes).
    let half_zone = w / p.crossing_angle_rad.sin().abs() + 1.0;
    let zone = Conflict {
        b_in_s: p.b_conflict_s - half_zone,
        b_out_s: p.b_conflict_s + half_zone,
        a_in_s: p.a_conflict_s - half_zone,
        a_out_s: p.a_conflict_s + half_zone,
    };
    let stop_s = zone.stop_s();
    let mut agents = p.pair.agents(1, 0.0, with_b);
    let follower_idx = agents.len();
    if let Some((gap, v, size, m)) = p.follower {
        agents.push(Agent::new(
            303,
            ObjectType::Vehicle,
            0,
            size,
            m,
            p.pair.a_s0 - gap,
            0.0,
            v,
        ));
    }
    let ped0 = agents.len();
    for (k, &(_, v, _)) in p.pedestrians.iter().enumerate() {
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
    for t in 0..b.steps() - 1 {
        let mut cmds = vec![0.0; agents.len()];
        let c = b.courtesy(t);
        // B decides from the current step on, so its courtesy shows in the future to predict.
        if with_b && decision.is_none() && t >= CURRENT_STEP && agents[1].s >= stop_s - 20.0 {
            let go = zone.b_goes_first(&agents[0], &agents[1], -2.5 + 5.0 * c);
            decision = Some(go);
            if go {
                agents[1].idm.desired_speed_mps *= 1.0 + 0.2 * c;
            }
        }
        // A: follows nothing on its road but B occupying (or committed to) the conflict zone, by
        // B's observable motion only ([`Conflict::a_leader`]).
        let leader = if with_b {
            zone.a_leader(&agents[0], &agents[1], p.pair.reaction_steps)
        } else {
            None
        };
        cmds[0] = agents[0].idm.accel(agents[0].v, leader) + p.noise[0][t];
        if with_b {
            let b = &agents[1];
            let a_cleared = agents[0].s - agents[0].length_m > zone.a_out_s;
            let undecided_history = decision.is_none() && t < CURRENT_STEP;
            let waits = decision != Some(true) && !undecided_history && !a_cleared;
            let leader = if waits { zone.b_stop_leader(b) } else { None };
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
            a.step(cmds[i], 0.0);
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
            lane(1, lane_pts(a_path, 0.0, a_end, 0.0)),
            lane(2, rev(lane_pts(a_path, 0.0, a_end, w))),
            lane(3, lane_pts(b_path, 0.0, b_end, 0.0)),
            lane(4, rev(lane_pts(b_path, 0.0, b_end, w))),
        ],
        road_lines: vec![
            RoadLine {
                id: 10,
                line_type: RoadLineType::SolidDoubleYellow,
                polyline: lane_pts(a_path, 0.0, p.a_conflict_s - half_zone, w / 2.0),
            },
            RoadLine {
                id: 11,
                line_type: RoadLineType::SolidDoubleYellow,
                polyline: lane_pts(a_path, p.a_conflict_s + half_zone, a_end, w / 2.0),
            },
            RoadLine {
                id: 12,
                line_type: RoadLineType::SolidDoubleYellow,
                polyline: lane_pts(b_path, 0.0, p.b_conflict_s - half_zone, w / 2.0),
            },
            RoadLine {
                id: 13,
                line_type: RoadLineType::SolidDoubleYellow,
                polyline: lane_pts(b_path, p.b_conflict_s + half_zone, b_end, w / 2.0),
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
        (a_path, p.a_conflict_s, a_end),
        (b_path, p.b_conflict_s, b_end),
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
        polygon: cw(b_path, stop_s + 0.5),
    });
    map.crosswalks.push(Crosswalk {
        id: 51,
        polygon: cw(a_path, p.a_conflict_s + half_zone + 0.5),
    });
    Run { paths, agents, map }
}
