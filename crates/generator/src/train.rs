//! One optimisation step of the generator (paper eqs. (5)–(7)).

use burn::optim::{GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use rand::seq::IndexedRandom;
use scbg_courtesy::losses::{courtesy_loss, huber_trajectory};
use scbg_courtesy::{Reward, courtesy};
use scbg_features::AgentSample;
use scbg_model::{Batch, BatchAugment, Multipath};

use crate::data::Example;
use crate::model::Generator;

/// The paper's three variants (Table II).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    /// ① logged futures only, trajectory loss only.
    Baseline,
    /// ① + ② sampled futures as extra targets (weight α).
    Augmented,
    /// ① + ② + ③ the courtesy loss through the frozen J_φ (weight β).
    Full,
}

/// Which examples count as "high courtesy" for the 50/50 batches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Threshold {
    /// |ψ| above this many m/s (the paper: 2).
    Absolute(f32),
    /// |ψ| above this quantile of the logged |ψ| (for data whose ψ scale differs from WOMD's).
    Quantile(f32),
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
    let thr = match threshold {
        Threshold::Absolute(v) => v,
        Threshold::Quantile(q) => {
            let mut s = abs.clone();
            s.sort_by(f32::total_cmp);
            s.get(((s.len() as f32 * q) as usize).min(s.len().saturating_sub(1)))
                .copied()
                .unwrap_or(0.0)
        }
    };
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
    pub trajectory: f32,
    pub courtesy: f32,
    pub total: f32,
}

/// Hyper-parameters of a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOptions {
    pub variant: Variant,
    /// Weight of the sampled futures' trajectory loss (α).
    pub alpha: f32,
    /// Weight of the courtesy loss (β).
    pub beta: f32,
    pub huber_delta: f32,
    /// Multiplies the whole trajectory loss (1 normally; 0 trains on the courtesy loss alone).
    pub trajectory_weight: f32,
    pub reward: Reward,
    pub learning_rate: f64,
}

fn rows_tensor(rows: Vec<f32>, shape: [usize; 3], device: &Device) -> Tensor<3> {
    Tensor::from_data(TensorData::new(rows, shape), device)
}

/// One step: `L = Huber(y⁰, ŷ⁰) + α Σ_m Huber(y^m, ŷ^m) + β Σ_m (ψ_m − J_φ(x, ŷ^m))²`
/// (paper eqs. (5)–(7)). `predictor` lives on the autodiff device so that J_φ passes gradients
/// to ŷ; only the generator's parameters are updated.
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
pub fn step_loss(
    generator: &Generator,
    predictor: &Multipath,
    examples: &[&Example],
    options: &StepOptions,
    device: &Device,
) -> (Tensor<1>, StepLosses) {
    let n = examples.len();
    let t = examples[0].logged_valid.len();
    let mut rng = rand_pcg::Pcg64Mcg::new(0x5eed);
    let bs: Vec<&AgentSample> = examples.iter().map(|e| &e.b).collect();
    let as_: Vec<&AgentSample> = examples.iter().map(|e| &e.a).collect();
    let batch_b = Batch::from_samples(
        &bs,
        &BatchAugment {
            condition_dropout: 1.0,
            history_mask_prob: 0.0,
        },
        &mut rng,
        device,
    );
    let embedding = predictor.encode(&batch_b).detach();
    let batch_a = (options.variant == Variant::Full)
        .then(|| Batch::from_samples(&as_, &BatchAugment::default(), &mut rng, device));
    let m_count = match options.variant {
        Variant::Baseline => 1,
        _ => examples.iter().map(|e| e.psi.len()).min().unwrap_or(1),
    };
    // B's frame → A's frame, per example: rotation by θ then translation.
    let (cos, sin): (Vec<f32>, Vec<f32>) = examples
        .iter()
        .map(|e| (e.a_from_b[0].cos(), e.a_from_b[0].sin()))
        .unzip();
    let col = |v: Vec<f32>| Tensor::<1>::from_data(TensorData::new(v, [n]), device).reshape([n, 1]);
    let (cos, sin) = (col(cos), col(sin));
    let tx = col(examples.iter().map(|e| e.a_from_b[1]).collect());
    let ty = col(examples.iter().map(|e| e.a_from_b[2]).collect());
    let mut traj_total: Option<Tensor<1>> = None;
    let mut court_total: Option<Tensor<1>> = None;
    for m in 0..m_count {
        let psi = Tensor::<1>::from_data(
            TensorData::new(examples.iter().map(|e| e.psi[m]).collect(), [n]),
            device,
        );
        let target = rows_tensor(
            examples
                .iter()
                .flat_map(|e| e.futures_b[m].iter().flat_map(|p| [p[0], p[1]]))
                .collect(),
            [n, t, 2],
            device,
        );
        let valid: Vec<f32> = examples
            .iter()
            .flat_map(|e| (0..t).map(move |s| if m > 0 || e.logged_valid[s] { 1.0 } else { 0.0 }))
            .collect();
        let valid = Tensor::<2>::from_data(TensorData::new(valid, [n, t]), device);
        let pred = generator.forward(embedding.clone(), psi.clone());
        let weight = if m == 0 { 1.0 } else { options.alpha };
        let l = huber_trajectory(pred.clone(), target, valid, options.huber_delta) * weight;
        traj_total = Some(match traj_total {
            Some(acc) => acc + l,
            None => l,
        });
        if let Some(batch_a) = &batch_a {
            let x = pred.clone().narrow(2, 0, 1).reshape([n, t]);
            let y = pred.narrow(2, 1, 1).reshape([n, t]);
            let xa = x.clone() * cos.clone() - y.clone() * sin.clone() + tx.clone();
            let ya = x * sin.clone() + y * cos.clone() + ty.clone();
            let in_a = Tensor::stack::<3>(vec![xa, ya], 2);
            let achieved = courtesy(predictor, batch_a, in_a, options.reward, 0.1).psi;
            let c = courtesy_loss(psi, achieved);
            court_total = Some(match court_total {
                Some(acc) => acc + c,
                None => c,
            });
        }
    }
    let traj = traj_total.expect("at least one target");
    let total = match &court_total {
        Some(c) => traj.clone() * options.trajectory_weight + c.clone() * options.beta,
        None => traj.clone() * options.trajectory_weight,
    };
    let losses = StepLosses {
        trajectory: traj.into_scalar(),
        courtesy: court_total.map_or(0.0, |c| c.into_scalar()),
        total: total.clone().into_scalar(),
    };
    (total, losses)
}
