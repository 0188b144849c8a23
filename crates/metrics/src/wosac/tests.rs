use std::f32::consts::PI;

use scbg_scene::{
    AgentState, Lane, LaneType, Map, MapPoint, ObjectType, PredictionTarget, RoadEdge, Scene,
    SignalLaneState, SignalState, Track,
};

use super::estimators::{BERNOULLI, HistogramSpec};
use super::geometry::{box_corners, rounded_box_distance, signed_distance_between_quads};
use super::interaction::{TtcBox, time_to_collision};
use super::kinematics::{central_difference, kinematic_features, wrap_angle};
use super::road_edge::RoadEdges;
use super::traffic_light::TrafficLights;
use super::*;

fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn wrap_angle_is_floor_modulo_into_minus_pi_pi() {
    assert_eq!(wrap_angle(0.0), 0.0);
    assert_eq!(wrap_angle(PI), -PI);
    assert_eq!(wrap_angle(-PI), -PI);
    assert!(close(wrap_angle(1.5 * PI), -0.5 * PI, 1e-6));
    assert!(close(wrap_angle(-1.5 * PI), 0.5 * PI, 1e-6));
    assert!(close(wrap_angle(7.0), 7.0 - 2.0 * PI, 1e-6));
    assert!(wrap_angle(f32::NAN).is_nan());
}

#[test]
fn central_difference_pads_with_nan() {
    let d = central_difference(&[0.0, 1.0, 4.0, 9.0]);
    assert!(d[0].is_nan() && d[3].is_nan());
    assert_eq!(&d[1..3], &[2.0, 4.0]);
}

#[test]
fn kinematics_of_a_straight_line_and_a_wrapping_heading() {
    // 10 m/s along a 3-4-5 direction with a slope, heading turning at 0.5 rad/s across ±π.
    let n = 12;
    let x: Vec<f32> = (0..n).map(|t| 0.6 * t as f32).collect();
    let y: Vec<f32> = (0..n).map(|t| 0.8 * t as f32).collect();
    let z = vec![3.0f32; n];
    let h: Vec<f32> = (0..n)
        .map(|t| wrap_angle(PI - 0.1 + 0.05 * t as f32))
        .collect();
    let k = kinematic_features(&x, &y, &z, &h, 0.1);
    assert!(k.speed_mps[0].is_nan() && k.speed_mps[n - 1].is_nan());
    for t in 1..n - 1 {
        assert!(close(k.speed_mps[t], 10.0, 1e-4), "{}", k.speed_mps[t]);
        assert!(
            close(k.angular_speed_radps[t], 0.5, 1e-4),
            "{}",
            k.angular_speed_radps[t]
        );
    }
    for t in [0, 1, n - 2, n - 1] {
        assert!(k.acceleration_mps2[t].is_nan());
        assert!(k.angular_acceleration_radps2[t].is_nan());
    }
    for t in 2..n - 2 {
        assert!(close(k.acceleration_mps2[t], 0.0, 1e-2));
        assert!(close(k.angular_acceleration_radps2[t], 0.0, 1e-2));
    }
}

#[test]
fn histogram_edges_bins_and_pseudocounts() {
    let spec = HistogramSpec::new(0.0, 25.0, 10, 0.1);
    let edges = spec.edges();
    assert_eq!(edges.len(), 11);
    assert_eq!(edges[0], 0.0);
    assert_eq!(edges[1], 2.5);
    assert_eq!(edges[10], 25.0);
    assert_eq!(spec.bin(&edges, 0.0), 0);
    assert_eq!(spec.bin(&edges, -3.0), 0); // clipped
    assert_eq!(spec.bin(&edges, 2.4999), 0);
    assert_eq!(spec.bin(&edges, 2.5), 1); // an edge belongs to the bin above
    assert_eq!(spec.bin(&edges, 24.9), 9);
    assert_eq!(spec.bin(&edges, 25.0), 9); // max is in the last bin
    assert_eq!(spec.bin(&edges, 1e10), 9); // clipped
    assert_eq!(spec.bin(&edges, f32::NAN), 9); // NaN into the last bin
    assert_eq!(spec.bin(&edges, f32::NEG_INFINITY), 0);

    // Counts [2, 0, ..., 0, 1 (NaN)]: p = (c + 0.1) / (3 + 1).
    let ln_p = spec.log_probabilities(&edges, [1.0, 2.0, f32::NAN]);
    assert!(close(ln_p[0], (2.1f32 / 4.0).ln(), 1e-6));
    assert!(close(ln_p[1], (0.1f32 / 4.0).ln(), 1e-6));
    assert!(close(ln_p[9], (1.1f32 / 4.0).ln(), 1e-6));

    // Non-round edges keep float32 arithmetic: e_k = min + k·δ.
    let spec = HistogramSpec::new(-0.628, 0.628, 11, 0.1);
    let edges = spec.edges();
    let delta = (0.628f32 - -0.628f32) / 11.0;
    assert_eq!(edges[3], -0.628 + 3.0 * delta);
    assert_eq!(edges[11], 0.628);

    // Bernoulli: P(b) = (count_b + 0.001) / (32 + 0.002).
    let edges = BERNOULLI.edges();
    let ln_p = BERNOULLI.log_probabilities(&edges, (0..32).map(|k| if k < 8 { 1.0 } else { 0.0 }));
    assert!(close(ln_p[1], (8.001f32 / 32.002).ln(), 1e-6));
    assert!(close(ln_p[0], (24.001f32 / 32.002).ln(), 1e-6));
}

