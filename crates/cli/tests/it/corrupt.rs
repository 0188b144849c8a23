//! Corrupt inputs: a clear error naming the file (exit 2) or a counted skip, never a panic.

use std::path::Path;

use crate::scbg;

fn record(data: &[u8]) -> Vec<u8> {
    let mut w = scbg_womd::RecordWriter::new(Vec::new());
    w.write_record(data).unwrap();
    w.into_inner()
}

fn valid_scene_record() -> Vec<u8> {
    // A tiny valid scenario, written through the project's own encoder.
    let state = scbg_scene::AgentState {
        valid: true,
        length_m: 4.0,
        width_m: 2.0,
        ..Default::default()
    };
    let scene = scbg_scene::Scene {
        scenario_id: "tiny".into(),
        timestamps_secs: vec![0.0, 0.1],
        current_step: 0,
        tracks: vec![scbg_scene::Track {
            id: 1,
            object_type: scbg_scene::ObjectType::Vehicle,
            states: vec![state; 2],
        }],
        ..Default::default()
    };
    record(&scbg_womd::encode_scene(&scene).unwrap())
}

fn assert_clean_failure(dir: &Path, name: &str, bytes: &[u8]) {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    let out = scbg(&["data", "inspect", path.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{name}: {stderr}");
    assert!(
        stderr.contains(name),
        "{name}: error must name the file: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "{name}: {stderr}");
}

#[test]
fn corrupt_files_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let good = valid_scene_record();
    let mut bad_len_crc = good.clone();
    bad_len_crc[8] ^= 1;
    assert_clean_failure(dir.path(), "bad_length_crc.tfrecord", &bad_len_crc);
    let mut bad_data_crc = good.clone();
    bad_data_crc[14] ^= 1;
    assert_clean_failure(dir.path(), "bad_data_crc.tfrecord", &bad_data_crc);
    assert_clean_failure(dir.path(), "truncated.tfrecord", &good[..good.len() - 5]);
    assert_clean_failure(dir.path(), "empty.tfrecord", &[]);
    assert_clean_failure(
        dir.path(),
        "random.tfrecord",
        &(0..4096u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
            .collect::<Vec<_>>(),
    );
    let huge = (1u64 << 60).to_le_bytes();
    let mut huge_len = huge.to_vec();
    huge_len.extend_from_slice(&scbg_womd::tfrecord::masked_crc32c(&huge).to_le_bytes());
    huge_len.extend_from_slice(&[0; 32]);
    assert_clean_failure(dir.path(), "huge_length.tfrecord", &huge_len);
    assert_clean_failure(
        dir.path(),
        "not_a_scenario.tfrecord",
        &record(b"\x08\x96\x01 just some protobuf-ish bytes"),
    );

    // NaN coordinates in a valid state: decoded, then rejected with track, step and field.
    let state = scbg_scene::AgentState {
        valid: true,
        x_m: f64::NAN,
        ..Default::default()
    };
    let scene = scbg_scene::Scene {
        scenario_id: "nan".into(),
        timestamps_secs: vec![0.0],
        tracks: vec![scbg_scene::Track {
            id: 9,
            object_type: scbg_scene::ObjectType::Vehicle,
            states: vec![state],
        }],
        ..Default::default()
    };
    let path = dir.path().join("nan.tfrecord");
    std::fs::write(&path, record(&scbg_womd::encode_scene(&scene).unwrap())).unwrap();
    let out = scbg(&["data", "inspect", path.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr.contains("track 9 step 0: field `center_x` is not finite or beyond ±1e7")
            && stderr.contains("nan.tfrecord"),
        "{stderr}"
    );

    // A scenario without map is valid.
    let path = dir.path().join("no_map.tfrecord");
    std::fs::write(&path, &good).unwrap();
    assert!(
        scbg(&["data", "inspect", path.to_str().unwrap()])
            .status
            .success()
    );
}

#[test]
fn prepare_counts_bad_inputs_and_keeps_going() {
    let dir = tempfile::tempdir().unwrap();
    let inputs = dir.path().join("in");
    std::fs::create_dir(&inputs).unwrap();
    let mut bad = valid_scene_record();
    bad[14] ^= 1;
    std::fs::write(inputs.join("a_bad.tfrecord"), &bad).unwrap();
    std::fs::write(inputs.join("b_empty.tfrecord"), b"").unwrap();
    let out_dir = dir.path().join("cache");
    let out = scbg(&[
        "data",
        "prepare",
        "--input",
        inputs.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("manifest.json")).unwrap())
            .unwrap();
    assert_eq!(manifest["total"]["skipped"]["bad_data_crc"], 1);
    assert_eq!(manifest["total"]["skipped"]["empty_file"], 1);
    assert_eq!(manifest["total"]["scenarios"], 0);
}
