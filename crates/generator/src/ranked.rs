//! Sample and rank: a controllable B without a learned generator. B's future for a requested
//! courtesy is chosen among the `M` futures sampled from B's marginal prediction — the very
//! candidates the labels score and the generator trains on — by their ψ labels (J_φ):
//!
//! - a quantile `q` takes the candidate of rank `⌊q·M⌋` (clamped to `M − 1`) of the candidates
//!   sorted by ψ, i.e. the empirical q-quantile of courtesy among B's predicted behaviours;
//! - an explicit ψ takes the candidate whose label is nearest.
//!
//! Every future is a sample of the predictor, so it is as realistic as the predictor; control
//! is as faithful as J_φ's ranking and as wide as the candidates' spread. It costs the labels
//! of the `M` futures per pair (B's marginal forward and one conditional forward of A over
//! the futures, A's scene encoded once) and no training.
//!
//! Its achieved ψ (J_φ of the chosen future) is the chosen label by construction: in an
//! evaluation, its CourtesyMSE and corr(q, ψ) measure how densely the candidates' labels cover
//! the requested ψ, not how faithfully a model follows them; only a ground truth (the
//! synthetic oracle's ψ_true) judges it like the generators.
//!
//! **Architecture invariant:** like the rest of the crate, no files; the predictor is frozen.

use burn::tensor::{Device, Tensor, TensorData};
use scbg_courtesy::Reward;
use scbg_model::Multipath;

use crate::courtesy::Courtesy;
use crate::data::Example;
use crate::eval::{
    EVAL_QUANTILES, EvalOptions, Measured, VariantEval, measure_chunk, predicted_ranges,
    requested_psi, summarize,
};

/// The index of the candidate a ranked choice takes at quantile `q` among `n` candidates
/// sorted by ψ: `⌊q·n⌋`, at most `n − 1`.
pub fn rank_at(q: f32, n: usize) -> usize {
    ((f64::from(q) * n as f64).floor() as usize).min(n.saturating_sub(1))
}

/// The candidate (an index into `labels`) a ranked choice takes for `courtesy`; `None`
/// without a candidate of finite label (NaN labels are never chosen).
pub fn ranked_choice(labels: &[f32], courtesy: Courtesy) -> Option<usize> {
    if labels.iter().all(|v| v.is_nan()) {
        return None;
    }
    match courtesy {
        Courtesy::Quantile(q) => {
            let mut order: Vec<usize> = (0..labels.len()).collect();
            // NaN last, ties in candidate order: deterministic.
            order.sort_by(|&i, &j| {
                let key = |k: usize| (labels[k].is_nan(), labels[k]);
                let (a, b) = (key(i), key(j));
                a.0.cmp(&b.0).then(a.1.total_cmp(&b.1))
            });
            let finite = labels.iter().filter(|v| !v.is_nan()).count();
            Some(order[rank_at(q, finite)])
        }
        Courtesy::Psi(p) => (0..labels.len())
            .filter(|&k| !labels[k].is_nan())
            .min_by(|&i, &j| (labels[i] - p).abs().total_cmp(&(labels[j] - p).abs())),
    }
}

/// The name of the ranked choice among the variants of a report.
pub const RANKED: &str = "ranked";

/// J_φ of given futures of B (`futures[i][k]`, B's frame, the same count `k` for every
/// example): the [`Measured`] that [`crate::eval::generate_and_measure`] returns for
/// generated ones.
pub fn measure_futures(
    predictor: &Multipath,
    examples: &[&Example],
    futures: &[Vec<Vec<[f32; 2]>>],
    reward: Reward,
    device: &Device,
) -> Measured {
    let mut out = Measured::default();
    let k = futures.first().map_or(0, Vec::len);
    if k == 0 {
        return out;
    }
    let chunk = (256 / k).max(1);
    for (c, exs) in examples.chunks(chunk).enumerate() {
        let n = exs.len();
        let t = futures[c * chunk].first().map_or(0, Vec::len);
        // Row j·n + i is example i's j-th future.
        let xy: Vec<f32> = (0..k)
            .flat_map(|j| (0..n).map(move |i| (i, j)))
            .flat_map(|(i, j)| futures[c * chunk + i][j].iter().flat_map(|p| [p[0], p[1]]))
            .collect();
        let pred = Tensor::<3>::from_data(TensorData::new(xy, [n * k, t, 2]), device);
        measure_chunk(predictor, exs, pred, k, reward, device, &mut out);
    }
    out
}