#[test]
fn likelihood_of_identical_log_and_sims() {
    let log: Vec<f32> = (0..SIMULATED_STEPS).map(|f| f as f32 * 0.1).collect();
    let sims: Vec<&[f32]> = vec![&log; 32];
    let mask = vec![true; SIMULATED_STEPS];
    let spec = HistogramSpec::new(0.0, 25.0, 10, 0.1);
    // Values 0..7.9: 25 in bin 0, 25 in bin 1, 25 in bin 2, 5 in bin 3.
    let l = estimators::time_series_likelihood(spec, &log, &sims, &mask, 1);
    let p = |c: f32| (32.0 * c + 0.1) / (2560.0 + 1.0);
    let expected = ((75.0 * p(25.0).ln() + 5.0 * p(5.0).ln()) / 80.0).exp();
    assert!(close(l, expected, 1e-6), "{l} vs {expected}");
    // An empty mask gives NaN, as officially.
    let none = vec![false; SIMULATED_STEPS];
    assert!(estimators::time_series_likelihood(spec, &log, &sims, &none, 1).is_nan());
    // Indicators: identical log and sims give (32.001 / 32.002).
    let l = estimators::indicator_likelihood(&[true, false], &vec![vec![true, false]; 32]);
    assert!(close(l, 32.001 / 32.002, 1e-7));
}

#[test]
fn rounded_box_distances_by_hand() {
    // 4 × 2 boxes: rounding radius 0.7, cores 2.6 × 0.6.
    let car = |x, y, h| [x, y, 4.0, 2.0, h];
    // Aligned, 10 m apart lengthwise: gap 10 − 4 = 6.
    assert!(close(
        rounded_box_distance(car(0.0, 0.0, 0.0), car(10.0, 0.0, 0.0)),
        6.0,
        1e-5
    ));
    // Overlapping cores by 1.1 lengthwise and 0.6 sideways: penetration 0.6 → −0.6 − 1.4.
    assert!(close(
        rounded_box_distance(car(0.0, 0.0, 0.0), car(1.5, 0.0, 0.0)),
        -2.0,
        1e-5
    ));
    // Cores disjoint but rounded boxes overlapping: core gap 0.4 → 0.4 − 1.4 = −1.
    assert!(close(
        rounded_box_distance(car(0.0, 0.0, 0.0), car(3.0, 0.0, 0.0)),
        -1.0,
        1e-5
    ));
    // Diagonal: core corners (1.3, 0.3) and (8.7, 9.7).
    let diag = (7.4f32 * 7.4 + 9.4 * 9.4).sqrt() - 1.4;
    assert!(close(
        rounded_box_distance(car(0.0, 0.0, 0.0), car(10.0, 10.0, 0.0)),
        diag,
        1e-5
    ));
    // Rotated by 90°, 5 m to the left: core spans y ∈ [3.7, 6.3]; gap 3.4 − 1.4 = 2.
    let d = rounded_box_distance(car(0.0, 0.0, 0.0), car(0.0, 5.0, PI / 2.0));
    assert!(close(d, 2.0, 1e-5), "{d}");
    // Symmetric, and invariant under a common rotation and translation.
    let d2 = rounded_box_distance(car(0.0, 5.0, PI / 2.0), car(0.0, 0.0, 0.0));
    assert!(close(d, d2, 1e-5));
    let (s, c) = 0.7f32.sin_cos();
    let moved =
        |[x, y, l, w, h]: [f32; 5]| [100.0 + c * x - s * y, -50.0 + s * x + c * y, l, w, h + 0.7];
    let d3 = rounded_box_distance(moved(car(0.0, 0.0, 0.0)), moved(car(0.0, 5.0, PI / 2.0)));
    assert!(close(d, d3, 1e-4), "{d3}");
    // 2 × 2 squares (r = 0.7, cores 0.6 × 0.6), the second turned 45° at x = 3: its core
    // vertex reaches x = 3 − 0.3·√2.
    let sq = |x, h| [x, 0.0, 2.0, 2.0, h];
    let expected = 3.0 - 0.3 * 2f32.sqrt() - 0.3 - 1.4;
    let d = rounded_box_distance(sq(0.0, 0.0), sq(3.0, PI / 4.0));
    assert!(close(d, expected, 1e-5), "{d} vs {expected}");
}

