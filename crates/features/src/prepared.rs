//! [`PreparedScene`]: the compact scene-level form stored in the cache.

use scbg_scene::{LaneType, ObjectType, RoadEdgeType, RoadLineType, Scene};

use crate::pairs::{InteractingPair, PairConfig, select_pairs};
use crate::window::{Window, WindowConfig, windows};

/// The 20 road-segment types of the Multipath++ road encoding (one-hot index = discriminant).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum RoadKind {
    LaneUndefined = 0,
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
}

impl RoadKind {
    pub const COUNT: usize = 20;

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

    fn lane(t: LaneType) -> Self {
        match t {
            LaneType::Undefined => Self::LaneUndefined,
            LaneType::Freeway => Self::LaneFreeway,
            LaneType::SurfaceStreet => Self::LaneSurfaceStreet,
            LaneType::BikeLane => Self::LaneBike,
        }
    }

    fn line(t: RoadLineType) -> Self {
        Self::from_index(Self::LineUnknown as u8 + t.code() as u8).expect("8 line types")
    }

    fn edge(t: RoadEdgeType) -> Self {
        Self::from_index(Self::EdgeUnknown as u8 + t.code() as u8).expect("3 edge types")
    }

    pub fn is_lane(self) -> bool {
        (self as u8) <= Self::LaneBike as u8
    }
}

/// A road polyline, subsampled, relative to the scene origin.
#[derive(Debug, Clone, PartialEq)]
pub struct RoadPolyline {
    pub kind: RoadKind,
    /// `[points, 2]` x, y in metres relative to [`PreparedScene::origin_xy_m`].
    pub xy_m: Vec<[f32; 2]>,
}

/// One track, every step, relative to the scene origin. Invalid steps hold zeros.
#[derive(Debug, Clone, PartialEq)]
pub struct PreparedTrack {
    pub id: i64,
    pub object_type: ObjectType,
    pub is_sdc: bool,
    /// Mean box size over valid steps.
    pub length_m: f32,
    pub width_m: f32,
    /// `[steps]` each.
    pub valid: Vec<bool>,
    pub x_m: Vec<f32>,
    pub y_m: Vec<f32>,
    pub heading_rad: Vec<f32>,
    pub vx_mps: Vec<f32>,
    pub vy_mps: Vec<f32>,
}

impl PreparedTrack {
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
    pub scenario_id: String,
    /// World position that every `x_m`/`y_m` here is relative to.
    pub origin_xy_m: [f64; 2],
    pub num_steps: usize,
    pub step_secs: f32,
    pub tracks: Vec<PreparedTrack>,
    pub road: Vec<RoadPolyline>,
    pub windows: Vec<Window>,
    /// Pairs per window: `pairs[w]` belongs to `windows[w]`.
    pub pairs: Vec<Vec<InteractingPair>>,
}

/// Why a scene yields no prepared scene.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PrepareError {
    #[error("scene has {num_steps} steps, fewer than one window of {window_steps}")]
    TooShort {
        num_steps: usize,
        window_steps: usize,
    },
}

impl PrepareError {
    pub fn reason(&self) -> &'static str {
        match self {
            Self::TooShort { .. } => "too_short",
        }
    }
}

fn subsample<T: Copy>(points: &[T], every: usize) -> Vec<T> {
    let every = every.max(1);
    let mut out: Vec<T> = points.iter().step_by(every).copied().collect();
    if points.len() > 1 && !(points.len() - 1).is_multiple_of(every) {
        out.push(points[points.len() - 1]);
    }
    out
}

impl PreparedScene {
    /// Builds the prepared form: tracks with at least one valid step inside some window's
    /// history (others can never be an input), road polylines subsampled to every
    /// `road_subsample`-th point, windows and pairs.
    pub fn from_scene(
        scene: &Scene,
        window_config: &WindowConfig,
        pair_config: &PairConfig,
        road_subsample: usize,
    ) -> Result<Self, PrepareError> {
        let wins = windows(scene, window_config);
        if wins.is_empty() {
            return Err(PrepareError::TooShort {
                num_steps: scene.num_steps(),
                window_steps: window_config.window_steps(),
            });
        }
        Ok(Self::build(
            scene,
            wins,
            window_config,
            pair_config,
            road_subsample,
        ))
    }

    /// Prepared form for inference on a scene with one window ending its history at
    /// `scene.current_step` (the future may be missing or short).
    pub fn for_inference(
        scene: &Scene,
        window_config: &WindowConfig,
        road_subsample: usize,
    ) -> Self {
        let wins = vec![Window {
            current_step: scene.current_step,
        }];
        Self::build(
            scene,
            wins,
            window_config,
            &PairConfig::default(),
            road_subsample,
        )
    }

