//! Reference paths with arclength parameterisation and a Frenet (s, d) pose lookup.

/// A dense polyline sampled every `ds_m` metres of arclength.
#[derive(Debug, Clone)]
pub struct RefPath {
    ds_m: f64,
    x: Vec<f64>,
    y: Vec<f64>,
    heading: Vec<f64>,
    /// A bounding circle `(centre x, centre y, radius)` of each run of [`CHUNK`] segments
    /// (radius infinite for the runs holding an end segment, which extends beyond the path):
    /// [`Self::project`] skips a run that cannot hold a nearer point than one already found.
    chunks: Vec<(f64, f64, f64)>,
}

/// Segments per bounding circle of [`RefPath::project`]'s search.
const CHUNK: usize = 8;

impl RefPath {
    /// Samples `f(s) -> (x, y)` every `ds_m` over `[0, length_m]`; `f` must be parameterised by
    /// (approximately) arclength. Headings come from finite differences.
    pub fn from_fn(length_m: f64, ds_m: f64, f: impl Fn(f64) -> (f64, f64)) -> Self {
        let n = (length_m / ds_m).ceil() as usize + 1;
        let (x, y): (Vec<f64>, Vec<f64>) = (0..n).map(|i| f(i as f64 * ds_m)).unzip();
        let heading = (0..n)
            .map(|i| {
                let (a, b) = if i + 1 < n { (i, i + 1) } else { (i - 1, i) };
                (y[b] - y[a]).atan2(x[b] - x[a])
            })
            .collect();
        let chunks = bounding_circles(&x, &y);
        Self {
            ds_m,
            x,
            y,
            heading,
            chunks,
        }
    }

