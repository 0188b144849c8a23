//! `scbg bench serve`: a bounded loopback load test of `POST /v1/generate` — the server runs in
//! this process on 127.0.0.1 (an ephemeral port), requests go out open-loop at a fixed rate
//! over keep-alive HTTP/1.1 connections, and every latency is kept.

use std::sync::Arc;
use std::time::{Duration, Instant};

use http_body_util::{BodyExt, Full};
use hyper::body::Bytes;
use hyper_util::client::legacy::Client;
use hyper_util::rt::TokioExecutor;
use scbg::Model;
use serde::Serialize;

use crate::{AppState, ServeConfig};

/// What the load test measured.
#[derive(Debug, Clone, Serialize)]
pub struct LoadReport {
    /// Requests per second asked for.
    pub rate_per_s: f64,
    /// Seconds of load.
    pub seconds: f64,
    /// Requests sent.
    pub sent: usize,
    /// Answered 200.
    pub ok: usize,
    /// Anything else (status or transport).
    pub errors: usize,
    /// Latency percentiles of the answered requests, ms.
    pub p50_ms: f64,
    /// 99th percentile, ms.
    pub p99_ms: f64,
    /// Largest, ms.
    pub max_ms: f64,
    /// Peak resident memory of the process (server and client), MiB.
    pub peak_rss_mib: f64,
    /// Inference workers of the server.
    pub workers: usize,
}

impl LoadReport {
    /// Human-readable lines.
    pub fn to_text(&self) -> String {
        format!(
            "POST /v1/generate on loopback: {:.0} requests/s for {:.0} s, {} workers\n\
             sent {}, ok {}, errors {}\n\
             latency p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms (targets: p50 ≤ 5 ms, p99 ≤ 25 ms)\n\
             peak RSS {:.0} MiB\n",
            self.rate_per_s,
            self.seconds,
            self.workers,
            self.sent,
            self.ok,
            self.errors,
            self.p50_ms,
            self.p99_ms,
            self.max_ms,
            self.peak_rss_mib
        )
    }
}

/// Peak resident set of this process, MiB (0 where /proc is not there).
pub fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// Serves `model` on loopback, uploads `scenario` (WOMD bytes), and sends `generate` for the
/// pair (`a`, `b`) at `rate` per second for `seconds`, quantiles cycling 0.1…0.9.
pub fn load_test(
    model: Model,
    scenario: Vec<u8>,
    (a, b): (i64, i64),
    rate: f64,
    seconds: f64,
    workers: usize,
) -> anyhow::Result<LoadReport> {
    anyhow::ensure!(
        rate > 0.0 && seconds > 0.0,
        "rate and seconds must be positive"
    );
    let runtime = crate::runtime()?;
    runtime.block_on(async move {
        let config = ServeConfig {
            addr: std::net::SocketAddr::from(([127, 0, 0, 1], 0)),
            workers,
            ..ServeConfig::default()
        };
        let listener = tokio::net::TcpListener::bind(config.addr).await?;
        let addr = listener.local_addr()?;
        let state = AppState::new(model, config)?;
        let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let server = tokio::spawn(crate::serve(state, listener, async move {
            let _ = stop_rx.await;
        }));
        let client: Client<_, Full<Bytes>> = Client::builder(TokioExecutor::new()).build_http();
        let post = |path: &str, content_type: &'static str, body: Vec<u8>| {
            hyper::Request::post(format!("http://{addr}{path}"))
                .header("content-type", content_type)
                .body(Full::new(Bytes::from(body)))
                .expect("a valid request")
        };
        let up = client
            .request(post("/v1/scenarios", "application/octet-stream", scenario))
            .await?;
        let status = up.status();
        let body = up.into_body().collect().await?.to_bytes();
        anyhow::ensure!(
            status.is_success(),
            "upload failed: {status} {}",
            String::from_utf8_lossy(&body)
        );
        let uploaded: serde_json::Value = serde_json::from_slice(&body)?;
        let scenario_id = uploaded["scenarios"][0]["scenario_id"]
            .as_str()
            .unwrap_or_default()
            .to_string();
        // Warm-up (first-use allocations).
        for q in [0.1, 0.5, 0.9] {
            let body =
                serde_json::json!({"scenario_id": scenario_id, "a": a, "b": b, "quantile": q});
            let r = client
                .request(post(
                    "/v1/generate",
                    "application/json",
                    body.to_string().into_bytes(),
                ))
                .await?;
            let status = r.status();
            let text = r.into_body().collect().await?.to_bytes();
            anyhow::ensure!(
                status.is_success(),
                "generate failed: {status} {}",
                String::from_utf8_lossy(&text)
            );
        }
        let total = (rate * seconds).round() as usize;
        let period = Duration::from_secs_f64(1.0 / rate);
        let latencies = Arc::new(std::sync::Mutex::new(Vec::with_capacity(total)));
        let errors = Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let started = Instant::now();
        let mut tasks = Vec::with_capacity(total);
        for k in 0..total {
            let due = started + period * k as u32;
            tokio::time::sleep_until(due.into()).await;
            let q = 0.1 * (1 + k % 9) as f64;
            let body =
                serde_json::json!({"scenario_id": scenario_id, "a": a, "b": b, "quantile": q});
            let req = post(
                "/v1/generate",
                "application/json",
                body.to_string().into_bytes(),
            );
            let (client, latencies, errors) = (client.clone(), latencies.clone(), errors.clone());
            tasks.push(tokio::spawn(async move {
                let t = Instant::now();
                let ok = match client.request(req).await {
                    Ok(r) => {
                        let status = r.status();
                        r.into_body().collect().await.is_ok() && status.is_success()
                    }
                    Err(_) => false,
                };
                if ok {
                    latencies
                        .lock()
                        .expect("latencies")
                        .push(t.elapsed().as_secs_f64() * 1e3);
                } else {
                    errors.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
            }));
        }
        for t in tasks {
            let _ = t.await;
        }
        let _ = stop_tx.send(());
        let _ = server.await;
        let mut l = latencies.lock().expect("latencies").clone();
        l.sort_by(f64::total_cmp);
        let pct = |p: f64| {
            if l.is_empty() {
                f64::NAN
            } else {
                l[((p * (l.len() - 1) as f64).round() as usize).min(l.len() - 1)]
            }
        };
        Ok(LoadReport {
            rate_per_s: rate,
            seconds,
            sent: total,
            ok: l.len(),
            errors: errors.load(std::sync::atomic::Ordering::Relaxed),
            p50_ms: pct(0.5),
            p99_ms: pct(0.99),
            max_ms: l.last().copied().unwrap_or(f64::NAN),
            peak_rss_mib: peak_rss_mib(),
            workers,
        })
    })
}
