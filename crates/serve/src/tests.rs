//! The API end to end on a tiny trained model: happy paths, every bad input the API rejects as
//! a 4xx JSON error, the token, the data folder's fence, sessions, a real TCP server that shuts
//! down gracefully.

use std::sync::{Arc, OnceLock};

use axum::body::Body;
use axum::http::{Request, StatusCode};
use http_body_util::BodyExt;
use scbg::Quiet;
use scbg::choices::{Family, MarginalEstimate, Reward, Variant};
use scbg_lab::{generator, predictor, synth};
use serde_json::{Value, json};
use tower::ServiceExt;

use super::*;

mod inputs;
mod server;

const TINY_CONFIG: &str = include_str!("../../lab/tests/tiny_train.toml");

/// A tiny trained generator and its synthetic data, built once for all tests.
fn fixture() -> &'static (tempfile::TempDir, Vec<u8>, scbg_lab::synth::GroundTruth) {
    static FIXTURE: OnceLock<(tempfile::TempDir, Vec<u8>, scbg_lab::synth::GroundTruth)> =
        OnceLock::new();
    FIXTURE.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let p = |s: &str| dir.path().join(s);
        synth::write_synthetic(
            &synth::SynthOptions {
                scenarios: 12,
                seed: 3,
                out: p("data"),
                families: Family::DEFAULT.to_vec(),
                held_out: Vec::new(),
                scenarios_per_file: 12,
                counterfactuals: 0,
            },
            &Quiet,
        )
        .unwrap();
        scbg_lab::prepare::prepare(
            &scbg_lab::prepare::PrepareOptions::new(
                vec![p("data").display().to_string()],
                p("cache"),
            ),
            &Quiet,
        )
        .unwrap();
        let config = predictor::TrainConfig::from_toml(TINY_CONFIG).unwrap();
        predictor::train_predictor(&p("cache"), &p("model"), &config, false, &Quiet).unwrap();
        let options =
            scbg_lab::labels::label_options(2, Reward::AverageSpeed, MarginalEstimate::default());
        let predictors = generator::load_predictors(&p("model")).unwrap();
        let examples = generator::examples_for_split(
            &predictors.plain,
            &predictors.ckpt,
            &predictors.plain_device,
            &p("cache"),
            None,
            options,
            0,
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
    state_of(&dir.path().join("gen"), token, max_body_bytes)
}

/// The server of the repository's release model (`models/courtesy`) on the fixture's data:
/// for a test of which way the knob moves A, which a tiny model does not decide.
fn release_state() -> Arc<AppState> {
    let model = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/courtesy");
    state_of(&model, None, 16 << 20)
}

fn state_of(model: &std::path::Path, token: Option<&str>, max_body_bytes: usize) -> Arc<AppState> {
    let (dir, _, _) = fixture();
    let model = scbg::Model::load(model, &scbg::LoadOptions::default()).unwrap();
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
    assert_eq!(health["members"], 1);
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
    // The reference documents every route the OpenAPI description holds.
    let reference = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/reference.md"),
    )
    .unwrap();
    for path in doc["paths"].as_object().unwrap().keys() {
        assert!(
            reference.contains(&format!("`{path}`")) || reference.contains(&format!(" {path}`")),
            "docs/reference.md does not document {path}"
        );
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
