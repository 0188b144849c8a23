//! Plane geometry of plans and lane centre lines (world frame, metres).

use super::{CHORD_M, MOVING_M, PAST_END_M};

pub(super) fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (b[0] - a[0]).hypot(b[1] - a[1])
}

/// The squared distance: what ranks many candidates (hypot is slow).
pub(super) fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)
}

pub(super) fn unit(a: [f64; 2], b: [f64; 2]) -> Option<[f64; 2]> {
    let len = dist(a, b);
    (len > 1e-9).then(|| [(b[0] - a[0]) / len, (b[1] - a[1]) / len])
}

pub(super) fn polyline_length(line: &[[f64; 2]]) -> f64 {
    line.windows(2).map(|w| dist(w[0], w[1])).sum()
}

/// Where `p` projects onto the line through segment `a`–`b`: the fraction along it (0 at `a`,
/// 1 at `b`, outside [0, 1] past either end; 0 for a segment of no length) and the nearest
/// point of the segment carried on `before_a_m` before `a` and `past_b_m` beyond `b`.
pub(super) fn foot(
    a: [f64; 2],
    b: [f64; 2],
    p: [f64; 2],
    before_a_m: f64,
    past_b_m: f64,
) -> (f64, [f64; 2]) {
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

/// The nearest point of a polyline to `p`, its last segment carried on [`super::PAST_END_M`]: the
/// segment, the point (on the polyline itself), `p`'s signed offset from it (m, left of the
/// line's way positive) and how far past the polyline's end it lies (m, 0 on the polyline);
/// `None` for fewer than two points.
pub(super) fn project(line: &[[f64; 2]], p: [f64; 2]) -> Option<(usize, [f64; 2], f64, f64)> {
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
pub(super) fn point_at(line: &[[f64; 2]], s_m: f64) -> ([f64; 2], [f64; 2]) {
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

/// The plan's direction at each point: the chord over [`super::CHORD_M`] on either side
/// ([`super::CHORD_M`]'s docs); where the plan spans less than that on both sides, the central
/// difference over two steps, or where that stands (under [`super::MOVING_M`]) the last direction the
/// plan had, or none before it first moves.
pub(super) fn plan_directions(plan: &[[f64; 2]]) -> Vec<Option<[f64; 2]>> {
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
