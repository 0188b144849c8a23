//! The paper's evaluation of a generator (Sec. IV-D, Table II, Figs. 4–5): pure functions of
//! examples, the frozen predictor, the generator and the range predictor.
//!
//! Definitions (per held-out example, i.e. one ordered pair (A, B) in one window):
//! - **CourtesyMSE** `(ψ − J_φ(x, g(x, ψ)))²`, mean ± std over the requested ψ values of every
//!   example, for ψ = *data* (the label of B's logged future), *range* (the ψ of quantiles
//!   0.1, 0.2, …, 0.9 of the predicted range, [`psi_for_quantile`]) and *arbitrary* (9 evenly
//!   spaced values from the dataset's smallest to its largest ψ).
//! - **TrajADE** mean distance between `g(x, ψ_data)` and B's logged future over its valid steps.
//! - **corr_quantile** Pearson correlation of the input quantile and the achieved
//!   `J_φ(x, g(x, ψ_q))`, pooled over all examples and the 9 quantiles; `corr_quantile_high`
//!   the same over examples whose logged |ψ| exceeds the high-courtesy threshold.

use burn::tensor::{Device, Tensor, TensorData};
use scbg_courtesy::Reward;
use scbg_model::Multipath;
use serde::Serialize;

use crate::audience::audience_courtesy;
use crate::candidates::b_modes_for;
use crate::data::Example;
use crate::model::Generator;
use crate::range::{RangePredictor, psi_for_quantile, stored_embeddings};
use crate::tensors::{repeat_rows, to_vec};

/// The quantiles of the *range* evaluation and of Fig. 4.
pub const EVAL_QUANTILES: [f32; 9] = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9];

/// Generated futures of B and what J_φ says about them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Measured {
    /// `[example][k]` achieved ψ = E[r(Y_A) | x, ŷ] − E[r(Y_A) | x].
    pub psi: Vec<Vec<f32>>,
    /// `[example][k]` E[r(Y_A) | x, ŷ] (A's expected average speed for the default reward).
    pub e_cond: Vec<Vec<f32>>,
    /// `[example]` E[r(Y_A) | x].
    pub e_marg: Vec<f32>,
    /// `[example][k][T]` the generated futures in B's frame.
    pub futures_b: Vec<Vec<Vec<[f32; 2]>>>,
}

/// Generates B's future for every requested ψ of every example (`psi[i]` holds example `i`'s
/// values, the same count for all) and measures J_φ on each. Run it on a plain device.
pub fn generate_and_measure(
    generator: &Generator,
    predictor: &Multipath,
    examples: &[&Example],
    psi: &[Vec<f32>],
    reward: Reward,
    device: &Device,
) -> Measured {
    let k = psi.first().map_or(0, Vec::len);
    let mut out = Measured::default();
    if k == 0 {
        return out;
    }
    // Chunks of about 256 generated futures per forward.
    let chunk = (256 / k).max(1);
    for (c, exs) in examples.chunks(chunk).enumerate() {
        let n = exs.len();
        let rows = n * k;
        let psi_rows: Vec<f32> = (0..k)
            .flat_map(|j| (0..n).map(move |i| psi[c * chunk + i][j]))
            .collect();
        let embedding = repeat_rows(stored_embeddings(exs, device), k);
        let modes = b_modes_for(generator, predictor, exs, reward, device).repeat_rows(k);
        let pred = generator.forward(
            embedding,
            Tensor::from_data(TensorData::new(psi_rows, [rows]), device),
            modes,
        );
        measure_chunk(predictor, exs, pred, k, reward, device, &mut out);
    }
    out
}

/// J_φ of `k` futures per example of `exs` (`pred: [k · n, T, 2]`, row `j · n + i` is
/// example `i`'s `j`-th future, B's frame), appended to `out`.
pub(crate) fn measure_chunk(
    predictor: &Multipath,
    exs: &[&Example],
    pred: Tensor<3>,
    k: usize,
    reward: Reward,
    device: &Device,
    out: &mut Measured,
) {
    let n = exs.len();
    let [_, t, _] = pred.dims();
    // E[r(Y_A) | x] as the labels estimated it.
    let e_marg: Vec<f32> = exs.iter().map(|e| e.e_marg).collect();
    let (achieved, e_cond) = audience_courtesy(predictor, pred.clone(), exs, k, reward, device);
    let (achieved, e_cond) = (to_vec(achieved), to_vec(e_cond));
    let xy = to_vec(pred);
    for i in 0..n {
        let cond: Vec<f32> = (0..k).map(|j| e_cond[j * n + i]).collect();
        out.psi.push((0..k).map(|j| achieved[j * n + i]).collect());
        out.e_cond.push(cond);
        out.e_marg.push(e_marg[i]);
        out.futures_b.push(
            (0..k)
                .map(|j| {
                    let base = (j * n + i) * t * 2;
                    (0..t)
                        .map(|s| [xy[base + 2 * s], xy[base + 2 * s + 1]])
                        .collect()
                })
                .collect(),
        );
    }
}

