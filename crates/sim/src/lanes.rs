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
//! intersection a drifting point is not kept on the crossing road. A lane counts for points up
//! to [`PAST_END_M`] beyond its ends, not farther. Points farther than [`REACH_M`] from every
//! lane centre before the plan keeps to any lane (a car park, a driveway) are left as they are.
//! The segments are listed once per simulation ([`LaneSegments`]).
//!
//! A plan keeps to one lane until it is clearly in another: a point stays with the lane the
//! point before it was kept to (while it lies alongside that lane, not beyond its ends) unless
//! another lane is [`SWITCH_MARGIN_M`] nearer, so a plan
//! drifting half a lane sideways (the generator's futures do, 1–2 m in 8 s on a straight road)
//! is not split between two lanes. Where the kept lane does change, the correction is ramped
//! over [`SWITCH_STEPS`] instead of jumping a lane width from one point to the next: a lane
//! change B can drive.
//!
//! A plan that leaves every lane heading its way after keeping to one (it cuts across a
//! roundabout's island, runs on past the end of an on-ramp, drifts off the outermost lane of
//! a highway: maps unlike the ones the generator learned on) goes on along that lane's route
//! instead, at the plan's own progress ([`LaneSegments::keep_near`]): timing is what courtesy is
//! about, and the road is where B can drive it.

use std::collections::HashMap;

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

/// A lane continues another where the map links none when it starts within this of the other's
/// end, heading its way (within 45°), m.
pub const JOIN_M: f64 = 1.5;
/// A point more than this past the end of a lane's centre line (along its last segment, m) is
/// not kept to that lane: a lane that ends is behind it. Joints between lanes at an angle leave
/// a point at most a few decimetres past one lane's end and before the next one's start.
pub const PAST_END_M: f64 = 2.0;
/// Where no lane starts at a lane's end, a lane passing near it continues it when it heads
/// within 60° of its way (the cosine): highway-env's roundabout entries meet the ring side-on,
/// 45–60° off its way, and a crossing road at a junction (90°) does not continue a lane.
pub const JOIN_ANGLE_COS: f64 = 0.5;
/// A plan's route runs over at most this many lanes past the one it leaves from.
pub const MAX_ROUTE_LANES: usize = 32;

/// The car-lane centre-line segments of a map (every lane but bike lanes), listed once per
/// simulation: the map does not change while plans are made.
#[derive(Debug, Clone, Default)]
pub struct LaneSegments {
    segments: Vec<Segment>,
    /// Each map lane's centre line (world frame, m); empty for bike lanes.
    centre_lines: Vec<Vec<[f64; 2]>>,
    /// Each map lane's linked exit lanes (indices into the map's lanes).
    exits: Vec<Vec<usize>>,
    /// Each car lane's bounding box `(min, max)` (empty for the others): a lane's route looks
    /// for side-on successors only among lanes whose box comes within [`REACH_M`].
    bounds: Vec<([f64; 2], [f64; 2])>,
}

/// `(start, end, lane index, first segment of its lane, last segment of its lane)`.
type Segment = ([f64; 2], [f64; 2], usize, bool, bool);

