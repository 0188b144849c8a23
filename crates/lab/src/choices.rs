//! The choices of the research pipeline: the runtime's ([`scbg::choices`]) and the predictor
//! evaluation's.

pub use scbg::choices::*;

pub use crate::predictor::{ModeSelection, SplitSelection};
