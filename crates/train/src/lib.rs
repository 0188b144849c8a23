//! Training and evaluation of the Multipath++ predictor.
//!
//! Main entry points: [`train`] (prepared cache → checkpoints, resumable), [`Checkpoint`]
//! (config + feature statistics + weights), [`eval`] (model and baseline predictions scored
//! with `scbg-metrics`).
//!
//! **Architecture invariant:** reads the prepared cache only (never WOMD files) and writes
//! checkpoints; knows nothing about the CLI or figures.

#![warn(missing_docs)]

pub mod checkpoint;
pub mod config;
pub mod data;
pub mod eval;
pub mod trainer;

pub use checkpoint::{Checkpoint, EpochReport};
pub use config::TrainConfig;
pub use trainer::{NoProgress, Progress, TrainError, loss_and_grads, train};

#[cfg(test)]
mod tests;
