//! Prometheus text-format counters (`GET /metrics`): requests and their total time by route
//! and status, in-flight inference jobs, connections refused, scenarios and sessions held.

use std::collections::BTreeMap;
use std::sync::Mutex;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};

/// The server's counters.
#[derive(Debug, Default)]
pub struct Metrics {
    requests: Mutex<BTreeMap<(String, u16), (u64, f64)>>,
    /// Inference jobs running or waiting for a worker.
    pub in_flight: AtomicI64,
    /// Connections answered 503 because [`crate::ServeConfig::max_connections`] were open.
    pub refused_connections: AtomicU64,
}

impl Metrics {
    /// Counts one answered request.
    pub fn record(&self, route: &str, status: u16, seconds: f64) {
        let mut map = self.requests.lock().expect("metrics lock");
        let e = map.entry((route.to_string(), status)).or_insert((0, 0.0));
        e.0 += 1;
        e.1 += seconds;
    }

    /// The text exposition.
    pub fn render(&self, scenarios: usize, sessions: usize) -> String {
        let mut out = String::from(
            "# HELP scbg_requests_total Answered HTTP requests.\n# TYPE scbg_requests_total counter\n",
        );
        let map = self.requests.lock().expect("metrics lock");
        for ((route, status), (n, _)) in map.iter() {
            out += &format!("scbg_requests_total{{route=\"{route}\",status=\"{status}\"}} {n}\n");
        }
        out += "# HELP scbg_request_seconds_total Time spent answering, seconds.\n# TYPE scbg_request_seconds_total counter\n";
        for ((route, status), (_, s)) in map.iter() {
            out += &format!(
                "scbg_request_seconds_total{{route=\"{route}\",status=\"{status}\"}} {s:.6}\n"
            );
        }
        out += &format!(
            "# HELP scbg_inference_in_flight Inference jobs running or queued.\n# TYPE scbg_inference_in_flight gauge\nscbg_inference_in_flight {}\n\
             # HELP scbg_refused_connections_total Connections refused over the limit.\n# TYPE scbg_refused_connections_total counter\nscbg_refused_connections_total {}\n\
             # HELP scbg_scenarios Scenarios held.\n# TYPE scbg_scenarios gauge\nscbg_scenarios {scenarios}\n\
             # HELP scbg_sessions Open closed-loop sessions.\n# TYPE scbg_sessions gauge\nscbg_sessions {sessions}\n",
            self.in_flight.load(Ordering::Relaxed),
            self.refused_connections.load(Ordering::Relaxed)
        );
        out
    }
}
