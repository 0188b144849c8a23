//! On-ramp merge into A's highway lane.

use rand::Rng;
use rand_pcg::Pcg64Mcg;
use scbg_scene::{
    Lane, LaneNeighbor, LaneType, Map, RoadEdge, RoadEdgeType, RoadLine, RoadLineType,
};

use super::{
    BPlan, Background, NUM_STEPS, PairSetup, Run, arc_path, idm, merging_into_lane, noise_track,
    pts, vehicle_size,
};
use crate::CURRENT_STEP;
use crate::RefPath;
use crate::sim::{STEP_SECS, closer};

/// Length over which the on-ramp's approach angle eases into the parallel lane.
const RAMP_BLEND_M: f64 = 90.0;

// ------------------------------------------------------------------------------------ merge

/// The random draws of one merge scene (geometry, A and B, background traffic, noise).
#[derive(Debug, Clone)]
pub struct MergeParams {
    ramp: Ramp,
    pair: PairSetup,
    background: Vec<Background>,
    noise: Vec<Vec<f64>>,
}

/// A main lane along a gently curved path with an on-ramp joining it from the right: the
/// geometry the merge and let-in families share. With [`Self::lane_drop`] the ramp is instead
/// a lane that runs beside the main lane from the road's start and ends in the taper (the
/// zipper family's lane drop).
#[derive(Debug, Clone)]
pub(super) struct Ramp {
    pub curvature: f64,
    pub lane_width_m: f64,
    /// Main-path arclength where the taper ends (the ramp car fully in the main lane).
    pub merge_end_s: f64,
    pub taper_m: f64,
    pub accel_lane_m: f64,
    pub ramp_angle_rad: f64,
    /// A lane drop's speed limit (m/s); `None` for an on-ramp.
    pub lane_drop: Option<f64>,
}

/// The grass island between the main lane and the on-ramp, as a closed polygon traversed with
/// the road on its left (as WOMD orients road edges): forward along the main lane's right
/// edge, back along the ramp's left edge, up to the gore's tip where the two are 0.4 m apart.
fn gore_island(path: &crate::RefPath, p: &Ramp, ramp_start: f64) -> Vec<(f64, f64)> {
    let w = p.lane_width_m;
    let main_d = -w / 2.0 - 0.2;
    let ramp_side = |s: f64| p.ramp_d(s) + w / 2.0 + 0.2;
    let parallel_start = p.merge_end_s - p.taper_m - p.accel_lane_m;
    let mut tip = ramp_start;
    while tip + 0.5 < parallel_start && ramp_side(tip + 0.5) < main_d {
        tip += 0.5;
    }
    let mut pts = path.offset_points(ramp_start, tip, 2.0, |_| main_d);
    let mut back = path.offset_points(ramp_start, tip, 2.0, ramp_side);
    back.reverse();
    pts.extend(back);
    pts.push(pts[0]);
    pts
}

/// Main-lane traffic around the main-lane vehicle at `s0`: a faster car 60–110 m ahead (60 %)
/// and one 25–45 m behind (50 %), as `(s, v, size, idm)`.
pub(super) fn main_lane_traffic(rng: &mut Pcg64Mcg, s0: f64) -> Vec<Background> {
    let mut background = Vec::new();
    if rng.random_bool(0.6) {
        let size = vehicle_size(rng);
        let v = rng.random_range(25.0..28.0);
        background.push((s0 + rng.random_range(60.0..110.0), v, size, idm(rng, v)));
    }
    if rng.random_bool(0.5) {
        let size = vehicle_size(rng);
        let v = rng.random_range(21.0..26.0);
        background.push((
            (s0 - rng.random_range(25.0..45.0)).max(-30.0),
            v * 0.95,
            size,
            idm(rng, v),
        ));
    }
    background
}

