//! `scbg bench soak`: the server under a long mixed load and hostile clients, on loopback, in
//! this process. In order:
//!
//! 1. **the mix**: `rate` requests per second for `seconds`, open-loop: generate, courtesy,
//!    session create / step / close, scenario upload, healthz, and ~10 % malformed requests
//!    (bad JSON, wrong types, out-of-range ψ and quantiles, unknown scenarios and sessions,
//!    wrong content type, unknown routes, garbage uploads); healthz is probed every 0.5 s and
//!    resident memory sampled every second;
//! 2. **a burst**: `connections` TCP connections opened at once, each asking `/healthz`;
//! 3. **hostile bodies and disconnects**: oversized bodies (413), JSON nested 100,000 deep
//!    (4xx), clients that close mid-body and before their answer;
//! 4. **slow clients**: half trickle their headers a byte at a time (the server disconnects
//!    them), half their body (408), while the server keeps answering others;
//! 5. **idle sessions** left open in the mix must be reclaimed within their time to live;
//! 6. **a graceful shutdown**, timed.
//!
//! Client and server share the process, so the memory figures include the client's.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use http_body_util::{BodyExt, Full};
use hyper::body::Bytes;
use hyper_util::client::legacy::Client;
use hyper_util::client::legacy::connect::HttpConnector;
use hyper_util::rt::TokioExecutor;
use rand::{Rng, SeedableRng};
use scbg::Model;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

use crate::{AppState, ServeConfig};

mod report;
pub use report::{KindCounts, SoakReport};

/// What to run.
#[derive(Debug, Clone)]
pub struct SoakOptions {
    /// Requests per second of the mix.
    pub rate: f64,
    /// Seconds of the mix.
    pub seconds: f64,
    /// Inference workers of the server.
    pub workers: usize,
    /// Connections of the burst.
    pub connections: usize,
    /// Slow clients.
    pub slow_clients: usize,
    /// Seeds the mix.
    pub seed: u64,
}

type HttpClient = Client<HttpConnector, Full<Bytes>>;

/// Status, latency and body of one request; `None` status (and the error) for a transport
/// error.
async fn send(
    client: &HttpClient,
    method: &str,
    uri: String,
    content_type: &str,
    body: Vec<u8>,
) -> (Option<u16>, f64, Result<Bytes, String>) {
    let request = hyper::Request::builder()
        .method(method)
        .uri(uri)
        .header("content-type", content_type)
        .body(Full::new(Bytes::from(body)))
        .expect("a valid request");
    let started = Instant::now();
    match client.request(request).await {
        Ok(r) => {
            let status = r.status().as_u16();
            let body = r.into_body().collect().await.map(|b| b.to_bytes());
            let ms = started.elapsed().as_secs_f64() * 1e3;
            match body {
                Ok(b) => (Some(status), ms, Ok(b)),
                Err(e) => (None, ms, Err(format!("reading the answer: {e}"))),
            }
        }
        Err(e) => (
            None,
            started.elapsed().as_secs_f64() * 1e3,
            Err(format!("{e:?}")),
        ),
    }
}

/// Resident memory of this process now, MiB (0 where /proc is not there).
fn rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<f64>().ok())
        .map_or(0.0, |pages| pages * 4096.0 / (1 << 20) as f64)
}

