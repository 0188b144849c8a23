//! The guard's rules on hand-built geometry.

use scbg_scene::AgentState;
use scbg_synth::RefPath;

use super::crossing::*;
use super::side::*;
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
    // 23.3 m/s (a side-swipe of the lane moves; docs/findings.md, *The safety guard, rule by
    // rule*). In my turned frame A is 4.9 m to the side; in its lane's, 3.6 m (1.7 m between
    // the boxes): in the next lane, and too close for its speed, so I may turn no further
    // toward it.
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
    let plan =
        |stop: usize| -> Vec<[f64; 2]> { (1..=80).map(|k| [k.min(stop) as f64, 0.0]).collect() };
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
