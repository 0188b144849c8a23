//! `scbg eval wosac` end to end: the specification's reference values on the genuine scenario,
//! submissions packed as the challenge uploads them, bad input left out by reason, and scbg's
//! own closed-loop export scored as the closed loop scored it.

use std::path::{Path, PathBuf};

use scbg_metrics::wosac::reference::{self, Reference};
use serde_json::Value;

use crate::{real_dir, scbg, scbg_ok};

/// `scbg eval wosac --json` of `scenarios` and `submission`; the exit code and the report.
fn eval(scenarios: &[&Path], submission: &[&Path], out: &Path) -> (Option<i32>, Value) {
    let mut args: Vec<String> = vec!["eval".into(), "wosac".into(), "--scenarios".into()];
    args.extend(scenarios.iter().map(|p| p.display().to_string()));
    args.push("--submission".into());
    args.extend(submission.iter().map(|p| p.display().to_string()));
    args.extend(["--out".into(), out.display().to_string(), "--json".into()]);
    let run = scbg(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let stdout = String::from_utf8(run.stdout).unwrap();
    let report: Value = serde_json::from_str(&stdout)
        .unwrap_or_else(|e| panic!("{e}: {stdout}\n{}", String::from_utf8_lossy(&run.stderr)));
    // The file and the printed report are the same.
    let written: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("wosac.json")).unwrap()).unwrap();
    assert_eq!(written, report);
    (run.status.code(), report)
}

/// The largest difference of `scenario` (one `per_scenario` entry) to `official`.
fn largest_difference(scenario: &Value, official: &Reference) -> f64 {
    let l = &scenario["likelihoods"];
    let mut rows = vec![("metametric", &scenario["metametric"], official.metametric)];
    for (k, name) in reference::LIKELIHOOD_NAMES.iter().enumerate() {
        rows.push((name, &l[name], official.likelihoods[k]));
    }
    rows.extend([
        (
            "average_displacement_error_m",
            &scenario["average_displacement_error_m"],
            official.ade_m,
        ),
        (
            "min_average_displacement_error_m",
            &scenario["min_average_displacement_error_m"],
            official.ade_m,
        ),
        (
            "simulated_collision_rate",
            &scenario["simulated_collision_rate"],
            official.collision_rate,
        ),
        (
            "simulated_offroad_rate",
            &scenario["simulated_offroad_rate"],
            official.offroad_rate,
        ),
    ]);
    let mut worst = 0.0f64;
    for (name, ours, theirs) in rows {
        let ours = ours
            .as_f64()
            .unwrap_or_else(|| panic!("{name}: {scenario}"));
        let diff = (ours - f64::from(theirs)).abs();
        assert!(diff < 1e-6, "{name}: {ours} against the official {theirs}");
        worst = worst.max(diff);
    }
    worst
}

/// The submission of `rollouts` of `scene` in `dir`, one shard written by
/// `write_submission_shards`.
fn shard_of(
    dir: &Path,
    name: &str,
    scenario_id: &str,
    rollouts: &scbg_metrics::wosac::Rollouts,
) -> PathBuf {
    let input = scbg::wosac::submission_input(scenario_id, rollouts);
    let header = scbg_womd::wosac::SubmissionHeader {
        unique_method_name: name.into(),
        ..Default::default()
    };
    scbg_womd::wosac::write_submission_shards(dir, name, &header, &[input], 1)
        .unwrap()
        .remove(0)
}

#[test]
fn eval_wosac_reproduces_the_reference_values() {
    let Some(real) = real_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = real.join("womd/motion_data_one_scenario.tfrecord");
    let scene = scbg_womd::WomdFile::open(&file)
        .unwrap()
        .scenes()
        .next()
        .unwrap()
        .unwrap();
    let n = scbg_metrics::wosac::ROLLOUTS_PER_SCENARIO;
    let mut worst = 0.0f64;
    for (name, rollouts, official) in [
        (
            "log-replay",
            scbg_metrics::wosac::log_replay_rollouts(&scene, n).unwrap(),
            reference::LOG_REPLAY,
        ),
        (
            "constant-velocity",
            scbg_metrics::wosac::constant_velocity_rollouts(&scene, n).unwrap(),
            reference::CONSTANT_VELOCITY,
        ),
    ] {
        // Written by the library's encoder, and by `scbg data wosac-baseline`.
        let shard = shard_of(&d.join(name), name, &scene.scenario_id, &rollouts);
        let baseline = d.join(format!("{name}-cli"));
        scbg_ok(&[
            "data",
            "wosac-baseline",
            "--scenarios",
            file.to_str().unwrap(),
            "--baseline",
            name,
            "--out",
            baseline.to_str().unwrap(),
        ]);
        let written = baseline.join("baseline.binproto-00000-of-00001");
        for submission in [&shard, &written] {
            let (code, report) = eval(&[&file], &[submission], &d.join("out"));
            assert_eq!(code, Some(0), "{report}");
            let scored = report["per_scenario"].as_array().unwrap();
            assert_eq!(scored.len(), 1, "{report}");
            assert_eq!(scored[0]["scenario_id"], reference::SCENARIO_ID);
            worst = worst.max(largest_difference(&scored[0], &official));
            assert_eq!(report["aggregate"]["metametric"], scored[0]["metametric"]);
            assert!(report["skipped_items"].as_array().unwrap().is_empty());
        }
    }
    println!("largest difference to the official values: {worst:.1e}");

    // The table, from a .tar.gz of the shards made as the challenge's tutorial makes it.
    let archive = d.join("submission.tar.gz");
    let tar = std::process::Command::new("tar")
        .arg("czf")
        .arg(&archive)
        .arg("-C")
        .arg(d.join("log-replay"))
        .arg("log-replay.binproto-00000-of-00001")
        .status()
        .unwrap();
    assert!(tar.success());
    let text = scbg_ok(&[
        "eval",
        "wosac",
        "--scenarios",
        file.to_str().unwrap(),
        "--submission",
        archive.to_str().unwrap(),
    ]);
    assert!(
        text.contains("637f20cafde22ff8    0.8266 ") && text.contains("mean of 1"),
        "{text}"
    );
    assert!(text.contains("skipped: nothing"), "{text}");
}

