//! Format-level tests: round trips, corrupt inputs, and the genuine Waymo files' facts that
//! only this crate can see (tf.Example keys and slots). Scene-level facts are asserted in the
//! integration tests of the `scbg` binary.

use prost::Message;
use scbg_scene::{
    AgentState, Lane, LaneNeighbor, LaneType, Map, MapPoint, ObjectType, PredictionDifficulty,
    PredictionTarget, RoadLine, RoadLineType, Scene, SignalLaneState, SignalState, StopSign, Track,
};

use super::*;

pub(crate) fn sample_scene() -> Scene {
    let state = |t: f64| AgentState {
        x_m: 1.0 + t,
        y_m: -2.0,
        z_m: 0.5,
        length_m: 4.5,
        width_m: 2.0,
        height_m: 1.6,
        heading_rad: 0.1,
        velocity_x_mps: 10.0,
        velocity_y_mps: 0.5,
        valid: true,
    };
    let p = |x: f64, y: f64| MapPoint {
        x_m: x,
        y_m: y,
        z_m: 0.0,
    };
    Scene {
        scenario_id: "roundtrip".into(),
        timestamps_secs: (0..5).map(|i| f64::from(i) * 0.1).collect(),
        current_step: 2,
        sdc_track_index: Some(1),
        tracks: vec![
            Track {
                id: 3,
                object_type: ObjectType::Vehicle,
                states: (0..5).map(|i| state(f64::from(i))).collect(),
            },
            Track {
                id: 9,
                object_type: ObjectType::Pedestrian,
                states: vec![
                    AgentState::default(),
                    state(0.0),
                    state(1.0),
                    AgentState::default(),
                    state(2.0),
                ],
            },
        ],
        objects_of_interest: vec![3, 9],
        tracks_to_predict: vec![PredictionTarget {
            track_index: 0,
            difficulty: PredictionDifficulty::Level2,
        }],
        map: Map {
            lanes: vec![Lane {
                id: 100,
                lane_type: LaneType::SurfaceStreet,
                speed_limit_mph: Some(25.0),
                polyline: vec![p(0.0, 0.0), p(10.0, 0.0)],
                entry_lanes: vec![101],
                exit_lanes: vec![102, 103],
                left_neighbors: vec![LaneNeighbor {
                    feature_id: 104,
                    self_end_index: 1,
                    ..Default::default()
                }],
                ..Default::default()
            }],
            road_lines: vec![RoadLine {
                id: 200,
                line_type: RoadLineType::SolidDoubleYellow,
                polyline: vec![p(0.0, 2.0), p(10.0, 2.0)],
            }],
            stop_signs: vec![StopSign {
                id: 300,
                lanes: vec![100],
                position: p(10.0, -1.0),
            }],
            ..Default::default()
        },
        signals_per_step: (0..5)
            .map(|_| {
                vec![SignalLaneState {
                    lane_id: 100,
                    state: SignalState::Go,
                    stop_point: Some(p(10.0, 0.0)),
                }]
            })
            .collect(),
    }
}

#[test]
fn scenario_round_trip_is_lossless() {
    let scene = sample_scene();
    let bytes = encode_scene(&scene).unwrap();
    assert_eq!(detect_record_format(&bytes).unwrap(), Format::Scenario);
    assert_eq!(decode_record(&bytes, Format::Scenario).unwrap(), scene);
}

#[test]
fn packed_and_unpacked_timestamps_both_decode() {
    let scene = sample_scene();
    let unpacked = encode_scene(&scene).unwrap();
    // Re-encode field 1 packed by hand: tag (1 << 3 | 2), length, raw doubles.
    let mut packed = Vec::new();
    prost::encoding::encode_key(1, prost::encoding::WireType::LengthDelimited, &mut packed);
    prost::encoding::encode_varint((scene.timestamps_secs.len() * 8) as u64, &mut packed);
    for t in &scene.timestamps_secs {
        packed.extend_from_slice(&t.to_le_bytes());
    }
    let mut without_ts = proto::Scenario::decode(&unpacked[..]).unwrap();
    without_ts.timestamps_seconds.clear();
    packed.extend(without_ts.encode_to_vec());
    assert_eq!(decode_record(&packed, Format::Scenario).unwrap(), scene);
}

#[test]
fn unknown_fields_are_skipped() {
    let mut bytes = encode_scene(&sample_scene()).unwrap();
    prost::encoding::encode_key(3, prost::encoding::WireType::LengthDelimited, &mut bytes);
    prost::encoding::encode_varint(3, &mut bytes);
    bytes.extend_from_slice(b"abc");
    prost::encoding::encode_key(99, prost::encoding::WireType::Varint, &mut bytes);
    prost::encoding::encode_varint(7, &mut bytes);
    assert_eq!(
        decode_record(&bytes, Format::Scenario).unwrap(),
        sample_scene()
    );
}

