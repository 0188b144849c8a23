//! WOSAC (Waymo Open Sim Agents Challenge) submission export.
//!
//! The challenge takes, per test scenario, 32 joint rollouts of every *sim agent* (every track
//! valid at the current step 10), each 80 future steps (global steps 11..=90) of centre x, y, z
//! and heading, world frame. Submissions are `SimAgentsChallengeSubmission` protos
//! (`shared/spec/wosac.md` §3), one per shard file named
//! `name.binproto-00000-of-0000N`; the shards are then packed into one `.tar.gz` by the caller.
//!
//! Callers use the protobuf-free types [`ScenarioRolloutsInput`], [`ObjectTrajectory`] and
//! [`SubmissionHeader`]:
//! - [`validate_rollouts`] applies the challenge's validation rules against the logged
//!   [`Scene`] (plus the duplicate-id and finiteness checks that the metric needs);
//! - [`encode_submission`] serializes one submission, [`write_submission_shards`] writes a
//!   sharded submission atomically, [`decode_submission`] reads one back.
//!
//! The hand-written `prost` messages ([`SimAgentsChallengeSubmission`] and the messages it
//! holds) mirror the official `sim_agents_submission.proto`. Unlike [`crate::proto`], repeated
//! scalars here are written **packed**, as the official encoder does; decoding accepts packed
//! and unpacked forms alike.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use prost::Message;
use scbg_scene::Scene;

mod error;
mod messages;

pub use error::WosacExportError;
pub use messages::{
    JointScene, ScenarioRollouts, SimAgentsChallengeSubmission, SimulatedTrajectory,
};

/// The step whose validity makes a track a sim agent (WOSAC's "current" step).
pub const CURRENT_STEP: usize = 10;
/// Number of simulated (future) steps per object and joint scene: global steps 11..=90.
pub const SIMULATED_STEPS: usize = 80;
/// Number of joint scenes (rollouts) required per scenario.
pub const ROLLOUTS_PER_SCENARIO: usize = 32;
/// `SimAgentsChallengeSubmission.SubmissionType.SIM_AGENTS_SUBMISSION`, the only accepted value.
pub const SUBMISSION_TYPE_SIM_AGENTS: i32 = 1;
/// Largest shard count the 5-digit file-name pattern can express.
pub const MAX_SHARDS: usize = 99_999;

// ---- protobuf-free input types ----

/// One object's simulated future in one joint scene (world frame, as in the scenario).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ObjectTrajectory {
    /// Id of the simulated track ([`scbg_scene::Track::id`]); must fit int32 to be encoded.
    pub object_id: i64,
    /// Centre x at global steps 11..=90, metres (exactly [`SIMULATED_STEPS`] values).
    pub x_m: Vec<f32>,
    /// Centre y at global steps 11..=90, metres (exactly [`SIMULATED_STEPS`] values).
    pub y_m: Vec<f32>,
    /// Centre z at global steps 11..=90, metres (exactly [`SIMULATED_STEPS`] values).
    pub z_m: Vec<f32>,
    /// Heading at global steps 11..=90, radians counter-clockwise from +x
    /// (exactly [`SIMULATED_STEPS`] values).
    pub heading_rad: Vec<f32>,
}

/// The rollouts submitted for one scenario.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ScenarioRolloutsInput {
    /// Id of the scenario ([`Scene::scenario_id`]).
    pub scenario_id: String,
    /// [`ROLLOUTS_PER_SCENARIO`] joint scenes, each with one trajectory per sim agent.
    pub joint_scenes: Vec<Vec<ObjectTrajectory>>,
}

/// The submission's metadata, repeated in every shard.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SubmissionHeader {
    /// E-mail address of the Waymo Open Dataset account that submits.
    pub account_name: String,
    /// Method name shown on the leaderboard (unique per account).
    pub unique_method_name: String,
    /// Author names, in order.
    pub authors: Vec<String>,
    /// Authors' affiliation.
    pub affiliation: String,
    /// Short description of the method.
    pub description: String,
    /// Link to a paper or code for the method (may be empty).
    pub method_link: String,
    /// Whether the method uses lidar data.
    pub uses_lidar_data: bool,
    /// Whether the method uses camera data.
    pub uses_camera_data: bool,
    /// Whether the method uses publicly available pretrained models.
    pub uses_public_model_pretraining: bool,
    /// Number of model parameters as text, e.g. `"645K"` or `"1.2M"`.
    pub num_model_parameters: String,
    /// Names of the public pretrained models used (empty when none).
    pub public_model_names: Vec<String>,
    /// Acknowledgement that the simulation is closed-loop at 10 Hz as the challenge rules
    /// require (`acknowledge_complies_with_closed_loop_requirement`).
    pub acknowledge_closed_loop: bool,
}