#[test]
fn eval_wosac_lists_what_it_cannot_score() {
    let Some(real) = real_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let genuine = real.join("womd/motion_data_one_scenario.tfrecord");
    let other = real.join("womd-reencoded/1c365f15b70ebdbf.tfrecord");
    let read = |p: &Path| {
        scbg_womd::WomdFile::open(p)
            .unwrap()
            .scenes()
            .next()
            .unwrap()
            .unwrap()
    };
    let (scene, other_scene) = (read(&genuine), read(&other));
    let n = scbg_metrics::wosac::ROLLOUTS_PER_SCENARIO;
    let good = shard_of(
        &d.join("good"),
        "good",
        &scene.scenario_id,
        &scbg_metrics::wosac::log_replay_rollouts(&scene, n).unwrap(),
    );
    let mut short = scbg_metrics::wosac::log_replay_rollouts(&other_scene, n).unwrap();
    short.trajectories.truncate(20);
    let short = shard_of(&d.join("short"), "short", &other_scene.scenario_id, &short);
    let corrupt = d.join("corrupt.binproto-00000-of-00001");
    let bytes = std::fs::read(&good).unwrap();
    std::fs::write(&corrupt, &bytes[..bytes.len() / 3]).unwrap();

    // The genuine scenario scored; the wrong rollout count and the corrupt shard listed.
    let out = d.join("mixed");
    let (code, report) = eval(&[&genuine, &other], &[&good, &short, &corrupt], &out);
    assert_eq!(code, Some(0), "{report}");
    assert_eq!(report["per_scenario"].as_array().unwrap().len(), 1);
    assert_eq!(report["skipped"]["not 32 joint scenes"], 1, "{report}");
    assert_eq!(
        report["skipped"]["not a SimAgentsChallengeSubmission protobuf"], 1,
        "{report}"
    );
    let items = report["skipped_items"].as_array().unwrap();
    let detail = |needle: &str| {
        items
            .iter()
            .find(|k| k["detail"].as_str().unwrap().contains(needle))
            .unwrap_or_else(|| panic!("no {needle:?} in {report}"))
    };
    let k = detail("20 joint scenes");
    assert_eq!(k["scenario_id"], "1c365f15b70ebdbf");
    assert!(
        k["file"]
            .as_str()
            .unwrap()
            .ends_with("short.binproto-00000-of-00001")
    );
    assert!(detail("corrupt.binproto-00000-of-00001")["scenario_id"].is_null());

    // The submitted scenario is in none of the scenario files: nothing scored, exit code 2,
    // the reason printed and written.
    let missing = d.join("missing");
    let mut args = [
        "eval".to_string(),
        "wosac".into(),
        "--scenarios".into(),
        other.display().to_string(),
        "--submission".into(),
        good.display().to_string(),
        "--out".into(),
        missing.display().to_string(),
    ];
    let run = scbg(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(run.status.code(), Some(2));
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("no scenario scored") && err.contains("1 × not in the scenario files"),
        "{err}"
    );
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(text.contains("637f20cafde22ff8"), "{text}");
    let written: Value =
        serde_json::from_str(&std::fs::read_to_string(missing.join("wosac.json")).unwrap())
            .unwrap();
    assert!(written["aggregate"].is_null(), "{written}");
    assert_eq!(written["not_submitted"], 1);

    // Paths that match nothing: a usage error naming the pattern.
    args[5] = d.join("nothing-*.binproto").display().to_string();
    let run = scbg(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("nothing-*"));
}

/// The WOSAC shard `scbg sim` wrote into `sim_dir` for a scenario of `scenario_file`, scored by
/// `scbg eval wosac`, gives every number the closed loop reported in `sim.json`.
pub(crate) fn own_submission_scores_as_the_closed_loop(
    scenario_file: &Path,
    sim_dir: &Path,
    name: &str,
) {
    let sim: Value =
        serde_json::from_str(&std::fs::read_to_string(sim_dir.join("sim.json")).unwrap()).unwrap();
    let closed_loop = &sim["wosac"];
    assert!(closed_loop["metametric"].is_number(), "{sim}");
    let shard = sim_dir.join(format!("{name}.binproto-00000-of-00001"));
    let (code, report) = eval(&[scenario_file], &[&shard], &sim_dir.join("eval"));
    assert_eq!(code, Some(0), "{report}");
    let scored = &report["per_scenario"][0];
    assert_eq!(scored["scenario_id"], sim["scenario_id"]);
    for (key, value) in closed_loop.as_object().unwrap() {
        assert_eq!(&scored[key], value, "{key}: {report}\nagainst {sim}");
    }
    // Rollouts of a courtesy-driven B, not the log: the agents drift from it.
    assert!(
        closed_loop["min_average_displacement_error_m"]
            .as_f64()
            .unwrap()
            > 0.0
    );
}
