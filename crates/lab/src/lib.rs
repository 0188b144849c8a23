//! scbg-lab: the research pipeline of scbg — synthetic data, feature preparation, predictor
//! and generator training, courtesy labelling, the paper's evaluations (Tables I–II, Figs.
//! 4–5), label fidelity, closed-loop evaluation, benches, figures and the demo that runs them
//! all.
//!
//! Only the command line uses this crate; the servers and the Python module use the runtime
//! (`scbg`) alone.
//!
//! | module | what | paper |
//! |---|---|---|
//! | [`config`] | the pipeline's settings (`docs/pipeline.toml`) | — |
//! | [`synth`] | synthetic interactive scenarios + ground-truth sidecar | — |
//! | [`prepare`] | WOMD files into the feature cache | — |
//! | [`predictor`] | train / evaluate Multipath++ (marginal + conditional), external predictions | Sec. III-B, Table I |
//! | [`labels`] | courtesy labels ψ of every pair role, the Parquet label table | eq. (2), Sec. III-C, Fig. 3 |
//! | [`generator`] | generator + range predictor training | eq. (1), Sec. III-D |
//! | [`scbg_eval`] | CourtesyMSE, TrajADE, correlations, Figs. 4–5 | Table II, Figs. 4–5 |
//! | [`fidelity`] | labels and generated futures against the synthetic world's truth | — |
//! | [`sim_eval`] | realised courtesy and WOSAC realism against the quantile, with baselines | beyond the paper |
//! | [`demo`] | the whole pipeline with report.md / report.json | — |
//! | [`bench`] | throughput measurements | — |
//!
//! **Architecture invariant:** no argument parsing and no terminal output, as in the runtime;
//! the runtime never depends on this crate.

#![warn(missing_docs)]

pub mod bench;
pub mod choices;
pub mod config;
pub mod demo;
pub mod fidelity;
mod figures;
pub mod generator;
mod label_table;
pub mod labels;
pub mod predictor;
pub mod prepare;
pub mod scbg_eval;
pub mod sim_eval;
pub mod synth;

pub use scbg::{
    Bar, InvalidRequest, Progress, Quiet, ROAD_SUBSAMPLE, ensure_request, fp, inputs,
    is_invalid_request, write_json,
};
