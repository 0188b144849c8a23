//! Lane keeping of a plan: points that drift from every car lane's centre line are pulled
//! back toward it before the tracker follows them.
//!
//! The generator is trained open loop on logged histories. Re-planned every second from the
//! simulated history, its futures compound sideways off the road (the demo measured B
//! off-road in 78 % of rollouts at quantile 0.1; a single plan stays on the road). Lane
//! keeping moves each plan point that lies more than `max_offset_m` from the nearest car-lane
//! centre line (any lane type but bike lanes) along the line to that nearest point, to
//! `max_offset_m` from it. Lane changes stay possible — a point between two lanes is pulled
//! toward the nearer one — and the plan's timing (when B is where along its way, which is what
//! courtesy is about) is kept. Only lanes heading the plan's way (within 45°) count, so at an
//! intersection a drifting point is not kept on the crossing road. Points farther than
//! [`REACH_M`] from every lane centre (a car park, a driveway) are left as they are. The
//! segments are listed once per simulation ([`LaneSegments`]).
//!
//! A plan keeps to one lane until it is clearly in another: a point stays with the lane the
//! point before it was kept to (while it lies alongside that lane, not beyond its ends) unless
//! another lane is [`SWITCH_MARGIN_M`] nearer, so a plan
//! drifting half a lane sideways (the generator's futures do, 1–2 m in 8 s on a straight road)
//! is not split between two lanes. Where the kept lane does change, the correction is ramped
//! over [`SWITCH_STEPS`] instead of jumping a lane width from one point to the next: a lane
//! change B can drive.

use scbg_scene::{LaneType, Map};

/// Lane segments farther than this from a plan point are not considered for it (m).
pub const REACH_M: f64 = 6.0;
/// Only lanes heading within 45° of the plan's own direction at a point count for it (the
/// cosine): at an intersection, a point that drifted sideways off its lane is not "kept" on
/// the crossing road's lane it happens to lie on.
pub const MAX_ANGLE_COS: f64 = std::f64::consts::FRAC_1_SQRT_2;
/// Plan points less than this apart (over two steps) are standing: they keep the direction
/// the plan had before (m). Used only where the plan spans less than [`CHORD_M`] on both sides
/// of a point.
pub const MOVING_M: f64 = 0.2;
/// The plan's direction at a point is that of the chord from the last point at least this far
/// behind it to the first point at least this far ahead (either end alone where the other does
/// not exist), m: a plan that slows to a stand wiggles by decimetres, and a direction taken
/// over two steps there can point across the road — onto the crossing road's lanes at an
/// intersection, which then pulled B's points 5 m sideways into A's lane (docs/findings.md,
/// *The safety guard, rule by rule*).
pub const CHORD_M: f64 = 2.0;
/// Another lane takes over a plan only when it is this much nearer than the lane the plan's
/// previous point was kept to (m).
pub const SWITCH_MARGIN_M: f64 = 1.0;
/// Steps over which the correction is ramped where the kept lane changes (3 s at 10 Hz, a
/// usual lane change).
pub const SWITCH_STEPS: usize = 30;

/// The car-lane centre-line segments of a map (every lane but bike lanes), listed once per
/// simulation: the map does not change while plans are made.
#[derive(Debug, Clone, Default)]
pub struct LaneSegments {
    segments: Vec<Segment>,
}

/// `(start, end, lane index, first segment of its lane, last segment of its lane)`.
type Segment = ([f64; 2], [f64; 2], usize, bool, bool);

impl LaneSegments {
    /// The segments of `map`'s car lanes.
    pub fn new(map: &Map) -> Self {
        Self {
            segments: map
                .lanes
                .iter()
                .enumerate()
                .filter(|(_, l)| l.lane_type != LaneType::BikeLane)
                .flat_map(|(k, l)| {
                    let last = l.polyline.len().saturating_sub(2);
                    l.polyline.windows(2).enumerate().map(move |(i, w)| {
                        let (a, b) = ([w[0].x_m, w[0].y_m], [w[1].x_m, w[1].y_m]);
                        (a, b, k, i == 0, i == last)
                    })
                })
                .collect(),
        }
    }

