//! The route handlers and the OpenAPI description generated from them.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::{BytesRejection, JsonRejection};
use axum::extract::{Path, State};
use axum::http::{StatusCode, header};
use axum::response::{Html, IntoResponse, Response};
use utoipa::OpenApi;

use crate::api::*;
use crate::{ApiError, AppState, Session};

type Body<T> = Result<Json<T>, JsonRejection>;

fn body<T>(b: Body<T>) -> Result<T, ApiError> {
    b.map(|Json(v)| v).map_err(ApiError::from)
}

/// The OpenAPI 3.1 description of the API.
#[derive(Debug, OpenApi)]
#[openapi(
    info(
        title = "scbg",
        description = "Socially-controllable behaviour generation: courtesy-controlled agents for traffic simulators."
    ),
    paths(
        healthz,
        list_scenarios,
        geometry,
        list_files,
        upload,
        open,
        generate,
        courtesy,
        create_session,
        step_session,
        close_session
    ),
    components(schemas(
        ErrorBody,
        Health,
        ScenarioList,
        FileList,
        TrackGeometry,
        SceneGeometry,
        TrackSummary,
        ScenarioSummary,
        Uploaded,
        OpenScenario,
        GenerateRequest,
        GenerateResponse,
        CourtesyRequest,
        CourtesyResponse,
        ControlledAsk,
        CreateSession,
        AgentStateBody,
        SessionState,
        StepRequest
    ))
)]
pub struct ApiDoc;

pub(crate) async fn index() -> Html<&'static str> {
    Html(include_str!("index.html"))
}

pub(crate) async fn docs() -> Html<&'static str> {
    Html(include_str!("docs.html"))
}

pub(crate) async fn openapi() -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        ApiDoc::openapi().to_pretty_json().unwrap_or_default(),
    )
        .into_response()
}

pub(crate) async fn metrics(State(state): State<Arc<AppState>>) -> Response {
    let scenarios = state.scenarios.lock().expect("scenarios lock").0.len();
    let sessions = state.expire_sessions();
    (
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        state.metrics.render(scenarios, sessions),
    )
        .into_response()
}

pub(crate) async fn not_found() -> ApiError {
    ApiError::not_found("no such route (see /openapi.json)")
}

pub(crate) async fn method_not_allowed() -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        "method not allowed on this route (see /openapi.json)",
    )
}

/// Liveness and what is loaded.
#[utoipa::path(get, path = "/healthz", responses((status = 200, body = Health)))]
pub(crate) async fn healthz(State(state): State<Arc<AppState>>) -> Json<Health> {
    Json(Health {
        status: "ok".into(),
        variant: state.model.variant().name().to_string(),
        policy: state.model.policy().name().to_string(),
        audience: state.model.audience(),
        members: state.model.members(),
        scenarios: state.scenarios.lock().expect("scenarios lock").0.len(),
        sessions: state.expire_sessions(),
    })
}

/// Every scenario the server holds.
#[utoipa::path(get, path = "/v1/scenarios", responses((status = 200, body = ScenarioList)))]
pub(crate) async fn list_scenarios(State(state): State<Arc<AppState>>) -> Json<ScenarioList> {
    let guard = state.scenarios.lock().expect("scenarios lock");
    let (map, order) = &*guard;
    Json(ScenarioList {
        scenarios: order
            .iter()
            .filter_map(|id| map.get(id))
            .map(|s| ScenarioSummary::of(s))
            .collect(),
    })
}

