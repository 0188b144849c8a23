//! The safety guard's rules for an agent following a plan: crossing conflicts along its path
//! (another agent at constant velocity in the plan's corridor while the agent's box is there,
//! never stopping inside a crossing agent's way) and steering bounds beside another agent
//! (and gap acceptance: none toward the lane of a follower that could not stay behind).
//! The rollout caps the tracker's acceleration by IDM toward the nearest conflict (with the
//! corridor leader of [`crate::idm`]) and clamps its steering to the bounds.

use scbg_scene::AgentState;
use scbg_synth::{CUT_IN_REACTION_S, LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2, RefPath, closer};

use crate::idm::LOOKAHEAD_M;

/// Steps of [`crossing_conflict`]'s look-ahead: the other agent's position every 0.5 s up to
/// 5 s ahead (and where it crosses my path between two of them).
const CONFLICT_HORIZON_STEPS: u32 = 10;
const CONFLICT_STEP_S: f64 = 0.5;
/// A crossing conflict is two arrivals at the same point less than this many seconds apart.
/// (With 3 s and 1 s, the controlled B of the synthetic crossings stopped with its nose in the
/// cross traffic's lane in 2–4 % of closed-loop rollouts; with 5 s and 2 s in ≤ 1 %,
/// BENCHMARKS.md.)
const CONFLICT_WINDOW_S: f64 = 2.0;

/// Margin beyond its stopping distance a yielding agent must have before my corridor, m.
const YIELD_MARGIN_M: f64 = 2.0;

/// A yielding agent's reaction in [`yields_in_time`], s: the crossing world's A reacts 0.3–0.7 s
/// late (`reaction_steps`). Its braking then ramps up under the world's 25 m/s³ jerk limit to at
/// most 7.5 m/s²; at the 7 m/s² asked of it that costs no more than the difference (within
/// 1.1 m at 12 m/s, less than [`YIELD_MARGIN_M`]).
const YIELD_REACTION_S: f64 = 0.7;

