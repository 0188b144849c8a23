//! `Scenario` protobuf ↔ [`Scene`].

use prost::Message;
use scbg_scene::{
    AgentState, BoundarySegment, Crosswalk, Driveway, Lane, LaneNeighbor, LaneType, Map, MapPoint,
    ObjectType, PredictionDifficulty, PredictionTarget, RoadEdge, RoadEdgeType, RoadLine,
    RoadLineType, Scene, SignalLaneState, SignalState, SpeedBump, StopSign, Track,
};

use crate::proto;

/// Why a decoded `Scenario` could not become a [`Scene`] (before [`Scene::validate`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScenarioError {
    /// `scenario_id` is absent.
    #[error("field `scenario_id` is missing: not a WOMD Scenario")]
    MissingScenarioId,
    /// `timestamps_seconds` is empty.
    #[error("field `timestamps_seconds` is empty: not a WOMD Scenario")]
    NoTimestamps,
    /// `current_time_index` is negative (the value given).
    #[error("field `current_time_index` is {0}, must be >= 0")]
    NegativeCurrentIndex(i32),
    /// A `tracks_to_predict` entry has a negative track index (the value given).
    #[error("field `tracks_to_predict.track_index` is {0}, must be >= 0")]
    NegativeTrackIndex(i32),
    /// `dynamic_map_states` is neither empty nor one entry per timestamp.
    #[allow(missing_docs)]
    #[error("field `dynamic_map_states` has {got} steps, expected 0 or {num_steps}")]
    SignalSteps { got: usize, num_steps: usize },
    /// The converted scene fails [`Scene::validate`].
    #[error(transparent)]
    Scene(#[from] scbg_scene::SceneError),
}

fn point(p: &proto::MapPoint) -> MapPoint {
    MapPoint {
        x_m: p.x(),
        y_m: p.y(),
        z_m: p.z(),
    }
}

fn points(ps: &[proto::MapPoint]) -> Vec<MapPoint> {
    ps.iter().map(point).collect()
}

fn boundary(b: &proto::BoundarySegment) -> BoundarySegment {
    BoundarySegment {
        lane_start_index: b.lane_start_index(),
        lane_end_index: b.lane_end_index(),
        boundary_feature_id: b.boundary_feature_id(),
        boundary_type: RoadLineType::from_code(b.boundary_type()),
    }
}

fn neighbor(n: &proto::LaneNeighbor) -> LaneNeighbor {
    LaneNeighbor {
        feature_id: n.feature_id(),
        self_start_index: n.self_start_index(),
        self_end_index: n.self_end_index(),
        neighbor_start_index: n.neighbor_start_index(),
        neighbor_end_index: n.neighbor_end_index(),
        boundaries: n.boundaries.iter().map(boundary).collect(),
    }
}

fn map_from_proto(features: &[proto::MapFeature]) -> Map {
    use proto::MapFeatureData as D;
    let mut map = Map::default();
    for f in features {
        let id = f.id();
        match &f.feature_data {
            Some(D::Lane(l)) => map.lanes.push(Lane {
                id,
                lane_type: LaneType::from_code(l.lane_type()),
                speed_limit_mph: l.speed_limit_mph,
                interpolating: l.interpolating(),
                polyline: points(&l.polyline),
                entry_lanes: l.entry_lanes.clone(),
                exit_lanes: l.exit_lanes.clone(),
                left_neighbors: l.left_neighbors.iter().map(neighbor).collect(),
                right_neighbors: l.right_neighbors.iter().map(neighbor).collect(),
                left_boundaries: l.left_boundaries.iter().map(boundary).collect(),
                right_boundaries: l.right_boundaries.iter().map(boundary).collect(),
            }),
            Some(D::RoadLine(l)) => map.road_lines.push(RoadLine {
                id,
                line_type: RoadLineType::from_code(l.line_type()),
                polyline: points(&l.polyline),
            }),
            Some(D::RoadEdge(e)) => map.road_edges.push(RoadEdge {
                id,
                edge_type: RoadEdgeType::from_code(e.edge_type()),
                polyline: points(&e.polyline),
            }),
            Some(D::StopSign(s)) => map.stop_signs.push(StopSign {
                id,
                lanes: s.lane.clone(),
                position: s.position.as_ref().map(point).unwrap_or_default(),
            }),
            Some(D::Crosswalk(p)) => map.crosswalks.push(Crosswalk {
                id,
                polygon: points(&p.polygon),
            }),
            Some(D::SpeedBump(p)) => map.speed_bumps.push(SpeedBump {
                id,
                polygon: points(&p.polygon),
            }),
            Some(D::Driveway(p)) => map.driveways.push(Driveway {
                id,
                polygon: points(&p.polygon),
            }),
            None => {} // a feature kind this reader does not know: skipped, like unknown fields
        }
    }
    map
}

