//! Multipath++ with a conditional (CBP-style) mode, in burn.
//!
//! Main types: [`MultipathConfig`] (`paper` / `cpu-small` presets) → [`MultipathConfig::init`]
//! → [`Multipath::forward`] returning a [`GmmOutput`]; [`gmm_nll`]; [`Batch`] built from
//! `AgentSample`s. The conditional mode adds a future encoder of the other agent's future
//! (target frame) to the scene embedding; `condition_flag = 0` turns it off (marginal mode), so
//! one set of weights serves both `p(y_A | x)` and `p(y_A | x, y_B)`.
//!
//! **Architecture invariant:** models know tensors and `AgentSample`s, never file formats or
//! the CLI; the backend is chosen in [`device`] only.

#![warn(missing_docs)]

pub mod batch;
pub mod blocks;
pub mod condition;
pub mod config;
pub mod device;
pub mod fixtures;
pub mod loss;
pub mod lstm_kernel;
pub mod model;
pub mod output;
pub mod param_ids;

pub use batch::{Batch, BatchAugment, Mode};
pub use config::{MultipathConfig, Preset};
pub use loss::gmm_nll;
pub use model::{CONDITION_STRIDE, Multipath, SceneEncoding};
pub use output::{GmmOutput, Mixture, MixtureMeans};

/// Draws every lazily initialised parameter of `module` now (burn initialises parameters at
/// first use): call it right after `init` where the draws must come from a seeded stream.
pub fn materialize<M: burn::module::Module>(module: &M) {
    module.visit(&mut Materialize);
}

/// Reads every parameter, which makes burn draw the lazy ones.
struct Materialize;

impl burn::module::ModuleVisitor for Materialize {
    fn visit_float<const D: usize>(
        &mut self,
        param: &burn::module::Param<burn::tensor::Tensor<D>>,
    ) {
        let _ = param.val();
    }

    fn visit_int<const D: usize>(
        &mut self,
        param: &burn::module::Param<burn::tensor::Tensor<D, burn::tensor::Int>>,
    ) {
        let _ = param.val();
    }

    fn visit_bool<const D: usize>(
        &mut self,
        param: &burn::module::Param<burn::tensor::Tensor<D, burn::tensor::Bool>>,
    ) {
        let _ = param.val();
    }
}

/// Tests that seed burn's process-global RNG hold this lock, so concurrent tests do not draw
/// from the stream between `seed` and `init`.
#[cfg(test)]
pub(crate) static SEED_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
