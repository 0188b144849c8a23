//! Traffic-light violation (§5 of the spec), reproducing the official code's two quirks: lanes
//! are zero-padded to the longest lane (a shorter lane gets one extra segment from its last
//! vertex to the origin), and the nearest-segment distance is `|(q − a) + clamp(t)(b − a)|`
//! (plus sign).

use std::collections::{BTreeMap, HashMap};
use std::ops::Range;

use scbg_scene::{LaneType, Map, Scene, SignalState};

use super::geometry::Point;
use super::{FIRST_FUTURE_STEP, SCENARIO_STEPS};

/// Segments per bounding box of the index.
const CHUNK_SEGMENTS: usize = 16;

#[derive(Debug, Clone, Copy)]
struct Segment {
    /// Start point.
    a: Point,
    /// `b − a` (b may be the (0, 0) padding point).
    d: Point,
    /// `|b − a|²`.
    len2: f32,
}

impl Segment {
    fn new(a: Point, b: Point) -> Self {
        let d = [b[0] - a[0], b[1] - a[1]];
        Self {
            a,
            d,
            len2: d[0] * d[0] + d[1] * d[1],
        }
    }

    /// `((q − a)·(b − a)) / |b − a|²`, 0 for a zero-length segment.
    fn project(&self, q: Point) -> f32 {
        if self.len2 > 0.0 {
            ((q[0] - self.a[0]) * self.d[0] + (q[1] - self.a[1]) * self.d[1]) / self.len2
        } else {
            0.0
        }
    }

    /// The official nearest-segment "distance" `|(q − a) + clamp(t, 0, 1)(b − a)|` (plus sign:
    /// the distance from `q` to a point of the segment reflected through `a`).
    fn quirk_distance(&self, q: Point) -> f32 {
        let t = self.project(q).clamp(0.0, 1.0);
        let vx = (q[0] - self.a[0]) + t * self.d[0];
        let vy = (q[1] - self.a[1]) + t * self.d[1];
        (vx * vx + vy * vy).sqrt()
    }
}

#[derive(Debug, Clone, Copy)]
struct Chunk {
    segments: (usize, usize),
    min: Point,
    max: Point,
}

impl Chunk {
    fn lower_bound(&self, q: Point) -> f32 {
        let dx = (self.min[0] - q[0]).max(q[0] - self.max[0]).max(0.0);
        let dy = (self.min[1] - q[1]).max(q[1] - self.max[1]).max(0.0);
        (dx * dx + dy * dy).sqrt()
    }
}

/// Surface-street lanes with their zero-padded segments, in (lane, segment) order.
#[derive(Debug, Clone)]
struct Lanes {
    ids: Vec<i64>,
    segments: Vec<Segment>,
    segment_lane: Vec<usize>,
    lane_segments: Vec<Range<usize>>,
    chunks: Vec<Chunk>,
}

impl Lanes {
    /// `None` without surface-street lanes of at least two points.
    fn new(map: &Map) -> Option<Self> {
        let lanes: Vec<(i64, Vec<Point>)> = map
            .lanes
            .iter()
            .filter(|l| l.lane_type == LaneType::SurfaceStreet && l.polyline.len() >= 2)
            .map(|l| {
                let points = l.polyline.iter().map(|p| [p.x_m as f32, p.y_m as f32]);
                (l.id, points.collect())
            })
            .collect();
        let max_points = lanes.iter().map(|(_, p)| p.len()).max()?;
        let mut out = Self {
            ids: Vec::with_capacity(lanes.len()),
            segments: Vec::new(),
            segment_lane: Vec::new(),
            lane_segments: Vec::with_capacity(lanes.len()),
            chunks: Vec::new(),
        };
        for (lane, (id, points)) in lanes.iter().enumerate() {
            let base = out.segments.len();
            for (k, &a) in points.iter().enumerate() {
                // A segment is kept when its start point is real; a lane shorter than the
                // longest one ends with a segment to the (0, 0) padding point.
                let b = match points.get(k + 1) {
                    Some(&b) => b,
                    None if points.len() < max_points => [0.0, 0.0],
                    None => break,
                };
                out.segments.push(Segment::new(a, b));
                out.segment_lane.push(lane);
            }
            let end = out.segments.len();
            for start in (base..end).step_by(CHUNK_SEGMENTS) {
                let stop = (start + CHUNK_SEGMENTS).min(end);
                let mut min = [f32::INFINITY; 2];
                let mut max = [f32::NEG_INFINITY; 2];
                // The quirk distance is measured to the segment reflected through `a`,
                // i.e. between `a` and `a − (b − a)`.
                for s in &out.segments[start..stop] {
                    for p in [s.a, [s.a[0] - s.d[0], s.a[1] - s.d[1]]] {
                        min = [min[0].min(p[0]), min[1].min(p[1])];
                        max = [max[0].max(p[0]), max[1].max(p[1])];
                    }
                }
                out.chunks.push(Chunk {
                    segments: (start, stop),
                    min,
                    max,
                });
            }
            out.ids.push(*id);
            out.lane_segments.push(base..end);
        }
        Some(out)
    }

    /// Nearest segment (quirk distance) among `range`, first on ties.
    fn nearest_in(&self, range: Range<usize>, q: Point, best: &mut (f32, usize)) {
        for s in range {
            let d = self.segments[s].quirk_distance(q);
            if d < best.0 || (d == best.0 && s < best.1) {
                *best = (d, s);
            }
        }
    }