/// Draws the parameters of a merge scene.
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
    let background = main_lane_traffic(rng, a_s0);
    let n_agents = 2 + background.len();
    // Draw order is part of the data: keep it.
    let curvature = rng.random_range(-1.0 / 900.0..1.0 / 900.0);
    let accel_lane_m = rng.random_range(20.0..60.0);
    let ramp_angle_rad = rng.random_range(5f64..15.0).to_radians();
    let pair = PairSetup::draw(rng, (a_v_des, a_s0, a_v0), (b_v_des, b_s0, b_v0));
    MergeParams {
        ramp: Ramp {
            curvature,
            lane_width_m,
            merge_end_s,
            taper_m,
            accel_lane_m,
            ramp_angle_rad,
            lane_drop: None,
        },
        pair,
        background,
        noise: (0..n_agents).map(|_| noise_track(rng, NUM_STEPS)).collect(),
    }
}

impl Ramp {
    /// Where the taper starts on the main path.
    pub fn taper_start(&self) -> f64 {
        self.merge_end_s - self.taper_m
    }

    /// The ramp's lateral offset from the main lane: approach at an angle, parallel
    /// acceleration lane, cosine taper into the main lane ending at `merge_end_s`.
    pub fn ramp_d(&self, s: f64) -> f64 {
        let w = self.lane_width_m;
        let taper_start = self.merge_end_s - self.taper_m;
        let parallel_start = taper_start - self.accel_lane_m;
        if s >= self.merge_end_s {
            0.0
        } else if s >= taper_start {
            let u = (s - taper_start) / self.taper_m;
            -w * 0.5 * (1.0 + (std::f64::consts::PI * u).cos())
        } else if s >= parallel_start || self.lane_drop.is_some() {
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

    /// The scene's reference path (every agent moves along it, the ramp car at
    /// [`Self::ramp_d`]).
    pub fn paths(&self) -> Vec<RefPath> {
        vec![arc_path(0.0, 0.0, 0.0, self.curvature, 700.0)]
    }

    /// The map: the main lane before and after the merge, the ramp lane from `ramp_start`, the
    /// acceleration lane's road line, the road edges and the gore island (a lane drop:
    /// [`Self::lane_drop_map`]).
    pub fn map(&self, path: &RefPath, ramp_start: f64) -> Map {
        if let Some(limit_mps) = self.lane_drop {
            return self.lane_drop_map(path, limit_mps);
        }
        let w = self.lane_width_m;
        let taper_start = self.taper_start();
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
        Map {
            lanes: vec![
                lane(1, main_lane(-50.0, self.merge_end_s), vec![], vec![2]),
                lane(2, main_lane(self.merge_end_s, end), vec![1, 3], vec![]),
                lane(
                    3,
                    pts(path.offset_points(ramp_start, self.merge_end_s, 1.0, |s| self.ramp_d(s))),
                    vec![],
                    vec![2],
                ),
            ],
            road_lines: vec![RoadLine {
                id: 10,
                line_type: RoadLineType::BrokenSingleWhite,
                polyline: pts(path.offset_points(
                    taper_start - self.accel_lane_m,
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
                        if s < self.merge_end_s {
                            self.ramp_d(s) - w / 2.0 - 0.5
                        } else {
                            -w / 2.0 - 0.5
                        }
                    })),
                },
                RoadEdge {
                    id: 22,
                    edge_type: RoadEdgeType::Boundary,
                    polyline: pts(gore_island(path, self, ramp_start)),
                },
            ],
            ..Default::default()
        }
    }

    /// A lane drop's map: the through lane before and after the drop, the dropped lane beside
    /// it from the road's start to the taper's end (lane neighbours of each other up to the
    /// taper), the broken line between them, and the road's two edges, the right one along the
    /// dropped lane's outer side; lanes typed by the road's limit ([`super::road_class`]).
    fn lane_drop_map(&self, path: &RefPath, limit_mps: f64) -> Map {
        let w = self.lane_width_m;
        let (start, end) = (-50.0, 650.0);
        let taper_start = self.taper_start();
        let (lane_type, speed_limit_mph) = super::road_class(limit_mps);
        let lane = |id, polyline, entry: Vec<i64>, exit: Vec<i64>| Lane {
            id,
            lane_type,
            speed_limit_mph,
            polyline,
            entry_lanes: entry,
            exit_lanes: exit,
            ..Default::default()
        };
        let mut through = lane(
            1,
            pts(path.offset_points(start, self.merge_end_s, 1.0, |_| 0.0)),
            vec![],
            vec![2],
        );
        let mut dropped = lane(
            3,
            pts(path.offset_points(start, self.merge_end_s, 1.0, |s| self.ramp_d(s))),
            vec![],
            vec![2],
        );
        // Both polylines are sampled every metre from `start`: index k is at `start + k`.
        let beside_end = (taper_start - start).round() as i32;
        let neighbour = |id| LaneNeighbor {
            feature_id: id,
            self_start_index: 0,
            self_end_index: beside_end,
            neighbor_start_index: 0,
            neighbor_end_index: beside_end,
            ..Default::default()
        };
        through.right_neighbors.push(neighbour(3));
        dropped.left_neighbors.push(neighbour(1));
        let after = lane(
            2,
            pts(path.offset_points(self.merge_end_s, end, 1.0, |_| 0.0)),
            vec![1, 3],
            vec![],
        );
        Map {
            lanes: vec![through, after, dropped],
            road_lines: vec![RoadLine {
                id: 10,
                line_type: RoadLineType::BrokenSingleWhite,
                polyline: pts(path.offset_points(start, taper_start, 1.0, |_| -w / 2.0)),
            }],
            road_edges: vec![
                RoadEdge {
                    id: 20,
                    edge_type: RoadEdgeType::Boundary,
                    polyline: pts(path.offset_points(start, end, 2.0, |_| w / 2.0 + 0.5)),
                },
                RoadEdge {
                    id: 21,
                    edge_type: RoadEdgeType::Boundary,
                    polyline: pts(
                        path.offset_points(start, end, 2.0, |s| self.ramp_d(s) - w / 2.0 - 0.5)
                    ),
                },
            ],
            ..Default::default()
        }
    }
}

/// The reference path of a merge scene (every agent moves along it).
pub fn merge_paths(p: &MergeParams) -> Vec<RefPath> {
    p.ramp.paths()
}

/// Simulates a merge scene on its `paths` ([`merge_paths`]) with B as `b` says; the map is
/// built only when `with_map`.
pub fn simulate_merge(p: &MergeParams, paths: Vec<RefPath>, b: BPlan<'_>, with_map: bool) -> Run {
    let with_b = b.present();
    let path = &paths[0];
    let mut b_idm = p.pair.b_idm;
    let mut agents = p.pair.agents(0, p.ramp.ramp_d(p.pair.b_s0), with_b);
    let bg0 = agents.len();
    agents.extend(super::background_agents(&p.background, 0));
    let w = p.ramp.lane_width_m;
    let taper_start = p.ramp.merge_end_s - p.ramp.taper_m;
    let mut decision: Option<bool> = None; // Some(true) = B goes first
    for t in 0..b.steps() - 1 {
        let mut cmds = vec![0.0; agents.len()];
        let c = b.courtesy(t);
        // B's decision, latched at the commit point.
        // B decides from the current step on, so its courtesy shows in the future to predict.
        if with_b && decision.is_none() && t >= CURRENT_STEP && agents[1].s >= taper_start - 40.0 {
            let (a, b) = (&agents[0], &agents[1]);
            let mid = p.ramp.merge_end_s - p.ramp.taper_m * 0.5;
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
                let delay = if i == 0 && with_b && j == 1 {
                    p.pair.reaction_steps
                } else {
                    0
                };
                let (s_j, d_j, v_j) = other.delayed(delay);
                let relevant = if with_b && j == 1 && i != 1 {
                    // B matters to main-lane traffic once it is (about to be) in the lane.
                    merging_into_lane(d_j, other.delayed_lateral_rate(delay), w)
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
                p.ramp.ramp_d(a.s + a.v * STEP_SECS)
            } else {
                0.0
            };
            a.step(cmds[i], d_next);
        }
        b.after_step(&mut agents, t);
        let _ = bg0;
    }
    if !with_map {
        return Run {
            paths,
            agents,
            map: Map::default(),
        };
    }
    let ramp_start = (p.pair.b_s0 - 30.0)
        .min(taper_start - p.ramp.accel_lane_m - 20.0)
        .max(-50.0);
    let map = p.ramp.map(path, ramp_start);
    Run { paths, agents, map }
}