#[test]
fn write_and_read_file_atomically() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.tfrecord");
    let scenes = vec![
        sample_scene(),
        Scene {
            scenario_id: "second".into(),
            ..sample_scene()
        },
    ];
    assert_eq!(write_scenes(&path, &scenes).unwrap(), 2);
    let file = WomdFile::open(&path).unwrap();
    assert_eq!(file.detect_format().unwrap(), Format::Scenario);
    let back: Vec<Scene> = file.scenes().collect::<Result<_, _>>().unwrap();
    assert_eq!(back, scenes);
    // Only the final file remains in the folder: no temp files left behind.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

fn first_error(bytes: Vec<u8>) -> WomdError {
    match WomdFile::from_bytes("mem.tfrecord", bytes) {
        Err(e) => e,
        Ok(f) => f.scenes().find_map(Result::err).expect("an error"),
    }
}

#[test]
fn corrupt_inputs_give_located_errors() {
    let good = scenes_to_tfrecord_bytes([&sample_scene()]).unwrap();

    let mut bad_len_crc = good.clone();
    bad_len_crc[9] ^= 0x10;
    let e = first_error(bad_len_crc);
    assert_eq!(e.reason(), "bad_length_crc");
    assert!(
        e.to_string().contains("record 0 at byte 0") && e.to_string().ends_with("mem.tfrecord"),
        "{e}"
    );

    let mut bad_data_crc = good.clone();
    bad_data_crc[20] ^= 0x10;
    assert_eq!(first_error(bad_data_crc).reason(), "bad_data_crc");

    assert_eq!(
        first_error(good[..good.len() - 3].to_vec()).reason(),
        "truncated_record"
    );
    assert_eq!(first_error(Vec::new()).reason(), "empty_file");

    let mut not_scenario = RecordWriter::new(Vec::new());
    not_scenario
        .write_record(
            &proto::RoadLine {
                line_type: Some(1),
                polyline: vec![],
            }
            .encode_to_vec(),
        )
        .unwrap();
    let e = first_error(not_scenario.into_inner());
    assert_eq!(e.reason(), "not_womd", "{e}");

    let mut nan = sample_scene();
    nan.tracks[0].states[1].y_m = f64::NAN;
    let e = first_error(scenes_to_tfrecord_bytes([&nan]).unwrap());
    assert_eq!(e.reason(), "invalid_scene");
    assert!(
        e.to_string().contains("track 3 step 1: field `center_y`"),
        "{e}"
    );

    let mut no_map = sample_scene();
    no_map.map = Map::default();
    no_map.signals_per_step.clear();
    let file = WomdFile::from_bytes("nomap", scenes_to_tfrecord_bytes([&no_map]).unwrap()).unwrap();
    assert!(file.scenes().next().unwrap().unwrap().map.is_empty());
}

#[test]
fn random_bytes_never_panic() {
    let mut state = 0x1234_5678_9abc_def0u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let good = scenes_to_tfrecord_bytes([&sample_scene()]).unwrap();
    for round in 0..2000 {
        let mut bytes = if round % 2 == 0 {
            good.clone()
        } else {
            (0..(next() % 256)).map(|_| next() as u8).collect()
        };
        for _ in 0..(next() % 8) {
            if bytes.is_empty() {
                break;
            }
            let i = (next() as usize) % bytes.len();
            bytes[i] = next() as u8;
        }
        // Records whose CRCs we recompute, so the corruption reaches the protobuf decoder.
        let mut w = RecordWriter::new(Vec::new());
        w.write_record(&bytes).unwrap();
        for input in [bytes, w.into_inner()] {
            if let Ok(f) = WomdFile::from_bytes("fuzz", input) {
                for _ in f.scenes() {}
            }
        }
    }
}

#[test]
fn real_tf_example_facts() {
    let Some(dir) = fixtures::real_data_dir() else {
        return;
    };
    let file = WomdFile::open(dir.join("womd/motion_data_one_example.tfrecord")).unwrap();
    assert_eq!(file.detect_format().unwrap(), Format::TfExample);
    let record = file.records().next().unwrap().unwrap();
    let ex = proto::Example::decode(record.data).unwrap();
    let features = ex.features.unwrap().feature;
    assert_eq!(features.len(), 72);
    let len = |k: &str| match &features[k].kind {
        Some(proto::FeatureKind::FloatList(l)) => l.value.len(),
        Some(proto::FeatureKind::Int64List(l)) => l.value.len(),
        _ => 0,
    };
    assert_eq!(len("state/id"), 128);
    assert_eq!(len("state/past/x"), 128 * 10);
    assert_eq!(len("state/current/x"), 128);
    assert_eq!(len("state/future/x"), 128 * 80);
    assert_eq!(len("roadgraph_samples/id"), 20000);
    assert_eq!(len("roadgraph_samples/xyz"), 60000);
}
