use super::*;
use scbg_scene::{Lane, MapPoint};

fn lane(y: f64, lane_type: LaneType) -> Lane {
    Lane {
        lane_type,
        polyline: (0..=10)
            .map(|i| MapPoint {
                x_m: 10.0 * f64::from(i),
                y_m: y,
                z_m: 0.0,
            })
            .collect(),
        ..Lane::default()
    }
}

/// A lane heading +y along `x` over `ys` (points 10 m apart).
fn lane_along_y(x: f64, ys: std::ops::RangeInclusive<f64>) -> Lane {
    let n = ((ys.end() - ys.start()) / 10.0).round() as u32;
    Lane {
        lane_type: LaneType::SurfaceStreet,
        polyline: (0..=n)
            .map(|i| MapPoint {
                x_m: x,
                y_m: ys.start() + 10.0 * f64::from(i),
                z_m: 0.0,
            })
            .collect(),
        ..Lane::default()
    }
}

#[test]
fn points_off_the_lane_come_back_and_points_on_it_stay() {
    let map = Map {
        lanes: vec![
            lane(0.0, LaneType::SurfaceStreet),
            lane(3.5, LaneType::Freeway),
        ],
        ..Map::default()
    };
    // One point at a time (no direction, no carried correction).
    let keep = |p: [f64; 2]| {
        let mut plan = [p];
        let moved = LaneSegments::new(&map).keep_near(&mut plan, 0.5);
        (moved, plan[0])
    };
    assert_eq!(keep([5.0, 0.3]), (0, [5.0, 0.3])); // on the first lane: stays
    let (moved, p) = keep([15.0, -2.0]); // 2 m right of it: to 0.5 m
    assert!(moved == 1 && (p[0] - 15.0).abs() < 1e-9 && (p[1] + 0.5).abs() < 1e-9);
    let (moved, p) = keep([25.0, 2.2]); // nearer the second lane (1.3 m): 0.5 m below it
    assert!(moved == 1 && (p[0] - 25.0).abs() < 1e-9 && (p[1] - 3.0).abs() < 1e-9);
    assert_eq!(keep([35.0, -20.0]), (0, [35.0, -20.0])); // out of reach: stays
    // A lane across the plan's way does not count: a plan heading +x drifting onto a
    // lane along y is pulled to the nearest lane along x (out of reach here: unchanged).
    let crossing = Map {
        lanes: vec![lane_along_y(50.0, -50.0..=50.0)],
        ..Map::default()
    };
    let mut p = vec![[48.0, 20.0], [49.0, 20.0], [50.0, 20.0]];
    assert_eq!(LaneSegments::new(&crossing).keep_near(&mut p, 0.5), 0);
    // A bike lane does not count.
    let bike = Map {
        lanes: vec![lane(0.0, LaneType::BikeLane)],
        ..Map::default()
    };
    let mut p = vec![[15.0, -2.0]];
    assert_eq!(LaneSegments::new(&bike).keep_near(&mut p, 0.5), 0);
    assert_eq!(p[0], [15.0, -2.0]);
}

#[test]
fn a_plan_wiggling_to_a_stand_before_a_crossing_road_is_not_pulled_onto_it() {
    // B's lane heads +y along x = 50 and ends at y = 0; the crossing road's lane runs
    // along x at y = 2.5. B's plan comes up its lane and stands just past the stop line,
    // wiggling sideways by half a metre: over two steps it heads along x there.
    let map = Map {
        lanes: vec![
            lane_along_y(50.0, -50.0..=0.0),
            lane(2.5, LaneType::SurfaceStreet),
        ],
        ..Map::default()
    };
    let mut plan: Vec<[f64; 2]> = (0..10).map(|k| [50.0, f64::from(k) - 9.0]).collect();
    plan.extend([
        [50.0, 0.5],
        [50.5, 0.6],
        [51.0, 0.7],
        [50.5, 0.8],
        [50.0, 0.9],
    ]);
    LaneSegments::new(&map).keep_near(&mut plan, 0.25);
    for p in &plan {
        assert!(p[1] < 1.0, "{p:?} pulled toward the crossing road");
    }
    // Its own lane's end pulls the wiggle back toward it instead.
    assert!(plan[11][0] < 50.5 && plan[12][0] < 51.0);
    // The direction over two steps alone would have taken the crossing road's lane.
    let two_step = plan_directions(&[[0.0, 0.5], [0.5, 0.6], [1.0, 0.7]]);
    assert!(two_step[1].is_some_and(|h| h[0] > 0.9));
}

