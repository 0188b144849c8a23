//! The request and response bodies (JSON), with their OpenAPI schemas.

use scbg::{AgentState, Scene};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// Every error: what is wrong, in words.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct ErrorBody {
    /// What went wrong (names the field, id or file).
    pub error: String,
}

/// `GET /healthz`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Health {
    /// Always `ok` when the server answers.
    pub status: String,
    /// The generator variant loaded.
    pub variant: String,
    /// How a courtesy becomes B's future: `generator` or `ranked` (`scbg serve --policy`).
    pub policy: String,
    /// Whose reward the loaded model's courtesy counts: `pair` (A alone, the paper) or
    /// `neighbours <radius> m <sum|proximity>` (A and the vehicles near B).
    pub audience: String,
    /// Generators planning together: 1, or an ensemble folder's members (each request runs
    /// every one).
    pub members: usize,
    /// Scenarios held.
    pub scenarios: usize,
    /// Open closed-loop sessions.
    pub sessions: usize,
}

/// One track of a scenario.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct TrackSummary {
    /// Track id.
    pub id: i64,
    /// `vehicle`, `pedestrian`, `cyclist`, `other` or `unset`.
    pub object_type: String,
    /// Whether it is valid at the current step (only those can be A, B or simulated).
    pub valid_now: bool,
}

/// A scenario the server holds (`POST /v1/scenarios`, `POST /v1/scenarios/open`).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ScenarioSummary {
    /// Its id: the key of every later request.
    pub scenario_id: String,
    /// Steps (91 in WOMD).
    pub num_steps: usize,
    /// The current step (10 in WOMD).
    pub current_step: usize,
    /// The SDC's track id, when known (the default ego).
    pub sdc_id: Option<i64>,
    /// Labelled interacting objects.
    pub objects_of_interest: Vec<i64>,
    /// Every track.
    pub tracks: Vec<TrackSummary>,
}

impl ScenarioSummary {
    /// The summary of a scene.
    pub fn of(scene: &Scene) -> Self {
        Self {
            scenario_id: scene.scenario_id.clone(),
            num_steps: scene.num_steps(),
            current_step: scene.current_step,
            sdc_id: scene.sdc_track_index.map(|i| scene.tracks[i].id),
            objects_of_interest: scene.objects_of_interest.clone(),
            tracks: scene
                .tracks
                .iter()
                .map(|t| TrackSummary {
                    id: t.id,
                    object_type: t.object_type.name().to_string(),
                    valid_now: t.states.get(scene.current_step).is_some_and(|s| s.valid),
                })
                .collect(),
        }
    }
}

/// `POST /v1/scenarios`'s answer: every scenario of the upload.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Uploaded {
    /// The scenarios now held (by `scenario_id`).
    pub scenarios: Vec<ScenarioSummary>,
}

/// `POST /v1/scenarios/open`: a file inside the server's data folder.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct OpenScenario {
    /// Path relative to the data folder (no `..`, not absolute).
    pub file: String,
    /// Keep only this scenario of the file (default: all of them).
    #[serde(default)]
    pub scenario_id: Option<String>,
}

/// A courtesy request: a quantile in [0, 1] of the predicted range, or an explicit ψ (m/s,
/// |ψ| ≤ 50).
#[derive(Debug, Clone, Copy, Deserialize, Serialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CourtesyAsk {
    /// Quantile in [0, 1] (0.1 and 0.9 are the predicted range's ends).
    #[serde(default)]
    pub quantile: Option<f32>,
    /// Explicit ψ (m/s for the default reward) instead of a quantile.
    #[serde(default)]
    pub psi: Option<f32>,
}

impl CourtesyAsk {
    /// The runtime's checked courtesy; exactly one of the two must be given.
    pub fn to_courtesy(self) -> Result<scbg::Courtesy, scbg::InvalidRequest> {
        scbg::Courtesy::from_request(self.quantile, self.psi)
    }
}

