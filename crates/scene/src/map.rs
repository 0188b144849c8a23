//! Static map features of a scene, in the world frame (metres).

/// A map point in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MapPoint {
    /// x, world frame, metres.
    pub x_m: f64,
    /// y, world frame, metres.
    pub y_m: f64,
    /// z (elevation), world frame, metres.
    pub z_m: f64,
}

/// A closed polygon (crosswalk, speed bump, driveway) in the world frame.
pub type Polygon = Vec<MapPoint>;

macro_rules! int_enum {
    ($(#[$m:meta])* $name:ident { $($variant:ident = $value:expr),+ $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
        pub enum $name {
            #[default]
            $(
                #[doc = concat!("`", stringify!($variant), "` (WOMD code ", stringify!($value), ").")]
                $variant = $value
            ),+
        }
        impl $name {
            /// Every variant, in code order.
            pub const ALL: &'static [$name] = &[$($name::$variant),+];
            /// The variant for a protobuf enum code; unknown codes map to the zero variant.
            pub fn from_code(code: i32) -> Self {
                match code {
                    $($value => $name::$variant,)+
                    _ => Self::default(),
                }
            }
            /// The protobuf enum code.
            pub fn code(self) -> i32 {
                self as i32
            }
        }
    };
}

int_enum!(
    /// WOMD `LaneCenter.LaneType`.
    LaneType { Undefined = 0, Freeway = 1, SurfaceStreet = 2, BikeLane = 3 }
);
int_enum!(
    /// WOMD `RoadLine.RoadLineType`.
    RoadLineType {
        Unknown = 0,
        BrokenSingleWhite = 1,
        SolidSingleWhite = 2,
        SolidDoubleWhite = 3,
        BrokenSingleYellow = 4,
        BrokenDoubleYellow = 5,
        SolidSingleYellow = 6,
        SolidDoubleYellow = 7,
        PassingDoubleYellow = 8,
    }
);
int_enum!(
    /// WOMD `RoadEdge.RoadEdgeType`.
    RoadEdgeType { Unknown = 0, Boundary = 1, Median = 2 }
);

/// Part of a lane bounded by a road line or edge (`LaneCenter.left/right_boundaries`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BoundarySegment {
    /// Index into the lane's polyline where this segment starts.
    pub lane_start_index: i32,
    /// Index into the lane's polyline where this segment ends.
    pub lane_end_index: i32,
    /// Id of the road line or road edge that bounds the lane here.
    pub boundary_feature_id: i64,
    /// Type of the bounding road line.
    pub boundary_type: RoadLineType,
}

/// A neighbouring lane over an index range of this lane (`LaneCenter.left/right_neighbors`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LaneNeighbor {
    /// Id of the neighbouring lane.
    pub feature_id: i64,
    /// Index into this lane's polyline where the neighbouring segment starts.
    pub self_start_index: i32,
    /// Index into this lane's polyline where the neighbouring segment ends.
    pub self_end_index: i32,
    /// Index into the neighbour's polyline where the shared segment starts.
    pub neighbor_start_index: i32,
    /// Index into the neighbour's polyline where the shared segment ends.
    pub neighbor_end_index: i32,
    /// Boundaries between the two lanes within the shared segment.
    pub boundaries: Vec<BoundarySegment>,
}

/// A lane centreline.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Lane {
    /// Map feature id.
    pub id: i64,
    /// Lane type.
    pub lane_type: LaneType,
    /// Speed limit, when the map gives one.
    pub speed_limit_mph: Option<f64>,
    /// True if the lane interpolates between two other lanes (e.g. inside an intersection).
    pub interpolating: bool,
    /// Centreline points, world frame, in driving direction.
    pub polyline: Vec<MapPoint>,
    /// Ids of lanes this lane may be entered from.
    pub entry_lanes: Vec<i64>,
    /// Ids of lanes this lane may exit to.
    pub exit_lanes: Vec<i64>,
    /// Lanes to the left, each over an index range of this lane.
    pub left_neighbors: Vec<LaneNeighbor>,
    /// Lanes to the right, each over an index range of this lane.
    pub right_neighbors: Vec<LaneNeighbor>,
    /// Road lines / edges bounding the lane on the left.
    pub left_boundaries: Vec<BoundarySegment>,
    /// Road lines / edges bounding the lane on the right.
    pub right_boundaries: Vec<BoundarySegment>,
}

