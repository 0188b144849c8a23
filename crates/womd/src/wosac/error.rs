//! Why a WOSAC submission could not be validated, encoded, written or decoded.

use std::path::PathBuf;

use super::{
    CURRENT_STEP, MAX_SHARDS, ROLLOUTS_PER_SCENARIO, SIMULATED_STEPS, SUBMISSION_TYPE_SIM_AGENTS,
};

/// Why a WOSAC submission could not be validated, encoded, written or decoded.
#[derive(Debug, thiserror::Error)]
pub enum WosacExportError {
    /// The rollouts carry no scenario id.
    #[error("rollouts for scenario {expected}: scenario_id is empty")]
    MissingScenarioId {
        /// Id of the scene they were checked against.
        expected: String,
    },
    /// The rollouts name another scenario than the scene.
    #[error("rollouts name scenario {got} but the scene is scenario {expected}")]
    ScenarioIdMismatch {
        /// Id of the scene.
        expected: String,
        /// Id in the rollouts.
        got: String,
    },
    /// The scene does not have WOSAC's layout (current step 10).
    #[error(
        "scenario {scenario_id}: current step is {current_step}, WOSAC needs {CURRENT_STEP} \
         (scene has {num_steps} steps)"
    )]
    SceneLayout {
        /// Id of the scene.
        scenario_id: String,
        /// The scene's current step.
        current_step: usize,
        /// The scene's number of steps.
        num_steps: usize,
    },
    /// Not exactly [`ROLLOUTS_PER_SCENARIO`] joint scenes.
    #[error("scenario {scenario_id}: {got} joint scenes, WOSAC needs {ROLLOUTS_PER_SCENARIO}")]
    JointSceneCount {
        /// Id of the scenario.
        scenario_id: String,
        /// Number of joint scenes given.
        got: usize,
    },
    /// A trajectory's object is not a sim agent (unknown id, or not valid at step 10).
    #[error(
        "scenario {scenario_id}, joint scene {joint_scene}, object {object_id}: \
         not a sim agent (no track with this id is valid at step {CURRENT_STEP})"
    )]
    NotSimAgent {
        /// Id of the scenario.
        scenario_id: String,
        /// 0-based index of the joint scene.
        joint_scene: usize,
        /// The offending object id.
        object_id: i64,
    },
    /// A sim agent has no trajectory in a joint scene.
    #[error(
        "scenario {scenario_id}, joint scene {joint_scene}, object {object_id}: \
         sim agent missing from the joint scene"
    )]
    MissingSimAgent {
        /// Id of the scenario.
        scenario_id: String,
        /// 0-based index of the joint scene.
        joint_scene: usize,
        /// The missing sim agent's id.
        object_id: i64,
    },
    /// An object has two trajectories in one joint scene.
    #[error(
        "scenario {scenario_id}, joint scene {joint_scene}, object {object_id}: \
         duplicate trajectory for this object"
    )]
    DuplicateObject {
        /// Id of the scenario.
        scenario_id: String,
        /// 0-based index of the joint scene.
        joint_scene: usize,
        /// The duplicated object id.
        object_id: i64,
    },
    /// A trajectory field does not have exactly [`SIMULATED_STEPS`] values.
    #[error(
        "scenario {scenario_id}, joint scene {joint_scene}, object {object_id}: \
         {field} has {got} values, WOSAC needs {SIMULATED_STEPS}"
    )]
    StepCount {
        /// Id of the scenario.
        scenario_id: String,
        /// 0-based index of the joint scene.
        joint_scene: usize,
        /// The object id.
        object_id: i64,
        /// Proto name of the field (`center_x`, `center_y`, `center_z`, `heading`).
        field: &'static str,
        /// Number of values given.
        got: usize,
    },
    /// A trajectory value is NaN or infinite.
    #[error(
        "scenario {scenario_id}, joint scene {joint_scene}, object {object_id}: \
         {field} at future step {future_step} (global step {}) is not finite",
        future_step + CURRENT_STEP + 1
    )]
    NonFinite {
        /// Id of the scenario.
        scenario_id: String,
        /// 0-based index of the joint scene.
        joint_scene: usize,
        /// The object id.
        object_id: i64,
        /// Proto name of the field (`center_x`, `center_y`, `center_z`, `heading`).
        field: &'static str,
        /// 0-based future step (global step = 11 + `future_step`).
        future_step: usize,
    },
    /// An object id does not fit the int32 `object_id` field.
    #[error(
        "scenario {scenario_id}, joint scene {joint_scene}, object {object_id}: \
         id does not fit the int32 `object_id` field"
    )]
    ObjectIdOverflow {
        /// Id of the scenario.
        scenario_id: String,
        /// 0-based index of the joint scene.
        joint_scene: usize,
        /// The offending object id.
        object_id: i64,
    },
    /// A scenario appears twice in one submission.
    #[error("scenario {scenario_id} appears more than once in the submission")]
    DuplicateScenario {
        /// Id of the repeated scenario.
        scenario_id: String,
    },
    /// The shard count is 0 or above [`MAX_SHARDS`].
    #[error("shard count {shards} is outside 1..={MAX_SHARDS}")]
    ShardCount {
        /// The requested count.
        shards: usize,
    },
    /// The shard base name is empty or contains a path separator.
    #[error("shard base name {name:?} must be non-empty and contain no path separator")]
    ShardName {
        /// The rejected name.
        name: String,
    },
    /// Creating the folder or writing a shard failed.
    #[error("{error}: {}", path.display())]
    Io {
        /// The folder or shard file.
        path: PathBuf,
        /// The underlying I/O error.
        error: std::io::Error,
    },
    /// The bytes are not a valid `SimAgentsChallengeSubmission`.
    #[error("protobuf: {0}")]
    Proto(prost::DecodeError),
    /// A decoded submission's type is not [`SUBMISSION_TYPE_SIM_AGENTS`].
    #[error(
        "submission_type is {got:?}, expected SIM_AGENTS_SUBMISSION ({SUBMISSION_TYPE_SIM_AGENTS})"
    )]
    SubmissionType {
        /// The decoded value (`None` when absent).
        got: Option<i32>,
    },
    /// A decoded trajectory has no `object_id`.
    #[error(
        "scenario {scenario_id}, joint scene {joint_scene}, trajectory {trajectory}: \
         no object_id"
    )]
    MissingObjectId {
        /// Id of the scenario (empty when absent).
        scenario_id: String,
        /// 0-based index of the joint scene.
        joint_scene: usize,
        /// 0-based index of the trajectory in the joint scene.
        trajectory: usize,
    },
}

