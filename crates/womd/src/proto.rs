//! Hand-written `prost` messages for the parts of WOMD's `scenario.proto`, `map.proto` and
//! TensorFlow's `example.proto` that scbg reads and writes.
//!
//! Hand-written rather than generated: the machine has no `protoc`, the messages are few and
//! stable, and `prost`'s derive gives the same wire behaviour as generated code. Field numbers
//! follow `shared/spec/womd-format.md`. Decoding accepts packed and unpacked repeated scalars
//! (prost handles both wire forms whatever the declaration) and skips unknown fields.
//! Encoding writes repeated scalars unpacked, as proto2 does by default.

use std::collections::BTreeMap;

#[derive(Clone, PartialEq, prost::Message)]
pub struct Scenario {
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub timestamps_seconds: Vec<f64>,
    #[prost(message, repeated, tag = "2")]
    pub tracks: Vec<Track>,
    #[prost(int32, repeated, packed = "false", tag = "4")]
    pub objects_of_interest: Vec<i32>,
    #[prost(string, optional, tag = "5")]
    pub scenario_id: Option<String>,
    #[prost(int32, optional, tag = "6")]
    pub sdc_track_index: Option<i32>,
    #[prost(message, repeated, tag = "7")]
    pub dynamic_map_states: Vec<DynamicMapState>,
    #[prost(message, repeated, tag = "8")]
    pub map_features: Vec<MapFeature>,
    #[prost(int32, optional, tag = "10")]
    pub current_time_index: Option<i32>,
    #[prost(message, repeated, tag = "11")]
    pub tracks_to_predict: Vec<RequiredPrediction>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct Track {
    #[prost(int32, optional, tag = "1")]
    pub id: Option<i32>,
    #[prost(int32, optional, tag = "2")]
    pub object_type: Option<i32>,
    #[prost(message, repeated, tag = "3")]
    pub states: Vec<ObjectState>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct ObjectState {
    #[prost(double, optional, tag = "2")]
    pub center_x: Option<f64>,
    #[prost(double, optional, tag = "3")]
    pub center_y: Option<f64>,
    #[prost(double, optional, tag = "4")]
    pub center_z: Option<f64>,
    #[prost(float, optional, tag = "5")]
    pub length: Option<f32>,
    #[prost(float, optional, tag = "6")]
    pub width: Option<f32>,
    #[prost(float, optional, tag = "7")]
    pub height: Option<f32>,
    #[prost(float, optional, tag = "8")]
    pub heading: Option<f32>,
    #[prost(float, optional, tag = "9")]
    pub velocity_x: Option<f32>,
    #[prost(float, optional, tag = "10")]
    pub velocity_y: Option<f32>,
    #[prost(bool, optional, tag = "11")]
    pub valid: Option<bool>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct RequiredPrediction {
    #[prost(int32, optional, tag = "1")]
    pub track_index: Option<i32>,
    #[prost(int32, optional, tag = "2")]
    pub difficulty: Option<i32>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct DynamicMapState {
    #[prost(message, repeated, tag = "1")]
    pub lane_states: Vec<TrafficSignalLaneState>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct TrafficSignalLaneState {
    #[prost(int64, optional, tag = "1")]
    pub lane: Option<i64>,
    #[prost(int32, optional, tag = "2")]
    pub state: Option<i32>,
    #[prost(message, optional, tag = "3")]
    pub stop_point: Option<MapPoint>,
}

#[derive(Clone, Copy, PartialEq, prost::Message)]
pub struct MapPoint {
    #[prost(double, optional, tag = "1")]
    pub x: Option<f64>,
    #[prost(double, optional, tag = "2")]
    pub y: Option<f64>,
    #[prost(double, optional, tag = "3")]
    pub z: Option<f64>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct MapFeature {
    #[prost(int64, optional, tag = "1")]
    pub id: Option<i64>,
    #[prost(oneof = "MapFeatureData", tags = "3, 4, 5, 7, 8, 9, 10")]
    pub feature_data: Option<MapFeatureData>,
}

#[derive(Clone, PartialEq, prost::Oneof)]
pub enum MapFeatureData {
    #[prost(message, tag = "3")]
    Lane(LaneCenter),
    #[prost(message, tag = "4")]
    RoadLine(RoadLine),
    #[prost(message, tag = "5")]
    RoadEdge(RoadEdge),
    #[prost(message, tag = "7")]
    StopSign(StopSign),
    #[prost(message, tag = "8")]
    Crosswalk(PolygonFeature),
    #[prost(message, tag = "9")]
    SpeedBump(PolygonFeature),
    #[prost(message, tag = "10")]
    Driveway(PolygonFeature),
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct LaneCenter {
    #[prost(double, optional, tag = "1")]
    pub speed_limit_mph: Option<f64>,
    #[prost(int32, optional, tag = "2")]
    pub lane_type: Option<i32>,
    #[prost(bool, optional, tag = "3")]
    pub interpolating: Option<bool>,
    #[prost(message, repeated, tag = "8")]
    pub polyline: Vec<MapPoint>,
    #[prost(int64, repeated, packed = "true", tag = "9")]
    pub entry_lanes: Vec<i64>,
    #[prost(int64, repeated, packed = "true", tag = "10")]
    pub exit_lanes: Vec<i64>,
    #[prost(message, repeated, tag = "11")]
    pub left_neighbors: Vec<LaneNeighbor>,
    #[prost(message, repeated, tag = "12")]
    pub right_neighbors: Vec<LaneNeighbor>,
    #[prost(message, repeated, tag = "13")]
    pub left_boundaries: Vec<BoundarySegment>,
    #[prost(message, repeated, tag = "14")]
    pub right_boundaries: Vec<BoundarySegment>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct BoundarySegment {
    #[prost(int32, optional, tag = "1")]
    pub lane_start_index: Option<i32>,
    #[prost(int32, optional, tag = "2")]
    pub lane_end_index: Option<i32>,
    #[prost(int64, optional, tag = "3")]
    pub boundary_feature_id: Option<i64>,
    #[prost(int32, optional, tag = "4")]
    pub boundary_type: Option<i32>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct LaneNeighbor {
    #[prost(int64, optional, tag = "1")]
    pub feature_id: Option<i64>,
    #[prost(int32, optional, tag = "2")]
    pub self_start_index: Option<i32>,
    #[prost(int32, optional, tag = "3")]
    pub self_end_index: Option<i32>,
    #[prost(int32, optional, tag = "4")]
    pub neighbor_start_index: Option<i32>,
    #[prost(int32, optional, tag = "5")]
    pub neighbor_end_index: Option<i32>,
    #[prost(message, repeated, tag = "6")]
    pub boundaries: Vec<BoundarySegment>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct RoadLine {
    #[prost(int32, optional, tag = "1")]
    pub line_type: Option<i32>,
    #[prost(message, repeated, tag = "2")]
    pub polyline: Vec<MapPoint>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct RoadEdge {
    #[prost(int32, optional, tag = "1")]
    pub edge_type: Option<i32>,
    #[prost(message, repeated, tag = "2")]
    pub polyline: Vec<MapPoint>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct StopSign {
    #[prost(int64, repeated, packed = "false", tag = "1")]
    pub lane: Vec<i64>,
    #[prost(message, optional, tag = "2")]
    pub position: Option<MapPoint>,
}

/// Crosswalk, SpeedBump and Driveway share one shape: `polygon = 1`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PolygonFeature {
    #[prost(message, repeated, tag = "1")]
    pub polygon: Vec<MapPoint>,
}

// ---- tensorflow/core/example/{example,feature}.proto ----

#[derive(Clone, PartialEq, prost::Message)]
pub struct Example {
    #[prost(message, optional, tag = "1")]
    pub features: Option<Features>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct Features {
    #[prost(btree_map = "string, message", tag = "1")]
    pub feature: BTreeMap<String, Feature>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct Feature {
    #[prost(oneof = "FeatureKind", tags = "1, 2, 3")]
    pub kind: Option<FeatureKind>,
}

#[derive(Clone, PartialEq, prost::Oneof)]
pub enum FeatureKind {
    #[prost(message, tag = "1")]
    BytesList(BytesList),
    #[prost(message, tag = "2")]
    FloatList(FloatList),
    #[prost(message, tag = "3")]
    Int64List(Int64List),
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct BytesList {
    #[prost(bytes = "vec", repeated, tag = "1")]
    pub value: Vec<Vec<u8>>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct FloatList {
    #[prost(float, repeated, packed = "true", tag = "1")]
    pub value: Vec<f32>,
}

#[derive(Clone, PartialEq, prost::Message)]
pub struct Int64List {
    #[prost(int64, repeated, packed = "true", tag = "1")]
    pub value: Vec<i64>,
}
