use std::f32::consts::PI;

use scbg_scene::{Map, MapPoint, RoadEdge};

use super::estimators::{BERNOULLI, HistogramSpec};
use super::geometry::{box_corners, rounded_box_distance, signed_distance_between_quads};
use super::interaction::{TtcBox, time_to_collision};
use super::kinematics::{central_difference, kinematic_features, wrap_angle};
use super::road_edge::RoadEdges;
use super::*;

pub(super) fn close(a: f32, b: f32, tol: f32) -> bool {
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

pub(super) fn point(x: f64, y: f64) -> MapPoint {
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