    /// A polyline `points` (in driving order, at most a few metres apart) resampled every
    /// `ds_m` of its arclength.
    ///
    /// # Panics
    /// If `points` has fewer than two points.
    pub fn from_points(points: &[(f64, f64)], ds_m: f64) -> Self {
        assert!(points.len() >= 2, "a path needs two points");
        let mut cumulative = Vec::with_capacity(points.len());
        let mut total = 0.0;
        cumulative.push(0.0);
        for w in points.windows(2) {
            total += (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1);
            cumulative.push(total);
        }
        Self::from_fn(total, ds_m, |s| {
            let i = cumulative
                .partition_point(|&c| c <= s)
                .clamp(1, points.len() - 1);
            let (c0, c1) = (cumulative[i - 1], cumulative[i]);
            let t = if c1 > c0 {
                ((s - c0) / (c1 - c0)).min(1.0)
            } else {
                0.0
            };
            let (a, b) = (points[i - 1], points[i]);
            (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1))
        })
    }

    /// A straight path from `(x0, y0)` with heading `heading_rad`.
    pub fn straight(x0: f64, y0: f64, heading_rad: f64, length_m: f64) -> Self {
        let (s, c) = heading_rad.sin_cos();
        Self::from_fn(length_m, 1.0, |t| (x0 + c * t, y0 + s * t))
    }

    /// Arclength of the path, metres.
    pub fn length_m(&self) -> f64 {
        (self.x.len() - 1) as f64 * self.ds_m
    }

    fn locate(&self, s: f64) -> (usize, f64) {
        let u = (s / self.ds_m).clamp(0.0, (self.x.len() - 1) as f64);
        let i = (u.floor() as usize).min(self.x.len() - 2);
        (i, u - i as f64)
    }

    /// Heading of the path at arclength `s` (radians).
    pub fn heading_at(&self, s: f64) -> f64 {
        let (i, t) = self.locate(s);
        let (h0, h1) = (self.heading[i], self.heading[i + 1]);
        h0 + t * scbg_scene::wrap_angle_rad(h1 - h0)
    }

    /// World position at arclength `s` and lateral offset `d` (positive to the left).
    pub fn pose(&self, s: f64, d: f64) -> (f64, f64) {
        let (i, t) = self.locate(s);
        let x = self.x[i] + t * (self.x[i + 1] - self.x[i]);
        let y = self.y[i] + t * (self.y[i + 1] - self.y[i]);
        // Extrapolate linearly beyond the ends so that agents never stick at a path end.
        let h = self.heading_at(s);
        let extra = if s < 0.0 {
            s
        } else {
            (s - self.length_m()).max(0.0)
        };
        let (sh, ch) = h.sin_cos();
        (x + extra * ch - d * sh, y + extra * sh + d * ch)
    }

    /// Frenet coordinates `(s, d)` of a world point: the nearest point of the polyline (a
    /// global scan when `s_hint` is `None`, else a search within 40 m of it, which is what a
    /// trajectory stepping along the path needs), extended linearly beyond both ends as
    /// [`Self::pose`] does. `d` is positive to the left. Of equally near segments, the first
    /// counts.
    ///
    /// The search is exact but skips each run of [`CHUNK`] segments whose bounding circle lies
    /// farther than the nearest point found so far, starting from the run whose circle is
    /// nearest: a few runs are scanned instead of the 81 segments of a 40 m window.
    pub fn project(&self, x: f64, y: f64, s_hint: Option<f64>) -> (f64, f64) {
        let (lo, hi) = self.window(s_hint);
        let (c_lo, c_hi) = (lo / CHUNK, hi / CHUNK);
        // A lower bound of the distance from the point to each run (squared, slightly under).
        let bound2 = |c: usize| {
            let (cx, cy, r) = self.chunks[c];
            let gap = ((x - cx).powi(2) + (y - cy).powi(2)).sqrt() - r;
            if gap <= 0.0 {
                0.0
            } else {
                (gap * (1.0 - 1e-9)).powi(2)
            }
        };
        let first = (c_lo..=c_hi)
            .map(|c| (bound2(c), c))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map_or(c_lo, |(_, c)| c);
        let segments = |c: usize| (c * CHUNK).max(lo)..=((c + 1) * CHUNK - 1).min(hi);
        let mut best = Nearest::NONE;
        self.scan(x, y, segments(first), &mut best);
        for c in (c_lo..=c_hi).filter(|&c| c != first) {
            if bound2(c) <= best.dist2 {
                self.scan(x, y, segments(c), &mut best);
            }
        }
        (best.s, best.d)
    }

    /// The segments [`Self::project`] searches: every one, or those within 40 m of the hint.
    fn window(&self, s_hint: Option<f64>) -> (usize, usize) {
        let last = self.x.len() - 2;
        match s_hint {
            None => (0, last),
            Some(s) => {
                let i = (s / self.ds_m).round().clamp(0.0, last as f64) as usize;
                let w = (40.0 / self.ds_m).ceil() as usize;
                (i.saturating_sub(w), (i + w).min(last))
            }
        }
    }

    /// Projects the point onto each of `segments`, keeping the nearest (the first of equals).
    fn scan(&self, x: f64, y: f64, segments: std::ops::RangeInclusive<usize>, best: &mut Nearest) {
        let last = self.x.len() - 2;
        for i in segments {
            let (ax, ay) = (self.x[i], self.y[i]);
            let (dx, dy) = (self.x[i + 1] - ax, self.y[i + 1] - ay);
            let l2 = (dx * dx + dy * dy).max(1e-12);
            let mut t = ((x - ax) * dx + (y - ay) * dy) / l2;
            // Only the end segments extend beyond the path.
            if i > 0 {
                t = t.max(0.0);
            }
            if i < last {
                t = t.min(1.0);
            }
            let (px, py) = (ax + t * dx, ay + t * dy);
            let dist2 = (x - px).powi(2) + (y - py).powi(2);
            if dist2 < best.dist2 || (dist2 == best.dist2 && i < best.segment) {
                let l = l2.sqrt();
                *best = Nearest {
                    dist2,
                    segment: i,
                    s: (i as f64 + t) * self.ds_m,
                    d: (dx * (y - ay) - dy * (x - ax)) / l,
                };
            }
        }
    }

    /// Points of the path offset by `d(s)`, every `step_m`, over `[s0, s1]`.
    pub fn offset_points(
        &self,
        s0: f64,
        s1: f64,
        step_m: f64,
        d: impl Fn(f64) -> f64,
    ) -> Vec<(f64, f64)> {
        let n = ((s1 - s0) / step_m).ceil().max(1.0) as usize;
        (0..=n)
            .map(|k| {
                let s = (s0 + k as f64 * step_m).min(s1);
                self.pose(s, d(s))
            })
            .collect()
    }
}

/// The nearest point found so far by [`RefPath::project`].
struct Nearest {
    dist2: f64,
    segment: usize,
    s: f64,
    d: f64,
}

impl Nearest {
    const NONE: Self = Self {
        dist2: f64::INFINITY,
        segment: usize::MAX,
        s: 0.0,
        d: 0.0,
    };
}