/// Evaluates the ranked choice on held-out examples with the requests and summaries of a
/// generator variant ([`crate::eval::evaluate_measured`]): the candidates are each example's
/// sampled futures (the logged one, index 0, is left out: it is the answer the evaluation
/// compares with, and a deployed B does not have it). ψ_data and the arbitrary ψ take the
/// nearest label; the quantiles take the candidate of that rank, as the policy does, while
/// the ψ they are scored against (CourtesyMSE *range*, the curves' target) stays the range
/// predictor's ψ for the quantile — so that column measures how far the rank's label is from
/// the range predictor, not the policy's fidelity (see the module docs). `None` when an
/// example has no sampled future.
pub fn evaluate_ranked(
    range: &crate::range::RangePredictor,
    predictor: &Multipath,
    examples: &[&Example],
    options: &EvalOptions,
    device: &Device,
) -> Option<(VariantEval, Measured)> {
    if examples.is_empty() || examples.iter().any(|e| e.futures_b.len() < 2) {
        return None;
    }
    let ranges = predicted_ranges(range, examples, device);
    let requested = requested_psi(examples, &ranges, options);
    let nq = EVAL_QUANTILES.len();
    let futures: Vec<Vec<Vec<[f32; 2]>>> = examples
        .iter()
        .zip(&requested)
        .map(|(e, req)| {
            let labels = &e.psi[1..];
            req.iter()
                .enumerate()
                .map(|(j, &psi)| {
                    let courtesy = if (1..=nq).contains(&j) {
                        Courtesy::Quantile(EVAL_QUANTILES[j - 1])
                    } else {
                        Courtesy::Psi(psi)
                    };
                    // A NaN-only example: its first candidate (the scores will say NaN).
                    let k = ranked_choice(labels, courtesy).unwrap_or(0);
                    e.futures_b[1 + k].clone()
                })
                .collect()
        })
        .collect();
    let m = measure_futures(predictor, examples, &futures, options.reward, device);
    Some((summarize(examples, &requested, &m, options), m))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_take_ranks_and_psi_the_nearest_label() {
        let labels = [0.3, -0.2, 0.1, 0.0];
        // Sorted: -0.2 (1), 0.0 (3), 0.1 (2), 0.3 (0).
        let q = |q| ranked_choice(&labels, Courtesy::Quantile(q)).unwrap();
        assert_eq!([q(0.0), q(0.25), q(0.5), q(0.75), q(1.0)], [1, 3, 2, 0, 0]);
        let p = |p| ranked_choice(&labels, Courtesy::Psi(p)).unwrap();
        assert_eq!([p(-5.0), p(0.04), p(0.06), p(9.0)], [1, 3, 2, 0]);
        assert_eq!(ranked_choice(&[], Courtesy::Quantile(0.5)), None);
        assert_eq!(ranked_choice(&[f32::NAN], Courtesy::Psi(0.0)), None);
    }

    #[test]
    fn nan_labels_are_never_chosen_while_others_exist() {
        let labels = [f32::NAN, 1.0, 2.0];
        for q in [0.0, 0.5, 0.99, 1.0] {
            assert_ne!(ranked_choice(&labels, Courtesy::Quantile(q)), Some(0));
        }
        assert_eq!(ranked_choice(&labels, Courtesy::Quantile(1.0)), Some(2));
        assert_eq!(ranked_choice(&labels, Courtesy::Psi(0.0)), Some(1));
    }

    #[test]
    fn rank_at_spreads_the_quantiles_over_the_candidates() {
        let ranks: Vec<usize> = EVAL_QUANTILES.iter().map(|&q| rank_at(q, 8)).collect();
        assert_eq!(ranks, [0, 1, 2, 3, 4, 4, 5, 6, 7]);
        let ranks: Vec<usize> = EVAL_QUANTILES.iter().map(|&q| rank_at(q, 9)).collect();
        assert_eq!(ranks, [0, 1, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(rank_at(0.0, 4), 0);
        assert_eq!(rank_at(1.0, 8), 7);
        assert_eq!(rank_at(0.5, 0), 0);
    }
}