#[test]
fn penetration_depth_of_rotated_overlap() {
    // Unit square and a square turned 45° whose vertex pokes 0.2 into it from the right.
    let a = box_corners(0.0, 0.0, 2.0, 2.0, 0.0);
    let half_diag = 2f32.sqrt();
    let b = box_corners(1.0 + half_diag - 0.2, 0.0, 2.0, 2.0, PI / 4.0);
    let d = signed_distance_between_quads(&a, &b);
    assert!(close(d, -0.2, 1e-5), "{d}");
    let b = box_corners(1.0 + half_diag + 0.3, 0.0, 2.0, 2.0, PI / 4.0);
    assert!(close(signed_distance_between_quads(&a, &b), 0.3, 1e-5));
    // Fully inside: penetration = distance to escape through the nearest side.
    let small = box_corners(0.5, 0.0, 0.4, 0.4, 0.0);
    assert!(close(signed_distance_between_quads(&a, &small), -0.7, 1e-5));
}

fn point(x: f64, y: f64) -> MapPoint {
    MapPoint {
        x_m: x,
        y_m: y,
        z_m: 0.0,
    }
}

fn square_map() -> Map {
    // Counter-clockwise square: the road (inside) is on the left of the travel direction.
    let square = [
        (0.0, 0.0),
        (10.0, 0.0),
        (10.0, 10.0),
        (0.0, 10.0),
        (0.0, 0.0),
    ];
    Map {
        road_edges: vec![RoadEdge {
            id: 1,
            polyline: square.iter().map(|&(x, y)| point(x, y)).collect(),
            ..Default::default()
        }],
        ..Default::default()
    }
}

#[test]
fn road_edge_sign_on_a_square() {
    let edges = RoadEdges::new(&square_map()).unwrap();
    let mut scratch = Vec::new();
    let mut d = |x, y, z| edges.signed_distance([x, y, z], &mut scratch);
    assert!(close(d(5.0, 5.0, 0.0), -5.0, 1e-6)); // on-road, inside
    assert!(close(d(9.0, 1.0, 0.0), -1.0, 1e-6));
    assert!(close(d(5.0, -2.0, 0.0), 2.0, 1e-6)); // off-road, right of the first edge
    assert!(close(d(12.0, -2.0, 0.0), 8f32.sqrt(), 1e-6)); // beyond a convex vertex
    assert!(close(d(-1.0, 11.0, 0.0), 2f32.sqrt(), 1e-6)); // beyond the closing vertex
    assert!(close(d(-1.0, -1.0, 0.0), 2f32.sqrt(), 1e-6)); // at the wrap-around vertex
    // z enters the selection only (stretched by 3), not the reported distance.
    assert!(close(d(5.0, 5.0, 1.0), -5.0, 1e-6));

    // An open polyline has no successor: the sign past its end is the segment's own side.
    let open = Map {
        road_edges: vec![RoadEdge {
            id: 2,
            polyline: vec![point(0.0, 0.0), point(10.0, 0.0)],
            ..Default::default()
        }],
        ..Default::default()
    };
    let edges = RoadEdges::new(&open).unwrap();
    let mut d = |x, y, z| edges.signed_distance([x, y, z], &mut scratch);
    assert!(close(d(12.0, -1.0, 0.0), 5f32.sqrt(), 1e-6));
    assert!(close(d(12.0, 1.0, 0.0), -(5f32.sqrt()), 1e-6));

    // The z stretch picks the edge at the object's height over a closer one 1 m below.
    let two = Map {
        road_edges: vec![
            RoadEdge {
                id: 3,
                polyline: vec![
                    MapPoint {
                        x_m: 0.0,
                        y_m: -1.0,
                        z_m: -1.0,
                    },
                    MapPoint {
                        x_m: 10.0,
                        y_m: -1.0,
                        z_m: -1.0,
                    },
                ],
                ..Default::default()
            },
            RoadEdge {
                id: 4,
                polyline: vec![point(10.0, 2.0), point(0.0, 2.0)],
                ..Default::default()
            },
        ],
        ..Default::default()
    };
    let edges = RoadEdges::new(&two).unwrap();
    // Selection: √(1 + 9) = 3.16 to the lower edge, 2 to the other; reported: 2, left → −2.
    assert!(close(
        edges.signed_distance([5.0, 0.0, 0.0], &mut scratch),
        -2.0,
        1e-6
    ));

    assert!(RoadEdges::new(&Map::default()).is_none());
}

