//! Hand-written `prost` messages for the parts of WOMD's `scenario.proto`, `map.proto` and
//! TensorFlow's `example.proto` that scbg reads and writes.
//!
//! Hand-written rather than generated: the machine has no `protoc`, the messages are few and
//! stable, and `prost`'s derive gives the same wire behaviour as generated code. Field numbers
//! follow `shared/spec/womd-format.md`. Decoding accepts packed and unpacked repeated scalars
//! (prost handles both wire forms whatever the declaration) and skips unknown fields.
//! Encoding writes repeated scalars unpacked, as proto2 does by default.

use std::collections::BTreeMap;

/// `waymo.open_dataset.Scenario`: one scenario with its tracks, map and signals.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Scenario {
    /// One timestamp per step, seconds.
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub timestamps_seconds: Vec<f64>,
    /// Every object, each with one state per step.
    #[prost(message, repeated, tag = "2")]
    pub tracks: Vec<Track>,
    /// Track ids (not indices) of the objects labelled as interacting.
    #[prost(int32, repeated, packed = "false", tag = "4")]
    pub objects_of_interest: Vec<i32>,
    /// Unique scenario id; its presence is what makes a record a `Scenario`.
    #[prost(string, optional, tag = "5")]
    pub scenario_id: Option<String>,
    /// Index of the self-driving car's track in `tracks`.
    #[prost(int32, optional, tag = "6")]
    pub sdc_track_index: Option<i32>,
    /// Traffic-signal states, one entry per step (or none).
    #[prost(message, repeated, tag = "7")]
    pub dynamic_map_states: Vec<DynamicMapState>,
    /// Static map features.
    #[prost(message, repeated, tag = "8")]
    pub map_features: Vec<MapFeature>,
    /// Index of the current ("now") step in `timestamps_seconds`.
    #[prost(int32, optional, tag = "10")]
    pub current_time_index: Option<i32>,
    /// Tracks the benchmark asks to predict.
    #[prost(message, repeated, tag = "11")]
    pub tracks_to_predict: Vec<RequiredPrediction>,
}

/// `Scenario` without its tracks and map features (fields 2 and 8 are skipped unread): what
/// prost decodes while [`crate::fast`] reads those.
#[derive(Clone, PartialEq, prost::Message)]
pub struct ScenarioRest {
    /// See [`Scenario::timestamps_seconds`].
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub timestamps_seconds: Vec<f64>,
    /// See [`Scenario::objects_of_interest`].
    #[prost(int32, repeated, packed = "false", tag = "4")]
    pub objects_of_interest: Vec<i32>,
    /// See [`Scenario::scenario_id`].
    #[prost(string, optional, tag = "5")]
    pub scenario_id: Option<String>,
    /// See [`Scenario::sdc_track_index`].
    #[prost(int32, optional, tag = "6")]
    pub sdc_track_index: Option<i32>,
    /// See [`Scenario::dynamic_map_states`].
    #[prost(message, repeated, tag = "7")]
    pub dynamic_map_states: Vec<DynamicMapState>,
    /// See [`Scenario::current_time_index`].
    #[prost(int32, optional, tag = "10")]
    pub current_time_index: Option<i32>,
    /// See [`Scenario::tracks_to_predict`].
    #[prost(message, repeated, tag = "11")]
    pub tracks_to_predict: Vec<RequiredPrediction>,
}

impl ScenarioRest {
    /// The whole `Scenario` with these map features and no tracks (the caller keeps them).
    pub fn with_map(self, map_features: Vec<MapFeature>) -> Scenario {
        Scenario {
            timestamps_seconds: self.timestamps_seconds,
            tracks: Vec::new(),
            objects_of_interest: self.objects_of_interest,
            scenario_id: self.scenario_id,
            sdc_track_index: self.sdc_track_index,
            dynamic_map_states: self.dynamic_map_states,
            map_features,
            current_time_index: self.current_time_index,
            tracks_to_predict: self.tracks_to_predict,
        }
    }
}