/// A scene track from a decoded `Track` (absent fields read as their defaults).
pub(crate) fn scene_track(t: &proto::Track) -> Track {
    Track {
        id: i64::from(t.id()),
        object_type: ObjectType::from_code(t.object_type()),
        states: t
            .states
            .iter()
            .map(|st| AgentState {
                x_m: st.center_x(),
                y_m: st.center_y(),
                z_m: st.center_z(),
                length_m: st.length(),
                width_m: st.width(),
                height_m: st.height(),
                heading_rad: st.heading(),
                velocity_x_mps: st.velocity_x(),
                velocity_y_mps: st.velocity_y(),
                valid: st.valid(),
            })
            .collect(),
    }
}

/// Converts a decoded `Scenario` into a validated [`Scene`].
pub fn scene_from_scenario(s: &proto::Scenario) -> Result<Scene, ScenarioError> {
    scene_from_parts(s, s.tracks.iter().map(scene_track).collect())
}

/// [`scene_from_scenario`] with the tracks already converted: `s.tracks` is ignored.
pub(crate) fn scene_from_parts(
    s: &proto::Scenario,
    tracks: Vec<Track>,
) -> Result<Scene, ScenarioError> {
    let scenario_id = s
        .scenario_id
        .clone()
        .ok_or(ScenarioError::MissingScenarioId)?;
    if s.timestamps_seconds.is_empty() {
        return Err(ScenarioError::NoTimestamps);
    }
    let num_steps = s.timestamps_seconds.len();
    let current = s.current_time_index();
    let current_step =
        usize::try_from(current).map_err(|_| ScenarioError::NegativeCurrentIndex(current))?;
    let tracks_to_predict = s
        .tracks_to_predict
        .iter()
        .map(|r| {
            let i = r.track_index();
            Ok(PredictionTarget {
                track_index: usize::try_from(i)
                    .map_err(|_| ScenarioError::NegativeTrackIndex(i))?,
                difficulty: PredictionDifficulty::from_code(r.difficulty()),
            })
        })
        .collect::<Result<Vec<_>, ScenarioError>>()?;
    if !s.dynamic_map_states.is_empty() && s.dynamic_map_states.len() != num_steps {
        return Err(ScenarioError::SignalSteps {
            got: s.dynamic_map_states.len(),
            num_steps,
        });
    }
    let signals_per_step = s
        .dynamic_map_states
        .iter()
        .map(|d| {
            d.lane_states
                .iter()
                .map(|l| SignalLaneState {
                    lane_id: l.lane(),
                    state: SignalState::from_code(l.state()),
                    stop_point: l.stop_point.as_ref().map(point),
                })
                .collect()
        })
        .collect();
    let scene = Scene {
        scenario_id,
        timestamps_secs: s.timestamps_seconds.clone(),
        current_step,
        // An index outside the track list (seen in re-encoded files that dropped tracks) means
        // "no known SDC", not a broken scenario.
        sdc_track_index: s
            .sdc_track_index
            .and_then(|i| usize::try_from(i).ok())
            .filter(|&i| i < tracks.len()),
        tracks,
        objects_of_interest: s
            .objects_of_interest
            .iter()
            .map(|&id| i64::from(id))
            .collect(),
        tracks_to_predict,
        map: map_from_proto(&s.map_features),
        signals_per_step,
    };
    scene.validate()?;
    Ok(scene)
}

fn proto_point(p: &MapPoint) -> proto::MapPoint {
    proto::MapPoint {
        x: Some(p.x_m),
        y: Some(p.y_m),
        z: Some(p.z_m),
    }
}

fn proto_points(ps: &[MapPoint]) -> Vec<proto::MapPoint> {
    ps.iter().map(proto_point).collect()
}

fn proto_boundary(b: &BoundarySegment) -> proto::BoundarySegment {
    proto::BoundarySegment {
        lane_start_index: Some(b.lane_start_index),
        lane_end_index: Some(b.lane_end_index),
        boundary_feature_id: Some(b.boundary_feature_id),
        boundary_type: Some(b.boundary_type.code()),
    }
}

fn proto_neighbor(n: &LaneNeighbor) -> proto::LaneNeighbor {
    proto::LaneNeighbor {
        feature_id: Some(n.feature_id),
        self_start_index: Some(n.self_start_index),
        self_end_index: Some(n.self_end_index),
        neighbor_start_index: Some(n.neighbor_start_index),
        neighbor_end_index: Some(n.neighbor_end_index),
        boundaries: n.boundaries.iter().map(proto_boundary).collect(),
    }
}