/// A scenario's map and tracks, for drawing.
#[utoipa::path(
    get,
    path = "/v1/scenarios/{id}/geometry",
    params(("id" = String, Path, description = "the scenario id")),
    responses((status = 200, body = SceneGeometry), (status = 404, body = ErrorBody))
)]
pub(crate) async fn geometry(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<SceneGeometry>, ApiError> {
    Ok(Json(SceneGeometry::of(&*state.scenario(&id)?)))
}

/// The WOMD files of the data folder (`.tfrecord` in their names, two levels deep at most;
/// links leading outside it are not listed).
#[utoipa::path(get, path = "/v1/files", responses((status = 200, body = FileList)))]
pub(crate) async fn list_files(State(state): State<Arc<AppState>>) -> Json<FileList> {
    let mut files = Vec::new();
    if let Some(root) = &state.data_dir {
        let mut dirs = vec![(root.clone(), 0)];
        while let Some((dir, depth)) = dirs.pop() {
            let Ok(entries) = std::fs::read_dir(&dir) else {
                continue;
            };
            for e in entries.flatten() {
                let path = e.path();
                // Only what `open` would read: nothing that resolves outside the folder.
                if !path.canonicalize().is_ok_and(|p| p.starts_with(root)) {
                    continue;
                }
                if path.is_dir() && depth < 1 {
                    dirs.push((path, depth + 1));
                } else if path.is_file()
                    && path
                        .file_name()
                        .is_some_and(|n| n.to_string_lossy().contains(".tfrecord"))
                    && let Ok(rel) = path.strip_prefix(root)
                {
                    files.push(rel.to_string_lossy().into_owned());
                }
            }
        }
    }
    files.sort();
    Json(FileList { files })
}

/// Upload WOMD bytes: a TFRecord file (Scenario or tf.Example records) or one serialized
/// `Scenario` message. Every scenario in it is held under its id.
#[utoipa::path(
    post,
    path = "/v1/scenarios",
    request_body(content = Vec<u8>, content_type = "application/octet-stream"),
    responses(
        (status = 200, body = Uploaded),
        (status = 400, body = ErrorBody, description = "not WOMD bytes"),
        (status = 413, body = ErrorBody, description = "body too large")
    )
)]
pub(crate) async fn upload(
    State(state): State<Arc<AppState>>,
    bytes: Result<Bytes, BytesRejection>,
) -> Result<Json<Uploaded>, ApiError> {
    let bytes = bytes?;
    if bytes.is_empty() {
        return Err(ApiError::bad("empty body: send the WOMD file's bytes"));
    }
    let scenes = state
        .blocking(move |_| scbg::data::scenes_from_bytes(bytes.to_vec()).map_err(ApiError::from))
        .await?;
    Ok(Json(hold(&state, scenes)))
}

fn hold(state: &AppState, scenes: Vec<scbg::Scene>) -> Uploaded {
    let scenarios = scenes.iter().map(ScenarioSummary::of).collect();
    for s in scenes {
        state.put_scenario(s);
    }
    Uploaded { scenarios }
}

/// Open a WOMD file inside the server's data folder (nothing outside it is readable).
#[utoipa::path(
    post,
    path = "/v1/scenarios/open",
    request_body = OpenScenario,
    responses(
        (status = 200, body = Uploaded),
        (status = 400, body = ErrorBody),
        (status = 403, body = ErrorBody, description = "outside the data folder, or none configured"),
        (status = 404, body = ErrorBody)
    )
)]
pub(crate) async fn open(
    State(state): State<Arc<AppState>>,
    req: Body<OpenScenario>,
) -> Result<Json<Uploaded>, ApiError> {
    let req = body(req)?;
    let Some(root) = state.data_dir.clone() else {
        return Err(ApiError::new(
            StatusCode::FORBIDDEN,
            "the server has no data folder (start it with --data-dir)",
        ));
    };
    let rel = std::path::Path::new(&req.file);
    if req.file.is_empty()
        || rel.is_absolute()
        || rel
            .components()
            .any(|c| !matches!(c, std::path::Component::Normal(_)))
    {
        return Err(ApiError::new(
            StatusCode::FORBIDDEN,
            format!(
                "file {:?}: give a path relative to the data folder, without `..`",
                req.file
            ),
        ));
    }
    let path = root
        .join(rel)
        .canonicalize()
        .map_err(|_| ApiError::not_found(format!("file {:?}: not in the data folder", req.file)))?;
    if !path.starts_with(&root) {
        return Err(ApiError::new(
            StatusCode::FORBIDDEN,
            format!("file {:?}: outside the data folder", req.file),
        ));
    }
    let wanted = req.scenario_id.clone();
    let file = req.file.clone();
    let scenes = state
        .blocking(move |_| {
            let scenes = scbg::data::read_scenes(&path)
                .map_err(|e| ApiError::bad(format!("file {file:?}: {e:#}")))?;
            let scenes: Vec<_> = match &wanted {
                Some(id) => scenes
                    .into_iter()
                    .filter(|s| &s.scenario_id == id)
                    .collect(),
                None => scenes,
            };
            if scenes.is_empty() {
                return Err(ApiError::not_found(format!(
                    "file {file:?}: no scenario{}",
                    wanted.map_or(String::new(), |id| format!(" {id:?}"))
                )));
            }
            Ok(scenes)
        })
        .await?;
    Ok(Json(hold(&state, scenes)))
}

