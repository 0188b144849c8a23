//! Scale-out: `deploy/ray/scbg_ray.py` runs `data prepare`, `label` and closed-loop `eval sim`
//! shards as Ray tasks on a local Ray cluster with 2 workers, and the merged results equal a
//! single-process run; the Kubernetes Indexed Job manifests validate against the Kubernetes
//! schema (`kubernetes-validate`, which bundles it).
//!
//! Python with `ray` and `kubernetes-validate` comes from the project's virtualenv
//! (`target/py-venv`, made by `.ci/run`); the test installs the two packages into it when they
//! are missing.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

use crate::scbg_ok;

/// Asserts that a finished command succeeded, with its output in the message.
fn assert_ran(out: &std::process::Output, what: &str) {
    assert!(
        out.status.success(),
        "{what}: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The virtualenv's python, with ray and kubernetes-validate installed.
fn python() -> PathBuf {
    let venv = root().join("target/py-venv");
    if !venv.join("bin/python").exists() {
        let ok = Command::new("python3")
            .args(["-m", "venv"])
            .arg(&venv)
            .status()
            .expect("python3 -m venv");
        assert!(ok.success(), "python3 -m venv failed");
    }
    let python = venv.join("bin/python");
    let has = |module: &str| {
        Command::new(&python)
            .args(["-c", &format!("import {module}")])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if !(has("ray") && has("kubernetes_validate")) {
        let out = Command::new(&python)
            .args(["-m", "pip", "install", "-q", "ray", "kubernetes-validate"])
            .output()
            .expect("pip");
        assert_ran(&out, "pip install ray kubernetes-validate");
    }
    python
}

/// Runs a stage of the Ray driver on a local 2-worker cluster; returns its `ray_<stage>.json`.
fn ray_stage(python: &Path, args: &[&str], out: &Path, stage: &str) -> Value {
    let driver = root().join("deploy/ray/scbg_ray.py");
    let result = Command::new(python)
        .arg(&driver)
        .args(["--num-cpus", "2", "--scbg", env!("CARGO_BIN_EXE_scbg")])
        .args(args)
        .env("RAY_USAGE_STATS_ENABLED", "0")
        .output()
        .expect("run the Ray driver");
    assert_ran(&result, &format!("scbg_ray.py {args:?}"));
    serde_json::from_str(&std::fs::read_to_string(out.join(format!("ray_{stage}.json"))).unwrap())
        .unwrap()
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn ray_shards_merge_to_the_single_process_result_and_k8s_jobs_validate() {
    let python = python();
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s);
    let s = |s: &str| dir.path().join(s).display().to_string();
    scbg_ok(&[
        "synth",
        "--scenarios",
        "24",
        "--seed",
        "4",
        "--scenarios-per-file",
        "4",
        "--out",
        &s("synth"),
    ]);
    let gt = s("synth/ground_truth.jsonl");

    // prepare: 3 Ray tasks over 3 cache shards (2 files each), then the merge.
    let record = ray_stage(
        &python,
        &[
            "prepare",
            "--input",
            &s("synth"),
            "--out",
            &s("cache"),
            "--shards",
            "3",
            "--",
            "--files-per-shard",
            "2",
        ],
        &p("cache"),
        "prepare",
    );
    assert_eq!(record["tasks"].as_array().unwrap().len(), 3);
    assert_eq!(record["total"]["scenarios"], 24);
    scbg_ok(&[
        "data",
        "prepare",
        "--input",
        &s("synth"),
        "--out",
        &s("cache_one"),
        "--files-per-shard",
        "2",
    ]);
    for shard in 0..3 {
        let name = format!("shard-{shard:05}.bin");
        assert_eq!(
            std::fs::read(p("cache").join(&name)).unwrap(),
            std::fs::read(p("cache_one").join(&name)).unwrap(),
            "{name}"
        );
    }
    assert_eq!(
        read_json(&p("cache/manifest.json"))["total"],
        read_json(&p("cache_one/manifest.json"))["total"]
    );

    // label: 2 Ray tasks over the 3 cache shards, then the merge writes the summary.
    std::fs::write(
        p("train.toml"),
        include_str!("../../../lab/tests/tiny_train.toml"),
    )
    .unwrap();
    scbg_ok(&[
        "train",
        "predictor",
        "--config",
        &s("train.toml"),
        "--data",
        &s("cache"),
        "--out",
        &s("model"),
    ]);
    let two_samples = crate::settings(dir.path(), "[labels]\nsamples = 2\n")
        .display()
        .to_string();
    let record = ray_stage(
        &python,
        &[
            "label",
            "--model",
            &s("model"),
            "--data",
            &s("cache"),
            "--out",
            &s("labels"),
            "--shards",
            "2",
            "--",
            "--config",
            &two_samples,
            "--ground-truth",
            &gt,
        ],
        &p("labels"),
        "label",
    );
    assert_eq!(record["tasks"].as_array().unwrap().len(), 2);
    // 24 scenarios × 2 roles × (1 logged + 2 sampled + the 24 kept baseline futures), then
    // the labelled lane moves (the defaults), as many as the one-process run below has.
    let moves = read_json(&p("labels/summary.json"))["lane_moves"]
        .as_u64()
        .unwrap();
    assert_eq!(record["rows"].as_u64().unwrap(), 24 * 2 * 27 + moves);
    scbg_ok(&[
        "label",
        "--model",
        &s("model"),
        "--data",
        &s("cache"),
        "--out",
        &s("labels_one"),
        "--config",
        &two_samples,
        "--ground-truth",
        &gt,
    ]);
    for shard in 0..3 {
        let name = scbg_lab::labels::shard_table_name(shard);
        assert_eq!(
            scbg_lab::labels::read_label_table(&p("labels").join(&name)).unwrap(),
            scbg_lab::labels::read_label_table(&p("labels_one").join(&name)).unwrap(),
            "{name}"
        );
    }
    assert_eq!(
        read_json(&p("labels/summary.json")),
        read_json(&p("labels_one/summary.json"))
    );
    let bad = crate::scbg(&[
        "label",
        "--model",
        &s("model"),
        "--data",
        &s("cache"),
        "--out",
        &s("labels_bad"),
        "--shard-index",
        "2",
        "--num-shards",
        "2",
    ]);
    assert!(!bad.status.success());
    assert!(
        String::from_utf8_lossy(&bad.stderr)
            .contains("shard index 2 is not below the number of shards 2"),
        "{}",
        String::from_utf8_lossy(&bad.stderr)
    );

    // Closed-loop sim: 2 Ray tasks over the 6 files; scene counts add up.
    scbg_ok(&[
        "train",
        "generator",
        "--predictor",
        &s("model"),
        "--data",
        &s("cache"),
        "--out",
        &s("gen"),
        "--config",
        &crate::settings(
            dir.path(),
            "[labels]\nsamples = 2\n[generator]\nepochs = 1\nbatch_size = 8\nrange_steps = 10\n",
        )
        .display()
        .to_string(),
    ]);
    let record = ray_stage(
        &python,
        &[
            "sim",
            "--model",
            &s("gen"),
            "--data",
            &s("synth"),
            "--out",
            &s("sim"),
            "--shards",
            "2",
            "--",
            "--ground-truth",
            &gt,
            "--split",
            "all",
            "--scenes",
            "100",
            "--wosac-scenes",
            "0",
        ],
        &p("sim"),
        "sim",
    );
    assert_eq!(record["tasks"].as_array().unwrap().len(), 2);
    let merged = read_json(&p("sim/eval_sim_merged.json"));
    let shards: Vec<Value> =
        serde_json::from_value(read_json(&p("sim/eval_sim_shards.json"))).unwrap();
    assert_eq!(shards.len(), 2);
    let scenes: u64 = shards.iter().map(|r| r["scenes"].as_u64().unwrap()).sum();
    assert_eq!(merged["scenes"].as_u64().unwrap(), scenes);
    assert!(scenes >= 20, "{merged}");
    assert_eq!(merged["per_quantile"].as_array().unwrap().len(), 9);

    // The Kubernetes Indexed Jobs of the same shards validate against the Kubernetes schema.
    let manifests: Vec<PathBuf> = std::fs::read_dir(root().join("deploy/k8s"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "yaml"))
        .collect();
    assert!(manifests.len() >= 3, "{manifests:?}");
    let out = Command::new(python.parent().unwrap().join("kubernetes-validate"))
        .arg("--strict")
        .args(&manifests)
        .output()
        .expect("kubernetes-validate");
    assert_ran(&out, "kubernetes-validate");
    // ... and the validator does reject a Job with a misspelt field.
    let broken = std::fs::read_to_string(&manifests[0])
        .unwrap()
        .replace("completions:", "completion:");
    std::fs::write(p("broken.yaml"), broken).unwrap();
    let out = Command::new(python.parent().unwrap().join("kubernetes-validate"))
        .arg("--strict")
        .arg(p("broken.yaml"))
        .output()
        .expect("kubernetes-validate");
    assert!(!out.status.success(), "a misspelt field passed validation");
}
