//! Every bad input as a 4xx JSON error, and the bearer token.

use super::*;

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
            Body::from(gen_body(json!({"psi": 1e30})).to_string()),
            StatusCode::BAD_REQUEST,
            "outside [-50, 50] m/s",
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
