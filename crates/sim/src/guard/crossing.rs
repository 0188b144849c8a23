//! Crossing conflicts along a plan's path: another agent at constant velocity in the plan's
//! corridor while the agent's box is there, never stopping inside a crossing agent's way, and
//! the right of way a yielding agent leaves.

use scbg_scene::AgentState;
use scbg_synth::{LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2, RefPath, closer};

use super::side::SIDE_SAME_LANE_M;
use crate::idm::LOOKAHEAD_M;

/// Steps of [`crossing_conflict`]'s look-ahead: the other agent's position every 0.5 s up to
/// 5 s ahead (and where it crosses my path between two of them).
pub(super) const CONFLICT_HORIZON_STEPS: u32 = 10;
pub(super) const CONFLICT_STEP_S: f64 = 0.5;
/// A crossing conflict is two arrivals at the same point less than this many seconds apart.
/// (With 3 s and 1 s, the controlled B of the synthetic crossings stopped with its nose in the
/// cross traffic's lane in 2–4 % of closed-loop rollouts; with 5 s and 2 s in ≤ 1 %;
/// docs/findings.md, *The safety guard, rule by rule*.)
pub(super) const CONFLICT_WINDOW_S: f64 = 2.0;

/// Margin beyond its stopping distance a yielding agent must have before my corridor, m.
pub(super) const YIELD_MARGIN_M: f64 = 2.0;

/// A yielding agent's reaction in [`yields_in_time`], s: the crossing world's A reacts 0.3–0.7 s
/// late (`reaction_steps`). Its braking then ramps up under the world's 25 m/s³ jerk limit to at
/// most 7.5 m/s²; at the 7 m/s² asked of it that costs no more than the difference (within
/// 1.1 m at 12 m/s, less than [`YIELD_MARGIN_M`]).
pub(super) const YIELD_REACTION_S: f64 = 0.7;

/// Whether `o`, crossing my `path` ahead of `s_m` (at 45° or more) with its front not in my
/// corridor yet (my half-width and 0.5 m), can still stop before it at its current velocity:
/// braking at most [`LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2`] after [`YIELD_REACTION_S`], with
/// [`YIELD_MARGIN_M`] to spare — or it does not reach my corridor within 5 s at all. What the
/// synthetic world's least courteous B asks of A when it takes the way. A standing or slow
/// agent (under 0.5 m/s, which [`crossing_conflict`] never asks about) is not judged (false).
pub(super) fn yields_in_time(path: &RefPath, s_m: f64, me: &AgentState, o: &AgentState) -> bool {
    let (vx, vy) = (f64::from(o.velocity_x_mps), f64::from(o.velocity_y_mps));
    let v = vx.hypot(vy);
    if v < 0.5 {
        return false;
    }
    let probe = |tau: f64| path.project(o.x_m + vx * tau, o.y_m + vy * tau, Some(s_m + 25.0));
    let (s_now, d_now) = probe(0.0);
    let (sn, cs) = path.heading_at(s_now).sin_cos();
    let cos_rel = ((vx * cs + vy * sn) / v).abs();
    if cos_rel > CROSSING_MIN_ANGLE_RAD.cos() {
        return false;
    }
    let sin_rel = (1.0 - cos_rel * cos_rel).max(0.0).sqrt();
    // How far its centre is from my path when its front reaches my corridor.
    let reach_m = 0.5 * f64::from(me.width_m)
        + 0.5
        + 0.5 * (f64::from(o.length_m) * sin_rel + f64::from(o.width_m) * cos_rel);
    if d_now.abs() <= reach_m {
        return false;
    }
    let needed_m =
        v * YIELD_REACTION_S + v * v / (2.0 * LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2) + YIELD_MARGIN_M;
    // When its front enters my corridor (or it crosses my path between two samples),
    // interpolated between samples 0.1 s apart, up to 5 s ahead.
    let mut previous = (0.0, d_now);
    for k in 1..=50 {
        let tau = 0.1 * f64::from(k);
        let d = probe(tau).1;
        if d.abs() <= reach_m || d.signum() != previous.1.signum() {
            // Its offset on the side it came from: negative once it has crossed, so the
            // denominator is positive and the fraction in [0, 1).
            let (tau_0, d_0) = (previous.0, previous.1.abs());
            let d_same_side = d * previous.1.signum();
            let tau_in = tau_0 + (tau - tau_0) * (d_0 - reach_m) / (d_0 - d_same_side);
            return v * tau_in >= needed_m;
        }
        previous = (tau, d);
    }
    true
}

