//! scbg: socially-controllable behavior generation for traffic simulation — the runtime.
//!
//! Every front end (the `scbg` command line, the HTTP server, the Python module) calls this
//! crate and nothing below it to load a trained model, measure courtesy, generate B's future at
//! a courtesy and run closed-loop simulations. The research pipeline (training, labelling,
//! evaluations, the demo, benches) lives in `scbg-lab`, which only the command line uses.
//!
//! | module | what | paper |
//! |---|---|---|
//! | [`Model`] | a loaded model: generate B's future at a [`Courtesy`], ψ of a given future | Sec. III-E, eq. (2) |
//! | [`Session`] | a closed-loop simulation stepped by a front end | beyond the paper |
//! | [`model`] | a trained model folder: its description and loading | eq. (1), Sec. III-D |
//! | [`generate`] | B's world-frame future at a courtesy quantile or ψ, ψ of a given future | Sec. III-E, eq. (2) |
//! | [`sim`] | closed-loop simulation with courtesy-controlled agents, WOSAC rollouts, export | beyond the paper |
//! | [`data`] | scenes from WOMD files and bytes, inspect, render, the synthetic ground truth | — |
//! | [`scene_arrays`] | a scene from plain arrays | — |
//! | [`inputs`] | paths and glob patterns to input files | — |
//! | [`wosac`] | WOSAC realism of a submission against the logged scenarios; baselines as submissions | — |
//!
//! Long-running functions take a [`Progress`]; [`Quiet`] ignores everything.
//!
//! **Architecture invariant:** no argument parsing, no terminal output (progress and notes go
//! through [`Progress`]), no process exit codes, no training. Errors are `anyhow` chains whose
//! messages name the file, record or field; a request that is the caller's fault carries an
//! [`InvalidRequest`] in its chain, so a server can answer 4xx.

#![warn(missing_docs)]

mod artefact;
pub mod choices;
mod courtesy;
pub mod data;
pub mod generate;
pub mod inputs;
pub mod model;
mod progress;
pub mod scene_arrays;
pub mod session;
pub mod sim;
pub mod wosac;

pub use courtesy::Courtesy;
pub use model::{LoadOptions, Model};
pub use scene_arrays::SceneArrays;
pub use session::{EgoPose, Session, Snapshot};
pub use sim::{ControlledAgent, DEFAULT_LANE_KEEPING_M, LoopOptions, keep_in_lane};

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
#[doc(hidden)]
#[macro_export]
macro_rules! ensure_request {
    ($cond:expr, $($arg:tt)+) => {
        if !$cond {
            return Err(anyhow::Error::new($crate::InvalidRequest(format!($($arg)+))));
        }
    };
}

/// Whether an error chain holds an [`InvalidRequest`] (the caller's fault).
pub fn is_invalid_request(err: &anyhow::Error) -> bool {
    err.chain()
        .any(|e| e.downcast_ref::<InvalidRequest>().is_some())
}