#[test]
fn road_edge_index_matches_brute_force() {
    // A long wiggly cyclic polyline and a few short ones; the chunked search must pick the
    // same segment as a full scan for points all over the map.
    let mut edges = Vec::new();
    let ring: Vec<MapPoint> = (0..=200)
        .map(|k| {
            let a = k as f64 / 200.0 * std::f64::consts::TAU;
            let r = 80.0 + 6.0 * (7.0 * a).sin();
            MapPoint {
                x_m: 1000.0 + r * a.cos(),
                y_m: -500.0 + r * a.sin(),
                z_m: 0.3 * (3.0 * a).cos(),
            }
        })
        .collect();
    edges.push(RoadEdge {
        id: 0,
        polyline: ring,
        ..Default::default()
    });
    for j in 0..5 {
        let line = (0..30)
            .map(|k| MapPoint {
                x_m: 950.0 + 3.0 * k as f64,
                y_m: -520.0 + 10.0 * j as f64 + (k as f64 * 0.7).sin(),
                z_m: 0.0,
            })
            .collect();
        edges.push(RoadEdge {
            id: j + 1,
            polyline: line,
            ..Default::default()
        });
    }
    let map = Map {
        road_edges: edges,
        ..Default::default()
    };
    let index = RoadEdges::new(&map).unwrap();
    let mut scratch = Vec::new();
    let brute = |p: [f32; 3]| {
        // Reference: every segment, first on ties.
        let mut best = (f32::INFINITY, 0.0f32);
        for e in &map.road_edges {
            for w in e.polyline.windows(2) {
                let a = [w[0].x_m as f32, w[0].y_m as f32, w[0].z_m as f32];
                let b = [w[1].x_m as f32, w[1].y_m as f32, w[1].z_m as f32];
                let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                let ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
                let len2 = d[0] * d[0] + d[1] * d[1];
                let t = if len2 > 0.0 {
                    (ap[0] * d[0] + ap[1] * d[1]) / len2
                } else {
                    0.0
                };
                let t = t.clamp(0.0, 1.0);
                let r = [ap[0] - t * d[0], ap[1] - t * d[1], 3.0 * (ap[2] - t * d[2])];
                let d3 = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
                if d3 < best.0 {
                    best = (d3, (r[0] * r[0] + r[1] * r[1]).sqrt());
                }
            }
        }
        best.1
    };
    for k in 0..2000 {
        let a = k as f32 * 0.618;
        let r = (k % 97) as f32 * 1.3;
        let p = [
            1000.0 + r * a.cos(),
            -500.0 + r * a.sin(),
            0.1 * (k % 5) as f32,
        ];
        let got = index.signed_distance(p, &mut scratch).abs();
        assert!(close(got, brute(p), 1e-4), "{p:?}: {got} vs {}", brute(p));
    }
}

