//! The closed-loop API through the library: rollouts, exports, the evaluation, sample and rank.

use scbg::choices::Courtesy;
use scbg::generate;
use scbg_lab::generator;

/// Sample and rank through the library: the same entry points as the generator, plans equal
/// generations, and a closed-loop rollout driven by it.
pub(crate) fn ranked_policy_in_the_loop(
    mut model: generator::LoadedScbg,
    scene: &scbg_scene::Scene,
    t: &scbg_synth::GroundTruth,
) {
    use scbg::sim::{self, ControlledAgent, SimConfig};
    model.set_policy(scbg::choices::Policy::Ranked);
    let quantiles = [0.0, 1.0].map(|q| Courtesy::quantile(q).unwrap());
    // The tiny model's labels draw 2 futures of B: the two ends take one each. On a map without
    // road edges both count (with them, an untrained sample that leaves the road would not:
    // the runtime's own test covers that rule). Each comes kept in lane, and J_φ of the future
    // returned is the ψ reported as achieved.
    let mut open_map = scene.clone();
    open_map.map.road_edges.clear();
    let out = generate::generate(&model, &open_map, t.a_id, t.b_id, &quantiles).unwrap();
    let [low, high] = [&out.trajectories[0], &out.trajectories[1]];
    assert!(low.psi < high.psi, "{} vs {}", low.psi, high.psi);
    assert_ne!(low.world_xy_m, high.world_xy_m);
    for g in [low, high] {
        let again = generate::courtesy(&model, &open_map, t.a_id, t.b_id, &g.world_xy_m).unwrap();
        assert!((g.achieved_psi - again.psi).abs() < 1e-4);
    }
    let planned = generate::plan(
        &model,
        &open_map,
        t.a_id,
        t.b_id,
        Courtesy::quantile(1.0).unwrap(),
    )
    .unwrap();
    assert_eq!(kept_in_lane(&open_map, planned), high.world_xy_m);
    let b = [ControlledAgent {
        id: t.b_id,
        courtesy: Courtesy::quantile(0.9).unwrap(),
    }];
    let config = SimConfig {
        others: sim::OthersMode::Reactive,
        ..SimConfig::default()
    };
    let rolled = sim::rollout(&model, scene, Some(t.a_id), &b, config, Some(t)).unwrap();
    rolled.validate().unwrap();
    let ib = rolled.track_index(t.b_id).unwrap();
    assert!(rolled.tracks[ib].states[11..].iter().all(|s| s.valid));
    // Shared first plans (the labelled futures of B, chosen by rank): the same rollouts.
    let shared = sim::FirstPlans::default();
    for q in [0.1, 0.9] {
        let b = [ControlledAgent {
            id: t.b_id,
            courtesy: Courtesy::quantile(q).unwrap(),
        }];
        assert_eq!(
            sim::rollout_sharing(&model, scene, Some(t.a_id), &b, config, Some(t), &shared)
                .unwrap(),
            sim::rollout(&model, scene, Some(t.a_id), &b, config, Some(t)).unwrap(),
            "quantile {q}"
        );
    }
    assert_eq!(shared.len(), 1);
}

