//! WOSAC submission export: hand-checked bytes, an independent wire reader, round trips,
//! validation errors and shard files.

use std::collections::BTreeSet;

use scbg_scene::{AgentState, ObjectType, Track};

use super::*;

mod layout;
mod shards;
mod validation;

// ---- fixtures ----

/// A 91-step scene (current step 10) whose sim agents are tracks 1, 2 and 13.
fn scene() -> Scene {
    let state = |valid: bool| AgentState {
        x_m: 3.0,
        y_m: -4.0,
        z_m: 0.5,
        length_m: 4.5,
        width_m: 2.0,
        height_m: 1.6,
        heading_rad: 0.2,
        velocity_x_mps: 5.0,
        velocity_y_mps: 0.0,
        valid,
    };
    let track = |id: i64, valid: &dyn Fn(usize) -> bool| Track {
        id,
        object_type: ObjectType::Vehicle,
        states: (0..91).map(|t| state(valid(t))).collect(),
    };
    let scene = Scene {
        scenario_id: "abc123".into(),
        timestamps_secs: (0..91).map(|i| f64::from(i) * 0.1).collect(),
        current_step: 10,
        sdc_track_index: Some(0),
        tracks: vec![
            track(1, &|_| true),
            track(2, &|t| t == 10),
            track(5, &|t| t < 10),
            track(8, &|t| t > 10),
            track(13, &|_| true),
            track(21, &|_| false),
        ],
        ..Default::default()
    };
    scene.validate().unwrap();
    scene
}

/// Valid rollouts for `scene`: 32 joint scenes of every sim agent, 80 distinct values each.
fn rollouts_for(scene: &Scene) -> ScenarioRolloutsInput {
    let ids = sim_agent_ids(scene);
    ScenarioRolloutsInput {
        scenario_id: scene.scenario_id.clone(),
        joint_scenes: (0..ROLLOUTS_PER_SCENARIO)
            .map(|j| {
                ids.iter()
                    .map(|&id| {
                        let v = |k: f32| -> Vec<f32> {
                            (0..SIMULATED_STEPS)
                                .map(|f| k + id as f32 + j as f32 * 0.01 + f as f32 * 0.1)
                                .collect()
                        };
                        ObjectTrajectory {
                            object_id: id,
                            x_m: v(100.0),
                            y_m: v(-50.0),
                            z_m: v(1.0),
                            heading_rad: v(-3.0),
                        }
                    })
                    .collect()
            })
            .collect(),
    }
}

fn header() -> SubmissionHeader {
    SubmissionHeader {
        account_name: "someone@example.com".into(),
        unique_method_name: "scbg".into(),
        authors: vec!["A. Author".into(), "B. Author".into()],
        affiliation: "Somewhere".into(),
        description: "closed-loop test".into(),
        method_link: "https://example.com".into(),
        uses_lidar_data: false,
        uses_camera_data: false,
        uses_public_model_pretraining: false,
        num_model_parameters: "645K".into(),
        public_model_names: vec![],
        acknowledge_closed_loop: true,
    }
}

// ---- (3) round trip ----

#[test]
fn encode_decode_round_trip() {
    let scene = scene();
    let mut second = rollouts_for(&scene);
    second.scenario_id = "other".into();
    second.joint_scenes.truncate(2); // the encoder does not validate
    let rollouts = vec![rollouts_for(&scene), second];
    let h = header();
    let bytes = encode_submission(&h, &rollouts).unwrap();
    let (h2, r2) = decode_submission(&bytes).unwrap();
    assert_eq!(h2, h);
    assert_eq!(r2, rollouts);
}

#[test]
fn encode_and_decode_errors() {
    let scene = scene();
    let r = rollouts_for(&scene);
    let e = encode_submission(&header(), &[r.clone(), r.clone()]).unwrap_err();
    assert!(
        matches!(&e, WosacExportError::DuplicateScenario { scenario_id } if scenario_id == "abc123"),
        "{e}"
    );

    let mut big = r.clone();
    big.joint_scenes[3][1].object_id = i64::from(i32::MAX) + 1;
    let e = encode_submission(&header(), &[big]).unwrap_err();
    assert!(
        matches!(
            e,
            WosacExportError::ObjectIdOverflow {
                joint_scene: 3,
                object_id: 2_147_483_648,
                ..
            }
        ),
        "{e}"
    );

    let e = decode_submission(&[0x10, 0x00]).unwrap_err();
    assert!(
        matches!(e, WosacExportError::SubmissionType { got: Some(0) }),
        "{e}"
    );
    let e = decode_submission(&[]).unwrap_err();
    assert!(
        matches!(e, WosacExportError::SubmissionType { got: None }),
        "{e}"
    );
    let e = decode_submission(&[0x0A, 0x05]).unwrap_err();
    assert!(matches!(e, WosacExportError::Proto(_)), "{e}");
    // A trajectory without object_id: scenario "s", joint scene 0, trajectory 0 empty.
    let bytes = [
        0x0A, 0x07, 0x0A, 0x01, b's', 0x12, 0x02, 0x0A, 0x00, 0x10, 0x01,
    ];
    let e = decode_submission(&bytes).unwrap_err();
    assert!(
        matches!(
            e,
            WosacExportError::MissingObjectId {
                joint_scene: 0,
                trajectory: 0,
                ..
            }
        ),
        "{e}"
    );
}