/// `Track`: one object over every step of the scenario.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Track {
    /// Object id, unique within the scenario.
    #[prost(int32, optional, tag = "1")]
    pub id: Option<i32>,
    /// `Track.ObjectType` code (see [`scbg_scene::ObjectType`]).
    #[prost(int32, optional, tag = "2")]
    pub object_type: Option<i32>,
    /// One state per step.
    #[prost(message, repeated, tag = "3")]
    pub states: Vec<ObjectState>,
}

/// `ObjectState`: one object at one step, world frame (metres, radians, m/s).
#[derive(Clone, PartialEq, prost::Message)]
pub struct ObjectState {
    /// Box centre x, metres.
    #[prost(double, optional, tag = "2")]
    pub center_x: Option<f64>,
    /// Box centre y, metres.
    #[prost(double, optional, tag = "3")]
    pub center_y: Option<f64>,
    /// Box centre z, metres.
    #[prost(double, optional, tag = "4")]
    pub center_z: Option<f64>,
    /// Box length, metres.
    #[prost(float, optional, tag = "5")]
    pub length: Option<f32>,
    /// Box width, metres.
    #[prost(float, optional, tag = "6")]
    pub width: Option<f32>,
    /// Box height, metres.
    #[prost(float, optional, tag = "7")]
    pub height: Option<f32>,
    /// Heading, radians.
    #[prost(float, optional, tag = "8")]
    pub heading: Option<f32>,
    /// Velocity x, m/s.
    #[prost(float, optional, tag = "9")]
    pub velocity_x: Option<f32>,
    /// Velocity y, m/s.
    #[prost(float, optional, tag = "10")]
    pub velocity_y: Option<f32>,
    /// Whether the state was observed; when false the other fields are placeholders (−1).
    #[prost(bool, optional, tag = "11")]
    pub valid: Option<bool>,
}

/// `RequiredPrediction`: a track to predict.
#[derive(Clone, PartialEq, prost::Message)]
pub struct RequiredPrediction {
    /// Index into `Scenario.tracks`.
    #[prost(int32, optional, tag = "1")]
    pub track_index: Option<i32>,
    /// `DifficultyLevel` code (see [`scbg_scene::PredictionDifficulty`]).
    #[prost(int32, optional, tag = "2")]
    pub difficulty: Option<i32>,
}

/// `DynamicMapState`: the signal states at one step.
#[derive(Clone, PartialEq, prost::Message)]
pub struct DynamicMapState {
    /// One entry per signal-controlled lane.
    #[prost(message, repeated, tag = "1")]
    pub lane_states: Vec<TrafficSignalLaneState>,
}

/// `TrafficSignalLaneState`: the signal controlling one lane.
#[derive(Clone, PartialEq, prost::Message)]
pub struct TrafficSignalLaneState {
    /// Id of the controlled lane's map feature.
    #[prost(int64, optional, tag = "1")]
    pub lane: Option<i64>,
    /// `State` code (see [`scbg_scene::SignalState`]).
    #[prost(int32, optional, tag = "2")]
    pub state: Option<i32>,
    /// Where vehicles in the lane must stop.
    #[prost(message, optional, tag = "3")]
    pub stop_point: Option<MapPoint>,
}

/// `MapPoint`: a point in the world frame, metres.
#[derive(Clone, Copy, PartialEq, prost::Message)]
pub struct MapPoint {
    /// x, metres.
    #[prost(double, optional, tag = "1")]
    pub x: Option<f64>,
    /// y, metres.
    #[prost(double, optional, tag = "2")]
    pub y: Option<f64>,
    /// z, metres.
    #[prost(double, optional, tag = "3")]
    pub z: Option<f64>,
}

/// `MapFeature`: one static map feature, with its id and kind-specific data.
#[derive(Clone, PartialEq, prost::Message)]
pub struct MapFeature {
    /// Feature id, unique within the scenario's map.
    #[prost(int64, optional, tag = "1")]
    pub id: Option<i64>,
    /// The feature's kind and data (`None` for a kind this reader does not know).
    #[prost(oneof = "MapFeatureData", tags = "3, 4, 5, 7, 8, 9, 10")]
    pub feature_data: Option<MapFeatureData>,
}

