//! The target's lane path: the centreline of the lane the target drives in, chained forward
//! through the lanes that continue it, resampled at fixed arc lengths.
//!
//! Why: the conditioning future of another agent is given in the target's frame, a straight
//! frame. On a curved road the lane of a point 150 m ahead is off that frame's x axis by tens
//! of metres, so *which lane* the other agent drives in (stays in A's lane, leaves it, cuts
//! into it) is invisible in its x, y alone. Its offset from this path is what says so; the
//! model computes it from the path (`scbg_model`'s future encoder).
//!
//! The map gives no lane connectivity after preparation (polylines only), so continuation is
//! geometric: the lane polyline whose first point lies within [`CONTINUATION_M`] of the
//! current end, heading on within [`MAX_TURN_RAD`]: of those starting nearest the end (within
//! [`CONTINUATION_TIE_M`]), the straightest.

use crate::lane_move::LANE_MOVE_M;
use crate::prepared::{RoadKind, RoadPolyline};
use crate::road_index::{Scratch, SegmentIndex};

/// Points of the lane path.
pub const LANE_PATH_POINTS: usize = 80;
/// Arc length between consecutive points, metres.
pub const LANE_PATH_SPACING_M: f32 = 5.0;
/// Arc length of the first point behind the target's projection on the lane, metres (the
/// path covers `[-20 m, 375 m]` along the lane).
pub const LANE_PATH_BEHIND_M: f32 = 20.0;
/// The target must be this close to a lane centreline for a path, metres.
const MAX_OFFSET_M: f32 = 4.0;
/// The lane's direction at the target must be within this of the target's heading.
const MAX_HEADING_RAD: f32 = std::f32::consts::FRAC_PI_4;
/// A continuing lane starts within this of the current end, metres.
const CONTINUATION_M: f32 = 5.0;
/// A continuing lane's first direction is within this of the current end's direction.
const MAX_TURN_RAD: f32 = std::f32::consts::FRAC_PI_6;
/// Lanes starting at most this much farther from the current end than the nearest start are
/// equally its continuation (a split), metres; a neighbour's next lane starts a lane width away.
const CONTINUATION_TIE_M: f32 = 1.0;

/// Arc length of lane path point `k` from the target's projection on its lane, metres.
pub fn lane_path_arc_m(k: usize) -> f32 {
    k as f32 * LANE_PATH_SPACING_M - LANE_PATH_BEHIND_M
}

fn is_vehicle_lane(kind: RoadKind) -> bool {
    kind.is_lane() && kind != RoadKind::LaneBike
}

