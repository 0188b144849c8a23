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
    pub future_steps: usize,
    /// Other agents kept, closest first (the paper-era model used up to 128).
    pub max_other_agents: usize,
    /// Road segments kept, closest first (P; the paper-era model used 128).
    pub max_road_segments: usize,
    /// Segments whose nearest endpoint is farther than this are dropped.
    pub road_radius_m: f32,
}

impl Default for FeatureConfig {
    fn default() -> Self {
        Self {
            history_steps: 11,
            future_steps: 80,
            max_other_agents: 32,
            max_road_segments: 128,
            road_radius_m: 150.0,
        }
    }
}

/// The features of one target agent in one window.
#[derive(Debug, Clone, PartialEq)]
pub struct AgentSample {
    pub scenario_id: String,
    pub window: Window,
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
}

impl AgentSample {
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

fn type_one_hot(t: ObjectType) -> [f32; 5] {
    let mut v = [0.0; 5];
    v[t.code() as usize] = 1.0;
    v
}

/// Writes the 13 per-step features of `track` at `step` (zeros if invalid).
fn step_features(track: &PreparedTrack, step: Option<usize>, frame: &Pose2, out: &mut [f32]) {
    out.fill(0.0);
    let Some(s) = step.filter(|&s| track.valid.get(s).copied().unwrap_or(false)) else {
        return;
    };
    let (x, y) = frame.agent_from_world(f64::from(track.x_m[s]), f64::from(track.y_m[s]));
    out[0] = x as f32;
    out[1] = y as f32;
    out[2] = frame.agent_from_world_heading(f64::from(track.heading_rad[s])) as f32;
    out[3] = track.speed_mps(s);
    out[4] = track.width_m;
    out[5] = track.length_m;
    out[6] = 1.0;
    out[7..12].copy_from_slice(&type_one_hot(track.object_type));
    out[12] = f32::from(u8::from(track.is_sdc));
}

/// Fills `[history, 13]` and `[history - 1, 11]` arrays for one track.
fn track_history(
    track: &PreparedTrack,
    window: &Window,
    history: usize,
    frame: &Pose2,
    hist: &mut [f32],
    diffs: &mut [f32],
) {
    for h in 0..history {
        let step = window.history_step(h, history);
        step_features(
            track,
            step,
            frame,
            &mut hist[h * AGENT_FEATURES..(h + 1) * AGENT_FEATURES],
        );
    }
    for h in 1..history {
        let (prev, cur) = hist.split_at(h * AGENT_FEATURES);
        let prev = &prev[(h - 1) * AGENT_FEATURES..];
        let cur = &cur[..AGENT_FEATURES];
        let d = &mut diffs[(h - 1) * DIFF_FEATURES..h * DIFF_FEATURES];
        d.fill(0.0);
        if prev[6] > 0.0 && cur[6] > 0.0 {
            d[0] = cur[0] - prev[0];
            d[1] = cur[1] - prev[1];
            d[2] = wrap_angle_rad(f64::from(cur[2] - prev[2])) as f32;
            d[3] = cur[3] - prev[3];
            d[4] = 1.0;
        }
        d[5..11].copy_from_slice(&cur[7..13]);
        if cur[6] == 0.0 {
            d[5..10].copy_from_slice(&type_one_hot(track.object_type));
            d[10] = f32::from(u8::from(track.is_sdc));
        }
    }
}

/// Why a sample cannot be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SampleError {
    #[error("track index {0} is out of range")]
    NoSuchTrack(usize),
    #[error("target track {track_id} is not valid at the current step {step}")]
    TargetInvalidNow { track_id: i64, step: usize },
}