/// The `feature_data` oneof of [`MapFeature`].
#[derive(Clone, PartialEq, prost::Oneof)]
pub enum MapFeatureData {
    /// A lane centreline.
    #[prost(message, tag = "3")]
    Lane(LaneCenter),
    /// A painted road line.
    #[prost(message, tag = "4")]
    RoadLine(RoadLine),
    /// A road edge.
    #[prost(message, tag = "5")]
    RoadEdge(RoadEdge),
    /// A stop sign.
    #[prost(message, tag = "7")]
    StopSign(StopSign),
    /// A crosswalk polygon.
    #[prost(message, tag = "8")]
    Crosswalk(PolygonFeature),
    /// A speed-bump polygon.
    #[prost(message, tag = "9")]
    SpeedBump(PolygonFeature),
    /// A driveway polygon.
    #[prost(message, tag = "10")]
    Driveway(PolygonFeature),
}

/// `LaneCenter`: a lane centreline with its type, links, neighbours and boundaries.
#[derive(Clone, PartialEq, prost::Message)]
pub struct LaneCenter {
    /// Speed limit, miles per hour.
    #[prost(double, optional, tag = "1")]
    pub speed_limit_mph: Option<f64>,
    /// `LaneType` code (see [`scbg_scene::LaneType`]).
    #[prost(int32, optional, tag = "2")]
    pub lane_type: Option<i32>,
    /// True if the lane interpolates between two other lanes (e.g. inside an intersection).
    #[prost(bool, optional, tag = "3")]
    pub interpolating: Option<bool>,
    /// Centreline points, in driving direction.
    #[prost(message, repeated, tag = "8")]
    pub polyline: Vec<MapPoint>,
    /// Ids of lanes this lane may be entered from.
    #[prost(int64, repeated, packed = "true", tag = "9")]
    pub entry_lanes: Vec<i64>,
    /// Ids of lanes this lane may exit to.
    #[prost(int64, repeated, packed = "true", tag = "10")]
    pub exit_lanes: Vec<i64>,
    /// Lanes to the left.
    #[prost(message, repeated, tag = "11")]
    pub left_neighbors: Vec<LaneNeighbor>,
    /// Lanes to the right.
    #[prost(message, repeated, tag = "12")]
    pub right_neighbors: Vec<LaneNeighbor>,
    /// Road lines / edges bounding the lane on the left.
    #[prost(message, repeated, tag = "13")]
    pub left_boundaries: Vec<BoundarySegment>,
    /// Road lines / edges bounding the lane on the right.
    #[prost(message, repeated, tag = "14")]
    pub right_boundaries: Vec<BoundarySegment>,
}

/// `BoundarySegment`: part of a lane bounded by one road line or edge.
#[derive(Clone, PartialEq, prost::Message)]
pub struct BoundarySegment {
    /// Index into the lane's polyline where the segment starts.
    #[prost(int32, optional, tag = "1")]
    pub lane_start_index: Option<i32>,
    /// Index into the lane's polyline where the segment ends.
    #[prost(int32, optional, tag = "2")]
    pub lane_end_index: Option<i32>,
    /// Id of the bounding road line or edge.
    #[prost(int64, optional, tag = "3")]
    pub boundary_feature_id: Option<i64>,
    /// `RoadLineType` code of the boundary.
    #[prost(int32, optional, tag = "4")]
    pub boundary_type: Option<i32>,
}

