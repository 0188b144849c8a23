//! A scene from plain arrays, as a simulator holds its state (the Python module's
//! `Scene.from_arrays`, a client's own converter).

use scbg_scene::{
    AgentState, Lane, LaneType, Map, MapPoint, ObjectType, RoadEdge, RoadEdgeType, RoadLine,
    RoadLineType, Scene, Track,
};

use crate::InvalidRequest;

/// One agent's state in a [`SceneArrays`] row: x, y (m), heading (rad), vx, vy (m/s), length,
/// width (m).
pub type StateRow = [f64; 7];

/// Agents' histories and a map as arrays: what [`SceneArrays::build`] turns into a [`Scene`].
///
/// Steps are 0.1 s apart. Lanes become car lanes of the given types (unknown when none are
/// given), road edges road boundaries, road lines broken single white lines, with ids counted
/// from 1.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SceneArrays {
    /// The scenario's id.
    pub scenario_id: String,
    /// Track id per agent.
    pub ids: Vec<i64>,
    /// `[agent][step]` states.
    pub states: Vec<Vec<StateRow>>,
    /// `[agent][step]` validity; every agent has as many steps as the first.
    pub valid: Vec<Vec<bool>>,
    /// Object type name per agent (`vehicle`, `pedestrian`, `cyclist`, `other`, `unset`);
    /// `None`: all vehicles.
    pub object_types: Option<Vec<String>>,
    /// The step the future starts after.
    pub current_step: usize,
    /// The self-driving car's track id.
    pub sdc_id: Option<i64>,
    /// Track ids of the objects of interest.
    pub objects_of_interest: Vec<i64>,
    /// Lane centre lines, world metres.
    pub lanes: Vec<Vec<[f64; 2]>>,
    /// Type name per lane (`freeway`, `surface_street`, `bike_lane`, `undefined`); `None`: all
    /// undefined. The learned models read a lane's type: a road of the kind they were trained
    /// on should say so.
    pub lane_types: Option<Vec<String>>,
    /// Road edges, world metres.
    pub road_edges: Vec<Vec<[f64; 2]>>,
    /// Road lines, world metres.
    pub road_lines: Vec<Vec<[f64; 2]>>,
}

fn object_type(name: &str) -> Result<ObjectType, InvalidRequest> {
    Ok(match name {
        "vehicle" => ObjectType::Vehicle,
        "pedestrian" => ObjectType::Pedestrian,
        "cyclist" => ObjectType::Cyclist,
        "other" => ObjectType::Other,
        "unset" => ObjectType::Unset,
        other => {
            return Err(InvalidRequest(format!(
                "object type {other:?}: expected vehicle, pedestrian, cyclist, other or unset"
            )));
        }
    })
}

fn lane_type(name: &str) -> Result<LaneType, InvalidRequest> {
    Ok(match name {
        "freeway" => LaneType::Freeway,
        "surface_street" => LaneType::SurfaceStreet,
        "bike_lane" => LaneType::BikeLane,
        "undefined" => LaneType::Undefined,
        other => {
            return Err(InvalidRequest(format!(
                "lane type {other:?}: expected freeway, surface_street, bike_lane or undefined"
            )));
        }
    })
}

fn points(line: &[[f64; 2]]) -> Vec<MapPoint> {
    line.iter()
        .map(|p| MapPoint {
            x_m: p[0],
            y_m: p[1],
            z_m: 0.0,
        })
        .collect()
}