    /// Pulls every point of `plan` (world frame) to within `max_offset_m` of the nearest
    /// car-lane centre line within [`REACH_M`] that heads the plan's way; returns how many
    /// points moved.
    pub fn keep_near(&self, plan: &mut [[f64; 2]], max_offset_m: f64) -> usize {
        if plan.is_empty() {
            return 0;
        }
        // The plan's bounding box grown by the reach: segments outside it cannot be nearest to
        // any point within reach.
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in plan.iter() {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let (lo, hi) = (
            [lo[0] - REACH_M, lo[1] - REACH_M],
            [hi[0] + REACH_M, hi[1] + REACH_M],
        );
        let segments: Vec<&Segment> = self
            .segments
            .iter()
            .filter(|(a, b, ..)| {
                a[0].max(b[0]) >= lo[0]
                    && a[0].min(b[0]) <= hi[0]
                    && a[1].max(b[1]) >= lo[1]
                    && a[1].min(b[1]) <= hi[1]
            })
            .collect();
        let heading = plan_directions(plan);
        // Per point: the correction that keeps it, and the lane it was kept to.
        let mut corrections = vec![[0.0f64; 2]; plan.len()];
        let mut kept_lane: Option<usize> = None;
        let mut switches = Vec::new();
        for (t, (p, heading)) in plan.iter().zip(heading).enumerate() {
            // The nearest point overall and on the lane the previous point was kept to.
            let (mut best, mut on_kept) = ((REACH_M * REACH_M, None), (f64::INFINITY, None));
            for &&(a, b, lane, first, last) in &segments {
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let len2 = dx * dx + dy * dy;
                if let Some(h) = heading
                    && (dx * h[0] + dy * h[1]) < MAX_ANGLE_COS * len2.sqrt()
                {
                    continue;
                }
                let u = if len2 > 0.0 {
                    (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let q = [a[0] + u * dx, a[1] + u * dy];
                let d2 = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
                if d2 < best.0 {
                    best = (d2, Some((q, lane)));
                }
                // A point beyond either end of the kept lane has left it (for its successor).
                let beyond = (first && u <= 0.0) || (last && u >= 1.0);
                if Some(lane) == kept_lane && !beyond && d2 < on_kept.0 {
                    on_kept = (d2, Some((q, lane)));
                }
            }
            let chosen = match (best.1, on_kept.1) {
                (Some(_), Some(k)) if on_kept.0.sqrt() <= best.0.sqrt() + SWITCH_MARGIN_M => {
                    Some((on_kept.0, k))
                }
                (Some(b), _) => Some((best.0, b)),
                (None, _) => None,
            };
            if let Some((d2, (q, lane))) = chosen {
                if kept_lane.is_some_and(|k| k != lane) {
                    switches.push(t);
                }
                kept_lane = Some(lane);
                let d = d2.sqrt();
                if d > max_offset_m {
                    let k = max_offset_m / d;
                    let to = [q[0] + k * (p[0] - q[0]), q[1] + k * (p[1] - q[1])];
                    corrections[t] = [to[0] - p[0], to[1] - p[1]];
                }
            }
        }
        // A change of the kept lane moves the correction by up to a lane width: ramp it.
        for &t in &switches {
            let (lo, hi) = (
                t.saturating_sub(SWITCH_STEPS / 2),
                (t + SWITCH_STEPS / 2).min(plan.len() - 1),
            );
            let jump = (corrections[t][0] - corrections[t - 1][0])
                .hypot(corrections[t][1] - corrections[t - 1][1]);
            if jump < 2.0 * max_offset_m.max(0.25) || hi <= lo {
                continue;
            }
            let (c0, c1) = (corrections[lo], corrections[hi]);
            for (j, c) in corrections.iter_mut().enumerate().take(hi).skip(lo + 1) {
                let w = (j - lo) as f64 / (hi - lo) as f64;
                let w = w * w * (3.0 - 2.0 * w);
                *c = [c0[0] + w * (c1[0] - c0[0]), c0[1] + w * (c1[1] - c0[1])];
            }
        }
        let mut moved = 0;
        for (p, c) in plan.iter_mut().zip(&corrections) {
            if c[0] != 0.0 || c[1] != 0.0 {
                *p = [p[0] + c[0], p[1] + c[1]];
                moved += 1;
            }
        }
        moved
    }
}

/// The plan's direction at each point: the chord over [`CHORD_M`] on either side
/// ([`CHORD_M`]'s docs); where the plan spans less than that on both sides, the central
/// difference over two steps, or where that stands (under [`MOVING_M`]) the last direction the
/// plan had, or none before it first moves.
fn plan_directions(plan: &[[f64; 2]]) -> Vec<Option<[f64; 2]>> {
    let n = plan.len();
    let dist = |a: [f64; 2], b: [f64; 2]| (b[0] - a[0]).hypot(b[1] - a[1]);
    let unit = |a: [f64; 2], b: [f64; 2]| {
        let len = dist(a, b);
        (len >= MOVING_M).then(|| [(b[0] - a[0]) / len, (b[1] - a[1]) / len])
    };
    let mut out = Vec::with_capacity(n);
    let mut last = None;
    for k in 0..n {
        let p = plan[k];
        let behind = (0..k).rev().find(|&j| dist(plan[j], p) >= CHORD_M);
        let ahead = (k + 1..n).find(|&j| dist(p, plan[j]) >= CHORD_M);
        let direction = match (behind, ahead) {
            (None, None) => unit(plan[k.saturating_sub(1)], plan[(k + 1).min(n - 1)]),
            (b, a) => unit(plan[b.unwrap_or(k)], plan[a.unwrap_or(k)]),
        };
        if direction.is_some() {
            last = direction;
        }
        out.push(last);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use scbg_scene::{Lane, MapPoint};

    fn lane(y: f64, lane_type: LaneType) -> Lane {
        Lane {
            lane_type,
            polyline: (0..=10)
                .map(|i| MapPoint {
                    x_m: 10.0 * f64::from(i),
                    y_m: y,
                    z_m: 0.0,
                })
                .collect(),
            ..Lane::default()
        }
    }

    /// A lane heading +y along `x` over `ys` (points 10 m apart).
    fn lane_along_y(x: f64, ys: std::ops::RangeInclusive<f64>) -> Lane {
        let n = ((ys.end() - ys.start()) / 10.0).round() as u32;
        Lane {
            lane_type: LaneType::SurfaceStreet,
            polyline: (0..=n)
                .map(|i| MapPoint {
                    x_m: x,
                    y_m: ys.start() + 10.0 * f64::from(i),
                    z_m: 0.0,
                })
                .collect(),
            ..Lane::default()
        }
    }

    #[test]
    fn points_off_the_lane_come_back_and_points_on_it_stay() {
        let map = Map {
            lanes: vec![
                lane(0.0, LaneType::SurfaceStreet),
                lane(3.5, LaneType::Freeway),
            ],
            ..Map::default()
        };
        // One point at a time (no direction, no carried correction).
        let keep = |p: [f64; 2]| {
            let mut plan = [p];
            let moved = LaneSegments::new(&map).keep_near(&mut plan, 0.5);
            (moved, plan[0])
        };
        assert_eq!(keep([5.0, 0.3]), (0, [5.0, 0.3])); // on the first lane: stays
        let (moved, p) = keep([15.0, -2.0]); // 2 m right of it: to 0.5 m
        assert!(moved == 1 && (p[0] - 15.0).abs() < 1e-9 && (p[1] + 0.5).abs() < 1e-9);
        let (moved, p) = keep([25.0, 2.2]); // nearer the second lane (1.3 m): 0.5 m below it
        assert!(moved == 1 && (p[0] - 25.0).abs() < 1e-9 && (p[1] - 3.0).abs() < 1e-9);
        assert_eq!(keep([35.0, -20.0]), (0, [35.0, -20.0])); // out of reach: stays
        // A lane across the plan's way does not count: a plan heading +x drifting onto a
        // lane along y is pulled to the nearest lane along x (out of reach here: unchanged).
        let crossing = Map {
            lanes: vec![lane_along_y(50.0, -50.0..=50.0)],
            ..Map::default()
        };
        let mut p = vec![[48.0, 20.0], [49.0, 20.0], [50.0, 20.0]];
        assert_eq!(LaneSegments::new(&crossing).keep_near(&mut p, 0.5), 0);
        // A bike lane does not count.
        let bike = Map {
            lanes: vec![lane(0.0, LaneType::BikeLane)],
            ..Map::default()
        };
        let mut p = vec![[15.0, -2.0]];
        assert_eq!(LaneSegments::new(&bike).keep_near(&mut p, 0.5), 0);
        assert_eq!(p[0], [15.0, -2.0]);
    }

    #[test]
    fn a_plan_wiggling_to_a_stand_before_a_crossing_road_is_not_pulled_onto_it() {
        // B's lane heads +y along x = 50 and ends at y = 0; the crossing road's lane runs
        // along x at y = 2.5. B's plan comes up its lane and stands just past the stop line,
        // wiggling sideways by half a metre: over two steps it heads along x there.
        let map = Map {
            lanes: vec![
                lane_along_y(50.0, -50.0..=0.0),
                lane(2.5, LaneType::SurfaceStreet),
            ],
            ..Map::default()
        };
        let mut plan: Vec<[f64; 2]> = (0..10).map(|k| [50.0, f64::from(k) - 9.0]).collect();
        plan.extend([
            [50.0, 0.5],
            [50.5, 0.6],
            [51.0, 0.7],
            [50.5, 0.8],
            [50.0, 0.9],
        ]);
        LaneSegments::new(&map).keep_near(&mut plan, 0.25);
        for p in &plan {
            assert!(p[1] < 1.0, "{p:?} pulled toward the crossing road");
        }
        // Its own lane's end pulls the wiggle back toward it instead.
        assert!(plan[11][0] < 50.5 && plan[12][0] < 51.0);
        // The direction over two steps alone would have taken the crossing road's lane.
        let two_step = plan_directions(&[[0.0, 0.5], [0.5, 0.6], [1.0, 0.7]]);
        assert!(two_step[1].is_some_and(|h| h[0] > 0.9));
    }

    #[test]
    fn a_drifting_plan_keeps_its_lane_and_a_lane_change_is_ramped() {
        let mut straight = lane(0.0, LaneType::Freeway);
        straight.polyline.extend((11..=30).map(|i| MapPoint {
            x_m: 10.0 * f64::from(i),
            y_m: 0.0,
            z_m: 0.0,
        }));
        let mut left = straight.clone();
        for p in &mut left.polyline {
            p.y_m = 3.5;
        }
        let map = Map {
            lanes: vec![straight, left],
            ..Map::default()
        };
        let lanes = LaneSegments::new(&map);
        // Drifting 2.2 m left over 8 s, past the middle between the lanes: kept to its lane.
        let mut drift: Vec<[f64; 2]> = (0..80)
            .map(|t| [2.0 * f64::from(t), 2.2 * f64::from(t) / 79.0])
            .collect();
        lanes.keep_near(&mut drift, 0.25);
        assert!(drift.iter().all(|p| p[1] <= 0.25 + 1e-9), "{drift:?}");
        // Drifting on to 3.0 m, clearly into the other lane: kept as a lane change whose
        // points never jump sideways by more than a few decimetres a step.
        let mut change: Vec<[f64; 2]> = (0..80)
            .map(|t| [2.0 * f64::from(t), 3.0 * f64::from(t) / 79.0])
            .collect();
        lanes.keep_near(&mut change, 0.25);
        assert!(change[0][1].abs() < 1e-9 && (change[79][1] - 3.5).abs() <= 0.25 + 1e-9);
        let worst_step = change
            .windows(2)
            .map(|w| (w[1][1] - w[0][1]).abs())
            .fold(0.0, f64::max);
        assert!(worst_step < 0.45, "a sideways step of {worst_step} m");
        // Past the end of its lane a plan goes on along the lane that continues it, never
        // pulled back toward the end it passed.
        let along = |x0: u32, x1: u32| Lane {
            lane_type: LaneType::Freeway,
            polyline: (x0..=x1)
                .map(|i| MapPoint {
                    x_m: 10.0 * f64::from(i),
                    y_m: 0.0,
                    z_m: 0.0,
                })
                .collect(),
            ..Lane::default()
        };
        let chained = Map {
            lanes: vec![along(0, 10), along(10, 30)],
            ..Map::default()
        };
        // (The plan ends just past the joint, so no later switch ramps the correction away.)
        let x = |t: usize| 61.0 + 0.5 * t as f64;
        let mut plan: Vec<[f64; 2]> = (0..80).map(|t| [x(t), 0.6]).collect();
        LaneSegments::new(&chained).keep_near(&mut plan, 0.25);
        for (t, p) in plan.iter().enumerate() {
            assert!(
                (p[0] - x(t)).abs() < 1e-9 && (p[1] - 0.25).abs() < 1e-9,
                "{p:?}"
            );
        }
    }
}
