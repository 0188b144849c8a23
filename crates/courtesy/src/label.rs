//! Auto-labelling (paper Sec. III-C): ψ of the logged future of B and of M futures sampled from
//! B's marginal prediction (the data augmentation of Sec. III-D).

use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use scbg_features::AgentSample;
use scbg_model::{Batch, BatchAugment, Mixture, Multipath};
use scbg_scene::Pose2;

use crate::{Reward, expected_reward};

/// The marginal mixture of each (standardised) sample.
pub fn marginal_mixtures(
    model: &Multipath,
    samples: &[&AgentSample],
    device: &Device,
) -> Vec<Mixture> {
    let mut rng = rand_pcg::Pcg64Mcg::new(0xcafe);
    let batch = Batch::from_samples(
        samples,
        &BatchAugment {
            condition_dropout: 1.0,
            history_mask_prob: 0.0,
        },
        &mut rng,
        device,
    );
    model.forward(&batch).into_mixtures()
}

/// Drawing futures from a predicted mixture.
pub trait SampleMixture {
    /// Draws `m` trajectories: a mode from π, then one standard-normal 2-vector z shared by
    /// every step, `y_t = μ_t + noise · L_t z` with `L_t` the Cholesky factor of Σ_t. Sharing
    /// z keeps samples smooth (independent per-step noise would make them jitter). `noise` = 1
    /// samples the mixture; 0 gives mode means drawn by π.
    fn sample(&self, m: usize, noise: f32, rng: &mut impl Rng) -> Vec<Vec<[f32; 2]>>;
}

impl SampleMixture for Mixture {
    fn sample(&self, m: usize, noise: f32, rng: &mut impl Rng) -> Vec<Vec<[f32; 2]>> {
        (0..m)
            .map(|_| {
                let u: f32 = rng.random();
                let mut acc = 0.0;
                let k = self.probs.iter().position(|p| {
                    acc += p;
                    u < acc
                });
                let k = k.unwrap_or(self.probs.len() - 1);
                let z: [f32; 2] = [StandardNormal.sample(rng), StandardNormal.sample(rng)];
                let z = [z[0] * noise, z[1] * noise];
                self.xy[k]
                    .iter()
                    .zip(&self.abc[k])
                    .map(|(mu, &[a, b, c])| {
                        let s = c.exp();
                        let (s11, s12, s22) = (
                            s * a.exp() * b.cosh(),
                            s * b.sinh(),
                            s * (-a).exp() * b.cosh(),
                        );
                        let l11 = s11.sqrt();
                        let l21 = s12 / l11;
                        let l22 = (s22 - l21 * l21).max(0.0).sqrt();
                        [mu[0] + l11 * z[0], mu[1] + l21 * z[0] + l22 * z[1]]
                    })
                    .collect()
            })
            .collect()
    }
}

/// Moves points from the frame `from` (world_from_agent of one agent) into the frame `to`.
pub fn change_frame(points: &[[f32; 2]], from: &Pose2, to: &Pose2) -> Vec<[f32; 2]> {
    points
        .iter()
        .map(|p| {
            let (wx, wy) = from.world_from_agent(f64::from(p[0]), f64::from(p[1]));
            let (x, y) = to.agent_from_world(wx, wy);
            [x as f32, y as f32]
        })
        .collect()
}

/// ψ and both expectations for several futures of B, for one target A.
#[derive(Debug, Clone, PartialEq)]
pub struct PairLabels {
    /// `[1 + M]`: index 0 is the logged future, 1.. the sampled ones.
    pub psi: Vec<f32>,
    pub e_cond: Vec<f32>,
    pub e_marg: f32,
    /// The futures of B in A's frame (`[1 + M][T]`; the logged one has its invalid steps at 0).
    pub futures_in_a: Vec<Vec<[f32; 2]>>,
}