impl LaneSegments {
    /// The segments of `map`'s car lanes.
    pub fn new(map: &Map) -> Self {
        let car = |l: &scbg_scene::Lane| l.lane_type != LaneType::BikeLane;
        let index_of: HashMap<i64, usize> = map
            .lanes
            .iter()
            .enumerate()
            .map(|(k, l)| (l.id, k))
            .collect();
        let centre_lines: Vec<Vec<[f64; 2]>> = map
            .lanes
            .iter()
            .map(|l| {
                if car(l) {
                    l.polyline.iter().map(|p| [p.x_m, p.y_m]).collect()
                } else {
                    Vec::new()
                }
            })
            .collect();
        let exits = map
            .lanes
            .iter()
            .map(|l| {
                l.exit_lanes
                    .iter()
                    .filter_map(|id| index_of.get(id).copied())
                    .filter(|&k| car(&map.lanes[k]))
                    .collect()
            })
            .collect();
        // Bike lanes have no centre line here, so no segments either.
        let segments = centre_lines
            .iter()
            .enumerate()
            .flat_map(|(k, line)| {
                let last = line.len().saturating_sub(2);
                line.windows(2)
                    .enumerate()
                    .map(move |(i, w)| (w[0], w[1], k, i == 0, i == last))
            })
            .collect();
        let bounds = centre_lines
            .iter()
            .map(|line| {
                line.iter().fold(
                    ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
                    |(lo, hi), p| {
                        (
                            [lo[0].min(p[0]), lo[1].min(p[1])],
                            [hi[0].max(p[0]), hi[1].max(p[1])],
                        )
                    },
                )
            })
            .collect();
        Self {
            segments,
            centre_lines,
            exits,
            bounds,
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
        // Where the plan leaves every lane after keeping to one: its route takes over there.
        let mut left_at: Option<(usize, usize)> = None;
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
                // Just past a lane's end (or before its start) a point is kept beside the
                // lane's line carried on; farther, the lane is behind (ahead of) the point, not
                // beside it.
                let len = len2.sqrt();
                let (before_m, past_m) = (
                    if first { PAST_END_M } else { 0.0 },
                    if last { PAST_END_M } else { 0.0 },
                );
                let (along, q) = foot(a, b, *p, before_m, past_m);
                if (last && (along - 1.0) * len > PAST_END_M)
                    || (first && -along * len > PAST_END_M)
                {
                    continue;
                }
                let u = along.clamp(0.0, 1.0);
                let d2 = dist2(q, *p);
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
            if let (None, Some(lane)) = (chosen, kept_lane) {
                left_at = Some((t, lane));
                break;
            }
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
        let kept_end = left_at.map_or(plan.len(), |(t, _)| t);
        for &t in &switches {
            let (lo, hi) = (
                t.saturating_sub(SWITCH_STEPS / 2),
                (t + SWITCH_STEPS / 2).min(kept_end - 1),
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
        let raw = left_at.map(|_| plan.to_vec());
        let mut moved = 0;
        for (p, c) in plan.iter_mut().zip(&corrections).take(kept_end) {
            if c[0] != 0.0 || c[1] != 0.0 {
                *p = [p[0] + c[0], p[1] + c[1]];
                moved += 1;
            }
        }
        if let (Some((t, lane)), Some(raw)) = (left_at, raw) {
            moved += self.continue_along_route(plan, &raw, t, lane, max_offset_m);
        }
        moved
    }

    /// Re-draws `plan[from..]` along the route of `lane`, the lane `plan[from - 1]` was kept
    /// to: from that point's place along the lane and its offset beside it (at most
    /// `max_offset_m`), each point lies as far along the route as `raw` (the plan as
    /// generated) travels by then. At each lane's end the route takes the lane that continues
    /// it ([`Self::successor_toward`]) nearest the plan's last point: where the plan means to
    /// go. Where no lane continues it, the plan's
    /// own moves carry on from the route's end, kept in lane afresh. Returns how many points
    /// moved.
    fn continue_along_route(
        &self,
        plan: &mut [[f64; 2]],
        raw: &[[f64; 2]],
        from: usize,
        lane: usize,
        max_offset_m: f64,
    ) -> usize {
        let Some(goal) = raw.last().copied() else {
            return 0;
        };
        let line = &self.centre_lines[lane];
        let start = plan[from - 1];
        let Some((seg, foot, offset_m, past_m)) = project(line, start) else {
            return 0;
        };
        let offset_m = offset_m.clamp(-max_offset_m, max_offset_m);
        let travel_m: f64 = raw[from - 1..].windows(2).map(|w| dist(w[0], w[1])).sum();
        // The route's centre line, from the foot of `start` on.
        let mut route = vec![foot];
        route.extend_from_slice(&line[seg + 1..]);
        let (mut current, mut length_m) = (lane, polyline_length(&route));
        for _ in 0..MAX_ROUTE_LANES {
            if length_m > past_m + travel_m + 1.0 {
                break;
            }
            let Some((next, seg, from_point)) = self.successor_toward(current, goal) else {
                break;
            };
            let next_line = &self.centre_lines[next];
            let joint = std::iter::once(from_point).chain(next_line[seg + 1..].iter().copied());
            for p in joint {
                let last = *route.last().expect("a route has a point");
                if dist(last, p) > 1e-6 {
                    length_m += dist(last, p);
                    route.push(p);
                }
            }
            current = next;
        }
        let route_end_m = polyline_length(&route);
        let mut s_m = past_m;
        let (mut beyond, mut beyond_from): (Option<[f64; 2]>, Option<usize>) = (None, None);
        for t in from..plan.len() {
            let step_m = dist(raw[t - 1], raw[t]);
            s_m += step_m;
            let beside = |s_m: f64| {
                let (p, dir) = point_at(&route, s_m);
                [p[0] - dir[1] * offset_m, p[1] + dir[0] * offset_m]
            };
            // Where no lane continues the route, the plan's own moves carry on from its end:
            // the part of this step past the end, then whole steps.
            let d = [raw[t][0] - raw[t - 1][0], raw[t][1] - raw[t - 1][1]];
            let to = match beyond {
                _ if s_m <= route_end_m => beside(s_m),
                Some(last) => [last[0] + d[0], last[1] + d[1]],
                None => {
                    let end = beside(route_end_m);
                    let k = if step_m > 0.0 {
                        (s_m - route_end_m) / step_m
                    } else {
                        0.0
                    };
                    [end[0] + k * d[0], end[1] + k * d[1]]
                }
            };
            if s_m > route_end_m {
                beyond = Some(to);
                beyond_from.get_or_insert(t);
            }
            plan[t] = to;
        }
        // Past a dead end the plan is kept in lane afresh (the far side of a junction whose
        // map has no lanes across it).
        if let Some(e) = beyond_from {
            self.keep_near(&mut plan[e..], max_offset_m);
        }
        (from..plan.len()).filter(|&t| plan[t] != raw[t]).count()
    }

    /// The lane that continues `lane`, and where on it (segment, point): the lanes linked as
    /// its exits and those starting within [`JOIN_M`] of its end heading its way, from their
    /// start; where there are none, the lanes passing within [`REACH_M`] of its end heading
    /// within [`JOIN_ANGLE_COS`] of its way (a roundabout's entry that meets the ring side-on),
    /// from their point nearest its end. Of these, the one whose centre line comes nearest
    /// `goal`.
    fn successor_toward(&self, lane: usize, goal: [f64; 2]) -> Option<(usize, usize, [f64; 2])> {
        let line = &self.centre_lines[lane];
        let (end, before) = (line[line.len() - 1], line[line.len().saturating_sub(2)]);
        let heading = unit(before, end);
        let along = |h: Option<[f64; 2]>, cos: f64| match (heading, h) {
            (Some(a), Some(b)) => a[0] * b[0] + a[1] * b[1] >= cos,
            _ => true,
        };
        let lines = || {
            (0..self.centre_lines.len()).filter(|&k| k != lane && self.centre_lines[k].len() >= 2)
        };
        let mut next: Vec<(usize, usize, [f64; 2])> = self.exits[lane]
            .iter()
            .copied()
            .filter(|&k| self.centre_lines[k].len() >= 2)
            .chain(lines().filter(|&k| {
                let l = &self.centre_lines[k];
                dist(l[0], end) <= JOIN_M && along(unit(l[0], l[1]), MAX_ANGLE_COS)
            }))
            .map(|k| (k, 0, self.centre_lines[k][0]))
            .collect();
        if next.is_empty() {
            let near_end = |k: &usize| {
                let (lo, hi) = self.bounds[*k];
                (0..2).all(|d| end[d] >= lo[d] - REACH_M && end[d] <= hi[d] + REACH_M)
            };
            next = lines()
                .filter(near_end)
                .filter_map(|k| {
                    let l = &self.centre_lines[k];
                    let (seg, q, ..) = project(l, end)?;
                    (dist(q, end) <= REACH_M && along(unit(l[seg], l[seg + 1]), JOIN_ANGLE_COS))
                        .then_some((k, seg, q))
                })
                .collect();
        }
        next.into_iter()
            .map(|(k, seg, q)| {
                let near = project(&self.centre_lines[k][seg..], goal)
                    .map_or(f64::INFINITY, |(_, g, ..)| dist(g, goal));
                (near, k, seg, q)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
            .map(|(_, k, seg, q)| (k, seg, q))
    }
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (b[0] - a[0]).hypot(b[1] - a[1])
}

/// The squared distance: what ranks many candidates (hypot is slow).
fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)
}

fn unit(a: [f64; 2], b: [f64; 2]) -> Option<[f64; 2]> {
    let len = dist(a, b);
    (len > 1e-9).then(|| [(b[0] - a[0]) / len, (b[1] - a[1]) / len])
}

fn polyline_length(line: &[[f64; 2]]) -> f64 {
    line.windows(2).map(|w| dist(w[0], w[1])).sum()
}

/// Where `p` projects onto the line through segment `a`–`b`: the fraction along it (0 at `a`,
/// 1 at `b`, outside [0, 1] past either end; 0 for a segment of no length) and the nearest
/// point of the segment carried on `before_a_m` before `a` and `past_b_m` beyond `b`.
fn foot(a: [f64; 2], b: [f64; 2], p: [f64; 2], before_a_m: f64, past_b_m: f64) -> (f64, [f64; 2]) {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    if len2 <= 0.0 {
        return (0.0, a);
    }
    let along = ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2;
    let len = len2.sqrt();
    let u = along.clamp(-before_a_m / len, 1.0 + past_b_m / len);
    (along, [a[0] + u * dx, a[1] + u * dy])
}

/// The nearest point of a polyline to `p`, its last segment carried on [`PAST_END_M`]: the
/// segment, the point (on the polyline itself), `p`'s signed offset from it (m, left of the
/// line's way positive) and how far past the polyline's end it lies (m, 0 on the polyline);
/// `None` for fewer than two points.
fn project(line: &[[f64; 2]], p: [f64; 2]) -> Option<(usize, [f64; 2], f64, f64)> {
    // (squared distance, segment, point, offset, past the end)
    let mut best: Option<(f64, usize, [f64; 2], f64, f64)> = None;
    let last = line.len().saturating_sub(2);
    for (i, w) in line.windows(2).enumerate() {
        let (a, b) = (w[0], w[1]);
        let (along, q) = foot(a, b, p, 0.0, if i == last { PAST_END_M } else { 0.0 });
        let d2 = dist2(p, q);
        if best.is_none_or(|(bd2, ..)| d2 < bd2) {
            let d = dist(p, q);
            let side = ((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])).signum();
            let past_m = dist(a, q) - dist(a, b);
            let (on_line, past_m) = if along > 1.0 && past_m > 0.0 {
                (b, past_m)
            } else {
                (q, 0.0)
            };
            best = Some((d2, i, on_line, side * d, past_m));
        }
    }
    best.map(|(_, i, q, offset, past_m)| (i, q, offset, past_m))
}

/// The point at arc length `s_m` along a polyline (clamped to its ends) and the unit direction
/// of the segment it lies on (+x where the polyline has no length).
fn point_at(line: &[[f64; 2]], s_m: f64) -> ([f64; 2], [f64; 2]) {
    let mut dir = [1.0, 0.0];
    let mut left = s_m.max(0.0);
    for w in line.windows(2) {
        let len = dist(w[0], w[1]);
        if len <= 1e-9 {
            continue;
        }
        dir = [(w[1][0] - w[0][0]) / len, (w[1][1] - w[0][1]) / len];
        if left <= len {
            return ([w[0][0] + dir[0] * left, w[0][1] + dir[1] * left], dir);
        }
        left -= len;
    }
    (*line.last().unwrap_or(&[0.0, 0.0]), dir)
}

/// The plan's direction at each point: the chord over [`CHORD_M`] on either side
/// ([`CHORD_M`]'s docs); where the plan spans less than that on both sides, the central
/// difference over two steps, or where that stands (under [`MOVING_M`]) the last direction the
/// plan had, or none before it first moves.
fn plan_directions(plan: &[[f64; 2]]) -> Vec<Option<[f64; 2]>> {
    let n = plan.len();
    let unit = |a: [f64; 2], b: [f64; 2]| {
        let len = dist(a, b);
        (len >= MOVING_M).then(|| [(b[0] - a[0]) / len, (b[1] - a[1]) / len])
    };
    let mut out = Vec::with_capacity(n);
    let mut last = None;
    for k in 0..n {
        let p = plan[k];
        let behind = (0..k)
            .rev()
            .find(|&j| dist2(plan[j], p) >= CHORD_M * CHORD_M);
        let ahead = (k + 1..n).find(|&j| dist2(p, plan[j]) >= CHORD_M * CHORD_M);
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
mod tests;
