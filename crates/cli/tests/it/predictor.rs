//! `scbg train predictor`, `scbg eval predictor`, `scbg eval metrics` and `scbg bench train`.

use crate::{inspect_json, real_dir, scbg, scbg_ok};
use serde_json::{Value, json};

/// The tiny predictor config of the library's tests.
const TINY_CONFIG: &str = include_str!("../../../scbg/tests/tiny_train.toml");

/// synth → prepare → train (tiny config) in `dir`: `synth/`, `cache/`, `train.toml`, `model/`.
fn tiny_trained_model(dir: &std::path::Path, scenarios: usize, seed: u64) {
    let p = |s: &str| dir.join(s).display().to_string();
    let (n, seed) = (scenarios.to_string(), seed.to_string());
    scbg_ok(&[
        "synth",
        "--scenarios",
        &n,
        "--seed",
        &seed,
        "--out",
        &p("synth"),
    ]);
    scbg_ok(&[
        "data",
        "prepare",
        "--input",
        &p("synth"),
        "--out",
        &p("cache"),
    ]);
    std::fs::write(p("train.toml"), TINY_CONFIG).unwrap();
    scbg_ok(&[
        "train",
        "predictor",
        "--config",
        &p("train.toml"),
        "--data",
        &p("cache"),
        "--out",
        &p("model"),
    ]);
}

#[test]
fn train_then_evaluate_on_synthetic_data() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).display().to_string();
    tiny_trained_model(dir.path(), 30, 4);
    let ckpt: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("model/checkpoint.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(ckpt["state"]["epoch"], 2);
    let out = scbg_ok(&[
        "eval",
        "predictor",
        "--model",
        &p("model"),
        "--data",
        &p("cache"),
        "--json",
    ]);
    let v: Value = serde_json::from_str(&out).unwrap();
    for row in [
        "Marginal (interacting agents)",
        "Conditional (interacting agents)",
        "Const. velocity (interacting)",
    ] {
        let m = &v[row];
        assert!(m["min_ade"].as_f64().unwrap() >= 0.0, "{row}: {m}");
        assert!(m["by_time"]["8"]["miss_rate"].is_number(), "{row}: {m}");
    }
    // A bad config is a clear error, not a panic.
    std::fs::write(p("bad.toml"), "epochs = \"many\"").unwrap();
    let bad = scbg(&[
        "train",
        "predictor",
        "--config",
        &p("bad.toml"),
        "--data",
        &p("cache"),
        "--out",
        &p("model2"),
    ]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("bad.toml"));
}