#[test]
fn a_drifting_plan_keeps_its_lane_and_a_lane_change_is_ramped() {
    let mut straight = lane(0.0, LaneType::Freeway);
    straight.polyline.extend((11..=30).map(|i| MapPoint {
        x_m: 10.0 * f64::from(i),
        y_m: 0.0,
        z_m: 0.0,
    }));
    let mut left = straight.clone();
    for p in &mut left.polyline {
        p.y_m = 3.5;
    }
    let map = Map {
        lanes: vec![straight, left],
        ..Map::default()
    };
    let lanes = LaneSegments::new(&map);
    // Drifting 2.2 m left over 8 s, past the middle between the lanes: kept to its lane.
    let mut drift: Vec<[f64; 2]> = (0..80)
        .map(|t| [2.0 * f64::from(t), 2.2 * f64::from(t) / 79.0])
        .collect();
    lanes.keep_near(&mut drift, 0.25);
    assert!(drift.iter().all(|p| p[1] <= 0.25 + 1e-9), "{drift:?}");
    // Drifting on to 3.0 m, clearly into the other lane: kept as a lane change whose
    // points never jump sideways by more than a few decimetres a step.
    let mut change: Vec<[f64; 2]> = (0..80)
        .map(|t| [2.0 * f64::from(t), 3.0 * f64::from(t) / 79.0])
        .collect();
    lanes.keep_near(&mut change, 0.25);
    assert!(change[0][1].abs() < 1e-9 && (change[79][1] - 3.5).abs() <= 0.25 + 1e-9);
    let worst_step = change
        .windows(2)
        .map(|w| (w[1][1] - w[0][1]).abs())
        .fold(0.0, f64::max);
    assert!(worst_step < 0.45, "a sideways step of {worst_step} m");
    // Past the end of its lane a plan goes on along the lane that continues it, never
    // pulled back toward the end it passed.
    let along = |x0: u32, x1: u32| Lane {
        lane_type: LaneType::Freeway,
        polyline: (x0..=x1)
            .map(|i| MapPoint {
                x_m: 10.0 * f64::from(i),
                y_m: 0.0,
                z_m: 0.0,
            })
            .collect(),
        ..Lane::default()
    };
    let chained = Map {
        lanes: vec![along(0, 10), along(10, 30)],
        ..Map::default()
    };
    // (The plan ends just past the joint, so no later switch ramps the correction away.)
    let x = |t: usize| 61.0 + 0.5 * t as f64;
    let mut plan: Vec<[f64; 2]> = (0..80).map(|t| [x(t), 0.6]).collect();
    LaneSegments::new(&chained).keep_near(&mut plan, 0.25);
    for (t, p) in plan.iter().enumerate() {
        assert!(
            (p[0] - x(t)).abs() < 1e-9 && (p[1] - 0.25).abs() < 1e-9,
            "{p:?}"
        );
    }
}

/// A lane along `points` (world frame, m).
fn lane_through(points: impl IntoIterator<Item = [f64; 2]>) -> Lane {
    Lane {
        lane_type: LaneType::SurfaceStreet,
        polyline: points
            .into_iter()
            .map(|[x_m, y_m]| MapPoint { x_m, y_m, z_m: 0.0 })
            .collect(),
        ..Lane::default()
    }
}