/// Builds the features of `target` (a track index) in `window`, conditioned on the future of
/// `condition` (another track index) when given.
pub fn extract_sample(
    scene: &PreparedScene,
    window: &Window,
    target: usize,
    condition: Option<usize>,
    config: &FeatureConfig,
) -> Result<AgentSample, SampleError> {
    let now = window.current_step;
    let track = scene
        .tracks
        .get(target)
        .ok_or(SampleError::NoSuchTrack(target))?;
    if let Some(c) = condition {
        scene.tracks.get(c).ok_or(SampleError::NoSuchTrack(c))?;
    }
    if !track.valid_at(now as isize) {
        return Err(SampleError::TargetInvalidNow {
            track_id: track.id,
            step: now,
        });
    }
    let history = config.history_steps;
    // The frame relative to the scene origin (for features) and in the world (for outputs).
    let frame = Pose2::new(
        f64::from(track.x_m[now]),
        f64::from(track.y_m[now]),
        f64::from(track.heading_rad[now]),
    );
    let world_from_agent = Pose2::new(
        frame.x_m + scene.origin_xy_m[0],
        frame.y_m + scene.origin_xy_m[1],
        frame.heading_rad,
    );

    let mut target_history = vec![0.0; history * AGENT_FEATURES];
    let mut target_diffs = vec![0.0; (history - 1) * DIFF_FEATURES];
    track_history(
        track,
        window,
        history,
        &frame,
        &mut target_history,
        &mut target_diffs,
    );

    // Other agents: every other track with a valid history step, closest (at its latest valid
    // history step) first; the conditioning agent is always kept.
    let mut others: Vec<(f32, usize)> = scene
        .tracks
        .iter()
        .enumerate()
        .filter(|&(i, _)| i != target)
        .filter_map(|(i, t)| {
            let last = (0..history)
                .rev()
                .filter_map(|h| window.history_step(h, history))
                .find(|&s| t.valid.get(s).copied().unwrap_or(false))?;
            let d = (t.x_m[last] - track.x_m[now]).hypot(t.y_m[last] - track.y_m[now]);
            Some((if Some(i) == condition { -1.0 } else { d }, i))
        })
        .collect();
    let max_others = config.max_other_agents;
    if others.len() > max_others && max_others > 0 {
        others.select_nth_unstable_by(max_others - 1, |a, b| {
            a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
        });
        others.truncate(max_others);
    }
    others.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    others.truncate(max_others);
    let mut others_history = vec![0.0; max_others * history * AGENT_FEATURES];
    let mut others_diffs = vec![0.0; max_others * (history - 1) * DIFF_FEATURES];
    let mut others_valid = vec![false; max_others];
    for (k, &(_, i)) in others.iter().enumerate() {
        let hs = history * AGENT_FEATURES;
        let ds = (history - 1) * DIFF_FEATURES;
        track_history(
            &scene.tracks[i],
            window,
            history,
            &frame,
            &mut others_history[k * hs..(k + 1) * hs],
            &mut others_diffs[k * ds..(k + 1) * ds],
        );
        others_valid[k] = true;
    }

    let (road_segments, road_valid) = road_features(scene, &frame, config);

    let future = config.future_steps;
    let future_of = |t: &PreparedTrack| {
        let mut xy = vec![0.0f32; future * 2];
        let mut heading = vec![0.0f32; future];
        let mut valid = vec![false; future];
        for f in 0..future {
            let s = window.future_step(f);
            if t.valid_at(s as isize) {
                let (x, y) = frame.agent_from_world(f64::from(t.x_m[s]), f64::from(t.y_m[s]));
                xy[2 * f] = x as f32;
                xy[2 * f + 1] = y as f32;
                heading[f] = frame.agent_from_world_heading(f64::from(t.heading_rad[s])) as f32;
                valid[f] = true;
            }
        }
        (xy, heading, valid)
    };
    let (future_xy_m, future_heading_rad, future_valid) = future_of(track);
    let (condition_future_xy_m, condition_future_valid) = match condition {
        Some(c) => {
            let (xy, _, v) = future_of(&scene.tracks[c]);
            (xy, v)
        }
        None => (vec![0.0; future * 2], vec![false; future]),
    };
    let (vx, vy) =
        frame.agent_from_world_vector(f64::from(track.vx_mps[now]), f64::from(track.vy_mps[now]));
    Ok(AgentSample {
        scenario_id: scene.scenario_id.clone(),
        window: *window,
        target_track_id: track.id,
        condition_track_id: condition.map(|c| scene.tracks[c].id),
        world_from_agent,
        target_history,
        target_diffs,
        others_history,
        others_diffs,
        others_valid,
        road_segments,
        road_valid,
        condition_future_xy_m,
        condition_future_valid,
        future_xy_m,
        future_heading_rad,
        future_valid,
        current_velocity_mps: [vx as f32, vy as f32],
    })
}

