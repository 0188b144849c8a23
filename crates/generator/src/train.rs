//! One optimisation step of the generator (paper eqs. (6)–(8), with J_φ of eq. (5)), its
//! variants and the balanced batches of Sec. IV-D.

use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use rand::seq::IndexedRandom;
use scbg_courtesy::Reward;
use scbg_courtesy::losses::{courtesy_loss, huber_trajectory};
use scbg_model::Multipath;

use crate::audience::audience_courtesy;
use crate::candidates::b_modes_for;
use crate::data::Example;
use crate::model::Generator;
use crate::range::stored_embeddings;
use crate::tensors::repeat_rows;

/// The paper's three variants (Table II).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Variant {
    /// ① logged futures only, trajectory loss only.
    #[serde(rename = "baseline")]
    Baseline,
    /// ① + ② sampled futures as extra targets (weight α).
    #[serde(rename = "aug")]
    #[cfg_attr(feature = "clap", value(name = "aug"))]
    Augmented,
    /// ① + ② + ③ the courtesy loss through the frozen J_φ (weight β).
    #[serde(rename = "full")]
    Full,
}

impl Variant {
    /// The three variants in the paper's order.
    pub const ALL: [Variant; 3] = [Variant::Baseline, Variant::Augmented, Variant::Full];

    /// The variant's name (`baseline`, `aug`, `full`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Baseline => "baseline",
            Self::Augmented => "aug",
            Self::Full => "full",
        }
    }
}

impl std::str::FromStr for Variant {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|v| v.name() == s)
            .ok_or_else(|| format!("unknown variant {s:?} (baseline, aug or full)"))
    }
}

/// Which examples count as "high courtesy" for the 50/50 batches. Written `qX` (a quantile)
/// or a number (m/s), also in `generator.json`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(into = "String", try_from = "String")]
pub enum Threshold {
    /// |ψ| above this many m/s (the paper: 2).
    Absolute(f32),
    /// |ψ| above this quantile of the logged |ψ| (for data whose ψ scale differs from WOMD's).
    Quantile(f32),
}

impl std::fmt::Display for Threshold {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Absolute(v) => write!(f, "{v}"),
            Self::Quantile(q) => write!(f, "q{q}"),
        }
    }
}

impl std::str::FromStr for Threshold {
    type Err = String;
    fn from_str(text: &str) -> Result<Self, String> {
        match text.strip_prefix('q') {
            Some(q) => {
                let q: f32 = q
                    .parse()
                    .map_err(|_| format!("threshold {text:?}: expected qX with X in [0, 1]"))?;
                if !(0.0..=1.0).contains(&q) {
                    return Err(format!("threshold {text:?}: quantile outside [0, 1]"));
                }
                Ok(Self::Quantile(q))
            }
            None => text
                .parse()
                .ok()
                .filter(|v: &f32| v.is_finite() && *v >= 0.0)
                .map(Self::Absolute)
                .ok_or_else(|| format!("threshold {text:?}: expected a number >= 0 (m/s) or qX")),
        }
    }
}

impl From<Threshold> for String {
    fn from(t: Threshold) -> String {
        t.to_string()
    }
}

impl TryFrom<String> for Threshold {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        s.parse()
    }
}

/// The |ψ| above which an example counts as high courtesy.
pub fn threshold_value(examples: &[Example], threshold: Threshold) -> f32 {
    match threshold {
        Threshold::Absolute(v) => v,
        Threshold::Quantile(q) => {
            let mut s: Vec<f32> = examples.iter().map(|e| e.psi[0].abs()).collect();
            s.sort_by(f32::total_cmp);
            s.get(((s.len() as f32 * q) as usize).min(s.len().saturating_sub(1)))
                .copied()
                .unwrap_or(0.0)
        }
    }
}

/// Batches of example indices, half from |ψ_logged| above the threshold and half from the
/// rest (drawn with replacement when a side runs short), `count` batches.
pub fn balanced_batches(
    examples: &[Example],
    threshold: Threshold,
    batch_size: usize,
    count: usize,
    rng: &mut impl Rng,
) -> Vec<Vec<usize>> {
    let abs: Vec<f32> = examples.iter().map(|e| e.psi[0].abs()).collect();
    let thr = threshold_value(examples, threshold);
    let high: Vec<usize> = (0..abs.len()).filter(|&i| abs[i] > thr).collect();
    let low: Vec<usize> = (0..abs.len()).filter(|&i| abs[i] <= thr).collect();
    (0..count)
        .map(|_| {
            let half = batch_size / 2;
            let mut batch: Vec<usize> = Vec::with_capacity(batch_size);
            let (first, second) = if high.is_empty() {
                (&low, &low)
            } else if low.is_empty() {
                (&high, &high)
            } else {
                (&high, &low)
            };
            batch.extend((0..half).filter_map(|_| first.choose(rng).copied()));
            batch.extend((0..batch_size - half).filter_map(|_| second.choose(rng).copied()));
            batch
        })
        .collect()
}

