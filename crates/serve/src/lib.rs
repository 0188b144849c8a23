//! `scbg serve`: courtesy-controlled agents over HTTP for simulators.
//!
//! One model folder is loaded at start. Endpoints (JSON unless said; OpenAPI 3.1 at
//! `/openapi.json`, a docs page at `/docs`):
//!
//! | method | path | what |
//! |---|---|---|
//! | GET | `/healthz` | liveness and what is loaded |
//! | GET | `/openapi.json`, `/docs`, `/` | the API description, its page, the web viewer (no token needed for these four) |
//! | GET | `/metrics` | Prometheus counters |
//! | POST | `/v1/scenarios` | upload WOMD bytes (a TFRecord file or one `Scenario` message) |
//! | GET | `/v1/scenarios`, `/v1/scenarios/{id}/geometry` | the scenarios held; one's map and tracks |
//! | GET | `/v1/files` | the WOMD files of the data folder |
//! | POST | `/v1/scenarios/open` | open a file inside the configured data folder |
//! | POST | `/v1/generate` | B's world-frame future at a quantile or ψ toward A |
//! | POST | `/v1/courtesy` | ψ of a given future of B, with both expectations |
//! | POST | `/v1/sessions` | start a closed-loop simulation |
//! | POST | `/v1/sessions/{id}/step` | one step (the ego's new state in) → every agent's state |
//! | DELETE | `/v1/sessions/{id}` | close it (idle sessions expire) |
//!
//! Binds 127.0.0.1 by default; any other address needs a bearer token. Bodies are limited in
//! size, inference runs on a bounded pool of blocking workers (never on the async executor)
//! with a time limit, every error is `{"error": "..."}` with a 4xx status when the request is
//! at fault, and shutdown finishes the requests in flight.
//!
//! **Architecture invariant:** glue between HTTP and the `scbg` library; no numerics, formats
//! or models of its own.

#![warn(missing_docs)]

pub mod api;
mod error;
mod handlers;
pub mod load;
mod metrics;
pub mod soak;

