//! The API end to end on a tiny trained model: happy paths, every bad input of the issue as a
//! 4xx JSON error, the token, the data folder's fence, sessions, a real TCP server that shuts
//! down gracefully.

use std::path::Path;
use std::sync::{Arc, OnceLock};

use axum::body::Body;
use axum::http::{Request, StatusCode};
use http_body_util::BodyExt;
use scbg::choices::{Family, MarginalEstimate, Reward, Variant};
use scbg::{Quiet, data, generator, predictor, synth};
use serde_json::{Value, json};
use tower::ServiceExt;

use super::*;

const TINY_CONFIG: &str = include_str!("../../scbg/tests/tiny_train.toml");

/// A tiny trained generator and its synthetic data, built once for all tests.
fn fixture() -> &'static (tempfile::TempDir, Vec<u8>, scbg::synth::GroundTruth) {
    static FIXTURE: OnceLock<(tempfile::TempDir, Vec<u8>, scbg::synth::GroundTruth)> =
        OnceLock::new();
    FIXTURE.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let p = |s: &str| dir.path().join(s);
        synth::write_synthetic(
            &synth::SynthOptions {
                scenarios: 12,
                seed: 3,
                out: p("data"),
                families: Family::ALL.to_vec(),
                scenarios_per_file: 12,
                counterfactuals: 0,
            },
            &Quiet,
        )
        .unwrap();
        data::prepare(
            &data::PrepareOptions::new(vec![p("data").display().to_string()], p("cache")),
            &Quiet,
        )
        .unwrap();
        let config = predictor::TrainConfig::from_toml(TINY_CONFIG).unwrap();
        predictor::train_predictor(&p("cache"), &p("model"), &config, false, &Quiet).unwrap();
        let options =
            scbg::labels::label_options(2, Reward::AverageSpeed, MarginalEstimate::default(), 1.0)
                .unwrap();
        let predictors = generator::load_predictors(&p("model")).unwrap();
        let examples = generator::examples_for_split(
            &predictors.plain,
            &predictors.ckpt,
            &predictors.plain_device,
            &p("cache"),
            None,
            options,
            0,
            false,
            &Quiet,
        )
        .unwrap();
        generator::train_variant(
            &predictors,
            &examples,
            &generator::VariantSettings {
                epochs: 1,
                batch_size: 8,
                // Enough for a range on the labels' scale: the generator reads ψ clamped to
                // ±20 label spreads, and a range 5 steps from its initial weights puts both ends
                // of the slider beyond that (the viewer test then sees no change).
                range_steps: 100,
                ..generator::VariantSettings::new(Variant::Full, options)
            },
            &p("gen"),
            &Quiet,
        )
        .unwrap();
        let bytes = std::fs::read(p("data/synth-00000.tfrecord")).unwrap();
        let truth = synth::read_ground_truth(&p("data").join(synth::GROUND_TRUTH_FILE)).unwrap();
        (dir, bytes, truth[0].clone())
    })
}

fn state(token: Option<&str>, max_body_bytes: usize) -> Arc<AppState> {
    let (dir, _, _) = fixture();
    let model = generator::load_scbg(&dir.path().join("gen"), None).unwrap();
    AppState::new(
        model,
        ServeConfig {
            token: token.map(str::to_string),
            data_dir: Some(dir.path().join("data")),
            max_body_bytes,
            workers: 2,
            ..ServeConfig::default()
        },
    )
    .unwrap()
}

async fn call(
    app: &axum::Router,
    method: &str,
    uri: &str,
    body: Body,
    content_type: &str,
    token: Option<&str>,
) -> (StatusCode, Value) {
    let mut req = Request::builder()
        .method(method)
        .uri(uri)
        .header("content-type", content_type);
    if let Some(t) = token {
        req = req.header("authorization", format!("Bearer {t}"));
    }
    let resp = app.clone().oneshot(req.body(body).unwrap()).await.unwrap();
    let status = resp.status();
    let bytes = resp.into_body().collect().await.unwrap().to_bytes();
    let value = serde_json::from_slice(&bytes)
        .unwrap_or(Value::String(String::from_utf8_lossy(&bytes).into_owned()));
    (status, value)
}

async fn json_call(
    app: &axum::Router,
    method: &str,
    uri: &str,
    body: Value,
) -> (StatusCode, Value) {
    call(
        app,
        method,
        uri,
        Body::from(body.to_string()),
        "application/json",
        None,
    )
    .await
}