    fn build(
        scene: &Scene,
        wins: Vec<Window>,
        window_config: &WindowConfig,
        pair_config: &PairConfig,
        road_subsample: usize,
    ) -> Self {
        let num_steps = scene.num_steps();
        let origin = scene
            .sdc_track_index
            .and_then(|i| scene.tracks[i].states.iter().find(|s| s.valid))
            .or_else(|| {
                scene
                    .tracks
                    .iter()
                    .flat_map(|t| t.states.iter())
                    .find(|s| s.valid)
            })
            .map_or([0.0, 0.0], |s| [s.x_m, s.y_m]);
        let history = window_config.history_steps;
        let in_some_history = |step: usize| wins.iter().any(|w| w.history_contains(step, history));
        let tracks = scene
            .tracks
            .iter()
            .enumerate()
            .filter(|(_, t)| {
                t.states
                    .iter()
                    .enumerate()
                    .any(|(s, st)| st.valid && in_some_history(s))
            })
            .map(|(i, t)| {
                let mut p = PreparedTrack {
                    id: t.id,
                    object_type: t.object_type,
                    is_sdc: scene.sdc_track_index == Some(i),
                    length_m: 0.0,
                    width_m: 0.0,
                    valid: t.states.iter().map(|s| s.valid).collect(),
                    x_m: vec![0.0; num_steps],
                    y_m: vec![0.0; num_steps],
                    heading_rad: vec![0.0; num_steps],
                    vx_mps: vec![0.0; num_steps],
                    vy_mps: vec![0.0; num_steps],
                };
                let mut n = 0.0f64;
                let (mut len, mut wid) = (0.0f64, 0.0f64);
                for (s, st) in t.states.iter().enumerate().filter(|(_, st)| st.valid) {
                    p.x_m[s] = (st.x_m - origin[0]) as f32;
                    p.y_m[s] = (st.y_m - origin[1]) as f32;
                    p.heading_rad[s] = st.heading_rad;
                    p.vx_mps[s] = st.velocity_x_mps;
                    p.vy_mps[s] = st.velocity_y_mps;
                    len += f64::from(st.length_m);
                    wid += f64::from(st.width_m);
                    n += 1.0;
                }
                if n > 0.0 {
                    p.length_m = (len / n) as f32;
                    p.width_m = (wid / n) as f32;
                }
                p
            })
            .collect();
        let rel =
            |p: &scbg_scene::MapPoint| [(p.x_m - origin[0]) as f32, (p.y_m - origin[1]) as f32];
        let closed = |poly: &[scbg_scene::MapPoint]| {
            let mut pts: Vec<[f32; 2]> = poly.iter().map(rel).collect();
            if pts.len() > 2 {
                pts.push(pts[0]);
            }
            pts
        };
        let m = &scene.map;
        let mut road = Vec::with_capacity(m.num_features());
        let mut push = |kind: RoadKind, pts: Vec<[f32; 2]>| {
            if !pts.is_empty() {
                road.push(RoadPolyline {
                    kind,
                    xy_m: subsample(&pts, road_subsample),
                });
            }
        };
        for l in &m.lanes {
            push(
                RoadKind::lane(l.lane_type),
                l.polyline.iter().map(rel).collect(),
            );
        }
        for l in &m.road_lines {
            push(
                RoadKind::line(l.line_type),
                l.polyline.iter().map(rel).collect(),
            );
        }
        for e in &m.road_edges {
            push(
                RoadKind::edge(e.edge_type),
                e.polyline.iter().map(rel).collect(),
            );
        }
        for s in &m.stop_signs {
            push(RoadKind::StopSign, vec![rel(&s.position)]);
        }
        // Polygons are short; keep every corner (subsampling would cut them).
        for c in &m.crosswalks {
            road.push(RoadPolyline {
                kind: RoadKind::Crosswalk,
                xy_m: closed(&c.polygon),
            });
        }
        for c in &m.speed_bumps {
            road.push(RoadPolyline {
                kind: RoadKind::SpeedBump,
                xy_m: closed(&c.polygon),
            });
        }
        for c in &m.driveways {
            road.push(RoadPolyline {
                kind: RoadKind::Driveway,
                xy_m: closed(&c.polygon),
            });
        }
        road.retain(|p| !p.xy_m.is_empty());
        let step_secs = if num_steps > 1 {
            ((scene.timestamps_secs[num_steps - 1] - scene.timestamps_secs[0])
                / (num_steps - 1) as f64) as f32
        } else {
            0.1
        };
        let mut prepared = Self {
            scenario_id: scene.scenario_id.clone(),
            origin_xy_m: origin,
            num_steps,
            step_secs: if step_secs.is_finite() && step_secs > 0.0 {
                step_secs
            } else {
                0.1
            },
            tracks,
            road,
            windows: wins,
            pairs: Vec::new(),
        };
        let interest: Vec<i64> = scene.objects_of_interest.clone();
        prepared.pairs = prepared
            .windows
            .iter()
            .map(|w| select_pairs(&prepared, w, window_config, &interest, pair_config))
            .collect();
        prepared
    }

    /// Index of the track with this id.
    pub fn track_index(&self, id: i64) -> Option<usize> {
        self.tracks.iter().position(|t| t.id == id)
    }

    /// Encodes into the cache's binary record format.
    pub fn encode(&self) -> Vec<u8> {
        crate::codec::encode(self)
    }

    /// Decodes a cache record; errors say which field is malformed.
    pub fn decode(bytes: &[u8]) -> Result<Self, crate::cache::CacheError> {
        crate::codec::decode(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subsample_keeps_last_point() {
        let pts: Vec<u32> = (0..10).collect();
        assert_eq!(subsample(&pts, 4), vec![0, 4, 8, 9]);
        assert_eq!(subsample(&pts[..9], 4), vec![0, 4, 8]);
        assert_eq!(subsample(&pts[..1], 4), vec![0]);
    }

    #[test]
    fn road_kind_indices_are_dense() {
        for i in 0..RoadKind::COUNT as u8 {
            assert_eq!(RoadKind::from_index(i).unwrap() as u8, i);
        }
        assert!(RoadKind::from_index(20).is_none());
        assert_eq!(
            RoadKind::line(RoadLineType::PassingDoubleYellow),
            RoadKind::LinePassingDoubleYellow
        );
        assert_eq!(RoadKind::edge(RoadEdgeType::Median), RoadKind::EdgeMedian);
    }
}
