//! Per-step features of the evaluated objects for one joint scene (or the log): §4–§5 of the
//! spec.

use scbg_scene::{ObjectType, Scene};

use super::geometry::{self, Point};
use super::interaction::{self, TtcBox};
use super::kinematics;
use super::road_edge::RoadEdges;
use super::traffic_light::TrafficLights;
use super::{
    CURRENT_STEP, DT_S, FIRST_FUTURE_STEP, LARGE_DISTANCE_M, SCENARIO_STEPS, SIMULATED_STEPS,
    SimPose, WosacError, evaluated_agent_ids,
};

/// Static facts about the sim agents, in the internal order: evaluated objects first (ascending
/// id), then the other sim agents in track order.
#[derive(Debug, Clone)]
pub(crate) struct Objects {
    /// Track ids.
    pub ids: Vec<i64>,
    /// Index into `scene.tracks`.
    pub track_index: Vec<usize>,
    /// Object types from the log.
    pub object_type: Vec<ObjectType>,
    /// Box length at the current step, metres.
    pub length_m: Vec<f32>,
    /// Box width at the current step, metres.
    pub width_m: Vec<f32>,
    /// Box height at the current step, metres.
    pub height_m: Vec<f32>,
    /// The first `num_evaluated` objects are the evaluated ones.
    pub num_evaluated: usize,
}

impl Objects {
    /// Expects a scene with the WOSAC layout (checked by the caller).
    pub fn new(scene: &Scene) -> Result<Self, WosacError> {
        let is_sim = |i: usize| scene.tracks[i].states[CURRENT_STEP].valid;
        let evaluated = evaluated_agent_ids(scene);
        if evaluated.is_empty() {
            return Err(WosacError::NoEvaluatedObjects {
                scenario_id: scene.scenario_id.clone(),
            });
        }
        let mut order = Vec::with_capacity(scene.tracks.len());
        for &id in &evaluated {
            let Some(i) = scene.track_index(id).filter(|&i| is_sim(i)) else {
                return Err(WosacError::EvaluatedNotSimulated {
                    scenario_id: scene.scenario_id.clone(),
                    object_id: id,
                });
            };
            order.push(i);
        }
        for (i, track) in scene.tracks.iter().enumerate() {
            if is_sim(i) && !evaluated.contains(&track.id) {
                order.push(i);
            }
        }
        let current = |i: usize| scene.tracks[i].states[CURRENT_STEP];
        Ok(Self {
            ids: order.iter().map(|&i| scene.tracks[i].id).collect(),
            object_type: order.iter().map(|&i| scene.tracks[i].object_type).collect(),
            length_m: order.iter().map(|&i| current(i).length_m).collect(),
            width_m: order.iter().map(|&i| current(i).width_m).collect(),
            height_m: order.iter().map(|&i| current(i).height_m).collect(),
            track_index: order,
            num_evaluated: evaluated.len(),
        })
    }

    pub fn len(&self) -> usize {
        self.ids.len()
    }
}

/// The 91-step series of every sim agent for one joint scene or the log, internal order,
/// flattened `[object * 91 + step]`, float32.
#[derive(Debug, Clone)]
pub(crate) struct Trajectories {
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    pub z: Vec<f32>,
    pub heading: Vec<f32>,
    valid: Vec<bool>,
}

impl Trajectories {
    pub fn index(&self, object: usize, step: usize) -> usize {
        object * SCENARIO_STEPS + step
    }

    pub fn valid(&self, object: usize, step: usize) -> bool {
        self.valid[self.index(object, step)]
    }