/// How `E[r(Y_A) | x]`, the second term of ψ, is estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MarginalEstimate {
    /// The predictor's marginal mode (paper eq. 4).
    Direct,
    /// The law of total expectation through the conditional mode:
    /// `E[r(Y_A) | x] = E_{y_B ~ p(y_B | x)} E[r(Y_A) | x, y_B]`, averaged over the sampled
    /// futures of B (falls back to [`MarginalEstimate::Direct`] without samples). The two
    /// modes of one network are not consistent with each other: with `Direct`, ψ carries a
    /// per-scene offset (the conditional mode's bias) that is the same for every y_B. This
    /// estimator removes it, so ψ measures what B's future changes for A relative to B's
    /// plausible behaviours.
    #[default]
    ConditionalAverage,
}

impl MarginalEstimate {
    pub fn parse(text: &str) -> Option<Self> {
        match text {
            "direct" => Some(Self::Direct),
            "conditional-average" => Some(Self::ConditionalAverage),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Direct => "direct",
            Self::ConditionalAverage => "conditional-average",
        }
    }
}

/// How to label: how many futures of B to sample, which reward, and how E[r(Y_A) | x] is
/// estimated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LabelOptions {
    pub samples: usize,
    pub reward: Reward,
    pub marginal: MarginalEstimate,
    /// Scale of the Gaussian part of B's sampled futures (1 = samples of the mixture, 0 =
    /// mode means); see [`SampleMixture::sample`].
    pub sample_noise: f32,
}

/// Labels one ordered pair. `a` is A's standardised sample conditioned on B's logged future;
/// `b` is B's standardised marginal sample; `b_mixture` is B's marginal prediction.
pub fn label_pair(
    model: &Multipath,
    a: &AgentSample,
    b: &AgentSample,
    b_mixture: &Mixture,
    options: LabelOptions,
    rng: &mut impl Rng,
    device: &Device,
) -> PairLabels {
    let LabelOptions {
        samples,
        reward,
        marginal,
        sample_noise,
    } = options;
    let t = a.condition_future_valid.len();
    let logged: Vec<[f32; 2]> = (0..t)
        .map(|i| {
            [
                a.condition_future_xy_m[2 * i],
                a.condition_future_xy_m[2 * i + 1],
            ]
        })
        .collect();
    let mut futures = vec![logged];
    futures.extend(
        b_mixture
            .sample(samples, sample_noise, rng)
            .iter()
            .map(|tr| change_frame(tr, &b.world_from_agent, &a.world_from_agent)),
    );
    let n = futures.len();
    let mut cond = Vec::with_capacity(n * t * 3);
    for (i, f) in futures.iter().enumerate() {
        for (s, p) in f.iter().enumerate() {
            let valid = i > 0 || a.condition_future_valid[s];
            cond.extend([
                if valid { p[0] } else { 0.0 },
                if valid { p[1] } else { 0.0 },
                f32::from(u8::from(valid)),
            ]);
        }
    }
    let refs: Vec<&AgentSample> = (0..n).map(|_| a).collect();
    let mut batch_rng = rand_pcg::Pcg64Mcg::new(0xbeef);
    let batch = Batch::from_samples(&refs, &BatchAugment::default(), &mut batch_rng, device);
    let condition = Tensor::<3>::from_data(TensorData::new(cond, [n, t, 3]), device);
    let e_cond: Vec<f32> = expected_reward(model, &batch, Some(condition), reward, 0.1)
        .into_data()
        .try_to_vec::<f32>()
        .expect("f32");
    let e_marg: f32 = if marginal == MarginalEstimate::ConditionalAverage && n > 1 {
        e_cond[1..].iter().sum::<f32>() / (n - 1) as f32
    } else {
        expected_reward(
            model,
            &Batch::from_samples(&[a], &BatchAugment::default(), &mut batch_rng, device),
            None,
            reward,
            0.1,
        )
        .into_data()
        .try_to_vec::<f32>()
        .expect("f32")[0]
    };
    PairLabels {
        psi: e_cond.iter().map(|e| e - e_marg).collect(),
        e_cond,
        e_marg,
        futures_in_a: futures,
    }
}