fn map_to_proto(map: &Map) -> Vec<proto::MapFeature> {
    use proto::MapFeatureData as D;
    let feature = |id: i64, data: D| proto::MapFeature {
        id: Some(id),
        feature_data: Some(data),
    };
    let polygon = |p: &[MapPoint]| proto::PolygonFeature {
        polygon: proto_points(p),
    };
    let mut out = Vec::with_capacity(map.num_features());
    out.extend(map.lanes.iter().map(|l| {
        feature(
            l.id,
            D::Lane(proto::LaneCenter {
                speed_limit_mph: l.speed_limit_mph,
                lane_type: Some(l.lane_type.code()),
                interpolating: Some(l.interpolating),
                polyline: proto_points(&l.polyline),
                entry_lanes: l.entry_lanes.clone(),
                exit_lanes: l.exit_lanes.clone(),
                left_neighbors: l.left_neighbors.iter().map(proto_neighbor).collect(),
                right_neighbors: l.right_neighbors.iter().map(proto_neighbor).collect(),
                left_boundaries: l.left_boundaries.iter().map(proto_boundary).collect(),
                right_boundaries: l.right_boundaries.iter().map(proto_boundary).collect(),
            }),
        )
    }));
    out.extend(map.road_lines.iter().map(|l| {
        feature(
            l.id,
            D::RoadLine(proto::RoadLine {
                line_type: Some(l.line_type.code()),
                polyline: proto_points(&l.polyline),
            }),
        )
    }));
    out.extend(map.road_edges.iter().map(|e| {
        feature(
            e.id,
            D::RoadEdge(proto::RoadEdge {
                edge_type: Some(e.edge_type.code()),
                polyline: proto_points(&e.polyline),
            }),
        )
    }));
    out.extend(map.stop_signs.iter().map(|s| {
        feature(
            s.id,
            D::StopSign(proto::StopSign {
                lane: s.lanes.clone(),
                position: Some(proto_point(&s.position)),
            }),
        )
    }));
    out.extend(
        map.crosswalks
            .iter()
            .map(|c| feature(c.id, D::Crosswalk(polygon(&c.polygon)))),
    );
    out.extend(
        map.speed_bumps
            .iter()
            .map(|c| feature(c.id, D::SpeedBump(polygon(&c.polygon)))),
    );
    out.extend(
        map.driveways
            .iter()
            .map(|c| feature(c.id, D::Driveway(polygon(&c.polygon)))),
    );
    out
}

/// Error for a scene that the `Scenario` format cannot hold.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("track id {0} does not fit the int32 `Track.id` of the Scenario format")]
pub struct TrackIdOverflow(pub i64);

/// Converts a [`Scene`] into a `Scenario` message (the inverse of [`scene_from_scenario`]).
pub fn scenario_from_scene(scene: &Scene) -> Result<proto::Scenario, TrackIdOverflow> {
    let to_i32 = |id: i64| i32::try_from(id).map_err(|_| TrackIdOverflow(id));
    let tracks = scene
        .tracks
        .iter()
        .map(|t| {
            Ok(proto::Track {
                id: Some(to_i32(t.id)?),
                object_type: Some(t.object_type.code()),
                states: t
                    .states
                    .iter()
                    .map(|s| proto::ObjectState {
                        center_x: Some(s.x_m),
                        center_y: Some(s.y_m),
                        center_z: Some(s.z_m),
                        length: Some(s.length_m),
                        width: Some(s.width_m),
                        height: Some(s.height_m),
                        heading: Some(s.heading_rad),
                        velocity_x: Some(s.velocity_x_mps),
                        velocity_y: Some(s.velocity_y_mps),
                        valid: Some(s.valid),
                    })
                    .collect(),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(proto::Scenario {
        timestamps_seconds: scene.timestamps_secs.clone(),
        tracks,
        objects_of_interest: scene
            .objects_of_interest
            .iter()
            .map(|&id| to_i32(id))
            .collect::<Result<_, _>>()?,
        scenario_id: Some(scene.scenario_id.clone()),
        sdc_track_index: scene.sdc_track_index.map(|i| i as i32),
        dynamic_map_states: scene
            .signals_per_step
            .iter()
            .map(|step| proto::DynamicMapState {
                lane_states: step
                    .iter()
                    .map(|l| proto::TrafficSignalLaneState {
                        lane: Some(l.lane_id),
                        state: Some(l.state as i32),
                        stop_point: l.stop_point.as_ref().map(proto_point),
                    })
                    .collect(),
            })
            .collect(),
        map_features: map_to_proto(&scene.map),
        current_time_index: Some(scene.current_step as i32),
        tracks_to_predict: scene
            .tracks_to_predict
            .iter()
            .map(|t| proto::RequiredPrediction {
                track_index: Some(t.track_index as i32),
                difficulty: Some(t.difficulty as i32),
            })
            .collect(),
    })
}

/// Serializes a [`Scene`] as `Scenario` protobuf bytes.
pub fn encode_scene(scene: &Scene) -> Result<Vec<u8>, TrackIdOverflow> {
    Ok(scenario_from_scene(scene)?.encode_to_vec())
}
