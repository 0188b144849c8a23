//! scbg: socially-controllable behavior generation for traffic simulation — the application
//! library.
//!
//! Every front end (the `scbg` command line, the HTTP server, the Python module, the
//! closed-loop simulator) calls this crate and nothing below it: it owns the artefacts (predictor
//! and generator folders, the label table), the pipelines (prepare, label, train, generate,
//! evaluate, the demo) and the reports, as plain Rust APIs with typed inputs and outputs.
//!
//! | module | what | paper |
//! |---|---|---|
//! | [`data`] | inspect, render, prepare WOMD files into the feature cache | — |
//! | [`synth`] | synthetic interactive scenarios + ground-truth sidecar | — |
//! | [`predictor`] | train / evaluate Multipath++ (marginal + conditional), external predictions | Sec. III-B, Table I |
//! | [`labels`] | courtesy labels ψ of every pair role (one labelling path), the Parquet label table | eq. (2), Sec. III-C, Fig. 3 |
//! | [`generator`] | generator + range predictor training, the generator artefact, loading | eq. (1), Sec. III-D |
//! | [`generate`] | B's world-frame future at a courtesy quantile or ψ | Sec. III-E |
//! | [`scbg_eval`] | CourtesyMSE, TrajADE, correlations, Figs. 4–5 | Table II, Figs. 4–5 |
//! | [`sim`] | closed-loop simulation with courtesy-controlled agents, WOSAC rollouts, export | beyond the paper |
//! | [`sim_eval`] | realised courtesy and WOSAC realism against the quantile, with baselines | beyond the paper |
//! | [`demo`] | the whole pipeline with report.md / report.json | — |
//! | [`bench`] | throughput measurements | — |
//!
//! Long-running functions take a [`Progress`]; [`Quiet`] ignores everything.
//!
//! **Architecture invariant:** no argument parsing, no terminal output (progress and notes go
//! through [`Progress`]), no process exit codes. Errors are `anyhow` chains whose messages name
//! the file, record or field (as cargo's library does); a request that is the caller's fault
//! carries an [`InvalidRequest`] in its chain, so a server can answer 4xx.

#![warn(missing_docs)]

pub mod bench;
pub mod choices;
pub mod data;
pub mod demo;
pub mod fidelity;
mod figures;
pub mod generate;
pub mod generator;
pub mod inputs;
mod label_table;
pub mod labels;
pub mod predictor;
mod progress;
pub mod scbg_eval;
pub mod sim;
pub mod sim_eval;
pub mod synth;

pub use progress::{Bar, Progress, Quiet};
pub use scbg_base::atomic::{write as write_atomic, write_json};
/// The floating-point mode of compute threads (subnormals flushed to zero), which the `scbg`
/// binary sets before it starts any thread.
pub use scbg_base::fp;
pub use scbg_scene::{AgentState, MapPoint, ObjectType, Scene};

/// The scene value types (tracks, map features), for front ends that build scenes themselves.
pub mod scene {
    pub use scbg_scene::*;
}

/// The road subsampling of the Multipath++ features: every 4th polyline point is kept.
pub const ROAD_SUBSAMPLE: usize = 4;

/// A request the caller got wrong (unknown track, quantile outside [0, 1], unknown scenario,
/// bad option value): its message says what and where. Front ends map it to a usage error
/// (HTTP 4xx); every other error is the system's.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct InvalidRequest(pub String);

/// Returns `Err(InvalidRequest(message))` from the enclosing function unless `cond` holds.
macro_rules! ensure_request {
    ($cond:expr, $($arg:tt)+) => {
        if !$cond {
            return Err(anyhow::Error::new($crate::InvalidRequest(format!($($arg)+))));
        }
    };
}
pub(crate) use ensure_request;

/// Whether an error chain holds an [`InvalidRequest`] (the caller's fault).
pub fn is_invalid_request(err: &anyhow::Error) -> bool {
    err.chain()
        .any(|e| e.downcast_ref::<InvalidRequest>().is_some())
}
