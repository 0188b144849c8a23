//! The P road segments closest to a point: a uniform grid over the scene's segments, its cells
//! visited nearest first.
//!
//! A scene has thousands of road segments and every sample needs its 128 closest; scanning all of
//! them per sample was the largest cost of feature building (docs/findings.md, *Speed work that
//! changed no number*). The grid visits only the cells that can still hold a closer segment than
//! the P-th found so far.
//!
//! **Exactness.** The result is the same set in the same order as [`closest_brute_force`]:
//! segments whose nearer endpoint is within the radius, ranked by the distance of their closest
//! point (`total_cmp`, ties by index), the first P. A segment is listed in every cell its
//! bounding box meets, so its closest point to the query lies in one of the listed cells; a cell
//! (dx, dy) cells away from the query's cell holds no point closer than
//! `|(max(|dx|−1, 0), max(|dy|−1, 0))| · cell` (minus a rounding margin). Cells are visited in
//! the order of that bound and the search stops when it exceeds the P-th distance found (or
//! the radius). Segments with a non-finite end are checked for every query.

use crate::prepared::{RoadKind, RoadPolyline};

/// Rounding margin of the cell bounds, metres (coordinates are f32 within a few km).
const MARGIN_M: f32 = 0.05;
/// Grid side, metres, unless the scene is so large that the grid would exceed `MAX_CELLS_PER_AXIS`.
const CELL_M: f32 = 10.0;
const MAX_CELLS_PER_AXIS: usize = 512;

/// Road segments `a`–`b` (scene frame, metres) and their kinds, with a grid over them.
#[derive(Debug, Clone)]
pub(crate) struct SegmentIndex {
    seg_a: Vec<[f32; 2]>,
    seg_b: Vec<[f32; 2]>,
    kind: Vec<RoadKind>,
    /// Segments with a non-finite end: checked for every query.
    unplaced: Vec<u32>,
    min_xy: [f32; 2],
    cell_m: f32,
    nx: usize,
    ny: usize,
    /// CSR: the segments whose bounding box meets cell `c` are
    /// `cell_segments[cell_start[c]..cell_start[c + 1]]`, each with its ends (the query reads
    /// a cell's segments in one sweep instead of looking each one up).
    cell_start: Vec<u32>,
    cell_segments: Vec<Listed>,
}

/// A segment as listed in a grid cell.
#[derive(Debug, Clone, Copy)]
struct Listed {
    a: [f32; 2],
    b: [f32; 2],
    /// The segment's index, with [`MULTI_CELL`] set when it is listed in more than one cell
    /// (only those can be met twice in a query).
    index: u32,
}

/// The flag of [`Listed::index`] for a segment listed in several cells.
const MULTI_CELL: u32 = 1 << 31;

impl Listed {
    fn segment(&self) -> u32 {
        self.index & !MULTI_CELL
    }
}

/// A candidate: squared distance of its closest point, then index (the ranking order), packed
/// in one `u64` so that selection and sorting compare integers: the high half is the distance's
/// bits mapped to the order of `f32::total_cmp`, the low half the index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct Key(u64);

impl Key {
    fn new(dist2: f32, index: u32) -> Self {
        Self((u64::from(total_order_bits(dist2)) << 32) | u64::from(index))
    }

    fn dist2(self) -> f32 {
        f32_from_total_order_bits((self.0 >> 32) as u32)
    }

    fn index(self) -> u32 {
        self.0 as u32
    }
}

/// `x`'s bits, mapped so that unsigned comparison is `f32::total_cmp`.
pub(crate) fn total_order_bits(x: f32) -> u32 {
    let b = x.to_bits();
    if b >> 31 == 1 { !b } else { b | 0x8000_0000 }
}

fn f32_from_total_order_bits(t: u32) -> f32 {
    f32::from_bits(if t >> 31 == 1 { t & 0x7fff_ffff } else { !t })
}

/// Scratch space reused between queries.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    found: Vec<Key>,
    /// `seen[i] == query` when segment i was already offered in this query (a segment is
    /// listed in every cell its bounding box meets).
    seen: Vec<u32>,
    query: u32,
    /// Cell offsets `(dx, dy, lower bound², metres²)` sorted by bound, for `offsets_for`.
    offsets: Vec<(i32, i32, f32)>,
    /// (cell size, reach) the offsets were made for.
    offsets_for: Option<(u32, u32)>,
}