/// B's future in the world frame at a courtesy quantile (or ψ) toward A.
#[utoipa::path(
    post,
    path = "/v1/generate",
    request_body = GenerateRequest,
    responses(
        (status = 200, body = GenerateResponse),
        (status = 400, body = ErrorBody, description = "unknown track, quantile outside [0, 1], …"),
        (status = 404, body = ErrorBody, description = "unknown scenario"),
        (status = 422, body = ErrorBody, description = "wrong JSON types or missing fields")
    )
)]
pub(crate) async fn generate(
    State(state): State<Arc<AppState>>,
    req: Body<GenerateRequest>,
) -> Result<Json<GenerateResponse>, ApiError> {
    let req = body(req)?;
    let courtesy = CourtesyAsk {
        quantile: req.quantile,
        psi: req.psi,
    }
    .to_courtesy()
    .map_err(|e| ApiError::bad(e.0))?;
    let scene = state.scenario(&req.scenario_id)?;
    let out = state
        .blocking(move |model| {
            model
                .generate(&scene, req.a, req.b, &[courtesy])
                .map_err(ApiError::from)
        })
        .await?;
    let g = out
        .trajectories
        .into_iter()
        .next()
        .ok_or_else(|| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, "no trajectory"))?;
    Ok(Json(GenerateResponse {
        quantile: g.quantile,
        psi: g.psi,
        psi_low: g.psi_low,
        psi_high: g.psi_high,
        achieved_psi: g.achieved_psi,
        a_expected_speed_mps: g.a_expected_reward_conditional,
        a_expected_speed_marginal_mps: g.a_expected_reward_marginal,
        world_xy_m: g.world_xy_m,
    }))
}

/// ψ of a given future of B toward A, with both expectations.
#[utoipa::path(
    post,
    path = "/v1/courtesy",
    request_body = CourtesyRequest,
    responses(
        (status = 200, body = CourtesyResponse),
        (status = 400, body = ErrorBody),
        (status = 404, body = ErrorBody),
        (status = 422, body = ErrorBody)
    )
)]
pub(crate) async fn courtesy(
    State(state): State<Arc<AppState>>,
    req: Body<CourtesyRequest>,
) -> Result<Json<CourtesyResponse>, ApiError> {
    let req = body(req)?;
    let scene = state.scenario(&req.scenario_id)?;
    let c = state
        .blocking(move |model| {
            model
                .courtesy_of(&scene, req.a, req.b, &req.future_xy_m)
                .map_err(ApiError::from)
        })
        .await?;
    Ok(Json(CourtesyResponse {
        psi: c.psi,
        a_expected_reward_conditional: c.a_expected_reward_conditional,
        a_expected_reward_marginal: c.a_expected_reward_marginal,
    }))
}

fn session_state(id: &str, sim: &scbg::Session) -> SessionState {
    SessionState {
        session_id: id.to_string(),
        step: sim.step_index(),
        finished: sim.finished(),
        agents: sim
            .snapshot()
            .iter()
            .map(|a| AgentStateBody::of(a.id, &a.state))
            .collect(),
    }
}

fn new_session_id() -> String {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos()),
    );
    format!("s{:016x}", h.finish())
}

