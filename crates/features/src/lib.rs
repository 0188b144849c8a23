//! From [`Scene`](scbg_scene::Scene) to model-ready samples, framework-free.
//!
//! Main types:
//! - [`PreparedScene`]: a compact, scene-level form of a `Scene` (tracks relative to an
//!   origin, road polylines already subsampled and typed), with its [`Window`]s and
//!   [`InteractingPair`]s. This is what the cache stores, once per scenario.
//! - [`AgentSample`]: the Multipath++ agent-centric features of one target agent in one
//!   window (plus, optionally, the conditioning future of the other agent of a pair), built on
//!   demand by [`extract_sample`] — so the cache never materialises every agent's view.
//! - [`cache`]: sharded, memory-mappable files of prepared scenes and their manifest.
//!
//! **Architecture invariant:** no tensors and no deep-learning framework here: samples are
//! plain `Vec<f32>` arrays with documented shapes and `valid` masks. No file formats other
//! than the cache's own; protobuf/TFRecord are unknown to this crate.

#![warn(missing_docs)]

mod build;
mod builder;
pub mod cache;
mod codec;
mod lane_move;
mod lane_path;
mod pairs;
mod prepared;
mod road_index;
mod sample;
mod stats;
mod window;

pub use build::PrepareError;
pub use builder::{SampleBuilder, extract_sample};
pub use codec::DecodeError;
pub use lane_move::{
    FollowerRoom, LANE_MOVE_M, LanePath, lane_move, leaves_room, sample_lane_path,
};
pub use lane_path::{
    LANE_PATH_BEHIND_M, LANE_PATH_POINTS, LANE_PATH_SPACING_M, lane_path, lane_path_arc_m,
};
pub use pairs::{PairConfig, select_pairs};
pub use prepared::{
    InteractingPair, PairSource, PreparedScene, PreparedTrack, RoadKind, RoadPolyline,
};
pub use sample::{
    AGENT_FEATURES, AgentSample, DIFF_FEATURES, FeatureConfig, ROAD_FEATURES, ROAD_TYPES,
    SampleError, marginal_targets,
};
pub use stats::FeatureStats;
pub use window::{Window, WindowConfig, window_scene, windows};