/// The closed-loop API on a trained (tiny) model: plans equal generations, a rollout in the
/// synthetic world, its metrics, both exports read back, the evaluation, and bad requests.
pub(crate) fn closed_loop_through_the_library(
    model: &generator::LoadedScbg,
    scene: &scbg_scene::Scene,
    t: &scbg_synth::GroundTruth,
    dir: &std::path::Path,
) {
    use scbg::sim::{self, ControlledAgent, SimConfig};
    // The planner's fast path gives the future `generate` gives, once kept in lane as the
    // closed loop keeps every plan.
    let planned = generate::plan(
        model,
        scene,
        t.a_id,
        t.b_id,
        Courtesy::quantile(0.7).unwrap(),
    )
    .unwrap();
    let generated = generate::generate(
        model,
        scene,
        t.a_id,
        t.b_id,
        &[Courtesy::quantile(0.7).unwrap()],
    )
    .unwrap();
    assert_eq!(
        kept_in_lane(scene, planned),
        generated.trajectories[0].world_xy_m
    );

    let b = |q: f32| {
        vec![ControlledAgent {
            id: t.b_id,
            courtesy: Courtesy::quantile(q).unwrap(),
        }]
    };
    let config = SimConfig {
        others: sim::OthersMode::Reactive,
        ..SimConfig::default()
    };
    let rolled = sim::rollout(model, scene, Some(t.a_id), &b(0.9), config, Some(t)).unwrap();
    rolled.validate().unwrap();
    assert_eq!(rolled.num_steps(), 91);
    let ib = rolled.track_index(t.b_id).unwrap();
    assert_eq!(
        rolled.tracks[ib].states[..=10],
        scene.tracks[ib].states[..=10]
    );
    assert!(rolled.tracks[ib].states[11..].iter().all(|s| s.valid));
    // Deterministic: the same request gives the same rollout.
    assert_eq!(
        sim::rollout(model, scene, Some(t.a_id), &b(0.9), config, Some(t)).unwrap(),
        rolled
    );
    let report = sim::report(&rolled, t.a_id, &[t.b_id]).unwrap();
    assert_eq!(report.controlled.len(), 1);
    assert!(report.ego.avg_speed_mps > 0.0 && report.ego.valid_steps == 80);

    // Scenario export reads back through the project's reader.
    let file = dir.join("rollouts.tfrecord");
    assert_eq!(
        sim::write_scenarios(&file, std::slice::from_ref(&rolled)).unwrap(),
        1
    );
    let back: Vec<_> = scbg_womd::WomdFile::open(&file)
        .unwrap()
        .scenes()
        .map(Result::unwrap)
        .collect();
    assert_eq!(back.len(), 1);
    for (p, q) in back[0].tracks[ib]
        .states
        .iter()
        .zip(&rolled.tracks[ib].states)
    {
        assert!((p.x_m - q.x_m).abs() < 1e-3 && (p.y_m - q.y_m).abs() < 1e-3);
    }
    // WOSAC shards: 32 rollouts, every sim agent, decoded back.
    let scenes: Vec<_> = sim::rollout_quantiles(0.5, 32, 0.2)
        .into_iter()
        .map(|q| sim::rollout(model, scene, Some(t.a_id), &b(q), config, Some(t)).unwrap())
        .collect();
    let rollouts = sim::wosac_rollouts(scene, &scenes);
    assert_eq!(rollouts.trajectories.len(), 32);
    // Rollouts that share their first plan (as `scbg eval sim` does) are the same rollouts,
    // with one basis computed for all of them.
    let shared = sim::FirstPlans::default();
    for (q, alone) in sim::rollout_quantiles(0.5, 32, 0.2)
        .into_iter()
        .zip(&scenes)
        .step_by(8)
    {
        let with =
            sim::rollout_sharing(model, scene, Some(t.a_id), &b(q), config, Some(t), &shared)
                .unwrap();
        assert_eq!(&with, alone, "quantile {q}");
    }
    assert_eq!(shared.len(), 1);
    let paths = sim::write_wosac(
        &dir.join("wosac"),
        "scbg-test",
        &scbg_womd::wosac::SubmissionHeader::default(),
        &[(scene.clone(), rollouts.clone())],
        1,
    )
    .unwrap();
    assert!(paths[0].ends_with("scbg-test.binproto-00000-of-00001"));
    let (_, decoded) =
        scbg_womd::wosac::decode_submission(&std::fs::read(&paths[0]).unwrap()).unwrap();
    assert_eq!(decoded[0].joint_scenes.len(), 32);
    assert_eq!(decoded[0].joint_scenes[0].len(), rollouts.object_ids.len());
    let metrics = scbg_metrics::wosac::scenario_metrics(
        scene,
        &rollouts,
        scbg_metrics::wosac::WosacConfig::V2025,
    )
    .unwrap();

    // The evaluation runs end to end on a couple of scenes.
    let sim_scene = scbg_lab::sim_eval::SimScene::of(scene.clone(), Some(t.clone())).unwrap();
    let eval = scbg_lab::sim_eval::evaluate_sim(
        model,
        &[sim_scene],
        &scbg_lab::sim_eval::SimEvalOptions {
            quantiles: vec![0.1, 0.9],
            wosac_quantiles: vec![0.5],
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(eval.curve.per_quantile.len(), 3, "0.5 is added");
    assert_eq!(eval.curve.per_quantile[1].realised_courtesy_mps, 0.0);
    assert!(eval.baselines["log_replay"].wosac.is_some());
    assert!(eval.wosac_scbg.is_some());
    // The 32 rollouts around quantile 0.5 are more realistic than constant velocity on the
    // same scene.
    let cv = eval.baselines["constant_velocity"]
        .wosac
        .as_ref()
        .unwrap()
        .metametric;
    assert!(
        metrics.metametric > cv,
        "scbg {} vs constant velocity {cv}",
        metrics.metametric
    );
    // The knob drawn from its prior is scored too, and both scbg runs are compared with
    // IDM-only scene by scene (one scene: the difference of the two meta-metrics, no spread).
    let idm = eval.baselines["idm_only"]
        .wosac
        .as_ref()
        .unwrap()
        .metametric;
    for (summary, diff) in [
        (&eval.wosac_scbg, &eval.wosac_scbg_minus_idm),
        (&eval.wosac_scbg_prior, &eval.wosac_prior_minus_idm),
    ] {
        let (summary, diff) = (summary.as_ref().unwrap(), diff.as_ref().unwrap());
        assert_eq!((diff.scenes, diff.std_error), (1, 0.0));
        assert!((diff.mean - f64::from(summary.metametric - idm)).abs() < 1e-6);
    }
    assert!(eval.realism_line().contains("knob drawn from its prior"));
    // Every collision of B is listed, with its quantile: as many as the rates say.
    let listed = |curve: &scbg_lab::sim_eval::KnobCurve| {
        for row in &curve.per_quantile {
            let n = curve
                .b_collisions
                .iter()
                .filter(|c| c.quantile == row.quantile && c.contact.step >= 1)
                .count();
            assert_eq!(n as f64, row.b_collision_rate * curve.scenes as f64);
        }
    };
    listed(&eval.curve);
    listed(eval.world_knob.as_ref().unwrap());
    // The world's own knob on the same scene: B at courtesy c = q by the world's rule, A's
    // realised speed what the oracle says for that future of B.
    let world = eval
        .world_knob
        .as_ref()
        .expect("a synthetic scene has the world's knob");
    assert_eq!((world.scenes, world.per_quantile.len()), (1, 3));
    assert_eq!(world.per_quantile[1].realised_courtesy_mps, 0.0);
    let scenario = scbg_synth::Scenario::of_truth(t).unwrap();
    let b_future: Vec<[f64; 2]> = scenario.tracks_with_courtesy(0.9)[1].states[11..]
        .iter()
        .map(|s| [s.x_m, s.y_m])
        .collect();
    let oracle_speed = scenario.oracle().a_avg_speed_mps(&b_future).unwrap();
    assert!(
        (world.per_quantile[2].a_avg_speed_mps - oracle_speed).abs() < 0.25,
        "{} vs the oracle's {oracle_speed}",
        world.per_quantile[2].a_avg_speed_mps
    );
    scbg_lab::sim_eval::write_figures(&eval, &dir.join("sim_figures")).unwrap();
    assert!(dir.join("sim_figures/sim_courtesy.png").is_file());

    // A genuine WOMD scene: IDM world on a real map, every sim agent in the WOSAC rollouts.
    if let Some(real) = scbg_womd::fixtures::real_data_dir() {
        let file = real.join("womd/motion_data_one_scenario.tfrecord");
        let womd = scbg_womd::WomdFile::open(&file).unwrap();
        let scene = womd.scenes().next().unwrap().unwrap();
        let a = scene.tracks[scene.sdc_track_index.unwrap()].id;
        let b_id = scene.tracks[scene.tracks_to_predict[0].track_index].id;
        let controlled = [ControlledAgent {
            id: b_id,
            courtesy: Courtesy::quantile(0.5).unwrap(),
        }];
        let rolled = sim::rollout(model, &scene, Some(a), &controlled, config, None).unwrap();
        rolled.validate().unwrap();
        let rollouts = sim::wosac_rollouts(&scene, &vec![rolled; 32]);
        assert_eq!(
            rollouts.object_ids,
            scbg_metrics::wosac::sim_agent_ids(&scene)
        );
        let m = scbg_metrics::wosac::scenario_metrics(
            &scene,
            &rollouts,
            scbg_metrics::wosac::WosacConfig::V2025,
        )
        .unwrap();
        assert!(m.metametric > 0.3, "{}", m.metametric);
    }

    // Bad requests name what is wrong and are the caller's fault.
    let bad = |r: anyhow::Result<scbg_scene::Scene>, needle: &str| {
        let e = r.unwrap_err();
        assert!(scbg::is_invalid_request(&e), "{e:#}");
        assert!(format!("{e:#}").contains(needle), "{e:#} lacks {needle}");
    };
    // A quantile outside [0, 1] cannot even be asked (the runtime's `Courtesy` checks it).
    assert!(
        Courtesy::quantile(1.5)
            .unwrap_err()
            .0
            .contains("quantile 1.5")
    );
    let unknown = vec![ControlledAgent {
        id: 4242,
        courtesy: Courtesy::quantile(0.5).unwrap(),
    }];
    bad(
        sim::rollout(model, scene, Some(t.a_id), &unknown, config, Some(t)),
        "no agent with id 4242",
    );
    let mut invalid = scene.clone();
    invalid.tracks[ib].states[10].valid = false;
    bad(
        sim::rollout(model, &invalid, Some(t.a_id), &b(0.5), config, None),
        "not valid at the current step",
    );
    let mut short = scene.clone();
    for tr in &mut short.tracks {
        tr.states.truncate(8);
    }
    short.timestamps_secs.truncate(8);
    short.current_step = 7;
    bad(
        sim::rollout(model, &short, Some(t.a_id), &b(0.5), config, None),
        "fewer than 11 history steps",
    );
}

/// A plan kept in lane as `generate` and the closed loop keep it.
fn kept_in_lane(scene: &scbg_scene::Scene, mut plan: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    scbg::keep_in_lane(scene, None, &mut plan, scbg::DEFAULT_LANE_KEEPING_M).unwrap();
    plan
}