    fn row<'a, T>(&self, v: &'a [T], object: usize) -> &'a [T] {
        &v[object * SCENARIO_STEPS..(object + 1) * SCENARIO_STEPS]
    }

    /// The log pseudo-rollout: every step copied from the log, invalid states included.
    pub fn from_log(scene: &Scene, objects: &Objects) -> Self {
        let n = objects.len() * SCENARIO_STEPS;
        let mut t = Self {
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            z: Vec::with_capacity(n),
            heading: Vec::with_capacity(n),
            valid: Vec::with_capacity(n),
        };
        for &i in &objects.track_index {
            for s in &scene.tracks[i].states {
                t.x.push(s.x_m as f32);
                t.y.push(s.y_m as f32);
                t.z.push(s.z_m as f32);
                t.heading.push(s.heading_rad);
                t.valid.push(s.valid);
            }
        }
        t
    }

    /// Replaces the future (steps 11..=90) by one joint scene, valid everywhere; `to_rollout`
    /// maps internal object index → index in the joint scene.
    pub fn set_future(&mut self, joint_scene: &[Vec<SimPose>], to_rollout: &[usize]) {
        for (o, &r) in to_rollout.iter().enumerate() {
            for (f, p) in joint_scene[r].iter().enumerate() {
                let k = self.index(o, FIRST_FUTURE_STEP + f);
                self.x[k] = p.x_m;
                self.y[k] = p.y_m;
                self.z[k] = p.z_m;
                self.heading[k] = p.heading_rad;
                self.valid[k] = true;
            }
        }
    }
}

/// The features of the evaluated objects over the 80 future steps, flattened
/// `[evaluated object * 80 + future step]`.
#[derive(Debug, Clone, Default)]
pub(crate) struct Features {
    pub linear_speed_mps: Vec<f32>,
    pub linear_acceleration_mps2: Vec<f32>,
    pub angular_speed_radps: Vec<f32>,
    pub angular_acceleration_radps2: Vec<f32>,
    pub distance_to_nearest_object_m: Vec<f32>,
    pub collision: Vec<bool>,
    pub time_to_collision_s: Vec<f32>,
    pub distance_to_road_edge_m: Vec<f32>,
    pub offroad: Vec<bool>,
    pub traffic_light_violation: Vec<bool>,
}

/// Buffers reused across joint scenes.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    road_edge: Vec<f32>,
    speed_2d: Vec<f32>,
    cores: Vec<[Point; 4]>,
}

/// The rounded-box geometry of one object at one step.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RoundedBox {
    /// Corner rounding radius `r = 0.7 · min(length, width) / 2`.
    pub radius_m: f32,
    /// Half-diagonal of the full box (bounding circle, for pruning).
    pub bound_m: f32,
}

impl RoundedBox {
    pub fn new(length_m: f32, width_m: f32) -> Self {
        Self {
            radius_m: geometry::rounding_radius(length_m, width_m),
            bound_m: 0.5 * (length_m * length_m + width_m * width_m).sqrt(),
        }
    }
}

