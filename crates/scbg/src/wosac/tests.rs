//! Scoring submissions: the closed loop's numbers for any object order, every kind of bad input
//! left out with its reason, archives, baselines, and the specification's reference values.

use std::path::{Path, PathBuf};

use scbg_metrics::wosac::{
    constant_velocity_rollouts, log_replay_rollouts, reference, scenario_metrics,
};
use scbg_scene::Scene;
use scbg_womd::wosac::write_submission_shards;

use super::*;

const N: usize = scbg_metrics::wosac::ROLLOUTS_PER_SCENARIO;

/// `n` synthetic scenes (91 steps, an SDC, road edges), ids `synth-…`.
fn scenes(n: u64) -> Vec<Scene> {
    (0..n)
        .map(|i| scbg_synth::generate(3, i, &scbg_synth::Family::DEFAULT).scene)
        .collect()
}

fn write_file(dir: &Path, name: &str, scenes: &[Scene]) -> PathBuf {
    let path = dir.join(name);
    scbg_womd::write_scenes(&path, scenes).unwrap();
    path
}

/// One shard `name.binproto-00000-of-00001` holding `rollouts`.
fn shard(dir: &Path, name: &str, rollouts: &[ScenarioRolloutsInput]) -> PathBuf {
    let header = SubmissionHeader {
        unique_method_name: name.into(),
        ..Default::default()
    };
    write_submission_shards(dir, name, &header, rollouts, 1)
        .unwrap()
        .remove(0)
}

fn paths(p: &[&Path]) -> Vec<String> {
    p.iter().map(|p| p.display().to_string()).collect()
}

fn score(scenarios: &[&Path], submission: &[&Path]) -> WosacScore {
    score_submission(&paths(scenarios), &paths(submission), &crate::Quiet).unwrap()
}

/// Log replay whose joint scene r moves every agent by 0.05·r m in x, so the rollouts differ.
fn spread_log_replay(scene: &Scene) -> Rollouts {
    let mut r = log_replay_rollouts(scene, N).unwrap();
    for (k, joint) in r.trajectories.iter_mut().enumerate() {
        for pose in joint.iter_mut().flatten() {
            pose.x_m += 0.05 * k as f32;
        }
    }
    r
}

#[test]
fn any_object_order_scores_as_the_closed_loop_does() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scenes(1).remove(0);
    let file = write_file(dir.path(), "s.tfrecord", std::slice::from_ref(&scene));
    let rollouts = spread_log_replay(&scene);
    let direct = scenario_metrics(&scene, &rollouts, CHALLENGE).unwrap();
    // A submission may list each joint scene's objects in its own order.
    let mut input = submission_input(&scene.scenario_id, &rollouts);
    for joint in input.joint_scenes.iter_mut().skip(1).step_by(2) {
        joint.reverse();
    }
    assert_eq!(rollouts_of_submission(&input), rollouts);
    let s = score(&[&file], &[&shard(dir.path(), "mine", &[input])]);
    assert_eq!(s.scored(), 1, "{s:?}");
    assert_eq!(s.per_scenario[0].metrics, direct);
    assert!(direct.min_average_displacement_error_m < direct.average_displacement_error_m);
    assert_eq!(s.aggregate.as_ref().unwrap().metametric, direct.metametric);
    assert!(s.per_scenario[0].seconds > 0.0);
    assert_eq!((s.not_submitted, s.shards), (0, 1));
    assert!(s.skipped.is_empty(), "{s:?}");
}

