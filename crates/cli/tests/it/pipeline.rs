//! Generated data through the reader, the cache and the renderer.

use crate::{inspect_json, real_dir, scbg_ok};

#[test]
fn synth_files_read_back_with_labelled_vehicle_pairs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("synth");
    scbg_ok(&[
        "synth",
        "--scenarios",
        "60",
        "--seed",
        "3",
        "--out",
        out.to_str().unwrap(),
        "--scenarios-per-file",
        "25",
    ]);
    let files: Vec<_> = (0..3)
        .map(|i| out.join(format!("synth-{i:05}.tfrecord")))
        .collect();
    let refs: Vec<&std::path::Path> = files.iter().map(|p| p.as_path()).collect();
    let rows = inspect_json(&refs);
    assert_eq!(rows.len(), 60);
    for v in &rows {
        assert_eq!(v["objects_of_interest"].as_array().unwrap().len(), 2);
        assert_eq!(
            v["objects_of_interest_types"],
            serde_json::json!(["vehicle", "vehicle"])
        );
        assert_eq!(v["num_steps"], 91);
        assert_eq!(v["tracks_to_predict"].as_array().unwrap().len(), 2);
    }
    let truth = std::fs::read_to_string(out.join("ground_truth.jsonl")).unwrap();
    let lines: Vec<serde_json::Value> = truth
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 60);
    for key in [
        "scenario_id",
        "family",
        "a_id",
        "b_id",
        "courtesy",
        "a_avg_speed_mps",
        "a_avg_speed_alone_mps",
    ] {
        assert!(lines[0].get(key).is_some(), "missing {key}");
    }
    // Deterministic for a seed.
    let again = dir.path().join("again");
    scbg_ok(&[
        "synth",
        "--scenarios",
        "60",
        "--seed",
        "3",
        "--out",
        again.to_str().unwrap(),
        "--scenarios-per-file",
        "25",
    ]);
    for i in 0..3 {
        let name = format!("synth-{i:05}.tfrecord");
        assert_eq!(
            std::fs::read(out.join(&name)).unwrap(),
            std::fs::read(again.join(&name)).unwrap()
        );
    }
}

/// `scbg data prepare` of `inputs` into `out` (4 files per shard); returns the manifest.
fn prepare(inputs: &[String], out: &std::path::Path) -> serde_json::Value {
    let mut args = vec![
        "data",
        "prepare",
        "--out",
        out.to_str().unwrap(),
        "--files-per-shard",
        "4",
        "--input",
    ];
    args.extend(inputs.iter().map(String::as_str));
    scbg_ok(&args);
    serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap()
}

/// A second run into `a` resumes (same manifest, shard files untouched), and a fresh run into
/// `b` writes identical shards.
fn assert_resumes_and_is_deterministic(
    inputs: &[String],
    a: &std::path::Path,
    b: &std::path::Path,
) {
    let m1: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(a.join("manifest.json")).unwrap()).unwrap();
    let shard = a.join("shard-00000.bin");
    let mtime = std::fs::metadata(&shard).unwrap().modified().unwrap();
    assert_eq!(prepare(inputs, a), m1);
    assert_eq!(
        std::fs::metadata(&shard).unwrap().modified().unwrap(),
        mtime
    );
    prepare(inputs, b);
    let mut shards = 0;
    for entry in std::fs::read_dir(a).unwrap() {
        let name = entry.unwrap().file_name();
        if name.to_string_lossy().ends_with(".bin") {
            shards += 1;
            assert_eq!(
                std::fs::read(a.join(&name)).unwrap(),
                std::fs::read(b.join(&name)).unwrap(),
                "{name:?}"
            );
        }
    }
    assert!(shards > 0);
}

/// Every scene of the cache at `dir` decodes, and samples are built for its targets and pairs;
/// returns how many marginal samples were built.
fn decode_every_scene(dir: &std::path::Path, scenes: usize) -> usize {
    let ds = scbg_features::cache::PreparedDataset::open(dir).unwrap();
    assert_eq!(ds.len(), scenes);
    let mut samples = 0;
    for i in 0..ds.len() {
        let scene = ds.scene(i).unwrap();
        for (w, pairs) in scene.windows.iter().zip(&scene.pairs) {
            for t in scbg_features::marginal_targets(&scene, w, 80, 1)
                .into_iter()
                .take(2)
            {
                scbg_features::extract_sample(
                    &scene,
                    w,
                    t,
                    None,
                    &scbg_features::FeatureConfig::default(),
                )
                .unwrap();
                samples += 1;
            }
            for p in pairs {
                let s = scbg_features::extract_sample(
                    &scene,
                    w,
                    p.first,
                    Some(p.second),
                    &scbg_features::FeatureConfig::default(),
                )
                .unwrap();
                assert!(s.condition_future_valid.iter().any(|&v| v));
            }
        }
    }
    samples
}

#[test]
fn prepare_of_synthetic_data_is_deterministic_and_resumable() {
    let dir = tempfile::tempdir().unwrap();
    let synth = dir.path().join("synth");
    scbg_ok(&[
        "synth",
        "--scenarios",
        "40",
        "--seed",
        "1",
        "--out",
        synth.to_str().unwrap(),
        "--scenarios-per-file",
        "5",
    ]);
    let inputs = [synth.display().to_string()];
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let m = prepare(&inputs, &a);
    assert_eq!(m["total"]["scenarios"], 40);
    // One labelled pair per synthetic scene (its ground truth's), in its current window.
    assert!(m["total"]["pairs"].as_u64().unwrap() >= 40, "{m}");
    assert_resumes_and_is_deterministic(&inputs, &a, &b);
    assert!(decode_every_scene(&a, 40) >= 40);
}

#[test]
fn prepare_of_real_data_mines_pairs() {
    let Some(real) = real_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    let synth = dir.path().join("synth");
    scbg_ok(&[
        "synth",
        "--scenarios",
        "40",
        "--seed",
        "1",
        "--out",
        synth.to_str().unwrap(),
    ]);
    let inputs = [
        synth.display().to_string(),
        real.join("womd-reencoded").display().to_string(),
        real.join("nuscenes-reencoded").display().to_string(),
    ];
    let a = dir.path().join("a");
    let m1 = prepare(&inputs, &a);
    assert_eq!(m1["total"]["scenarios"], 40 + 12 + 10);
    // 20 s WOMD scenarios and nuScenes scenes yield several windows each, and mined pairs.
    assert!(m1["total"]["windows"].as_u64().unwrap() > 62 + 50);
    assert!(m1["total"]["pairs"].as_u64().unwrap() >= 40 + 2 + 10);
    let ratio = m1["total"]["bytes"].as_f64().unwrap() / m1["total"]["raw_bytes"].as_f64().unwrap();
    assert!(ratio < 0.3, "cache is {ratio:.3} of raw bytes");
    assert_resumes_and_is_deterministic(&inputs, &a, &dir.path().join("b"));
    assert!(decode_every_scene(&a, 62) > 100);
}

#[test]
fn render_writes_a_png() {
    let dir = tempfile::tempdir().unwrap();
    let synth = dir.path().join("synth");
    scbg_ok(&[
        "synth",
        "--scenarios",
        "3",
        "--seed",
        "2",
        "--out",
        synth.to_str().unwrap(),
    ]);
    let png = dir.path().join("scene.png");
    scbg_ok(&[
        "data",
        "render",
        synth.join("synth-00000.tfrecord").to_str().unwrap(),
        "--out",
        png.to_str().unwrap(),
        "--size-px",
        "400",
    ]);
    crate::assert_drawn_png(&png, (400, 400));
}
