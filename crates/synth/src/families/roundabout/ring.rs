//! The roundabout's geometry: the ring, its arms, and the arcs that join them.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// Length of each arm's straight beyond its connector, m.
pub(super) const ARM_M: f64 = 120.0;
/// Spacing of the points routes are built from before resampling, m.
const ROUTE_STEP_M: f64 = 0.25;
/// The vehicle a yield line is placed for: half its length and half its width, m (the
/// largest the families draw), and the clearance its front corners keep from a circulating
/// vehicle of the same width on the ring lane's centre line.
const YIELD_HALF_LENGTH_M: f64 = 2.6;
const YIELD_HALF_WIDTH_M: f64 = 1.05;
const YIELD_CLEARANCE_M: f64 = 0.5;
/// The geometry of a single-lane roundabout, centred on the origin, traffic counter-clockwise.
#[derive(Debug, Clone)]
pub(super) struct Ring {
    /// Radius of the ring lane's centre line, m.
    pub(super) radius_m: f64,
    pub(super) lane_width_m: f64,
    /// Axis angle of every arm (counter-clockwise, increasing); A and B meet at arm 0's entry.
    pub(super) arms_rad: Vec<f64>,
    /// Radius of the arcs that take an arm's entry lane onto the ring and the ring onto its
    /// exit lane (tangent to both), m: the entries' deflection.
    pub(super) deflection_m: f64,
}

fn unit(angle_rad: f64) -> (f64, f64) {
    (angle_rad.cos(), angle_rad.sin())
}

fn polyline_len(points: &[(f64, f64)]) -> f64 {
    points
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
        .sum()
}

/// Counter-clockwise angle from `from` to `to`, in `(0, 2π]`.
pub(super) fn ccw_span(from: f64, to: f64) -> f64 {
    let d = (to - from).rem_euclid(TAU);
    if d < 1e-9 { TAU } else { d }
}

impl Ring {
    /// The deflection arcs' centre: how far along an arm's axis it lies, and the angle
    /// (from the axis, at the origin) at which the arcs meet the ring.
    pub(super) fn deflection(&self) -> (f64, f64) {
        let (r, side) = (
            self.radius_m + self.deflection_m,
            self.lane_width_m / 2.0 + self.deflection_m,
        );
        let along = (r * r - side * side).sqrt();
        (along, side.atan2(along))
    }

    /// Angle where arm `k`'s entry joins the ring.
    pub(super) fn join(&self, k: usize) -> f64 {
        self.arms_rad[k] + self.deflection().1
    }

    /// Angle where arm `k`'s exit leaves the ring.
    pub(super) fn leave(&self, k: usize) -> f64 {
        self.arms_rad[k] - self.deflection().1
    }

    pub(super) fn on_ring(&self, angle: f64, r: f64) -> (f64, f64) {
        let (c, s) = unit(angle);
        (r * c, r * s)
    }

    /// Point on arm `k`'s axis at radius `r`, moved `side` m counter-clockwise across it.
    pub(super) fn on_arm(&self, k: usize, r: f64, side: f64) -> (f64, f64) {
        let th = self.arms_rad[k];
        let (c, s) = unit(th);
        (r * c - side * s, r * s + side * c)
    }

    /// A clockwise arc of the deflection radius around `centre`, from angle `from` turning by
    /// `turn` rad (exclusive of its start).
    pub(super) fn deflection_arc(
        &self,
        centre: (f64, f64),
        from: f64,
        turn: f64,
    ) -> Vec<(f64, f64)> {
        let n = (turn * self.deflection_m / ROUTE_STEP_M).ceil().max(1.0) as usize;
        (1..=n)
            .map(|i| {
                let (c, s) = unit(from - turn * i as f64 / n as f64);
                (
                    centre.0 + self.deflection_m * c,
                    centre.1 + self.deflection_m * s,
                )
            })
            .collect()
    }

