//! Multipath++ agent-centric features of one target agent (`shared/spec/multipathpp.md`).
//!
//! Everything is expressed in the target's frame at the window's current step: translate by
//! its position, rotate by −heading (`agent_from_world`). Arrays are flat, row-major, with
//! the shapes given on each field of [`AgentSample`].

use scbg_scene::{ObjectType, Pose2, wrap_angle_rad};

use crate::prepared::{PreparedScene, PreparedTrack, RoadKind};
use crate::window::Window;

/// Per history step: x, y, yaw, speed, width, length, valid, type one-hot (5), is_sdc.
pub const AGENT_FEATURES: usize = 13;
/// Per step difference: Δx, Δy, Δyaw (wrapped), Δspeed, valid_diff, type one-hot (5), is_sdc.
pub const DIFF_FEATURES: usize = 11;
/// Per road segment: |p|, p/|p| (2), unit tangent (2), length, distance p→end, type one-hot (20).
pub const ROAD_FEATURES: usize = 27;
/// Road segment types (see [`RoadKind`]).
pub const ROAD_TYPES: usize = RoadKind::COUNT;

/// Sizes of the feature arrays.
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureConfig {
    /// History steps including the current one.
    pub history_steps: usize,
    /// Future steps after the current one.
    pub future_steps: usize,
    /// Other agents kept, closest first (the paper-era model used up to 128).
    pub max_other_agents: usize,
    /// Road segments kept, closest first (P; the paper-era model used 128).
    pub max_road_segments: usize,
    /// Segments whose nearest endpoint is farther than this are dropped.
    pub road_radius_m: f32,
    /// Build the target's lane path ([`AgentSample::lane_path_xy_m`]); only a model with the
    /// lane frame uses it, so it is off unless that model's configuration asks for it.
    pub lane_path: bool,
}

impl Default for FeatureConfig {
    fn default() -> Self {
        Self {
            history_steps: 11,
            future_steps: 80,
            max_other_agents: 32,
            max_road_segments: 128,
            road_radius_m: 150.0,
            lane_path: false,
        }
    }
}

/// The features of one target agent in one window.
#[derive(Debug, Clone, PartialEq)]
pub struct AgentSample {
    /// Scenario id of the scene.
    pub scenario_id: String,
    /// The window the sample is taken from.
    pub window: Window,
    /// Track id of the target agent.
    pub target_track_id: i64,
    /// The other agent of a pair whose future conditions the prediction, if any.
    pub condition_track_id: Option<i64>,
    /// The target's pose at the current step in the world frame: maps agent-frame points back
    /// to the world (`world_from_agent`), and its inverse gives `agent_from_world`.
    pub world_from_agent: Pose2,
    /// `[history_steps, AGENT_FEATURES]`.
    pub target_history: Vec<f32>,
    /// `[history_steps - 1, DIFF_FEATURES]`.
    pub target_diffs: Vec<f32>,
    /// `[max_other_agents, history_steps, AGENT_FEATURES]`, closest other agent first.
    pub others_history: Vec<f32>,
    /// `[max_other_agents, history_steps - 1, DIFF_FEATURES]`.
    pub others_diffs: Vec<f32>,
    /// `[max_other_agents]`.
    pub others_valid: Vec<bool>,
    /// `[max_road_segments, ROAD_FEATURES]`, closest segment first.
    pub road_segments: Vec<f32>,
    /// `[max_road_segments]`.
    pub road_valid: Vec<bool>,
    /// `[future_steps, 2]`: the conditioning agent's future x, y in the target frame.
    pub condition_future_xy_m: Vec<f32>,
    /// `[future_steps]`; all false without a condition.
    pub condition_future_valid: Vec<bool>,
    /// `[future_steps, 2]`: the target's ground-truth future in its own frame.
    pub future_xy_m: Vec<f32>,
    /// `[future_steps]`: ground-truth heading in the target frame.
    pub future_heading_rad: Vec<f32>,
    /// `[future_steps]`.
    pub future_valid: Vec<bool>,
    /// Target velocity at the current step, in the target frame.
    pub current_velocity_mps: [f32; 2],
    /// `[LANE_PATH_POINTS, 2]`: the target's lane path in its frame, at arc lengths
    /// [`lane_path_arc_m`](crate::lane_path_arc_m) (zeros where invalid); empty unless
    /// [`FeatureConfig::lane_path`].
    pub lane_path_xy_m: Vec<f32>,
    /// `[LANE_PATH_POINTS]`: whether each point lies on a known lane; all false when the
    /// target is on no lane; empty unless [`FeatureConfig::lane_path`].
    pub lane_path_valid: Vec<bool>,
    /// `[LANE_PATH_POINTS]`: whether a vehicle lane heading the path's way runs a lane's width
    /// ([`LANE_MOVE_M`](crate::LANE_MOVE_M), within 1.5 m) to the `[left, right]` of each
    /// valid path point (false where invalid): where a lane move may end. Empty unless
    /// [`FeatureConfig::lane_path`].
    pub lane_path_beside: Vec<[bool; 2]>,
    /// Training never drops this sample's condition: the target's future is a reaction to a
    /// condition that was imposed (a future of the other agent replayed in a simulator), not
    /// a draw of its own marginal behaviour, so it must not teach the marginal mode. False
    /// for every sample the builder makes.
    pub condition_required: bool,
}

