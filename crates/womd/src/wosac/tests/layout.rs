//! The submission's bytes: hand-checked layouts, and an independent wire reader that walks
//! whole submissions (the genuine scenario's too).

use super::*;

// ---- (1) hand-checked byte layout ----

/// A tiny submission built from the message structs (so the 80-step rule does not apply),
/// compared with bytes derived by hand from the spec's tag bytes.
#[test]
fn byte_layout_matches_hand_derived_bytes() {
    let msg = SimAgentsChallengeSubmission {
        scenario_rollouts: vec![ScenarioRollouts {
            scenario_id: Some("ab".into()),
            joint_scenes: vec![JointScene {
                simulated_trajectories: vec![SimulatedTrajectory {
                    center_x: vec![1.0, 2.0],
                    center_y: vec![-1.0, 0.5],
                    center_z: vec![0.0, 0.25],
                    heading: vec![1.5, -0.5],
                    object_id: Some(7),
                    ..Default::default()
                }],
            }],
        }],
        submission_type: Some(1),
        account_name: Some("a@b".into()),
        unique_method_name: Some("m".into()),
        authors: vec!["A".into(), "B".into()],
        affiliation: Some("X".into()),
        description: Some("d".into()),
        method_link: Some("l".into()),
        uses_lidar_data: Some(false),
        uses_camera_data: Some(false),
        uses_public_model_pretraining: Some(true),
        num_model_parameters: Some("1K".into()),
        public_model_names: vec!["p".into()],
        acknowledge_complies_with_closed_loop_requirement: Some(true),
    };
    #[rustfmt::skip]
    let trajectory: &[u8] = &[
        0x12, 0x08, 0x00, 0x00, 0x80, 0x3F, 0x00, 0x00, 0x00, 0x40, // center_x: 1.0, 2.0
        0x1A, 0x08, 0x00, 0x00, 0x80, 0xBF, 0x00, 0x00, 0x00, 0x3F, // center_y: -1.0, 0.5
        0x22, 0x08, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3E, // center_z: 0.0, 0.25
        0x2A, 0x08, 0x00, 0x00, 0xC0, 0x3F, 0x00, 0x00, 0x00, 0xBF, // heading: 1.5, -0.5
        0x30, 0x07,                                                 // object_id: 7
    ]; // 42 = 0x2A bytes; width/length/height/object_type/valid absent
    #[rustfmt::skip]
    let header: &[u8] = &[
        0x10, 0x01,                   // submission_type: SIM_AGENTS_SUBMISSION
        0x1A, 0x03, b'a', b'@', b'b', // account_name
        0x22, 0x01, b'm',             // unique_method_name
        0x2A, 0x01, b'A',             // authors[0]
        0x2A, 0x01, b'B',             // authors[1]
        0x32, 0x01, b'X',             // affiliation
        0x3A, 0x01, b'd',             // description
        0x42, 0x01, b'l',             // method_link
        0x48, 0x00,                   // uses_lidar_data: false
        0x50, 0x00,                   // uses_camera_data: false
        0x58, 0x01,                   // uses_public_model_pretraining: true
        0x62, 0x02, b'1', b'K',       // num_model_parameters
        0x6A, 0x01, b'p',             // public_model_names[0]
        0x70, 0x01,                   // acknowledge_complies_with_closed_loop_requirement
    ];
    let mut expected: Vec<u8> = vec![
        0x0A, 0x32, // scenario_rollouts[0], 50 bytes
        0x0A, 0x02, b'a', b'b', // scenario_id "ab"
        0x12, 0x2C, // joint_scenes[0], 44 bytes
        0x0A, 0x2A, // simulated_trajectories[0], 42 bytes
    ];
    expected.extend_from_slice(trajectory);
    expected.extend_from_slice(header);
    assert_eq!(msg.encode_to_vec(), expected);
    assert_eq!(
        SimAgentsChallengeSubmission::decode(&expected[..]).unwrap(),
        msg
    );

    // The same header through the input type (no scenarios: field 1 absent).
    let input_header = SubmissionHeader {
        account_name: "a@b".into(),
        unique_method_name: "m".into(),
        authors: vec!["A".into(), "B".into()],
        affiliation: "X".into(),
        description: "d".into(),
        method_link: "l".into(),
        uses_lidar_data: false,
        uses_camera_data: false,
        uses_public_model_pretraining: true,
        num_model_parameters: "1K".into(),
        public_model_names: vec!["p".into()],
        acknowledge_closed_loop: true,
    };
    assert_eq!(encode_submission(&input_header, &[]).unwrap(), header);
}

