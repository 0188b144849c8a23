//! The socially-controllable behaviour generator `y_B = g(x, ψ)` (paper eq. (1), Sec. III-D).
//!
//! Main types: [`GeneratorConfig`] → [`GeneratorConfig::init`] → [`Generator::forward`];
//! [`Example`] (one pair role with its labelled futures); [`train_step`] with the paper's three
//! variants ([`Variant`]).
//!
//! The scene encoder is the predictor's, frozen: the embedding of B (marginal mode) is computed
//! once per example on a plain device and stored, so only the decoder learns. The decoder has
//! no anchors: an MLP of `[embedding ‖ MLP(ψ)]` gives one displacement per knot (every 5th of
//! the 80 steps by default), summed into knot positions in B's frame and interpolated linearly
//! to every step.
//!
//! **Architecture invariant:** no files or CLI; the predictor is passed in and never updated.

#![warn(missing_docs)]

mod audience;
mod candidates;
mod courtesy;
mod data;
pub mod eval;
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
pub use data::{
    A_CONTEXT_WIDTH, Example, a_context, a_context_of, a_from_b, build_examples, marginal_embedding,
};
pub use infer::{CourtesyOf, GenerateError, Generated, PairContext, Scbg};
pub use model::{
    CandidateFutures, Generator, GeneratorConfig, RELATIVE_COURTESY_FLOOR, relative_courtesy,
};
pub use modes::{BModes, MAX_SPEEDUP, slowdown_warp};
pub use plan::PlanBasis;
pub use range::{
    HIGH_QUANTILE, LOW_QUANTILE, RangePredictor, psi_for_quantile, quantile_for_psi, range_step,
    stored_embeddings,
};
pub use scbg_features::{LANE_MOVE_M, lane_move, lane_path_points};
pub use train::{
    SelectorLoss, StepLosses, StepOptions, Threshold, Variant, balanced_batches, step_loss,
    threshold_value, train_step,
};

#[cfg(test)]
mod tests;