impl WosacExportError {
    /// A short, stable description of the kind of problem, without ids or counts, for skip
    /// counters in summaries (the full message names the scenario, joint scene, object and
    /// field).
    pub fn reason(&self) -> &'static str {
        match self {
            Self::MissingScenarioId { .. } => "no scenario_id",
            Self::ScenarioIdMismatch { .. } => "rollouts of another scenario",
            Self::SceneLayout { .. } => "the logged scene's current step is not 10",
            Self::JointSceneCount { .. } => "not 32 joint scenes",
            Self::NotSimAgent { .. } => "a trajectory of an object that is not a sim agent",
            Self::MissingSimAgent { .. } => "a sim agent missing from a joint scene",
            Self::DuplicateObject { .. } => "an object twice in one joint scene",
            Self::StepCount { .. } => "a trajectory without 80 steps",
            Self::NonFinite { .. } => "a simulated value is not finite",
            Self::ObjectIdOverflow { .. } => "an object id beyond int32",
            Self::DuplicateScenario { .. } => "a scenario repeated in the submission",
            Self::ShardCount { .. } | Self::ShardName { .. } => "a bad shard layout",
            Self::Io { .. } => "an I/O error",
            Self::Proto(_) => "not a SimAgentsChallengeSubmission protobuf",
            Self::SubmissionType { .. } => "submission_type is not SIM_AGENTS_SUBMISSION",
            Self::MissingObjectId { .. } => "a trajectory without object_id",
        }
    }
}