/// int32 object ids are varints; negative ones take 10 bytes (two's complement), and the
/// ignored fields 7..11 use the spec's tag bytes, packed.
#[test]
fn negative_object_id_and_ignored_fields_layout() {
    let t = SimulatedTrajectory {
        object_id: Some(-1),
        width: vec![2.0],
        length: vec![4.0],
        height: vec![1.5],
        object_type: Some(1),
        valid: vec![true, false],
        ..Default::default()
    };
    #[rustfmt::skip]
    let expected: &[u8] = &[
        0x30, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x01, // object_id: -1
        0x3A, 0x04, 0x00, 0x00, 0x00, 0x40, // width: 2.0
        0x42, 0x04, 0x00, 0x00, 0x80, 0x40, // length: 4.0
        0x4A, 0x04, 0x00, 0x00, 0xC0, 0x3F, // height: 1.5
        0x50, 0x01,                         // object_type: VEHICLE
        0x5A, 0x02, 0x01, 0x00,             // valid: true, false (packed)
    ];
    assert_eq!(t.encode_to_vec(), expected);
}

/// Unpacked repeated floats (tag 0x15 = field 2, fixed32) decode too.
#[test]
fn decode_accepts_unpacked_floats() {
    #[rustfmt::skip]
    let bytes: &[u8] = &[
        0x0A, 0x13,             // scenario_rollouts[0], 19 bytes
        0x0A, 0x01, b's',       //   scenario_id "s"
        0x12, 0x0E,             //   joint_scenes[0], 14 bytes
        0x0A, 0x0C,             //     simulated_trajectories[0], 12 bytes
        0x15, 0x00, 0x00, 0x80, 0x3F, // center_x 1.0 (unpacked)
        0x15, 0x00, 0x00, 0x00, 0x40, // center_x 2.0 (unpacked)
        0x30, 0x07,             //       object_id 7
        0x10, 0x01,             // submission_type
    ];
    let (h, r) = decode_submission(bytes).unwrap();
    assert_eq!(h, SubmissionHeader::default());
    assert_eq!(
        r,
        [ScenarioRolloutsInput {
            scenario_id: "s".into(),
            joint_scenes: vec![vec![ObjectTrajectory {
                object_id: 7,
                x_m: vec![1.0, 2.0],
                ..Default::default()
            }]],
        }]
    );
}

// ---- (2) independent wire reader ----

#[derive(Debug, Clone, Copy, PartialEq)]
enum Value<'a> {
    Varint(u64),
    Fixed64([u8; 8]),
    Bytes(&'a [u8]),
    Fixed32([u8; 4]),
}

impl Value<'_> {
    fn wire_type(&self) -> u8 {
        match self {
            Value::Varint(_) => 0,
            Value::Fixed64(_) => 1,
            Value::Bytes(_) => 2,
            Value::Fixed32(_) => 5,
        }
    }
    fn bytes(&self) -> &[u8] {
        match self {
            Value::Bytes(b) => b,
            other => panic!("expected length-delimited, got {other:?}"),
        }
    }
}

fn read_varint(buf: &[u8], pos: &mut usize) -> u64 {
    let mut value = 0u64;
    for shift in (0..64).step_by(7) {
        let byte = buf[*pos];
        *pos += 1;
        value |= u64::from(byte & 0x7F) << shift;
        if byte & 0x80 == 0 {
            return value;
        }
    }
    panic!("varint longer than 10 bytes");
}

/// Splits one message into (field number, value), in wire order.
fn fields(buf: &[u8]) -> Vec<(u64, Value<'_>)> {
    let mut pos = 0;
    let mut out = Vec::new();
    while pos < buf.len() {
        let key = read_varint(buf, &mut pos);
        let value = match key & 7 {
            0 => Value::Varint(read_varint(buf, &mut pos)),
            1 => {
                pos += 8;
                Value::Fixed64(buf[pos - 8..pos].try_into().unwrap())
            }
            2 => {
                let len = usize::try_from(read_varint(buf, &mut pos)).unwrap();
                pos += len;
                Value::Bytes(&buf[pos - len..pos])
            }
            5 => {
                pos += 4;
                Value::Fixed32(buf[pos - 4..pos].try_into().unwrap())
            }
            w => panic!("wire type {w}"),
        };
        out.push((key >> 3, value));
    }
    assert_eq!(pos, buf.len(), "message overruns its buffer");
    out
}

