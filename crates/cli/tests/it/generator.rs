//! `scbg label`, `scbg train generator` and what runs on a trained generator.

use crate::predictor::tiny_trained_model;
use crate::{inspect_json, scbg, scbg_ok};
use serde_json::Value;

#[test]
fn label_writes_parquet_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).display().to_string();
    tiny_trained_model(dir.path(), 20, 8);
    let gt = format!("{}/ground_truth.jsonl", p("synth"));
    // `scbg label` of the tiny model's cache with 3 sampled futures, the `[labels]` settings
    // `labels` and more flags, into `out`; `label` adds the ground truth, expects success and
    // returns its summary.json.
    let run_label = |out: &str, labels: &str, more: &[&str]| {
        let (out_dir, model, cache) = (p(out), p("model"), p("cache"));
        let config = crate::settings(dir.path(), &format!("[labels]\nsamples = 3\n{labels}"));
        let config = config.display().to_string();
        let mut args = vec![
            "label", "--model", &model, "--data", &cache, "--out", &out_dir, "--config", &config,
        ];
        args.extend_from_slice(more);
        scbg(&args)
    };
    let label = |out: &str, labels: &str| -> Value {
        let done = run_label(out, labels, &["--ground-truth", &gt]);
        assert!(
            done.status.success(),
            "{}",
            String::from_utf8_lossy(&done.stderr)
        );
        serde_json::from_str(
            &std::fs::read_to_string(dir.path().join(out).join("summary.json")).unwrap(),
        )
        .unwrap()
    };
    let old_layout = "lane_move_steps = 0\nkeep_baseline_samples = false\n";
    let summary = label("labels", old_layout);
    // 20 scenarios × 1 labelled pair × 2 roles × (1 logged + 3 sampled).
    assert_eq!(summary["rows"], 20 * 2 * 4);
    assert_eq!(summary["keep_baseline"], false, "{summary}");
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
    let rows = scbg_lab::labels::read_label_table(&dir.path().join("labels/labels-00000.parquet"))
        .unwrap();
    assert_eq!(rows.iter().filter(|r| r.psi_true.is_some()).count(), 80);
    let parquet = dir.path().join("labels/labels-00000.parquet");
    let bytes = std::fs::read(&parquet).unwrap();
    assert_eq!(&bytes[..4], b"PAR1");
    // A second run reads the finished shard instead of relabelling it.
    let before = std::fs::metadata(&parquet).unwrap().modified().unwrap();
    assert!(run_label("labels", old_layout, &[]).status.success());
    assert_eq!(
        std::fs::metadata(&parquet).unwrap().modified().unwrap(),
        before
    );
    // A run asking for other options (the default layout) is refused, naming what differs,
    // and the folder's tables are left alone; so is a folder of tables without the record of
    // their options (labelled before it existed).
    let other = run_label("labels", "", &[]);
    let err = String::from_utf8_lossy(&other.stderr);
    assert!(!other.status.success(), "{err}");
    assert!(
        err.contains("other options") && err.contains("keep_baseline: false there, true asked"),
        "{err}"
    );
    assert!(err.contains("lane_move_steps: 0 there, 30 asked"), "{err}");
    assert_eq!(
        std::fs::metadata(&parquet).unwrap().modified().unwrap(),
        before
    );
    std::fs::create_dir_all(p("labels_unrecorded")).unwrap();
    std::fs::copy(
        &parquet,
        dir.path().join("labels_unrecorded/labels-00000.parquet"),
    )
    .unwrap();
    let unrecorded = run_label("labels_unrecorded", "", &[]);
    let err = String::from_utf8_lossy(&unrecorded.stderr);
    assert!(
        !unrecorded.status.success() && err.contains("no label_options.json"),
        "{err}"
    );
    // A record without `lane_move_room` reads as MOBIL's polite room, the one its moves were
    // kept with: today's room is refused, naming it.
    let record = dir.path().join("labels/label_options.json");
    let current: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&record).unwrap()).unwrap();
    assert_eq!(current["lane_move_room"]["braking_mps2"], 7.0, "{current}");
    let mut old = current.clone();
    old.as_object_mut().unwrap().remove("lane_move_room");
    std::fs::write(&record, old.to_string()).unwrap();
    let refused = run_label("labels", old_layout, &[]);
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && err.contains("lane_move_room"),
        "{err}"
    );
    // A field this build does not know (a newer run's) is a difference too.
    let mut newer = current.clone();
    newer
        .as_object_mut()
        .unwrap()
        .insert("newer_field".into(), true.into());
    std::fs::write(&record, newer.to_string()).unwrap();
    let refused = run_label("labels", old_layout, &[]);
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && err.contains("newer_field: true there, - asked"),
        "{err}"
    );
    assert_eq!(
        std::fs::metadata(&parquet).unwrap().modified().unwrap(),
        before
    );
    // ψ toward B's neighbours: same rows, each counting its audience; a bad radius or an
    // unknown setting is refused before anything is written.
    for (bad_settings, needle) in [
        ("audience = \"neighbours:0\"\n", "radius 0"),
        ("lane_moves = 3\n", "lane_moves"),
    ] {
        let bad = run_label("labels_bad", bad_settings, &[]);
        let err = String::from_utf8_lossy(&bad.stderr);
        assert!(!bad.status.success() && err.contains(needle), "{err}");
        assert!(!dir.path().join("labels_bad").exists());
    }
    let summary = label(
        "labels_neighbours",
        &format!("audience = \"neighbours:30:proximity\"\n{old_layout}"),
    );
    assert_eq!(summary["rows"], 20 * 2 * 4);
    assert_eq!(summary["audience"]["kind"], "neighbours", "{summary}");
    assert_eq!(summary["audience"]["weighting"], "proximity", "{summary}");
    assert!(summary["audience_size_mean"].as_f64().unwrap() >= 1.0);
    assert!(summary["fidelity"].is_null(), "{summary}");
    // With lane moves (the default): the logged and sampled futures as before, then the
    // moves of the sampled ones, scored by the oracle apart from them.
    let summary = label("labels_moves", "keep_baseline_samples = false\n");
    assert_eq!(summary["lane_move_steps"], 30, "{summary}");
    assert_eq!(summary["lane_move_room"]["braking_mps2"], 7.0, "{summary}");
    assert_eq!(summary["lane_move_room"]["reaction_s"], 0.5, "{summary}");
    let moves = summary["lane_moves"].as_u64().unwrap();
    assert!(moves > 0, "no lane move labelled: {summary}");
    assert_eq!(summary["rows"].as_u64().unwrap(), 20 * 2 * 4 + moves);
    let fidelity = &summary["fidelity"];
    assert_eq!(fidelity["sampled"]["all"]["n"], 60, "{summary}");
    // Only the ground-truth roles' moves are scored (half of the roles): some, not all.
    let scored = fidelity["lane_moves"]["all"]["n"]
        .as_u64()
        .unwrap_or_else(|| panic!("no lane-move fidelity: {summary}"));
    assert!(
        scored > 0 && scored < moves,
        "{scored} of {moves}: {summary}"
    );
    // The baseline's futures kept (the default): labelled after the 3 sampled ones (5 in
    // all), the moves after them; none left over for E[r(Y_A) | x] alone.
    let summary = label("labels_kept", "baseline_samples = 2\n");
    assert_eq!(summary["samples_per_pair"], 5, "{summary}");
    assert_eq!(summary["baseline_samples"], 0, "{summary}");
    assert_eq!(summary["keep_baseline"], true, "{summary}");
    let moves = summary["lane_moves"].as_u64().unwrap();
    assert!(moves > 0, "no lane move labelled: {summary}");
    assert_eq!(summary["rows"].as_u64().unwrap(), 20 * 2 * 6 + moves);
    assert_eq!(summary["fidelity"]["sampled"]["all"]["n"], 100, "{summary}");
}

