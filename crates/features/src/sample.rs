//! Multipath++ agent-centric features of one target agent (`shared/spec/multipathpp.md`).
//!
//! Everything is expressed in the target's frame at the window's current step: translate by
//! its position, rotate by −heading (`agent_from_world`). Arrays are flat, row-major, with
//! the shapes given on each field of [`AgentSample`].

use scbg_scene::{ObjectType, Pose2, wrap_angle_rad};

use crate::prepared::{PreparedScene, PreparedTrack, RoadKind};
use crate::road_index::{Scratch, SegmentIndex, total_order_bits};
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
struct AgentFrame {
    x_m: f64,
    y_m: f64,
    heading_rad: f64,
    sin: f64,
    cos: f64,
}

impl AgentFrame {
    fn new(x_m: f64, y_m: f64, heading_rad: f64) -> Self {
        let (sin, cos) = heading_rad.sin_cos();
        Self {
            x_m,
            y_m,
            heading_rad,
            sin,
            cos,
        }
    }

    fn point(&self, x: f32, y: f32) -> (f32, f32) {
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

/// Fills `[history, 13]` and `[history - 1, 11]` arrays for one track.
///
/// Per history step: x, y, yaw, speed, width, length, valid, type one-hot, is_sdc (zeros where
/// the track is invalid); per pair of consecutive steps: Δx, Δy, Δyaw (wrapped), Δspeed and
/// valid where both are valid, then the type one-hot and is_sdc.
fn track_history(
    track: &PreparedTrack,
    window: &Window,
    history: usize,
    frame: &AgentFrame,
    hist: &mut [f32],
    diffs: &mut [f32],
) {
    let one_hot = type_index(track.object_type);
    let is_sdc = f32::from(u8::from(track.is_sdc));
    // x, y, yaw, speed of the previous step where it was valid.
    let mut prev: Option<[f32; 4]> = None;
    for h in 0..history {
        let row = &mut hist[h * AGENT_FEATURES..(h + 1) * AGENT_FEATURES];
        row.fill(0.0);
        let step = window
            .history_step(h, history)
            .filter(|&s| track.valid.get(s).copied().unwrap_or(false));
        let cur = step.map(|s| {
            let (x, y) = frame.point(track.x_m[s], track.y_m[s]);
            let cur = [
                x,
                y,
                frame.heading(track.heading_rad[s]),
                track.speed_mps(s),
            ];
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
            d.fill(0.0);
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

/// Builds the features of `target` (a track index) in `window`, conditioned on the future of
/// `condition` (another track index) when given. For many samples of one scene, a
/// [`SampleBuilder`] is faster.
pub fn extract_sample(
    scene: &PreparedScene,
    window: &Window,
    target: usize,
    condition: Option<usize>,
    config: &FeatureConfig,
) -> Result<AgentSample, SampleError> {
    SampleBuilder::new(scene, config).sample(window, target, condition)
}

/// Builds many samples of one scene: indexes the road segments once and reuses its scratch
/// buffers between samples.
///
/// Within a window, the marginal sample of a pair member (and of any target a conditioned
/// sample was asked for) is kept: a conditioned sample of the same target is that sample with
/// the condition agent ranked first among the other agents and its future filled in, so its
/// road query and the other agents' histories are not computed again (trainer, labeler and
/// `scbg bench ingest` ask for every pair member marginally and conditioned). The result is
/// the same to the bit as building it from scratch (tested).
#[derive(Debug)]
pub struct SampleBuilder<'a> {
    scene: &'a PreparedScene,
    config: &'a FeatureConfig,
    /// The road segments (flattened once per scene) with a grid over them.
    segments: SegmentIndex,
    /// Scratch: the selected segments with their squared distances, and the search's state.
    candidates: Vec<(u32, f32)>,
    scratch: Scratch,
    /// The window the per-window state below is for.
    window: Option<Window>,
    /// Per track, its position at its latest valid history step of `window` (the ranking
    /// key of other agents; the same for every target of a window).
    latest_history_xy: Vec<Option<[f32; 2]>>,
    /// Per track, whether it is a member of one of `window`'s pairs.
    pair_member: Vec<bool>,
    /// Marginal samples of `window` kept for conditioned samples of the same target.
    marginals: Vec<Marginal>,
}

/// A marginal sample with what a conditioned sample of the same target needs from it.
#[derive(Debug)]
struct Marginal {
    target: usize,
    frame: AgentFrame,
    /// The other agents' ranking keys (distance bits, then track index), in rank order.
    others: Vec<u64>,
    sample: AgentSample,
}

/// Ranking key of another agent: its squared distance's total-order bits, then its index (the
/// condition agent gets −1, ahead of everyone).
fn other_key(dist2: f32, index: usize) -> u64 {
    (u64::from(total_order_bits(dist2)) << 32) | index as u64
}

fn key_index(key: u64) -> usize {
    (key as u32) as usize
}

impl<'a> SampleBuilder<'a> {
    /// A builder for samples of `scene` with sizes from `config`.
    pub fn new(scene: &'a PreparedScene, config: &'a FeatureConfig) -> Self {
        Self {
            scene,
            config,
            segments: SegmentIndex::from_road(&scene.road),
            candidates: Vec::new(),
            scratch: Scratch::default(),
            window: None,
            latest_history_xy: Vec::new(),
            pair_member: Vec::new(),
            marginals: Vec::new(),
        }
    }

    /// Makes the per-window state that of `window`.
    fn enter_window(&mut self, window: &Window) {
        if self.window == Some(*window) {
            return;
        }
        let (scene, history) = (self.scene, self.config.history_steps);
        self.latest_history_xy.clear();
        self.latest_history_xy.extend(scene.tracks.iter().map(|t| {
            let last = (0..history)
                .rev()
                .filter_map(|h| window.history_step(h, history))
                .find(|&s| t.valid.get(s).copied().unwrap_or(false))?;
            Some([t.x_m[last], t.y_m[last]])
        }));
        self.pair_member.clear();
        self.pair_member.resize(scene.tracks.len(), false);
        let pairs = scene
            .windows
            .iter()
            .position(|w| w == window)
            .and_then(|i| scene.pairs.get(i));
        for p in pairs.into_iter().flatten() {
            for i in [p.first, p.second] {
                if let Some(m) = self.pair_member.get_mut(i) {
                    *m = true;
                }
            }
        }
        self.marginals.clear();
        self.window = Some(*window);
    }

    /// The features of `target` in `window`, conditioned on `condition`'s future when given.
    pub fn sample(
        &mut self,
        window: &Window,
        target: usize,
        condition: Option<usize>,
    ) -> Result<AgentSample, SampleError> {
        let scene = self.scene;
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
        self.enter_window(window);
        let k = match self.marginals.iter().position(|m| m.target == target) {
            Some(k) => k,
            None => {
                let m = self.marginal(window, target);
                if condition.is_none() && !self.pair_member[target] {
                    return Ok(m.sample);
                }
                self.marginals.push(m);
                self.marginals.len() - 1
            }
        };
        let m = &self.marginals[k];
        Ok(match condition {
            None => m.sample.clone(),
            Some(c) => self.conditioned(m, window, c),
        })
    }

    /// The marginal sample of `target` (valid now) in the current window.
    fn marginal(&mut self, window: &Window, target: usize) -> Marginal {
        let (scene, config) = (self.scene, self.config);
        let now = window.current_step;
        let track = &scene.tracks[target];
        let history = config.history_steps;
        // The frame relative to the scene origin (for features) and in the world (for outputs).
        let frame = AgentFrame::new(
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

        // Other agents: every other track with a valid history step, closest (at its latest
        // valid history step) first, ranked by (squared distance, index) as one integer key
        // (`total_order_bits` orders like `f32::total_cmp`).
        let (tx, ty) = (track.x_m[now], track.y_m[now]);
        let mut others: Vec<u64> = self
            .latest_history_xy
            .iter()
            .enumerate()
            .filter(|&(i, _)| i != target)
            .filter_map(|(i, xy)| {
                let [x, y] = (*xy)?;
                let (dx, dy) = (x - tx, y - ty);
                Some(other_key(dx * dx + dy * dy, i))
            })
            .collect();
        let max_others = config.max_other_agents;
        if others.len() > max_others && max_others > 0 {
            others.select_nth_unstable(max_others - 1);
        }
        others.truncate(max_others);
        others.sort_unstable();
        let (hs, ds) = (history * AGENT_FEATURES, (history - 1) * DIFF_FEATURES);
        let mut others_history = vec![0.0; max_others * hs];
        let mut others_diffs = vec![0.0; max_others * ds];
        let mut others_valid = vec![false; max_others];
        for (k, i) in others.iter().map(|&key| key_index(key)).enumerate() {
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

        let (road_segments, road_valid) = self.road_features(&frame);

        let future = config.future_steps;
        let (future_xy_m, future_heading_rad, future_valid) =
            future_of(track, window, &frame, future);
        let (vx, vy) = (f64::from(track.vx_mps[now]), f64::from(track.vy_mps[now]));
        let current_velocity_mps = [
            (frame.cos * vx + frame.sin * vy) as f32,
            (-frame.sin * vx + frame.cos * vy) as f32,
        ];
        let sample = AgentSample {
            scenario_id: scene.scenario_id.clone(),
            window: *window,
            target_track_id: track.id,
            condition_track_id: None,
            world_from_agent,
            target_history,
            target_diffs,
            others_history,
            others_diffs,
            others_valid,
            road_segments,
            road_valid,
            condition_future_xy_m: vec![0.0; future * 2],
            condition_future_valid: vec![false; future],
            future_xy_m,
            future_heading_rad,
            future_valid,
            current_velocity_mps,
        };
        Marginal {
            target,
            frame,
            others,
            sample,
        }
    }

    /// `m`'s sample conditioned on `condition`'s future: the condition agent (when it has a
    /// valid history step) ranked ahead of every other agent, the rest in `m`'s order.
    fn conditioned(&self, m: &Marginal, window: &Window, condition: usize) -> AgentSample {
        let (scene, config) = (self.scene, self.config);
        let mut s = m.sample.clone();
        let cond = &scene.tracks[condition];
        s.condition_track_id = Some(cond.id);
        let (xy, _, valid) = future_of(cond, window, &m.frame, config.future_steps);
        s.condition_future_xy_m = xy;
        s.condition_future_valid = valid;
        let max_others = config.max_other_agents;
        if condition == m.target || self.latest_history_xy[condition].is_none() || max_others == 0 {
            return s;
        }
        // The ranking with the condition agent's key replaced by −1 (exactly what ranking all
        // agents with that key gives: the first `max_others` of `m` hold every agent that can
        // follow it).
        let mut order: Vec<u64> = m
            .others
            .iter()
            .copied()
            .filter(|&k| key_index(k) != condition)
            .collect();
        let key = other_key(-1.0, condition);
        order.insert(order.partition_point(|&k| k < key), key);
        order.truncate(max_others);
        let history = config.history_steps;
        let (hs, ds) = (history * AGENT_FEATURES, (history - 1) * DIFF_FEATURES);
        for (k, &key) in order.iter().enumerate() {
            if m.others.get(k) == Some(&key) {
                continue; // the same agent in the same row
            }
            let i = key_index(key);
            let (hist, diffs) = (
                &mut s.others_history[k * hs..(k + 1) * hs],
                &mut s.others_diffs[k * ds..(k + 1) * ds],
            );
            match m.others.iter().position(|&o| key_index(o) == i) {
                Some(j) => {
                    hist.copy_from_slice(&m.sample.others_history[j * hs..(j + 1) * hs]);
                    diffs.copy_from_slice(&m.sample.others_diffs[j * ds..(j + 1) * ds]);
                }
                None => track_history(&scene.tracks[i], window, history, &m.frame, hist, diffs),
            }
            s.others_valid[k] = true;
        }
        s
    }

    /// The P closest road segments in the target frame, with their 27 features.
    ///
    /// Segments whose nearest endpoint is within the radius are ranked by the distance of their
    /// closest point in the scene frame translated to the agent (distances do not depend on
    /// rotation); only the P selected segments are rotated into the agent frame.
    fn road_features(&mut self, frame: &AgentFrame) -> (Vec<f32>, Vec<bool>) {
        let p_max = self.config.max_road_segments;
        let (ox, oy) = (frame.x_m as f32, frame.y_m as f32);
        self.segments.closest(
            [ox, oy],
            p_max,
            self.config.road_radius_m,
            &mut self.scratch,
            &mut self.candidates,
        );
        let (sn, cs) = (frame.sin as f32, frame.cos as f32);
        let to_agent = |p: [f32; 2]| {
            let (dx, dy) = (p[0] - ox, p[1] - oy);
            [cs * dx + sn * dy, -sn * dx + cs * dy]
        };
        let mut out = vec![0.0f32; p_max * ROAD_FEATURES];
        let mut valid = vec![false; p_max];
        for (k, &(i, dist2)) in self.candidates.iter().enumerate() {
            let i = i as usize;
            let (a, b) = (
                to_agent(self.segments.seg_a(i)),
                to_agent(self.segments.seg_b(i)),
            );
            let f = &mut out[k * ROAD_FEATURES..(k + 1) * ROAD_FEATURES];
            let p = closest_point_to_origin(a, b);
            let dist = dist2.sqrt();
            f[0] = dist;
            if dist > 1e-6 {
                f[1] = p[0] / dist;
                f[2] = p[1] / dist;
            }
            let (tx, ty) = (b[0] - a[0], b[1] - a[1]);
            let len = (tx * tx + ty * ty).sqrt();
            if len > 1e-6 {
                f[3] = tx / len;
                f[4] = ty / len;
            }
            f[5] = len;
            f[6] = ((b[0] - p[0]).powi(2) + (b[1] - p[1]).powi(2)).sqrt();
            f[7 + self.segments.kind(i) as usize] = 1.0;
            valid[k] = true;
        }
        (out, valid)
    }
}

/// A track's future in `frame`: `[future, 2]` x, y, `[future]` heading and valid.
fn future_of(
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

/// The point of segment `a`–`b` closest to the origin.
pub(crate) fn closest_point_to_origin(a: [f32; 2], b: [f32; 2]) -> [f32; 2] {
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
    use crate::prepared::{InteractingPair, PairSource, RoadPolyline};

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

    /// A scene of `n` tracks at pseudo-random places, some with gaps in their history, and
    /// one pair in its only window.
    fn crowded_scene(n: usize, seed: u64) -> PreparedScene {
        let mut state = seed;
        let mut next = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut s = scene();
        s.tracks = (0..n)
            .map(|i| {
                let mut t = straight_track(i as i64 + 1, 0.0, 2.0 + 10.0 * next(), 91);
                let (x0, y0, h) = (80.0 * next() - 40.0, 80.0 * next() - 40.0, 6.0 * next());
                for x in &mut t.x_m {
                    *x += x0;
                }
                for y in &mut t.y_m {
                    *y += y0;
                }
                t.heading_rad.fill(h);
                // Some tracks miss steps of the history (one misses all but "now").
                if i % 3 == 1 {
                    t.valid[9] = false;
                }
                if i % 5 == 2 {
                    t.valid[..10].fill(false);
                }
                t
            })
            .collect();
        s.pairs = vec![vec![InteractingPair {
            first: 0,
            second: n - 1,
            source: PairSource::Mined,
        }]];
        s
    }

    /// The conditioned sample computed directly: every other agent ranked, the condition
    /// agent first, each row from `track_history`.
    fn others_directly(
        s: &PreparedScene,
        w: &Window,
        target: usize,
        condition: usize,
        cfg: &FeatureConfig,
    ) -> (Vec<f32>, Vec<f32>, Vec<bool>) {
        let now = w.current_step;
        let t = &s.tracks[target];
        let frame = AgentFrame::new(
            f64::from(t.x_m[now]),
            f64::from(t.y_m[now]),
            f64::from(t.heading_rad[now]),
        );
        let h = cfg.history_steps;
        let mut ranked: Vec<(f32, usize)> = (0..s.tracks.len())
            .filter(|&i| i != target)
            .filter_map(|i| {
                let o = &s.tracks[i];
                let last = (0..h)
                    .rev()
                    .filter_map(|k| w.history_step(k, h))
                    .find(|&st| o.valid[st])?;
                let (dx, dy) = (o.x_m[last] - t.x_m[now], o.y_m[last] - t.y_m[now]);
                Some((
                    if i == condition {
                        -1.0
                    } else {
                        dx * dx + dy * dy
                    },
                    i,
                ))
            })
            .collect();
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        ranked.truncate(cfg.max_other_agents);
        let (hs, ds) = (h * AGENT_FEATURES, (h - 1) * DIFF_FEATURES);
        let mut hist = vec![0.0; cfg.max_other_agents * hs];
        let mut diffs = vec![0.0; cfg.max_other_agents * ds];
        let mut valid = vec![false; cfg.max_other_agents];
        for (k, &(_, i)) in ranked.iter().enumerate() {
            track_history(
                &s.tracks[i],
                w,
                h,
                &frame,
                &mut hist[k * hs..(k + 1) * hs],
                &mut diffs[k * ds..(k + 1) * ds],
            );
            valid[k] = true;
        }
        (hist, diffs, valid)
    }

    #[test]
    fn conditioned_samples_from_kept_marginals_equal_direct_ones() {
        for (seed, max_others) in [(1, 3), (2, 4), (3, 32), (4, 1), (5, 0)] {
            let s = crowded_scene(12, seed);
            let w = s.windows[0];
            let cfg = FeatureConfig {
                max_other_agents: max_others,
                max_road_segments: 4,
                ..Default::default()
            };
            let mut builder = SampleBuilder::new(&s, &cfg);
            // Every order of asking: marginal first (pair member or not), conditioned first,
            // the same target under several conditions.
            for target in 0..s.tracks.len() {
                if !s.tracks[target].valid[w.current_step] {
                    continue;
                }
                let marginal = builder.sample(&w, target, None).unwrap();
                let fresh = SampleBuilder::new(&s, &cfg)
                    .sample(&w, target, None)
                    .unwrap();
                assert_eq!(marginal, fresh);
                for condition in (0..s.tracks.len()).rev() {
                    let c = builder.sample(&w, target, Some(condition)).unwrap();
                    let (hist, diffs, valid) = others_directly(&s, &w, target, condition, &cfg);
                    let why = format!("seed {seed}, target {target}, condition {condition}");
                    assert_eq!(c.others_history, hist, "{why}");
                    assert_eq!(c.others_diffs, diffs, "{why}");
                    assert_eq!(c.others_valid, valid, "{why}");
                    assert_eq!(c.condition_track_id, Some(s.tracks[condition].id));
                    // The rest is the marginal sample's.
                    assert_eq!(
                        (&c.road_segments, &c.target_history, &c.future_xy_m),
                        (
                            &marginal.road_segments,
                            &marginal.target_history,
                            &marginal.future_xy_m
                        ),
                    );
                    let again = SampleBuilder::new(&s, &cfg)
                        .sample(&w, target, Some(condition))
                        .unwrap();
                    assert_eq!(c, again, "{why}");
                }
            }
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
