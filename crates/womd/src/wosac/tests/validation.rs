//! Validation errors: each names the scenario, the joint scene and the object.

use super::*;

// ---- (4) validation errors ----

/// Asserts the message names the scenario, the joint scene and the object.
fn names_all(e: &WosacExportError, joint_scene: usize, object_id: i64) {
    let msg = e.to_string();
    for part in [
        "scenario abc123".to_string(),
        format!("joint scene {joint_scene}"),
        format!("object {object_id}"),
    ] {
        assert!(msg.contains(&part), "{msg:?} lacks {part:?}");
    }
}

#[test]
fn sim_agents_are_tracks_valid_at_step_10() {
    assert_eq!(sim_agent_ids(&scene()), [1, 2, 13]);
}

#[test]
fn validation_errors() {
    let scene = scene();
    let good = rollouts_for(&scene);
    validate_rollouts(&scene, &good).unwrap();

    // Wrong rollout count.
    let mut r = good.clone();
    r.joint_scenes.pop();
    let e = validate_rollouts(&scene, &r).unwrap_err();
    assert!(
        matches!(e, WosacExportError::JointSceneCount { got: 31, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("abc123"), "{e}");

    // 79 steps.
    let mut r = good.clone();
    r.joint_scenes[5][1].y_m.pop();
    let e = validate_rollouts(&scene, &r).unwrap_err();
    assert!(
        matches!(
            e,
            WosacExportError::StepCount {
                joint_scene: 5,
                object_id: 2,
                field: "center_y",
                got: 79,
                ..
            }
        ),
        "{e}"
    );
    names_all(&e, 5, 2);

    // Unknown object id, and a track that exists but is invalid at step 10.
    for bad_id in [99, 5] {
        let mut r = good.clone();
        r.joint_scenes[7][0].object_id = bad_id;
        let e = validate_rollouts(&scene, &r).unwrap_err();
        assert!(
            matches!(e, WosacExportError::NotSimAgent { joint_scene: 7, object_id, .. } if object_id == bad_id),
            "{e}"
        );
        names_all(&e, 7, bad_id);
    }

    // Missing sim agent.
    let mut r = good.clone();
    r.joint_scenes[31].remove(2);
    let e = validate_rollouts(&scene, &r).unwrap_err();
    assert!(
        matches!(
            e,
            WosacExportError::MissingSimAgent {
                joint_scene: 31,
                object_id: 13,
                ..
            }
        ),
        "{e}"
    );
    names_all(&e, 31, 13);

    // Duplicate id (replacing agent 13 by a second agent 1).
    let mut r = good.clone();
    r.joint_scenes[0][2] = r.joint_scenes[0][0].clone();
    let e = validate_rollouts(&scene, &r).unwrap_err();
    assert!(
        matches!(
            e,
            WosacExportError::DuplicateObject {
                joint_scene: 0,
                object_id: 1,
                ..
            }
        ),
        "{e}"
    );
    names_all(&e, 0, 1);

    // NaN, and infinity.
    for (bad, field) in [(f32::NAN, "heading"), (f32::INFINITY, "center_z")] {
        let mut r = good.clone();
        let t = &mut r.joint_scenes[12][0];
        match field {
            "heading" => t.heading_rad[40] = bad,
            _ => t.z_m[40] = bad,
        }
        let e = validate_rollouts(&scene, &r).unwrap_err();
        assert!(
            matches!(
                e,
                WosacExportError::NonFinite {
                    joint_scene: 12,
                    object_id: 1,
                    future_step: 40,
                    field: f,
                    ..
                } if f == field
            ),
            "{e}"
        );
        names_all(&e, 12, 1);
        assert!(e.to_string().contains("global step 51"), "{e}");
    }

    // Scenario id missing or wrong.
    let mut r = good.clone();
    r.scenario_id.clear();
    let e = validate_rollouts(&scene, &r).unwrap_err();
    assert!(
        matches!(e, WosacExportError::MissingScenarioId { .. }),
        "{e}"
    );
    r.scenario_id = "zzz".into();
    let e = validate_rollouts(&scene, &r).unwrap_err();
    assert!(
        matches!(e, WosacExportError::ScenarioIdMismatch { .. }),
        "{e}"
    );
    assert!(e.to_string().contains("zzz") && e.to_string().contains("abc123"));

    // A scene whose current step is not 10.
    let mut other = scene.clone();
    other.current_step = 11;
    let e = validate_rollouts(&other, &good).unwrap_err();
    assert!(
        matches!(
            e,
            WosacExportError::SceneLayout {
                current_step: 11,
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn each_kind_of_invalid_rollouts_has_its_own_reason() {
    let scene = scene();
    let good = rollouts_for(&scene);
    let mutations: [fn(&mut ScenarioRolloutsInput); 7] = [
        |r| r.scenario_id.clear(),
        |r| r.scenario_id = "zzz".into(),
        |r| {
            r.joint_scenes.pop();
        },
        |r| r.joint_scenes[3][0].object_id = 99,
        |r| {
            r.joint_scenes[3].pop();
        },
        |r| {
            r.joint_scenes[3][1].x_m.pop();
        },
        |r| r.joint_scenes[3][1].x_m[0] = f32::NAN,
    ];
    let reasons: BTreeSet<&str> = mutations
        .iter()
        .map(|mutate| {
            let mut r = good.clone();
            mutate(&mut r);
            let e = validate_rollouts(&scene, &r).unwrap_err();
            // The reason is the kind alone: no scenario, joint scene or object named.
            let reason = e.reason();
            assert!(
                !reason.contains("abc123") && !reason.contains("99"),
                "{reason}"
            );
            assert!(e.to_string().contains("abc123"), "{e}");
            reason
        })
        .collect();
    assert_eq!(reasons.len(), mutations.len(), "{reasons:?}");
}