#[test]
fn time_to_collision_two_cars() {
    let car = |x: f32, y: f32, heading: f32, speed: f32| TtcBox {
        x_m: x,
        y_m: y,
        length_m: 4.0,
        width_m: 2.0,
        heading_rad: heading,
        speed_mps: speed,
        valid: true,
    };
    // Ego at 10 m/s, car 20 m ahead at 5 m/s: gap 20 − 2 − 2 = 16 m, closing at 5 m/s.
    let ttc = time_to_collision(0, &[car(0.0, 0.0, 0.0, 10.0), car(20.0, 0.0, 0.0, 5.0)]);
    assert!(close(ttc, 3.2, 1e-5), "{ttc}");
    // The ego's index does not matter.
    let ttc = time_to_collision(1, &[car(20.0, 0.0, 0.0, 5.0), car(0.0, 0.0, 0.0, 10.0)]);
    assert!(close(ttc, 3.2, 1e-5));
    // Far away: capped at 5 s.
    assert_eq!(
        time_to_collision(0, &[car(0.0, 0.0, 0.0, 10.0), car(200.0, 0.0, 0.0, 5.0)]),
        5.0
    );
    // Faster car ahead, car behind, car in the next lane, car turned 80°, invalid car: 5 s.
    for other in [
        car(20.0, 0.0, 0.0, 15.0),
        car(-20.0, 0.0, 0.0, 0.0),
        car(20.0, 3.0, 0.0, 0.0),
        car(20.0, 0.0, 80f32.to_radians(), 0.0),
        TtcBox {
            valid: false,
            ..car(20.0, 0.0, 0.0, 0.0)
        },
    ] {
        assert_eq!(
            time_to_collision(0, &[car(0.0, 0.0, 0.0, 10.0), other]),
            5.0,
            "{other:?}"
        );
    }
    // Small lateral overlap (< 0.5 m) counts only when nearly aligned (≤ 10°).
    let ego = car(0.0, 0.0, 0.0, 10.0);
    let slight = car(20.0, 1.7, 0.0, 5.0); // lateral overlap 0.3 m, aligned
    assert!(close(time_to_collision(0, &[ego, slight]), 3.2, 1e-5));
    // Turned 20°: lateral offset 2·sin 20° + cos 20° = 1.624, overlap 0.3 m at y = 2.324.
    let turned = car(20.0, 2.324, 20f32.to_radians(), 5.0);
    assert_eq!(time_to_collision(0, &[ego, turned]), 5.0);
    // The nearer of two cars in front sets the time; a NaN speed gives 5 s.
    let ttc = time_to_collision(
        0,
        &[ego, car(30.0, 0.0, 0.0, 0.0), car(14.0, 0.0, 0.0, 8.0)],
    );
    assert!(close(ttc, 5.0f32.min(10.0 / 2.0), 1e-5));
    let ttc = time_to_collision(
        0,
        &[ego, car(10.0, 0.0, 0.0, 0.0), car(14.0, 0.0, 0.0, 8.0)],
    );
    assert!(close(ttc, 6.0 / 10.0, 1e-5));
    assert_eq!(
        time_to_collision(0, &[ego, car(10.0, 0.0, 0.0, f32::NAN)]),
        5.0
    );
    // Unwrapped heading difference: headings π − 0.01 and −π + 0.01 are nearly aligned, but
    // the official code sees a difference of ~2π and ignores the car.
    let a = car(0.0, 0.0, PI - 0.01, 10.0);
    let b = car(-20.0, 0.0, -PI + 0.01, 0.0);
    assert_eq!(time_to_collision(0, &[a, b]), 5.0);
}

/// One synthetic track: id, type and the (x, y) centre at each of the 91 steps.
type TrackSpec = (i64, ObjectType, Vec<(f64, f64)>);

/// A 91-step scene of valid 4.5 × 2 m boxes heading +x (velocities from forward differences)
/// between two straight road edges at y = ±5, with one surface-street lane along y = 0; track 0
/// is the SDC and track 1 a track to predict.
fn scene_with(tracks: Vec<TrackSpec>) -> Scene {
    let tracks: Vec<Track> = tracks
        .into_iter()
        .map(|(id, object_type, xy)| Track {
            id,
            object_type,
            states: xy
                .iter()
                .enumerate()
                .map(|(t, &(x, y))| {
                    let (vx, vy) = if t + 1 < xy.len() {
                        ((xy[t + 1].0 - x) * 10.0, (xy[t + 1].1 - y) * 10.0)
                    } else {
                        (0.0, 0.0)
                    };
                    AgentState {
                        x_m: x,
                        y_m: y,
                        z_m: 0.0,
                        length_m: 4.5,
                        width_m: 2.0,
                        height_m: 1.5,
                        heading_rad: 0.0,
                        velocity_x_mps: vx as f32,
                        velocity_y_mps: vy as f32,
                        valid: true,
                    }
                })
                .collect(),
        })
        .collect();
    Scene {
        scenario_id: "synthetic".into(),
        timestamps_secs: (0..SCENARIO_STEPS).map(|t| t as f64 * 0.1).collect(),
        current_step: CURRENT_STEP,
        sdc_track_index: Some(0),
        tracks,
        tracks_to_predict: vec![PredictionTarget {
            track_index: 1,
            difficulty: Default::default(),
        }],
        map: Map {
            road_edges: vec![
                RoadEdge {
                    id: 100,
                    polyline: vec![point(-100.0, -5.0), point(300.0, -5.0)],
                    ..Default::default()
                },
                RoadEdge {
                    id: 101,
                    polyline: vec![point(300.0, 5.0), point(-100.0, 5.0)],
                    ..Default::default()
                },
            ],
            lanes: vec![Lane {
                id: 7,
                lane_type: LaneType::SurfaceStreet,
                polyline: (0..=20).map(|k| point(10.0 * k as f64, 0.0)).collect(),
                ..Default::default()
            }],
            ..Default::default()
        },
        ..Default::default()
    }
}

