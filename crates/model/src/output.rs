//! The model's output, a Gaussian mixture over future trajectories ([`GmmOutput`] as tensors,
//! [`Mixture`] as plain arrays), and the clamp ranges of its covariance parameters, shared by
//! the loss and by [`GmmOutput::into_mixtures`].

use burn::tensor::Tensor;

/// Clamp ranges of the covariance parameters, guarding against the NaN/inf covariances the
/// public Multipath++ code is known for. `c` is the log-scale (σ² ∝ e^c).
/// With these bounds the smallest principal standard deviation is about 0.1 m and the largest
/// about 400 m, so one outlier cannot blow a batch's loss up by orders of magnitude.
///
/// This one clamps `a`, the log-ratio of the two axis variances.
pub const COV_A_RANGE: (f32, f32) = (-2.0, 2.0);
/// Clamp range of `b`, the correlation parameter (off-diagonal `e^c·sinh b`); see
/// [`COV_A_RANGE`].
pub const COV_B_RANGE: (f32, f32) = (-2.0, 2.0);
/// Clamp range of `c`, the log-scale of Σ (`log|Σ| = 2c`); see [`COV_A_RANGE`].
pub const COV_C_RANGE: (f32, f32) = (-2.0, 8.0);

/// Output of the model: a Gaussian mixture over future trajectories in the target frame.
#[derive(Debug, Clone)]
pub struct GmmOutput {
    /// `[batch, modes, future_steps, 2]` positions in the target frame (metres).
    pub xy: Tensor<4>,
    /// `[batch, modes, future_steps, 3]`: (a, b, c) of
    /// Σ = e^c·[[e^a·cosh b, sinh b], [sinh b, e^−a·cosh b]] (unclamped).
    pub cov_abc: Tensor<4>,
    /// `[batch, modes]` unnormalised mode logits.
    pub logits: Tensor<2>,
}

/// The means and mode logits of a predicted mixture, without the covariances: what an
/// expectation `Σ_k π_k r(μ_k)` over the modes needs ([`crate::Multipath::forward_means`]).
#[derive(Debug, Clone)]
pub struct MixtureMeans {
    /// `[batch, modes, future_steps, 2]` positions in the target frame (metres).
    pub xy: Tensor<4>,
    /// `[batch, modes]` unnormalised mode logits.
    pub logits: Tensor<2>,
}

impl From<GmmOutput> for MixtureMeans {
    fn from(out: GmmOutput) -> Self {
        Self {
            xy: out.xy,
            logits: out.logits,
        }
    }
}

/// One agent's predicted mixture as plain arrays (for evaluation, labelling, serving).
#[derive(Debug, Clone, PartialEq)]
pub struct Mixture {
    /// `[K][T]` mean positions (target frame, metres).
    pub xy: Vec<Vec<[f32; 2]>>,
    /// `[K][T]` covariance parameters (a, b, c), clamped to the ranges the loss uses.
    pub abc: Vec<Vec<[f32; 3]>>,
    /// `[K]` mode probabilities (softmax of the logits).
    pub probs: Vec<f32>,
}

impl GmmOutput {
    /// Reads the batch back into one [`Mixture`] per target.
    pub fn into_mixtures(self) -> Vec<Mixture> {
        let [b, k, t, _] = self.xy.dims();
        let xy: Vec<f32> = self.xy.into_data().try_to_vec::<f32>().expect("f32 tensor");
        let abc: Vec<f32> = self
            .cov_abc
            .into_data()
            .try_to_vec::<f32>()
            .expect("f32 tensor");
        let probs: Vec<f32> = burn::tensor::activation::softmax(self.logits, 1)
            .into_data()
            .try_to_vec::<f32>()
            .expect("f32 tensor");
        (0..b)
            .map(|i| Mixture {
                xy: (0..k)
                    .map(|m| {
                        (0..t)
                            .map(|s| {
                                let o = ((i * k + m) * t + s) * 2;
                                [xy[o], xy[o + 1]]
                            })
                            .collect()
                    })
                    .collect(),
                abc: (0..k)
                    .map(|m| {
                        (0..t)
                            .map(|s| {
                                let o = ((i * k + m) * t + s) * 3;
                                [
                                    abc[o].clamp(COV_A_RANGE.0, COV_A_RANGE.1),
                                    abc[o + 1].clamp(COV_B_RANGE.0, COV_B_RANGE.1),
                                    abc[o + 2].clamp(COV_C_RANGE.0, COV_C_RANGE.1),
                                ]
                            })
                            .collect()
                    })
                    .collect(),
                probs: probs[i * k..(i + 1) * k].to_vec(),
            })
            .collect()
    }
}