/// `POST /v1/generate`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct GenerateRequest {
    /// A scenario the server holds.
    pub scenario_id: String,
    /// Track id of A (whose reward courtesy is about).
    pub a: i64,
    /// Track id of B (the generated agent).
    pub b: i64,
    /// Quantile in [0, 1].
    #[serde(default)]
    pub quantile: Option<f32>,
    /// Or an explicit ψ in m/s, |ψ| ≤ 50.
    #[serde(default)]
    pub psi: Option<f32>,
}

/// `POST /v1/generate`'s answer: B's future in the world frame.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct GenerateResponse {
    /// The quantile asked for (or the one an explicit ψ corresponds to).
    pub quantile: f32,
    /// The ψ asked of the generator.
    pub psi: f32,
    /// The predicted 0.1 quantile of ψ for this scene and pair.
    pub psi_low: f32,
    /// The predicted 0.9 quantile.
    pub psi_high: f32,
    /// J_φ of the generated future.
    pub achieved_psi: f32,
    /// A's expected average speed given B's generated future, m/s.
    pub a_expected_speed_mps: f32,
    /// A's expected average speed without conditioning on B, m/s.
    pub a_expected_speed_marginal_mps: f32,
    /// B's future: 80 world-frame points, 10 Hz, after the current step, kept in lane as the
    /// closed loop keeps its plans.
    pub world_xy_m: Vec<[f64; 2]>,
}

/// `POST /v1/courtesy`: ψ of a future of B.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CourtesyRequest {
    /// A scenario the server holds.
    pub scenario_id: String,
    /// Track id of A.
    pub a: i64,
    /// Track id of B.
    pub b: i64,
    /// B's future: 80 world-frame points `[x, y]`, 10 Hz, after the current step.
    pub future_xy_m: Vec<[f64; 2]>,
}

/// `POST /v1/courtesy`'s answer.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct CourtesyResponse {
    /// ψ = E[r(Y_A) | x, y_B] − E[r(Y_A) | x].
    pub psi: f32,
    /// E[r(Y_A) | x, y_B] (for a model trained toward B's neighbours: the weighted sum over
    /// them; see `/healthz`'s `audience`).
    pub a_expected_reward_conditional: f32,
    /// E[r(Y_A) | x].
    pub a_expected_reward_marginal: f32,
}

/// One controlled agent of a session.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ControlledAsk {
    /// Track id.
    pub id: i64,
    /// Quantile in [0, 1].
    #[serde(default)]
    pub quantile: Option<f32>,
    /// Or an explicit ψ in m/s, |ψ| ≤ 50.
    #[serde(default)]
    pub psi: Option<f32>,
}

/// `POST /v1/sessions`: a closed-loop simulation.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateSession {
    /// A scenario the server holds.
    pub scenario_id: String,
    /// The ego's track id (default: the SDC).
    #[serde(default)]
    pub ego: Option<i64>,
    /// The agents the generator drives, each with its courtesy toward the ego.
    pub controlled: Vec<ControlledAsk>,
    /// Steps between plans (1..=80; default 20, 2 s, with either policy).
    #[serde(default)]
    pub replan_every: Option<usize>,
    /// `external` (default: the caller sends the ego's state with every step), `reactive` or
    /// `log`.
    #[serde(default)]
    pub ego_mode: Option<String>,
    /// `log` (default) or `reactive`.
    #[serde(default)]
    pub others: Option<String>,
}

/// One agent's state.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, ToSchema)]
pub struct AgentStateBody {
    /// Track id (ignored in a step request).
    #[serde(default)]
    pub id: i64,
    /// Centre x, world frame, m.
    pub x_m: f64,
    /// Centre y, world frame, m.
    pub y_m: f64,
    /// Heading, rad.
    pub heading_rad: f32,
    /// Velocity x, m/s.
    #[serde(default)]
    pub velocity_x_mps: f32,
    /// Velocity y, m/s.
    #[serde(default)]
    pub velocity_y_mps: f32,
    /// Whether the agent exists at this step (answers only).
    #[serde(default = "yes")]
    pub valid: bool,
}

fn yes() -> bool {
    true
}