fn straight(x0: f64, speed: f64) -> Vec<(f64, f64)> {
    (0..SCENARIO_STEPS)
        .map(|t| (x0 + speed * 0.1 * t as f64, 0.0))
        .collect()
}

#[test]
fn traffic_light_violation_on_a_synthetic_crossing() {
    // Car 0 drives through x = 50 between steps 29 and 30 (10 m/s from x = 20.5); a STOP
    // signal on lane 7 with its stop point at x = 50.
    let mut scene = scene_with(vec![
        (1, ObjectType::Vehicle, straight(20.5, 10.0)),
        (2, ObjectType::Vehicle, straight(-80.0, 5.0)),
    ]);
    let signal = |state| SignalLaneState {
        lane_id: 7,
        state,
        stop_point: Some(point(50.0, 0.0)),
    };
    let run = |scene: &Scene| -> Vec<bool> {
        let lights = TrafficLights::new(scene);
        let track = &scene.tracks[0];
        let x: Vec<f32> = track.states.iter().map(|s| s.x_m as f32).collect();
        let y: Vec<f32> = track.states.iter().map(|s| s.y_m as f32).collect();
        let valid: Vec<bool> = track.states.iter().map(|s| s.valid).collect();
        lights.violations(&x, &y, &valid).collect()
    };
    scene.signals_per_step = vec![vec![signal(SignalState::Stop)]; SCENARIO_STEPS];
    let v = run(&scene);
    let hits: Vec<usize> = (0..SIMULATED_STEPS).filter(|&f| v[f]).collect();
    assert_eq!(
        hits,
        vec![30 - FIRST_FUTURE_STEP],
        "crossing at global step 30"
    );

    // Green, or flashing red: no violation. Red arrow: violation.
    for (state, expected) in [
        (SignalState::Go, false),
        (SignalState::FlashingStop, false),
        (SignalState::ArrowStop, true),
    ] {
        scene.signals_per_step = vec![vec![signal(state)]; SCENARIO_STEPS];
        assert_eq!(run(&scene).contains(&true), expected, "{state:?}");
    }
    // A signal on a lane that is not a surface street does not count.
    scene.signals_per_step = vec![vec![signal(SignalState::Stop)]; SCENARIO_STEPS];
    scene.map.lanes[0].lane_type = LaneType::Freeway;
    assert!(!run(&scene).contains(&true));
    // No signal states at all: never a violation.
    scene.map.lanes[0].lane_type = LaneType::SurfaceStreet;
    scene.signals_per_step.clear();
    assert!(!run(&scene).contains(&true));
}

