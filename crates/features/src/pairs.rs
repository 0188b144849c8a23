//! Interacting vehicle pairs of a window.
//!
//! Rule, in order:
//! 1. **Labelled**: when the scene's `objects_of_interest` are exactly two tracks, both
//!    vehicles, both valid at the window's current step, that pair is taken (WOMD's
//!    interactive subset; the synthetic generator labels its pairs the same way).
//! 2. **Mined** otherwise: among vehicles valid at the current step with at least
//!    `min_future_valid_steps` valid future steps, a pair interacts when their future paths
//!    come within `max_path_distance_m` of each other at times at most `max_time_gap_s`
//!    apart (one reaches a point the other occupied, or will occupy, within that gap), and at
//!    least one of them moves more than `min_travel_m`. Paths are compared at
//!    `path_stride_steps` (2 Hz by default). Pairs are ranked by closest approach and at most
//!    `max_pairs` are kept. Both vehicles of a pair are interchangeable: consumers use both
//!    directions (A, B) and (B, A).

use crate::prepared::{InteractingPair, PairSource, PreparedScene};
use crate::window::{Window, WindowConfig};
use scbg_scene::ObjectType;

/// Parameters of the pair-mining rule (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct PairConfig {
    /// Future paths must come this close, metres (default 3).
    pub max_path_distance_m: f32,
    /// …at times at most this far apart, seconds (default 4).
    pub max_time_gap_s: f32,
    /// At least one vehicle must travel more than this over the future, metres (default 5).
    pub min_travel_m: f32,
    /// Valid future steps a vehicle needs to be a candidate (default 40).
    pub min_future_valid_steps: usize,
    /// Steps between compared path points (default 5: 2 Hz at 10 Hz).
    pub path_stride_steps: usize,
    /// Most mined pairs kept per window, closest approach first (default 4).
    pub max_pairs: usize,
}

impl Default for PairConfig {
    fn default() -> Self {
        Self {
            max_path_distance_m: 3.0,
            max_time_gap_s: 4.0,
            min_travel_m: 5.0,
            min_future_valid_steps: 40,
            path_stride_steps: 5,
            max_pairs: 4,
        }
    }
}

/// Pairs of one window (see the module docs for the rule).
pub fn select_pairs(
    scene: &PreparedScene,
    window: &Window,
    window_config: &WindowConfig,
    objects_of_interest: &[i64],
    config: &PairConfig,
) -> Vec<InteractingPair> {
    let now = window.current_step;
    let is_vehicle_now = |i: usize| {
        let t = &scene.tracks[i];
        t.object_type == ObjectType::Vehicle && t.valid_at(now as isize)
    };
    if let [a, b] = objects_of_interest
        && let (Some(i), Some(j)) = (scene.track_index(*a), scene.track_index(*b))
        && i != j
        && is_vehicle_now(i)
        && is_vehicle_now(j)
    {
        return vec![InteractingPair {
            first: i,
            second: j,
            source: PairSource::Labelled,
        }];
    }
    let stride = config.path_stride_steps.max(1);
    let future: Vec<usize> = (0..window_config.future_steps)
        .step_by(stride)
        .map(|f| window.future_step(f))
        .filter(|&s| s < scene.num_steps)
        .collect();
    // Candidate paths: (track, [(time index, x, y)]) with bounding boxes for a quick reject.
    struct Path {
        track: usize,
        points: Vec<(usize, f32, f32)>,
        min: [f32; 2],
        max: [f32; 2],
    }
    let paths: Vec<Path> = (0..scene.tracks.len())
        .filter(|&i| is_vehicle_now(i))
        .filter_map(|i| {
            let t = &scene.tracks[i];
            let valid_future = (window.future_step(0)
                ..window
                    .future_step(window_config.future_steps)
                    .min(scene.num_steps))
                .filter(|&s| t.valid[s])
                .count();
            if valid_future < config.min_future_valid_steps {
                return None;
            }
            let mut points: Vec<(usize, f32, f32)> = Vec::with_capacity(future.len() + 1);
            points.push((now, t.x_m[now], t.y_m[now]));
            points.extend(
                future
                    .iter()
                    .filter(|&&s| t.valid[s])
                    .map(|&s| (s, t.x_m[s], t.y_m[s])),
            );
            let mut min = [f32::INFINITY; 2];
            let mut max = [f32::NEG_INFINITY; 2];
            for &(_, x, y) in &points {
                min = [min[0].min(x), min[1].min(y)];
                max = [max[0].max(x), max[1].max(y)];
            }
            Some(Path {
                track: i,
                points,
                min,
                max,
            })
        })
        .collect();
    let travel = |p: &Path| {
        let (_, x0, y0) = p.points[0];
        let far2 = p
            .points
            .iter()
            .map(|&(_, x, y)| squared_norm(x - x0, y - y0))
            .fold(0.0f64, f64::max);
        norm_from_squared(far2)
    };
    let d = config.max_path_distance_m;
    let max_gap_steps = (config.max_time_gap_s / scene.step_secs.max(1e-3)).round() as isize;
    let mut found: Vec<(f32, InteractingPair)> = Vec::new();
    for (ai, a) in paths.iter().enumerate() {
        for b in &paths[ai + 1..] {
            if a.min[0] - d > b.max[0]
                || b.min[0] - d > a.max[0]
                || a.min[1] - d > b.max[1]
                || b.min[1] - d > a.max[1]
            {
                continue;
            }
            if travel(a) < config.min_travel_m && travel(b) < config.min_travel_m {
                continue;
            }
            let mut best2 = f64::INFINITY;
            for &(sa, xa, ya) in &a.points[1..] {
                for &(sb, xb, yb) in &b.points[1..] {
                    if (sa as isize - sb as isize).abs() > max_gap_steps {
                        continue;
                    }
                    best2 = best2.min(squared_norm(xa - xb, ya - yb));
                }
            }
            let best = norm_from_squared(best2);
            if best <= d {
                found.push((
                    best,
                    InteractingPair {
                        first: a.track,
                        second: b.track,
                        source: PairSource::Mined,
                    },
                ));
            }
        }
    }
    found.sort_by(|x, y| {
        x.0.total_cmp(&y.0)
            .then(x.1.first.cmp(&y.1.first))
            .then(x.1.second.cmp(&y.1.second))
    });
    found
        .into_iter()
        .take(config.max_pairs)
        .map(|(_, p)| p)
        .collect()
}

/// `dx² + dy²` in f64: exact products, one rounding. With [`norm_from_squared`] this is
/// `f32::hypot` (glibc computes `(float) sqrt((double) x * x + (double) y * y)`), and because
/// that map is monotonic, the closest (farthest) of many points can be found on the squares
/// and the root taken once.
fn squared_norm(dx: f32, dy: f32) -> f64 {
    let (dx, dy) = (f64::from(dx), f64::from(dy));
    dx * dx + dy * dy
}

fn norm_from_squared(d2: f64) -> f32 {
    d2.sqrt() as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn squared_then_root_is_hypot() {
        let mut state = 7u64;
        let mut next = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            f32::from_bits((state >> 32) as u32)
        };
        let mut checked = 0;
        while checked < 200_000 {
            let (x, y) = (next(), next());
            if !(x.is_finite() && y.is_finite()) {
                continue;
            }
            // Random bit patterns cover every exponent; scaled ones the metre range.
            for (x, y) in [(x, y), (x.fract() * 300.0, y.fract() * 300.0)] {
                assert_eq!(
                    norm_from_squared(squared_norm(x, y)).to_bits(),
                    x.hypot(y).to_bits(),
                    "{x} {y}"
                );
            }
            checked += 1;
        }
    }
}
