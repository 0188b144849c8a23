//! The target's lane path (`AgentSample::lane_path_xy_m`) on scenes whose lanes are known
//! (synthetic) and on the shared real WOMD scenes.

mod common;

use scbg_features::{
    FeatureConfig, LANE_PATH_BEHIND_M, LANE_PATH_SPACING_M, PairConfig, PreparedScene,
    SampleBuilder, WindowConfig, marginal_targets,
};
use scbg_synth::Family;

/// Offset (left positive) of a target-frame point from the sample's lane path, at the nearest
/// valid path point.
fn offset_from_path(path: &[f32], valid: &[bool], p: [f32; 2]) -> Option<f32> {
    let k = (0..valid.len() - 1)
        .filter(|&k| valid[k] && valid[k + 1])
        .min_by(|&i, &j| {
            let d = |k: usize| (path[2 * k] - p[0]).powi(2) + (path[2 * k + 1] - p[1]).powi(2);
            d(i).total_cmp(&d(j))
        })?;
    let (a, b) = (
        [path[2 * k], path[2 * k + 1]],
        [path[2 * k + 2], path[2 * k + 3]],
    );
    let t = [b[0] - a[0], b[1] - a[1]];
    let len = (t[0] * t[0] + t[1] * t[1]).sqrt();
    Some(((p[1] - a[1]) * t[0] - (p[0] - a[0]) * t[1]) / len)
}

/// Synthetic scene `index` of data seed 11 drawn from `families`, and its prepared form.
fn synthetic(index: u64, families: &[Family]) -> (scbg_synth::Generated, PreparedScene) {
    let g = scbg_synth::generate(11, index, families);
    let p = PreparedScene::from_scene(
        &g.scene,
        &WindowConfig::default(),
        &PairConfig::default(),
        4,
    )
    .unwrap();
    (g, p)
}

/// In every synthetic family (the left turn's and the zipper's too) A has a lane path starting on A (A drives its lane's centre),
/// 5 m apart along the lane for at least 150 m; in a cut-in scene, where B starts one lane to A's right or ahead
/// in A's lane, B's offset from A's path is −1 or 0 lane widths although the road curves.
#[test]
fn synthetic_targets_have_their_lane_and_b_its_offset_from_it() {
    let features = FeatureConfig {
        lane_path: true,
        ..Default::default()
    };
    let mut cutin_offsets = Vec::new();
    // The default world's families, then left turns and zippers (drawn only when asked for).
    let scenes = (0..40)
        .map(|i| (i, &Family::DEFAULT[..]))
        .chain((0..8).map(|i| (i, &[Family::Leftturn][..])))
        .chain((0..8).map(|i| (i, &[Family::Zipper][..])));
    for (index, families) in scenes {
        let (g, p) = synthetic(index, families);
        let w = p.windows[0];
        let a = p.tracks.iter().position(|t| t.id == g.truth.a_id).unwrap();
        let b = p.tracks.iter().position(|t| t.id == g.truth.b_id).unwrap();
        let s = SampleBuilder::new(&p, &features)
            .sample(&w, a, Some(b))
            .unwrap();
        let (path, valid) = (&s.lane_path_xy_m, &s.lane_path_valid);
        let at_a = (LANE_PATH_BEHIND_M / LANE_PATH_SPACING_M) as usize;
        // 150 m ahead at least: a roundabout's exit arm ends 120 m beyond its ring.
        assert!(
            valid[at_a..at_a + 30].iter().all(|&v| v),
            "{}: {valid:?}",
            p.scenario_id
        );
        let (x, y) = (path[2 * at_a], path[2 * at_a + 1]);
        // (Where an entry joins a roundabout's ring, the joining lane may be the nearest, up to
        // 0.7 m beside the ring's.)
        assert!(
            x.abs() < 0.5 && y.abs() < 0.7,
            "{}: A's path point {x}, {y}",
            p.scenario_id
        );
        for k in at_a..at_a + 29 {
            let step = ((path[2 * k + 2] - path[2 * k]).powi(2)
                + (path[2 * k + 3] - path[2 * k + 1]).powi(2))
            .sqrt();
            // Chords of 5 m of lane: up to 0.15 m short on a roundabout's tight arcs.
            let tolerance_m = if g.truth.family == Family::Roundabout {
                0.15
            } else {
                0.05
            };
            assert!((step - LANE_PATH_SPACING_M).abs() < tolerance_m, "{step}");
        }
        if g.truth.family == Family::Cutin {
            // B at the current step (the first condition point is one step later).
            let first = [s.condition_future_xy_m[0], s.condition_future_xy_m[1]];
            cutin_offsets.push(offset_from_path(path, valid, first).unwrap());
        }
    }
    assert!(cutin_offsets.len() >= 4, "{cutin_offsets:?}");
    for o in &cutin_offsets {
        let lanes = o / 3.6;
        assert!(
            (lanes + 1.0).abs() < 0.25 || lanes.abs() < 0.25,
            "B's offset {o} m is neither one lane right nor in A's lane"
        );
    }
}