use std::collections::{HashMap, VecDeque};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::{DefaultBodyLimit, MatchedPath, Request, State};
use axum::http::{HeaderMap, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::{delete, get, post};
use scbg::Model;
use scbg::Scene;
use tokio::sync::Semaphore;

pub use error::ApiError;
pub use handlers::ApiDoc;
pub use metrics::Metrics;

/// How the server runs.
#[derive(Debug, Clone)]
pub struct ServeConfig {
    /// Address to bind (default 127.0.0.1:8080).
    pub addr: SocketAddr,
    /// Bearer token every request but `/healthz` must carry (required off loopback).
    pub token: Option<String>,
    /// Folder whose files `POST /v1/scenarios/open` may read (nothing outside it).
    pub data_dir: Option<PathBuf>,
    /// Largest request body, bytes.
    pub max_body_bytes: usize,
    /// Longest an inference job may take before the request gets a 503.
    pub request_timeout: Duration,
    /// Inference jobs at once (blocking worker threads).
    pub workers: usize,
    /// A session idle this long is closed.
    pub session_ttl: Duration,
    /// Scenarios held (the oldest is dropped beyond this).
    pub max_scenarios: usize,
    /// Sessions open at once.
    pub max_sessions: usize,
    /// Connections open at once; one more is answered 503 and closed.
    pub max_connections: usize,
    /// Longest a client may take to send a request's headers (also how long an idle
    /// keep-alive connection is kept); the connection is closed after it.
    pub header_timeout: Duration,
    /// After the shutdown signal, how long requests in flight may take to finish.
    pub shutdown_grace: Duration,
}

impl Default for ServeConfig {
    fn default() -> Self {
        Self {
            addr: SocketAddr::from(([127, 0, 0, 1], 8080)),
            token: None,
            data_dir: None,
            max_body_bytes: 16 << 20,
            request_timeout: Duration::from_secs(30),
            workers: std::thread::available_parallelism().map_or(2, |n| n.get()),
            session_ttl: Duration::from_secs(600),
            max_scenarios: 256,
            max_sessions: 256,
            max_connections: 2048,
            header_timeout: Duration::from_secs(10),
            shutdown_grace: Duration::from_secs(30),
        }
    }
}

impl ServeConfig {
    /// Refuses an address other than loopback without a token, and empty tokens.
    pub fn check(&self) -> anyhow::Result<()> {
        if let Some(t) = &self.token {
            anyhow::ensure!(!t.trim().is_empty(), "the bearer token is empty");
        }
        anyhow::ensure!(
            self.addr.ip().is_loopback() || self.token.is_some(),
            "binding {} (not loopback) needs a bearer token (--token or SCBG_TOKEN)",
            self.addr
        );
        anyhow::ensure!(self.workers >= 1, "at least one worker");
        anyhow::ensure!(self.max_connections >= 1, "at least one connection");
        Ok(())
    }
}

/// Scenarios by id, and their insertion order (the oldest goes first).
pub(crate) type Scenarios = (HashMap<String, Arc<Scene>>, VecDeque<String>);

/// One closed-loop session and when it was last stepped.
#[derive(Debug)]
pub(crate) struct Session {
    pub session: scbg::Session,
    pub last_used: Instant,
}

/// What the handlers share.
#[derive(Debug)]
pub struct AppState {
    pub(crate) model: Arc<Model>,
    pub(crate) config: ServeConfig,
    pub(crate) scenarios: Mutex<Scenarios>,
    pub(crate) sessions: Mutex<HashMap<String, Arc<Mutex<Session>>>>,
    pub(crate) workers: Arc<Semaphore>,
    pub(crate) metrics: Metrics,
    pub(crate) data_dir: Option<PathBuf>,
}

impl AppState {
    /// The state for `model` under `config` (the data folder resolved once).
    pub fn new(model: Model, config: ServeConfig) -> anyhow::Result<Arc<Self>> {
        let data_dir = config
            .data_dir
            .as_ref()
            .map(|d| {
                d.canonicalize()
                    .map_err(|e| anyhow::anyhow!("data folder {}: {e}", d.display()))
            })
            .transpose()?;
        Ok(Arc::new(Self {
            model: Arc::new(model),
            workers: Arc::new(Semaphore::new(config.workers)),
            config,
            scenarios: Mutex::new((HashMap::new(), VecDeque::new())),
            sessions: Mutex::new(HashMap::new()),
            metrics: Metrics::default(),
            data_dir,
        }))
    }

    /// Holds `scene` under its id (the oldest scenario goes beyond the limit).
    pub(crate) fn put_scenario(&self, scene: Scene) {
        let mut guard = self.scenarios.lock().expect("scenarios lock");
        let (map, order) = &mut *guard;
        let id = scene.scenario_id.clone();
        if map.insert(id.clone(), Arc::new(scene)).is_none() {
            order.push_back(id);
        }
        while order.len() > self.config.max_scenarios {
            if let Some(old) = order.pop_front() {
                map.remove(&old);
            }
        }
    }

    /// The scenario `id`, or a 404 naming it.
    pub(crate) fn scenario(&self, id: &str) -> Result<Arc<Scene>, ApiError> {
        self.scenarios
            .lock()
            .expect("scenarios lock")
            .0
            .get(id)
            .cloned()
            .ok_or_else(|| {
                ApiError::not_found(format!(
                    "no scenario {id:?} (upload it with POST /v1/scenarios or open it with POST /v1/scenarios/open)"
                ))
            })
    }

    /// Closes sessions idle longer than the TTL; returns how many are left.
    pub(crate) fn expire_sessions(&self) -> usize {
        let ttl = self.config.session_ttl;
        let mut sessions = self.sessions.lock().expect("sessions lock");
        sessions.retain(|_, s| s.try_lock().map_or(true, |s| s.last_used.elapsed() < ttl));
        sessions.len()
    }

    /// Runs `f` on a blocking worker (at most `workers` at once) within the time limit.
    pub(crate) async fn blocking<T: Send + 'static>(
        self: &Arc<Self>,
        f: impl FnOnce(&Arc<Model>) -> Result<T, ApiError> + Send + 'static,
    ) -> Result<T, ApiError> {
        use std::sync::atomic::Ordering;
        self.metrics.in_flight.fetch_add(1, Ordering::Relaxed);
        let state = self.clone();
        let work =
            async move {
                let permit =
                    state.workers.clone().acquire_owned().await.map_err(|_| {
                        ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "shutting down")
                    })?;
                let model = state.model.clone();
                tokio::task::spawn_blocking(move || {
                    let _permit = permit;
                    f(&model)
                })
                .await
                .map_err(|_| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, "a worker failed"))?
            };
        let out = tokio::time::timeout(self.config.request_timeout, work)
            .await
            .unwrap_or_else(|_| {
                Err(ApiError::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    format!(
                        "the request took longer than {:.0} s",
                        self.config.request_timeout.as_secs_f64()
                    ),
                ))
            });
        self.metrics.in_flight.fetch_sub(1, Ordering::Relaxed);
        out
    }
}