/// The distance from `p` to the nearest centre line of `map`.
fn off_centre_m(map: &Map, p: [f64; 2]) -> f64 {
    map.lanes
        .iter()
        .filter_map(|l| {
            let line: Vec<[f64; 2]> = l.polyline.iter().map(|q| [q.x_m, q.y_m]).collect();
            project(&line, p).map(|(_, q, ..)| dist(p, q))
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn a_plan_cutting_across_a_roundabout_goes_on_around_it_at_its_own_progress() {
    // A one-lane ring of radius 20 m, counter-clockwise, drawn as four quarter lanes with no
    // links (they join end to start), and an exit leaving the west point westwards.
    let arc = |from_deg: f64| {
        lane_through((0..=18).map(move |i| {
            let a = (from_deg + 5.0 * f64::from(i)).to_radians();
            [20.0 * a.cos(), 20.0 * a.sin()]
        }))
    };
    let exit_west = lane_through((0..=10).map(|i| [-20.0 - 5.0 * f64::from(i), 0.0]));
    let map = Map {
        lanes: vec![arc(270.0), arc(0.0), arc(90.0), arc(180.0), exit_west],
        ..Map::default()
    };
    let lanes = LaneSegments::new(&map);
    // B enters at the south point heading east, then its plan goes straight on (as a model that
    // never saw a roundabout plans), 8 m/s for 8 s: through the island, out far to the east.
    let raw: Vec<[f64; 2]> = (0..80).map(|t| [0.8 * f64::from(t), -20.0]).collect();
    let mut plan = raw.clone();
    lanes.keep_near(&mut plan, 0.25);
    for p in &plan {
        assert!(off_centre_m(&map, *p) <= 0.25 + 1e-6, "{p:?} left the ring");
    }
    // Never a jump; and once it has left the ring's reach, 0.8 m a step along the road, the
    // plan's own progress. (Before, each point is pulled to the ring's nearest point.)
    for (t, w) in plan.windows(2).enumerate() {
        let step = dist(w[0], w[1]);
        assert!(step <= 0.9, "a step of {step} m at {t}");
        if t >= 40 {
            assert!((step - 0.8).abs() < 0.05, "a step of {step} m at {t}");
        }
    }
    // 63.2 m around the ring from the south point: past the east point, heading north-west.
    let last = plan[79];
    assert!(last[0] > 0.0 && last[1] > 0.0, "{last:?}");
}

#[test]
fn a_route_takes_the_branch_the_plan_heads_for_and_ends_in_the_plans_own_moves() {
    // A lane along x to a fork at x = 50 m: straight on, or a branch bending right to
    // (100, -40). The plan heads straight for the branch's end, off the road from the start.
    let straight_on = lane_through((5..=15).map(|i| [10.0 * f64::from(i), 0.0]));
    let branch = lane_through((0..=10).map(|i| {
        let u = f64::from(i) / 10.0;
        [50.0 + 50.0 * u, -40.0 * u * u]
    }));
    let map = Map {
        lanes: vec![
            lane_through((0..=5).map(|i| [10.0 * f64::from(i), 0.0])),
            straight_on,
            branch,
        ],
        ..Map::default()
    };
    let raw: Vec<[f64; 2]> = (0..80)
        .map(|t| [1.25 * f64::from(t), -0.5 * f64::from(t)])
        .collect();
    let mut plan = raw.clone();
    assert!(LaneSegments::new(&map).keep_near(&mut plan, 0.25) > 0);
    let branch_only = Map {
        lanes: vec![map.lanes[2].clone()],
        ..Map::default()
    };
    assert!(
        off_centre_m(&branch_only, plan[79]) <= 0.25 + 1e-6,
        "{:?}",
        plan[79]
    );
    for w in plan.windows(2) {
        assert!(dist(w[0], w[1]) < 1.5, "a jump {w:?}");
    }

    // Where no lane continues the route, the plan's own moves carry on from its end.
    let short = Map {
        lanes: vec![lane_through((0..=3).map(|i| [10.0 * f64::from(i), 0.0]))],
        ..Map::default()
    };
    let raw: Vec<[f64; 2]> = (0..80)
        .map(|t| [f64::from(t), -0.1 * f64::from(t)])
        .collect();
    let mut plan = raw.clone();
    LaneSegments::new(&short).keep_near(&mut plan, 0.25);
    let left = (0..80).find(|&t| plan[t] != raw[t] && dist(plan[t], raw[t]) > 1.0);
    assert!(left.is_some(), "the plan was never re-drawn");
    // (Up to PAST_END_M past the end, points are kept beside the lane's line carried on.)
    let end = plan
        .iter()
        .position(|p| p[0] > 30.0 + PAST_END_M)
        .expect("the plan passes the lane's end");
    for t in end + 1..80 {
        let (d, r) = (
            [plan[t][0] - plan[t - 1][0], plan[t][1] - plan[t - 1][1]],
            [raw[t][0] - raw[t - 1][0], raw[t][1] - raw[t - 1][1]],
        );
        assert!(
            (d[0] - r[0]).abs() < 1e-9 && (d[1] - r[1]).abs() < 1e-9,
            "step {t}: {d:?} against {r:?}"
        );
    }
    for w in plan.windows(2) {
        assert!(dist(w[0], w[1]) < 1.5, "a jump {w:?}");
    }
}

#[test]
fn a_plan_drifting_off_the_outermost_lane_stays_on_it() {
    // Two lanes; the plan drifts 12 m right of the right lane over 8 s (out of every lane's
    // reach after 6 m): it stays beside the right lane, at the plan's speed.
    let map = Map {
        lanes: vec![
            lane(0.0, LaneType::Undefined),
            lane(3.5, LaneType::Undefined),
        ],
        ..Map::default()
    };
    let raw: Vec<[f64; 2]> = (0..80)
        .map(|t| [1.2 * f64::from(t), -12.0 * (f64::from(t) / 79.0).powi(2)])
        .collect();
    let mut plan = raw.clone();
    LaneSegments::new(&map).keep_near(&mut plan, 0.25);
    for p in &plan {
        assert!(p[1] >= -0.25 - 1e-6 && p[1] <= 0.0 + 1e-6, "{p:?}");
    }
    let travelled: f64 = raw.windows(2).map(|w| dist(w[0], w[1])).sum();
    assert!(
        (plan[79][0] - travelled).abs() < 0.5,
        "{:?} after {travelled} m",
        plan[79]
    );
}

#[test]
fn a_lane_met_side_on_continues_the_route_and_a_far_lane_is_kept_to_afresh() {
    // B's lane ends at (30, 0) beside a lane crossing its way at 55° (a roundabout's ring as
    // highway-env draws it): the route goes on along that lane.
    let (c, s) = (55f64.to_radians().cos(), 55f64.to_radians().sin());
    let ring = lane_through((-10..=80).map(|i| [31.0 + c * f64::from(i), 1.0 + s * f64::from(i)]));
    let map = Map {
        lanes: vec![
            lane_through((0..=3).map(|i| [10.0 * f64::from(i), 0.0])),
            ring,
        ],
        ..Map::default()
    };
    let raw: Vec<[f64; 2]> = (0..80).map(|t| [f64::from(t), 0.0]).collect();
    let mut plan = raw.clone();
    LaneSegments::new(&map).keep_near(&mut plan, 0.25);
    let ring_only = Map {
        lanes: vec![map.lanes[1].clone()],
        ..Map::default()
    };
    for p in &plan[40..] {
        assert!(
            off_centre_m(&ring_only, *p) <= 0.25 + 1e-6,
            "{p:?} off the ring"
        );
    }

    // A junction whose map has no lanes across it: B's lane ends at x = 30 m, the far side's
    // starts at x = 50 m; the plan drifts left 5 cm a step. Past the dead end the plan's own
    // moves carry it across, and from PAST_END_M before the far lane it is kept in lane again.
    let map = Map {
        lanes: vec![
            lane_through((0..=3).map(|i| [10.0 * f64::from(i), 0.0])),
            lane_through((5..=15).map(|i| [10.0 * f64::from(i), 0.0])),
        ],
        ..Map::default()
    };
    let raw: Vec<[f64; 2]> = (0..80)
        .map(|t| [1.2 * f64::from(t), 0.05 * f64::from(t)])
        .collect();
    let mut plan = raw.clone();
    LaneSegments::new(&map).keep_near(&mut plan, 0.25);
    for (t, w) in plan.windows(2).enumerate() {
        let (p, q) = (w[0], w[1]);
        assert!((q[0] - p[0] - 1.2).abs() < 0.01, "step {t}: {p:?} to {q:?}");
        if q[0] > 30.0 + PAST_END_M + 1e-6 && q[0] < 50.0 - PAST_END_M {
            assert!(
                (q[1] - p[1] - 0.05).abs() < 0.06,
                "step {t}: {p:?} to {q:?} in the gap"
            );
        } else {
            assert!(q[1] <= 0.25 + 1e-6, "step {t}: {q:?} not kept");
        }
    }
}

#[test]
fn a_plan_turning_where_the_map_has_no_turn_lane_goes_on_along_its_lane() {
    // A four-way junction of two straight two-lane roads meeting at the origin, lanes running
    // through it with no turn lanes: B's lane heads +y along x = 1.75, the crossing road's
    // eastbound lane runs along y = -1.75.
    let map = Map {
        lanes: vec![
            lane_through((0..=10).map(|i| [1.75, -50.0 + 10.0 * f64::from(i)])),
            lane_through((0..=10).map(|i| [-50.0 + 10.0 * f64::from(i), -1.75])),
            lane_through((0..=10).map(|i| [50.0 - 10.0 * f64::from(i), 1.75])),
        ],
        ..Map::default()
    };
    let lanes = LaneSegments::new(&map);
    // B stands at its stop line (y = -8) and its plan turns right onto the eastbound lane,
    // cutting the corner: 40 points to (2.5, -3), then east along y = -2.5.
    let turn: Vec<[f64; 2]> = (0..80)
        .map(|t| {
            let t = f64::from(t);
            if t < 40.0 {
                [1.75 + 0.75 * t / 40.0, -8.0 + 5.0 * t / 40.0]
            } else {
                [2.5 + 0.5 * (t - 40.0), -3.0 + 0.5 * ((t - 40.0) / 39.0)]
            }
        })
        .collect();
    let travelled: f64 = turn.windows(2).map(|w| dist(w[0], w[1])).sum();
    let mut plan = turn.clone();
    lanes.keep_near(&mut plan, 0.25);
    // It keeps to its own lane, straight on through the junction at the plan's own progress.
    for p in &plan {
        assert!((p[0] - 1.75).abs() <= 0.25 + 1e-6, "{p:?} left B's lane");
    }
    assert!(
        (plan[79][1] - (-8.0 + travelled)).abs() < 0.5,
        "{:?}",
        plan[79]
    );
    // Inside the junction box both roads' lanes lie under B. A plan starting there and heading
    // east starts on the eastbound lane unless B's own heading (+y) is known: then it starts on
    // B's lane and goes on along it.
    let east: Vec<[f64; 2]> = (0..80).map(|t| [1.0 + 0.5 * f64::from(t), -1.6]).collect();
    let mut free = east.clone();
    lanes.keep_near(&mut free, 0.25);
    assert!((free[79][1] + 1.75).abs() <= 0.25 + 1e-6, "{:?}", free[79]);
    let mut from_b = east.clone();
    lanes.keep_near_from(&mut from_b, 0.25, Some(std::f64::consts::FRAC_PI_2));
    for p in &from_b {
        assert!((p[0] - 1.75).abs() <= 0.25 + 1e-6, "{p:?} left B's lane");
    }
}

#[test]
fn a_plan_into_a_linked_lane_keeps_to_the_road_through_the_joint() {
    // A lane along x to the origin, linked to an exit leaving it 40° to the right (a kink a
    // roundabout's exit or a junction's connector makes with its lanes sampled coarsely). The
    // plan goes straight on: kept, each point lies within the offset of a centre line (a lane
    // change there would have been ramped over 3 s, off both lanes).
    let mut approach = lane_through((0..=5).map(|i| [-50.0 + 10.0 * f64::from(i), 0.0]));
    approach.id = 1;
    approach.exit_lanes = vec![2];
    let (c, s) = (40f64.to_radians().cos(), 40f64.to_radians().sin());
    let mut exit =
        lane_through((0..=10).map(|i| [5.0 * c * f64::from(i), -5.0 * s * f64::from(i)]));
    exit.id = 2;
    let map = Map {
        lanes: vec![approach, exit],
        ..Map::default()
    };
    let mut plan: Vec<[f64; 2]> = (0..80).map(|t| [-20.0 + 0.5 * f64::from(t), 0.0]).collect();
    LaneSegments::new(&map).keep_near(&mut plan, 0.25);
    for p in &plan {
        // (Up to PAST_END_M past its end, a point is kept beside the approach carried on.)
        let beside_approach = p[0] <= PAST_END_M && p[1].abs() <= 0.25 + 1e-6;
        assert!(
            beside_approach || off_centre_m(&map, *p) <= 0.25 + 1e-6,
            "{p:?} off the road"
        );
    }
}