/// Whether `o`, crossing my `path` ahead of `s_m` (at 45° or more) with its front not in my
/// corridor yet (my half-width and 0.5 m), can still stop before it at its current velocity:
/// braking at most [`LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2`] after [`YIELD_REACTION_S`], with
/// [`YIELD_MARGIN_M`] to spare — or it does not reach my corridor within 5 s at all. What the
/// synthetic world's least courteous B asks of A when it takes the way. A standing or slow
/// agent (under 0.5 m/s, which [`crossing_conflict`] never asks about) is not judged (false).
fn yields_in_time(path: &RefPath, s_m: f64, me: &AgentState, o: &AgentState) -> bool {
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
/// 2 m, none fewer at 3 m; BENCHMARKS.md).
const CONFLICT_MARGIN_M: f64 = 2.0;

/// Heading difference between two agents' ways above which one crosses the other (and below
/// 180° minus it), rad.
const CROSSING_MIN_ANGLE_RAD: f64 = std::f64::consts::FRAC_PI_4;

/// The deceleration at which the guard still stops before a crossing agent's way rather than
/// at the conflict beyond it (the guard IDM's comfortable braking), m/s².
const WAY_STOP_DECEL_MPS2: f64 = 3.0;

/// Half-width margin of a crossing agent's way beyond half its width, m.
const WAY_MARGIN_M: f64 = 0.5;

/// Where my box, moved along my `path` ahead of `s_m` (at the path's heading, in steps of
/// 0.5 m), first reaches the way of a crossing agent `o` — the band of half its width plus
/// [`WAY_MARGIN_M`] around its position continued along its velocity for up to
/// [`LOOKAHEAD_M`] — as the distance my centre can still go, m (0: my box is in it already);
/// `None` when the way crosses my path at under 45° (or over 135°) there, or my box does not
/// reach it within `limit_m`. (Measured from my box, not my path's centre line: a B turning
/// right into a road from the side had its nose in the cross traffic's lane while the way's
/// crossing of its path's centre line was still 4 m ahead; BENCHMARKS.md.)
fn crossing_way(
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
fn occupied(arrival: &impl Fn(f64) -> Option<f64>, s_in: f64, s_out: f64, tau: f64) -> bool {
    let Some(enter) = arrival(s_in) else {
        return false;
    };
    tau > enter - CONFLICT_WINDOW_S
        && arrival(s_out).is_none_or(|leave| tau < leave + CONFLICT_WINDOW_S)
}

/// Lateral clearance below which an agent alongside bounds the steering, m (more while I drift
/// toward it: see [`SIDE_ALIGN_S`]).
const SIDE_CLEARANCE_M: f64 = 0.8;
/// Time constant in which the bounded steering turns the agent parallel to the one alongside,
/// s. The yaw rate toward parallel is the relative heading over it, re-set every step, so the
/// turn decays exponentially and the agent drifts `v_lat ·` this much sideways on the way, with
/// `v_lat` its lateral speed toward the other: while drifting, the time is shortened so the
/// drift keeps [`SIDE_KEEP_M`] of the clearance (down to [`SIDE_MIN_ALIGN_S`]), and the bound
/// starts where the drift of the full time would take more than the clearance. (A B at 24 m/s
/// moving over at 6° toward A, 3 m ahead of it, was bounded at 0.7 m and drifted 1.2 m into it;
/// BENCHMARKS.md.)
const SIDE_ALIGN_S: f64 = 0.5;
/// The least alignment time constant, s (a yaw rate the bicycle's steering reaches in ~0.1 s).
const SIDE_MIN_ALIGN_S: f64 = 0.1;
/// Clearance the bounded drift toward an agent alongside leaves, m.
const SIDE_KEEP_M: f64 = 0.2;
/// An agent behind that catches up counts as alongside from as far back as it closes in this
/// many seconds (a slow B at 13 m/s moving over into the lane of A coming up at 24 m/s was hit
/// from behind-left, A's centre 1.6 m behind B's: bounded only once A was alongside, B was
/// already in its way; BENCHMARKS.md).
const SIDE_CATCH_UP_S: f64 = 3.0;
/// A catching-up agent whose box overlaps mine sideways by more than this is behind me in my
/// lane, not in the next one, m.
const SIDE_SAME_LANE_M: f64 = 0.5;
/// An agent whose box is less than this far from mine sideways is in the next lane, m (two
/// cars about 2 m wide in lanes 3.5–3.7 m apart are 1.5–1.8 m apart; two lanes over, 5 m).
const NEXT_LANE_CLEARANCE_M: f64 = 2.5;

/// Whether moving in front of a follower that is `gap_m` behind my rear bumper and closes on
/// me at `closing_mps` would ask it to brake harder than the synthetic world's least
/// courteous B asks of A ([`LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2`], after its
/// [`CUT_IN_REACTION_S`]; MOBIL's safety criterion) to stay behind me: the constant
/// deceleration that matches my speed in the gap left after its reaction,
/// `Δv² / 2 (gap − Δv·t_r)`.
fn cut_in_unsafe(gap_m: f64, closing_mps: f64) -> bool {
    if closing_mps <= 0.0 {
        return false;
    }
    let room_m = (gap_m - closing_mps * CUT_IN_REACTION_S).max(0.1);
    closing_mps * closing_mps / (2.0 * room_m) > LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2
}

/// How far ahead a plan's slowing counts for gap acceptance, s: the 1 s windows of
/// [`planned_gap_speed_mps`] start at most this long after now (so they reach 4 s ahead).
const PLAN_SLOWING_S: f64 = 3.0;
/// The window over which a plan's speed is averaged for [`planned_gap_speed_mps`], steps (1 s:
/// a sampled future's points carry noise that single steps would read as speed).
const PLAN_SPEED_WINDOW_STEPS: usize = 10;

/// The least speed, m/s, that a plan of positions `step_s` seconds apart comes down to soon:
/// the least average over 1 s windows starting from its point `from` (where it has me now)
/// to [`PLAN_SLOWING_S`] after it; `None` when no whole window is left. A follower that gap
/// acceptance lets me cut in front of must stay behind me at that speed, not only at my
/// current one.
pub(crate) fn planned_gap_speed_mps(plan: &[[f64; 2]], from: usize, step_s: f64) -> Option<f64> {
    let w = PLAN_SPEED_WINDOW_STEPS;
    let last = plan.len().checked_sub(w + 1)?;
    let end = (from + (PLAN_SLOWING_S / step_s).round() as usize).min(last);
    (from..=end)
        .map(|k| {
            let (p, q) = (plan[k], plan[k + w]);
            (q[0] - p[0]).hypot(q[1] - p[1]) / (w as f64 * step_s)
        })
        .reduce(f64::min)
}

/// Gap acceptance toward `o` behind me in the next lane, closing on me at `closing_mps`: the
/// clearance between our boxes across *its* heading (its lane's direction; in my frame,
/// turned toward it, a follower far behind seems farther to the side than it is) when it is
/// in the next lane ([`NEXT_LANE_CLEARANCE_M`]) and could not stay behind me
/// ([`cut_in_unsafe`]); `None` when it could.
fn refused_gap(me: &AgentState, o: &AgentState, closing_mps: f64) -> Option<f64> {
    let (dx, dy) = (o.x_m - me.x_m, o.y_m - me.y_m);
    let (sn, cs) = f64::from(o.heading_rad).sin_cos();
    let ahead_of_it = -(dx * cs + dy * sn);
    let clearance = (dx * sn - dy * cs).abs() - 0.5 * f64::from(me.width_m + o.width_m);
    let gap = ahead_of_it - 0.5 * f64::from(me.length_m + o.length_m);
    (clearance < NEXT_LANE_CLEARANCE_M && cut_in_unsafe(gap, closing_mps)).then_some(clearance)
}

/// Steering bounds `(min, max)` (rad, positive left) that keep an agent from turning toward
/// another one alongside it: an agent heading within 30° of its heading whose centre is within
/// half the two lengths plus 1 m along it (behind it, plus what the other closes on it in
/// 3 s) and whose box is less than 0.8 m away to one side (more while drifting toward it) —
/// or a follower in the next lane (its box less than 2.5 m from mine across its heading),
/// however far behind, that could not stay behind me braking at 7 m/s² ([`cut_in_unsafe`])
/// as I slow to `gap_speed_mps` (my speed, or the least my plan comes down to in 1 s
/// averages starting within 3 s: [`planned_gap_speed_mps`]).
/// Toward such an agent the steering may at most turn the agent parallel to it with a time
/// constant of 0.5 s, shorter while drifting toward it ([`SIDE_ALIGN_S`]; the bicycle's yaw
/// rate `v·tan δ / wheelbase`). `None` when nobody is alongside.
pub(crate) fn side_steer_bounds(
    me: &AgentState,
    speed_mps: f64,
    gap_speed_mps: f64,
    wheelbase_m: f64,
    others: &[&AgentState],
) -> Option<(f64, f64)> {
    let (sn, cs) = f64::from(me.heading_rad).sin_cos();
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for o in others {
        let rel = scbg_scene::wrap_angle_rad(f64::from(o.heading_rad - me.heading_rad));
        if rel.abs() > 30f64.to_radians() {
            continue;
        }
        let (dx, dy) = (o.x_m - me.x_m, o.y_m - me.y_m);
        let along = dx * cs + dy * sn;
        let left = -dx * sn + dy * cs;
        let clearance = left.abs() - 0.5 * f64::from(me.width_m + o.width_m);
        // Behind me, an agent catching up counts from as far back as it closes in
        // SIDE_CATCH_UP_S: turning toward it then would put me in its way as it arrives.
        // (Only one in the next lane: one behind me in mine is for the leader rule.)
        let alongside = 0.5 * f64::from(me.length_m + o.length_m) + 1.0;
        let closing =
            f64::from(o.velocity_x_mps) * cs + f64::from(o.velocity_y_mps) * sn - speed_mps;
        let behind_next_lane = along < -alongside && clearance > -SIDE_SAME_LANE_M;
        let reach = if behind_next_lane {
            alongside + closing.max(0.0) * SIDE_CATCH_UP_S
        } else {
            alongside
        };
        // My lateral speed toward it (my heading turned toward its side of its heading).
        let toward_mps = speed_mps * (-rel * left.signum()).sin();
        let trigger = SIDE_CLEARANCE_M.max(SIDE_KEEP_M + toward_mps * SIDE_ALIGN_S);
        // Gap acceptance: a follower in the next lane that could not stay behind me without
        // braking harder than the least courteous driver asks keeps me out of its lane
        // altogether, however far behind (moving in slowly ahead of a fast one, then braking,
        // was side-swiped; BENCHMARKS.md) — behind me as my plan slows me down, too (a B
        // merging 30 m ahead of A, then stopping at the end of the ramp, was run into).
        let closing_gap = closing + speed_mps - gap_speed_mps.min(speed_mps);
        let (clearance, trigger, reach) = match behind_next_lane
            .then(|| refused_gap(me, o, closing_gap))
            .flatten()
        {
            Some(across_its_lane) => (across_its_lane, NEXT_LANE_CLEARANCE_M, f64::INFINITY),
            None => (clearance, trigger, reach),
        };
        if along.abs() > reach || clearance > trigger {
            continue;
        }
        // The steering that turns me parallel to it, with the time constant whose drift keeps
        // SIDE_KEEP_M of the clearance.
        let align_s = if toward_mps > 0.0 {
            ((clearance - SIDE_KEEP_M) / toward_mps).clamp(SIDE_MIN_ALIGN_S, SIDE_ALIGN_S)
        } else {
            SIDE_ALIGN_S
        };
        let yaw_rate = rel / align_s;
        let align = (yaw_rate * wheelbase_m / speed_mps.max(1.0)).atan();
        if left > 0.0 {
            hi = hi.min(align);
        } else {
            lo = lo.max(align);
        }
    }
    if lo == f64::NEG_INFINITY && hi == f64::INFINITY {
        return None;
    }
    if lo > hi {
        // Hemmed in on both sides: steer halfway.
        let mid = 0.5 * (lo + hi);
        return Some((mid, mid));
    }
    Some((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::idm::polyline_path;

    /// A car at the origin heading +x at 10 m/s.
    fn me_along_x() -> AgentState {
        AgentState {
            length_m: 4.5,
            width_m: 1.9,
            velocity_x_mps: 10.0,
            valid: true,
            ..Default::default()
        }
    }

    /// An agent like [`me_along_x`] at `(x, y)` driving along y at `vy` m/s, across a path
    /// along x.
    fn crossing_y(x: f64, y: f64, vy: f32) -> AgentState {
        AgentState {
            x_m: x,
            y_m: y,
            heading_rad: std::f32::consts::FRAC_PI_2 * vy.signum(),
            velocity_x_mps: 0.0,
            velocity_y_mps: vy,
            ..me_along_x()
        }
    }

    /// My path: straight along x from the origin.
    fn path_along_x() -> RefPath {
        polyline_path(&[[0.0, 0.0], [200.0, 0.0]], 0.0)
    }

    /// When [`me_along_x`] reaches arclength `s_m` of a straight path along x.
    fn arrival_at_10_mps(s_m: f64) -> Option<f64> {
        Some(s_m / 10.0)
    }

    /// The same plan at 10 m/s, stopping at arclength `x_stop` (never reaching beyond it).
    fn stops_at(x_stop: f64) -> impl Fn(f64) -> Option<f64> {
        move |s: f64| (s <= x_stop).then_some(s / 10.0)
    }

    #[test]
    fn crossing_conflicts_within_two_seconds_up_to_five_ahead() {
        // Me at the origin heading +x at 10 m/s, my path straight along x (arrival at
        // arclength s after s / 10 s). The other drives +y at 10 m/s and crosses my path at
        // x = 30 m (I get there after 3 s) when `t_cross` s from now.
        let me = me_along_x();
        let path = path_along_x();
        let arrival = arrival_at_10_mps;
        let crossing_at = |t_cross: f64| AgentState {
            x_m: 30.0,
            y_m: -10.0 * t_cross,
            heading_rad: std::f32::consts::FRAC_PI_2,
            velocity_x_mps: 0.0,
            velocity_y_mps: 10.0,
            ..me
        };
        let conflict = |t_cross: f64| {
            let other = crossing_at(t_cross);
            crossing_conflict(&path, 0.0, &me, &[&other], None, arrival)
        };
        // 1.5 s apart (a near miss the old 1 s window let through) and 4.5 s ahead (beyond
        // the old 3 s look-ahead) are conflicts; 3 s apart is not.
        for t in [3.0, 1.5, 4.5] {
            let (gap, v) = conflict(t).unwrap_or_else(|| panic!("no conflict at {t} s"));
            assert!((gap - (30.0 - 4.5)).abs() < 1.0, "gap {gap}");
            assert_eq!(v, 0.0);
        }
        assert_eq!(conflict(6.0), None);
        assert_eq!(conflict(0.0), None, "it is through before I get there");
    }

    /// A crossing agent known to yield is no conflict while it can still stop before my
    /// corridor braking at 7 m/s² after 0.7 s, with 2 m to spare (16.1 m at 10 m/s); closer,
    /// or not known to yield, it is one.
    #[test]
    fn a_yielding_crossing_agent_is_no_conflict_while_it_can_stop() {
        let (me, path) = (me_along_x(), path_along_x());
        // Driving +y at 10 m/s toward my path at x = 30 m, which I reach after 3 s; it gets
        // there 0.5 or 1.1 s before me (a conflict). Its front reaches my corridor (my
        // half-width and 0.5 m) when its centre is 3.7 m from my path: after 21.3 or 15.3 m.
        let far = crossing_y(30.0, -25.0, 10.0);
        let near = crossing_y(30.0, -19.0, 10.0);
        let conflict = |o: &AgentState, yielding: Option<&AgentState>| {
            crossing_conflict(&path, 0.0, &me, &[o], yielding, arrival_at_10_mps)
        };
        assert!(conflict(&far, None).is_some());
        assert_eq!(conflict(&far, Some(&far)), None);
        assert!(conflict(&near, None).is_some());
        assert!(conflict(&near, Some(&near)).is_some(), "too close to stop");
        assert!(
            conflict(&far, Some(&near)).is_some(),
            "another agent yields"
        );
    }

    #[test]
    fn a_plan_that_stops_in_the_way_is_a_conflict_whenever_the_other_comes() {
        // My plan stops with my centre at x = 28 m: my box (4.5 m) then reaches into the way
        // of an agent crossing at x = 30 m, so that agent is a conflict even when it comes
        // long after I get there; a plan that stops at x = 20 m leaves its way free.
        let me = me_along_x();
        let path = path_along_x();
        let crossing_in = |t_cross: f64| AgentState {
            x_m: 30.0,
            y_m: -10.0 * t_cross,
            heading_rad: std::f32::consts::FRAC_PI_2,
            velocity_x_mps: 0.0,
            velocity_y_mps: 10.0,
            ..me
        };
        let other = crossing_in(5.0);
        assert!(crossing_conflict(&path, 0.0, &me, &[&other], None, stops_at(28.0)).is_some());
        assert_eq!(
            crossing_conflict(&path, 0.0, &me, &[&other], None, stops_at(20.0)),
            None
        );
        // Passing through at 20 m/s (never stopping), I have left its way 3.3 s before it
        // comes.
        assert_eq!(
            crossing_conflict(&path, 0.0, &me, &[&other], None, |s: f64| Some(s / 20.0)),
            None
        );
    }

    #[test]
    fn a_fast_crossing_agent_is_not_missed_between_samples() {
        // At 15 m/s across my path at x = 30 m (me there after 3 s), its centre is 3.75 m
        // before my path at 1.5 s and 3.75 m past it at 2 s: outside my corridor (± 2.4 m) at
        // both half-second samples, inside it in between — a conflict all the same.
        let me = me_along_x();
        let path = path_along_x();
        let fast = crossing_y(30.0, -26.25, 15.0);
        assert!(crossing_conflict(&path, 0.0, &me, &[&fast], None, arrival_at_10_mps).is_some());
    }

    #[test]
    fn a_plan_that_stops_just_short_of_the_way_keeps_a_margin() {
        // The other crosses at x = 30 m; my box reaches its box with my centre 3.2 m before
        // (half my length plus half its width). A plan that stops at 26.5 m leaves 0.3 m: not
        // enough (the margin is 2 m); one that stops at 24 m is clear.
        let me = me_along_x();
        let path = path_along_x();
        let other = crossing_y(30.0, -50.0, 10.0);
        assert!(crossing_conflict(&path, 0.0, &me, &[&other], None, stops_at(26.5)).is_some());
        assert_eq!(
            crossing_conflict(&path, 0.0, &me, &[&other], None, stops_at(24.0)),
            None
        );
    }

    #[test]
    fn a_conflict_behind_another_way_stops_me_before_that_way() {
        // A conflict at x = 40 m (an agent crossing there as I arrive), and the way of a second
        // crossing agent at x = 25 m, far away yet: I stop before its way, not in it.
        let me = me_along_x();
        let path = path_along_x();
        let conflict = crossing_y(40.0, -40.0, 10.0);
        let far_way = crossing_y(25.0, 55.0, -5.0);
        let (alone, _) =
            crossing_conflict(&path, 0.0, &me, &[&conflict], None, arrival_at_10_mps).unwrap();
        assert!((alone - (40.0 - 4.5)).abs() < 1.0, "gap {alone}");
        let (both, v) = crossing_conflict(
            &path,
            0.0,
            &me,
            &[&conflict, &far_way],
            None,
            arrival_at_10_mps,
        )
        .unwrap();
        // (Where my front reaches the band around that way: 25 m less half my length and half
        // the band, 0.95 + 0.5 m.)
        assert!((both - (25.0 - 2.25 - 1.45)).abs() < 0.5, "gap {both}");
        assert_eq!(v, 0.0);
        // Without a conflict the far way alone does not stop me.
        assert_eq!(
            crossing_conflict(&path, 0.0, &me, &[&far_way], None, arrival_at_10_mps),
            None
        );
        // An agent driving along my path (in the next lane, inside my corridor) has no
        // crossing way.
        let alongside = AgentState {
            x_m: 20.0,
            y_m: 2.0,
            velocity_x_mps: 3.0,
            ..me
        };
        assert_eq!(crossing_way(&path, 0.0, &me, &alongside, 60.0), None);
    }

    #[test]
    fn a_crossing_way_is_measured_from_my_box_to_its_near_edge_from_either_side() {
        // Rays crossing my path (along x) at x = 30 m at 90°, 60° and 135°, each from 40 m
        // away; at 30° to my path a way is not a crossing one.
        let me = me_along_x();
        let path = path_along_x();
        let ray = |deg: f64| {
            let (sn, cs) = deg.to_radians().sin_cos();
            AgentState {
                x_m: 30.0 - 40.0 * cs,
                y_m: -40.0 * sn,
                heading_rad: deg.to_radians() as f32,
                velocity_x_mps: (5.0 * cs) as f32,
                velocity_y_mps: (5.0 * sn) as f32,
                ..me
            }
        };
        let gap = |deg: f64| crossing_way(&path, 0.0, &me, &ray(deg), 60.0);
        // My box (4.5 × 1.9 m) first touches the band (half 0.95 + 0.5 m) around the ray when
        // my front corner on the ray's near side does: half my length, half the band across
        // my path and half my width along the ray short of the crossing (found in 0.5 m steps).
        let first_touch = |deg: f64| {
            let theta = deg.to_radians();
            30.0 - 2.25 - 1.45 / theta.sin() - 0.95 / theta.tan().abs()
        };
        for deg in [90.0, 60.0, 135.0] {
            let (g, expected) = (gap(deg).unwrap(), first_touch(deg));
            assert!(
                g >= expected - 1e-9 && g < expected + 0.5,
                "{deg}°: {g} vs {expected}"
            );
        }
        assert_eq!(gap(30.0), None);
        assert_eq!(gap(150.0), None);
        // Beyond the limit it is not looked for; my box already in it gives 0.
        assert_eq!(crossing_way(&path, 0.0, &me, &ray(90.0), 20.0), None);
        assert_eq!(crossing_way(&path, 30.0, &me, &ray(90.0), 60.0), Some(0.0));
    }

    #[test]
    fn a_way_too_close_to_stop_before_leaves_the_conflict() {
        // At 10 m/s I need 16.7 m to stop at 3 m/s²: a way 10 m ahead is passed, and I stop
        // for the conflict at 40 m.
        let me = me_along_x();
        let path = path_along_x();
        let conflict = crossing_y(40.0, -40.0, 10.0);
        let near_way = crossing_y(14.5, 55.0, -5.0);
        let (gap, _) = crossing_conflict(
            &path,
            0.0,
            &me,
            &[&conflict, &near_way],
            None,
            arrival_at_10_mps,
        )
        .unwrap();
        assert!((gap - (40.0 - 4.5)).abs() < 1.0, "gap {gap}");
    }

    #[test]
    fn a_follower_is_a_conflict_only_while_it_catches_up() {
        // Me at the origin heading +x at 10 m/s; the other 5 m behind in the next lane over
        // (2 m to the left, inside the corridor: half the widths plus 0.5 m), heading +x.
        let me = me_along_x();
        let path = path_along_x();
        let arrival = arrival_at_10_mps;
        let follower = |speed_mps: f32| AgentState {
            x_m: -5.0,
            y_m: 2.0,
            velocity_x_mps: speed_mps,
            ..me
        };
        let conflict = |v: f32| crossing_conflict(&path, 0.0, &me, &[&follower(v)], None, arrival);
        // Slower or as fast: braking would only bring it closer, so no conflict.
        assert_eq!(conflict(8.0), None);
        assert_eq!(conflict(10.0), None);
        // Faster: it will be alongside ahead of me, so I hold back (a standing obstacle).
        let (gap, v) = conflict(14.0).expect("a faster follower is a conflict");
        assert!(gap < 10.0, "gap {gap}");
        assert_eq!(v, 0.0);
        // The same agent ahead of me and slower still is one (the crossing rule).
        let ahead = AgentState {
            x_m: 8.0,
            ..follower(8.0)
        };
        assert!(crossing_conflict(&path, 0.0, &me, &[&ahead], None, arrival).is_some());
    }

    #[test]
    fn an_agent_alongside_bounds_the_steering_toward_it() {
        let me = me_along_x();
        let at = |x_m: f64, y_m: f64, heading_deg: f32| AgentState {
            x_m,
            y_m,
            heading_rad: heading_deg.to_radians(),
            ..me
        };
        let bounds = |others: &[&AgentState]| side_steer_bounds(&me, 10.0, 10.0, 2.7, others);
        // Parallel, 2.5 m to the left (0.6 m between the boxes): no steering to the left.
        let left = at(1.0, 2.5, 0.0);
        assert_eq!(bounds(&[&left]), Some((f64::NEG_INFINITY, 0.0)));
        // Turned 10° away from me: I may follow it parallel, within 0.5 s.
        let (lo, hi) = bounds(&[&at(1.0, 2.5, 10.0)]).unwrap();
        let expected = ((10f64.to_radians() / 0.5) * 2.7 / 10.0).atan();
        assert_eq!(lo, f64::NEG_INFINITY);
        assert!((hi - expected).abs() < 1e-6);
        // On the right it bounds from below; on both sides both ways.
        let right = at(-2.0, -2.6, 0.0);
        assert_eq!(bounds(&[&right]), Some((0.0, f64::INFINITY)));
        assert_eq!(bounds(&[&left, &right]), Some((0.0, 0.0)));
        // Far enough ahead, far enough to the side or crossing: nobody alongside.
        assert_eq!(bounds(&[&at(8.0, 2.5, 0.0)]), None);
        assert_eq!(bounds(&[&at(0.0, 3.0, 0.0)]), None);
        assert_eq!(bounds(&[&at(0.0, 2.5, 90.0)]), None);
        // 15 m behind in the next lane: counted while it closes on me (at 20 m/s against my
        // 10 it is alongside in 1.5 s), not at my own speed.
        let behind = |speed_mps: f32| AgentState {
            velocity_x_mps: speed_mps,
            velocity_y_mps: 0.0,
            ..at(-15.0, 2.5, 0.0)
        };
        assert_eq!(bounds(&[&behind(10.0)]), None);
        assert_eq!(bounds(&[&behind(20.0)]), Some((f64::NEG_INFINITY, 0.0)));
    }

    #[test]
    fn a_follower_that_could_not_stay_behind_keeps_me_out_of_its_lane() {
        // The rule of the least courteous synthetic B: A may have to brake at up to 7 m/s²
        // after 0.5 s. 13.9 m ahead of its bumper, 10.5 m/s slower: 6.4 m/s², accepted;
        // 12.8 m and 11.3 m/s slower: 8.9 m/s², refused; bumper to bumper, 2 m/s slower,
        // refused too. A follower no faster never is.
        assert!(!cut_in_unsafe(13.9, 10.5));
        assert!(cut_in_unsafe(12.8, 11.3));
        assert!(!cut_in_unsafe(1.0, 0.0));
        assert!(cut_in_unsafe(0.0, 2.0));
        // Me at 12 m/s, turned 5° toward the next lane on my left; A there 17 m behind at
        // 23.3 m/s (a side-swipe of the lane moves; BENCHMARKS.md). In my turned frame A is
        // 4.9 m to the side; in its lane's, 3.6 m (1.7 m between the boxes): in the next
        // lane, and too close for its speed, so I may turn no further toward it.
        let me = AgentState {
            heading_rad: 5f32.to_radians(),
            velocity_x_mps: 12.0 * 5f32.to_radians().cos(),
            velocity_y_mps: 12.0 * 5f32.to_radians().sin(),
            ..me_along_x()
        };
        let a_at = |x_m: f64| AgentState {
            x_m,
            y_m: 3.6,
            velocity_x_mps: 23.3,
            ..me_along_x()
        };
        let (lo, hi) = side_steer_bounds(&me, 12.0, 12.0, 2.7, &[&a_at(-17.3)]).expect("bounded");
        assert_eq!(lo, f64::NEG_INFINITY);
        assert!(hi < 0.0, "turning back parallel to A: {hi}");
        // 40 m behind it needs 2.1 m/s²: room enough, and I may move over.
        assert_eq!(
            side_steer_bounds(&me, 12.0, 12.0, 2.7, &[&a_at(-40.0)]),
            None
        );
        // Two lanes over (7.2 m) it is none of my business.
        let far = AgentState {
            y_m: 7.2,
            ..a_at(-17.3)
        };
        assert_eq!(side_steer_bounds(&me, 12.0, 12.0, 2.7, &[&far]), None);
    }

    #[test]
    fn a_plan_that_slows_down_soon_needs_a_longer_gap() {
        // A plan along x at 10 m/s that stops dead after `stop` steps (points 0.1 s apart,
        // the first a step after the start).
        let plan = |stop: usize| -> Vec<[f64; 2]> {
            (1..=80).map(|k| [k.min(stop) as f64, 0.0]).collect()
        };
        let dt = 0.1;
        assert!((planned_gap_speed_mps(&plan(80), 0, dt).unwrap() - 10.0).abs() < 1e-9);
        // Stopping within 3 s: 0. Stopping at 5 s: beyond the look-ahead, 10 m/s until then
        // (the last window starts at 3 s and ends at 4 s).
        assert_eq!(planned_gap_speed_mps(&plan(25), 0, dt), Some(0.0));
        assert!((planned_gap_speed_mps(&plan(50), 0, dt).unwrap() - 10.0).abs() < 1e-9);
        // Half a window into the stop: half the speed. From later in the plan, it comes closer.
        assert!((planned_gap_speed_mps(&plan(36), 0, dt).unwrap() - 5.0).abs() < 1e-9);
        assert_eq!(planned_gap_speed_mps(&plan(50), 20, dt), Some(0.0));
        // No whole second left: nothing to say.
        assert_eq!(planned_gap_speed_mps(&plan(80)[..10], 0, dt), None);
        assert_eq!(planned_gap_speed_mps(&plan(80), 75, dt), None);

        // Me at 12 m/s, turned 5° toward A in the next lane 40 m behind at 23.3 m/s: at my
        // speed it needs 2.1 m/s² and I may move over. If my plan comes down to 6 m/s, 5.6
        // m/s²: still. Down to 2 m/s: 9.1 m/s², more than the least courteous B asks, and I
        // may not.
        let me = AgentState {
            heading_rad: 5f32.to_radians(),
            velocity_x_mps: 12.0 * 5f32.to_radians().cos(),
            velocity_y_mps: 12.0 * 5f32.to_radians().sin(),
            ..me_along_x()
        };
        let a = AgentState {
            x_m: -40.0,
            y_m: 3.6,
            velocity_x_mps: 23.3,
            ..me_along_x()
        };
        let bounds = |gap_speed: f64| side_steer_bounds(&me, 12.0, gap_speed, 2.7, &[&a]);
        assert_eq!(bounds(12.0), None);
        assert_eq!(bounds(6.0), None);
        let (lo, hi) = bounds(2.0).expect("refused");
        assert_eq!(lo, f64::NEG_INFINITY);
        assert!(hi < 0.0, "turning back parallel to A: {hi}");
        // A plan that speeds up changes nothing (the gap is judged at my speed or below).
        assert_eq!(bounds(30.0), None);
    }

    #[test]
    fn drifting_toward_an_agent_alongside_is_bounded_earlier_and_harder() {
        // Me at 24 m/s heading 6° left of the other, which is 3 m behind on my left.
        let me = me_along_x();
        let rel = -6f64.to_radians();
        let (v, wheelbase) = (24.0, 2.7);
        let toward = v * 6f64.to_radians().sin();
        let half_widths = f64::from(me.width_m);
        let at_clearance = |c: f64| AgentState {
            x_m: -3.0,
            y_m: half_widths + c,
            heading_rad: rel as f32,
            ..me
        };
        let hi = |c: f64| side_steer_bounds(&me, v, v, wheelbase, &[&at_clearance(c)]).map(|b| b.1);
        // The time constant is the one whose drift keeps 0.2 m of the clearance — from beyond
        // 0.8 m (where 0.5 s of drift would take more than the clearance) on, and the closer,
        // the harder the turn away.
        let expected = |c: f64| ((rel / ((c - 0.2) / toward)) * wheelbase / v).atan();
        for c in [1.3, 0.7] {
            assert!((hi(c).unwrap() - expected(c)).abs() < 1e-6, "clearance {c}");
        }
        assert!(expected(0.7) < expected(1.3));
        // Farther than 0.5 s of drift: free. Very close: the shortest time constant, 0.1 s.
        assert_eq!(hi(0.3 + toward * 0.5), None);
        let hardest = ((rel / 0.1) * wheelbase / v).atan();
        assert!((hi(0.25).unwrap() - hardest).abs() < 1e-6);
    }
}