/// Bearer-token check (every route but the pages, `/openapi.json` and `/healthz`), and the
/// request counters.
async fn guard(State(state): State<Arc<AppState>>, req: Request, next: Next) -> Response {
    let started = Instant::now();
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "unmatched".to_string(), |p| p.as_str().to_string());
    // Pages and descriptions carry no data: open without the token.
    let open = matches!(route.as_str(), "/" | "/healthz" | "/docs" | "/openapi.json");
    let response = if !open && !authorized(&state.config, req.headers()) {
        ApiError::new(
            StatusCode::UNAUTHORIZED,
            "missing or wrong bearer token (Authorization: Bearer <token>)",
        )
        .into_response()
    } else {
        // The whole request, body included, within the inference's limit plus the headers'
        // (a client trickling its body gets a 408, not a connection held for ever).
        let limit = state.config.request_timeout + state.config.header_timeout;
        tokio::time::timeout(limit, next.run(req))
            .await
            .unwrap_or_else(|_| {
                ApiError::new(
                    StatusCode::REQUEST_TIMEOUT,
                    format!(
                        "the request was not complete within {:.0} s",
                        limit.as_secs_f64()
                    ),
                )
                .into_response()
            })
    };
    // A request whose body was not read to its end (too large, too slow) leaves the
    // connection unusable: say so, so that no client sends another request on it.
    let mut response = response;
    if matches!(
        response.status(),
        StatusCode::PAYLOAD_TOO_LARGE | StatusCode::REQUEST_TIMEOUT
    ) {
        response.headers_mut().insert(
            axum::http::header::CONNECTION,
            axum::http::HeaderValue::from_static("close"),
        );
    }
    state.metrics.record(
        &route,
        response.status().as_u16(),
        started.elapsed().as_secs_f64(),
    );
    response
}

fn authorized(config: &ServeConfig, headers: &HeaderMap) -> bool {
    let Some(token) = &config.token else {
        return true;
    };
    headers
        .get(axum::http::header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .is_some_and(|given| constant_time_eq(given.as_bytes(), token.as_bytes()))
}

/// Compares two byte strings in a time that depends on their lengths only: every byte is
/// looked at, whatever differs first.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = u8::from(a.len() != b.len());
    for i in 0..a.len().max(b.len()) {
        let (x, y) = (
            a.get(i).copied().unwrap_or(0),
            b.get(i).copied().unwrap_or(0),
        );
        diff |= std::hint::black_box(x ^ y);
    }
    diff == 0
}

/// The application: every route, the body limit, the token check, the JSON 404/405.
pub fn router(state: Arc<AppState>) -> Router {
    let limit = state.config.max_body_bytes;
    Router::new()
        .route("/", get(handlers::index))
        .route("/healthz", get(handlers::healthz))
        .route("/metrics", get(handlers::metrics))
        .route("/openapi.json", get(handlers::openapi))
        .route("/docs", get(handlers::docs))
        .route(
            "/v1/scenarios",
            post(handlers::upload).get(handlers::list_scenarios),
        )
        .route("/v1/scenarios/{id}/geometry", get(handlers::geometry))
        .route("/v1/files", get(handlers::list_files))
        .route("/v1/scenarios/open", post(handlers::open))
        .route("/v1/generate", post(handlers::generate))
        .route("/v1/courtesy", post(handlers::courtesy))
        .route("/v1/sessions", post(handlers::create_session))
        .route("/v1/sessions/{id}/step", post(handlers::step_session))
        .route("/v1/sessions/{id}", delete(handlers::close_session))
        .fallback(handlers::not_found)
        .method_not_allowed_fallback(handlers::method_not_allowed)
        .layer(axum::middleware::from_fn_with_state(state.clone(), guard))
        .layer(DefaultBodyLimit::max(limit))
        .with_state(state)
}

