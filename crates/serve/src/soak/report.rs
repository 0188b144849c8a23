//! The soak's report: what was measured, and the bars it is held to.

use std::collections::BTreeMap;

use serde::Serialize;

/// Answers of one kind of request in the mix.
#[derive(Debug, Clone, Default, Serialize)]
pub struct KindCounts {
    /// Sent.
    pub sent: usize,
    /// 2xx.
    pub ok: usize,
    /// 4xx.
    pub client_error: usize,
    /// 503 (the documented overload answer).
    pub unavailable: usize,
    /// Any other 5xx.
    pub server_error: usize,
    /// No answer (transport error).
    pub transport_error: usize,
}

/// What the soak measured.
#[derive(Debug, Clone, Serialize)]
pub struct SoakReport {
    /// Requests per second asked of the mix.
    pub rate_per_s: f64,
    /// Seconds of the mix.
    pub seconds: f64,
    /// Inference workers.
    pub workers: usize,
    /// The mix, by kind (`malformed` included).
    pub mix: BTreeMap<String, KindCounts>,
    /// Latency of the answered requests by kind, ms: [p50, p99].
    pub latency_ms: BTreeMap<String, [f64; 2]>,
    /// `POST /v1/generate` latency in the mix, ms.
    pub generate_p50_ms: f64,
    /// 99th percentile, ms.
    pub generate_p99_ms: f64,
    /// Resident memory every second of the mix: (seconds, MiB).
    pub rss_samples_mib: Vec<(f64, f64)>,
    /// Mean resident memory over the mix's first and second halves, MiB.
    pub rss_first_half_mib: f64,
    /// Second half.
    pub rss_second_half_mib: f64,
    /// Healthz probes during everything, and how many failed or took over 1 s.
    pub healthz_probes: usize,
    /// Failed probes.
    pub healthz_failures: usize,
    /// Burst: connections opened, answered 200, answered 503, anything else.
    pub burst_connections: usize,
    /// Answered 200.
    pub burst_ok: usize,
    /// Answered 503.
    pub burst_refused: usize,
    /// Neither.
    pub burst_other: usize,
    /// Oversized and deeply nested bodies sent, and how many were refused (4xx, or the
    /// connection closed while the oversized body was being sent).
    pub hostile_bodies: usize,
    /// Refused.
    pub hostile_refused: usize,
    /// Clients that disconnected mid-request.
    pub disconnecting_clients: usize,
    /// Slow clients (half trickling headers, half a body), and how many the server cut within
    /// its limit + 2 s (header timeout; whole-request deadline, with a 408).
    pub slow_clients: usize,
    /// Disconnected in time.
    pub slow_clients_cut: usize,
    /// Sessions opened in the mix, and those still open one time-to-live after it.
    pub sessions_opened: usize,
    /// Still open.
    pub sessions_left: usize,
    /// The first few unanswered requests and why.
    pub lost: Vec<String>,
    /// Seconds from the shutdown signal to the server's return; whether it returned.
    pub shutdown_s: f64,
    /// Returned within its grace.
    pub shutdown_clean: bool,
}

impl SoakReport {
    /// Each bar: (what, met).
    pub fn checks(&self) -> Vec<(String, bool)> {
        let server_errors: usize = self.mix.values().map(|k| k.server_error).sum();
        let lost: usize = self.mix.values().map(|k| k.transport_error).sum();
        let malformed_ok = self.mix.get("malformed").map_or(0, |k| k.ok);
        vec![
            (
                format!("no 5xx but documented 503s: {server_errors}"),
                server_errors == 0,
            ),
            (format!("no request unanswered: {lost}"), lost == 0),
            (
                format!("no malformed request accepted: {malformed_ok}"),
                malformed_ok == 0,
            ),
            (
                format!("generate p99 {:.1} ms ≤ 25 ms", self.generate_p99_ms),
                self.generate_p99_ms <= 25.0,
            ),
            (
                format!(
                    "memory flat: {:.0} → {:.0} MiB (≤ 1.1×)",
                    self.rss_first_half_mib, self.rss_second_half_mib
                ),
                self.rss_second_half_mib <= 1.1 * self.rss_first_half_mib,
            ),
            (
                format!(
                    "healthz answered throughout: {} of {} failed",
                    self.healthz_failures, self.healthz_probes
                ),
                self.healthz_failures == 0,
            ),
            (
                format!(
                    "burst of {}: {} ok, {} refused (503), {} other",
                    self.burst_connections, self.burst_ok, self.burst_refused, self.burst_other
                ),
                self.burst_other == 0,
            ),
            (
                format!(
                    "oversized and nested bodies refused: {} of {}",
                    self.hostile_refused, self.hostile_bodies
                ),
                self.hostile_refused == self.hostile_bodies,
            ),
            (
                format!(
                    "slow clients cut: {} of {}",
                    self.slow_clients_cut, self.slow_clients
                ),
                self.slow_clients_cut == self.slow_clients,
            ),
            (
                format!(
                    "idle sessions reclaimed: {} of {} left",
                    self.sessions_left, self.sessions_opened
                ),
                self.sessions_left == 0,
            ),
            (
                format!("graceful shutdown in {:.2} s", self.shutdown_s),
                self.shutdown_clean,
            ),
        ]
    }

    /// Whether every bar is met.
    pub fn passed(&self) -> bool {
        self.checks().iter().all(|(_, ok)| *ok)
    }

    /// Human-readable lines.
    pub fn to_text(&self) -> String {
        let mut s = format!(
            "scbg serve soak on loopback: {:.0} requests/s for {:.0} s, {} workers\n\
             kind          sent     2xx     4xx   503  other 5xx  lost    p50 ms   p99 ms\n",
            self.rate_per_s, self.seconds, self.workers
        );
        for (kind, k) in &self.mix {
            let [p50, p99] = self.latency_ms.get(kind).copied().unwrap_or([f64::NAN; 2]);
            s += &format!(
                "{kind:<12} {:>6}  {:>6}  {:>6}  {:>4}  {:>9}  {:>4}  {p50:>8.2} {p99:>8.2}\n",
                k.sent, k.ok, k.client_error, k.unavailable, k.server_error, k.transport_error
            );
        }
        s += &format!(
            "generate p50 {:.2} ms, p99 {:.2} ms\n",
            self.generate_p50_ms, self.generate_p99_ms
        );
        for why in &self.lost {
            s += &format!("unanswered: {why}\n");
        }
        for (what, ok) in self.checks() {
            s += &format!("[{}] {what}\n", if ok { "ok" } else { "FAIL" });
        }
        s
    }
}