    /// Nearest segment of one lane.
    fn nearest_in_lane(&self, lane: usize, q: Point) -> usize {
        // Starting from a real segment keeps a non-finite query (a NaN stop point) from
        // indexing out of range.
        let range = self.lane_segments[lane].clone();
        let mut best = (f32::INFINITY, range.start);
        self.nearest_in(range, q, &mut best);
        best.1
    }

    /// Lane of the nearest segment over all lanes (exactly as a full scan, first on ties).
    fn nearest_lane(&self, q: Point) -> usize {
        let bounds: Vec<f32> = self.chunks.iter().map(|c| c.lower_bound(q)).collect();
        let mut first = 0;
        for (k, &lb) in bounds.iter().enumerate() {
            if lb < bounds[first] {
                first = k;
            }
        }
        let (s0, s1) = self.chunks[first].segments;
        let mut best = (f32::INFINITY, s0);
        self.nearest_in(s0..s1, q, &mut best);
        for (k, c) in self.chunks.iter().enumerate() {
            if k != first && bounds[k] <= best.0 + 1e-3 + 1e-4 * best.0 {
                self.nearest_in(c.segments.0..c.segments.1, q, &mut best);
            }
        }
        self.segment_lane[best.1]
    }
}

/// One lane controlled by a signal that stops at some future step.
#[derive(Debug, Clone)]
struct ControlledLane {
    lane_id: i64,
    /// `[91]` whether the lane's signal is ARROW_STOP or STOP at the step.
    stops: Vec<bool>,
    /// `[91]` the lane segment nearest to the step's stop point ((0, 0) without a state).
    segment: Vec<Segment>,
    /// `[91]` projection of the stop point onto that segment's line.
    stop_tau: Vec<f32>,
}

/// The signalised surface-street lanes of a scene.
#[derive(Debug, Clone)]
pub(crate) struct TrafficLights {
    lanes: Option<Lanes>,
    controlled: Vec<ControlledLane>,
}

impl TrafficLights {
    /// Lanes of type SURFACE_STREET (≥ 2 points) and the signal states per step; without such
    /// lanes or without one signal entry per step there are no violations.
    pub fn new(scene: &Scene) -> Self {
        let none = Self {
            lanes: None,
            controlled: Vec::new(),
        };
        let Some(lanes) = Lanes::new(&scene.map) else {
            return none;
        };
        if scene.signals_per_step.len() != SCENARIO_STEPS {
            return none;
        }
        let mut lane_of_id = HashMap::new();
        for (k, &id) in lanes.ids.iter().enumerate() {
            lane_of_id.entry(id).or_insert(k);
        }
        let mut states: BTreeMap<usize, Vec<Option<(SignalState, Point)>>> = BTreeMap::new();
        for (t, step) in scene.signals_per_step.iter().enumerate() {
            for s in step {
                let Some(&lane) = lane_of_id.get(&s.lane_id) else {
                    continue;
                };
                // A missing stop point reads as the proto default (0, 0).
                let stop = s
                    .stop_point
                    .map_or([0.0, 0.0], |p| [p.x_m as f32, p.y_m as f32]);
                states
                    .entry(lane)
                    .or_insert_with(|| vec![None; SCENARIO_STEPS])[t] = Some((s.state, stop));
            }
        }
        let mut controlled = Vec::new();
        for (lane, steps) in states {
            let stops: Vec<bool> = steps
                .iter()
                .map(|s| matches!(s, Some((SignalState::ArrowStop | SignalState::Stop, _))))
                .collect();
            if !stops[FIRST_FUTURE_STEP..].contains(&true) {
                continue;
            }
            let mut segment = Vec::with_capacity(SCENARIO_STEPS);
            let mut stop_tau = Vec::with_capacity(SCENARIO_STEPS);
            for s in &steps {
                // A step without a state for this lane has its stop point at (0, 0).
                let stop = s.map_or([0.0, 0.0], |(_, p)| p);
                let seg = lanes.segments[lanes.nearest_in_lane(lane, stop)];
                segment.push(seg);
                stop_tau.push(seg.project(stop));
            }
            controlled.push(ControlledLane {
                lane_id: lanes.ids[lane],
                stops,
                segment,
                stop_tau,
            });
        }
        Self {
            lanes: Some(lanes),
            controlled,
        }
    }

    /// Violation flags of one object over the 80 future steps, from its 91-step centre
    /// series and validity.
    pub fn violations<'a>(
        &'a self,
        x: &'a [f32],
        y: &'a [f32],
        valid: &'a [bool],
    ) -> impl Iterator<Item = bool> + 'a {
        (FIRST_FUTURE_STEP..SCENARIO_STEPS).map(move |t| {
            let Some(lanes) = &self.lanes else {
                return false;
            };
            if !valid[t] {
                return false;
            }
            let before = [x[t - 1], y[t - 1]];
            let now = [x[t], y[t]];
            let mut current_lane = None;
            for c in &self.controlled {
                if !c.stops[t] {
                    continue;
                }
                let crossed = c.segment[t - 1].project(before) < c.stop_tau[t - 1]
                    && c.segment[t].project(now) > c.stop_tau[t];
                if !crossed {
                    continue;
                }
                let lane = *current_lane.get_or_insert_with(|| lanes.nearest_lane(now));
                if lanes.ids[lane] == c.lane_id {
                    return true;
                }
            }
            false
        })
    }
}