/// On the shared real scenes, most moving vehicles have a lane path, starting within 4 m of
/// them; the share is printed (`--nocapture`).
#[test]
fn most_moving_real_vehicles_have_a_lane_path() {
    let Some(scenes) = common::real_prepared_scenes() else {
        return; // real_data_dir said why (and fails under CI)
    };
    let future_steps = WindowConfig::default().future_steps;
    let features = FeatureConfig {
        lane_path: true,
        ..Default::default()
    };
    let at_a = (LANE_PATH_BEHIND_M / LANE_PATH_SPACING_M) as usize;
    let (mut moving, mut with_path) = (0usize, 0usize);
    for prepared in &scenes {
        let mut builder = SampleBuilder::new(prepared, &features);
        for w in &prepared.windows {
            for target in marginal_targets(prepared, w, future_steps, 1) {
                let s = builder.sample(w, target, None).unwrap();
                let [vx, vy] = s.current_velocity_mps;
                if (vx * vx + vy * vy).sqrt() < 3.0 {
                    continue;
                }
                moving += 1;
                if s.lane_path_valid.iter().any(|&v| v) {
                    with_path += 1;
                    let (x, y) = (s.lane_path_xy_m[2 * at_a], s.lane_path_xy_m[2 * at_a + 1]);
                    assert!((x * x + y * y).sqrt() <= 4.0 + 1e-3, "{x}, {y}");
                }
            }
        }
    }
    let share = with_path as f64 / moving.max(1) as f64;
    println!(
        "real moving vehicles with a lane path: {with_path} of {moving} ({:.1} %)",
        100.0 * share
    );
    assert!(moving > 100 && share > 0.8, "{with_path} of {moving}");
}

/// The lanes beside a path (`AgentSample::lane_path_beside`): on the cut-in's two-lane road A
/// has B's lane on its right and none on its left; in a let-in scene B, on a one-lane main
/// road, has no lane on its left, and on its right only the acceleration lane (where the ramp
/// runs beside it), not the gore before it nor the road after the merge.
#[test]
fn the_lanes_beside_a_path_are_the_roads_own() {
    let features = FeatureConfig {
        lane_path: true,
        ..Default::default()
    };
    let (mut cutins, mut letins) = (0, 0);
    for index in 0..40 {
        let (g, p) = synthetic(index, &Family::DEFAULT);
        let w = p.windows[0];
        let track = |id| p.tracks.iter().position(|t| t.id == id).unwrap();
        let at_a = (LANE_PATH_BEHIND_M / LANE_PATH_SPACING_M) as usize;
        let mut builder = SampleBuilder::new(&p, &features);
        match g.truth.family {
            Family::Cutin => {
                let s = builder.sample(&w, track(g.truth.a_id), None).unwrap();
                for k in at_a..at_a + 10 {
                    assert_eq!(s.lane_path_beside[k], [false, true], "{}", p.scenario_id);
                }
                cutins += 1;
            }
            Family::Letin => {
                let s = builder.sample(&w, track(g.truth.b_id), None).unwrap();
                let valid: Vec<[bool; 2]> = (0..s.lane_path_valid.len())
                    .filter(|&k| s.lane_path_valid[k])
                    .map(|k| s.lane_path_beside[k])
                    .collect();
                assert!(valid.iter().all(|b| !b[0]), "{}", p.scenario_id);
                // Right: one stretch (the acceleration lane and taper), none before or after.
                let right: Vec<bool> = valid.iter().map(|b| b[1]).collect();
                let first = right
                    .iter()
                    .position(|&r| r)
                    .expect("the acceleration lane");
                let after = first + right[first..].iter().take_while(|&&r| r).count();
                assert!(
                    first > 0 && after < right.len(),
                    "{}: {right:?}",
                    p.scenario_id
                );
                assert!(
                    right[after..].iter().all(|&r| !r),
                    "{}: {right:?}",
                    p.scenario_id
                );
                // At least the 20 m acceleration lane, at most it with the taper (≤ 200 m).
                let metres = (after - first) as f32 * LANE_PATH_SPACING_M;
                assert!(
                    (15.0..=200.0).contains(&metres),
                    "{}: {metres} m",
                    p.scenario_id
                );
                letins += 1;
            }
            _ => {}
        }
    }
    assert!(
        cutins >= 3 && letins >= 3,
        "{cutins} cut-ins, {letins} let-ins"
    );
}
