//! `scbg train predictor`, `scbg eval predictor`, `scbg eval metrics` and `scbg bench train`;
//! the tiny trained model the other modules start from.

use crate::{real_dir, scbg, scbg_ok};
use serde_json::{Value, json};

/// The tiny predictor config of the library's tests.
pub(crate) const TINY_CONFIG: &str = include_str!("../../../lab/tests/tiny_train.toml");

/// synth → prepare → train (tiny config) in `dir`: `synth/`, `cache/`, `train.toml`, `model/`.
pub(crate) fn tiny_trained_model(dir: &std::path::Path, scenarios: usize, seed: u64) {
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
    tiny_trained_model(dir.path(), 60, 4);
    let ckpt: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("model/checkpoint.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(ckpt["state"]["epoch"], 30);
    // The evaluation reads the scenes it is given only, never the sibling caches the model
    // trained with (gone here, as where a shipped model is evaluated).
    let mut moved = ckpt.clone();
    moved["train_config"]["counterfactual_cache"] = Value::from(p("gone"));
    moved["train_config"]["reaction_cache"] = Value::from(p("gone"));
    std::fs::write(
        dir.path().join("model/checkpoint.json"),
        serde_json::to_string_pretty(&moved).unwrap(),
    )
    .unwrap();
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
    // On the held-out scenes the predictor's six modes beat the single constant-velocity
    // future on minADE, marginally and conditioned on the other agent of the pair.
    let min_ade = |row: &str| {
        let m = &v[row];
        assert!(m["by_time"]["8"]["miss_rate"].is_number(), "{row}: {m}");
        m["min_ade"]
            .as_f64()
            .unwrap_or_else(|| panic!("{row}: no min_ade in {m}"))
    };
    let cv = min_ade("Const. velocity (interacting)");
    for row in [
        "Marginal (interacting agents)",
        "Conditional (interacting agents)",
    ] {
        let ade = min_ade(row);
        assert!(
            ade < cv,
            "{row}: minADE {ade:.2} m, constant velocity {cv:.2} m"
        );
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
