//! Every choice a front end offers, as enums from the crates that own them (each with
//! `clap::ValueEnum` under the `clap` feature, serde names, `name()` and `FromStr`), so a
//! front end needs no other crate.

pub use scbg_courtesy::label::{LabelOptions, MarginalEstimate};
pub use scbg_courtesy::{Audience, Reward, Weighting};
pub use scbg_generator::{Policy, Threshold, Variant};
pub use scbg_sim::{EgoMode, OthersMode};

pub use crate::Courtesy;
pub use scbg_model::{Mode, Preset};
pub use scbg_synth::Family;