#[test]
fn ids_baselines_and_errors_on_a_synthetic_scene() {
    let mut scene = scene_with(vec![
        (5, ObjectType::Vehicle, straight(0.0, 10.0)),
        (3, ObjectType::Vehicle, straight(-30.0, 10.0)),
        (9, ObjectType::Pedestrian, straight(100.0, 1.0)),
    ]);
    // Track 9 is not valid at the current step: not a sim agent.
    scene.tracks[2].states[CURRENT_STEP].valid = false;
    assert_eq!(sim_agent_ids(&scene), vec![5, 3]);
    assert_eq!(evaluated_agent_ids(&scene), vec![3, 5]);

    let log = log_replay_rollouts(&scene, ROLLOUTS_PER_SCENARIO).unwrap();
    let m = scenario_metrics(&scene, &log, WosacConfig::V2025).unwrap();
    assert_eq!(m.average_displacement_error_m, 0.0);
    assert_eq!(m.simulated_collision_rate, 0.0);
    assert_eq!(m.simulated_offroad_rate, 0.0);
    assert!(close(
        m.likelihoods.collision_indication,
        32.001 / 32.002,
        1e-6
    ));
    assert!(m.metametric > 0.5 && m.metametric <= 1.0, "{m:?}");
    let w: f32 = WosacConfig::V2025.weights().iter().sum();
    assert!(close(w, 1.0, 1e-6));
    let w: f32 = WosacConfig::V2024.weights().iter().sum();
    assert!(close(w, 1.0, 1e-6));

    // Constant velocity reproduces these straight lines: ADE ≈ 0.
    let cv = constant_velocity_rollouts(&scene, ROLLOUTS_PER_SCENARIO).unwrap();
    let m2 = scenario_metrics(&scene, &cv, WosacConfig::V2024).unwrap();
    assert!(m2.average_displacement_error_m < 1e-4, "{m2:?}");
    let agg = aggregate(&[m.clone(), m2.clone()], WosacConfig::V2025).unwrap();
    assert_eq!(agg.num_scenarios, 2);
    assert!(close(
        agg.metametric,
        (m.metametric + m2.metametric) / 2.0,
        1e-6
    ));
    assert!(aggregate(&[], WosacConfig::V2025).is_none());

    // Errors name the problem.
    let err = |r: &Rollouts| scenario_metrics(&scene, r, WosacConfig::V2025).unwrap_err();
    let mut r = log.clone();
    r.trajectories.pop();
    assert_eq!(err(&r), WosacError::RolloutCount { got: 31 });
    let mut r = log.clone();
    r.trajectories[4][1].pop();
    assert_eq!(
        err(&r),
        WosacError::StepCount {
            rollout: 4,
            object_id: 3,
            got: 79
        }
    );
    let mut r = log.clone();
    r.object_ids[1] = 5;
    assert_eq!(err(&r), WosacError::DuplicateObject { object_id: 5 });
    let mut r = log.clone();
    r.object_ids[1] = 9;
    assert_eq!(err(&r), WosacError::UnknownObject { object_id: 9 });
    let mut r = log.clone();
    r.object_ids.pop();
    assert_eq!(err(&r), WosacError::MissingObject { object_id: 3 });
    let mut r = log.clone();
    r.trajectories[2][0][7].heading_rad = f32::NAN;
    assert_eq!(
        err(&r),
        WosacError::NonFinite {
            rollout: 2,
            object_id: 5,
            step: 7,
            field: "heading"
        }
    );
    let mut r = log.clone();
    r.trajectories[0].pop();
    assert!(matches!(
        err(&r),
        WosacError::TrajectoryCount { rollout: 0, .. }
    ));
    assert!(err(&r).to_string().contains("rollout 0"));

    let mut no_edges = scene.clone();
    no_edges.map.road_edges.clear();
    assert!(matches!(
        scenario_metrics(&no_edges, &log, WosacConfig::V2025),
        Err(WosacError::NoRoadEdges { .. })
    ));
    let mut short = scene.clone();
    short.timestamps_secs.pop();
    assert!(matches!(
        log_replay_rollouts(&short, 1),
        Err(WosacError::SceneLayout { num_steps: 90, .. })
    ));
    let mut not_sim = scene.clone();
    not_sim.tracks_to_predict[0].track_index = 2;
    assert!(matches!(
        scenario_metrics(&not_sim, &log, WosacConfig::V2025),
        Err(WosacError::EvaluatedNotSimulated { object_id: 9, .. })
    ));
    let mut none = scene.clone();
    none.sdc_track_index = None;
    none.tracks_to_predict.clear();
    assert!(matches!(
        scenario_metrics(&none, &log, WosacConfig::V2025),
        Err(WosacError::NoEvaluatedObjects { .. })
    ));
}

/// Official values (§11 of the spec) in [`FeatureLikelihoods::to_array`] order.
struct Reference {
    metametric: f32,
    likelihoods: [f32; 10],
    ade: f32,
    collision_rate: f32,
    offroad_rate: f32,
}