#[test]
fn bad_input_is_left_out_with_its_reason() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let all = scenes(4);
    let file = write_file(d, "s.tfrecord", &all);
    let garbage_file = d.join("garbage.tfrecord");
    std::fs::write(&garbage_file, b"not a tfrecord file").unwrap();
    let input = |scene: &Scene| {
        submission_input(&scene.scenario_id, &log_replay_rollouts(scene, N).unwrap())
    };
    let good = shard(d, "a", &[input(&all[0])]);
    let corrupt = d.join("b.binproto-00000-of-00001");
    std::fs::write(&corrupt, [0x0A, 0x05, 0x01]).unwrap();
    let mut short = input(&all[1]);
    short.joint_scenes.pop();
    let mut nan = input(&all[2]);
    nan.joint_scenes[3][1].heading_rad[7] = f32::NAN;
    let mut unknown = input(&all[0]);
    unknown.scenario_id = "nope".into();
    // Scene 0 again, the wrong count, a NaN, an id no file holds; scene 3 is not submitted.
    let mixed = shard(d, "c", &[input(&all[0]), short, nan, unknown]);

    let s = score(&[&file, &garbage_file], &[&good, &corrupt, &mixed]);
    let ids: Vec<&str> = s
        .per_scenario
        .iter()
        .map(|p| p.metrics.scenario_id.as_str())
        .collect();
    assert_eq!(ids, [all[0].scenario_id.as_str()]);
    assert_eq!(s.per_scenario[0].shard, good.display().to_string());
    assert_eq!(s.per_scenario[0].scenario_file, file.display().to_string());
    assert_eq!((s.scenarios_in_files, s.not_submitted, s.shards), (4, 1, 3));
    let count = |reason: &str| s.skipped.get(reason).copied().unwrap_or(0);
    assert_eq!(
        count("not a SimAgentsChallengeSubmission protobuf"),
        1,
        "{s:#?}"
    );
    assert_eq!(count("a scenario repeated in the submission"), 1);
    assert_eq!(count("not 32 joint scenes"), 1);
    assert_eq!(count("a simulated value is not finite"), 1);
    assert_eq!(count(NOT_IN_SCENARIO_FILES), 1);
    assert_eq!(
        count("unreadable scenario file (bad_length_crc)"),
        1,
        "{s:#?}"
    );
    assert_eq!(s.skipped_items.len(), 6);
    // Each item names its file, its scenario and what is wrong.
    let item = |reason: &str| {
        s.skipped_items
            .iter()
            .find(|k| k.reason == reason)
            .unwrap()
            .clone()
    };
    assert_eq!(
        item("not a SimAgentsChallengeSubmission protobuf").file,
        corrupt.display().to_string()
    );
    let k = item("not 32 joint scenes");
    assert_eq!(k.scenario_id.as_deref(), Some(all[1].scenario_id.as_str()));
    assert!(k.detail.contains("31 joint scenes"), "{k:?}");
    assert_eq!(k.file, mixed.display().to_string());
    let k = item("a simulated value is not finite");
    assert!(
        k.detail.contains("joint scene 3") && k.detail.contains("heading"),
        "{k:?}"
    );
    assert!(item(NOT_IN_SCENARIO_FILES).detail.contains("nope"));
    let k = item("unreadable scenario file (bad_length_crc)");
    assert!(k.file.ends_with("garbage.tfrecord") && k.detail.contains("record 0"));
    let text = s.to_text();
    assert!(text.contains("skipped: 6 ("), "{text}");
    assert!(text.contains("31 joint scenes"), "{text}");
    assert!(text.contains("mean of 1"), "{text}");

    // Nothing scored: the report says why, with no mean.
    let s = score(&[&file], &[&corrupt]);
    assert_eq!((s.scored(), s.not_submitted), (0, 4));
    assert!(s.aggregate.is_none() && s.seconds_per_scenario.is_none());
    assert!(s.to_text().contains("not a SimAgentsChallengeSubmission"));
}

/// A gzip-compressed tar archive at `path` with `(name, bytes)` entries.
fn tar_gz(path: &Path, entries: &[(&str, Vec<u8>)]) {
    let gz = flate2::write::GzEncoder::new(
        std::fs::File::create(path).unwrap(),
        flate2::Compression::default(),
    );
    let mut tar = tar::Builder::new(gz);
    for (name, bytes) in entries {
        let mut header = tar::Header::new_gnu();
        header.set_size(bytes.len() as u64);
        header.set_mode(0o644);
        header.set_cksum();
        tar.append_data(&mut header, name, &bytes[..]).unwrap();
    }
    tar.into_inner().unwrap().finish().unwrap();
}

#[test]
fn archives_of_shards_score_as_their_shards() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let all = scenes(3);
    let file = write_file(d, "s.tfrecord", &all);
    let inputs: Vec<ScenarioRolloutsInput> = all
        .iter()
        .map(|s| submission_input(&s.scenario_id, &spread_log_replay(s)))
        .collect();
    let header = SubmissionHeader::default();
    let shards = write_submission_shards(&d.join("shards"), "m", &header, &inputs, 2).unwrap();
    let plain = score(
        &[&file],
        &shards.iter().map(PathBuf::as_path).collect::<Vec<_>>(),
    );
    assert_eq!(plain.scored(), 3);

    // The archive's file name does not matter; entries without `.binproto` are ignored.
    let mut entries = vec![("README.txt", b"my method".to_vec())];
    let names: Vec<String> = shards
        .iter()
        .map(|p| format!("sub/{}", p.file_name().unwrap().to_string_lossy()))
        .collect();
    for (name, path) in names.iter().zip(&shards) {
        entries.push((name.as_str(), std::fs::read(path).unwrap()));
    }
    let archive = d.join("submission.bin");
    tar_gz(&archive, &entries);
    let packed = score(&[&file], &[&archive]);
    assert_eq!(packed.shards, 2);
    let metrics = |s: &WosacScore| -> Vec<ScenarioMetrics> {
        s.per_scenario.iter().map(|p| p.metrics.clone()).collect()
    };
    assert_eq!(metrics(&packed), metrics(&plain));
    assert_eq!(packed.aggregate, plain.aggregate);
    assert!(
        packed.per_scenario[0]
            .shard
            .ends_with("submission.bin:sub/m.binproto-00000-of-00002"),
        "{}",
        packed.per_scenario[0].shard
    );

    // An archive without shards, and one cut short.
    let empty = d.join("empty.tar.gz");
    tar_gz(&empty, &entries[..1]);
    let s = score(&[&file], &[&empty]);
    assert_eq!(s.skipped.get("no shard in the archive"), Some(&1), "{s:?}");
    assert!(s.skipped_items[0].detail.contains("README.txt"), "{s:?}");
    let bytes = std::fs::read(&archive).unwrap();
    let cut = d.join("cut.tar.gz");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let s = score(&[&file], &[&cut]);
    assert_eq!(
        s.skipped.get("unreadable submission archive"),
        Some(&1),
        "{s:?}"
    );
    assert!(
        s.skipped_items
            .iter()
            .any(|k| k.file.ends_with("cut.tar.gz"))
    );
}