// ---- validation ----

/// Ids of the scene's sim agents, in track order: every track whose state at
/// [`CURRENT_STEP`] is valid.
pub fn sim_agent_ids(scene: &Scene) -> Vec<i64> {
    scene
        .tracks
        .iter()
        .filter(|t| t.states.get(CURRENT_STEP).is_some_and(|s| s.valid))
        .map(|t| t.id)
        .collect()
}

/// Checks `rollouts` against the logged `scene` with the challenge's rules: the scenario id is
/// present and matches; the scene's current step is 10; exactly 32 joint scenes; in each, every
/// object is a sim agent, no object appears twice (the official validator accepts that but the
/// metric then fails), every sim agent is present, and each trajectory has exactly 80 finite
/// values of x, y, z and heading. The first problem found is returned.
pub fn validate_rollouts(
    scene: &Scene,
    rollouts: &ScenarioRolloutsInput,
) -> Result<(), WosacExportError> {
    let scenario_id = &rollouts.scenario_id;
    if scenario_id.is_empty() {
        return Err(WosacExportError::MissingScenarioId {
            expected: scene.scenario_id.clone(),
        });
    }
    if *scenario_id != scene.scenario_id {
        return Err(WosacExportError::ScenarioIdMismatch {
            expected: scene.scenario_id.clone(),
            got: scenario_id.clone(),
        });
    }
    if scene.current_step != CURRENT_STEP {
        return Err(WosacExportError::SceneLayout {
            scenario_id: scenario_id.clone(),
            current_step: scene.current_step,
            num_steps: scene.num_steps(),
        });
    }
    if rollouts.joint_scenes.len() != ROLLOUTS_PER_SCENARIO {
        return Err(WosacExportError::JointSceneCount {
            scenario_id: scenario_id.clone(),
            got: rollouts.joint_scenes.len(),
        });
    }
    let sim_agents = sim_agent_ids(scene);
    let sim_set: HashSet<i64> = sim_agents.iter().copied().collect();
    for (joint_scene, trajectories) in rollouts.joint_scenes.iter().enumerate() {
        let mut seen = HashSet::with_capacity(trajectories.len());
        for t in trajectories {
            let object_id = t.object_id;
            if !sim_set.contains(&object_id) {
                return Err(WosacExportError::NotSimAgent {
                    scenario_id: scenario_id.clone(),
                    joint_scene,
                    object_id,
                });
            }
            if !seen.insert(object_id) {
                return Err(WosacExportError::DuplicateObject {
                    scenario_id: scenario_id.clone(),
                    joint_scene,
                    object_id,
                });
            }
            let fields: [(&'static str, &[f32]); 4] = [
                ("center_x", &t.x_m),
                ("center_y", &t.y_m),
                ("center_z", &t.z_m),
                ("heading", &t.heading_rad),
            ];
            for (field, values) in fields {
                if values.len() != SIMULATED_STEPS {
                    return Err(WosacExportError::StepCount {
                        scenario_id: scenario_id.clone(),
                        joint_scene,
                        object_id,
                        field,
                        got: values.len(),
                    });
                }
                if let Some(future_step) = values.iter().position(|v| !v.is_finite()) {
                    return Err(WosacExportError::NonFinite {
                        scenario_id: scenario_id.clone(),
                        joint_scene,
                        object_id,
                        field,
                        future_step,
                    });
                }
            }
        }
        if let Some(&object_id) = sim_agents.iter().find(|id| !seen.contains(id)) {
            return Err(WosacExportError::MissingSimAgent {
                scenario_id: scenario_id.clone(),
                joint_scene,
                object_id,
            });
        }
    }
    Ok(())
}

// ---- encoding ----

fn scenario_rollouts_proto(
    rollouts: &ScenarioRolloutsInput,
) -> Result<ScenarioRollouts, WosacExportError> {
    let joint_scenes = rollouts
        .joint_scenes
        .iter()
        .enumerate()
        .map(|(joint_scene, trajectories)| {
            let simulated_trajectories = trajectories
                .iter()
                .map(|t| {
                    let object_id = i32::try_from(t.object_id).map_err(|_| {
                        WosacExportError::ObjectIdOverflow {
                            scenario_id: rollouts.scenario_id.clone(),
                            joint_scene,
                            object_id: t.object_id,
                        }
                    })?;
                    Ok(SimulatedTrajectory {
                        center_x: t.x_m.clone(),
                        center_y: t.y_m.clone(),
                        center_z: t.z_m.clone(),
                        heading: t.heading_rad.clone(),
                        object_id: Some(object_id),
                        ..Default::default()
                    })
                })
                .collect::<Result<Vec<_>, WosacExportError>>()?;
            Ok(JointScene {
                simulated_trajectories,
            })
        })
        .collect::<Result<Vec<_>, WosacExportError>>()?;
    Ok(ScenarioRollouts {
        scenario_id: Some(rollouts.scenario_id.clone()),
        joint_scenes,
    })
}

/// Builds the submission message for `rollouts` (submission type SIM_AGENTS_SUBMISSION; every
/// header field is written, including empty strings and `false` flags).
pub fn submission_proto(
    header: &SubmissionHeader,
    rollouts: &[ScenarioRolloutsInput],
) -> Result<SimAgentsChallengeSubmission, WosacExportError> {
    Ok(SimAgentsChallengeSubmission {
        scenario_rollouts: rollouts
            .iter()
            .map(scenario_rollouts_proto)
            .collect::<Result<_, _>>()?,
        submission_type: Some(SUBMISSION_TYPE_SIM_AGENTS),
        account_name: Some(header.account_name.clone()),
        unique_method_name: Some(header.unique_method_name.clone()),
        authors: header.authors.clone(),
        affiliation: Some(header.affiliation.clone()),
        description: Some(header.description.clone()),
        method_link: Some(header.method_link.clone()),
        uses_lidar_data: Some(header.uses_lidar_data),
        uses_camera_data: Some(header.uses_camera_data),
        uses_public_model_pretraining: Some(header.uses_public_model_pretraining),
        num_model_parameters: Some(header.num_model_parameters.clone()),
        public_model_names: header.public_model_names.clone(),
        acknowledge_complies_with_closed_loop_requirement: Some(header.acknowledge_closed_loop),
    })
}

fn check_unique_scenarios(rollouts: &[ScenarioRolloutsInput]) -> Result<(), WosacExportError> {
    let mut seen = HashSet::with_capacity(rollouts.len());
    match rollouts
        .iter()
        .find(|r| !seen.insert(r.scenario_id.as_str()))
    {
        Some(r) => Err(WosacExportError::DuplicateScenario {
            scenario_id: r.scenario_id.clone(),
        }),
        None => Ok(()),
    }
}

/// Serializes one `SimAgentsChallengeSubmission` holding `rollouts`.
///
/// This is a wire-level encoder: run [`validate_rollouts`] on each scenario first. It fails
/// only when a scenario id repeats or an object id does not fit int32.
pub fn encode_submission(
    header: &SubmissionHeader,
    rollouts: &[ScenarioRolloutsInput],
) -> Result<Vec<u8>, WosacExportError> {
    check_unique_scenarios(rollouts)?;
    Ok(submission_proto(header, rollouts)?.encode_to_vec())
}

/// The file name of shard `index` of `count`: `name.binproto-00000-of-00002`.
pub fn shard_file_name(name: &str, index: usize, count: usize) -> String {
    format!("{name}.binproto-{index:05}-of-{count:05}")
}

/// Writes `rollouts` as `shards` submission files `dir/name.binproto-IIIII-of-NNNNN`, each a
/// complete `SimAgentsChallengeSubmission` with the same header. Scenarios are split into
/// contiguous, evenly sized runs in the given order, so each appears in exactly one shard
/// (a shard may hold none when `shards > rollouts.len()`). `dir` is created if missing. Each
/// file is written atomically (temporary file, then rename); on an error the shards already
/// written stay. Returns the paths in shard order.
///
/// Run [`validate_rollouts`] on each scenario first; this checks only that scenario ids are
/// unique and object ids fit int32.
pub fn write_submission_shards(
    dir: &Path,
    name: &str,
    header: &SubmissionHeader,
    rollouts: &[ScenarioRolloutsInput],
    shards: usize,
) -> Result<Vec<PathBuf>, WosacExportError> {
    if shards == 0 || shards > MAX_SHARDS {
        return Err(WosacExportError::ShardCount { shards });
    }
    if name.is_empty() || name.contains(['/', '\\']) {
        return Err(WosacExportError::ShardName { name: name.into() });
    }
    check_unique_scenarios(rollouts)?;
    std::fs::create_dir_all(dir).map_err(|error| WosacExportError::Io {
        path: dir.to_path_buf(),
        error,
    })?;
    let n = rollouts.len();
    let mut paths = Vec::with_capacity(shards);
    for index in 0..shards {
        let part = &rollouts[index * n / shards..(index + 1) * n / shards];
        let bytes = submission_proto(header, part)?.encode_to_vec();
        let path = dir.join(shard_file_name(name, index, shards));
        scbg_base::atomic::write(&path, &bytes).map_err(|e| WosacExportError::Io {
            path: path.clone(),
            error: e.into(),
        })?;
        paths.push(path);
    }
    Ok(paths)
}

// ---- decoding ----

/// Parses one serialized `SimAgentsChallengeSubmission` (packed or unpacked repeated scalars)
/// into its header and scenarios. Absent strings and flags read as empty / `false`; the
/// submission type must be SIM_AGENTS_SUBMISSION and every trajectory must have an object id.
pub fn decode_submission(
    bytes: &[u8],
) -> Result<(SubmissionHeader, Vec<ScenarioRolloutsInput>), WosacExportError> {
    let msg = SimAgentsChallengeSubmission::decode(bytes).map_err(WosacExportError::Proto)?;
    if msg.submission_type != Some(SUBMISSION_TYPE_SIM_AGENTS) {
        return Err(WosacExportError::SubmissionType {
            got: msg.submission_type,
        });
    }
    let rollouts = msg
        .scenario_rollouts
        .into_iter()
        .map(|sr| {
            let scenario_id = sr.scenario_id.unwrap_or_default();
            let joint_scenes = sr
                .joint_scenes
                .into_iter()
                .enumerate()
                .map(|(joint_scene, js)| {
                    js.simulated_trajectories
                        .into_iter()
                        .enumerate()
                        .map(|(trajectory, t)| {
                            let object_id =
                                t.object_id
                                    .ok_or_else(|| WosacExportError::MissingObjectId {
                                        scenario_id: scenario_id.clone(),
                                        joint_scene,
                                        trajectory,
                                    })?;
                            Ok(ObjectTrajectory {
                                object_id: i64::from(object_id),
                                x_m: t.center_x,
                                y_m: t.center_y,
                                z_m: t.center_z,
                                heading_rad: t.heading,
                            })
                        })
                        .collect::<Result<Vec<_>, WosacExportError>>()
                })
                .collect::<Result<Vec<_>, WosacExportError>>()?;
            Ok(ScenarioRolloutsInput {
                scenario_id,
                joint_scenes,
            })
        })
        .collect::<Result<Vec<_>, WosacExportError>>()?;
    let header = SubmissionHeader {
        account_name: msg.account_name.unwrap_or_default(),
        unique_method_name: msg.unique_method_name.unwrap_or_default(),
        authors: msg.authors,
        affiliation: msg.affiliation.unwrap_or_default(),
        description: msg.description.unwrap_or_default(),
        method_link: msg.method_link.unwrap_or_default(),
        uses_lidar_data: msg.uses_lidar_data.unwrap_or_default(),
        uses_camera_data: msg.uses_camera_data.unwrap_or_default(),
        uses_public_model_pretraining: msg.uses_public_model_pretraining.unwrap_or_default(),
        num_model_parameters: msg.num_model_parameters.unwrap_or_default(),
        public_model_names: msg.public_model_names,
        acknowledge_closed_loop: msg
            .acknowledge_complies_with_closed_loop_requirement
            .unwrap_or_default(),
    };
    Ok((header, rollouts))
}

#[cfg(test)]
mod tests;