/// A crossing conflict ahead of an agent at `s_m` on `path` that follows `arrival` (the time,
/// s from now, at which it reaches each arclength, increasing; `None` beyond where its plan
/// stops): another agent whose position extrapolated at constant velocity 0.5, 1, …, 5 s ahead
/// lies in the corridor ahead at an arclength the agent's box occupies within 2 s of the same
/// time — from when its box reaches the other's until it has left it, or for good when its plan
/// stops there (a plan that stands in another's way is a conflict however late the other
/// comes). A follower — behind the agent and heading its way (velocity within 60° of its
/// heading) — counts only while it is faster and in the next lane (its box overlapping mine
/// sideways by at most 0.5 m): one that does not catch up is left to yield, and one behind me
/// in my lane to its leader rule, as braking in front of it would only bring it closer. Nor
/// does a crossing agent (at 45° or more) whose near edge my front has already passed at the
/// conflict point: braking would only leave me standing in its way. The conflict point is
/// returned as a standing leader `(bumper gap m, 0)`; the nearest one counts. The agent never
/// stops for a conflict inside another agent's way: when its box, moved along the path,
/// reaches the way of a crossing agent (one heading at 45° or more to the path; the band
/// around its position continued along its velocity) before the conflict, it stops before
/// that way instead if it can at 3 m/s² (don't block the box). A `yielding` agent (one of
/// `others`, known to yield to me, as the synthetic world's A yields to B) is no conflict while
/// it crosses toward my corridor and can still stop before it braking as the world's least
/// courteous B asks ([`yields_in_time`]): my plan then decides who goes first.
pub(crate) fn crossing_conflict(
    path: &RefPath,
    s_m: f64,
    me: &AgentState,
    others: &[&AgentState],
    yielding: Option<&AgentState>,
    arrival: impl Fn(f64) -> Option<f64>,
) -> Option<(f64, f64)> {
    let mut best: Option<(f64, f64)> = None;
    let (sn, cs) = f64::from(me.heading_rad).sin_cos();
    let moving_near = |o: &&&AgentState| {
        let v = f64::from(o.velocity_x_mps).hypot(f64::from(o.velocity_y_mps));
        v >= 0.5 && (o.x_m - me.x_m).hypot(o.y_m - me.y_m) <= LOOKAHEAD_M + 40.0
    };
    for o in others.iter().filter(moving_near) {
        let (vx, vy) = (f64::from(o.velocity_x_mps), f64::from(o.velocity_y_mps));
        let (dx, dy) = (o.x_m - me.x_m, o.y_m - me.y_m);
        // A follower (behind, heading the same way) that is not catching up, or that is
        // behind me in my own lane, is no conflict to brake for: braking in front of it only
        // brings it closer (in my lane, keeping its distance is its leader rule's work).
        let along = vx * cs + vy * sn;
        if along > 0.5 * vx.hypot(vy) && dx * cs + dy * sn < 0.0 {
            let clearance = (-dx * sn + dy * cs).abs() - 0.5 * f64::from(me.width_m + o.width_m);
            if along <= f64::from(me.speed_mps()) || clearance < -SIDE_SAME_LANE_M {
                continue;
            }
        }
        let half = 0.5 * f64::from(me.width_m + o.width_m) + 0.5;
        // Where the other is at `tau` s from now, as (arclength, signed offset) on my path.
        let probe = |tau: f64| path.project(o.x_m + vx * tau, o.y_m + vy * tau, Some(s_m + 25.0));
        if yielding.is_some_and(|y| std::ptr::eq(*o, y)) && yields_in_time(path, s_m, me, o) {
            continue;
        }
        // Whether the other, at `tau` s from now, is in my corridor while my box is on its way;
        // the bumper gap to that point if so.
        let conflict_at = |tau: f64, (s, d): (f64, f64)| -> Option<f64> {
            let ahead = s - s_m;
            if ahead <= 0.0 || ahead > LOOKAHEAD_M || d.abs() > half {
                return None;
            }
            // My box overlaps the other's (at s, crossing my path at its heading there) while
            // my centre is within `reach` of s, less the margin.
            let (sn_p, cs_p) = path.heading_at(s).sin_cos();
            let cos_rel = ((vx * cs_p + vy * sn_p) / vx.hypot(vy)).abs();
            let sin_rel = (1.0 - cos_rel * cos_rel).max(0.0).sqrt();
            let touch = 0.5 * f64::from(me.length_m)
                + 0.5 * (f64::from(o.length_m) * cos_rel + f64::from(o.width_m) * sin_rel);
            // Committed: my front is already past the near edge of a crossing agent's box at
            // that point, so braking would only leave me standing in its way.
            if cos_rel <= std::f64::consts::FRAC_1_SQRT_2 && ahead < touch {
                return None;
            }
            let reach = touch + CONFLICT_MARGIN_M;
            occupied(&arrival, s - reach, s + reach, tau)
                .then(|| ahead - 0.5 * f64::from(me.length_m + o.length_m))
        };
        // The side of my path the other is on at each sample: a fast agent (over ~9.6 m/s at
        // 90°) can cross my corridor between two samples 0.5 s apart, so where the side flips
        // the crossing itself (its time interpolated) is tested too.
        let mut previous = (0.0, probe(0.0).1);
        for k in 1..=CONFLICT_HORIZON_STEPS {
            let tau = CONFLICT_STEP_S * f64::from(k);
            let at = probe(tau);
            let (tau_0, d_0) = previous;
            let d = at.1;
            previous = (tau, d);
            let crossed = (d_0 > half && d < -half) || (d_0 < -half && d > half);
            let tau_cross = tau_0 + (tau - tau_0) * d_0.abs() / (d_0.abs() + d.abs());
            if let Some(gap) = crossed
                .then(|| conflict_at(tau_cross, probe(tau_cross)))
                .flatten()
                .or_else(|| conflict_at(tau, at))
            {
                best = closer(best, Some((gap, 0.0)));
                break;
            }
        }
    }
    // Never stop for a conflict inside another agent's way: stop before the nearest way
    // between here and the conflict instead — one I can still stop before at a comfortable
    // deceleration (braking harder for it would only leave me standing in it).
    if let Some((conflict_gap, _)) = best {
        let v = f64::from(me.speed_mps());
        let stopping_m = v * v / (2.0 * WAY_STOP_DECEL_MPS2);
        for o in others.iter().filter(moving_near) {
            if let Some(gap) = crossing_way(path, s_m, me, o, conflict_gap)
                && gap >= stopping_m
                && gap > 0.0
                && gap < conflict_gap
            {
                best = closer(best, Some((gap, 0.0)));
            }
        }
    }
    best
}