#[test]
fn inputs_that_match_nothing_are_the_callers_fault() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("none-*.tfrecord").display().to_string();
    let args = std::slice::from_ref(&missing);
    let err = score_submission(args, args, &crate::Quiet).unwrap_err();
    assert!(crate::is_invalid_request(&err), "{err:#}");
    assert!(format!("{err:#}").contains("none-*"), "{err:#}");
}

#[test]
fn baselines_are_written_per_file_and_score_as_their_rollouts() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let all = scenes(3);
    let mut short = all[2].clone();
    short.scenario_id = "short".into();
    for t in &mut short.tracks {
        t.states.truncate(50);
    }
    short.timestamps_secs.truncate(50);
    let first = write_file(d, "a.tfrecord", &all[..2]);
    let second = write_file(d, "b.tfrecord", &[short]);
    let files = paths(&[&first, &second]);
    let out = write_baseline(
        &files,
        Baseline::ConstantVelocity,
        &d.join("cv"),
        "cv",
        &crate::Quiet,
    )
    .unwrap();
    assert_eq!(out.files.len(), 2);
    assert!(out.files[1].ends_with("cv.binproto-00001-of-00002"));
    assert_eq!(out.scenarios, 2);
    assert_eq!(out.skipped.len(), 1);
    assert_eq!(out.skipped[0].scenario_id.as_deref(), Some("short"));
    assert!(out.skipped[0].detail.contains("50 steps"), "{out:?}");

    let shard_paths = paths(&out.files.iter().map(PathBuf::as_path).collect::<Vec<_>>());
    let s = score_submission(&files, &shard_paths, &crate::Quiet).unwrap();
    assert_eq!(s.scored(), 2);
    assert_eq!(s.not_submitted, 1); // the short scene
    for (p, scene) in s.per_scenario.iter().zip(&all) {
        let direct = scenario_metrics(
            scene,
            &constant_velocity_rollouts(scene, N).unwrap(),
            CHALLENGE,
        )
        .unwrap();
        assert_eq!(p.metrics, direct);
    }
    let err = write_baseline(&files, Baseline::LogReplay, d, "a/b", &crate::Quiet).unwrap_err();
    assert!(crate::is_invalid_request(&err), "{err:#}");
}

#[test]
fn reference_values_of_the_genuine_scenario() {
    let Some(real) = scbg_womd::fixtures::real_data_dir() else {
        return;
    };
    let file = real.join("womd/motion_data_one_scenario.tfrecord");
    let scene = crate::data::read_scenes(&file).unwrap().remove(0);
    assert_eq!(scene.scenario_id, reference::SCENARIO_ID);
    let dir = tempfile::tempdir().unwrap();
    let mut worst = 0.0f32;
    for (name, rollouts, official) in [
        (
            "log_replay",
            log_replay_rollouts(&scene, N).unwrap(),
            reference::LOG_REPLAY,
        ),
        (
            "constant_velocity",
            constant_velocity_rollouts(&scene, N).unwrap(),
            reference::CONSTANT_VELOCITY,
        ),
    ] {
        let input = submission_input(&scene.scenario_id, &rollouts);
        let s = score(&[&file], &[&shard(dir.path(), name, &[input])]);
        assert_eq!(s.scored(), 1, "{s:?}");
        for (field, ours, theirs) in official.compare(&s.per_scenario[0].metrics) {
            let diff = (ours - theirs).abs();
            println!("{name} {field}: {ours} (official {theirs}, diff {diff:.1e})");
            assert!(diff < 1e-6, "{name} {field}: {ours} against {theirs}");
            worst = worst.max(diff);
        }
    }
    println!("largest difference to the official values: {worst:.1e}");
}