#[test]
fn metrics_of_external_predictions_on_a_genuine_scenario() {
    let Some(real) = real_dir() else { return };
    let file = real.join("womd/motion_data_one_scenario.tfrecord");
    let scene = scbg_womd::WomdFile::open(&file)
        .unwrap()
        .scenes()
        .next()
        .unwrap()
        .unwrap();
    // Constant-velocity predictions (one trajectory at 10 Hz, one copy at 2 Hz) for the tracks to predict.
    let mut preds = Vec::new();
    let mut preds_2hz = Vec::new();
    for t in &scene.tracks_to_predict {
        let track = &scene.tracks[t.track_index];
        let s = track.states[scene.current_step];
        let traj: Vec<[f64; 2]> = (1..=80)
            .map(|i| {
                [
                    s.x_m + f64::from(s.velocity_x_mps) * 0.1 * i as f64,
                    s.y_m + f64::from(s.velocity_y_mps) * 0.1 * i as f64,
                ]
            })
            .collect();
        let traj_2hz: Vec<[f64; 2]> = (0..16).map(|p| traj[(p + 1) * 5 - 1]).collect();
        preds.push(json!({"scenario_id": scene.scenario_id, "object_id": track.id, "trajectories": [traj], "scores": [1.0]}));
        preds_2hz.push(json!({"scenario_id": scene.scenario_id, "object_id": track.id, "trajectories": [traj_2hz], "scores": [1.0]}));
    }
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, body: Value| {
        let path = dir.path().join(name);
        std::fs::write(&path, body.to_string()).unwrap();
        let out = scbg_ok(&[
            "eval",
            "metrics",
            "--scenarios",
            file.to_str().unwrap(),
            "--predictions",
            path.to_str().unwrap(),
            "--json",
        ]);
        serde_json::from_str::<Value>(&out).unwrap()
    };
    let v = run("cv.json", json!({"predictions": preds}));
    for key in ["ade", "min_ade", "min_fde", "miss_rate", "map", "soft_map"] {
        assert!(v.get(key).is_some(), "missing {key}: {v}");
        assert!(
            v["by_time"]["8"].get(key).is_some(),
            "missing by_time.8.{key}"
        );
    }
    assert_eq!(v["num_objects"], 3);
    // One trajectory: ADE equals minADE.
    assert_eq!(v["ade"], v["min_ade"]);
    // The 2 Hz version is scored at its 16 points: the 8 s FDE is the same.
    let v2 = run("cv2.json", json!({"predictions": preds_2hz}));
    let fde = |v: &Value| v["by_time"]["8"]["min_fde"].as_f64().unwrap();
    assert!((fde(&v) - fde(&v2)).abs() < 1e-3);
    // A prediction for an unknown object is a clear error.
    let path = dir.path().join("bad.json");
    std::fs::write(&path, json!({"predictions": [{"scenario_id": scene.scenario_id, "object_id": -5, "trajectories": [[[0.0, 0.0]]], "scores": [1.0]}]}).to_string()).unwrap();
    let out = scbg(&[
        "eval",
        "metrics",
        "--scenarios",
        file.to_str().unwrap(),
        "--predictions",
        path.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("object -5"));
}

#[test]
fn demo_writes_a_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    scbg_ok(&[
        "demo",
        "--out",
        out.to_str().unwrap(),
        "--scenarios",
        "40",
        "--epochs",
        "2",
        "--generator-epochs",
        "1",
        "--generator-seeds",
        "2",
        // Reaction siblings, made after the first epoch, join the second.
        "--reaction-siblings",
        "2",
        "--reaction-epochs",
        "1",
        // The predictor's batch and learning rate reach its training config.
        "--batch-size",
        "64",
        "--learning-rate",
        "0.002",
    ]);
    let config = std::fs::read_to_string(out.join("predictor.toml")).unwrap();
    assert!(
        config.contains("batch_size = 64") && config.contains("learning_rate = 0.002"),
        "{config}"
    );
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["data"]["scenarios"], 40);
    assert!(
        report["predictor"]["Marginal (interacting agents)"]["min_ade"].is_number(),
        "{report}"
    );
    // The report.json layout.
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
    assert_eq!(families.len(), 3, "{report}");
    assert!(report["checks"]["range_below_arbitrary"].is_boolean());
    // The closed-loop stage ran on the held-out scenes.
    let cl = &report["closed_loop"];
    assert_eq!(cl["per_quantile"].as_array().unwrap().len(), 9);
    assert!(cl["baselines"]["constant_velocity"]["wosac"]["metametric"].is_number());
    assert!(report["checks"]["closed_loop_b_collision_2pct"].is_boolean());
    assert!(report["checks"]["closed_loop_wosac_prior_above_baselines"].is_boolean());
    assert!(cl["wosac_scbg_prior"]["metametric"].is_number());
    assert!(cl["wosac_prior_minus_idm"]["std_error"].is_number());
    // The knob within a scene: a mean of Spearman values, over responsive scenes only.
    let within = cl["spearman_within_scene_a_speed"]["all"].as_f64().unwrap();
    let responsive = cl["responsive_fraction"]["all"].as_f64().unwrap();
    assert!(within.abs() <= responsive + 1e-9, "{cl}");
    assert!(report["truth_control"]["full"]["spearman_within_example"]["all"].is_number());
    // Then sample and rank in the same loop, at its own cadence (both 2 s), without the
    // prior's score.
    let rk = &report["closed_loop_ranked"];
    assert_eq!(rk["policy"], "ranked", "{rk}");
    assert_eq!(rk["replan_every"], 20);
    assert_eq!(cl["replan_every"], 20);
    assert_eq!(rk["per_quantile"].as_array().unwrap().len(), 9);
    assert!(rk["wosac_scbg"]["metametric"].is_number(), "{rk}");
    assert!(rk["wosac_scbg_prior"].is_null());
    assert!(report["checks"]["closed_loop_ranked_b_collision_2pct"].is_boolean());
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
    // The fidelity issue's keys.
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
    // Where the time went, stage by stage.
    let stages = report["stage_seconds"].as_object().unwrap();
    assert_eq!(stages.len(), 9, "{report}");
    assert!(stages.values().all(|v| v.as_f64().unwrap() >= 0.0));
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
    for key in [
        "oracle_consistency_95",
        "fidelity_logged_spearman_0_7",
        "fidelity_sampled_spearman_0_7",
        "fidelity_spread_ratio",
        "label_latent_spearman_0_5",
        "truth_control_spearman",
        "corr_quantile_at_least_0_6",
        "corr_quantile_high_at_least_0_8",
    ] {
        assert!(report["checks"][key].is_boolean(), "{key}: {report}");
    }
    assert!(report["checks"]["oracle_consistency_95"].as_bool().unwrap());
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