/// One malformed request of the mix: (method, path, content type, body).
fn malformed(k: u64, scenario_id: &str) -> (&'static str, String, &'static str, Vec<u8>) {
    let json = "application/json";
    match k % 10 {
        0 => (
            "POST",
            "/v1/generate".into(),
            json,
            b"{\"scenario_id\": ".to_vec(),
        ),
        1 => (
            "POST",
            "/v1/generate".into(),
            json,
            format!(r#"{{"scenario_id":"{scenario_id}","a":"one","b":2,"quantile":0.5}}"#).into(),
        ),
        2 => (
            "POST",
            "/v1/generate".into(),
            json,
            format!(r#"{{"scenario_id":"{scenario_id}","a":1,"b":2,"psi":1e30}}"#).into(),
        ),
        3 => (
            "POST",
            "/v1/courtesy".into(),
            json,
            br#"{"scenario_id":"nope","a":1,"b":2,"future_xy_m":[[0,0]]}"#.to_vec(),
        ),
        4 => (
            "POST",
            "/v1/sessions".into(),
            json,
            format!(r#"{{"scenario_id":"{scenario_id}","controlled":[{{"id":2,"quantile":-1}}]}}"#)
                .into(),
        ),
        5 => (
            "POST",
            "/v1/generate".into(),
            "text/plain",
            b"quantile=0.5".to_vec(),
        ),
        6 => ("GET", "/v1/nothing/here".into(), json, Vec::new()),
        7 => (
            "POST",
            "/v1/sessions/no-such-session/step".into(),
            json,
            b"{}".to_vec(),
        ),
        8 => (
            "POST",
            "/v1/scenarios".into(),
            "application/octet-stream",
            (0..4096u32)
                .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
                .collect(),
        ),
        _ => (
            "DELETE",
            "/v1/sessions/no-such-session".into(),
            json,
            Vec::new(),
        ),
    }
}

/// Sends `request` over a raw connection and reads the status code of the answer.
async fn raw_status(addr: std::net::SocketAddr, request: &[u8]) -> Option<u16> {
    let mut stream = tokio::net::TcpStream::connect(addr).await.ok()?;
    stream.write_all(request).await.ok()?;
    let mut answer = Vec::new();
    tokio::time::timeout(Duration::from_secs(30), stream.read_to_end(&mut answer))
        .await
        .ok()?
        .ok()?;
    std::str::from_utf8(answer.get(9..12)?).ok()?.parse().ok()
}

/// Runs the soak against a server of `model` (sessions expire after 5 s so that the reclaim is
/// seen within the run).
pub fn soak(
    model: Model,
    scenario: Vec<u8>,
    (a, b): (i64, i64),
    options: &SoakOptions,
) -> anyhow::Result<SoakReport> {
    anyhow::ensure!(
        options.rate > 0.0 && options.seconds > 0.0,
        "rate and seconds must be positive"
    );
    let runtime = crate::runtime()?;
    let options = options.clone();
    runtime.block_on(async move {
        let config = ServeConfig {
            addr: std::net::SocketAddr::from(([127, 0, 0, 1], 0)),
            workers: options.workers,
            session_ttl: Duration::from_secs(5),
            header_timeout: Duration::from_secs(5),
            request_timeout: Duration::from_secs(5),
            max_connections: options.connections.max(1) * 2,
            ..ServeConfig::default()
        };
        let (header_timeout, grace, ttl) =
            (config.header_timeout, config.shutdown_grace, config.session_ttl);
        let request_limit = config.request_timeout + config.header_timeout;
        let listener = tokio::net::TcpListener::bind(config.addr).await?;
        let addr = listener.local_addr()?;
        let state = AppState::new(model, config)?;
        let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let server = tokio::spawn(crate::serve(state.clone(), listener, async move {
            let _ = stop_rx.await;
        }));
        // Idle pooled connections are dropped before the server's keep-alive limit (its header
        // timeout) closes them, as a well-behaved client does.
        let client: HttpClient = Client::builder(TokioExecutor::new())
            .pool_idle_timeout(header_timeout / 5)
            .build_http();
        let url = move |path: &str| format!("http://{addr}{path}");
        let (status, _, body) =
            send(&client, "POST", url("/v1/scenarios"), "application/octet-stream", scenario.clone())
                .await;
        anyhow::ensure!(status == Some(200), "upload failed: {status:?}");
        let uploaded: serde_json::Value =
            serde_json::from_slice(&body.map_err(anyhow::Error::msg)?)?;
        let scenario_id = uploaded["scenarios"][0]["scenario_id"]
            .as_str()
            .unwrap_or_default()
            .to_string();

        // Healthz probes and memory samples until told to stop.
        let probing = Arc::new(std::sync::atomic::AtomicBool::new(true));
        let probes = {
            let (client, probing) = (client.clone(), probing.clone());
            tokio::spawn(async move {
                let (mut n, mut failed) = (0usize, 0usize);
                while probing.load(Ordering::Relaxed) {
                    let (status, ms, _) =
                        send(&client, "GET", url("/healthz"), "application/json", Vec::new()).await;
                    n += 1;
                    if status != Some(200) || ms > 1000.0 {
                        failed += 1;
                    }
                    tokio::time::sleep(Duration::from_millis(500)).await;
                }
                (n, failed)
            })
        };

        // 1. The mix.
        let counts: Arc<Mutex<BTreeMap<String, KindCounts>>> = Arc::default();
        let latencies: Arc<Mutex<BTreeMap<String, Vec<f64>>>> = Arc::default();
        let sessions: Arc<Mutex<Vec<String>>> = Arc::default();
        let opened = Arc::new(AtomicUsize::new(0));
        let rss: Arc<Mutex<Vec<(f64, f64)>>> = Arc::default();
        let total = (options.rate * options.seconds).round() as usize;
        let period = Duration::from_secs_f64(1.0 / options.rate);
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(options.seed);
        let started = Instant::now();
        let mut last_sample = started;
        // Requests not yet answered; finished tasks are not kept (a kept handle would keep
        // each task's memory, and the client would grow, not the server).
        let pending = Arc::new(AtomicUsize::new(0));
        let lost_why: Arc<Mutex<Vec<String>>> = Arc::default();
        for k in 0..total {
            tokio::time::sleep_until((started + period * k as u32).into()).await;
            if last_sample.elapsed() >= Duration::from_secs(1) {
                last_sample = Instant::now();
                rss.lock()
                    .expect("rss")
                    .push((started.elapsed().as_secs_f64(), rss_mib()));
            }
            let roll: f64 = rng.random();
            let q = 0.1 * f64::from(rng.random_range(1..10u8));
            let pick = |v: &Vec<String>, r: usize| v.get(r % v.len().max(1)).cloned();
            let r = rng.random_range(0..usize::MAX);
            let (kind, method, path, content_type, body): (&str, &str, String, &str, Vec<u8>) =
                if roll < 0.40 {
                    let body = serde_json::json!({"scenario_id": scenario_id, "a": a, "b": b, "quantile": q});
                    ("generate", "POST", "/v1/generate".into(), "application/json", body.to_string().into())
                } else if roll < 0.50 {
                    let future: Vec<[f64; 2]> = (1..=80).map(|t| [0.5 * f64::from(t), 0.0]).collect();
                    let body = serde_json::json!({"scenario_id": scenario_id, "a": a, "b": b, "future_xy_m": future});
                    ("courtesy", "POST", "/v1/courtesy".into(), "application/json", body.to_string().into())
                } else if roll < 0.56 {
                    let others = if r % 2 == 0 { "log" } else { "reactive" };
                    let body = serde_json::json!({"scenario_id": scenario_id, "ego": a, "ego_mode": "reactive", "others": others, "controlled": [{"id": b, "quantile": q}]});
                    ("session", "POST", "/v1/sessions".into(), "application/json", body.to_string().into())
                } else if roll < 0.72 {
                    match pick(&sessions.lock().expect("sessions"), r) {
                        Some(id) => ("step", "POST", format!("/v1/sessions/{id}/step"), "application/json", b"{}".to_vec()),
                        None => ("healthz", "GET", "/healthz".into(), "application/json", Vec::new()),
                    }
                } else if roll < 0.75 {
                    let id = {
                        let mut open = sessions.lock().expect("sessions");
                        let n = open.len();
                        (n > 0).then(|| open.swap_remove(r % n))
                    };
                    match id {
                        Some(id) => ("close", "DELETE", format!("/v1/sessions/{id}"), "application/json", Vec::new()),
                        None => ("healthz", "GET", "/healthz".into(), "application/json", Vec::new()),
                    }
                } else if roll < 0.77 {
                    ("upload", "POST", "/v1/scenarios".into(), "application/octet-stream", scenario.clone())
                } else if roll < 0.90 {
                    ("healthz", "GET", "/healthz".into(), "application/json", Vec::new())
                } else {
                    let (m, p, c, b) = malformed(k as u64, &scenario_id);
                    ("malformed", m, p, c, b)
                };
            let (client, counts, latencies, sessions, opened, pending, lost_why) = (
                client.clone(),
                counts.clone(),
                latencies.clone(),
                sessions.clone(),
                opened.clone(),
                pending.clone(),
                lost_why.clone(),
            );
            let (method, content_type) = (method.to_string(), content_type.to_string());
            pending.fetch_add(1, Ordering::Relaxed);
            tokio::spawn(async move {
                let (status, ms, answer) = send(&client, &method, url(&path), &content_type, body).await;
                if let (None, Err(why)) = (status, &answer) {
                    let mut lost = lost_why.lock().expect("lost");
                    if lost.len() < 5 {
                        lost.push(format!("{kind} {method} {path}: {why}"));
                    }
                }
                let answer = answer.unwrap_or_default();
                if status.is_some() {
                    latencies
                        .lock()
                        .expect("latencies")
                        .entry(kind.to_string())
                        .or_default()
                        .push(ms);
                }
                // A session that expired or finished is stepped no more.
                if kind == "step" && matches!(status, Some(400 | 404)) {
                    let id = path.trim_start_matches("/v1/sessions/").trim_end_matches("/step");
                    sessions.lock().expect("sessions").retain(|s| s != id);
                }
                if kind == "session" && status == Some(200) {
                    let v: serde_json::Value = serde_json::from_slice(&answer).unwrap_or_default();
                    if let Some(id) = v["session_id"].as_str() {
                        opened.fetch_add(1, Ordering::Relaxed);
                        sessions.lock().expect("sessions").push(id.to_string());
                    }
                }
                let mut counts = counts.lock().expect("counts");
                let c = counts.entry(kind.to_string()).or_default();
                c.sent += 1;
                match status {
                    None => c.transport_error += 1,
                    Some(200..=299) => c.ok += 1,
                    Some(400..=499) => c.client_error += 1,
                    Some(503) => c.unavailable += 1,
                    Some(_) => c.server_error += 1,
                }
                pending.fetch_sub(1, Ordering::Relaxed);
            });
        }
        let waiting = Instant::now();
        while pending.load(Ordering::Relaxed) > 0 && waiting.elapsed() < Duration::from_secs(120) {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        let mix_s = started.elapsed().as_secs_f64();
        let samples = rss.lock().expect("rss").clone();
        let mean = |v: Vec<f64>| v.iter().sum::<f64>() / v.len().max(1) as f64;
        let rss_first = mean(samples.iter().filter(|s| s.0 < mix_s / 2.0).map(|s| s.1).collect());
        let rss_second = mean(samples.iter().filter(|s| s.0 >= mix_s / 2.0).map(|s| s.1).collect());

        // 2. The burst.
        let burst: Vec<_> = (0..options.connections)
            .map(|_| {
                tokio::spawn(raw_status(
                    addr,
                    b"GET /healthz HTTP/1.1\r\nhost: scbg\r\nconnection: close\r\n\r\n",
                ))
            })
            .collect();
        let (mut burst_ok, mut burst_refused, mut burst_other) = (0, 0, 0);
        for t in burst {
            match t.await.ok().flatten() {
                Some(200) => burst_ok += 1,
                Some(503) => burst_refused += 1,
                _ => burst_other += 1,
            }
        }

        // 3. Hostile bodies: over the size limit (refused while being sent: a 413, or the
        // connection closed under the sender) and nested past any parser's depth.
        let mut hostile_ok = 0;
        let hostile = 20;
        for i in 0..hostile {
            let (path, body) = if i % 2 == 0 {
                ("/v1/scenarios", vec![0u8; 17 << 20])
            } else {
                let mut v = vec![b'['; 100_000];
                v.extend(vec![b']'; 100_000]);
                ("/v1/generate", v)
            };
            let (status, _, answer) =
                send(&client, "POST", url(path), "application/json", body).await;
            let refused = match (status, &answer) {
                (Some(400..=499), _) => true,
                (None, Err(why)) => why.contains("BodyWrite"),
                _ => false,
            };
            if refused {
                hostile_ok += 1;
            }
        }

        // Clients that leave: mid-body, and right after sending a whole request.
        let generate_body =
            serde_json::json!({"scenario_id": scenario_id, "a": a, "b": b, "quantile": 0.5})
                .to_string();
        let leavers = 100;
        for i in 0..leavers {
            if let Ok(mut stream) = tokio::net::TcpStream::connect(addr).await {
                let head = format!(
                    "POST /v1/generate HTTP/1.1\r\nhost: scbg\r\ncontent-type: application/json\r\ncontent-length: {}\r\n\r\n",
                    generate_body.len()
                );
                let cut = if i % 2 == 0 { generate_body.len() / 2 } else { generate_body.len() };
                let _ = stream.write_all(head.as_bytes()).await;
                let _ = stream.write_all(&generate_body.as_bytes()[..cut]).await;
                drop(stream);
            }
        }

        // 4. Slow clients: a byte every 200 ms, never finishing.
        let slow: Vec<_> = (0..options.slow_clients)
            .map(|i| {
                tokio::spawn(async move {
                    let Ok(mut stream) = tokio::net::TcpStream::connect(addr).await else {
                        return false;
                    };
                    let started = Instant::now();
                    let (limit, trickle): (Duration, &[u8]) = if i % 2 == 0 {
                        (header_timeout, b"GET /healthz HTTP/1.1\r\nx-slow: aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa")
                    } else {
                        let head = b"POST /v1/generate HTTP/1.1\r\nhost: scbg\r\ncontent-type: application/json\r\ncontent-length: 100000\r\n\r\n";
                        if stream.write_all(head).await.is_err() {
                            return false;
                        }
                        (request_limit, b"[[[[[[[[[[[[")
                    };
                    for byte in trickle.iter().cycle() {
                        if stream.write_all(&[*byte]).await.is_err() {
                            break;
                        }
                        // A closed connection shows as a read of 0 bytes or an error.
                        let mut buf = [0u8; 256];
                        let read = tokio::time::timeout(Duration::from_millis(200), stream.read(&mut buf));
                        if let Ok(Ok(0) | Err(_)) = read.await {
                            break;
                        }
                        if started.elapsed() > limit + Duration::from_secs(2) {
                            return false;
                        }
                    }
                    started.elapsed() <= limit + Duration::from_secs(2)
                })
            })
            .collect();
        let mut slow_cut = 0;
        for t in slow {
            if t.await.unwrap_or(false) {
                slow_cut += 1;
            }
        }

        // 5. Idle sessions: the ones the mix left open expire.
        tokio::time::sleep(ttl + Duration::from_secs(1)).await;
        let sessions_left = state.sessions.lock().expect("sessions lock").len();
        probing.store(false, Ordering::Relaxed);
        let (healthz_probes, healthz_failures) = probes.await.unwrap_or((0, 1));

        // 6. Shutdown.
        let stop = Instant::now();
        let _ = stop_tx.send(());
        let clean = tokio::time::timeout(grace + Duration::from_secs(1), server)
            .await
            .is_ok_and(|r| r.is_ok_and(|r| r.is_ok()));
        let shutdown_s = stop.elapsed().as_secs_f64();

        let pct = |l: &[f64], p: f64| {
            l.get(((p * l.len().saturating_sub(1) as f64).round()) as usize)
                .copied()
                .unwrap_or(f64::NAN)
        };
        let mut latency_ms = BTreeMap::new();
        for (kind, mut l) in latencies.lock().expect("latencies").clone() {
            l.sort_by(f64::total_cmp);
            latency_ms.insert(kind, [pct(&l, 0.5), pct(&l, 0.99)]);
        }
        let generate = latency_ms.get("generate").copied().unwrap_or([f64::NAN; 2]);
        Ok(SoakReport {
            rate_per_s: options.rate,
            seconds: options.seconds,
            workers: options.workers,
            mix: counts.lock().expect("counts").clone(),
            generate_p50_ms: generate[0],
            generate_p99_ms: generate[1],
            latency_ms,
            rss_samples_mib: samples,
            rss_first_half_mib: rss_first,
            rss_second_half_mib: rss_second,
            healthz_probes,
            healthz_failures,
            burst_connections: options.connections,
            burst_ok,
            burst_refused,
            burst_other,
            hostile_bodies: hostile,
            hostile_refused: hostile_ok,
            disconnecting_clients: leavers,
            slow_clients: options.slow_clients,
            slow_clients_cut: slow_cut,
            sessions_opened: opened.load(Ordering::Relaxed),
            sessions_left,
            lost: lost_why.lock().expect("lost").clone(),
            shutdown_s,
            shutdown_clean: clean,
        })
    })
}