/// Computes every feature of the evaluated objects for one set of trajectories.
pub(crate) fn compute(
    traj: &Trajectories,
    objects: &Objects,
    road_edges: &RoadEdges,
    lights: &TrafficLights,
    scratch: &mut Scratch,
) -> Features {
    let n_eval = objects.num_evaluated;
    let n_obj = objects.len();
    let len = n_eval * SIMULATED_STEPS;
    let mut out = Features {
        linear_speed_mps: Vec::with_capacity(len),
        linear_acceleration_mps2: Vec::with_capacity(len),
        angular_speed_radps: Vec::with_capacity(len),
        angular_acceleration_radps2: Vec::with_capacity(len),
        distance_to_nearest_object_m: vec![0.0; len],
        collision: vec![false; len],
        time_to_collision_s: vec![0.0; len],
        distance_to_road_edge_m: vec![0.0; len],
        offroad: vec![false; len],
        traffic_light_violation: Vec::with_capacity(len),
    };
    let future = FIRST_FUTURE_STEP..SCENARIO_STEPS;

    // Kinematics on the full 91 steps, cut to the future.
    for i in 0..n_eval {
        let k = kinematics::kinematic_features(
            traj.row(&traj.x, i),
            traj.row(&traj.y, i),
            traj.row(&traj.z, i),
            traj.row(&traj.heading, i),
            DT_S,
        );
        out.linear_speed_mps
            .extend_from_slice(&k.speed_mps[future.clone()]);
        out.linear_acceleration_mps2
            .extend_from_slice(&k.acceleration_mps2[future.clone()]);
        out.angular_speed_radps
            .extend_from_slice(&k.angular_speed_radps[future.clone()]);
        out.angular_acceleration_radps2
            .extend_from_slice(&k.angular_acceleration_radps2[future.clone()]);
    }

    // 2-D speeds of every object (for the time to collision).
    scratch.speed_2d.clear();
    for o in 0..n_obj {
        scratch.speed_2d.extend(kinematics::speed_2d(
            traj.row(&traj.x, o),
            traj.row(&traj.y, o),
            DT_S,
        ));
    }

    let shapes: Vec<RoundedBox> = (0..n_obj)
        .map(|o| RoundedBox::new(objects.length_m[o], objects.width_m[o]))
        .collect();
    let mut ttc_boxes = Vec::with_capacity(n_obj);
    for (f, t) in future.clone().enumerate() {
        // Core rectangles of every object at this step.
        scratch.cores.clear();
        for (o, shape) in shapes.iter().enumerate() {
            let k = traj.index(o, t);
            let r = shape.radius_m;
            scratch.cores.push(geometry::box_corners(
                traj.x[k],
                traj.y[k],
                objects.length_m[o] - 2.0 * r,
                objects.width_m[o] - 2.0 * r,
                traj.heading[k],
            ));
        }
        ttc_boxes.clear();
        ttc_boxes.extend((0..n_obj).map(|o| {
            let k = traj.index(o, t);
            TtcBox {
                x_m: traj.x[k],
                y_m: traj.y[k],
                length_m: objects.length_m[o],
                width_m: objects.width_m[o],
                heading_rad: traj.heading[k],
                speed_mps: scratch.speed_2d[k],
                valid: traj.valid[k],
            }
        }));
        for i in 0..n_eval {
            let slot = i * SIMULATED_STEPS + f;
            let ki = traj.index(i, t);

            // Distance to the nearest object (1e10 when i is invalid or alone).
            let mut nearest = LARGE_DISTANCE_M;
            if traj.valid[ki] {
                for j in 0..n_obj {
                    let kj = traj.index(j, t);
                    if j == i || !traj.valid[kj] {
                        continue;
                    }
                    let dx = traj.x[kj] - traj.x[ki];
                    let dy = traj.y[kj] - traj.y[ki];
                    let lower_bound =
                        (dx * dx + dy * dy).sqrt() - shapes[i].bound_m - shapes[j].bound_m;
                    if lower_bound > nearest + 1e-3 + 1e-4 * nearest.abs() {
                        continue;
                    }
                    let d = geometry::signed_distance_between_quads(
                        &scratch.cores[i],
                        &scratch.cores[j],
                    ) - shapes[i].radius_m
                        - shapes[j].radius_m;
                    nearest = nearest.min(d);
                }
            }
            out.distance_to_nearest_object_m[slot] = nearest;
            out.collision[slot] = nearest < 0.0;

            out.time_to_collision_s[slot] = interaction::time_to_collision(i, &ttc_boxes);

            // Distance to the road edge: max over the 4 bottom corners of the full box.
            let edge = if traj.valid[ki] {
                let corners = geometry::box_corners(
                    traj.x[ki],
                    traj.y[ki],
                    objects.length_m[i],
                    objects.width_m[i],
                    traj.heading[ki],
                );
                let z = traj.z[ki] - objects.height_m[i] * 0.5;
                corners
                    .iter()
                    .map(|c| road_edges.signed_distance([c[0], c[1], z], &mut scratch.road_edge))
                    .fold(f32::NEG_INFINITY, f32::max)
            } else {
                -LARGE_DISTANCE_M
            };
            out.distance_to_road_edge_m[slot] = edge;
            out.offroad[slot] = edge > 0.0;
        }
    }

    for i in 0..n_eval {
        out.traffic_light_violation.extend(lights.violations(
            traj.row(&traj.x, i),
            traj.row(&traj.y, i),
            traj.row(&traj.valid, i),
        ));
    }
    out
}