/// The predicted 0.1 and 0.9 quantiles of ψ for each example.
pub fn predicted_ranges(
    range: &RangePredictor,
    examples: &[&Example],
    device: &Device,
) -> Vec<(f32, f32)> {
    if examples.is_empty() {
        return Vec::new();
    }
    let (low, high) = range.forward(stored_embeddings(examples, device));
    to_vec(low).into_iter().zip(to_vec(high)).collect()
}

/// Mean and standard deviation (population) of a set of values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MeanStd {
    /// The mean.
    pub mean: f64,
    /// The population standard deviation.
    pub std: f64,
}

impl MeanStd {
    /// Mean and standard deviation of `values`; `None` when empty.
    pub fn of(values: &[f64]) -> Option<Self> {
        if values.is_empty() {
            return None;
        }
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        Some(Self {
            mean,
            std: var.sqrt(),
        })
    }
}

/// Achieved courtesy at one input quantile (Figs. 4 and 5b).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct QuantilePoint {
    /// The input quantile (one of [`EVAL_QUANTILES`]).
    pub quantile: f32,
    /// Requested ψ, mean over examples.
    pub target_psi_mean: f64,
    /// Achieved ψ, mean ± std over examples.
    pub achieved_psi: MeanStd,
    /// E[r(Y_A) | x, ŷ], mean over examples (m/s for the default reward).
    pub a_expected_reward_mean: f64,
}

/// One variant's row of Table II, with the per-quantile curve.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VariantEval {
    /// CourtesyMSE (paper eq. 10) with ψ = the label of B's logged future, (m/s)² for the
    /// default reward; `None` without examples.
    pub courtesy_mse_data: Option<MeanStd>,
    /// CourtesyMSE with ψ at the quantiles [`EVAL_QUANTILES`] of the predicted range.
    pub courtesy_mse_range: Option<MeanStd>,
    /// CourtesyMSE with 9 evenly spaced ψ over the dataset's range
    /// ([`EvalOptions::arbitrary_min`] to [`EvalOptions::arbitrary_max`]).
    pub courtesy_mse_arbitrary: Option<MeanStd>,
    /// TrajADE (paper eq. 11) of `g(x, ψ_data)` against B's logged future over its valid
    /// steps, metres; mean ± std over examples.
    pub traj_ade: Option<MeanStd>,
    /// Pearson correlation of input quantile and achieved ψ, pooled over all examples.
    pub corr_quantile: Option<f64>,
    /// The same over the high-courtesy examples (logged |ψ| above
    /// [`EvalOptions::high_threshold`]).
    pub corr_quantile_high: Option<f64>,
    /// Mean over examples of the Pearson correlation of quantile and achieved ψ within the
    /// example (the pooled correlations also count differences between scenes).
    pub corr_quantile_within: Option<f64>,
    /// Number of examples evaluated.
    pub examples: usize,
    /// Number of them with logged |ψ| above the high-courtesy threshold.
    pub high_examples: usize,
    /// Achieved ψ per quantile over all examples (empty without examples).
    pub per_quantile: Vec<QuantilePoint>,
    /// The same over the high-courtesy examples (paper Fig. 4).
    pub per_quantile_high: Vec<QuantilePoint>,
}

/// What [`evaluate`] needs besides the models.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalOptions {
    /// Lower end of the dataset's ψ range, for the *arbitrary* evaluation.
    pub arbitrary_min: f32,
    /// Upper end of that range.
    pub arbitrary_max: f32,
    /// |ψ_logged| above this counts as high courtesy (corr_quantile_high).
    pub high_threshold: f32,
    /// The reward r(y_A) of J_φ (as used for the labels).
    pub reward: Reward,
}

/// Evaluates one generator variant on held-out examples (see the module docs).
pub fn evaluate(
    generator: &Generator,
    range: &RangePredictor,
    predictor: &Multipath,
    examples: &[&Example],
    options: &EvalOptions,
    device: &Device,
) -> VariantEval {
    evaluate_measured(generator, range, predictor, examples, options, device).0
}

/// [`evaluate`], also returning what was generated and measured: per example, index 0 is
/// `g(x, ψ_data)`, `1..=9` the futures for [`EVAL_QUANTILES`], then the 9 arbitrary ψ.
pub fn evaluate_measured(
    generator: &Generator,
    range: &RangePredictor,
    predictor: &Multipath,
    examples: &[&Example],
    options: &EvalOptions,
    device: &Device,
) -> (VariantEval, Measured) {
    let ranges = predicted_ranges(range, examples, device);
    let requested = requested_psi(examples, &ranges, options);
    let m = generate_and_measure(
        generator,
        predictor,
        examples,
        &requested,
        options.reward,
        device,
    );
    (summarize(examples, &requested, &m, options), m)
}

