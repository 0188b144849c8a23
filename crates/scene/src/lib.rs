//! The `Scene`: a plain value type describing one recorded (or generated) traffic scenario.
//!
//! Main types: [`Scene`], [`Track`], [`AgentState`], [`Map`] with its feature kinds, and the
//! rigid transform [`Pose2`] used to move points between the world frame and an agent's frame.
//!
//! A `Scene` is the boundary between the dataset formats and everything downstream: readers
//! produce it, the synthetic generator produces it, feature extraction consumes it.
//!
//! **Architecture invariant:** this crate knows nothing about file formats (protobuf,
//! TFRecord, tf.Example), about tensors or deep-learning frameworks, or about I/O. It has no
//! dependencies beyond `thiserror`. Every per-step quantity carries a `valid` flag; sentinel
//! values such as `-1` are never interpreted.

#![warn(missing_docs)]

mod geometry;
mod map;
mod scene;

pub use geometry::{Pose2, wrap_angle_rad};
pub use map::{
    BoundarySegment, Crosswalk, Driveway, Lane, LaneNeighbor, LaneType, Map, MapPoint, Polygon,
    RoadEdge, RoadEdgeType, RoadLine, RoadLineType, SpeedBump, StopSign,
};
pub use scene::{
    AgentState, MAX_ABS_VALUE, ObjectType, PredictionDifficulty, PredictionTarget, Scene,
    SceneError, SignalLaneState, SignalState, Track,
};