    /// Arm `k`'s entry lane, from the far end of its straight to the ring (inclusive): the
    /// straight, then a right-hand arc tangent to the ring.
    pub(super) fn entry_points(&self, k: usize) -> Vec<(f64, f64)> {
        let (along, join) = self.deflection();
        let w = self.lane_width_m;
        let n = ARM_M as usize;
        let mut out: Vec<(f64, f64)> = (0..=n)
            .map(|i| self.on_arm(k, along + ARM_M - i as f64, w / 2.0))
            .collect();
        let centre = self.on_arm(k, along, w / 2.0 + self.deflection_m);
        let th = self.arms_rad[k];
        out.extend(self.deflection_arc(centre, th - FRAC_PI_2, FRAC_PI_2 - join));
        out
    }

    /// Arm `k`'s exit lane, from the ring (exclusive) to the far end of its straight: a
    /// right-hand arc tangent to the ring, then the straight.
    pub(super) fn exit_points(&self, k: usize) -> Vec<(f64, f64)> {
        let (along, leave) = self.deflection();
        let w = self.lane_width_m;
        let centre = self.on_arm(k, along, -(w / 2.0 + self.deflection_m));
        let th = self.arms_rad[k];
        let mut out = self.deflection_arc(centre, th - leave + PI, FRAC_PI_2 - leave);
        out.extend((1..=ARM_M as usize).map(|i| self.on_arm(k, along + i as f64, -w / 2.0)));
        out
    }

    /// The ring counter-clockwise from `from` over `span` rad (exclusive of its start), at
    /// radius `r`.
    pub(super) fn arc_points(&self, from: f64, span: f64, r: f64) -> Vec<(f64, f64)> {
        let n = (span * r / ROUTE_STEP_M).ceil().max(1.0) as usize;
        (1..=n)
            .map(|i| self.on_ring(from + span * i as f64 / n as f64, r))
            .collect()
    }

    /// The route entering by arm `entry` and leaving by arm `exit`.
    pub(super) fn route(&self, entry: usize, exit: usize) -> Vec<(f64, f64)> {
        let mut points = self.entry_points(entry);
        let span = ccw_span(self.join(entry), self.leave(exit));
        points.extend(self.arc_points(self.join(entry), span, self.radius_m));
        points.extend(self.exit_points(exit));
        points
    }

    /// Arclength at which a route entering by arm `entry` passes the angle `at` on the ring.
    pub(super) fn s_at(&self, entry: usize, at: f64) -> f64 {
        polyline_len(&self.entry_points(entry))
            + self.radius_m * (at - self.join(entry)).rem_euclid(TAU)
    }

    /// Arclength along the ring from the merge point at arm 0 to where arm `exit` leaves.
    pub(super) fn common_to(&self, exit: usize) -> f64 {
        self.radius_m * ccw_span(self.join(0), self.leave(exit))
    }

    /// The yield line before the merge point on arm 0's entry route (`entry` its points, the
    /// merge at its end), in the merge coordinate (negative): the last point where a vehicle
    /// centred on it keeps its front corners [`YIELD_CLEARANCE_M`] clear of a vehicle
    /// circulating on the ring lane's centre line.
    pub(super) fn yield_m(&self, entry: &[(f64, f64)]) -> f64 {
        let clear_r = self.radius_m + 2.0 * YIELD_HALF_WIDTH_M + YIELD_CLEARANCE_M;
        let mut m = 0.0;
        for w in entry.windows(2).rev() {
            let (dx, dy) = (w[1].0 - w[0].0, w[1].1 - w[0].1);
            let len = dx.hypot(dy).max(1e-9);
            m -= len;
            let (hx, hy) = (dx / len, dy / len);
            let front = (
                w[0].0 + YIELD_HALF_LENGTH_M * hx,
                w[0].1 + YIELD_HALF_LENGTH_M * hy,
            );
            let corners_clear = [-1.0, 1.0].iter().all(|side| {
                let (x, y) = (
                    front.0 - side * YIELD_HALF_WIDTH_M * hy,
                    front.1 + side * YIELD_HALF_WIDTH_M * hx,
                );
                x.hypot(y) >= clear_r
            });
            if corners_clear {
                break;
            }
        }
        m
    }
}