fn sub(a: [f32; 2], b: [f32; 2]) -> [f32; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn norm(a: [f32; 2]) -> f32 {
    (a[0] * a[0] + a[1] * a[1]).sqrt()
}

fn angle_between(a: [f32; 2], b: [f32; 2]) -> f32 {
    let cross = a[0] * b[1] - a[1] * b[0];
    let dot = a[0] * b[0] + a[1] * b[1];
    cross.atan2(dot).abs()
}

/// Candidate segments asked of the grid per target (the nearest few within reach).
const CANDIDATES: usize = 16;

/// A scene's vehicle lanes, made once per scene: each lane's points with their arc lengths,
/// its continuation, and a grid over the lane segments (the target's lane is found among the
/// few segments near it, not by scanning the map: real scenes have thousands).
#[derive(Debug, Clone)]
pub(crate) struct LaneNetwork {
    /// Per lane: its points (scene frame) and the arc length at each.
    points: Vec<Vec<[f32; 2]>>,
    arc_m: Vec<Vec<f32>>,
    /// Per lane: the lane that continues it, if any.
    next: Vec<Option<usize>>,
    /// Lane segments in lane order (segment `i` of the grid is `segment_of[i]`).
    grid: SegmentIndex,
    segment_of: Vec<(u32, u32)>,
    /// Per lane point, once asked: the lanes beside it, `[left, right]`
    /// ([`LaneNetwork::beside`]). Paths of a scene's targets share their lanes.
    beside: Vec<Vec<Option<[bool; 2]>>>,
}

impl LaneNetwork {
    /// The network of `road`'s vehicle lanes (bike lanes and one-point lanes left out).
    pub(crate) fn new(road: &[RoadPolyline]) -> Self {
        let lanes: Vec<&RoadPolyline> = road
            .iter()
            .filter(|p| is_vehicle_lane(p.kind) && p.xy_m.len() >= 2)
            .collect();
        let points: Vec<Vec<[f32; 2]>> = lanes.iter().map(|p| p.xy_m.clone()).collect();
        let arc_m: Vec<Vec<f32>> = points
            .iter()
            .map(|pts| {
                let mut at = 0.0;
                std::iter::once(0.0)
                    .chain(pts.windows(2).map(|w| {
                        at += norm(sub(w[1], w[0]));
                        at
                    }))
                    .collect()
            })
            .collect();
        // Continuations through a hash of lane starts by cell (CONTINUATION_M wide): each
        // lane end looks at the 3 × 3 cells around it.
        let cell = |p: [f32; 2]| {
            (
                (p[0] / CONTINUATION_M).floor() as i64,
                (p[1] / CONTINUATION_M).floor() as i64,
            )
        };
        let mut starts: std::collections::HashMap<(i64, i64), Vec<usize>> = Default::default();
        for (i, pts) in points.iter().enumerate() {
            if pts[0].iter().all(|v| v.is_finite()) {
                starts.entry(cell(pts[0])).or_default().push(i);
            }
        }
        let next = points
            .iter()
            .enumerate()
            .map(|(i, pts)| {
                let n = pts.len();
                let (end, end_dir) = (pts[n - 1], sub(pts[n - 1], pts[n - 2]));
                if !end.iter().all(|v| v.is_finite()) {
                    return None;
                }
                let (cx, cy) = cell(end);
                // `(gap, turn, lane)` of every lane that may continue this one.
                let mut candidates: Vec<(f32, f32, usize)> = Vec::new();
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        for &j in starts.get(&(cx + dx, cy + dy)).into_iter().flatten() {
                            let q = &points[j];
                            let gap = norm(sub(q[0], end));
                            let turn = angle_between(end_dir, sub(q[1], q[0]));
                            if j != i && gap <= CONTINUATION_M && turn <= MAX_TURN_RAD {
                                candidates.push((gap, turn, j));
                            }
                        }
                    }
                }
                // The lanes that start where this one ends, the straightest first: on a curve
                // the next lane of a neighbour (a lane width away) can be straighter.
                let nearest = candidates.iter().map(|c| c.0).fold(f32::INFINITY, f32::min);
                candidates
                    .iter()
                    .filter(|c| c.0 <= nearest + CONTINUATION_TIE_M)
                    .min_by(|a, b| (a.1, a.2).partial_cmp(&(b.1, b.2)).expect("finite"))
                    .map(|c| c.2)
            })
            .collect();
        let owned: Vec<RoadPolyline> = lanes.into_iter().cloned().collect();
        let segment_of = points
            .iter()
            .enumerate()
            .flat_map(|(l, pts)| (0..pts.len() - 1).map(move |s| (l as u32, s as u32)))
            .collect();
        Self {
            beside: points.iter().map(|p| vec![None; p.len()]).collect(),
            points,
            arc_m,
            next,
            grid: SegmentIndex::from_road(&owned),
            segment_of,
        }
    }

    /// The lane path of a target at `xy` (scene frame) heading `heading_rad`; see
    /// [`lane_path`]. `scratch` and `found` are the grid query's buffers.
    pub(crate) fn path(
        &self,
        xy: [f32; 2],
        heading_rad: f32,
        scratch: &mut Scratch,
        found: &mut Vec<(u32, f32)>,
    ) -> Option<ScenePath> {
        let dir = [heading_rad.cos(), heading_rad.sin()];
        // The grid ranks by the closest point but admits by the nearer endpoint: ask a reach
        // of a segment length beyond the offset limit, then check the distance itself.
        self.grid
            .closest(xy, CANDIDATES, MAX_OFFSET_M + 10.0, scratch, found);
        let (lane, seg, u) = found.iter().find_map(|&(i, d2)| {
            let (lane, seg) = self.segment_of[i as usize];
            let (lane, seg) = (lane as usize, seg as usize);
            let (a, b) = (self.points[lane][seg], self.points[lane][seg + 1]);
            let d = sub(b, a);
            let len2 = d[0] * d[0] + d[1] * d[1];
            if d2 > MAX_OFFSET_M * MAX_OFFSET_M
                || len2 < 1e-6
                || angle_between(d, dir) > MAX_HEADING_RAD
            {
                return None;
            }
            let r = sub(xy, a);
            Some((
                lane,
                seg,
                ((r[0] * d[0] + r[1] * d[1]) / len2).clamp(0.0, 1.0),
            ))
        })?;
        let arc = &self.arc_m[lane];
        let s0 = arc[seg] + u * (arc[seg + 1] - arc[seg]);
        // Walk the chain of lanes once: `(lane, arc length of its first point on the chain)`.
        let mut chain = vec![(lane, 0.0f32)];
        let mut end = *arc.last().expect("two points");
        let (mut points, mut valid, mut nearest) = (
            Vec::with_capacity(LANE_PATH_POINTS),
            Vec::with_capacity(LANE_PATH_POINTS),
            Vec::with_capacity(LANE_PATH_POINTS),
        );
        let (mut c, mut k) = (0usize, 0usize);
        for i in 0..LANE_PATH_POINTS {
            let s = s0 + lane_path_arc_m(i);
            // Extend the chain while it ends before s.
            while s > end && chain.len() < 32 {
                let (last, _) = *chain.last().expect("non-empty");
                match self.next[last] {
                    Some(n) if !chain.iter().any(|&(l, _)| l == n) => {
                        // A continuation starts where its predecessor ends (within 5 m).
                        chain.push((n, end));
                        end += *self.arc_m[n].last().expect("two points");
                    }
                    _ => break,
                }
            }
            // Move to the lane and segment holding s (or stay at the ends, extrapolating).
            while c + 1 < chain.len() && s > chain[c + 1].1 {
                c += 1;
                k = 0;
            }
            let (l, base) = chain[c];
            let (pts, arc) = (&self.points[l], &self.arc_m[l]);
            while k + 2 < pts.len() && s - base > arc[k + 1] {
                k += 1;
            }
            let len = (arc[k + 1] - arc[k]).max(1e-6);
            let f = (s - base - arc[k]) / len;
            let d = sub(pts[k + 1], pts[k]);
            points.push([pts[k][0] + f * d[0], pts[k][1] + f * d[1]]);
            valid.push(s >= 0.0 && s <= end);
            nearest.push((l as u32, (k + usize::from(f > 0.5)) as u32));
        }
        Some(ScenePath {
            points,
            valid,
            nearest,
        })
    }

    /// Per point of `path`: whether a vehicle lane heading its way passes a lane's width
    /// ([`LANE_MOVE_M`]) to its `[left, right]`, within [`NEIGHBOUR_TOLERANCE_M`] (lanes
    /// 2.0–5.0 m apart count: every lane width in use) and [`MAX_TURN_RAD`]; asked at the lane
    /// point nearest it. What a lane move needs to end on a lane, not on a gore, a shoulder or
    /// the verge.
    pub(crate) fn beside(&mut self, path: &ScenePath) -> Vec<[bool; 2]> {
        path.nearest
            .iter()
            .enumerate()
            .map(|(i, &(lane, k))| {
                // Behind the target or past the lanes' ends: no lane move ends there.
                if !path.valid[i] || lane_path_arc_m(i) < 0.0 {
                    return [false, false];
                }
                let (lane, k) = (lane as usize, k as usize);
                if let Some(b) = self.beside[lane][k] {
                    return b;
                }
                let pts = &self.points[lane];
                let d = sub(pts[(k + 1).min(pts.len() - 1)], pts[k.saturating_sub(1)]);
                let len = norm(d);
                let b = if len < 1e-6 {
                    [false, false]
                } else {
                    let (dir, left) = ([d[0] / len, d[1] / len], [-d[1] / len, d[0] / len]);
                    [1.0f32, -1.0].map(|side| {
                        let at = [
                            pts[k][0] + side * LANE_MOVE_M * left[0],
                            pts[k][1] + side * LANE_MOVE_M * left[1],
                        ];
                        self.grid.any_within(at, NEIGHBOUR_TOLERANCE_M, |a, b| {
                            let e = sub(b, a);
                            norm(e) > 1e-6 && angle_between(e, dir) <= MAX_TURN_RAD
                        })
                    })
                };
                self.beside[lane][k] = Some(b);
                b
            })
            .collect()
    }
}