/// Losses of one step (means over the batch).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepLosses {
    /// `L_traj` (paper eq. 6): logged-future Huber loss plus α times the sampled ones'.
    pub trajectory: f32,
    /// `L_court` (paper eq. 7) in units of the generator's `psi_scale`; 0 unless
    /// [`Variant::Full`].
    pub courtesy: f32,
    /// `L = trajectory_weight · L_traj + β · L_court` (paper eq. 8).
    pub total: f32,
}

/// Hyper-parameters of a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOptions {
    /// Which losses and futures the step uses.
    pub variant: Variant,
    /// Weight of the sampled futures' trajectory loss (α).
    pub alpha: f32,
    /// Weight of the courtesy loss (β).
    pub beta: f32,
    /// Huber δ of the trajectory loss (metres).
    pub huber_delta: f32,
    /// Multiplies the whole trajectory loss (1 normally; 0 trains on the courtesy loss alone).
    pub trajectory_weight: f32,
    /// The reward r(y_A) of J_φ (as used for the labels).
    pub reward: Reward,
    /// Learning rate of the optimizer step.
    pub learning_rate: f64,
}

/// One step: `L = Huber(y⁰, ŷ⁰) + α Σ_m Huber(y^m, ŷ^m) + β Σ_m (ψ_m − J_φ(x, ŷ^m))²`
/// (paper eqs. (6)–(8)). `predictor` lives on the autodiff device so that J_φ passes gradients
/// to ŷ; only the generator's parameters are updated. Pass the predictor through
/// `Module::no_grad` first: then the backward pass skips the predictor's own weights.
pub fn train_step(
    generator: Generator,
    optimizer: &mut ModuleOptimizer,
    predictor: &Multipath,
    examples: &[&Example],
    options: &StepOptions,
    device: &Device,
) -> (Generator, StepLosses) {
    let (total, losses) = step_loss(&generator, predictor, examples, options, device);
    if !losses.total.is_finite() {
        return (generator, losses);
    }
    let grads = GradientsParams::from_grads(total.backward(), &generator);
    (
        optimizer.step(options.learning_rate, generator, grads),
        losses,
    )
}

/// The loss of [`train_step`] as a tensor (for the update, and for gradient checks).
///
/// All `1 + M` futures of every example go through the generator (and, for
/// [`Variant::Full`], through J_φ) as one batch of `(1 + M) · n` rows, `m`-major. The marginal
/// term E[r(Y_A) | x] of J_φ does not depend on ŷ: it is the labels' value; the
/// courtesy loss is measured in units of the generator's `psi_scale` (the labels' spread), so
/// β means the same on data whose ψ is 0.03 m/s wide or 3 m/s wide.
pub fn step_loss(
    generator: &Generator,
    predictor: &Multipath,
    examples: &[&Example],
    options: &StepOptions,
    device: &Device,
) -> (Tensor<1>, StepLosses) {
    let n = examples.len();
    let t = examples[0].logged_valid.len();
    let m_count = match options.variant {
        Variant::Baseline => 1,
        _ => examples.iter().map(|e| e.psi.len()).min().unwrap_or(1),
    };
    let rows = n * m_count;
    let embedding = repeat_rows(stored_embeddings(examples, device), m_count);
    let psi = Tensor::<1>::from_data(
        TensorData::new(
            (0..m_count)
                .flat_map(|m| examples.iter().map(move |e| e.psi[m]))
                .collect(),
            [rows],
        ),
        device,
    );
    // Row-major `[rows, T, 2]` and `[rows, T]`, kept on the host for the classification's
    // assignment.
    let target_xy: Vec<f32> = (0..m_count)
        .flat_map(|m| {
            examples
                .iter()
                .flat_map(move |e| e.futures_b[m].iter().flat_map(|p| [p[0], p[1]]))
        })
        .collect();
    let valid_steps: Vec<f32> = (0..m_count)
        .flat_map(|m| {
            examples.iter().flat_map(move |e| {
                (0..t).map(move |s| f32::from(u8::from(m > 0 || e.logged_valid[s])))
            })
        })
        .collect();
    let target = Tensor::<3>::from_data(TensorData::new(target_xy.clone(), [rows, t, 2]), device);
    let valid = Tensor::<2>::from_data(TensorData::new(valid_steps.clone(), [rows, t]), device);
    let modes =
        b_modes_for(generator, predictor, examples, options.reward, device).repeat_rows(m_count);
    // MultiPath's classification: each target future is assigned its nearest candidate (mean
    // distance over its valid steps, the candidates' own means without the displacement); the
    // trajectory loss is the Huber loss of that candidate plus the displacement, plus the
    // cross-entropy of the selector's logits against the assignment. The selector learns
    // which candidate a future of courtesy ψ is, and the likeliest candidate — what B drives
    // outside training — is trained directly; the courtesy loss acts on the softmax blend
    // (differentiable in the selector).
    let nearest = nearest_candidates(&modes.xy, &target_xy, &valid_steps);
    let k = modes.xy.dims()[1];
    let candidates = generator.forward_candidates(embedding, psi.clone(), modes);
    let onehot = Tensor::<2>::from_data(
        TensorData::new(
            nearest
                .iter()
                .flat_map(|&j| (0..k).map(move |c| f32::from(u8::from(c == j))))
                .collect(),
            [rows, k],
        ),
        device,
    );
    let futures = candidates.futures;
    let blend = burn::tensor::activation::softmax(candidates.logits.clone(), 1)
        .reshape([rows, 1, k])
        .matmul(futures.clone().reshape([rows, k, t * 2]))
        .reshape([rows, t, 2]);
    let chosen = (futures * onehot.clone().reshape([rows, k, 1, 1]))
        .sum_dim(1)
        .reshape([rows, t, 2]);
    let cross_entropy = (burn::tensor::activation::log_softmax(candidates.logits, 1) * onehot)
        .sum_dim(1)
        .reshape([rows])
        .neg();
    let part = |start: usize, len: usize| {
        huber_trajectory(
            chosen.clone().narrow(0, start, len),
            target.clone().narrow(0, start, len),
            valid.clone().narrow(0, start, len),
            options.huber_delta,
        ) + cross_entropy.clone().narrow(0, start, len).mean()
    };
    let mut traj = part(0, n);
    if m_count > 1 {
        // Σ_m of per-future means = (M) × the mean over the sampled rows (equal valid counts).
        traj = traj + part(n, rows - n) * (options.alpha * (m_count - 1) as f32);
    }
    let court = (options.variant == Variant::Full).then(|| {
        let (achieved, _) =
            audience_courtesy(predictor, blend, examples, m_count, options.reward, device);
        let scale = generator.psi_scale.max(1e-12);
        courtesy_loss(psi / scale, achieved / scale) * m_count as f32
    });
    let total = match &court {
        Some(c) => traj.clone() * options.trajectory_weight + c.clone() * options.beta,
        None => traj.clone() * options.trajectory_weight,
    };
    let losses = StepLosses {
        trajectory: traj.into_scalar(),
        courtesy: court.map_or(0.0, |c| c.into_scalar()),
        total: total.clone().into_scalar(),
    };
    (total, losses)
}

