//! `scbg demo`: the whole pipeline on a tiny synthetic set.

use crate::scbg_ok;
use serde_json::Value;

#[test]
fn demo_writes_a_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    // Settings over the defaults: reaction siblings, made after the first epoch, join the
    // second; the predictor's batch and learning rate reach its training config.
    let config = crate::settings(
        dir.path(),
        "[data]\nscenarios = 40\n\
         [predictor]\nepochs = 2\nreaction_siblings = 2\nreaction_epochs = 1\n\
         batch_size = 64\nlearning_rate = 0.002\n\
         [generator]\nepochs = 1\nseeds = 2\n",
    );
    let started = std::time::Instant::now();
    scbg_ok(&[
        "demo",
        "--out",
        out.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
    ]);
    let wall_seconds = started.elapsed().as_secs_f64();
    let config = std::fs::read_to_string(out.join("predictor.toml")).unwrap();
    assert!(
        config.contains("batch_size = 64") && config.contains("learning_rate = 0.002"),
        "{config}"
    );
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["data"]["scenarios"], 40);
    // The reference documents every key of the report.
    let reference = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/reference.md"),
    )
    .unwrap();
    for key in report.as_object().unwrap().keys() {
        assert!(
            reference.contains(&format!("`{key}`")),
            "docs/reference.md does not document report.json's {key}"
        );
    }
    assert!(
        report["predictor"]["Marginal (interacting agents)"]["min_ade"].is_number(),
        "{report}"
    );
    // The report's layout of the paper's numbers.
    for variant in ["baseline", "aug", "full"] {
        let v = &report["variants"][variant];
        for key in [
            "courtesy_mse_data",
            "courtesy_mse_range",
            "courtesy_mse_arbitrary",
            "traj_ade",
        ] {
            assert!(v[key]["mean"].is_number(), "{variant}.{key}: {report}");
        }
        assert!(v.get("corr_quantile").is_some() && v.get("corr_quantile_high").is_some());
    }
    let families = report["spearman_latent"].as_object().unwrap();
    assert_eq!(
        families.len(),
        scbg_synth::Family::DEFAULT.len(),
        "every family of the synthetic world: {report}"
    );
    // The closed-loop stage ran on the held-out scenes.
    let cl = &report["closed_loop"];
    assert_eq!(cl["per_quantile"].as_array().unwrap().len(), 9);
    assert!(cl["baselines"]["constant_velocity"]["wosac"]["metametric"].is_number());
    assert!(cl["wosac_scbg_prior"]["metametric"].is_number());
    assert!(cl["wosac_prior_minus_idm"]["std_error"].is_number());
    // The knob within a scene: a mean of Spearman values, over responsive scenes only.
    let within = cl["spearman_within_scene_a_speed"]["all"].as_f64().unwrap();
    let responsive = cl["responsive_fraction"]["all"].as_f64().unwrap();
    assert!(within.abs() <= responsive + 1e-9, "{cl}");
    assert!(report["truth_control"]["full"]["spearman_within_example"]["all"].is_number());
    // Ordered to rise with the quantile within each scene (or role), no order ranks higher.
    for (m, key) in [
        (cl, "spearman_quantile_a_speed"),
        (&cl["world_knob"], "spearman_quantile_a_speed"),
        (
            &report["truth_control"]["full"],
            "spearman_quantile_psi_true",
        ),
    ] {
        let ordered = &m[format!("{key}_ordered")]["all"];
        match (ordered.as_f64(), m[key]["all"].as_f64()) {
            (Some(ordered), Some(as_given)) => {
                assert!(ordered >= as_given - 1e-9, "{key}: {m}")
            }
            (None, None) => assert!(ordered.is_null(), "{key}: {m}"),
            _ => panic!("{key}: one of the two is missing: {m}"),
        }
    }
    // Then sample and rank in the same loop, at its own cadence (both 2 s), without the
    // prior's score.
    let rk = &report["closed_loop_ranked"];
    assert_eq!(rk["policy"], "ranked", "{rk}");
    assert_eq!(rk["replan_every"], 20);
    assert_eq!(cl["replan_every"], 20);
    assert_eq!(rk["per_quantile"].as_array().unwrap().len(), 9);
    assert!(rk["wosac_scbg"]["metametric"].is_number(), "{rk}");
    assert!(rk["wosac_scbg_prior"].is_null());
    assert!(
        report["checks"]
            .get("closed_loop_ranked_wosac_prior_above_baselines")
            .is_none()
    );
    assert!(
        out.join("figures/closed_loop_ranked/sim_courtesy.png")
            .is_file()
    );
    // Two generator seeds: seed means, their spread, each seed's numbers.
    assert_eq!(report["generator_seeds"], serde_json::json!([0, 1]));
    assert_eq!(report["variants_per_seed"].as_array().unwrap().len(), 2);
    assert!(report["variants_seed_std"]["full"]["traj_ade"]["mean"].is_number());
    assert!(out.join("generator_full_seed1/generator.json").is_file());
    // The label fidelity keys.
    assert_eq!(
        report["fidelity_all_scenes"]["logged"]["all"]["n"], 40,
        "{report}"
    );
    // The held-out split's share of the 40 scenes.
    let held_out = report["fidelity"]["logged"]["all"]["n"].as_u64().unwrap();
    assert!((1..40).contains(&held_out), "{report}");
    // The fidelity on the same held-out scenes of the checkpoint the siblings were made with
    // (after the first epoch), and the siblings' epoch in the predictor's history.
    assert_eq!(
        report["fidelity_stage1"]["logged"]["all"]["n"], held_out,
        "{report}"
    );
    let ckpt: Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("predictor/checkpoint.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(ckpt["state"]["epoch"], 2, "{ckpt}");
    assert_eq!(ckpt["train_config"]["reaction_from_epoch"], 1, "{ckpt}");
    // Where the time went, stage by stage: every stage took some, and together no more than
    // the run did.
    let stages = report["stage_seconds"].as_object().unwrap();
    assert_eq!(stages.len(), 9, "{report}");
    let seconds: Vec<f64> = stages.values().map(|v| v.as_f64().unwrap()).collect();
    assert!(seconds.iter().all(|&s| s > 0.0), "{stages:?}");
    assert!(
        seconds.iter().sum::<f64>() <= wall_seconds,
        "{stages:?} in {wall_seconds:.1} s"
    );
    let tuned: Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("cache_reaction/manifest.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(tuned["total"]["scenarios"], 40 * 2, "{tuned}");
    assert!(report["truth_control"]["full"]["spearman_quantile_psi_true"].is_object());
    // Its yardstick scores the same held-out roles.
    let world = &report["truth_control_world"];
    assert_eq!(
        world["examples"]["all"].as_f64().unwrap(),
        report["truth_control"]["full"]["examples"]["all"]
            .as_f64()
            .unwrap(),
        "{report}"
    );
    assert_eq!(world["per_quantile"].as_array().unwrap().len(), 9);
    // Every acceptance check is reported; those a 40-scene demo of two predictor epochs meets
    // hold. (Label fidelity, control in truth, the closed loop's Spearman and rising curve,
    // WOSAC above the baselines and the full variant's TrajADE need the default demo's data
    // and training: BENCHMARKS.md.)
    let checks = report["checks"].as_object().unwrap();
    let mut keys: Vec<&str> = checks.keys().map(String::as_str).collect();
    keys.sort_unstable();
    assert_eq!(
        keys,
        [
            "closed_loop_b_collision_2pct",
            "closed_loop_curve_rises",
            "closed_loop_ranked_b_collision_2pct",
            "closed_loop_ranked_curve_rises",
            "closed_loop_ranked_spearman_0_6",
            "closed_loop_ranked_wosac_above_baselines",
            "closed_loop_spearman_0_6",
            "closed_loop_wosac_above_baselines",
            "closed_loop_wosac_prior_above_baselines",
            "corr_quantile_at_least_0_6",
            "corr_quantile_high_at_least_0_8",
            "fidelity_logged_spearman_0_7",
            "fidelity_sampled_spearman_0_7",
            "fidelity_spread_ratio",
            "full_courtesy_mse_data_no_worse",
            "full_traj_ade_no_worse",
            "label_latent_spearman_0_5",
            "oracle_consistency_95",
            "range_below_arbitrary",
            "truth_control_spearman",
        ]
    );
    assert!(
        checks.values().all(serde_json::Value::is_boolean),
        "{checks:?}"
    );
    for key in [
        "oracle_consistency_95",
        "range_below_arbitrary",
        "full_courtesy_mse_data_no_worse",
        "closed_loop_b_collision_2pct",
        "closed_loop_ranked_b_collision_2pct",
    ] {
        assert_eq!(checks[key], true, "{key}: {report}");
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("| Conditional (interacting agents) |"), "{md}");
    assert!(md.contains("| ①+②+③ courtesy loss |"), "{md}");
    for f in [
        "scene.png",
        "psi_histogram.png",
        "psi_fidelity.png",
        "fig4_quantile_courtesy.png",
        "fig5a_case1.png",
        "fig5b_quantile_speed.png",
    ] {
        assert!(out.join("figures").join(f).is_file(), "{f}");
    }
    // Outputs get the usual permissions (what `File::create` gives under this umask), not a
    // temporary file's owner-only 0600.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let probe = out.join("probe");
        std::fs::File::create(&probe).unwrap();
        let mode = |p: &std::path::Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        for f in [
            "report.json",
            "report.md",
            "figures/fig4_quantile_courtesy.png",
            "labels/labels-00000.parquet",
        ] {
            assert_eq!(mode(&out.join(f)), mode(&probe), "{f}");
        }
    }
}
