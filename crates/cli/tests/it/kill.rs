//! Crash safety: every stage killed with SIGKILL at a few seeded moments, then re-run (the
//! full sweep is `scbg bench kill`, in BENCHMARKS.md).

use crate::{scbg, scbg_ok};
use serde_json::Value;

#[test]
fn every_stage_killed_and_rerun_ends_as_an_undisturbed_run() {
    let dir = tempfile::tempdir().unwrap();
    let work = dir.path().join("work");
    let out = scbg(&[
        "bench",
        "kill",
        "--work",
        work.to_str().unwrap(),
        "--kills",
        "3",
        "--scenarios",
        "16",
        "--seed",
        "5",
        "--json",
    ]);
    let report: Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!("{e}: {}", String::from_utf8_lossy(&out.stderr));
    });
    assert!(out.status.success(), "{report:#}");
    let rows = report["rows"].as_array().unwrap();
    let stages: Vec<&str> = rows.iter().map(|r| r["stage"].as_str().unwrap()).collect();
    assert_eq!(
        stages,
        [
            "prepare",
            "train_predictor",
            "label",
            "train_generator",
            "sim",
            "eval_sim"
        ]
    );
    for row in rows {
        assert_eq!(row["kills"], 3, "{row}");
        assert_eq!(row["equal"], 3, "{row}");
        for zero in ["partial_visible", "temp_left", "unchecked"] {
            assert_eq!(row[zero], 0, "{zero}: {row}");
        }
    }
    // At least some kills struck a running stage (the rest found it done).
    let struck: u64 = rows.iter().map(|r| r["struck"].as_u64().unwrap()).sum();
    assert!(struck >= 6, "{report:#}");
}

#[test]
fn a_stage_sweeps_what_a_killed_writer_left() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).display().to_string();
    scbg_ok(&["synth", "--scenarios", "4", "--out", &p("synth")]);
    let cache = dir.path().join("cache");
    std::fs::create_dir_all(&cache).unwrap();
    let stale = cache.join(".tmpKILLED.tmp");
    std::fs::write(&stale, "half a shard").unwrap();
    let user = cache.join("notes.tmp");
    std::fs::write(&user, "the user's").unwrap();
    scbg_ok(&[
        "data",
        "prepare",
        "--input",
        &p("synth"),
        "--out",
        &p("cache"),
    ]);
    assert!(!stale.exists(), "the stale temporary file is gone");
    assert!(user.exists(), "a file of the user's stays");
}