const LOG_REPLAY: Reference = Reference {
    metametric: 0.8266314,
    likelihoods: [
        0.82652855, 0.5305248, 0.48732617, 0.6562856, 0.40035117, 0.99996877, 0.8362134, 0.5591777,
        0.99996877, 0.99996877,
    ],
    ade: 0.0,
    collision_rate: 0.25,
    offroad_rate: 0.0,
};

const CONSTANT_VELOCITY: Reference = Reference {
    metametric: 0.21769527,
    likelihoods: [
        0.075650506,
        0.12974364,
        0.061595537,
        0.3092796,
        0.26297095,
        0.07476451,
        0.64172214,
        0.22063595,
        0.0747645,
        0.99996877,
    ],
    ade: 2.1528234,
    collision_rate: 0.5,
    offroad_rate: 0.25,
};

const NAMES: [&str; 10] = [
    "linear_speed",
    "linear_acceleration",
    "angular_speed",
    "angular_acceleration",
    "distance_to_nearest_object",
    "collision_indication",
    "time_to_collision",
    "distance_to_road_edge",
    "offroad_indication",
    "traffic_light_violation",
];

/// Compares with the official values; returns the largest absolute difference.
fn compare(label: &str, m: &ScenarioMetrics, r: &Reference) -> f32 {
    let mut rows = vec![("metametric", m.metametric, r.metametric)];
    for (k, name) in NAMES.iter().enumerate() {
        rows.push((*name, m.likelihoods.to_array()[k], r.likelihoods[k]));
    }
    rows.push((
        "average_displacement_error",
        m.average_displacement_error_m,
        r.ade,
    ));
    rows.push((
        "min_average_displacement_error",
        m.min_average_displacement_error_m,
        r.ade,
    ));
    rows.push((
        "simulated_collision_rate",
        m.simulated_collision_rate,
        r.collision_rate,
    ));
    rows.push((
        "simulated_offroad_rate",
        m.simulated_offroad_rate,
        r.offroad_rate,
    ));
    let mut worst = 0.0f32;
    println!(
        "{label}: {:<32} {:>12} {:>12} {:>10}",
        "field", "ours", "official", "diff"
    );
    for (name, ours, official) in rows {
        let diff = (ours - official).abs();
        worst = worst.max(if diff.is_nan() { f32::INFINITY } else { diff });
        println!("{label}: {name:<32} {ours:>12.8} {official:>12.8} {diff:>10.2e}");
    }
    worst
}

#[test]
fn reference_values_of_scenario_637f20cafde22ff8() {
    let Some(dir) = scbg_womd::fixtures::real_data_dir() else {
        return;
    };
    let path = dir.join("womd/motion_data_one_scenario.tfrecord");
    let file = scbg_womd::WomdFile::open(&path).unwrap();
    let scene = file.scenes().next().unwrap().unwrap();
    assert_eq!(scene.scenario_id, "637f20cafde22ff8");
    assert_eq!(sim_agent_ids(&scene).len(), 50);
    assert_eq!(evaluated_agent_ids(&scene), vec![1675, 1676, 2320, 2406]);

    let mut worst = 0.0f32;
    for (label, rollouts, reference) in [
        (
            "log replay",
            log_replay_rollouts(&scene, ROLLOUTS_PER_SCENARIO).unwrap(),
            &LOG_REPLAY,
        ),
        (
            "constant velocity",
            constant_velocity_rollouts(&scene, ROLLOUTS_PER_SCENARIO).unwrap(),
            &CONSTANT_VELOCITY,
        ),
    ] {
        let start = std::time::Instant::now();
        let m = scenario_metrics(&scene, &rollouts, WosacConfig::V2025).unwrap();
        println!(
            "{label}: scenario_metrics took {:.1} ms (1 scenario × 32 rollouts, 1 thread)",
            start.elapsed().as_secs_f64() * 1e3
        );
        worst = worst.max(compare(label, &m, reference));
        let b = m.buckets;
        println!(
            "{label}: buckets kinematic {:.6} interactive {:.6} map-based {:.6}",
            b.kinematic, b.interactive, b.map_based
        );
        let m24 = scenario_metrics(&scene, &rollouts, WosacConfig::V2024).unwrap();
        println!(
            "{label}: 2024 config metametric {:.7}, time to collision {:.7}",
            m24.metametric, m24.likelihoods.time_to_collision
        );
    }
    println!("largest absolute difference to the official values: {worst:.2e}");
    assert!(worst < 1e-6, "largest difference {worst}");
}