/// The ψ an evaluation requests of each example: `[ψ_data, ψ of the 9 quantiles of its
/// predicted range (`ranges`), the 9 arbitrary values]`.
pub(crate) fn requested_psi(
    examples: &[&Example],
    ranges: &[(f32, f32)],
    options: &EvalOptions,
) -> Vec<Vec<f32>> {
    let nq = EVAL_QUANTILES.len();
    let arbitrary: Vec<f32> = (0..nq)
        .map(|j| {
            options.arbitrary_min
                + (options.arbitrary_max - options.arbitrary_min) * j as f32 / (nq - 1) as f32
        })
        .collect();
    examples
        .iter()
        .zip(ranges)
        .map(|(e, &(lo, hi))| {
            let mut v = vec![e.psi[0]];
            v.extend(EVAL_QUANTILES.iter().map(|&q| psi_for_quantile(q, lo, hi)));
            v.extend(&arbitrary);
            v
        })
        .collect()
}

/// Table II's row and the curves of the futures `m` produced for `requested`
/// ([`requested_psi`]).
pub(crate) fn summarize(
    examples: &[&Example],
    requested: &[Vec<f32>],
    m: &Measured,
    options: &EvalOptions,
) -> VariantEval {
    let nq = EVAL_QUANTILES.len();
    let sq = |i: usize, j: usize| f64::from(requested[i][j] - m.psi[i][j]).powi(2);
    let n = examples.len();
    let data: Vec<f64> = (0..n).map(|i| sq(i, 0)).collect();
    let range_err: Vec<f64> = (0..n)
        .flat_map(|i| (1..=nq).map(move |j| (i, j)))
        .map(|(i, j)| sq(i, j))
        .collect();
    let arbitrary_err: Vec<f64> = (0..n)
        .flat_map(|i| (nq + 1..=2 * nq).map(move |j| (i, j)))
        .map(|(i, j)| sq(i, j))
        .collect();
    let ade: Vec<f64> = examples
        .iter()
        .zip(&m.futures_b)
        .filter_map(|(e, f)| {
            let (sum, count) = f[0]
                .iter()
                .zip(&e.futures_b[0])
                .zip(&e.logged_valid)
                .filter(|(_, v)| **v)
                .fold((0.0f64, 0usize), |(s, c), ((p, g), _)| {
                    let d = f64::from((p[0] - g[0]).hypot(p[1] - g[1]));
                    (s + d, c + 1)
                });
            (count > 0).then(|| sum / count as f64)
        })
        .collect();
    let corr = |keep: &dyn Fn(usize) -> bool| {
        let (mut q, mut a) = (Vec::new(), Vec::new());
        for i in (0..n).filter(|&i| keep(i)) {
            for (j, &qq) in EVAL_QUANTILES.iter().enumerate() {
                q.push(f64::from(qq));
                a.push(f64::from(m.psi[i][1 + j]));
            }
        }
        scbg_metrics::pearson(&q, &a)
    };
    let high = |i: usize| examples[i].psi[0].abs() > options.high_threshold;
    let curve = |keep: &dyn Fn(usize) -> bool| -> Vec<QuantilePoint> {
        let idx: Vec<usize> = (0..n).filter(|&i| keep(i)).collect();
        if idx.is_empty() {
            return Vec::new();
        }
        EVAL_QUANTILES
            .iter()
            .enumerate()
            .map(|(j, &q)| {
                let achieved: Vec<f64> = idx.iter().map(|&i| f64::from(m.psi[i][1 + j])).collect();
                let mean = |f: &dyn Fn(usize) -> f32| {
                    idx.iter().map(|&i| f64::from(f(i))).sum::<f64>() / idx.len() as f64
                };
                QuantilePoint {
                    quantile: q,
                    target_psi_mean: mean(&|i| requested[i][1 + j]),
                    achieved_psi: MeanStd::of(&achieved).expect("non-empty"),
                    a_expected_reward_mean: mean(&|i| m.e_cond[i][1 + j]),
                }
            })
            .collect()
    };
    let per_quantile = curve(&|_| true);
    let per_quantile_high = curve(&high);
    VariantEval {
        courtesy_mse_data: MeanStd::of(&data),
        courtesy_mse_range: MeanStd::of(&range_err),
        courtesy_mse_arbitrary: MeanStd::of(&arbitrary_err),
        traj_ade: MeanStd::of(&ade),
        corr_quantile: corr(&|_| true),
        corr_quantile_high: corr(&high),
        corr_quantile_within: {
            let q: Vec<f64> = EVAL_QUANTILES.iter().map(|&q| f64::from(q)).collect();
            let per: Vec<f64> = (0..n)
                .filter_map(|i| {
                    let a: Vec<f64> = (0..nq).map(|j| f64::from(m.psi[i][1 + j])).collect();
                    scbg_metrics::pearson(&q, &a)
                })
                .collect();
            MeanStd::of(&per).map(|m| m.mean)
        },
        examples: n,
        high_examples: (0..n).filter(|&i| high(i)).count(),
        per_quantile,
        per_quantile_high,
    }
}
