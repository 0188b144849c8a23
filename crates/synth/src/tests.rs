//! Determinism, physics and the courtesy → A-speed relation over many scenarios.

use super::*;
use scbg_scene::Lane;

fn spearman(x: &[f64], y: &[f64]) -> f64 {
    scbg_metrics::spearman(x, y).expect("non-constant series")
}

fn distance_to_lane(lane: &Lane, x: f64, y: f64) -> f64 {
    lane.polyline
        .windows(2)
        .map(|w| {
            let (ax, ay, bx, by) = (w[0].x_m, w[0].y_m, w[1].x_m, w[1].y_m);
            let (dx, dy) = (bx - ax, by - ay);
            let l2 = dx * dx + dy * dy;
            let t = if l2 > 0.0 {
                (((x - ax) * dx + (y - ay) * dy) / l2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (ax + t * dx - x).hypot(ay + t * dy - y)
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn deterministic_for_a_seed() {
    let a = generate(7, 3, &Family::ALL);
    let b = generate(7, 3, &Family::ALL);
    assert_eq!(a.scene, b.scene);
    assert_eq!(a.truth, b.truth);
    assert_ne!(generate(8, 3, &Family::ALL).scene, a.scene);
    a.scene.validate().unwrap();
}

#[test]
fn physics_and_lanes_over_many_scenarios() {
    let mut collisions = 0;
    let n = 1200;
    for i in 0..n {
        let g = generate(11, i, &Family::ALL);
        let s = &g.scene;
        assert_eq!(s.num_steps(), 91);
        collisions += usize::from(g.truth.collision);
        for track in &s.tracks {
            for w in track.states.windows(2) {
                let speed = w[1].speed_mps();
                assert!(
                    speed <= 40.0,
                    "{} track {} speed {speed}",
                    s.scenario_id,
                    track.id
                );
                let ax = (w[1].velocity_x_mps - w[0].velocity_x_mps) / 0.1;
                let ay = (w[1].velocity_y_mps - w[0].velocity_y_mps) / 0.1;
                let acc = ax.hypot(ay);
                assert!(
                    acc <= 8.0,
                    "{} track {} accel {acc}",
                    s.scenario_id,
                    track.id
                );
            }
            if track.object_type == scbg_scene::ObjectType::Vehicle {
                for st in &track.states {
                    let d = s
                        .map
                        .lanes
                        .iter()
                        .map(|l| distance_to_lane(l, st.x_m, st.y_m))
                        .fold(f64::INFINITY, f64::min);
                    assert!(
                        d < 2.5,
                        "{} track {} is {d:.2} m off every lane",
                        s.scenario_id,
                        track.id
                    );
                }
            }
        }
    }
    assert!(
        collisions * 100 <= n as usize * 2,
        "{collisions} A–B collisions in {n} scenarios"
    );
}

#[test]
fn courtesy_raises_a_speed_in_every_family() {
    for family in Family::ALL {
        let (mut c, mut v) = (Vec::new(), Vec::new());
        for i in 0..600 {
            let g = generate(5, i, &[family]);
            c.push(g.truth.courtesy);
            v.push(g.truth.a_avg_speed_mps);
        }
        let rho = spearman(&c, &v);
        eprintln!("{}: spearman(c, A speed) = {rho:.3}", family.name());
        // B decides from the current step on (so that courtesy shows in the future to
        // predict); cut-in's effect on A's speed is the weakest (measured 0.20 at this seed).
        assert!(rho > 0.15, "{}: spearman {rho:.3}", family.name());
    }
}

#[test]
fn family_statistics_report() {
    // The per-family numbers that BENCHMARKS.md quotes (printed), and what they must show: B
    // only ever slows A (A with B no faster than alone, within 0.05 m/s, in every quartile of
    // B's courtesy c), A is faster behind B's top quartile than behind its bottom one, and
    // A–B overlaps stay rare (≤ 3 %).
    for family in Family::ALL {
        let mut bins = [(0.0, 0.0, 0usize); 4];
        let mut coll = 0;
        for i in 0..400 {
            let g = generate(9, i, &[family]);
            let b = ((g.truth.courtesy * 4.0) as usize).min(3);
            bins[b].0 += g.truth.a_avg_speed_mps;
            bins[b].1 += g.truth.a_avg_speed_alone_mps;
            bins[b].2 += 1;
            coll += usize::from(g.truth.collision);
        }
        let means: Vec<(f64, f64)> = bins
            .iter()
            .map(|(v, a, n)| {
                assert!(*n > 0, "{}: an empty courtesy quartile", family.name());
                (v / *n as f64, a / *n as f64)
            })
            .collect();
        let line: Vec<String> = means
            .iter()
            .map(|(v, a)| format!("{v:.2}/{a:.2}"))
            .collect();
        eprintln!(
            "{}: A speed with B / alone by courtesy quartile: {:?}; collisions {coll}/400",
            family.name(),
            line
        );
        for (with_b, alone) in &means {
            assert!(*with_b <= alone + 0.05, "{}: {line:?}", family.name());
        }
        assert!(means[3].0 > means[0].0, "{}: {line:?}", family.name());
        assert!(coll * 100 <= 400 * 3, "{}: {coll}/400", family.name());
    }
}

#[test]
fn oracle_replays_logged_futures_and_psi_true_tracks_courtesy() {
    // The oracle's fidelity: replaying B's logged future reproduces A's logged average
    // speed within 0.2 m/s in ≥ 95 % of the scenes of every family.
    for family in Family::ALL {
        let n = 200;
        let (mut ok, mut worst) = (0, 0.0f64);
        let (mut c, mut psi) = (Vec::new(), Vec::new());
        for i in 0..n {
            let t = generate(13, i, &[family]).truth;
            let err = (t.a_avg_speed_replayed_mps - t.a_avg_speed_mps).abs();
            worst = worst.max(err);
            ok += usize::from(err <= 0.2);
            c.push(t.courtesy);
            psi.push(t.psi_true);
        }
        let share = ok as f64 / n as f64;
        let rho = spearman(&c, &psi);
        eprintln!(
            "{}: replay within 0.2 m/s in {:.1} % (worst {worst:.3} m/s); Spearman(ψ_true, c) {rho:.3}",
            family.name(),
            100.0 * share
        );
        assert!(share >= 0.95, "{}: {share}", family.name());
        assert!(rho > 0.4, "{}: {rho}", family.name());
    }
}

#[test]
fn oracle_scores_any_future_and_rejects_bad_ones() {
    let g = generate(21, 4, &Family::ALL);
    let scenario = Scenario::of_truth(&g.truth).unwrap();
    let b = &g.scene.tracks[1];
    let logged: Vec<[f64; 2]> = b.states[CURRENT_STEP + 1..]
        .iter()
        .map(|s| [s.x_m, s.y_m])
        .collect();
    let oracle = scenario.oracle();
    assert!((oracle.psi_true(&logged).unwrap() - g.truth.psi_true).abs() < 1e-9);
    assert!((scenario.psi_true(&logged).unwrap() - g.truth.psi_true).abs() < 1e-9);
    assert_eq!(
        oracle.psi_true(&logged[1..]),
        Err(OracleError::Steps {
            got: 79,
            expected: 80
        })
    );
    let mut bad = logged.clone();
    bad[7][1] = f64::NAN;
    assert_eq!(oracle.psi_true(&bad), Err(OracleError::NotFinite(7)));
    // A B that stands still where it is now never gets in A's way on a merge or a crossing
    // approach any less than one that moves: its reward differs from the logged one but is a
    // finite speed within the physical range.
    let still = vec![[b.states[CURRENT_STEP].x_m, b.states[CURRENT_STEP].y_m]; 80];
    let v = oracle.a_avg_speed_mps(&still).unwrap();
    assert!(v.is_finite() && (0.0..40.0).contains(&v));
    let mut wrong = g.truth.clone();
    wrong.index += 1;
    assert!(matches!(
        Scenario::of_truth(&wrong),
        Err(OracleError::Mismatch(_))
    ));
}

#[test]
fn closed_loop_world_is_causal_and_replays_the_log() {
    for index in 0..30 {
        let scenario = Scenario::draw(5, index, &Family::ALL);
        let logged = scenario.generate();
        let world = scenario.clone().closed_loop();
        let b_future: Vec<[f64; 2]> = logged.scene.tracks[1].states[CURRENT_STEP + 1..]
            .iter()
            .map(|s| [s.x_m, s.y_m])
            .collect();
        let full = world.tracks(&b_future).unwrap();
        assert_eq!(full.len(), logged.scene.tracks.len());
        // Replaying the whole logged future reproduces A's logged track closely.
        let a_err = full[0]
            .states
            .iter()
            .zip(&logged.scene.tracks[0].states)
            .map(|(p, q)| (p.x_m - q.x_m).hypot(p.y_m - q.y_m))
            .fold(0.0, f64::max);
        assert!(
            a_err < 3.0,
            "{} A off the log by {a_err} m",
            logged.scene.scenario_id
        );
        // A prefix of k steps fixes every agent other than B up to step CURRENT_STEP + k + 1.
        for k in [0, 1, 7, 40] {
            let part = world.tracks(&b_future[..k]).unwrap();
            for (i, (p, f)) in part.iter().zip(&full).enumerate() {
                if i == 1 {
                    continue;
                }
                let last = CURRENT_STEP + k + 1;
                assert_eq!(
                    p.states[..=last],
                    f.states[..=last],
                    "track {i}, prefix {k}"
                );
            }
        }
    }
    let world = Scenario::draw(5, 0, &Family::ALL).closed_loop();
    let mut prefix = crate::BPrefix::default();
    for _ in 0..80 {
        world.push_b(&mut prefix, [0.0, 0.0]).unwrap();
    }
    assert!(world.push_b(&mut prefix, [0.0, 0.0]).is_err());
    assert!(
        world
            .push_b(&mut crate::BPrefix::default(), [0.0, f64::INFINITY])
            .is_err()
    );
    assert!(world.tracks(&vec![[0.0, 0.0]; 81]).is_err());
    assert!(world.tracks(&[[f64::NAN, 0.0]]).is_err());
}

/// The logged vehicles (A, B and the others) stay on the road by the WOSAC definition (signed road-edge distance ≤ 0,
/// road on each edge's left as in WOMD) — the synthetic maps are oriented like real ones.
#[test]
fn logged_agents_are_on_the_road_by_the_wosac_rule() {
    let (mut off, mut total) = (0, 0);
    for index in 0..60 {
        let scene = generate(9, index, &Family::ALL).scene;
        let edges = scbg_metrics::wosac::RoadEdges::new(&scene.map).unwrap();
        let mut scratch = Vec::new();
        // Pedestrians walk on the sidewalks, off the road by definition.
        for track in scene
            .tracks
            .iter()
            .filter(|t| t.object_type == scbg_scene::ObjectType::Vehicle)
        {
            total += 1;
            let (worst, at) = track
                .states
                .iter()
                .enumerate()
                .map(|(t, s)| {
                    (
                        edges.signed_distance([s.x_m as f32, s.y_m as f32, 0.0], &mut scratch),
                        t,
                    )
                })
                .fold((f32::NEG_INFINITY, 0), |a, b| if b.0 > a.0 { b } else { a });
            if worst > 0.0 {
                off += 1;
                let s = &track.states[at];
                eprintln!(
                    "{} track {} off-road by {worst:.2} m at step {at} ({:.1}, {:.1})",
                    scene.scenario_id, track.id, s.x_m, s.y_m
                );
            }
        }
    }
    assert!(
        off * 50 <= total,
        "{off} of {total} vehicle tracks leave the road"
    );
}

#[test]
fn counterfactual_siblings_share_the_history_and_intervene_on_b_only() {
    // Each sibling keeps every track's history, draws B's future from another courtesy, and
    // A reacts to it (A's future is the oracle's reward for that future of B).
    let (mut a_changed, mut scenes, mut b_differs) = (0, 0, 0);
    for index in 0..30 {
        let scenario = Scenario::draw(8, index, &Family::ALL);
        let g = scenario.generate();
        let oracle = scenario.oracle();
        let mut b_futures = Vec::new();
        for k in 0..3 {
            let sib = scenario.counterfactual(k, 3);
            assert_eq!(sib.scenario_id, format!("{}~cf{k}", g.scene.scenario_id));
            assert_eq!(sib.tracks.len(), g.scene.tracks.len());
            assert_eq!(sib.map, g.scene.map);
            for (s, o) in sib.tracks.iter().zip(&g.scene.tracks) {
                assert_eq!(s.id, o.id);
                // Heading and velocity at the current step are central differences (they see
                // step 11); positions up to it and full states before it are the scene's.
                assert_eq!(s.states[..CURRENT_STEP], o.states[..CURRENT_STEP]);
                let (sc, oc) = (&s.states[CURRENT_STEP], &o.states[CURRENT_STEP]);
                assert_eq!((sc.x_m, sc.y_m), (oc.x_m, oc.y_m));
            }
            let b: Vec<[f64; 2]> = sib.tracks[1].states[CURRENT_STEP + 1..]
                .iter()
                .map(|s| [s.x_m, s.y_m])
                .collect();
            let a_speed = a_future_speed(&sib.tracks[0]);
            // A's logged reaction in the sibling is what the oracle says for B's future.
            assert!(
                (oracle.a_avg_speed_mps(&b).unwrap() - a_speed).abs() < 0.25,
                "scene {index} sibling {k}"
            );
            scenes += 1;
            a_changed += usize::from((a_speed - g.truth.a_avg_speed_mps).abs() > 0.05);
            b_futures.push(b);
        }
        b_differs += usize::from(b_futures[0] != b_futures[2]);
    }
    eprintln!(
        "A's future changed in {a_changed} of {scenes} siblings; B's c' 1/6 and 5/6 futures differ in {b_differs} of 30 scenes"
    );
    assert!(b_differs >= 20, "{b_differs}");
    assert!(a_changed * 4 >= scenes, "{a_changed} of {scenes}");
}

#[test]
fn a_replayed_scene_is_what_the_oracle_scores() {
    // Any future of B (here a sibling's, slowed down by a fifth along its way): the replayed
    // scene keeps the history and map, B follows the future, and A's track is the one the
    // oracle scores.
    for index in 0..12 {
        let scenario = Scenario::draw(21, index, &Family::ALL);
        let g = scenario.generate();
        let sib = scenario.counterfactual(0, 3);
        let states = &sib.tracks[1].states;
        let b: Vec<[f64; 2]> = (1..NUM_STEPS - CURRENT_STEP)
            .map(|k| {
                let at = CURRENT_STEP as f64 + 0.8 * k as f64;
                let (i, t) = (at.floor() as usize, at.fract());
                let (p, q) = (&states[i], &states[(i + 1).min(NUM_STEPS - 1)]);
                [p.x_m + t * (q.x_m - p.x_m), p.y_m + t * (q.y_m - p.y_m)]
            })
            .collect();
        let scene = scenario
            .clone()
            .closed_loop()
            .replayed_scene(&b, "rx0")
            .unwrap();
        assert_eq!(scene.scenario_id, format!("{}~rx0", g.scene.scenario_id));
        assert_eq!(scene.map, g.scene.map);
        for (s, o) in scene.tracks.iter().zip(&g.scene.tracks) {
            assert_eq!(s.states[..CURRENT_STEP], o.states[..CURRENT_STEP]);
        }
        for (s, p) in scene.tracks[1].states[CURRENT_STEP + 1..].iter().zip(&b) {
            // B is projected onto its path: within a few centimetres of the future.
            assert!((s.x_m - p[0]).hypot(s.y_m - p[1]) < 0.05, "scene {index}");
        }
        let a_speed = a_future_speed(&scene.tracks[0]);
        let oracle = scenario.oracle();
        assert!(
            (oracle.a_avg_speed_mps(&b).unwrap() - a_speed).abs() < 1e-6,
            "scene {index}"
        );
    }
    let world = Scenario::draw(21, 0, &Family::ALL).closed_loop();
    assert!(world.replayed_scene(&[[0.0, 0.0]; 3], "rx").is_err());
}

#[test]
fn the_worlds_knob_is_the_sibling_and_the_logged_courtesy_is_the_log() {
    for index in 0..12 {
        let scenario = Scenario::draw(21, index, &Family::ALL);
        let g = scenario.generate();
        // B at its own courtesy is the logged scene.
        let own = scenario.tracks_with_courtesy(scenario.courtesy);
        assert_eq!(own.len(), g.scene.tracks.len());
        for (t, o) in own.iter().zip(&g.scene.tracks) {
            assert_eq!(t.id, o.id);
            assert_eq!(t.states, o.states, "scene {index} track {}", t.id);
        }
        // Any other courtesy is the counterfactual sibling at that courtesy.
        let sib = scenario.counterfactual(0, 4);
        let knob = scenario.tracks_with_courtesy(0.125);
        for (t, s) in knob.iter().zip(&sib.tracks) {
            assert_eq!(t.states, s.states, "scene {index} track {}", t.id);
        }
        // Outside the prior it is clamped.
        assert_eq!(
            scenario.tracks_with_courtesy(7.0)[1].states,
            scenario.tracks_with_courtesy(1.0)[1].states
        );
    }
}

/// The step-wise world (each step simulates only the steps so far) gives, at every step of a
/// closed loop, exactly the states the whole-scene re-simulation gives there.
#[test]
fn step_wise_world_equals_the_whole_scene_replay() {
    for index in 0..12 {
        let scenario = Scenario::draw(9, index, &Family::ALL);
        let logged = scenario.generate();
        let world = scenario.clone().closed_loop();
        // B's logged future bent sideways and slowed: a future the log never had.
        let b_future: Vec<[f64; 2]> = logged.scene.tracks[1].states[CURRENT_STEP + 1..]
            .iter()
            .enumerate()
            .map(|(k, s)| [s.x_m - 0.02 * k as f64, s.y_m + 0.01 * k as f64])
            .collect();
        let mut prefix = crate::BPrefix::default();
        for k in 0..b_future.len() {
            let whole = world.tracks(&b_future[..k]).unwrap();
            let step = CURRENT_STEP + k + 1;
            let next = world.next_states(&prefix);
            assert_eq!(next.len(), whole.len());
            for (i, (n, w)) in next.iter().zip(&whole).enumerate() {
                assert_eq!(*n, w.states[step], "scene {index}, track {i}, prefix {k}");
            }
            world.push_b(&mut prefix, b_future[k]).unwrap();
            assert_eq!(prefix.len(), k + 1);
        }
    }
}

#[test]
fn courtesy_orders_a_speed_within_a_roundabout_scene_either_way_round() {
    // The world's own knob, paired within a scene: B circulating and letting A in, and B
    // entering ahead of or after a circulating A, each moves A's speed with the courtesy in
    // many scenes and orders it there (measured 0.74 and 0.83 over 400 scenes of seed 31).
    let qs = [0.1, 0.3, 0.5, 0.7, 0.9];
    for b_circulates in [true, false] {
        let (mut rho_sum, mut responsive, mut n) = (0.0, 0, 0);
        for i in 0..160 {
            let scenario = Scenario::draw(31, i, &[Family::Roundabout]);
            let Params::Roundabout(p) = &scenario.params else {
                unreachable!("a roundabout scene")
            };
            if p.b_circulates() != b_circulates {
                continue;
            }
            n += 1;
            let speeds: Vec<f64> = qs
                .iter()
                .map(|&q| a_future_speed(&scenario.tracks_with_courtesy(q)[0]))
                .collect();
            let (lo, hi) = speeds
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                    (l.min(v), h.max(v))
                });
            if hi - lo > 0.05 {
                responsive += 1;
                rho_sum += spearman(&qs, &speeds);
            }
        }
        let rho = rho_sum / responsive.max(1) as f64;
        eprintln!(
            "roundabout, B circulates {b_circulates}: {responsive} of {n} respond, Spearman {rho:.3}"
        );
        assert!(responsive * 3 >= n, "{responsive} of {n}");
        assert!(rho > 0.6, "{rho:.3}");
    }
}
