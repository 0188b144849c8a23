//! Reference paths with arclength parameterisation and a Frenet (s, d) pose lookup.

/// A dense polyline sampled every `ds_m` metres of arclength.
#[derive(Debug, Clone)]
pub struct RefPath {
    ds_m: f64,
    x: Vec<f64>,
    y: Vec<f64>,
    heading: Vec<f64>,
}

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
        Self {
            ds_m,
            x,
            y,
            heading,
        }
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
    /// [`Self::pose`] does. `d` is positive to the left.
    pub fn project(&self, x: f64, y: f64, s_hint: Option<f64>) -> (f64, f64) {
        let last = self.x.len() - 2;
        let (lo, hi) = match s_hint {
            None => (0, last),
            Some(s) => {
                let i = (s / self.ds_m).round().clamp(0.0, last as f64) as usize;
                let w = (40.0 / self.ds_m).ceil() as usize;
                (i.saturating_sub(w), (i + w).min(last))
            }
        };
        let mut best = (f64::INFINITY, 0.0, 0.0);
        for i in lo..=hi {
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
            if dist2 < best.0 {
                let l = l2.sqrt();
                let d = (dx * (y - ay) - dy * (x - ax)) / l;
                best = (dist2, (i as f64 + t) * self.ds_m, d);
            }
        }
        (best.1, best.2)
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
}
