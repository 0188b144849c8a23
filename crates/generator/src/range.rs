//! The courtesy range predictor (paper Sec. III-E) and the quantile → ψ mapping.

use burn::module::Module;
use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::tensor::activation::softplus;
use burn::tensor::{Device, Tensor, TensorData};
use scbg_courtesy::losses::pinball;
use scbg_model::blocks::Mlp;

use crate::data::Example;

/// The lower quantile τ the range predictor estimates (paper Sec. III-E).
pub const LOW_QUANTILE: f32 = 0.1;
/// The upper quantile τ the range predictor estimates.
pub const HIGH_QUANTILE: f32 = 0.9;

/// Predicts the 0.1 and 0.9 quantiles of ψ for a scene from B's frozen embedding.
/// `q_0.9 = q_0.1 + softplus(·)`, so the upper quantile is never below the lower one.
#[derive(Module, Debug)]
pub struct RangePredictor {
    /// MLP `e → hidden → hidden → 2`: the lower quantile and the pre-softplus gap.
    pub head: Mlp,
}

impl RangePredictor {
    /// A range predictor for embeddings of `embedding_width`, with two hidden layers of
    /// `hidden`; parameter ids come from their paths ([`scbg_model::param_ids`]).
    pub fn init(embedding_width: usize, hidden: usize, device: &Device) -> Self {
        let range = Self {
            head: Mlp::init(&[embedding_width, hidden, hidden, 2], device),
        };
        scbg_model::param_ids::with_path_ids(range, "range")
    }

    /// The predicted 0.1 and 0.9 quantiles of ψ, `q_high ≥ q_low`.
    ///
    /// # Shapes
    /// `embedding: [batch, e]` `-> (q_low: [batch], q_high: [batch])`
    pub fn forward(&self, embedding: Tensor<2>) -> (Tensor<1>, Tensor<1>) {
        let [b, _] = embedding.dims();
        let out = self.head.forward(embedding);
        let low = out.clone().narrow(1, 0, 1).reshape([b]);
        let gap = softplus(out.narrow(1, 1, 1).reshape([b]), 1.0);
        (low.clone(), low + gap)
    }
}

/// Maps a user quantile `q ∈ [0, 1]` to a ψ: linear between the predicted 0.1 and 0.9
/// quantiles and extended linearly beyond them (so q = 0.5 is their midpoint, q = 0 and q = 1
/// lie an eighth of the range outside). Documented choice: the paper normalises by the
/// predicted range without saying how; linear is the simplest monotone map.
pub fn psi_for_quantile(q: f32, q_low: f32, q_high: f32) -> f32 {
    q_low + (q - LOW_QUANTILE) / (HIGH_QUANTILE - LOW_QUANTILE) * (q_high - q_low)
}

/// The inverse of [`psi_for_quantile`]: the quantile a ψ corresponds to (0.5 when the
/// predicted range is empty).
pub fn quantile_for_psi(psi: f32, q_low: f32, q_high: f32) -> f32 {
    let span = q_high - q_low;
    if span.abs() < f32::EPSILON {
        return 0.5;
    }
    LOW_QUANTILE + (HIGH_QUANTILE - LOW_QUANTILE) * (psi - q_low) / span
}

/// The examples' stored frozen embeddings of B as one tensor on `device`.
///
/// # Shapes
/// `-> [examples, e]` (`e` = the predictor's embedding width)
pub fn stored_embeddings(examples: &[&Example], device: &Device) -> Tensor<2> {
    let n = examples.len();
    let e = examples.first().map_or(0, |x| x.b_embedding.len());
    let flat: Vec<f32> = examples
        .iter()
        .flat_map(|x| x.b_embedding.iter().copied())
        .collect();
    Tensor::from_data(TensorData::new(flat, [n, e]), device)
}

/// One pinball-loss step (paper eq. 9, τ = 0.1 and 0.9) on every ψ (logged and sampled) of
/// the examples: each example's scene gets the losses of all its labels (the first as many as
/// the example with the fewest has). Only the range predictor is updated. Returns it with the
/// loss; a non-finite loss leaves it unchanged.
///
/// # Shapes
/// `embedding: [examples, e]` (see [`stored_embeddings`]), `psi: [examples][labels]`
pub fn range_step(
    range: RangePredictor,
    optimizer: &mut ModuleOptimizer,
    embedding: Tensor<2>,
    psi: &[&[f32]],
    learning_rate: f64,
) -> (RangePredictor, f32) {
    let n = psi.len();
    let device = embedding.device();
    let (low, high) = range.forward(embedding);
    let m = psi.iter().map(|p| p.len()).min().unwrap_or(1);
    let mut total: Option<Tensor<1>> = None;
    for k in 0..m {
        let target = Tensor::<1>::from_data(
            TensorData::new(psi.iter().map(|p| p[k]).collect(), [n]),
            &device,
        );
        let l = pinball(target.clone(), low.clone(), LOW_QUANTILE)
            + pinball(target, high.clone(), HIGH_QUANTILE);
        total = Some(match total {
            Some(t) => t + l,
            None => l,
        });
    }
    let loss = total.expect("at least one label") / m as f32;
    let value: f32 = loss.clone().into_scalar();
    if !value.is_finite() {
        return (range, value);
    }
    let grads = GradientsParams::from_grads(loss.backward(), &range);
    (optimizer.step(learning_rate, range, grads), value)
}
