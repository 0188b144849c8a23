//! Signed distance to the road edge (§5 of the spec), with a bounding-box index that keeps the
//! exact "nearest segment, first on ties" selection of the official brute-force search.

use scbg_scene::Map;

use super::geometry::{Point, cross};

/// Weight of the z residual when selecting the nearest segment.
const Z_STRETCH: f32 = 3.0;
/// A polyline is cyclic when its first and last points are closer than this (squared, m²).
const CYCLIC_DISTANCE2_M2: f32 = 1.0;
/// Segments per bounding box of the index.
const CHUNK_SEGMENTS: usize = 16;
/// No predecessor / successor.
const NONE: usize = usize::MAX;

/// A run of consecutive segments with their xy bounding box.
#[derive(Debug, Clone, Copy)]
struct Chunk {
    start: usize,
    end: usize,
    min: Point,
    max: Point,
}

impl Chunk {
    /// Lower bound of the xy distance from `p` to any segment of the chunk.
    fn lower_bound(&self, p: [f32; 3]) -> f32 {
        let dx = (self.min[0] - p[0]).max(p[0] - self.max[0]).max(0.0);
        let dy = (self.min[1] - p[1]).max(p[1] - self.max[1]).max(0.0);
        (dx * dx + dy * dy).sqrt()
    }
}

/// The road-edge polylines of a map as flat segments (float32, 3-D).
#[derive(Debug, Clone)]
pub struct RoadEdges {
    /// Segment start points.
    start: Vec<[f32; 3]>,
    /// Segment vectors `b − a`.
    dir: Vec<[f32; 3]>,
    /// Squared xy length of each segment.
    len2: Vec<f32>,
    /// Predecessor segment (same polyline), or [`NONE`].
    pred: Vec<usize>,
    /// Successor segment (same polyline), or [`NONE`].
    succ: Vec<usize>,
    chunks: Vec<Chunk>,
}

/// Where a query point falls relative to one segment.
struct Residual {
    /// Unclamped projection parameter (0 for a zero-length segment).
    t: f32,
    /// `p − a − clamp(t, 0, 1)(b − a)`, 3-D.
    r: [f32; 3],
}

fn sign(v: f32) -> f32 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

impl RoadEdges {
    /// Every road-edge polyline with at least two points, in map order; `None` when there is
    /// none (the official code fails then).
    ///
    /// Official padding quirk: a cyclic polyline (first and last point closer than 1 m, 3-D)
    /// wraps around (last segment ↔ first segment) only if it is one of the longest road-edge
    /// polylines of the map; shorter cyclic polylines behave as open ones.
    pub fn new(map: &Map) -> Option<Self> {
        let polylines: Vec<Vec<[f32; 3]>> = map
            .road_edges
            .iter()
            .map(|e| {
                e.polyline
                    .iter()
                    .map(|p| [p.x_m as f32, p.y_m as f32, p.z_m as f32])
                    .collect::<Vec<_>>()
            })
            .filter(|p| p.len() >= 2)
            .collect();
        let max_points = polylines.iter().map(Vec::len).max()?;
        let mut edges = Self {
            start: Vec::new(),
            dir: Vec::new(),
            len2: Vec::new(),
            pred: Vec::new(),
            succ: Vec::new(),
            chunks: Vec::new(),
        };
        for points in &polylines {
            let n = points.len();
            let (first, last) = (points[0], points[n - 1]);
            let gap2 = (0..3)
                .map(|k| (first[k] - last[k]) * (first[k] - last[k]))
                .sum::<f32>();
            let wraps = gap2 < CYCLIC_DISTANCE2_M2 && n == max_points;
            let base = edges.start.len();
            let segments = n - 1;
            for (k, w) in points.windows(2).enumerate() {
                let (a, b) = (w[0], w[1]);
                let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                edges.start.push(a);
                edges.dir.push(d);
                edges.len2.push(d[0] * d[0] + d[1] * d[1]);
                edges.pred.push(match (k, wraps) {
                    (0, true) => base + segments - 1,
                    (0, false) => NONE,
                    _ => base + k - 1,
                });
                edges.succ.push(match (k + 1 == segments, wraps) {
                    (true, true) => base,
                    (true, false) => NONE,
                    _ => base + k + 1,
                });
            }
            for start in (base..base + segments).step_by(CHUNK_SEGMENTS) {
                let end = (start + CHUNK_SEGMENTS).min(base + segments);
                let mut min = [f32::INFINITY; 2];
                let mut max = [f32::NEG_INFINITY; 2];
                for p in &points[start - base..=end - base] {
                    min = [min[0].min(p[0]), min[1].min(p[1])];
                    max = [max[0].max(p[0]), max[1].max(p[1])];
                }
                edges.chunks.push(Chunk {
                    start,
                    end,
                    min,
                    max,
                });
            }
        }
        Some(edges)
    }