impl Scratch {
    /// Every cell offset whose cells can hold a point within `reach_m` of a query, in order of
    /// the smallest distance a segment there can have from a query in cell (0, 0).
    fn offsets(&mut self, cell_m: f32, reach_m: f32) -> &[(i32, i32, f32)] {
        let key = (cell_m.to_bits(), reach_m.to_bits());
        if self.offsets_for != Some(key) {
            let k = ((reach_m / cell_m).ceil() as i32 + 2).clamp(1, MAX_CELLS_PER_AXIS as i32 + 2);
            self.offsets.clear();
            for dy in -k..=k {
                for dx in -k..=k {
                    let gap = |d: i32| (d.abs() - 1).max(0) as f32 * cell_m;
                    let (gx, gy) = (gap(dx), gap(dy));
                    // Every point of a cell (dx, dy) away is at least the gap from the query.
                    let lb = ((gx * gx + gy * gy).sqrt() - MARGIN_M).max(0.0);
                    if lb < reach_m {
                        self.offsets.push((dx, dy, lb * lb));
                    }
                }
            }
            self.offsets.sort_by(|a, b| a.2.total_cmp(&b.2));
            self.offsets_for = Some(key);
        }
        &self.offsets
    }
}

impl SegmentIndex {
    /// The segments of a scene's road polylines, in order (a one-point polyline is a
    /// zero-length segment).
    pub(crate) fn from_road(road: &[RoadPolyline]) -> Self {
        let n: usize = road
            .iter()
            .map(|p| p.xy_m.len().saturating_sub(1).max(1))
            .sum();
        let (mut seg_a, mut seg_b, mut kind) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for poly in road {
            let pts = &poly.xy_m;
            if pts.len() == 1 {
                seg_a.push(pts[0]);
                seg_b.push(pts[0]);
                kind.push(poly.kind);
            }
            for w in pts.windows(2) {
                seg_a.push(w[0]);
                seg_b.push(w[1]);
                kind.push(poly.kind);
            }
        }
        Self::new(seg_a, seg_b, kind)
    }

    /// An index over the segments `seg_a[i]`–`seg_b[i]` of kinds `kind[i]`.
    fn new(seg_a: Vec<[f32; 2]>, seg_b: Vec<[f32; 2]>, kind: Vec<RoadKind>) -> Self {
        // (2³¹ segments would be tens of GB of map; the index's top bit is a flag.)
        debug_assert!(seg_a.len() < MULTI_CELL as usize);
        let finite = |i: usize| seg_a[i].iter().chain(&seg_b[i]).all(|v| v.is_finite());
        let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        for i in (0..seg_a.len()).filter(|&i| finite(i)) {
            for d in 0..2 {
                lo[d] = lo[d].min(seg_a[i][d]).min(seg_b[i][d]);
                hi[d] = hi[d].max(seg_a[i][d]).max(seg_b[i][d]);
            }
        }
        if lo[0] > hi[0] || lo[1] > hi[1] {
            (lo, hi) = ([0.0; 2], [0.0; 2]);
        }
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let cell_m = CELL_M.max(extent / (MAX_CELLS_PER_AXIS - 1) as f32);
        let cells = |d: usize| ((hi[d] - lo[d]) / cell_m) as usize + 1;
        let (nx, ny) = (cells(0), cells(1));
        // The cells of segment i's bounding box, as (x0..=x1, y0..=y1).
        let bbox = |i: usize| {
            let (a, b) = (seg_a[i], seg_b[i]);
            let c = |v: f32, d: usize, n: usize| (((v - lo[d]) / cell_m) as usize).min(n - 1);
            (
                c(a[0].min(b[0]), 0, nx)..=c(a[0].max(b[0]), 0, nx),
                c(a[1].min(b[1]), 1, ny)..=c(a[1].max(b[1]), 1, ny),
            )
        };
        let mut unplaced = Vec::new();
        let mut counts = vec![0u32; nx * ny + 1];
        for i in 0..seg_a.len() {
            if !finite(i) {
                unplaced.push(i as u32);
                continue;
            }
            let (xs, ys) = bbox(i);
            for y in ys {
                for x in xs.clone() {
                    counts[y * nx + x + 1] += 1;
                }
            }
        }
        for c in 0..nx * ny {
            counts[c + 1] += counts[c];
        }
        let cell_start = counts;
        let mut fill = cell_start.clone();
        let mut cell_segments = vec![
            Listed {
                a: [0.0; 2],
                b: [0.0; 2],
                index: 0
            };
            cell_start[nx * ny] as usize
        ];
        for i in (0..seg_a.len()).filter(|&i| finite(i)) {
            let (xs, ys) = bbox(i);
            let multi = if xs.clone().count() * ys.clone().count() > 1 {
                MULTI_CELL
            } else {
                0
            };
            for y in ys {
                for x in xs.clone() {
                    let slot = &mut fill[y * nx + x];
                    cell_segments[*slot as usize] = Listed {
                        a: seg_a[i],
                        b: seg_b[i],
                        index: i as u32 | multi,
                    };
                    *slot += 1;
                }
            }
        }
        Self {
            seg_a,
            seg_b,
            kind,
            unplaced,
            min_xy: lo,
            cell_m,
            nx,
            ny,
            cell_start,
            cell_segments,
        }
    }

