//! Steering bounds beside another agent, and gap acceptance: none toward the lane of a
//! follower that could not stay behind, judged at the speed the plan comes down to.

use scbg_scene::AgentState;
use scbg_synth::{CUT_IN_REACTION_S, LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2};

/// Lateral clearance below which an agent alongside bounds the steering, m (more while I drift
/// toward it: see [`SIDE_ALIGN_S`]).
pub(super) const SIDE_CLEARANCE_M: f64 = 0.8;
/// Time constant in which the bounded steering turns the agent parallel to the one alongside,
/// s. The yaw rate toward parallel is the relative heading over it, re-set every step, so the
/// turn decays exponentially and the agent drifts `v_lat ·` this much sideways on the way, with
/// `v_lat` its lateral speed toward the other: while drifting, the time is shortened so the
/// drift keeps [`SIDE_KEEP_M`] of the clearance (down to [`SIDE_MIN_ALIGN_S`]), and the bound
/// starts where the drift of the full time would take more than the clearance. (A B at 24 m/s
/// moving over at 6° toward A, 3 m ahead of it, was bounded at 0.7 m and drifted 1.2 m into it;
/// docs/findings.md, *The safety guard, rule by rule*.)
pub(super) const SIDE_ALIGN_S: f64 = 0.5;
/// The least alignment time constant, s (a yaw rate the bicycle's steering reaches in ~0.1 s).
pub(super) const SIDE_MIN_ALIGN_S: f64 = 0.1;
/// Clearance the bounded drift toward an agent alongside leaves, m.
pub(super) const SIDE_KEEP_M: f64 = 0.2;
/// An agent behind that catches up counts as alongside from as far back as it closes in this
/// many seconds (a slow B at 13 m/s moving over into the lane of A coming up at 24 m/s was hit
/// from behind-left, A's centre 1.6 m behind B's: bounded only once A was alongside, B was
/// already in its way; docs/findings.md, *The safety guard, rule by rule*).
pub(super) const SIDE_CATCH_UP_S: f64 = 3.0;
/// A catching-up agent whose box overlaps mine sideways by more than this is behind me in my
/// lane, not in the next one, m.
pub(super) const SIDE_SAME_LANE_M: f64 = 0.5;
/// An agent whose box is less than this far from mine sideways is in the next lane, m (two
/// cars about 2 m wide in lanes 3.5–3.7 m apart are 1.5–1.8 m apart; two lanes over, 5 m).
pub(super) const NEXT_LANE_CLEARANCE_M: f64 = 2.5;

/// Whether moving in front of a follower that is `gap_m` behind my rear bumper and closes on
/// me at `closing_mps` would ask it to brake harder than the synthetic world's least
/// courteous B asks of A ([`LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2`], after its
/// [`CUT_IN_REACTION_S`]; MOBIL's safety criterion) to stay behind me: the constant
/// deceleration that matches my speed in the gap left after its reaction,
/// `Δv² / 2 (gap − Δv·t_r)`.
pub(super) fn cut_in_unsafe(gap_m: f64, closing_mps: f64) -> bool {
    if closing_mps <= 0.0 {
        return false;
    }
    let room_m = (gap_m - closing_mps * CUT_IN_REACTION_S).max(0.1);
    closing_mps * closing_mps / (2.0 * room_m) > LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2
}

/// How far ahead a plan's slowing counts for gap acceptance, s: the 1 s windows of
/// [`planned_gap_speed_mps`] start at most this long after now (so they reach 4 s ahead).
pub(super) const PLAN_SLOWING_S: f64 = 3.0;
/// The window over which a plan's speed is averaged for [`planned_gap_speed_mps`], steps (1 s:
/// a sampled future's points carry noise that single steps would read as speed).
pub(super) const PLAN_SPEED_WINDOW_STEPS: usize = 10;

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
pub(super) fn refused_gap(me: &AgentState, o: &AgentState, closing_mps: f64) -> Option<f64> {
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
        // was side-swiped; docs/findings.md, *The safety guard, rule by rule*) — behind me as
        // my plan slows me down, too (a B merging 30 m ahead of A, then stopping at the end of
        // the ramp, was run into).
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