/// `LaneNeighbor`: a neighbouring lane over an index range of this lane.
#[derive(Clone, PartialEq, prost::Message)]
pub struct LaneNeighbor {
    /// Id of the neighbouring lane.
    #[prost(int64, optional, tag = "1")]
    pub feature_id: Option<i64>,
    /// Index into this lane's polyline where the neighbouring segment starts.
    #[prost(int32, optional, tag = "2")]
    pub self_start_index: Option<i32>,
    /// Index into this lane's polyline where the neighbouring segment ends.
    #[prost(int32, optional, tag = "3")]
    pub self_end_index: Option<i32>,
    /// Index into the neighbour's polyline where the shared segment starts.
    #[prost(int32, optional, tag = "4")]
    pub neighbor_start_index: Option<i32>,
    /// Index into the neighbour's polyline where the shared segment ends.
    #[prost(int32, optional, tag = "5")]
    pub neighbor_end_index: Option<i32>,
    /// Boundaries between the two lanes within the shared segment.
    #[prost(message, repeated, tag = "6")]
    pub boundaries: Vec<BoundarySegment>,
}

/// `RoadLine`: a painted line.
#[derive(Clone, PartialEq, prost::Message)]
pub struct RoadLine {
    /// `RoadLineType` code (see [`scbg_scene::RoadLineType`]).
    #[prost(int32, optional, tag = "1")]
    pub line_type: Option<i32>,
    /// Line points.
    #[prost(message, repeated, tag = "2")]
    pub polyline: Vec<MapPoint>,
}

/// `RoadEdge`: a road edge (kerb, median).
#[derive(Clone, PartialEq, prost::Message)]
pub struct RoadEdge {
    /// `RoadEdgeType` code (see [`scbg_scene::RoadEdgeType`]).
    #[prost(int32, optional, tag = "1")]
    pub edge_type: Option<i32>,
    /// Edge points.
    #[prost(message, repeated, tag = "2")]
    pub polyline: Vec<MapPoint>,
}

/// `StopSign`: a stop sign and the lanes it controls.
#[derive(Clone, PartialEq, prost::Message)]
pub struct StopSign {
    /// Ids of the controlled lanes.
    #[prost(int64, repeated, packed = "false", tag = "1")]
    pub lane: Vec<i64>,
    /// Position of the sign.
    #[prost(message, optional, tag = "2")]
    pub position: Option<MapPoint>,
}

/// Crosswalk, SpeedBump and Driveway share one shape: `polygon = 1`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PolygonFeature {
    /// Outline points.
    #[prost(message, repeated, tag = "1")]
    pub polygon: Vec<MapPoint>,
}

// ---- tensorflow/core/example/{example,feature}.proto ----

/// `tensorflow.Example`: a map of named features.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Example {
    /// The feature map.
    #[prost(message, optional, tag = "1")]
    pub features: Option<Features>,
}

/// `tensorflow.Features`: features by name.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Features {
    /// Feature name (e.g. `state/past/x`) → values.
    #[prost(btree_map = "string, message", tag = "1")]
    pub feature: BTreeMap<String, Feature>,
}

/// `tensorflow.Feature`: one list of bytes, floats or integers.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Feature {
    /// The list (`None` for an empty feature).
    #[prost(oneof = "FeatureKind", tags = "1, 2, 3")]
    pub kind: Option<FeatureKind>,
}

/// The `kind` oneof of [`Feature`].
#[derive(Clone, PartialEq, prost::Oneof)]
pub enum FeatureKind {
    /// Byte strings.
    #[prost(message, tag = "1")]
    BytesList(BytesList),
    /// 32-bit floats.
    #[prost(message, tag = "2")]
    FloatList(FloatList),
    /// 64-bit integers.
    #[prost(message, tag = "3")]
    Int64List(Int64List),
}

/// `tensorflow.BytesList`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct BytesList {
    /// The byte strings.
    #[prost(bytes = "vec", repeated, tag = "1")]
    pub value: Vec<Vec<u8>>,
}

/// `tensorflow.FloatList`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct FloatList {
    /// The floats.
    #[prost(float, repeated, packed = "true", tag = "1")]
    pub value: Vec<f32>,
}

/// `tensorflow.Int64List`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Int64List {
    /// The integers.
    #[prost(int64, repeated, packed = "true", tag = "1")]
    pub value: Vec<i64>,
}