/// A painted road line.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RoadLine {
    /// Map feature id.
    pub id: i64,
    /// Paint type.
    pub line_type: RoadLineType,
    /// Line points, world frame.
    pub polyline: Vec<MapPoint>,
}

/// A road edge (kerb, median).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RoadEdge {
    /// Map feature id.
    pub id: i64,
    /// Edge type.
    pub edge_type: RoadEdgeType,
    /// Edge points, world frame.
    pub polyline: Vec<MapPoint>,
}

/// A stop sign controlling the listed lanes.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StopSign {
    /// Map feature id.
    pub id: i64,
    /// Ids of the lanes the sign controls.
    pub lanes: Vec<i64>,
    /// Position of the sign, world frame.
    pub position: MapPoint,
}

/// A crosswalk polygon.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Crosswalk {
    /// Map feature id.
    pub id: i64,
    /// Outline, world frame.
    pub polygon: Polygon,
}

/// A speed-bump polygon.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SpeedBump {
    /// Map feature id.
    pub id: i64,
    /// Outline, world frame.
    pub polygon: Polygon,
}

/// A driveway polygon.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Driveway {
    /// Map feature id.
    pub id: i64,
    /// Outline, world frame.
    pub polygon: Polygon,
}

/// All static map features of a scene, grouped by kind (each kind keeps its file order).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Map {
    /// Lane centrelines.
    pub lanes: Vec<Lane>,
    /// Painted road lines.
    pub road_lines: Vec<RoadLine>,
    /// Road edges.
    pub road_edges: Vec<RoadEdge>,
    /// Stop signs.
    pub stop_signs: Vec<StopSign>,
    /// Crosswalk polygons.
    pub crosswalks: Vec<Crosswalk>,
    /// Speed-bump polygons.
    pub speed_bumps: Vec<SpeedBump>,
    /// Driveway polygons.
    pub driveways: Vec<Driveway>,
}

impl Map {
    /// Total number of map features of every kind.
    pub fn num_features(&self) -> usize {
        self.lanes.len()
            + self.road_lines.len()
            + self.road_edges.len()
            + self.stop_signs.len()
            + self.crosswalks.len()
            + self.speed_bumps.len()
            + self.driveways.len()
    }

    /// True when the scene carries no map at all.
    pub fn is_empty(&self) -> bool {
        self.num_features() == 0
    }

    /// Looks a lane up by id (linear scan; maps hold a few hundred lanes).
    pub fn lane(&self, id: i64) -> Option<&Lane> {
        self.lanes.iter().find(|lane| lane.id == id)
    }

    /// Every point of every polyline and polygon, for bounds and sanity checks.
    pub fn all_points(&self) -> impl Iterator<Item = &MapPoint> {
        self.lanes
            .iter()
            .flat_map(|f| f.polyline.iter())
            .chain(self.road_lines.iter().flat_map(|f| f.polyline.iter()))
            .chain(self.road_edges.iter().flat_map(|f| f.polyline.iter()))
            .chain(self.stop_signs.iter().map(|f| &f.position))
            .chain(self.crosswalks.iter().flat_map(|f| f.polygon.iter()))
            .chain(self.speed_bumps.iter().flat_map(|f| f.polygon.iter()))
            .chain(self.driveways.iter().flat_map(|f| f.polygon.iter()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn enum_codes_round_trip_and_unknown_maps_to_zero() {
        for t in RoadLineType::ALL {
            assert_eq!(RoadLineType::from_code(t.code()), *t);
        }
        assert_eq!(LaneType::from_code(99), LaneType::Undefined);
        assert_eq!(RoadEdgeType::from_code(2), RoadEdgeType::Median);
    }
}