async fn uploaded(app: &axum::Router) -> String {
    let (_, bytes, truth) = fixture();
    let (status, v) = call(
        app,
        "POST",
        "/v1/scenarios",
        Body::from(bytes.clone()),
        "application/octet-stream",
        None,
    )
    .await;
    assert_eq!(status, StatusCode::OK, "{v}");
    assert_eq!(v["scenarios"].as_array().unwrap().len(), 12);
    truth.scenario_id.clone()
}

/// A 4xx whose JSON error contains `needle`.
fn assert_error(status: StatusCode, v: &Value, want: StatusCode, needle: &str) {
    assert_eq!(status, want, "{v}");
    let msg = v["error"]
        .as_str()
        .unwrap_or_else(|| panic!("not a JSON error: {v}"));
    assert!(msg.contains(needle), "{msg:?} lacks {needle:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn generate_courtesy_and_descriptions() {
    let app = router(state(None, 16 << 20));
    let (_, _, t) = fixture();
    let sid = uploaded(&app).await;
    let (status, v) = json_call(
        &app,
        "POST",
        "/v1/generate",
        json!({"scenario_id": sid, "a": t.a_id, "b": t.b_id, "quantile": 0.8}),
    )
    .await;
    assert_eq!(status, StatusCode::OK, "{v}");
    let future = v["world_xy_m"].as_array().unwrap();
    assert_eq!(future.len(), 80);
    // The courtesy endpoint scores the generated future as generate's J_φ did.
    let (status, c) = json_call(
        &app,
        "POST",
        "/v1/courtesy",
        json!({"scenario_id": sid, "a": t.a_id, "b": t.b_id, "future_xy_m": future}),
    )
    .await;
    assert_eq!(status, StatusCode::OK, "{c}");
    let (psi, achieved) = (
        c["psi"].as_f64().unwrap(),
        v["achieved_psi"].as_f64().unwrap(),
    );
    assert!((psi - achieved).abs() < 1e-3, "{psi} vs {achieved}");

    let (status, health) = json_call(&app, "GET", "/healthz", Value::Null).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(health["status"], "ok");
    assert_eq!(health["audience"], "pair");
    assert_eq!(health["policy"], "generator");
    let (status, doc) = json_call(&app, "GET", "/openapi.json", Value::Null).await;
    assert_eq!(status, StatusCode::OK);
    assert!(doc["openapi"].as_str().unwrap().starts_with("3.1"));
    for path in [
        "/v1/generate",
        "/v1/courtesy",
        "/v1/scenarios",
        "/v1/scenarios/open",
        "/v1/sessions",
        "/v1/sessions/{id}/step",
        "/v1/sessions/{id}",
        "/healthz",
    ] {
        assert!(doc["paths"].get(path).is_some(), "{path} missing");
    }
    let (status, page) = call(&app, "GET", "/docs", Body::empty(), "text/html", None).await;
    assert_eq!(status, StatusCode::OK);
    assert!(page.as_str().unwrap().contains("/openapi.json"));
    let (status, metrics) = call(&app, "GET", "/metrics", Body::empty(), "text/plain", None).await;
    assert_eq!(status, StatusCode::OK);
    let text = metrics.as_str().unwrap();
    assert!(
        text.contains("scbg_requests_total{route=\"/v1/generate\",status=\"200\"} 1"),
        "{text}"
    );
    assert!(text.contains("scbg_scenarios 12"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_inputs_are_4xx_json_errors() {
    let app = router(state(None, 256 << 10));
    let (_, _, t) = fixture();
    let sid = uploaded_small(&app).await;
    let gen_body = |extra: Value| {
        let mut b = json!({"scenario_id": sid, "a": t.a_id, "b": t.b_id});
        for (k, v) in extra.as_object().unwrap() {
            b[k] = v.clone();
        }
        b
    };
    let cases: Vec<(Body, StatusCode, &str)> = vec![
        (Body::from("{not json"), StatusCode::BAD_REQUEST, "JSON"),
        (
            Body::from(
                json!({"scenario_id": sid, "a": "one", "b": t.b_id, "quantile": 0.5}).to_string(),
            ),
            StatusCode::UNPROCESSABLE_ENTITY,
            "a",
        ),
        (
            Body::from(json!({"scenario_id": sid, "b": t.b_id, "quantile": 0.5}).to_string()),
            StatusCode::UNPROCESSABLE_ENTITY,
            "missing field `a`",
        ),
        (
            Body::from(json!({"scenario_id": "nope", "a": 1, "b": 2, "quantile": 0.5}).to_string()),
            StatusCode::NOT_FOUND,
            "no scenario \"nope\"",
        ),
        (
            Body::from(gen_body(json!({"b": 987654, "quantile": 0.5})).to_string()),
            StatusCode::BAD_REQUEST,
            "987654",
        ),
        (
            Body::from(gen_body(json!({"quantile": 1.5})).to_string()),
            StatusCode::BAD_REQUEST,
            "quantile 1.5",
        ),
        (
            Body::from(gen_body(json!({"quantile": 0.5, "psi": 0.1})).to_string()),
            StatusCode::BAD_REQUEST,
            "not both",
        ),
        (
            Body::from(gen_body(json!({"quantile": 0.5, "extra": 1})).to_string()),
            StatusCode::UNPROCESSABLE_ENTITY,
            "unknown field",
        ),
        (
            Body::from(vec![b' '; 300 << 10]),
            StatusCode::PAYLOAD_TOO_LARGE,
            "",
        ),
    ];
    for (body, want, needle) in cases {
        let (status, v) = call(&app, "POST", "/v1/generate", body, "application/json", None).await;
        assert_error(status, &v, want, needle);
    }
    // Wrong content type, wrong route, wrong method.
    let (status, v) = call(
        &app,
        "POST",
        "/v1/generate",
        Body::from("{}"),
        "text/plain",
        None,
    )
    .await;
    assert_error(
        status,
        &v,
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "Content-Type",
    );
    let (status, v) = json_call(&app, "POST", "/v1/nothing", json!({})).await;
    assert_error(status, &v, StatusCode::NOT_FOUND, "no such route");
    let (status, v) = json_call(&app, "GET", "/v1/generate", Value::Null).await;
    assert_error(status, &v, StatusCode::METHOD_NOT_ALLOWED, "method");
    // Garbage upload; a courtesy future of the wrong length.
    let (status, v) = call(
        &app,
        "POST",
        "/v1/scenarios",
        Body::from(vec![7u8; 100]),
        "application/octet-stream",
        None,
    )
    .await;
    assert_error(
        status,
        &v,
        StatusCode::BAD_REQUEST,
        "neither a WOMD TFRecord",
    );
    let (status, v) = json_call(
        &app,
        "POST",
        "/v1/courtesy",
        json!({"scenario_id": sid, "a": t.a_id, "b": t.b_id, "future_xy_m": [[0.0, 0.0]]}),
    )
    .await;
    assert_error(status, &v, StatusCode::BAD_REQUEST, "1 points, expected 80");
    // The data folder's fence, a symlink that leads out of it included.
    let (dir, _, _) = fixture();
    let escape = dir.path().join("data/escape.tfrecord");
    if !escape.exists() {
        std::os::unix::fs::symlink("/etc/hostname", &escape).unwrap();
    }
    let (status, files) = json_call(&app, "GET", "/v1/files", Value::Null).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(
        files["files"],
        json!(["synth-00000.tfrecord"]),
        "the link is not listed"
    );
    for (file, want) in [
        ("escape.tfrecord", StatusCode::FORBIDDEN),
        ("../data/synth-00000.tfrecord", StatusCode::FORBIDDEN),
        ("/etc/passwd", StatusCode::FORBIDDEN),
        ("missing.tfrecord", StatusCode::NOT_FOUND),
    ] {
        let (status, v) =
            json_call(&app, "POST", "/v1/scenarios/open", json!({"file": file})).await;
        assert_error(status, &v, want, "file");
    }
    let (status, v) = json_call(
        &app,
        "POST",
        "/v1/scenarios/open",
        json!({"file": "synth-00000.tfrecord", "scenario_id": t.scenario_id}),
    )
    .await;
    assert_eq!(status, StatusCode::OK, "{v}");
    assert_eq!(v["scenarios"].as_array().unwrap().len(), 1);
}

/// Uploads only the first scenario (as a bare Scenario message), for a small body limit.
async fn uploaded_small(app: &axum::Router) -> String {
    let (dir, _, truth) = fixture();
    let scenes = scbg::data::read_scenes(&dir.path().join("data/synth-00000.tfrecord")).unwrap();
    let file = dir.path().join("one.tfrecord");
    scbg::sim::write_scenarios(&file, &scenes[..1]).unwrap();
    let (status, v) = call(
        app,
        "POST",
        "/v1/scenarios",
        Body::from(std::fs::read(&file).unwrap()),
        "application/octet-stream",
        None,
    )
    .await;
    assert_eq!(status, StatusCode::OK, "{v}");
    assert_eq!(v["scenarios"][0]["scenario_id"], truth.scenario_id.as_str());
    truth.scenario_id.clone()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tokens_are_checked() {
    let app = router(state(Some("s3cret"), 16 << 20));
    let (status, v) = call(
        &app,
        "POST",
        "/v1/generate",
        Body::from("{}"),
        "application/json",
        None,
    )
    .await;
    assert_error(status, &v, StatusCode::UNAUTHORIZED, "bearer token");
    let (status, v) = call(
        &app,
        "POST",
        "/v1/generate",
        Body::from("{}"),
        "application/json",
        Some("wrong"),
    )
    .await;
    assert_error(status, &v, StatusCode::UNAUTHORIZED, "bearer token");
    let (status, v) = call(
        &app,
        "POST",
        "/v1/generate",
        Body::from("{}"),
        "application/json",
        Some("s3cret"),
    )
    .await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{v}");
    let (status, _) = call(&app, "GET", "/healthz", Body::empty(), "", None).await;
    assert_eq!(status, StatusCode::OK);
    // Off loopback without a token is refused at start.
    let open = ServeConfig {
        addr: "0.0.0.0:8080".parse().unwrap(),
        ..ServeConfig::default()
    };
    assert!(
        open.check()
            .unwrap_err()
            .to_string()
            .contains("bearer token")
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn closed_loop_sessions() {
    let app = router(state(None, 16 << 20));
    let (dir, _, t) = fixture();
    let sid = uploaded(&app).await;
    let log = scbg::data::read_scenes(&dir.path().join("data/synth-00000.tfrecord"))
        .unwrap()
        .into_iter()
        .find(|s| s.scenario_id == sid)
        .unwrap();
    let ia = log.track_index(t.a_id).unwrap();
    let (status, v) = json_call(
        &app,
        "POST",
        "/v1/sessions",
        json!({"scenario_id": sid, "ego": t.a_id, "controlled": [{"id": t.b_id, "quantile": 0.9}]}),
    )
    .await;
    assert_eq!(status, StatusCode::OK, "{v}");
    let id = v["session_id"].as_str().unwrap().to_string();
    assert_eq!(v["step"], 10);
    let step_uri = format!("/v1/sessions/{id}/step");
    // The ego is driven from outside: a step without its state is refused, nothing moves.
    let (status, e) = json_call(&app, "POST", &step_uri, json!({})).await;
    assert_error(status, &e, StatusCode::BAD_REQUEST, "ego");
    for step in 11..=15 {
        let s = &log.tracks[ia].states[step];
        let (status, v) = json_call(
            &app,
            "POST",
            &step_uri,
            json!({"ego": {"x_m": s.x_m, "y_m": s.y_m, "heading_rad": s.heading_rad,
                           "velocity_x_mps": s.velocity_x_mps, "velocity_y_mps": s.velocity_y_mps}}),
        )
        .await;
        assert_eq!(status, StatusCode::OK, "{v}");
        assert_eq!(v["step"], step);
        let ego = v["agents"]
            .as_array()
            .unwrap()
            .iter()
            .find(|a| a["id"] == t.a_id)
            .unwrap();
        assert!((ego["x_m"].as_f64().unwrap() - s.x_m).abs() < 1e-9);
    }
    // Bad session requests.
    for (body, want, needle) in [
        (
            json!({"scenario_id": sid, "controlled": [{"id": 4242, "quantile": 0.5}]}),
            StatusCode::BAD_REQUEST,
            "no agent with id 4242",
        ),
        (
            json!({"scenario_id": sid, "controlled": [{"id": t.b_id, "quantile": 2.0}]}),
            StatusCode::BAD_REQUEST,
            "quantile 2",
        ),
        (
            json!({"scenario_id": sid, "controlled": [{"id": t.b_id, "quantile": 0.5}], "ego_mode": "flying"}),
            StatusCode::BAD_REQUEST,
            "ego_mode",
        ),
        (
            json!({"scenario_id": sid, "controlled": [{"id": t.b_id}]}),
            StatusCode::BAD_REQUEST,
            "quantile",
        ),
    ] {
        let (status, v) = json_call(&app, "POST", "/v1/sessions", body).await;
        assert_error(status, &v, want, needle);
    }
    let (status, v) = json_call(&app, "DELETE", &format!("/v1/sessions/{id}"), Value::Null).await;
    assert_eq!(status, StatusCode::NO_CONTENT, "{v}");
    let (status, v) = json_call(&app, "POST", &step_uri, json!({})).await;
    assert_error(status, &v, StatusCode::NOT_FOUND, "no session");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tcp_server_finishes_in_flight_requests_on_shutdown() {
    use http_body_util::Full;
    use hyper::body::Bytes;
    use hyper_util::client::legacy::Client;
    use hyper_util::rt::TokioExecutor;
    let (_, bytes, t) = fixture();
    let st = state(None, 16 << 20);
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let held = st.clone();
    let server = tokio::spawn(serve(st, listener, async move {
        let _ = stop_rx.await;
    }));
    let client: Client<_, Full<Bytes>> = Client::builder(TokioExecutor::new()).build_http();
    let post = |path: &str, ct: &'static str, body: Vec<u8>| {
        hyper::Request::post(format!("http://{addr}{path}"))
            .header("content-type", ct)
            .body(Full::new(Bytes::from(body)))
            .unwrap()
    };
    let up = client
        .request(post(
            "/v1/scenarios",
            "application/octet-stream",
            bytes.clone(),
        ))
        .await
        .unwrap();
    assert!(up.status().is_success());
    // Several generate requests in flight (every worker held, so they wait inside the
    // server), then shutdown, then the workers free: every one is answered.
    let permits = held.workers.clone().acquire_many_owned(2).await.unwrap();
    let mut pending = Vec::new();
    for q in [0.1, 0.3, 0.5, 0.7, 0.9] {
        let body = json!({"scenario_id": t.scenario_id, "a": t.a_id, "b": t.b_id, "quantile": q});
        pending.push(tokio::spawn(client.request(post(
            "/v1/generate",
            "application/json",
            body.to_string().into_bytes(),
        ))));
    }
    while held
        .metrics
        .in_flight
        .load(std::sync::atomic::Ordering::Relaxed)
        < 5
    {
        tokio::time::sleep(std::time::Duration::from_millis(1)).await;
    }
    stop_tx.send(()).unwrap();
    tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    drop(permits);
    for p in pending {
        let r = p.await.unwrap().unwrap();
        assert_eq!(r.status(), StatusCode::OK);
    }
    server.await.unwrap().unwrap();
    assert!(
        tokio::net::TcpStream::connect(addr).await.is_err(),
        "still listening"
    );
}

#[test]
fn scenario_paths_are_checked_before_reading() {
    // The fence does not depend on the file existing: `..` is refused outright.
    let rel = Path::new("a/../../b");
    assert!(
        rel.components()
            .any(|c| !matches!(c, std::path::Component::Normal(_)))
    );
}

/// The browser to drive (`SCBG_CHROMIUM`, else chromium on the PATH); `None` prints why. Under
/// CI (`CI` set) a missing browser is a failure, never a silent pass.
fn chromium() -> Option<std::path::PathBuf> {
    if let Some(p) = std::env::var_os("SCBG_CHROMIUM") {
        return Some(p.into());
    }
    for name in ["chromium", "chromium-browser", "google-chrome"] {
        if let Ok(out) = std::process::Command::new("which").arg(name).output()
            && out.status.success()
        {
            let path = String::from_utf8_lossy(&out.stdout).trim().to_string();
            if !path.is_empty() {
                return Some(path.into());
            }
        }
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "no chromium in CI (.ci/run installs Debian's chromium; or set SCBG_CHROMIUM)"
    );
    eprintln!("SKIPPED: no chromium found (install Debian's chromium or set SCBG_CHROMIUM)");
    None
}

/// The web viewer in a real headless browser: the page loads a scenario from the data folder,
/// the slider moves from 0.1 to 0.9 and the drawn trajectory changes, and a closed-loop
/// session plays three steps.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn viewer_in_a_headless_browser() {
    let Some(browser) = chromium() else {
        return;
    };
    let st = state(None, 16 << 20);
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(serve(st, listener, async move {
        let _ = stop_rx.await;
    }));
    let profile = tempfile::tempdir().unwrap();
    let url = format!("http://{addr}/?selftest=1");
    let out = tokio::task::spawn_blocking(move || {
        std::process::Command::new(browser)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-dev-shm-usage",
                "--window-size=1200,800",
                "--virtual-time-budget=20000",
                &format!("--user-data-dir={}", profile.path().display()),
                "--dump-dom",
                &url,
            ])
            .output()
            .unwrap()
    })
    .await
    .unwrap();
    stop_tx.send(()).unwrap();
    server.await.unwrap().unwrap();
    let dom = String::from_utf8_lossy(&out.stdout);
    assert!(
        dom.contains("data-result=\"changed\""),
        "the viewer's self-test did not see the trajectory change:\n{}\nstderr: {}",
        dom.lines()
            .filter(|l| l.contains("selftest") || l.contains("error"))
            .collect::<Vec<_>>()
            .join("\n"),
        String::from_utf8_lossy(&out.stderr)
            .lines()
            .take(20)
            .collect::<Vec<_>>()
            .join("\n")
    );
    assert!(
        dom.contains("data-steps=\"13\""),
        "the closed loop did not step"
    );
}
