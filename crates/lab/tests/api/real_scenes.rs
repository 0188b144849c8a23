//! The closed loop on every file of the shared real data (`SCBG_REAL_DATA`): every scene with
//! an interacting vehicle pair is simulated in each window that has one, the others are left
//! out with a reason, no number is NaN, and B's off-road rate per quantile is reported.

use scbg_features::{PairConfig, PreparedScene, WindowConfig};
use scbg_lab::generator;
use scbg_lab::predictor::SplitSelection;
use scbg_lab::sim_eval::{self, SimEvalOptions};

pub(crate) fn closed_loop_on_every_real_file(model: &generator::LoadedScbg) {
    let Some(files) = scbg_womd::fixtures::real_tfrecords() else {
        return;
    };
    let inputs: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    let (scenes, skipped) =
        sim_eval::load_scenes(&inputs, None, SplitSelection::All, 0.0, usize::MAX).unwrap();
    // What `data prepare` finds, scene by scene: the windows with a pair.
    let mut with_pair = 0;
    for file in &files {
        for scene in scbg_womd::WomdFile::open(file).unwrap().scenes() {
            let scene = scene.unwrap();
            let id = scene.scenario_id.clone();
            let windows_with_pair = PreparedScene::from_scene(
                &scene,
                &WindowConfig::default(),
                &PairConfig::default(),
                scbg::ROAD_SUBSAMPLE,
            )
            .map_or(0, |p| p.pairs.iter().filter(|w| !w.is_empty()).count());
            let simulated = scenes.iter().filter(|s| s.source_id() == id).count();
            let listed = skipped.iter().filter(|s| s.scenario_id == id).count();
            if windows_with_pair > 0 {
                with_pair += 1;
                assert!(
                    simulated >= windows_with_pair,
                    "{id}: {simulated} windows to simulate, {windows_with_pair} with a pair"
                );
            }
            assert!(
                (simulated > 0) != (listed > 0),
                "{id}: {simulated} windows to simulate, listed {listed} times as skipped"
            );
        }
    }
    assert!(with_pair >= 20, "{with_pair} scenes with a mined pair");
    // Long scenes are cut into 91-step windows at current step 10, as `data prepare` cuts them.
    let long = scenes.iter().find(|s| s.window.is_some()).unwrap();
    assert_eq!((long.scene.num_steps(), long.scene.current_step), (91, 10));
    assert!(scenes.iter().any(|s| s.pair == sim_eval::PairOrigin::Mined));

    let options = SimEvalOptions {
        quantiles: vec![0.1, 0.9],
        scenes: usize::MAX,
        wosac_scenes: 1,
        wosac_quantiles: vec![0.5],
        wosac_prior: false,
        ..SimEvalOptions::default()
    };
    let mut eval = sim_eval::evaluate_sim(model, &scenes, &options).unwrap();
    eval.add_skipped(skipped.clone());
    // Every window with a pair is simulated; nothing fails.
    assert_eq!(eval.curve.scenes, scenes.len(), "{}", eval.skipped_line());
    for s in &eval.skipped_scenes {
        assert!(
            s.reason == sim_eval::NO_PAIR
                || s.reason == sim_eval::TOO_SHORT
                || s.reason.starts_with(sim_eval::REALISM_NA),
            "{}: {}",
            s.scenario_id,
            s.reason
        );
    }
    let sources = eval.sources.as_ref().unwrap();
    assert!(
        sources.windows > 0 && sources.pairs["mined"] > 0,
        "{sources:?}"
    );
    // Realism where the window has the WOSAC layout, an evaluated object and road edges; not
    // applicable elsewhere (nuScenes has no road edge), by reason.
    assert!(eval.wosac_scbg.is_some());
    assert!(
        eval.skipped
            .keys()
            .any(|k| k.starts_with(sim_eval::REALISM_NA) && k.contains("no road edge")),
        "{:?}",
        eval.skipped
    );
    // No NaN: every number finite, the missing ones `None`.
    let finite = |x: f64, what: &str| assert!(x.is_finite(), "{what}: {x}");
    for r in &eval.curve.per_quantile {
        for (x, what) in [
            (r.a_avg_speed_mps, "A speed"),
            (r.a_avg_speed_std_mps, "A speed std"),
            (r.realised_courtesy_mps, "realised courtesy"),
            (r.realised_courtesy_std_mps, "realised courtesy std"),
            (r.b_collision_rate, "B collision"),
            (r.b_mean_abs_jerk_mps3, "B jerk"),
            (r.b_progress_m, "B progress"),
        ] {
            finite(x, what);
        }
        let offroad = r.b_offroad_rate.expect("scenes with road edges");
        finite(offroad, "B off-road");
        eprintln!(
            "real data, quantile {:.1}: B off-road {offroad:.3} over the scenes with road edges, B collision {:.3}",
            r.quantile, r.b_collision_rate
        );
    }
    for b in eval.baselines.values() {
        for x in [b.a_avg_speed_mps, b.b_collision_rate, b.b_offroad_rate]
            .into_iter()
            .flatten()
        {
            finite(x, "baseline");
        }
    }
    let text = format!(
        "{}\n{}\n{}\n{}",
        eval.realism_line(),
        eval.curve.collision_line(),
        eval.skipped_line(),
        serde_json::to_string(&eval).unwrap()
    );
    assert!(!text.contains("NaN"), "{text}");
    assert!(eval.rollout_ms.is_finite() && eval.seconds.is_finite());

    // No scene at all: an evaluation of nothing, every number absent, the reasons kept.
    let mut none = sim_eval::evaluate_sim(model, &[], &options).unwrap();
    assert_eq!(none.curve.scenes, 0);
    assert!(none.curve.per_quantile.is_empty());
    assert_eq!(none.curve.max_b_collision_rate, None);
    assert_eq!(none.curve.a_speed_curve_rises, None);
    assert!(
        none.baselines
            .values()
            .all(|b| b.a_avg_speed_mps.is_none() && b.b_offroad_rate.is_none())
    );
    none.add_skipped(vec![sim_eval::SkippedScene {
        scenario_id: "short".into(),
        reason: sim_eval::TOO_SHORT.into(),
        detail: None,
    }]);
    let text = format!(
        "{}\n{}\n{}",
        none.realism_line(),
        none.curve.collision_line(),
        none.skipped_line()
    );
    assert!(
        text.contains(sim_eval::TOO_SHORT) && text.contains("n/a"),
        "{text}"
    );
    assert!(!text.contains("NaN"), "{text}");
}