    fn residual(&self, s: usize, p: [f32; 3]) -> Residual {
        let a = self.start[s];
        let d = self.dir[s];
        let ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
        let t = if self.len2[s] > 0.0 {
            (ap[0] * d[0] + ap[1] * d[1]) / self.len2[s]
        } else {
            0.0
        };
        let tc = t.clamp(0.0, 1.0);
        Residual {
            t,
            r: [ap[0] - tc * d[0], ap[1] - tc * d[1], ap[2] - tc * d[2]],
        }
    }

    /// Distance used to select the nearest segment: `√(r_x² + r_y² + (3 r_z)²)`.
    fn selection_distance(&self, s: usize, p: [f32; 3]) -> f32 {
        let r = self.residual(s, p).r;
        let rz = r[2] * Z_STRETCH;
        (r[0] * r[0] + r[1] * r[1] + rz * rz).sqrt()
    }

    /// Side of `p` relative to segment `s`: +1 right (off-road), −1 left, 0 on the line.
    fn side(&self, s: usize, p: [f32; 3]) -> f32 {
        let a = self.start[s];
        let d = self.dir[s];
        sign(cross([p[0] - a[0], p[1] - a[1]], [d[0], d[1]]))
    }

    fn dir_xy(&self, s: usize) -> Point {
        [self.dir[s][0], self.dir[s][1]]
    }

    /// The index of the segment with the smallest selection distance (first on ties), exactly
    /// as a full scan finds it: chunks whose bounding box is farther than the best distance so
    /// far (plus a float margin) cannot hold a closer or tied segment.
    fn nearest_segment(&self, p: [f32; 3], scratch: &mut Vec<f32>) -> usize {
        scratch.clear();
        scratch.extend(self.chunks.iter().map(|c| c.lower_bound(p)));
        let mut first = 0;
        for (k, &lb) in scratch.iter().enumerate() {
            if lb < scratch[first] {
                first = k;
            }
        }
        let mut best = (f32::INFINITY, self.chunks[first].start);
        let visit = |c: &Chunk, best: &mut (f32, usize)| {
            for s in c.start..c.end {
                let d = self.selection_distance(s, p);
                if d < best.0 || (d == best.0 && s < best.1) {
                    *best = (d, s);
                }
            }
        };
        visit(&self.chunks[first], &mut best);
        for (k, c) in self.chunks.iter().enumerate() {
            if k != first && scratch[k] <= best.0 + 1e-3 + 1e-4 * best.0 {
                visit(c, &mut best);
            }
        }
        best.1
    }

    /// Signed 2-D distance from `p` (x, y, z) to the road edge: positive off-road.
    pub fn signed_distance(&self, p: [f32; 3], scratch: &mut Vec<f32>) -> f32 {
        let s = self.nearest_segment(p, scratch);
        let Residual { t, r } = self.residual(s, p);
        let n = self.side(s, p);
        let sign = if t < 0.0 && self.pred[s] != NONE {
            let q = self.pred[s];
            let nq = self.side(q, p);
            if cross(self.dir_xy(q), self.dir_xy(s)) > 0.0 {
                n.max(nq)
            } else {
                n.min(nq)
            }
        } else if t > 1.0 && self.succ[s] != NONE {
            let q = self.succ[s];
            let nq = self.side(q, p);
            if cross(self.dir_xy(s), self.dir_xy(q)) > 0.0 {
                n.max(nq)
            } else {
                n.min(nq)
            }
        } else {
            n
        };
        sign * (r[0] * r[0] + r[1] * r[1]).sqrt()
    }
}
