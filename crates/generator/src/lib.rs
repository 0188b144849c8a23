//! The socially-controllable behaviour generator `y_B = g(x, ψ)` (paper eq. (1), Sec. III-D).
//!
//! Main types: [`GeneratorConfig`] → [`GeneratorConfig::init`] → [`Generator::forward`];
//! [`Example`] (one pair role with its labelled futures); [`train_step`] with the paper's three
//! variants ([`Variant`]).
//!
//! The scene encoder is the predictor's, frozen: the embedding of B (marginal mode) is computed
//! once per example on a plain device and stored, so only the decoder learns. The generator
//! chooses among B's predicted modes and their slowed copies, each scored by its own courtesy
//! under J_φ, and adds a displacement: an MLP of `[embedding ‖ MLP(ψ)]` gives one per knot
//! (every 5th of the 80 steps by default), interpolated linearly to every step.
//!
//! Inference has one path ([`Scbg::plan_basis`] → [`Scbg::plan_from`]); [`Scbg::generate`]
//! is that choice measured by J_φ.
//!
//! **Architecture invariant:** no files or CLI; the predictor is passed in and never updated.

#![warn(missing_docs)]

mod audience;
mod candidates;
mod courtesy;
mod data;
pub mod eval;
mod generate;
mod infer;
mod model;
mod modes;
mod plan;
mod range;
pub mod ranked;
mod tensors;
mod train;

pub use candidates::{
    ScoredCandidate, b_modes, b_modes_for, b_modes_of, fill_mode_courtesy, mode_courtesy,
    scored_candidates,
};
pub use courtesy::{Courtesy, Policy};
pub use data::{Example, a_from_b, build_examples, marginal_embedding};
pub use generate::{ChosenFuture, CourtesyOf, Generated, PairContext};
pub use infer::{GenerateError, Scbg};
pub use model::{
    CandidateFutures, DEFAULT_MODE_SLOWDOWNS, Generator, GeneratorConfig, RELATIVE_COURTESY_FLOOR,
    relative_courtesy,
};
pub use modes::{BModes, MAX_SPEEDUP, slowdown_warp, slowed_future};
pub use plan::PlanBasis;
pub use range::{
    HIGH_QUANTILE, LOW_QUANTILE, RangePredictor, psi_for_quantile, quantile_for_psi, range_step,
    stored_embeddings,
};
pub use train::{
    StepLosses, StepOptions, Threshold, Variant, balanced_batches, step_loss, threshold_value,
    train_step,
};

#[cfg(test)]
mod tests;
