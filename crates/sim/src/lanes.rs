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
//! change B can drive. A lane the map links on from the kept one (through a junction, into or
//! out of a roundabout) takes over without a ramp: the plan keeps to the road through the
//! joint, where a ramp left points between two lanes at an angle, off both.
//!
//! Once on a lane, a plan moves only along the map's lane graph: to a lane beside it (heading
//! within 45° of it) or one its route goes on to within [`ONWARD_LANES`]. A plan that turns
//! where the map has no lane for the turn (a junction of straight lanes) has left its lane and
//! goes on along it (below), rather than being kept on the crossing road's lane around the
//! corner it cuts. The plan starts on the lane under the agent ([`ON_LANE_M`]) heading the
//! agent's way where the caller knows it ([`LaneSegments::keep_near_from`]), else the plan's.
//!
//! A plan that leaves every lane heading its way after keeping to one (it cuts across a
//! roundabout's island, runs on past the end of an on-ramp, drifts off the outermost lane of
//! a highway: maps unlike the ones the generator learned on) goes on along that lane's route
//! instead, at the plan's own progress ([`LaneSegments::keep_near`]): timing is what courtesy is
//! about, and the road is where B can drive it.

use std::collections::HashMap;

use scbg_scene::{LaneType, Map};

use geometry::{dist, dist2, foot, plan_directions, point_at, polyline_length, project, unit};

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
/// A plan's first point lies on a lane whose centre line is within this (m): about half a
/// lane.
pub const ON_LANE_M: f64 = 1.5;
/// At a plan's first point, a lane within [`ON_LANE_M`] heading within 120° of the plan's way
/// (the cosine) is the lane the agent is on: a sampled plan may start with a sharp turn, but
/// not back along the road's other carriageway.
pub const START_ANGLE_COS: f64 = -0.5;
/// A plan on a lane may be kept to the lanes up to this many successors on (besides lanes
/// heading its lane's way): the connectors through a junction and the lanes after them.
pub const ONWARD_LANES: usize = 4;

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
        self.keep_near_from(plan, max_offset_m, None)
    }

    /// [`Self::keep_near`] for an agent heading `start_heading_rad` (world frame) where the
    /// plan starts: the plan starts on the lane under the agent that heads its way (within
    /// [`ON_LANE_M`] and 45°), whatever way the plan itself turns from there. A plan turning
    /// inside a junction, where the crossing road's lane also lies under the agent, then stays
    /// with the agent's lane.
    pub fn keep_near_from(
        &self,
        plan: &mut [[f64; 2]],
        max_offset_m: f64,
        start_heading_rad: Option<f64>,
    ) -> usize {
        let start_dir = start_heading_rad
            .filter(|h| h.is_finite())
            .map(|h| [h.cos(), h.sin()]);
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
        // The direction of the kept lane's segment at the previous point, and the lanes its
        // route may go on to (linked or joining at its end, transitively).
        let mut kept_dir: Option<[f64; 2]> = None;
        let mut onward: Vec<(usize, bool)> = Vec::new();
        let mut switches = Vec::new();
        // Where the plan leaves every lane after keeping to one: its route takes over there.
        let mut left_at: Option<(usize, usize)> = None;
        for (t, (p, heading)) in plan.iter().zip(heading).enumerate() {
            // The nearest point overall and on the lane the previous point was kept to, each
            // with its rank (the squared distance, but at the first point see `tier`).
            let (mut best, mut on_kept) = ((f64::INFINITY, None), (f64::INFINITY, None));
            for &&(a, b, lane, first, last) in &segments {
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let len2 = dx * dx + dy * dy;
                // Only lanes heading the plan's way count; at the plan's first point, also the
                // lane the agent is on (within [`ON_LANE_M`], not against the plan's way, see
                // [`START_ANGLE_COS`]): a plan that starts by turning where its lane goes
                // straight on starts on its lane, not on the crossing road's.
                let along_plan = heading.map(|h| (dx * h[0] + dy * h[1]) / len2.sqrt());
                let heads_along = along_plan.is_none_or(|c| c >= MAX_ANGLE_COS);
                let may_start_on = t == 0 && along_plan.is_some_and(|c| c > START_ANGLE_COS);
                let agent_along = t == 0
                    && start_dir
                        .is_some_and(|h| dx * h[0] + dy * h[1] >= MAX_ANGLE_COS * len2.sqrt());
                if !heads_along && !may_start_on && !agent_along {
                    continue;
                }
                // Once on a lane, the plan moves only along the map's lane graph: to a lane
                // beside its own (heading within 45° of it) or one its route goes on to. A
                // plan turning where the map has no lane for the turn (a junction without
                // turn lanes) is not kept on the crossing road's lane: it has left its lane
                // and goes on along its route.
                if let (Some(k), Some(d)) = (kept_lane, kept_dir)
                    && lane != k
                    && !onward.iter().any(|o| o.0 == lane)
                    && (dx * d[0] + dy * d[1]) < MAX_ANGLE_COS * len2.sqrt()
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
                let on_lane = d2 <= ON_LANE_M * ON_LANE_M;
                if d2 > REACH_M * REACH_M || (!heads_along && !on_lane) {
                    continue;
                }
                // At the first point: the lane under the agent heading the agent's way (when
                // known), then one under it heading the plan's way, then one under it heading
                // otherwise, then one within reach heading the plan's way.
                let tier = match (t, on_lane, agent_along, heads_along) {
                    (0, true, true, _) => 0.0,
                    (0, true, false, true) => 1.0,
                    (0, true, false, false) => 2.0,
                    (0, false, ..) => 3.0,
                    _ => 0.0,
                };
                let rank = d2 + tier * REACH_M * REACH_M;
                let dir = [dx / len, dy / len];
                if rank < best.0 {
                    best = (rank, Some((d2, q, lane, dir)));
                }
                // A point beyond either end of the kept lane has left it (for its successor).
                let beyond = (first && u <= 0.0) || (last && u >= 1.0);
                if Some(lane) == kept_lane && !beyond && d2 < on_kept.0 {
                    on_kept = (d2, Some((d2, q, lane, dir)));
                }
            }
            let chosen = match (best.1, on_kept.1) {
                (Some(b), Some(k)) if k.0.sqrt() <= b.0.sqrt() + SWITCH_MARGIN_M => Some(k),
                (b, _) => b,
            };
            if let (None, Some(lane)) = (chosen, kept_lane) {
                left_at = Some((t, lane));
                break;
            }
            if let Some((d2, q, lane, dir)) = chosen {
                // A lane change (to a lane beside) is ramped; a lane linked on from the kept
                // one (through a junction, into or out of a roundabout) is not: the plan keeps
                // to the road through the joint.
                if kept_lane.is_some_and(|k| k != lane) && !onward.contains(&(lane, true)) {
                    switches.push(t);
                }
                if kept_lane != Some(lane) {
                    onward = self.onward(lane);
                }
                kept_lane = Some(lane);
                kept_dir = Some(dir);
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

    /// The lane that continues `lane`, and where on it (segment, point): of its
    /// [`Self::successors`], the one whose centre line comes nearest `goal`.
    fn successor_toward(&self, lane: usize, goal: [f64; 2]) -> Option<(usize, usize, [f64; 2])> {
        self.successors(lane)
            .0
            .into_iter()
            .map(|(k, seg, q)| {
                let near = project(&self.centre_lines[k][seg..], goal)
                    .map_or(f64::INFINITY, |(_, g, ..)| dist(g, goal));
                (near, k, seg, q)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
            .map(|(_, k, seg, q)| (k, seg, q))
    }

    /// The lanes a route may take from `lane` within [`ONWARD_LANES`] successors
    /// ([`Self::successors`]), in the order found, each with whether it is reached through
    /// lanes linked or joining end to start alone (not a lane met side-on, which may be one
    /// running alongside).
    fn onward(&self, lane: usize) -> Vec<(usize, bool)> {
        let mut found = vec![(lane, true)];
        let mut from = 0;
        for _ in 0..ONWARD_LANES {
            let to = found.len();
            for k in from..to {
                let (at, joined) = found[k];
                let (next, side_on) = self.successors(at);
                for (n, ..) in next {
                    if !found.iter().any(|f| f.0 == n) {
                        found.push((n, joined && !side_on));
                    }
                }
            }
            from = to;
        }
        found.remove(0);
        found
    }

    /// The lanes that continue `lane`, and where on each (segment, point): the lanes linked as
    /// its exits and those starting within [`JOIN_M`] of its end heading its way, from their
    /// start; where there are none, the lanes passing within [`REACH_M`] of its end heading
    /// within [`JOIN_ANGLE_COS`] of its way (a roundabout's entry that meets the ring side-on),
    /// from their point nearest its end.
    fn successors(&self, lane: usize) -> (Vec<(usize, usize, [f64; 2])>, bool) {
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
            return (next, true);
        }
        (next, false)
    }
}

mod geometry;

#[cfg(test)]
mod tests;
