//! The small things every other scbg crate shares, in one place.
//!
//! - [`atomic`]: the project's one atomic file writer (temporary file in the destination's
//!   folder, renamed into place when complete, removed on failure).
//! - [`fp`]: the floating-point mode of compute threads (subnormals flushed to zero).
//! - [`skips`]: what a run left out, counted by reason, and the line summaries show.
//! - [`split`]: the scenario-id marks that decide a scene's split (held-out families,
//!   siblings).
//! - [`seed`]: the SplitMix64 mixer that derives independent, reproducible random streams
//!   from a `(seed, stream)` pair.
//!
//! **Architecture invariant:** no knowledge of scenes, features, models or dataset formats;
//! anything here must be useful to more than one crate.

#![warn(missing_docs)]

pub mod atomic;
pub mod fp;
pub mod seed;
pub mod skips;
pub mod split;