impl SceneArrays {
    /// The scene, checked ([`Scene::validate`]); a wrong shape, unknown name or id is an
    /// [`InvalidRequest`] naming the field.
    pub fn build(self) -> Result<Scene, InvalidRequest> {
        let n = self.ids.len();
        let t = self.states.first().map_or(0, Vec::len);
        if self.states.len() != n || self.valid.len() != n {
            return Err(InvalidRequest(format!(
                "ids has {n} agents, states {} and valid {}",
                self.states.len(),
                self.valid.len()
            )));
        }
        if let Some(i) = (0..n).find(|&i| self.states[i].len() != t || self.valid[i].len() != t) {
            return Err(InvalidRequest(format!(
                "agent {i}: {} states and {} valid flags, expected {t} steps",
                self.states[i].len(),
                self.valid[i].len()
            )));
        }
        let types = match &self.object_types {
            Some(v) if v.len() != n => {
                return Err(InvalidRequest(format!(
                    "object_types has {} names for {n} agents",
                    v.len()
                )));
            }
            Some(v) => v
                .iter()
                .map(|s| object_type(s))
                .collect::<Result<Vec<_>, _>>()?,
            None => vec![ObjectType::Vehicle; n],
        };
        let tracks: Vec<Track> = (0..n)
            .map(|i| Track {
                id: self.ids[i],
                object_type: types[i],
                states: (0..t)
                    .map(|k| {
                        let s = self.states[i][k];
                        AgentState {
                            x_m: s[0],
                            y_m: s[1],
                            z_m: 0.0,
                            heading_rad: s[2] as f32,
                            velocity_x_mps: s[3] as f32,
                            velocity_y_mps: s[4] as f32,
                            length_m: s[5] as f32,
                            width_m: s[6] as f32,
                            height_m: 1.6,
                            valid: self.valid[i][k],
                        }
                    })
                    .collect(),
            })
            .collect();
        let sdc_track_index = match self.sdc_id {
            None => None,
            Some(id) => Some(
                tracks
                    .iter()
                    .position(|tr| tr.id == id)
                    .ok_or_else(|| InvalidRequest(format!("sdc_id {id} is not one of the ids")))?,
            ),
        };
        let lane_types = match &self.lane_types {
            Some(v) if v.len() != self.lanes.len() => {
                return Err(InvalidRequest(format!(
                    "lane_types has {} names for {} lanes",
                    v.len(),
                    self.lanes.len()
                )));
            }
            Some(v) => v
                .iter()
                .map(|s| lane_type(s))
                .collect::<Result<Vec<_>, _>>()?,
            None => vec![LaneType::Undefined; self.lanes.len()],
        };
        let mut id = 0i64;
        let mut next = || {
            id += 1;
            id
        };
        let map = Map {
            lanes: self
                .lanes
                .iter()
                .zip(&lane_types)
                .map(|(l, &lane_type)| Lane {
                    id: next(),
                    lane_type,
                    polyline: points(l),
                    ..Default::default()
                })
                .collect(),
            road_edges: self
                .road_edges
                .iter()
                .map(|l| RoadEdge {
                    id: next(),
                    edge_type: RoadEdgeType::Boundary,
                    polyline: points(l),
                })
                .collect(),
            road_lines: self
                .road_lines
                .iter()
                .map(|l| RoadLine {
                    id: next(),
                    line_type: RoadLineType::BrokenSingleWhite,
                    polyline: points(l),
                })
                .collect(),
            ..Default::default()
        };
        let scene = Scene {
            scenario_id: self.scenario_id,
            timestamps_secs: (0..t).map(|k| k as f64 * 0.1).collect(),
            current_step: self.current_step,
            sdc_track_index,
            tracks,
            objects_of_interest: self.objects_of_interest,
            tracks_to_predict: Vec::new(),
            map,
            signals_per_step: Vec::new(),
        };
        scene
            .validate()
            .map_err(|e| InvalidRequest(format!("invalid scene: {e}")))?;
        Ok(scene)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_agents() -> SceneArrays {
        let row = |x: f64| [x, 0.0, 0.0, 10.0, 0.0, 4.5, 2.0];
        SceneArrays {
            scenario_id: "s".into(),
            ids: vec![7, 9],
            states: vec![
                (0..11).map(|k| row(k as f64)).collect(),
                (0..11).map(|k| row(20.0 + k as f64)).collect(),
            ],
            valid: vec![vec![true; 11]; 2],
            current_step: 10,
            sdc_id: Some(9),
            lanes: vec![vec![[0.0, 0.0], [50.0, 0.0]]],
            ..Default::default()
        }
    }

    #[test]
    fn arrays_become_a_scene() {
        let scene = two_agents().build().unwrap();
        assert_eq!(scene.tracks.len(), 2);
        assert_eq!(scene.num_steps(), 11);
        assert_eq!(scene.sdc_track_index, Some(1));
        assert_eq!(scene.tracks[1].states[3].x_m, 23.0);
        assert_eq!(scene.map.lanes[0].polyline.len(), 2);
        assert_eq!(scene.map.lanes[0].lane_type, LaneType::Undefined);
        let mut a = two_agents();
        a.lane_types = Some(vec!["freeway".into()]);
        assert_eq!(a.build().unwrap().map.lanes[0].lane_type, LaneType::Freeway);
    }

    #[test]
    fn wrong_shapes_and_names_are_named() {
        let mut a = two_agents();
        a.valid[1].pop();
        assert!(a.build().unwrap_err().0.contains("agent 1"));
        let mut a = two_agents();
        a.object_types = Some(vec!["vehicle".into(), "tram".into()]);
        assert!(a.build().unwrap_err().0.contains("tram"));
        let mut a = two_agents();
        a.sdc_id = Some(3);
        assert!(a.build().unwrap_err().0.contains("sdc_id 3"));
        let mut a = two_agents();
        a.lane_types = Some(vec!["motorway".into()]);
        assert!(a.build().unwrap_err().0.contains("motorway"));
        let mut a = two_agents();
        a.lane_types = Some(vec![]);
        assert!(a.build().unwrap_err().0.contains("0 names for 1 lanes"));
    }
}