/// Serves until `shutdown` resolves, then finishes the requests in flight (for at most
/// [`ServeConfig::shutdown_grace`]). Sessions idle past the TTL are closed as they expire
/// (checked every tenth of the TTL, at most every 10 s). Beyond
/// [`ServeConfig::max_connections`] a new connection is answered 503 and closed; a client that
/// does not send its headers within [`ServeConfig::header_timeout`] is disconnected.
pub async fn serve(
    state: Arc<AppState>,
    listener: tokio::net::TcpListener,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let reaper = {
        let state = state.clone();
        let every = (state.config.session_ttl / 10)
            .clamp(Duration::from_millis(100), Duration::from_secs(10));
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(every);
            loop {
                tick.tick().await;
                state.expire_sessions();
            }
        })
    };
    let app = router(state.clone());
    let connections = Arc::new(Semaphore::new(state.config.max_connections));
    let graceful = hyper_util::server::graceful::GracefulShutdown::new();
    let mut shutdown = std::pin::pin!(shutdown);
    loop {
        let stream = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => stream,
                // Out of file descriptors and the like: the connection is lost, the server
                // is not.
                Err(e) => {
                    tracing::warn!("accepting a connection: {e}");
                    tokio::time::sleep(Duration::from_millis(20)).await;
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        let _ = stream.set_nodelay(true);
        let Ok(permit) = connections.clone().try_acquire_owned() else {
            state
                .metrics
                .refused_connections
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            tokio::spawn(refuse(stream));
            continue;
        };
        let connection = hyper::server::conn::http1::Builder::new()
            .timer(hyper_util::rt::TokioTimer::new())
            .header_read_timeout(state.config.header_timeout)
            .serve_connection(
                hyper_util::rt::TokioIo::new(stream),
                hyper_util::service::TowerToHyperService::new(app.clone()),
            );
        let connection = graceful.watch(connection);
        tokio::spawn(async move {
            let _ = connection.await;
            drop(permit);
        });
    }
    drop(listener);
    reaper.abort();
    let grace = state.config.shutdown_grace;
    if tokio::time::timeout(grace, graceful.shutdown())
        .await
        .is_err()
    {
        tracing::warn!(
            "requests still in flight {:.0} s after the shutdown signal were dropped",
            grace.as_secs_f64()
        );
    }
    Ok(())
}

/// Answers a connection beyond the limit with a 503 and closes it.
async fn refuse(mut stream: tokio::net::TcpStream) {
    use tokio::io::AsyncWriteExt;
    let body = r#"{"error":"too many connections; retry shortly"}"#;
    let response = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\ncontent-length: {}\r\nretry-after: 1\r\nconnection: close\r\n\r\n{body}",
        body.len()
    );
    let _ = tokio::time::timeout(Duration::from_secs(1), async {
        let _ = stream.write_all(response.as_bytes()).await;
        let _ = stream.shutdown().await;
    })
    .await;
}

/// A multi-threaded runtime whose threads carry the caller's floating-point mode (for the
/// server and the benches that run one).
pub(crate) fn runtime() -> std::io::Result<tokio::runtime::Runtime> {
    let mode = scbg::fp::Mode::current();
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .on_thread_start(move || mode.apply())
        .build()
}

/// `scbg serve`: loads the model, binds, serves until Ctrl-C (or SIGTERM).
pub fn run(model: Model, config: ServeConfig) -> anyhow::Result<()> {
    config.check()?;
    let runtime = runtime()?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(config.addr)
            .await
            .map_err(|e| anyhow::anyhow!("binding {}: {e}", config.addr))?;
        let addr = listener.local_addr()?;
        tracing::info!("scbg serve listening on http://{addr} (docs at /docs)");
        eprintln!("listening on http://{addr} — viewer at /, API docs at /docs");
        let state = AppState::new(model, config)?;
        serve(state, listener, shutdown_signal()).await
    })
}

/// Ctrl-C or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        if let Ok(mut s) = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        {
            s.recv().await;
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        () = ctrl_c => {},
        () = term => {},
    }
}

#[cfg(test)]
mod tests;