impl AgentSample {
    /// Whether the sample is conditioned on another agent's future.
    pub fn has_condition(&self) -> bool {
        self.condition_track_id.is_some()
    }
}

/// Vehicles valid at the window's current step with at least `min_future_valid_steps` valid
/// future steps: the marginal-mode training targets.
pub fn marginal_targets(
    scene: &PreparedScene,
    window: &Window,
    future_steps: usize,
    min_future_valid_steps: usize,
) -> Vec<usize> {
    (0..scene.tracks.len())
        .filter(|&i| {
            let t = &scene.tracks[i];
            t.object_type == ObjectType::Vehicle
                && t.valid_at(window.current_step as isize)
                && (0..future_steps)
                    .filter(|&f| t.valid_at(window.future_step(f) as isize))
                    .count()
                    >= min_future_valid_steps
        })
        .collect()
}

/// The target's frame with its rotation precomputed (features transform thousands of points).
#[derive(Debug, Clone, Copy)]
pub(crate) struct AgentFrame {
    pub(crate) x_m: f64,
    pub(crate) y_m: f64,
    pub(crate) heading_rad: f64,
    pub(crate) sin: f64,
    pub(crate) cos: f64,
}

impl AgentFrame {
    pub(crate) fn new(x_m: f64, y_m: f64, heading_rad: f64) -> Self {
        let (sin, cos) = heading_rad.sin_cos();
        Self {
            x_m,
            y_m,
            heading_rad,
            sin,
            cos,
        }
    }

    pub(crate) fn point(&self, x: f32, y: f32) -> (f32, f32) {
        let (dx, dy) = (f64::from(x) - self.x_m, f64::from(y) - self.y_m);
        (
            (self.cos * dx + self.sin * dy) as f32,
            (-self.sin * dx + self.cos * dy) as f32,
        )
    }

    fn heading(&self, heading_rad: f32) -> f32 {
        wrap_angle_rad(f64::from(heading_rad) - self.heading_rad) as f32
    }
}

/// Index of `t` in the 5-wide type one-hot. (The one-hot is written into zeroed rows in
/// place: copying a stack array built with a variable-index store stalled store forwarding
/// and cost a tenth of feature building.)
fn type_index(t: ObjectType) -> usize {
    t.code() as usize
}

/// One history step of a track in the scene frame: what [`track_rows`] transforms into a
/// target's frame. The same for every target of a window, so
/// [`SampleBuilder`](crate::SampleBuilder) makes them once
/// per window (speed's square root included).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct HistoryStep {
    pub(crate) x_m: f32,
    pub(crate) y_m: f32,
    pub(crate) heading_rad: f32,
    pub(crate) speed_mps: f32,
    pub(crate) valid: bool,
}

/// `track`'s `history` steps of `window` (invalid before the scene's start).
pub(crate) fn history_steps(
    track: &PreparedTrack,
    window: &Window,
    history: usize,
    out: &mut Vec<HistoryStep>,
) {
    out.extend((0..history).map(|h| {
        match window
            .history_step(h, history)
            .filter(|&s| track.valid.get(s).copied().unwrap_or(false))
        {
            Some(s) => HistoryStep {
                x_m: track.x_m[s],
                y_m: track.y_m[s],
                heading_rad: track.heading_rad[s],
                speed_mps: track.speed_mps(s),
                valid: true,
            },
            None => HistoryStep::default(),
        }
    }));
}

