//! [`SampleBuilder`]: many samples of one scene, sharing the road index and, within a window,
//! the work a conditioned sample has in common with the marginal one; [`extract_sample`]: one
//! sample.

use scbg_scene::Pose2;

use crate::lane_path::{LANE_PATH_POINTS, LaneNetwork};
use crate::prepared::PreparedScene;
use crate::road_index::{Scratch, SegmentIndex, closest_point_to_origin, total_order_bits};
use crate::sample::{
    AGENT_FEATURES, AgentFrame, AgentSample, DIFF_FEATURES, FeatureConfig, HistoryStep,
    ROAD_FEATURES, SampleError, future_of, history_steps, track_rows,
};
use crate::window::Window;

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
    /// The scene's vehicle lanes (for each target's lane path), made on first use.
    lanes: Option<LaneNetwork>,
    /// The lane grid's query state (its own: a scratch sized for another grid is reset).
    lane_scratch: Scratch,
    /// Scratch: the selected segments with their squared distances, and the search's state.
    candidates: Vec<(u32, f32)>,
    scratch: Scratch,
    /// The window the per-window state below is for.
    window: Option<Window>,
    /// Per track, its position at its latest valid history step of `window` (the ranking
    /// key of other agents; the same for every target of a window), from `steps`.
    latest_history_xy: Vec<Option<[f32; 2]>>,
    /// Per track, its `history_steps` steps of `window` in the scene frame (track-major).
    steps: Vec<HistoryStep>,
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
            lanes: None,
            lane_scratch: Scratch::default(),
            candidates: Vec::new(),
            scratch: Scratch::default(),
            window: None,
            latest_history_xy: Vec::new(),
            steps: Vec::new(),
            pair_member: Vec::new(),
            marginals: Vec::new(),
        }
    }

    /// The scene the samples come from.
    pub fn scene(&self) -> &'a PreparedScene {
        self.scene
    }

    /// Makes the per-window state that of `window`.
    fn enter_window(&mut self, window: &Window) {
        if self.window == Some(*window) {
            return;
        }
        let (scene, history) = (self.scene, self.config.history_steps);
        self.steps.clear();
        for t in &scene.tracks {
            history_steps(t, window, history, &mut self.steps);
        }
        self.latest_history_xy.clear();
        let steps = &self.steps;
        self.latest_history_xy
            .extend((0..scene.tracks.len()).map(|i| {
                let last = steps[i * history..(i + 1) * history]
                    .iter()
                    .rev()
                    .find(|s| s.valid)?;
                Some([last.x_m, last.y_m])
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

    /// Track `i`'s history steps of the current window.
    fn track_steps(&self, i: usize) -> &[HistoryStep] {
        let h = self.config.history_steps;
        &self.steps[i * h..(i + 1) * h]
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
        track_rows(
            track,
            self.track_steps(target),
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
            track_rows(
                &scene.tracks[i],
                self.track_steps(i),
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
        let (lane_path_xy_m, lane_path_valid, lane_path_beside) = if config.lane_path {
            self.lane_path(
                &frame,
                [track.x_m[now], track.y_m[now]],
                track.heading_rad[now],
            )
        } else {
            (Vec::new(), Vec::new(), Vec::new())
        };
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
            lane_path_xy_m,
            lane_path_valid,
            lane_path_beside,
            condition_required: false,
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
                None => {
                    // (The row held another agent.)
                    hist.fill(0.0);
                    diffs.fill(0.0);
                    track_rows(&scene.tracks[i], self.track_steps(i), &m.frame, hist, diffs);
                }
            }
            s.others_valid[k] = true;
        }
        s
    }

    /// The lane path of a target at `xy` heading `heading_rad` (scene frame) in the target's
    /// `frame`: `[LANE_PATH_POINTS, 2]` points (zeros where invalid), their validity and the
    /// lanes beside each (`[left, right]`, false where invalid). The scene's lane network is
    /// made on first use.
    fn lane_path(
        &mut self,
        frame: &AgentFrame,
        xy: [f32; 2],
        heading_rad: f32,
    ) -> (Vec<f32>, Vec<bool>, Vec<[bool; 2]>) {
        let (mut points_xy_m, mut valid, mut beside) = (
            vec![0.0; 2 * LANE_PATH_POINTS],
            vec![false; LANE_PATH_POINTS],
            vec![[false; 2]; LANE_PATH_POINTS],
        );
        let scene = self.scene;
        let lanes = self
            .lanes
            .get_or_insert_with(|| LaneNetwork::new(&scene.road));
        let Some(path) = lanes.path(
            xy,
            heading_rad,
            &mut self.lane_scratch,
            &mut self.candidates,
        ) else {
            return (points_xy_m, valid, beside);
        };
        let lanes_beside = lanes.beside(&path);
        for (k, ((p, &v), b)) in path
            .points
            .iter()
            .zip(&path.valid)
            .zip(lanes_beside)
            .enumerate()
        {
            if v {
                let (x, y) = frame.point(p[0], p[1]);
                points_xy_m[2 * k] = x;
                points_xy_m[2 * k + 1] = y;
                valid[k] = true;
                beside[k] = b;
            }
        }
        (points_xy_m, valid, beside)
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

#[cfg(test)]
mod tests;
