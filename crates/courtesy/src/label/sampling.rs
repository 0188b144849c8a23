//! B's marginal prediction, futures drawn from it, and points moved between agents' frames.

use burn::tensor::Device;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use scbg_features::AgentSample;
use scbg_model::{Batch, Mixture, Mode, Multipath};
use scbg_scene::Pose2;

/// The marginal mixture of each (standardised) sample.
pub fn marginal_mixtures(
    model: &Multipath,
    samples: &[&AgentSample],
    device: &Device,
) -> Vec<Mixture> {
    model
        .forward_marginal(&Batch::for_mode(samples, Mode::Marginal, device))
        .into_mixtures()
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