    pub(crate) fn seg_a(&self, i: usize) -> [f32; 2] {
        self.seg_a[i]
    }

    pub(crate) fn seg_b(&self, i: usize) -> [f32; 2] {
        self.seg_b[i]
    }

    pub(crate) fn kind(&self, i: usize) -> RoadKind {
        self.kind[i]
    }

    /// Segment `i` as a candidate: `Some(key)` when its nearer endpoint is within the radius.
    #[inline]
    fn candidate(&self, i: u32, origin: [f32; 2], r2: f32) -> Option<Key> {
        candidate(
            self.seg_a[i as usize],
            self.seg_b[i as usize],
            i,
            origin,
            r2,
        )
    }

    /// The segments listed in grid cell `(x, y)` (none outside the grid).
    fn cell(&self, x: i64, y: i64) -> &[Listed] {
        if !((0..self.nx as i64).contains(&x) && (0..self.ny as i64).contains(&y)) {
            return &[];
        }
        let c = y as usize * self.nx + x as usize;
        &self.cell_segments[self.cell_start[c] as usize..self.cell_start[c + 1] as usize]
    }

    /// The at most `p` segments closest to `origin` whose nearer endpoint is within
    /// `radius_m`, closest first, as `(index, squared distance of the closest point)`.
    ///
    /// Cells are visited in order of the least distance a segment in them can have; once `p`
    /// candidates are found, the p-th distance bounds which further cells and candidates count.
    pub(crate) fn closest(
        &self,
        origin: [f32; 2],
        p: usize,
        radius_m: f32,
        scratch: &mut Scratch,
        out: &mut Vec<(u32, f32)>,
    ) {
        out.clear();
        if p == 0 {
            return;
        }
        let r2 = radius_m * radius_m;
        let mut found = std::mem::take(&mut scratch.found);
        found.clear();
        found.extend(
            self.unplaced
                .iter()
                .filter_map(|&i| self.candidate(i, origin, r2)),
        );
        let mut seen = std::mem::take(&mut scratch.seen);
        if seen.len() != self.seg_a.len() || scratch.query == u32::MAX {
            seen.clear();
            seen.resize(self.seg_a.len(), 0);
            scratch.query = 0;
        }
        scratch.query += 1;
        let query = scratch.query;
        let mut fresh = |i: u32| {
            let s = &mut seen[i as usize];
            let new = *s != query;
            *s = query;
            new
        };
        let cell = |d: usize| ((origin[d] - self.min_xy[d]) / self.cell_m).floor();
        let (cx, cy) = (cell(0), cell(1));
        if !(cx.is_finite() && cy.is_finite() && radius_m.is_finite()) {
            // A non-finite origin or radius: every segment, as the brute force would.
            found.extend(
                self.cell_segments
                    .iter()
                    .filter(|l| fresh(l.segment()))
                    .filter_map(|l| candidate(l.a, l.b, l.segment(), origin, r2)),
            );
        } else {
            // A query outside the grid is moved to the cell just outside it: its offsets'
            // bounds only shrink (still lower bounds), and every grid cell within reach stays
            // within reach.
            let (nx, ny) = (self.nx as i64, self.ny as i64);
            let (cx, cy) = ((cx as i64).clamp(-1, nx), (cy as i64).clamp(-1, ny));
            // The p-th smallest key found so far: only keys up to it can still be among the
            // first p. Without one yet, everything within the radius may count.
            let mut bound = Key(u64::MAX);
            let mut bounded_at = 0;
            for &(dx, dy, lb2) in scratch.offsets(self.cell_m, radius_m) {
                if lb2 >= r2 || Key::new(lb2, 0) > bound {
                    break;
                }
                let (x, y) = (cx + i64::from(dx), cy + i64::from(dy));
                let segments = self.cell(x, y);
                if segments.is_empty() {
                    continue;
                }
                // This cell's own bound from the query point (tighter than the offset's, which
                // holds for any query in the cell), minus the rounding margin.
                if bound.0 != u64::MAX {
                    let gap = |q: f32, lo: f32| (lo - q).max(q - (lo + self.cell_m)).max(0.0);
                    let gx = gap(origin[0], self.min_xy[0] + x as f32 * self.cell_m);
                    let gy = gap(origin[1], self.min_xy[1] + y as f32 * self.cell_m);
                    let lb = ((gx * gx + gy * gy).sqrt() - MARGIN_M).max(0.0);
                    if Key::new(lb * lb, 0) > bound {
                        continue;
                    }
                }
                // Only segments listed in several cells can have been met before.
                found.extend(
                    segments
                        .iter()
                        .filter(|l| l.index & MULTI_CELL == 0 || fresh(l.segment()))
                        .filter_map(|l| candidate(l.a, l.b, l.segment(), origin, r2))
                        .filter(|&k| k <= bound),
                );
                // Tighten the bound each time the candidates have doubled since the last time.
                if found.len() >= p && found.len() >= 2 * bounded_at {
                    let (_, kth, _) = found.select_nth_unstable(p - 1);
                    bound = *kth;
                    bounded_at = found.len();
                }
            }
        }
        if found.len() > p {
            found.select_nth_unstable(p - 1);
            found.truncate(p);
        }
        found.sort_unstable();
        out.extend(found.iter().map(|k| (k.index(), k.dist2())));
        scratch.found = found;
        scratch.seen = seen;
    }

