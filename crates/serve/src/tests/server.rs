//! Closed-loop sessions, a real TCP server that shuts down gracefully, the data folder's fence,
//! and the web viewer in a headless browser.

use super::*;

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
    let (taken_tx, taken_rx) = tokio::sync::oneshot::channel::<()>();
    let held = st.clone();
    let server = tokio::spawn(serve(st, listener, async move {
        let _ = stop_rx.await;
        let _ = taken_tx.send(());
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
    // Shutdown begins while all five still wait for a worker: the server has taken the
    // signal (its shutdown future resolved) and closed its listener; only then are the
    // workers freed.
    stop_tx.send(()).unwrap();
    taken_rx.await.unwrap();
    while tokio::net::TcpStream::connect(addr).await.is_ok() {
        tokio::task::yield_now().await;
    }
    assert_eq!(
        held.metrics
            .in_flight
            .load(std::sync::atomic::Ordering::Relaxed),
        5
    );
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

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scenario_paths_are_checked_before_reading() {
    // The fence does not depend on the file existing: a path with `..` (or `.`) is refused
    // outright (403), even where it names no file or leads back into the data folder; only a
    // plain relative name that is missing is a 404.
    let app = router(state(None, 16 << 20));
    for file in [
        "a/../../b",
        "nothing/../synth-00000.tfrecord",
        "./synth-00000.tfrecord",
    ] {
        let (status, v) =
            json_call(&app, "POST", "/v1/scenarios/open", json!({"file": file})).await;
        assert_error(status, &v, StatusCode::FORBIDDEN, "without `..`");
    }
    let (status, v) = json_call(
        &app,
        "POST",
        "/v1/scenarios/open",
        json!({"file": "a/b.tfrecord"}),
    )
    .await;
    assert_error(status, &v, StatusCode::NOT_FOUND, "not in the data folder");
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
/// the slider moves from 0.1 to 0.9, the drawn trajectory changes and the A speed it shows
/// (E[r(Y_A) | x, ŷ_B]) rises, and a closed-loop session plays three steps.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn viewer_in_a_headless_browser() {
    let Some(browser) = chromium() else {
        return;
    };
    let st = release_state();
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
    // The speeds shown, as the page printed them (two decimals).
    let shown = |name: &str| -> f64 {
        let key = format!("data-{name}-speed=\"");
        let start = dom
            .find(&key)
            .unwrap_or_else(|| panic!("no {key} in the page"))
            + key.len();
        let len = dom[start..].find('"').unwrap();
        dom[start..start + len].parse().unwrap()
    };
    let (low, high) = (shown("low"), shown("high"));
    eprintln!("the viewer's A speed: {low} m/s at quantile 0.1, {high} m/s at 0.9");
    assert!(
        high > low,
        "A's expected speed shown at quantile 0.9 ({high}) is not above 0.1's ({low})"
    );
}

/// The connection cap answers 503, a client trickling its headers is cut, one trickling its
/// body gets a 408, and a client stuck mid-request does not hold up the shutdown for longer
/// than its grace.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hostile_clients_are_bounded() {
    use std::time::{Duration, Instant};
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let model = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/courtesy");
    let model = scbg::Model::load(&model, &scbg::LoadOptions::default()).unwrap();
    let st = AppState::new(
        model,
        ServeConfig {
            workers: 1,
            max_connections: 1,
            header_timeout: Duration::from_millis(300),
            request_timeout: Duration::from_millis(200),
            shutdown_grace: Duration::from_secs(1),
            ..ServeConfig::default()
        },
    )
    .unwrap();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let held = st.clone();
    let server = tokio::spawn(serve(st, listener, async move {
        let _ = stop_rx.await;
    }));
    // Reads whatever comes until the server closes (or 3 s pass).
    async fn answer(stream: &mut tokio::net::TcpStream) -> (String, Duration) {
        let started = Instant::now();
        let mut out = Vec::new();
        let _ = tokio::time::timeout(Duration::from_secs(3), stream.read_to_end(&mut out)).await;
        (
            String::from_utf8_lossy(&out).into_owned(),
            started.elapsed(),
        )
    }
    // One slow client holds the only connection.
    let mut slow = tokio::net::TcpStream::connect(addr).await.unwrap();
    slow.write_all(b"GET /healthz HTTP/1.1\r\nho")
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(50)).await;
    let mut over = tokio::net::TcpStream::connect(addr).await.unwrap();
    let (text, _) = answer(&mut over).await;
    assert!(text.starts_with("HTTP/1.1 503"), "{text}");
    assert!(text.contains("too many connections"), "{text}");
    // The slow client is cut once its header time is up.
    let (text, waited) = answer(&mut slow).await;
    assert!(
        waited < Duration::from_secs(2),
        "cut after {waited:?}: {text:?}"
    );
    assert_eq!(
        held.metrics
            .refused_connections
            .load(std::sync::atomic::Ordering::Relaxed),
        1
    );
    // Its connection is free again; a body that never completes gets a 408.
    let mut trickle = tokio::net::TcpStream::connect(addr).await.unwrap();
    trickle
        .write_all(b"POST /v1/generate HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\ncontent-length: 100\r\n\r\n{\"scen")
        .await
        .unwrap();
    let (text, waited) = answer(&mut trickle).await;
    assert!(text.starts_with("HTTP/1.1 408"), "{text}");
    assert!(waited < Duration::from_secs(2), "{waited:?}");
    // A client stuck mid-body at shutdown: the server still returns, within its grace.
    let mut stuck = tokio::net::TcpStream::connect(addr).await.unwrap();
    stuck
        .write_all(b"POST /v1/generate HTTP/1.1\r\nhost: x\r\ncontent-length: 100\r\n\r\n{")
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(50)).await;
    let stopping = Instant::now();
    stop_tx.send(()).unwrap();
    server.await.unwrap().unwrap();
    assert!(
        stopping.elapsed() < Duration::from_secs(2),
        "{:?}",
        stopping.elapsed()
    );
}