impl AgentStateBody {
    /// From a track's state.
    pub fn of(id: i64, s: &AgentState) -> Self {
        Self {
            id,
            x_m: s.x_m,
            y_m: s.y_m,
            heading_rad: s.heading_rad,
            velocity_x_mps: s.velocity_x_mps,
            velocity_y_mps: s.velocity_y_mps,
            valid: s.valid,
        }
    }
}

/// A session's state after `create` or `step`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SessionState {
    /// The session's id.
    pub session_id: String,
    /// The step the simulation is at.
    pub step: usize,
    /// Whether all 80 steps are done.
    pub finished: bool,
    /// Every agent's state at `step`.
    pub agents: Vec<AgentStateBody>,
}

/// `POST /v1/sessions/{id}/step`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct StepRequest {
    /// The ego's new state (required when the ego is driven from outside).
    #[serde(default)]
    pub ego: Option<AgentStateBody>,
}

/// `GET /v1/scenarios`: every scenario held.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ScenarioList {
    /// Their summaries, oldest first.
    pub scenarios: Vec<ScenarioSummary>,
}

/// `GET /v1/files`: the WOMD files of the data folder (paths relative to it).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct FileList {
    /// Relative paths, sorted.
    pub files: Vec<String>,
}

/// One drawn track: its states as `[x, y, heading, valid]` per step.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct TrackGeometry {
    /// Track id.
    pub id: i64,
    /// Object type name.
    pub object_type: String,
    /// Box length, m (at the current step).
    pub length_m: f32,
    /// Box width, m.
    pub width_m: f32,
    /// `[x m, y m, heading rad, valid 0/1]` per step.
    pub states: Vec<[f64; 4]>,
}

/// `GET /v1/scenarios/{id}/geometry`: what a viewer draws.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SceneGeometry {
    /// The scenario.
    pub scenario_id: String,
    /// The current step.
    pub current_step: usize,
    /// The SDC's id.
    pub sdc_id: Option<i64>,
    /// Objects of interest.
    pub objects_of_interest: Vec<i64>,
    /// Lane centre lines, `[[x, y], …]` each.
    pub lanes: Vec<Vec<[f64; 2]>>,
    /// Road lines.
    pub road_lines: Vec<Vec<[f64; 2]>>,
    /// Road edges.
    pub road_edges: Vec<Vec<[f64; 2]>>,
    /// Crosswalk polygons.
    pub crosswalks: Vec<Vec<[f64; 2]>>,
    /// Every track.
    pub tracks: Vec<TrackGeometry>,
}

impl SceneGeometry {
    /// The geometry of a scene.
    pub fn of(scene: &Scene) -> Self {
        let line = |pts: &[scbg::MapPoint]| pts.iter().map(|p| [p.x_m, p.y_m]).collect();
        let now = scene.current_step;
        Self {
            scenario_id: scene.scenario_id.clone(),
            current_step: now,
            sdc_id: scene.sdc_track_index.map(|i| scene.tracks[i].id),
            objects_of_interest: scene.objects_of_interest.clone(),
            lanes: scene.map.lanes.iter().map(|l| line(&l.polyline)).collect(),
            road_lines: scene
                .map
                .road_lines
                .iter()
                .map(|l| line(&l.polyline))
                .collect(),
            road_edges: scene
                .map
                .road_edges
                .iter()
                .map(|l| line(&l.polyline))
                .collect(),
            crosswalks: scene
                .map
                .crosswalks
                .iter()
                .map(|c| line(&c.polygon))
                .collect(),
            tracks: scene
                .tracks
                .iter()
                .map(|t| {
                    let at = t.states.get(now).copied().unwrap_or_default();
                    TrackGeometry {
                        id: t.id,
                        object_type: t.object_type.name().to_string(),
                        length_m: at.length_m,
                        width_m: at.width_m,
                        states: t
                            .states
                            .iter()
                            .map(|s| {
                                [
                                    s.x_m,
                                    s.y_m,
                                    f64::from(s.heading_rad),
                                    f64::from(u8::from(s.valid)),
                                ]
                            })
                            .collect(),
                    }
                })
                .collect(),
        }
    }
}