#[test]
fn train_generator_saves_generator_and_range_predictor() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).display().to_string();
    tiny_trained_model(dir.path(), 16, 12);
    let tiny = |epochs: usize| {
        crate::settings(
            dir.path(),
            &format!(
                "[labels]\nsamples = 2\n[generator]\nepochs = {epochs}\nbatch_size = 8\nrange_steps = 20\n"
            ),
        )
        .display()
        .to_string()
    };
    // `scbg train generator` into `out` with `epochs` and the remaining arguments.
    let train = |out: &str, epochs: usize, rest: &[&str]| {
        let (model, cache, out, config) = (p("model"), p("cache"), p(out), tiny(epochs));
        let mut args = vec![
            "train",
            "generator",
            "--predictor",
            &model,
            "--data",
            &cache,
        ];
        args.extend(["--out", &out, "--config", &config]);
        args.extend(rest);
        scbg_ok(&args);
    };
    train("gen", 2, &[]);
    let saved: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("gen/generator.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(saved["variant"], "full");
    // The modes' slowed copies join the choices.
    assert_eq!(
        saved["generator"]["mode_slowdowns"],
        serde_json::json!([0.75, 0.5])
    );
    assert_eq!(saved["history"].as_array().unwrap().len(), 2);
    assert!(saved["examples"].as_u64().unwrap() > 0);
    assert!(saved["range_loss"].as_f64().unwrap().is_finite());
    assert!(
        dir.path().join("gen/generator.bpk").is_file()
            && dir.path().join("gen/range.bpk").is_file()
    );
    train("gen_base", 1, &["--variant", "baseline"]);
    let base: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("gen_base/generator.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(base["variant"], "baseline");
    assert_eq!(base["history"].as_array().unwrap().len(), 1);

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
    // The arguments of `command` that name the generator, the scene and the pair.
    let pair_args = |command: &'static str, b: &str, rest: &[&str]| -> Vec<String> {
        [
            command,
            "--model",
            &gen_dir,
            "--scenario",
            &file,
            "--scenario-id",
            sid,
        ]
        .into_iter()
        .chain(["--a", &a, "--b", b])
        .chain(rest.iter().copied())
        .map(str::to_string)
        .collect()
    };
    let generate = |b: &str, rest: &[&str]| {
        let args = pair_args("generate", b, rest);
        scbg(&args.iter().map(String::as_str).collect::<Vec<_>>())
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
    // Each future answers its quantile, in the order asked, over a range the range predictor
    // did not collapse; the two ends of the knob give B different futures. (That ψ_true and
    // J_φ rise with the quantile is checked on held-out scenes, `direction.rs`.)
    for (t, q) in trajs.iter().zip([0.1, 0.5, 0.9]) {
        assert!((t["quantile"].as_f64().unwrap() - q).abs() < 1e-6, "{t}");
        assert_eq!(t["world_xy_m"].as_array().unwrap().len(), 80);
        let (low, high) = (
            t["psi_low"].as_f64().unwrap(),
            t["psi_high"].as_f64().unwrap(),
        );
        assert!(low < high, "a collapsed range: {low} … {high}");
        assert!(t["achieved_psi"].as_f64().unwrap().is_finite(), "{t}");
    }
    assert_ne!(trajs[0]["world_xy_m"], trajs[2]["world_xy_m"]);
    crate::assert_drawn_png(&dir.path().join("traj.png"), (900, 900));
    // Bad requests name what is wrong and exit 2.
    let bad = generate("987654321", &["--quantile", "0.5"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("987654321"));
    let bad = generate(&b, &["--quantile", "1.5"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("quantile"));

    // An ensemble folder: its future at each quantile is the medoid of its members'. With two
    // copies of `gen` and one other generator listed first, that is `gen`'s future.
    train("gen2", 2, &["--seed", "1"]);
    let ens_dir = dir.path().join("ens");
    std::fs::create_dir_all(&ens_dir).unwrap();
    let ensemble = |members: &[&str]| {
        let manifest = serde_json::json!({
            "kind": "scbg-ensemble", "format_version": 1, "members": members,
        });
        std::fs::write(ens_dir.join("ensemble.json"), manifest.to_string()).unwrap();
    };
    let ens_dir = ens_dir.display().to_string();
    // `scbg generate` of the pair with another model.
    let generate_with = |model: &str, quantiles: &[&str]| {
        let mut args = pair_args("generate", &b, &["--quantile"]);
        args[2] = model.to_string();
        args.extend(quantiles.iter().map(|q| q.to_string()));
        scbg(&args.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let futures = |model: &str, quantiles: &[&str]| -> Vec<Value> {
        let out = generate_with(model, quantiles);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let json: Value = serde_json::from_slice(&out.stdout).unwrap();
        let trajectories = json["trajectories"].as_array().unwrap();
        trajectories
            .iter()
            .map(|t| t["world_xy_m"].clone())
            .collect()
    };
    let gen_futures: Vec<Value> = trajs.iter().map(|t| t["world_xy_m"].clone()).collect();
    let gen_path = gen_dir.as_str();
    for members in [
        ["../gen2", "../gen", gen_path],
        ["../gen", gen_path, "../gen2"],
    ] {
        ensemble(&members);
        assert_eq!(
            futures(&ens_dir, &["0.1", "0.5", "0.9"]),
            gen_futures,
            "{members:?}"
        );
    }
    assert_ne!(
        futures(&p("gen2"), &["0.9"]),
        futures(&gen_dir, &["0.9"]),
        "the members differ"
    );
    // Members of different variants, or none, are refused, naming the file.
    for members in [&["../gen", "../gen_base"][..], &[]] {
        ensemble(members);
        let bad = generate_with(&ens_dir, &["0.5"]);
        assert_eq!(bad.status.code(), Some(2), "{members:?}");
        assert!(String::from_utf8_lossy(&bad.stderr).contains("ensemble.json"));
    }

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
    // The same selectors among the generator's own choices: every role has all of them
    // (B's modes and their two slowed copies), and ranked by ψ_true the picks rise with q.
    let candidates = &eval["truth_control_candidates"];
    let modes = saved["generator"]["modes"].as_u64().unwrap();
    assert!(modes > 0);
    assert_eq!(
        candidates["by_label"]["examples"]["all"].as_u64(),
        Some(roles),
        "{eval}"
    );
    assert_eq!(
        candidates["candidates_mean"].as_f64(),
        Some(3.0 * modes as f64),
        "{candidates}"
    );
    let means: Vec<f64> = candidates["by_truth"]["per_quantile"]
        .as_array()
        .unwrap()
        .iter()
        .map(|q| q["psi_true_mean"].as_f64().unwrap())
        .collect();
    assert!(means.windows(2).all(|w| w[0] <= w[1]), "{means:?}");
    for variant in ["baseline", "full"] {
        let v = &eval["variants"][variant];
        for key in [
            "courtesy_mse_data",
            "courtesy_mse_range",
            "courtesy_mse_arbitrary",
            "traj_ade",
        ] {
            // Means and spreads over the examples: errors that are positive and differ
            // from one example to the next.
            let (mean, std) = (
                v[key]["mean"].as_f64().unwrap(),
                v[key]["std"].as_f64().unwrap(),
            );
            assert!(mean.is_finite() && mean > 0.0, "{variant} {key}: {v}");
            assert!(std.is_finite() && std > 0.0, "{variant} {key}: {v}");
        }
        assert!(v["corr_quantile"].is_number(), "{variant}: {v}");
        assert!(v.get("corr_quantile_high").is_some(), "{variant}: {v}");
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
        let mut args = pair_args("sim", &b, &["--out", out]);
        args.extend(rest.iter().map(|r| r.to_string()));
        scbg(&args.iter().map(String::as_str).collect::<Vec<_>>())
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
    let closed_loop = |text: &str| {
        crate::settings(dir.path(), &format!("[closed_loop]\n{text}"))
            .display()
            .to_string()
    };
    let wosac = closed_loop("format = \"wosac\"\nname = \"mine\"\n");
    let ok = sim(&p("simw"), &["--config", &wosac]);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    crate::wosac::own_submission_scores_as_the_closed_loop(
        std::path::Path::new(&file),
        &dir.path().join("simw"),
        "mine",
    );
    // Bad requests: named, exit 2, nothing written.
    let few = closed_loop("format = \"wosac\"\nrollouts = 3\n");
    let never = closed_loop("replan_every = 0\n");
    let unknown = closed_loop("spred = 0.1\n");
    for (rest, needle) in [
        (&["--quantile", "1.5"][..], "quantile 1.5"),
        (&["--also", "4242=0.5"][..], "4242"),
        (&["--config", &few][..], "32 rollouts"),
        (&["--config", &never][..], "replan_every"),
        (&["--config", &unknown][..], "spred"),
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
        "--config",
        &closed_loop("wosac_quantiles = [0.5]\nspread = 0.1\n"),
        "--out",
        &p("evalsim"),
        "--json",
    ]);
    let eval: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(eval["scenes"], 2);
    assert_eq!(eval["per_quantile"].as_array().unwrap().len(), 9);
    // Realism: the log's own futures and IDM score above constant velocity.
    let meta = |baseline: &str| {
        eval["baselines"][baseline]["wosac"]["metametric"]
            .as_f64()
            .unwrap_or_else(|| panic!("no {baseline} meta-metric: {eval}"))
    };
    let cv = meta("constant_velocity");
    assert!(meta("log_replay") > cv && meta("idm_only") > cv, "{eval}");
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
    crate::real_data::eval_sim_on_real_files(&gen_dir, dir.path());

    // A malformed threshold is a clear error naming the setting.
    let qx = crate::settings(dir.path(), "[generator]\nthreshold = \"qx\"\n");
    let bad = scbg(&[
        "train",
        "generator",
        "--predictor",
        &p("model"),
        "--data",
        &p("cache"),
        "--out",
        &p("gen2"),
        "--config",
        qx.to_str().unwrap(),
    ]);
    assert_eq!(bad.status.code(), Some(2));
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("threshold") && err.contains("qx"), "{err}");
}