/// A neighbour lane's centre lies within this of a lane's width beside the path, metres.
const NEIGHBOUR_TOLERANCE_M: f32 = 1.5;

/// A lane path in the scene frame ([`LaneNetwork::path`]).
pub(crate) struct ScenePath {
    /// `[LANE_PATH_POINTS]` points.
    pub(crate) points: Vec<[f32; 2]>,
    /// Whether each lies on a known lane.
    pub(crate) valid: Vec<bool>,
    /// The lane point nearest each, `(lane, point)`.
    nearest: Vec<(u32, u32)>,
}

/// The lane path of a target at `xy` (scene frame) heading `heading_rad`: `LANE_PATH_POINTS`
/// points in the scene frame at arc lengths [`lane_path_arc_m`] and whether each lies on a
/// known lane (points past the chain's ends are not). `None` when no vehicle lane passes
/// within 4 m of the target in its direction (off-road, parking lots, maps without lanes).
/// (Samples get theirs from the [`SampleBuilder`](crate::SampleBuilder), which builds the
/// scene's lane network once.)
pub fn lane_path(
    road: &[RoadPolyline],
    xy: [f32; 2],
    heading_rad: f32,
) -> Option<(Vec<[f32; 2]>, Vec<bool>)> {
    LaneNetwork::new(road)
        .path(xy, heading_rad, &mut Scratch::default(), &mut Vec::new())
        .map(|p| (p.points, p.valid))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lane(points: Vec<[f32; 2]>) -> RoadPolyline {
        RoadPolyline {
            kind: RoadKind::LaneSurfaceStreet,
            xy_m: points,
        }
    }

    #[test]
    fn the_path_follows_the_lane_and_its_continuation_not_the_branch() {
        // A straight lane to x = 100, then a straight continuation and a branch turning left.
        let road = vec![
            lane((0..=25).map(|i| [4.0 * i as f32, 0.0]).collect()),
            // The branch: first direction 40° off (beyond the 30° continuation limit).
            lane(
                (0..=50)
                    .map(|i| [100.0 + 3.0 * i as f32, 2.5 * i as f32])
                    .collect(),
            ),
            lane((0..=100).map(|i| [100.0 + 4.0 * i as f32, 0.0]).collect()),
            // A lane the other way, nearer than the first: not the target's.
            lane((0..=25).map(|i| [100.0 - 4.0 * i as f32, 1.0]).collect()),
            RoadPolyline {
                kind: RoadKind::EdgeBoundary,
                xy_m: vec![[0.0, 0.5], [500.0, 0.5]],
            },
        ];
        let (pts, valid) = lane_path(&road, [30.0, 1.5], 0.05).expect("a path");
        assert_eq!(pts.len(), LANE_PATH_POINTS);
        for (k, (p, v)) in pts.iter().zip(&valid).enumerate() {
            let s = 30.0 + lane_path_arc_m(k);
            assert!(
                (p[0] - s).abs() < 1e-3 && p[1].abs() < 1e-3,
                "point {k}: {p:?}"
            );
            assert_eq!(*v, (0.0..=500.0).contains(&s), "point {k}");
        }
        // Facing the other way the target is on the opposite lane.
        let (pts, _) = lane_path(&road, [30.0, 1.5], std::f32::consts::PI).expect("a path");
        assert!((pts[4][0] - 30.0).abs() < 1e-3 && (pts[4][1] - 1.0).abs() < 1e-3);
        // Off every lane: no path.
        assert!(lane_path(&road, [30.0, 9.0], 0.0).is_none());
    }

    #[test]
    fn on_a_two_lane_ring_the_path_keeps_its_lane_across_the_lane_ends() {
        // A ring of two lanes (radii 20 and 24 m) in eight arcs each, points every ~2 m as
        // highway-env samples them: the outer lane's next arc, 4 m away, turns less per point.
        let arc = |radius: f32, from: usize| {
            let n = (radius * std::f32::consts::FRAC_PI_4 / 2.0).ceil() as usize;
            lane(
                (0..=n)
                    .map(|i| {
                        let a = (from as f32 + i as f32 / n as f32) * std::f32::consts::FRAC_PI_4;
                        [radius * a.cos(), radius * a.sin()]
                    })
                    .collect(),
            )
        };
        let road: Vec<RoadPolyline> = (0..8).flat_map(|k| [arc(20.0, k), arc(24.0, k)]).collect();
        for (radius, at) in [(20.0f32, 0.3f32), (24.0, 2.6)] {
            let (pts, valid) = lane_path(
                &road,
                [radius * at.cos(), radius * at.sin()],
                at + std::f32::consts::FRAC_PI_2,
            )
            .expect("a path");
            for (k, (p, _)) in pts.iter().zip(&valid).enumerate().filter(|(_, (_, v))| **v) {
                let r = (p[0] * p[0] + p[1] * p[1]).sqrt();
                assert!(
                    (r - radius).abs() < 0.2,
                    "radius {radius}, point {k}: r = {r}"
                );
            }
        }
    }
}