/// Fills zeroed `[history, 13]` and `[history - 1, 11]` arrays for one track.
///
/// Per history step: x, y, yaw, speed, width, length, valid, type one-hot, is_sdc (zeros where
/// the track is invalid); per pair of consecutive steps: Δx, Δy, Δyaw (wrapped), Δspeed and
/// valid where both are valid, then the type one-hot and is_sdc.
#[cfg(test)]
pub(crate) fn track_history(
    track: &PreparedTrack,
    window: &Window,
    history: usize,
    frame: &AgentFrame,
    hist: &mut [f32],
    diffs: &mut [f32],
) {
    let mut steps = Vec::new();
    history_steps(track, window, history, &mut steps);
    track_rows(track, &steps, frame, hist, diffs);
}

/// [`track_history`] from the track's [`history_steps`], into zeroed `hist` and `diffs`
/// (only the non-zero features are written).
pub(crate) fn track_rows(
    track: &PreparedTrack,
    steps: &[HistoryStep],
    frame: &AgentFrame,
    hist: &mut [f32],
    diffs: &mut [f32],
) {
    let one_hot = type_index(track.object_type);
    let is_sdc = f32::from(u8::from(track.is_sdc));
    // x, y, yaw, speed of the previous step where it was valid.
    let mut prev: Option<[f32; 4]> = None;
    for (h, st) in steps.iter().enumerate() {
        let row = &mut hist[h * AGENT_FEATURES..(h + 1) * AGENT_FEATURES];
        let cur = st.valid.then(|| {
            let (x, y) = frame.point(st.x_m, st.y_m);
            let cur = [x, y, frame.heading(st.heading_rad), st.speed_mps];
            row[..4].copy_from_slice(&cur);
            row[4] = track.width_m;
            row[5] = track.length_m;
            row[6] = 1.0;
            row[7 + one_hot] = 1.0;
            row[12] = is_sdc;
            cur
        });
        if h > 0 {
            let d = &mut diffs[(h - 1) * DIFF_FEATURES..h * DIFF_FEATURES];
            if let (Some(p), Some(c)) = (prev, cur) {
                d[0] = c[0] - p[0];
                d[1] = c[1] - p[1];
                d[2] = wrap_angle_rad(f64::from(c[2] - p[2])) as f32;
                d[3] = c[3] - p[3];
                d[4] = 1.0;
            }
            d[5 + one_hot] = 1.0;
            d[10] = is_sdc;
        }
        prev = cur;
    }
}

/// Why a sample cannot be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SampleError {
    /// The target or condition track index is out of range.
    #[error("track index {0} is out of range")]
    NoSuchTrack(usize),
    /// The target track is not valid at the window's current step.
    #[allow(missing_docs)]
    #[error("target track {track_id} is not valid at the current step {step}")]
    TargetInvalidNow { track_id: i64, step: usize },
}