/// For each row, the candidate nearest its target: the least total distance over the row's
/// valid steps between the candidate's mean (`xy`, without the generator's displacement) and
/// the target (every candidate is measured on the same steps, so also the least mean
/// distance); 0 for a row with no valid step. Computed on the host: an assignment, not a
/// differentiable quantity.
///
/// # Shapes
/// `xy: [rows, K, T, 2]`; `target`: `[rows, T, 2]` and `valid`: `[rows, T]` (1 = valid), row-major
/// `-> rows` indices
fn nearest_candidates(xy: &Tensor<4>, target: &[f32], valid: &[f32]) -> Vec<usize> {
    let [rows, k, t, _] = xy.dims();
    let xy = xy
        .to_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .unwrap_or_default();
    (0..rows)
        .map(|r| {
            let distance = |c: usize| -> f32 {
                (0..t)
                    .filter(|&s| valid.get(r * t + s).is_some_and(|&v| v > 0.0))
                    .map(|s| {
                        let m = ((r * k + c) * t + s) * 2;
                        let g = (r * t + s) * 2;
                        (xy[m] - target[g]).hypot(xy[m + 1] - target[g + 1])
                    })
                    .sum()
            };
            (0..k)
                .map(|c| (c, distance(c)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map_or(0, |(c, _)| c)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each row is assigned the candidate nearest its target over the row's valid steps
    /// only: a target that follows candidate 1 while valid and candidate 0 afterwards is
    /// candidate 1's.
    #[test]
    fn the_nearest_candidate_counts_valid_steps_only() {
        let device = Device::flex();
        let t = 80;
        let xy = crate::modes::two_modes(&device).reshape([1, 2, t, 2]);
        // Candidate 0 runs along y = 0, candidate 1 along y = 0.1 x.
        let target: Vec<f32> = (1..=t)
            .flat_map(|s| [s as f32, if s <= 30 { 0.1 * s as f32 } else { 0.0 }])
            .collect();
        let mask = |valid_until: usize| -> Vec<f32> {
            (0..t)
                .map(|s| f32::from(u8::from(s < valid_until)))
                .collect()
        };
        assert_eq!(nearest_candidates(&xy, &target, &mask(30)), vec![1]);
        // Every step valid: the 50 steps on y = 0 outweigh the 30 on the turn.
        assert_eq!(nearest_candidates(&xy, &target, &mask(t)), vec![0]);
        // No valid step: candidate 0.
        assert_eq!(nearest_candidates(&xy, &target, &mask(0)), vec![0]);
    }
}
