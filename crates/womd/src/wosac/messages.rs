//! The hand-written `prost` messages of a submission (package `waymo.open_dataset`), mirroring
//! the official `sim_agents_submission.proto`; repeated scalars are written packed.

/// `SimulatedTrajectory`: one object's simulated future in one joint scene.
#[derive(Clone, PartialEq, prost::Message)]
pub struct SimulatedTrajectory {
    /// Centre x per simulated step, world frame, metres (exactly 80 values).
    #[prost(float, repeated, packed = "true", tag = "2")]
    pub center_x: Vec<f32>,
    /// Centre y per simulated step, world frame, metres (exactly 80 values).
    #[prost(float, repeated, packed = "true", tag = "3")]
    pub center_y: Vec<f32>,
    /// Centre z per simulated step, world frame, metres (exactly 80 values).
    #[prost(float, repeated, packed = "true", tag = "4")]
    pub center_z: Vec<f32>,
    /// Heading per simulated step, radians counter-clockwise from +x (exactly 80 values).
    #[prost(float, repeated, packed = "true", tag = "5")]
    pub heading: Vec<f32>,
    /// Id of the simulated object (`Track.id` in the scenario).
    #[prost(int32, optional, tag = "6")]
    pub object_id: Option<i32>,
    /// Box width per step, metres. Ignored by the sim-agents metric; left empty by the exporter.
    #[prost(float, repeated, packed = "true", tag = "7")]
    pub width: Vec<f32>,
    /// Box length per step, metres. Ignored by the sim-agents metric; left empty by the exporter.
    #[prost(float, repeated, packed = "true", tag = "8")]
    pub length: Vec<f32>,
    /// Box height per step, metres. Ignored by the sim-agents metric; left empty by the exporter.
    #[prost(float, repeated, packed = "true", tag = "9")]
    pub height: Vec<f32>,
    /// `Track.ObjectType` code. Ignored by the sim-agents metric; left unset by the exporter.
    #[prost(int32, optional, tag = "10")]
    pub object_type: Option<i32>,
    /// Validity per step. Ignored by the sim-agents metric; left empty by the exporter.
    #[prost(bool, repeated, packed = "true", tag = "11")]
    pub valid: Vec<bool>,
}

/// `JointScene`: one joint sample of every sim agent of a scenario.
#[derive(Clone, PartialEq, prost::Message)]
pub struct JointScene {
    /// One trajectory per sim agent.
    #[prost(message, repeated, tag = "1")]
    pub simulated_trajectories: Vec<SimulatedTrajectory>,
}

/// `ScenarioRollouts`: the joint scenes submitted for one scenario.
#[derive(Clone, PartialEq, prost::Message)]
pub struct ScenarioRollouts {
    /// Id of the scenario (`Scenario.scenario_id`).
    #[prost(string, optional, tag = "1")]
    pub scenario_id: Option<String>,
    /// Exactly 32 joint scenes.
    #[prost(message, repeated, tag = "2")]
    pub joint_scenes: Vec<JointScene>,
}

/// `SimAgentsChallengeSubmission`: one submission shard with its metadata.
#[derive(Clone, PartialEq, prost::Message)]
pub struct SimAgentsChallengeSubmission {
    /// The scenarios of this shard.
    #[prost(message, repeated, tag = "1")]
    pub scenario_rollouts: Vec<ScenarioRollouts>,
    /// `SubmissionType` code; must be
    /// [`SUBMISSION_TYPE_SIM_AGENTS`](super::SUBMISSION_TYPE_SIM_AGENTS).
    #[prost(int32, optional, tag = "2")]
    pub submission_type: Option<i32>,
    /// E-mail of the submitting account.
    #[prost(string, optional, tag = "3")]
    pub account_name: Option<String>,
    /// Method name shown on the leaderboard.
    #[prost(string, optional, tag = "4")]
    pub unique_method_name: Option<String>,
    /// Author names.
    #[prost(string, repeated, tag = "5")]
    pub authors: Vec<String>,
    /// Authors' affiliation.
    #[prost(string, optional, tag = "6")]
    pub affiliation: Option<String>,
    /// Method description.
    #[prost(string, optional, tag = "7")]
    pub description: Option<String>,
    /// Link to the method (paper, code).
    #[prost(string, optional, tag = "8")]
    pub method_link: Option<String>,
    /// Whether the method uses lidar data (required by the challenge).
    #[prost(bool, optional, tag = "9")]
    pub uses_lidar_data: Option<bool>,
    /// Whether the method uses camera data (required by the challenge).
    #[prost(bool, optional, tag = "10")]
    pub uses_camera_data: Option<bool>,
    /// Whether the method uses publicly pretrained models (required by the challenge).
    #[prost(bool, optional, tag = "11")]
    pub uses_public_model_pretraining: Option<bool>,
    /// Model size as text, e.g. `"645K"` (required by the challenge).
    #[prost(string, optional, tag = "12")]
    pub num_model_parameters: Option<String>,
    /// Names of the public pretrained models used.
    #[prost(string, repeated, tag = "13")]
    pub public_model_names: Vec<String>,
    /// Acknowledgement that the simulation is closed-loop at 10 Hz as the rules require.
    #[prost(bool, optional, tag = "14")]
    pub acknowledge_complies_with_closed_loop_requirement: Option<bool>,
}