/// A track's future in `frame`: `[future, 2]` x, y, `[future]` heading and valid.
pub(crate) fn future_of(
    t: &PreparedTrack,
    window: &Window,
    frame: &AgentFrame,
    future: usize,
) -> (Vec<f32>, Vec<f32>, Vec<bool>) {
    let mut xy = vec![0.0f32; future * 2];
    let mut heading = vec![0.0f32; future];
    let mut valid = vec![false; future];
    for f in 0..future {
        let s = window.future_step(f);
        if t.valid_at(s as isize) {
            let (x, y) = frame.point(t.x_m[s], t.y_m[s]);
            xy[2 * f] = x;
            xy[2 * f + 1] = y;
            heading[f] = frame.heading(t.heading_rad[s]);
            valid[f] = true;
        }
    }
    (xy, heading, valid)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::builder::extract_sample;
    use crate::prepared::RoadPolyline;

    pub(crate) fn straight_track(id: i64, y: f32, speed: f32, n: usize) -> PreparedTrack {
        PreparedTrack {
            id,
            object_type: ObjectType::Vehicle,
            is_sdc: false,
            length_m: 4.5,
            width_m: 2.0,
            valid: vec![true; n],
            x_m: (0..n).map(|s| s as f32 * speed * 0.1).collect(),
            y_m: vec![y; n],
            heading_rad: vec![0.0; n],
            vx_mps: vec![speed; n],
            vy_mps: vec![0.0; n],
        }
    }

    pub(crate) fn scene() -> PreparedScene {
        PreparedScene {
            scenario_id: "t".into(),
            origin_xy_m: [100.0, 200.0],
            num_steps: 91,
            step_secs: 0.1,
            tracks: vec![
                straight_track(1, 0.0, 10.0, 91),
                straight_track(2, 3.5, 5.0, 91),
            ],
            road: vec![RoadPolyline {
                kind: RoadKind::LaneSurfaceStreet,
                xy_m: vec![[0.0, 0.0], [50.0, 0.0], [100.0, 0.0]],
            }],
            windows: vec![Window { current_step: 10 }],
            pairs: vec![vec![]],
        }
    }

    #[test]
    fn target_frame_features() {
        let s = scene();
        let cfg = FeatureConfig {
            max_other_agents: 4,
            max_road_segments: 8,
            ..Default::default()
        };
        let sample = extract_sample(&s, &s.windows[0], 0, Some(1), &cfg).unwrap();
        // Current step is the last history row: at the origin of its own frame, speed 10.
        let cur = &sample.target_history[10 * AGENT_FEATURES..11 * AGENT_FEATURES];
        assert!(
            cur[0].abs() < 1e-5
                && cur[1].abs() < 1e-5
                && (cur[3] - 10.0).abs() < 1e-5
                && cur[6] == 1.0
        );
        // Oldest step is 10 steps (1 s) behind: x = -10 m.
        assert!((sample.target_history[0] + 10.0).abs() < 1e-4);
        // Step diff Δx = 1 m per 0.1 s step.
        assert!((sample.target_diffs[0] - 1.0).abs() < 1e-4 && sample.target_diffs[4] == 1.0);
        // Future 1 s ahead is at x = 10 m.
        assert!((sample.future_xy_m[2 * 9] - 10.0).abs() < 1e-4);
        assert!(sample.future_valid.iter().all(|&v| v));
        // The conditioning agent is the first other agent, 3.5 m to the left.
        assert!(sample.others_valid[0] && !sample.others_valid[1]);
        assert!((sample.others_history[10 * AGENT_FEATURES + 1] - 3.5).abs() < 1e-4);
        assert!((sample.condition_future_xy_m[1] - 3.5).abs() < 1e-4);
        assert_eq!(sample.condition_track_id, Some(2));
        // World pose of the target: origin + (10 m, 0).
        assert!((sample.world_from_agent.x_m - 110.0).abs() < 1e-6);
        assert_eq!(sample.current_velocity_mps, [10.0, 0.0]);
    }

    #[test]
    fn road_segment_features() {
        let s = scene();
        let cfg = FeatureConfig {
            max_road_segments: 3,
            ..Default::default()
        };
        let sample = extract_sample(&s, &s.windows[0], 0, None, &cfg).unwrap();
        assert_eq!(sample.road_valid, vec![true, true, false]);
        let f = &sample.road_segments[..ROAD_FEATURES];
        // The agent sits on the first segment (0..50 m, it is at x = 10 m): distance 0.
        assert!(f[0].abs() < 1e-5);
        assert_eq!((f[3], f[4]), (1.0, 0.0));
        assert!((f[5] - 50.0).abs() < 1e-4);
        assert!((f[6] - 40.0).abs() < 1e-4);
        assert_eq!(f[7 + RoadKind::LaneSurfaceStreet as usize], 1.0);
        // Second segment starts 40 m ahead: closest point is its start.
        let g = &sample.road_segments[ROAD_FEATURES..2 * ROAD_FEATURES];
        assert!((g[0] - 40.0).abs() < 1e-4 && (g[1] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn invalid_target_is_an_error() {
        let mut s = scene();
        s.tracks[0].valid[10] = false;
        let e = extract_sample(&s, &s.windows[0], 0, None, &FeatureConfig::default()).unwrap_err();
        assert_eq!(
            e,
            SampleError::TargetInvalidNow {
                track_id: 1,
                step: 10
            }
        );
    }

    #[test]
    fn marginal_targets_need_valid_now_and_future() {
        let mut s = scene();
        s.tracks[1].valid[50..].fill(false);
        assert_eq!(marginal_targets(&s, &s.windows[0], 80, 60), vec![0]);
        assert_eq!(marginal_targets(&s, &s.windows[0], 80, 10), vec![0, 1]);
    }
}