/// Margin by which my box is taken to reach a crossing agent's box early and leave it late,
/// m: the tracker may run past the point where a plan stops, and the other need not keep its
/// velocity (held-out synthetic scenes: B's crossing collisions 20 → 11 of 2 745 rollouts at
/// 2 m, none fewer at 3 m; docs/findings.md, *The safety guard, rule by rule*).
pub(super) const CONFLICT_MARGIN_M: f64 = 2.0;

/// Heading difference between two agents' ways above which one crosses the other (and below
/// 180° minus it), rad.
pub(super) const CROSSING_MIN_ANGLE_RAD: f64 = std::f64::consts::FRAC_PI_4;

/// The deceleration at which the guard still stops before a crossing agent's way rather than
/// at the conflict beyond it (the guard IDM's comfortable braking), m/s².
pub(super) const WAY_STOP_DECEL_MPS2: f64 = 3.0;

/// Half-width margin of a crossing agent's way beyond half its width, m.
pub(super) const WAY_MARGIN_M: f64 = 0.5;

/// Where my box, moved along my `path` ahead of `s_m` (at the path's heading, in steps of
/// 0.5 m), first reaches the way of a crossing agent `o` — the band of half its width plus
/// [`WAY_MARGIN_M`] around its position continued along its velocity for up to
/// [`LOOKAHEAD_M`] — as the distance my centre can still go, m (0: my box is in it already);
/// `None` when the way crosses my path at under 45° (or over 135°) there, or my box does not
/// reach it within `limit_m`. (Measured from my box, not my path's centre line: a B turning
/// right into a road from the side had its nose in the cross traffic's lane while the way's
/// crossing of its path's centre line was still 4 m ahead; docs/findings.md, *The safety
/// guard, rule by rule*.)
pub(super) fn crossing_way(
    path: &RefPath,
    s_m: f64,
    me: &AgentState,
    o: &AgentState,
    limit_m: f64,
) -> Option<f64> {
    let (vx, vy) = (f64::from(o.velocity_x_mps), f64::from(o.velocity_y_mps));
    let v = vx.hypot(vy);
    let (ux, uy) = (vx / v, vy / v);
    let band = 0.5 * f64::from(o.width_m) + WAY_MARGIN_M;
    let (hl, hw) = (0.5 * f64::from(me.length_m), 0.5 * f64::from(me.width_m));
    let crossing = CROSSING_MIN_ANGLE_RAD..=std::f64::consts::PI - CROSSING_MIN_ANGLE_RAD;
    let mut k = 0.0;
    while k <= limit_m.min(LOOKAHEAD_M) {
        let s = s_m + k;
        let (x, y) = path.pose(s, 0.0);
        let h = path.heading_at(s);
        let (sn, cs) = h.sin_cos();
        // My box's corners in the way's frame: along it from o, and across it.
        let (mut a_min, mut a_max) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut c_min, mut c_max) = (f64::INFINITY, f64::NEG_INFINITY);
        for (u, w) in [(1.0, 1.0), (1.0, -1.0), (-1.0, -1.0), (-1.0, 1.0)] {
            let cx = x + u * hl * cs - w * hw * sn - o.x_m;
            let cy = y + u * hl * sn + w * hw * cs - o.y_m;
            let along = cx * ux + cy * uy;
            let across = -cx * uy + cy * ux;
            (a_min, a_max) = (a_min.min(along), a_max.max(along));
            (c_min, c_max) = (c_min.min(across), c_max.max(across));
        }
        if a_max >= 0.0 && a_min <= LOOKAHEAD_M && c_min <= band && c_max >= -band {
            let angle = (ux * cs + uy * sn).clamp(-1.0, 1.0).acos();
            return crossing.contains(&angle).then_some(k);
        }
        k += 0.5;
    }
    None
}

/// Whether the agent that reaches each arclength at `arrival(s)` s from now (`None`: never, its
/// plan stops before) is on `[s_in, s_out]` within [`CONFLICT_WINDOW_S`] of `tau`: from when it
/// gets to `s_in` until it has left `s_out`, or for good when its plan stops in between.
pub(super) fn occupied(
    arrival: &impl Fn(f64) -> Option<f64>,
    s_in: f64,
    s_out: f64,
    tau: f64,
) -> bool {
    let Some(enter) = arrival(s_in) else {
        return false;
    };
    tau > enter - CONFLICT_WINDOW_S
        && arrival(s_out).is_none_or(|leave| tau < leave + CONFLICT_WINDOW_S)
}