/// The bounding circle of each run of [`CHUNK`] segments of the polyline `(x, y)` (the centre
/// of the run's vertices' box, the farthest vertex's distance), infinite for the first and last
/// runs, whose end segments extend beyond the path.
fn bounding_circles(x: &[f64], y: &[f64]) -> Vec<(f64, f64, f64)> {
    let segments = x.len() - 1;
    let runs = segments.div_ceil(CHUNK);
    (0..runs)
        .map(|c| {
            if c == 0 || c + 1 == runs {
                return (0.0, 0.0, f64::INFINITY);
            }
            let v = c * CHUNK..=((c + 1) * CHUNK).min(segments);
            let (mut x0, mut x1, mut y0, mut y1) = (
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
            );
            for i in v.clone() {
                (x0, x1) = (x0.min(x[i]), x1.max(x[i]));
                (y0, y1) = (y0.min(y[i]), y1.max(y[i]));
            }
            let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
            let r = v.map(|i| (x[i] - cx).hypot(y[i] - cy)).fold(0.0, f64::max);
            // Outward rounding: the bound must never exceed the true distance.
            (cx, cy, r * (1.0 + 1e-12) + 1e-9)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_path_pose_and_offset() {
        let p = RefPath::straight(1.0, 2.0, std::f64::consts::FRAC_PI_2, 100.0);
        let (x, y) = p.pose(10.0, 0.0);
        assert!((x - 1.0).abs() < 1e-9 && (y - 12.0).abs() < 1e-9);
        // Left of a path heading +y is −x.
        let (x, _) = p.pose(10.0, 3.0);
        assert!((x + 2.0).abs() < 1e-9);
        assert!((p.heading_at(50.0) - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        let (_, y) = p.pose(110.0, 0.0);
        assert!((y - 112.0).abs() < 1e-9);
    }

    #[test]
    fn project_inverts_pose() {
        let k = 1.0 / 300.0;
        let p = RefPath::from_fn(400.0, 1.0, |s| {
            ((k * s).sin() / k, (1.0 - (k * s).cos()) / k)
        });
        for (s, d) in [
            (0.3, 0.0),
            (57.25, 3.5),
            (200.0, -2.0),
            (399.5, 1.0),
            (-5.0, 0.5),
            (410.0, -1.0),
        ] {
            let (x, y) = p.pose(s, d);
            for hint in [None, Some(s + 15.0)] {
                let (s2, d2) = p.project(x, y, hint);
                assert!(
                    (s2 - s).abs() < 0.02 && (d2 - d).abs() < 0.02,
                    "{s},{d} -> {s2},{d2}"
                );
            }
        }
    }

    /// The plain scan of every segment in the window: what the pruned search must return.
    fn project_every_segment(p: &RefPath, x: f64, y: f64, s_hint: Option<f64>) -> (f64, f64) {
        let (lo, hi) = p.window(s_hint);
        let mut best = Nearest::NONE;
        p.scan(x, y, lo..=hi, &mut best);
        (best.s, best.d)
    }

    #[test]
    fn pruned_projection_equals_the_full_scan() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        // A winding path that comes back near itself, a gentle arc, a short straight one.
        let winding = RefPath::from_fn(300.0, 1.0, |s| {
            (30.0 * (s / 40.0).sin() + 0.2 * s, 25.0 * (s / 23.0).cos())
        });
        let arc = RefPath::from_fn(700.0, 1.0, |s| {
            let k = 1.0 / 900.0;
            ((k * s).sin() / k, (1.0 - (k * s).cos()) / k)
        });
        let short = RefPath::straight(3.0, -1.0, 0.4, 5.0);
        for path in [&winding, &arc, &short] {
            let len = path.length_m();
            for _ in 0..4000 {
                let s = rng.random_range(-30.0..len + 30.0);
                let (x, y) = path.pose(s, rng.random_range(-40.0..40.0));
                // Vertices and segment midpoints too: ties between neighbouring segments.
                let (x, y) = if rng.random_bool(0.1) {
                    path.pose(s.round().clamp(0.0, len), 0.0)
                } else {
                    (x, y)
                };
                for hint in [None, Some(s + rng.random_range(-30.0..30.0))] {
                    assert_eq!(
                        path.project(x, y, hint),
                        project_every_segment(path, x, y, hint),
                        "({x}, {y}) hint {hint:?}"
                    );
                }
            }
        }
    }
}