    /// Whether a segment passes within `radius_m` of `origin` (its closest point) for which
    /// `accept(a, b)` holds. A segment is listed in every cell its bounding box meets, so the
    /// cell holding its closest point is among those the square around `origin` meets; the
    /// search stops at the first accepted segment. Segments with a non-finite end are never
    /// within reach.
    pub(crate) fn any_within(
        &self,
        origin: [f32; 2],
        radius_m: f32,
        accept: impl Fn([f32; 2], [f32; 2]) -> bool,
    ) -> bool {
        let r2 = radius_m * radius_m;
        let cell = |v: f32, d: usize| ((v - self.min_xy[d]) / self.cell_m).floor();
        let (x0, x1) = (cell(origin[0] - radius_m, 0), cell(origin[0] + radius_m, 0));
        let (y0, y1) = (cell(origin[1] - radius_m, 1), cell(origin[1] + radius_m, 1));
        if ![x0, x1, y0, y1].iter().all(|v| v.is_finite()) {
            return false;
        }
        let clamp = |v: f32, n: usize| (v as i64).clamp(-1, n as i64);
        for y in clamp(y0, self.ny)..=clamp(y1, self.ny) {
            for x in clamp(x0, self.nx)..=clamp(x1, self.nx) {
                let hit = self.cell(x, y).iter().any(|l| {
                    let q = closest_point_to_origin(
                        [l.a[0] - origin[0], l.a[1] - origin[1]],
                        [l.b[0] - origin[0], l.b[1] - origin[1]],
                    );
                    q[0] * q[0] + q[1] * q[1] <= r2 && accept(l.a, l.b)
                });
                if hit {
                    return true;
                }
            }
        }
        false
    }
}

/// Segment `a`–`b` (index `i`) as a candidate: `Some(key)` when its nearer endpoint is within
/// the radius.
#[inline]
fn candidate(a: [f32; 2], b: [f32; 2], i: u32, origin: [f32; 2], r2: f32) -> Option<Key> {
    let a = [a[0] - origin[0], a[1] - origin[1]];
    let b = [b[0] - origin[0], b[1] - origin[1]];
    ((a[0] * a[0] + a[1] * a[1]).min(b[0] * b[0] + b[1] * b[1]) < r2).then(|| {
        let q = closest_point_to_origin(a, b);
        Key::new(q[0] * q[0] + q[1] * q[1], i)
    })
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

/// The reference: every segment checked, the first `p` by (distance, index).
#[cfg(test)]
pub(crate) fn closest_brute_force(
    index: &SegmentIndex,
    origin: [f32; 2],
    p: usize,
    radius_m: f32,
) -> Vec<(u32, f32)> {
    let r2 = radius_m * radius_m;
    let mut all: Vec<(u32, f32)> = (0..index.seg_a.len() as u32)
        .filter_map(|i| index.candidate(i, origin, r2))
        .map(|k| (k.index(), k.dist2()))
        .collect();
    all.sort_unstable_by(|x, y| x.1.total_cmp(&y.1).then(x.0.cmp(&y.0)));
    all.truncate(p);
    all
}

#[cfg(test)]
mod tests;
