//! [`PreparedScene`]: the compact scene-level form stored in the cache, and the types it is
//! made of. Built from a `Scene` by `PreparedScene::from_scene` (`build.rs`), encoded and
//! decoded by `codec.rs`.

use scbg_scene::ObjectType;

use crate::window::Window;

/// The 20 road-segment types of the Multipath++ road encoding (one-hot index = discriminant).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum RoadKind {
    /// Lane centreline, type undefined.
    LaneUndefined = 0,
    /// Lane centreline, freeway.
    LaneFreeway,
    /// Lane centreline, surface street.
    LaneSurfaceStreet,
    /// Lane centreline, bike lane.
    LaneBike,
    /// Road line, type unknown.
    LineUnknown,
    /// Road line, broken single white.
    LineBrokenSingleWhite,
    /// Road line, solid single white.
    LineSolidSingleWhite,
    /// Road line, solid double white.
    LineSolidDoubleWhite,
    /// Road line, broken single yellow.
    LineBrokenSingleYellow,
    /// Road line, broken double yellow.
    LineBrokenDoubleYellow,
    /// Road line, solid single yellow.
    LineSolidSingleYellow,
    /// Road line, solid double yellow.
    LineSolidDoubleYellow,
    /// Road line, passing double yellow.
    LinePassingDoubleYellow,
    /// Road edge, type unknown.
    EdgeUnknown,
    /// Road edge, boundary (kerb).
    EdgeBoundary,
    /// Road edge, median.
    EdgeMedian,
    /// Stop sign (a single point).
    StopSign,
    /// Crosswalk outline (closed polygon).
    Crosswalk,
    /// Speed-bump outline (closed polygon).
    SpeedBump,
    /// Driveway outline (closed polygon).
    Driveway,
}

impl RoadKind {
    /// Number of kinds (the one-hot width, [`ROAD_TYPES`](crate::ROAD_TYPES)).
    pub const COUNT: usize = 20;

    /// The kind with this one-hot index (discriminant), or `None` if `i >= COUNT`.
    pub fn from_index(i: u8) -> Option<Self> {
        use RoadKind::*;
        const ALL: [RoadKind; RoadKind::COUNT] = [
            LaneUndefined,
            LaneFreeway,
            LaneSurfaceStreet,
            LaneBike,
            LineUnknown,
            LineBrokenSingleWhite,
            LineSolidSingleWhite,
            LineSolidDoubleWhite,
            LineBrokenSingleYellow,
            LineBrokenDoubleYellow,
            LineSolidSingleYellow,
            LineSolidDoubleYellow,
            LinePassingDoubleYellow,
            EdgeUnknown,
            EdgeBoundary,
            EdgeMedian,
            StopSign,
            Crosswalk,
            SpeedBump,
            Driveway,
        ];
        ALL.get(usize::from(i)).copied()
    }

    /// Whether this is a lane centreline kind.
    pub fn is_lane(self) -> bool {
        (self as u8) <= Self::LaneBike as u8
    }
}

/// A road polyline, subsampled, relative to the scene origin.
#[derive(Debug, Clone, PartialEq)]
pub struct RoadPolyline {
    /// What the polyline is.
    pub kind: RoadKind,
    /// `[points, 2]` x, y in metres relative to [`PreparedScene::origin_xy_m`].
    pub xy_m: Vec<[f32; 2]>,
}

/// One track, every step, relative to the scene origin. Invalid steps hold zeros.
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedTrack {
    /// Track id, as in the source [`Scene`](scbg_scene::Scene).
    pub id: i64,
    /// Object type.
    pub object_type: ObjectType,
    /// Whether this is the self-driving car's track.
    pub is_sdc: bool,
    /// Mean box size over valid steps.
    pub length_m: f32,
    /// Mean box width over valid steps, metres.
    pub width_m: f32,
    /// `[steps]` each.
    pub valid: Vec<bool>,
    /// x relative to [`PreparedScene::origin_xy_m`], metres.
    pub x_m: Vec<f32>,
    /// y relative to [`PreparedScene::origin_xy_m`], metres.
    pub y_m: Vec<f32>,
    /// Heading, radians, world frame.
    pub heading_rad: Vec<f32>,
    /// Velocity x, m/s, world frame.
    pub vx_mps: Vec<f32>,
    /// Velocity y, m/s, world frame.
    pub vy_mps: Vec<f32>,
}

impl PreparedTrack {
    /// Speed at `step`, m/s (0 where invalid). Panics if `step` is out of range.
    pub fn speed_mps(&self, step: usize) -> f32 {
        (self.vx_mps[step] * self.vx_mps[step] + self.vy_mps[step] * self.vy_mps[step]).sqrt()
    }

    /// Valid at `step`, with out-of-range steps counting as invalid.
    pub fn valid_at(&self, step: isize) -> bool {
        usize::try_from(step)
            .ok()
            .and_then(|s| self.valid.get(s).copied())
            .unwrap_or(false)
    }
}

/// A scene reduced to what features need, with its windows and interacting pairs.
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedScene {
    /// Scenario id of the source scene.
    pub scenario_id: String,
    /// World position that every `x_m`/`y_m` here is relative to.
    pub origin_xy_m: [f64; 2],
    /// Steps of every track (`valid.len()` etc.).
    pub num_steps: usize,
    /// Seconds between steps (from the timestamps; 0.1 when they give none).
    pub step_secs: f32,
    /// Tracks with a valid step in some window's history (so indices differ from the scene's).
    pub tracks: Vec<PreparedTrack>,
    /// Typed, subsampled road polylines.
    pub road: Vec<RoadPolyline>,
    /// The scene's windows.
    pub windows: Vec<Window>,
    /// Pairs per window: `pairs[w]` belongs to `windows[w]`.
    pub pairs: Vec<Vec<InteractingPair>>,
}

/// How pairs were found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PairSource {
    /// The scene's `objects_of_interest` label.
    Labelled = 0,
    /// Found by the mining rule of [`select_pairs`](crate::select_pairs).
    Mined = 1,
}

/// Two interacting vehicles, as indices into [`PreparedScene::tracks`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InteractingPair {
    /// One vehicle of the pair.
    pub first: usize,
    /// The other vehicle (the order carries no meaning).
    pub second: usize,
    /// How the pair was found.
    pub source: PairSource,
}

impl PreparedScene {
    /// Index of the track with this id.
    pub fn track_index(&self, id: i64) -> Option<usize> {
        self.tracks.iter().position(|t| t.id == id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn road_kind_indices_are_dense() {
        for i in 0..RoadKind::COUNT as u8 {
            assert_eq!(RoadKind::from_index(i).unwrap() as u8, i);
        }
        assert!(RoadKind::from_index(20).is_none());
    }
}