#[test]
fn label_writes_parquet_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).display().to_string();
    tiny_trained_model(dir.path(), 20, 8);
    let gt = format!("{}/ground_truth.jsonl", p("synth"));
    scbg_ok(&[
        "label",
        "--model",
        &p("model"),
        "--data",
        &p("cache"),
        "--out",
        &p("labels"),
        "--samples",
        "3",
        "--ground-truth",
        &gt,
    ]);
    let summary: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("labels/summary.json")).unwrap(),
    )
    .unwrap();
    // 20 scenarios × 1 labelled pair × 2 roles × (1 logged + 3 sampled).
    assert_eq!(summary["rows"], 20 * 2 * 4);
    assert_eq!(summary["pairs_roles"], 40);
    assert!(dir.path().join("labels/psi_histogram.png").is_file());
    // The fidelity report: every future of the 20 ground-truth roles is scored by the oracle.
    let fidelity = &summary["fidelity"];
    assert_eq!(fidelity["logged"]["all"]["n"], 20, "{summary}");
    assert_eq!(fidelity["sampled"]["all"]["n"], 60, "{summary}");
    for key in ["spearman", "pearson", "slope", "spread_ratio"] {
        assert!(fidelity["logged"]["all"].get(key).is_some(), "{key}");
    }
    assert!(fidelity["oracle_consistency"]["all"][0].as_f64().unwrap() >= 0.95);
    assert!(dir.path().join("labels/psi_fidelity.png").is_file());
    let rows =
        scbg::labels::read_label_table(&dir.path().join("labels/labels-00000.parquet")).unwrap();
    assert_eq!(rows.iter().filter(|r| r.psi_true.is_some()).count(), 80);
    let parquet = dir.path().join("labels/labels-00000.parquet");
    let bytes = std::fs::read(&parquet).unwrap();
    assert_eq!(&bytes[..4], b"PAR1");
    // A second run reads the finished shard instead of relabelling it.
    let before = std::fs::metadata(&parquet).unwrap().modified().unwrap();
    scbg_ok(&[
        "label",
        "--model",
        &p("model"),
        "--data",
        &p("cache"),
        "--out",
        &p("labels"),
        "--samples",
        "3",
    ]);
    assert_eq!(
        std::fs::metadata(&parquet).unwrap().modified().unwrap(),
        before
    );
    // ψ toward B's neighbours (issue 12): same rows, each counting its audience; a bad radius
    // is refused before anything is written.
    let bad = crate::scbg(&[
        "label",
        "--model",
        &p("model"),
        "--data",
        &p("cache"),
        "--out",
        &p("labels_bad"),
        "--audience",
        "neighbours",
        "--audience-radius-m",
        "0",
    ]);
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && err.contains("radius 0"), "{err}");
    assert!(!dir.path().join("labels_bad").exists());
    scbg_ok(&[
        "label",
        "--model",
        &p("model"),
        "--data",
        &p("cache"),
        "--out",
        &p("labels_neighbours"),
        "--samples",
        "3",
        "--audience",
        "neighbours",
        "--audience-weighting",
        "proximity",
        "--ground-truth",
        &gt,
    ]);
    let summary: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("labels_neighbours/summary.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(summary["rows"], 20 * 2 * 4);
    assert_eq!(summary["audience"]["kind"], "neighbours", "{summary}");
    assert_eq!(summary["audience"]["weighting"], "proximity", "{summary}");
    assert!(summary["audience_size_mean"].as_f64().unwrap() >= 1.0);
    assert!(summary["fidelity"].is_null(), "{summary}");
}

