//! Tests on whole scenes: a synthetic one (ids, baselines, errors, traffic lights) and the
//! genuine reference scenario of the spec (§11).

use scbg_scene::{
    AgentState, Lane, LaneType, Map, ObjectType, PredictionTarget, RoadEdge, Scene,
    SignalLaneState, SignalState, Track,
};

use super::reference::{CONSTANT_VELOCITY, LOG_REPLAY, Reference, SCENARIO_ID};
use super::tests::{close, point};
use super::traffic_light::TrafficLights;
use super::*;

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

/// Compares with the official values; returns the largest absolute difference.
fn compare(label: &str, m: &ScenarioMetrics, r: &Reference) -> f32 {
    let mut worst = 0.0f32;
    println!(
        "{label}: {:<32} {:>12} {:>12} {:>10}",
        "field", "ours", "official", "diff"
    );
    for (name, ours, official) in r.compare(m) {
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
    assert_eq!(scene.scenario_id, SCENARIO_ID);
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