/// Start a closed-loop simulation: the controlled agents are driven by the generator (each
/// toward the ego), the ego by the caller (default), the others by their logs or IDM.
#[utoipa::path(
    post,
    path = "/v1/sessions",
    request_body = CreateSession,
    responses(
        (status = 200, body = SessionState),
        (status = 400, body = ErrorBody, description = "unknown agent, agent not valid now, bad quantile or mode, scenario too short"),
        (status = 404, body = ErrorBody),
        (status = 422, body = ErrorBody),
        (status = 503, body = ErrorBody, description = "too many sessions")
    )
)]
pub(crate) async fn create_session(
    State(state): State<Arc<AppState>>,
    req: Body<CreateSession>,
) -> Result<Json<SessionState>, ApiError> {
    let req = body(req)?;
    let scene = state.scenario(&req.scenario_id)?;
    let ego: scbg::choices::EgoMode = req
        .ego_mode
        .as_deref()
        .unwrap_or("external")
        .parse()
        .map_err(ApiError::bad)?;
    let others: scbg::choices::OthersMode = req
        .others
        .as_deref()
        .unwrap_or("log")
        .parse()
        .map_err(ApiError::bad)?;
    let controlled = req
        .controlled
        .iter()
        .map(|c| {
            CourtesyAsk {
                quantile: c.quantile,
                psi: c.psi,
            }
            .to_courtesy()
            .map(|courtesy| scbg::ControlledAgent::new(c.id, courtesy))
            .map_err(|e| ApiError::bad(format!("controlled agent {}: {e}", c.id)))
        })
        .collect::<Result<Vec<_>, _>>()?;
    if state.expire_sessions() >= state.config.max_sessions {
        return Err(ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "{} sessions are open; close one (DELETE /v1/sessions/{{id}})",
                state.config.max_sessions
            ),
        ));
    }
    let options = scbg::LoopOptions {
        ego,
        others,
        replan_every: req.replan_every,
    };
    let ego_id = req.ego;
    let session = state
        .blocking(move |model| {
            scbg::Session::start(model.clone(), scene, ego_id, controlled, &options)
                .map_err(ApiError::from)
        })
        .await?;
    let id = new_session_id();
    let answer = session_state(&id, &session);
    state.sessions.lock().expect("sessions lock").insert(
        id,
        Arc::new(Mutex::new(Session {
            session,
            last_used: Instant::now(),
        })),
    );
    Ok(Json(answer))
}

/// One step: the ego's new state in (when the caller drives it), every agent's state out.
#[utoipa::path(
    post,
    path = "/v1/sessions/{id}/step",
    params(("id" = String, Path, description = "the session")),
    request_body = StepRequest,
    responses(
        (status = 200, body = SessionState),
        (status = 400, body = ErrorBody, description = "no ego state, a non-finite field, finished"),
        (status = 404, body = ErrorBody),
        (status = 422, body = ErrorBody)
    )
)]
pub(crate) async fn step_session(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    req: Body<StepRequest>,
) -> Result<Json<SessionState>, ApiError> {
    let req = body(req)?;
    let session = state
        .sessions
        .lock()
        .expect("sessions lock")
        .get(&id)
        .cloned()
        .ok_or_else(|| ApiError::not_found(format!("no session {id:?} (closed or expired)")))?;
    let answer = state
        .blocking(move |_| {
            let mut s = session.lock().map_err(|_| {
                ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, "the session is broken")
            })?;
            let s = &mut *s;
            let ego = req.ego.map(|e| scbg::EgoPose {
                x_m: e.x_m,
                y_m: e.y_m,
                heading_rad: e.heading_rad,
                velocity_mps: [e.velocity_x_mps, e.velocity_y_mps],
            });
            s.session.step(ego).map_err(ApiError::from)?;
            s.last_used = Instant::now();
            Ok(session_state(&id, &s.session))
        })
        .await?;
    Ok(Json(answer))
}

/// Close a session.
#[utoipa::path(
    delete,
    path = "/v1/sessions/{id}",
    params(("id" = String, Path, description = "the session")),
    responses((status = 204), (status = 404, body = ErrorBody))
)]
pub(crate) async fn close_session(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    state
        .sessions
        .lock()
        .expect("sessions lock")
        .remove(&id)
        .map(|_| StatusCode::NO_CONTENT)
        .ok_or_else(|| ApiError::not_found(format!("no session {id:?}")))
}