#[test]
fn train_generator_saves_generator_and_range_predictor() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).display().to_string();
    tiny_trained_model(dir.path(), 16, 12);
    scbg_ok(&[
        "train",
        "generator",
        "--predictor",
        &p("model"),
        "--data",
        &p("cache"),
        "--out",
        &p("gen"),
        "--epochs",
        "2",
        "--samples",
        "2",
        "--batch-size",
        "8",
        "--range-steps",
        "20",
    ]);
    let saved: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("gen/generator.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(saved["variant"], "full");
    assert_eq!(saved["history"].as_array().unwrap().len(), 2);
    assert!(saved["examples"].as_u64().unwrap() > 0);
    assert!(saved["range_loss"].as_f64().unwrap().is_finite());
    assert!(
        dir.path().join("gen/generator.bpk").is_file()
            && dir.path().join("gen/range.bpk").is_file()
    );
    scbg_ok(&[
        "train",
        "generator",
        "--predictor",
        &p("model"),
        "--data",
        &p("cache"),
        "--out",
        &p("gen_base"),
        "--variant",
        "baseline",
        "--epochs",
        "1",
        "--samples",
        "2",
        "--batch-size",
        "8",
        "--range-steps",
        "20",
    ]);

    // `scbg generate` on a pair of the synthetic ground truth.
    let gt = std::fs::read_to_string(dir.path().join("synth/ground_truth.jsonl")).unwrap();
    let first: Value = serde_json::from_str(gt.lines().next().unwrap()).unwrap();
    let (a, b) = (first["a_id"].to_string(), first["b_id"].to_string());
    let file = std::fs::read_dir(dir.path().join("synth"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "tfrecord"))
        .unwrap();
    let file = file.display().to_string();
    let sid = first["scenario_id"].as_str().unwrap();
    let gen_dir = p("gen");
    // `scbg generate` for this scenario and A, with B and the remaining arguments given.
    let generate = |b: &str, rest: &[&str]| {
        let mut args = vec![
            "generate",
            "--model",
            &gen_dir,
            "--scenario",
            &file,
            "--scenario-id",
            sid,
            "--a",
            &a,
            "--b",
            b,
        ];
        args.extend_from_slice(rest);
        scbg(&args)
    };
    let (traj_json, traj_png) = (p("traj.json"), p("traj.png"));
    let ok = generate(
        &b,
        &[
            "--quantile",
            "0.1",
            "0.5",
            "0.9",
            "--out",
            &traj_json,
            "--render",
            &traj_png,
        ],
    );
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let traj: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("traj.json")).unwrap())
            .unwrap();
    let trajs = traj["trajectories"].as_array().unwrap();
    assert_eq!(trajs.len(), 3);
    assert_eq!(trajs[0]["world_xy_m"].as_array().unwrap().len(), 80);
    assert!(trajs[0]["psi"].as_f64().unwrap() <= trajs[2]["psi"].as_f64().unwrap());
    assert!(dir.path().join("traj.png").is_file());
    // Bad requests name what is wrong and exit 2.
    let bad = generate("987654321", &["--quantile", "0.5"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("987654321"));
    let bad = generate(&b, &["--quantile", "1.5"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("quantile"));

    // `scbg eval scbg` over both variants, with figures.
    let out = scbg_ok(&[
        "eval",
        "scbg",
        "--model",
        &p("gen_base"),
        &p("gen"),
        "--data",
        &p("cache"),
        "--split",
        "all",
        "--ground-truth",
        &p("synth/ground_truth.jsonl"),
        "--json",
        "--figures",
        &p("figs"),
    ]);
    let eval: Value = serde_json::from_str(&out).unwrap();
    // Control in truth for each variant, and its yardstick over the same roles.
    let roles = eval["truth_control"]["full"]["examples"]["all"]
        .as_u64()
        .unwrap();
    assert!(roles > 0, "{eval}");
    assert_eq!(
        eval["truth_control_world"]["examples"]["all"].as_u64(),
        Some(roles)
    );
    assert!(eval["truth_control_world"]["spearman_quantile_psi_true"]["all"].is_number());
    // The selectors among B's labelled futures score the same roles; ranked by ψ_true itself,
    // each role's picks rise with the quantile, so the mean does too.
    let selection = &eval["truth_control_selection"];
    assert_eq!(
        selection["by_label"]["examples"]["all"].as_u64(),
        Some(roles),
        "{eval}"
    );
    let means: Vec<f64> = selection["by_truth"]["per_quantile"]
        .as_array()
        .unwrap()
        .iter()
        .map(|q| q["psi_true_mean"].as_f64().unwrap())
        .collect();
    assert_eq!(means.len(), 9);
    assert!(means.windows(2).all(|w| w[0] <= w[1]), "{means:?}");
    assert!(selection["candidates_mean"].as_f64().unwrap() >= 2.0);
    // Within each role the picks by ψ_true never fall with q: every responsive role's
    // Spearman is positive.
    let by_truth = &selection["by_truth"];
    let within = by_truth["spearman_within_example"]["all"].as_f64().unwrap();
    let responsive = by_truth["responsive_fraction"]["all"].as_f64().unwrap();
    assert!(within >= 0.0 && within <= responsive + 1e-9, "{by_truth}");
    assert_eq!(within > 0.0, responsive > 0.0, "{by_truth}");
    for variant in ["baseline", "full"] {
        let v = &eval["variants"][variant];
        for key in [
            "courtesy_mse_data",
            "courtesy_mse_range",
            "courtesy_mse_arbitrary",
            "traj_ade",
        ] {
            assert!(
                v[key]["mean"].as_f64().unwrap().is_finite(),
                "{variant} {key}"
            );
            assert!(v[key]["std"].as_f64().unwrap() >= 0.0);
        }
        assert!(v.get("corr_quantile").is_some() && v.get("corr_quantile_high").is_some());
        assert_eq!(v["per_quantile"].as_array().unwrap().len(), 9);
    }
    for f in [
        "fig4_quantile_courtesy.png",
        "fig5a_case1.png",
        "fig5b_quantile_speed.png",
    ] {
        assert!(dir.path().join("figs").join(f).is_file(), "{f}");
    }

    // `scbg sim`: one rollout as a Scenario file, 32 as a WOSAC shard, in the synthetic world
    // (ground_truth.jsonl beside the file); `scbg eval sim` on the synthetic folder.
    let sim = |out: &str, rest: &[&str]| {
        let mut args = vec![
            "sim",
            "--model",
            &gen_dir,
            "--scenario",
            &file,
            "--scenario-id",
            sid,
            "--a",
            &a,
            "--b",
            &b,
            "--out",
            out,
        ];
        args.extend_from_slice(rest);
        scbg(&args)
    };
    let ok = sim(&p("sim1"), &["--quantile", "0.8"]);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    assert!(String::from_utf8_lossy(&ok.stderr).contains("synthetic world"));
    let summary = inspect_json(&[&dir.path().join("sim1/rollouts.tfrecord")]);
    assert_eq!(summary.len(), 1);
    assert_eq!(summary[0]["scenario_id"], sid);
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("sim1/sim.json")).unwrap())
            .unwrap();
    assert_eq!(report["reports"].as_array().unwrap().len(), 1);
    assert!(report["synthetic_world"].as_bool().unwrap());
    let ok = sim(&p("simw"), &["--format", "wosac", "--name", "mine"]);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    assert!(
        dir.path()
            .join("simw/mine.binproto-00000-of-00001")
            .is_file()
    );
    // Bad requests: named, exit 2, nothing written.
    for (rest, needle) in [
        (&["--quantile", "1.5"][..], "quantile 1.5"),
        (&["--also", "4242=0.5"][..], "4242"),
        (&["--format", "wosac", "--rollouts", "3"][..], "32 rollouts"),
        (&["--replan-every", "0"][..], "replan_every"),
    ] {
        let bad = sim(&p("simbad"), rest);
        assert_eq!(bad.status.code(), Some(2), "{rest:?}");
        let err = String::from_utf8_lossy(&bad.stderr);
        assert!(err.contains(needle), "{rest:?}: {err}");
        assert!(!dir.path().join("simbad/sim.json").exists());
    }
    let out = scbg_ok(&[
        "eval",
        "sim",
        "--model",
        &gen_dir,
        "--data",
        &p("synth"),
        "--ground-truth",
        &p("synth/ground_truth.jsonl"),
        "--split",
        "all",
        "--scenes",
        "2",
        "--wosac-scenes",
        "1",
        "--wosac-quantiles",
        "0.5",
        "--spread",
        "0.1",
        "--out",
        &p("evalsim"),
        "--json",
    ]);
    let eval: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(eval["scenes"], 2);
    assert_eq!(eval["per_quantile"].as_array().unwrap().len(), 9);
    assert!(
        eval["baselines"]["idm_only"]["wosac"]["metametric"]
            .as_f64()
            .is_some()
    );
    // Only the quantile asked for is scored around its band, and the prior beside it.
    let wosac_rows: Vec<f64> = eval["per_quantile"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| !r["wosac"].is_null())
        .map(|r| r["quantile"].as_f64().unwrap())
        .collect();
    assert_eq!(wosac_rows, [0.5]);
    assert_eq!(eval["wosac_prior_minus_idm"]["scenes"], 1);
    for f in ["eval_sim.json", "sim_courtesy.png", "sim_realism.png"] {
        assert!(dir.path().join("evalsim").join(f).is_file(), "{f}");
    }

    // A malformed threshold is a clear error.
    let bad = scbg(&[
        "train",
        "generator",
        "--predictor",
        &p("model"),
        "--data",
        &p("cache"),
        "--out",
        &p("gen2"),
        "--threshold",
        "qx",
    ]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--threshold"));
}

#[test]
fn bench_train_times_the_data_parallel_step_and_its_phases() {
    let out = scbg_ok(&[
        "bench",
        "train",
        "--presets",
        "cpu-small",
        "--batch",
        "6",
        "--steps",
        "1",
        "--chunks",
        "4",
    ]);
    assert!(out.contains("4 chunk(s), backend flex"), "{out}");
    let step = out
        .lines()
        .find(|l| l.starts_with("cpu-small"))
        .unwrap_or_else(|| panic!("no cpu-small row: {out}"));
    assert!(
        step.contains("train step") && step.contains("samples/s"),
        "{step}"
    );
    assert!(out.contains("phases (synced): batch"), "{out}");
    // A backend this build lacks (or a GPU that does not answer) is a clear error.
    let missing = scbg(&[
        "bench",
        "train",
        "--backend",
        "no-such-backend",
        "--steps",
        "1",
    ]);
    assert!(!missing.status.success());
    let err = String::from_utf8_lossy(&missing.stderr);
    assert!(
        err.contains("\"no-such-backend\" is not available: this build has flex"),
        "{err}"
    );
}