/// The P closest road segments in the target frame, with their 27 features.
fn road_features(
    scene: &PreparedScene,
    frame: &Pose2,
    config: &FeatureConfig,
) -> (Vec<f32>, Vec<bool>) {
    let p_max = config.max_road_segments;
    let r2 = config.road_radius_m * config.road_radius_m;
    let (s, c) = frame.heading_rad.sin_cos();
    let (s, c, ox, oy) = (s as f32, c as f32, frame.x_m as f32, frame.y_m as f32);
    let to_agent = |p: [f32; 2]| {
        let (dx, dy) = (p[0] - ox, p[1] - oy);
        [c * dx + s * dy, -s * dx + c * dy]
    };
    // (distance to the closest point, segment start in agent frame, end, kind)
    let mut candidates: Vec<(f32, [f32; 2], [f32; 2], RoadKind)> = Vec::new();
    for poly in &scene.road {
        let pts = &poly.xy_m;
        let n_seg = pts.len().saturating_sub(1).max(1);
        let mut a = to_agent(pts[0]);
        for k in 0..n_seg {
            let b = if pts.len() > 1 {
                to_agent(pts[k + 1])
            } else {
                a
            };
            let near2 = (a[0] * a[0] + a[1] * a[1]).min(b[0] * b[0] + b[1] * b[1]);
            if near2 < r2 {
                let p = closest_point_to_origin(a, b);
                candidates.push((p[0].hypot(p[1]), a, b, poly.kind));
            }
            a = b;
        }
    }
    let order = |x: &(f32, [f32; 2], [f32; 2], RoadKind),
                 y: &(f32, [f32; 2], [f32; 2], RoadKind)| {
        x.0.total_cmp(&y.0)
            .then(x.1[0].total_cmp(&y.1[0]))
            .then(x.1[1].total_cmp(&y.1[1]))
    };
    if candidates.len() > p_max && p_max > 0 {
        candidates.select_nth_unstable_by(p_max - 1, order);
        candidates.truncate(p_max);
    }
    candidates.sort_by(order);
    candidates.truncate(p_max);
    let mut out = vec![0.0f32; p_max * ROAD_FEATURES];
    let mut valid = vec![false; p_max];
    for (k, &(dist, a, b, kind)) in candidates.iter().enumerate() {
        let f = &mut out[k * ROAD_FEATURES..(k + 1) * ROAD_FEATURES];
        let p = closest_point_to_origin(a, b);
        f[0] = dist;
        if dist > 1e-6 {
            f[1] = p[0] / dist;
            f[2] = p[1] / dist;
        }
        let (tx, ty) = (b[0] - a[0], b[1] - a[1]);
        let len = tx.hypot(ty);
        if len > 1e-6 {
            f[3] = tx / len;
            f[4] = ty / len;
        }
        f[5] = len;
        f[6] = (b[0] - p[0]).hypot(b[1] - p[1]);
        f[7 + kind as usize] = 1.0;
        valid[k] = true;
    }
    (out, valid)
}

/// The point of segment `a`–`b` closest to the origin.
fn closest_point_to_origin(a: [f32; 2], b: [f32; 2]) -> [f32; 2] {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    if len2 <= 1e-12 {
        return a;
    }
    let t = (-(a[0] * dx + a[1] * dy) / len2).clamp(0.0, 1.0);
    [a[0] + t * dx, a[1] + t * dy]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::prepared::RoadPolyline;

    fn straight_track(id: i64, y: f32, speed: f32, n: usize) -> PreparedTrack {
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

    fn scene() -> PreparedScene {
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