/// (field number, wire type) sequence of a message.
fn layout(fields: &[(u64, Value<'_>)]) -> Vec<(u64, u8)> {
    fields.iter().map(|(n, v)| (*n, v.wire_type())).collect()
}

fn packed_floats(bytes: &[u8]) -> Vec<f32> {
    assert_eq!(bytes.len() % 4, 0);
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

/// Walks an encoded submission with the hand-written reader and checks every field number,
/// wire type and count against the header and rollouts it was made from.
fn check_wire_layout(bytes: &[u8], h: &SubmissionHeader, rollouts: &[ScenarioRolloutsInput]) {
    let top = fields(bytes);
    let mut expected_layout = vec![(1, 2); rollouts.len()];
    expected_layout.extend([(2, 0), (3, 2), (4, 2)]);
    expected_layout.extend(vec![(5, 2); h.authors.len()]);
    expected_layout.extend([(6, 2), (7, 2), (8, 2), (9, 0), (10, 0), (11, 0), (12, 2)]);
    expected_layout.extend(vec![(13, 2); h.public_model_names.len()]);
    expected_layout.push((14, 0));
    assert_eq!(layout(&top), expected_layout);
    assert_eq!(top[rollouts.len()].1, Value::Varint(1), "submission_type");
    assert_eq!(
        top.last().unwrap().1,
        Value::Varint(u64::from(h.acknowledge_closed_loop))
    );

    for (sr_bytes, r) in top.iter().map(|(_, v)| v.bytes()).zip(rollouts) {
        let sr = fields(sr_bytes);
        let mut expected = vec![(1, 2)];
        expected.extend(vec![(2, 2); ROLLOUTS_PER_SCENARIO]);
        assert_eq!(layout(&sr), expected);
        assert_eq!(sr[0].1.bytes(), r.scenario_id.as_bytes());
        for ((_, js_value), trajectories) in sr[1..].iter().zip(&r.joint_scenes) {
            let js = fields(js_value.bytes());
            assert_eq!(layout(&js), vec![(1, 2); trajectories.len()]);
            let mut ids = BTreeSet::new();
            for ((_, t_value), t) in js.iter().zip(trajectories) {
                let tf = fields(t_value.bytes());
                assert_eq!(layout(&tf), [(2, 2), (3, 2), (4, 2), (5, 2), (6, 0)]);
                for (k, want) in [&t.x_m, &t.y_m, &t.z_m, &t.heading_rad].iter().enumerate() {
                    let b = tf[k].1.bytes();
                    assert_eq!(b.len(), 4 * SIMULATED_STEPS);
                    assert_eq!(&packed_floats(b), *want);
                }
                let Value::Varint(id) = tf[4].1 else {
                    unreachable!()
                };
                assert_eq!(id, t.object_id as u64);
                ids.insert(id as i64);
            }
            assert_eq!(ids.len(), trajectories.len());
        }
    }
}

#[test]
fn full_size_submission_walks_with_independent_reader() {
    let scene = scene();
    let r = rollouts_for(&scene);
    validate_rollouts(&scene, &r).unwrap();
    let mut h = header();
    h.public_model_names = vec!["none-really".into()];
    let bytes = encode_submission(&h, std::slice::from_ref(&r)).unwrap();
    check_wire_layout(&bytes, &h, std::slice::from_ref(&r));
    // Every joint scene holds exactly the sim agents.
    let sim: BTreeSet<i64> = [1, 2, 13].into();
    for js in &r.joint_scenes {
        assert_eq!(js.iter().map(|t| t.object_id).collect::<BTreeSet<_>>(), sim);
    }
}

// ---- genuine scenario ----

/// Constant-velocity rollouts for every sim agent of the genuine WOMD scenario validate,
/// encode, walk and round-trip (spec §11: 50 sim agents).
#[test]
fn real_scenario_constant_velocity_submission() {
    let Some(dir) = crate::fixtures::real_data_dir() else {
        return;
    };
    let file = crate::WomdFile::open(dir.join("womd/motion_data_one_scenario.tfrecord")).unwrap();
    let scene = file.scenes().next().unwrap().unwrap();
    let ids = sim_agent_ids(&scene);
    assert_eq!(ids.len(), 50);
    let trajectories: Vec<ObjectTrajectory> = ids
        .iter()
        .map(|&id| {
            let s = scene.tracks[scene.track_index(id).unwrap()].states[CURRENT_STEP];
            let steps = 1..=SIMULATED_STEPS;
            ObjectTrajectory {
                object_id: id,
                x_m: steps
                    .clone()
                    .map(|k| (s.x_m + f64::from(s.velocity_x_mps) * 0.1 * k as f64) as f32)
                    .collect(),
                y_m: steps
                    .clone()
                    .map(|k| (s.y_m + f64::from(s.velocity_y_mps) * 0.1 * k as f64) as f32)
                    .collect(),
                z_m: vec![s.z_m as f32; SIMULATED_STEPS],
                heading_rad: vec![s.heading_rad; SIMULATED_STEPS],
            }
        })
        .collect();
    let r = ScenarioRolloutsInput {
        scenario_id: scene.scenario_id.clone(),
        joint_scenes: vec![trajectories; ROLLOUTS_PER_SCENARIO],
    };
    validate_rollouts(&scene, &r).unwrap();
    let h = header();
    let bytes = encode_submission(&h, std::slice::from_ref(&r)).unwrap();
    check_wire_layout(&bytes, &h, std::slice::from_ref(&r));
    let (h2, r2) = decode_submission(&bytes).unwrap();
    assert_eq!((h2, r2), (h, vec![r]));
}
