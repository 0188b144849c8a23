//! Building a [`PreparedScene`] from a [`Scene`]: tracks relative to an origin, road
//! polylines subsampled and typed, windows and their interacting pairs.

use scbg_scene::{LaneType, RoadEdgeType, RoadLineType, Scene};

use crate::pairs::{PairConfig, select_pairs};
use crate::prepared::{PreparedScene, PreparedTrack, RoadKind, RoadPolyline};
use crate::window::{Window, WindowConfig, windows};

/// Why a scene yields no prepared scene.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PrepareError {
    /// The scene is shorter than one window (history + future).
    #[error("scene has {num_steps} steps, fewer than one window of {window_steps}")]
    TooShort {
        /// Steps of the scene.
        num_steps: usize,
        /// Steps one window needs.
        window_steps: usize,
    },
}

impl PrepareError {
    /// A short, stable name for the kind of problem, for skip counters in summaries.
    pub fn reason(&self) -> &'static str {
        match self {
            Self::TooShort { .. } => "too_short",
        }
    }
}

impl RoadKind {
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
    fn road_kinds_of_lines_and_edges() {
        assert_eq!(
            RoadKind::line(RoadLineType::PassingDoubleYellow),
            RoadKind::LinePassingDoubleYellow
        );
        assert_eq!(RoadKind::edge(RoadEdgeType::Median), RoadKind::EdgeMedian);
    }
}
