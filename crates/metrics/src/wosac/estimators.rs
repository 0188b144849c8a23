//! Histogram and Bernoulli estimators and the per-feature likelihoods (§6–§7 of the spec).

use super::SIMULATED_STEPS;

/// A fixed-width histogram with pseudocounts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct HistogramSpec {
    /// Lower end of the first bin.
    pub min: f32,
    /// Upper end of the last bin.
    pub max: f32,
    /// Number of bins.
    pub num_bins: usize,
    /// Added to every bin count.
    pub pseudocount: f32,
}

/// The Bernoulli estimator: a 2-bin histogram over `[−0.5, 1.5]` with pseudocount 0.001.
pub(crate) const BERNOULLI: HistogramSpec = HistogramSpec::new(-0.5, 1.5, 2, 0.001);

impl HistogramSpec {
    pub const fn new(min: f32, max: f32, num_bins: usize, pseudocount: f32) -> Self {
        Self {
            min,
            max,
            num_bins,
            pseudocount,
        }
    }

    /// The `num_bins + 1` float32 edges: `min + k·δ` with `δ = (max − min)/num_bins`, and
    /// exactly `max` last.
    pub fn edges(&self) -> Vec<f32> {
        let n = self.num_bins;
        let delta = (self.max - self.min) / n as f32;
        (0..=n)
            .map(|k| {
                if k == n {
                    self.max
                } else {
                    self.min + k as f32 * delta
                }
            })
            .collect()
    }

    /// Bin of `x`: clipped to `[min, max]`, bin `k` holds `e_k ≤ x < e_{k+1}`, the last bin
    /// also holds `max`, and NaN goes into the last bin.
    pub fn bin(&self, edges: &[f32], x: f32) -> usize {
        let last = self.num_bins - 1;
        if x.is_nan() {
            return last;
        }
        let x = x.clamp(self.min, self.max);
        edges[1..self.num_bins]
            .iter()
            .take_while(|&&e| e <= x)
            .count()
            .min(last)
    }

    /// `ln p_k` per bin with `p_k = (c_k + pc) / (N + num_bins · pc)` over the sim samples.
    pub fn log_probabilities(&self, edges: &[f32], sim: impl IntoIterator<Item = f32>) -> Vec<f32> {
        let mut counts = vec![0usize; self.num_bins];
        let mut total = 0usize;
        for x in sim {
            counts[self.bin(edges, x)] += 1;
            total += 1;
        }
        let denominator = total as f32 + self.num_bins as f32 * self.pseudocount;
        counts
            .iter()
            .map(|&c| ((c as f32 + self.pseudocount) / denominator).ln())
            .collect()
    }
}

/// `exp(Σ_{(i,f)∈M} ll[i,f] / |M|)` for a time-series feature: each evaluated object's 80 log
/// values are scored against the histogram of all its simulated values (every rollout, every
/// future step, unmasked). Values are `[object * 80 + step]`; `|M| = 0` gives NaN.
pub(crate) fn time_series_likelihood(
    spec: HistogramSpec,
    log: &[f32],
    sims: &[&[f32]],
    mask: &[bool],
    num_objects: usize,
) -> f32 {
    let edges = spec.edges();
    let mut sum = 0.0f64;
    let mut count = 0usize;
    for i in 0..num_objects {
        let row = i * SIMULATED_STEPS..(i + 1) * SIMULATED_STEPS;
        let ln_p = spec.log_probabilities(
            &edges,
            sims.iter().flat_map(|s| s[row.clone()].iter().copied()),
        );
        for k in row {
            if mask[k] {
                sum += f64::from(ln_p[spec.bin(&edges, log[k])]);
                count += 1;
            }
        }
    }
    ((sum / count as f64) as f32).exp()
}

/// `exp(mean over objects of ln P(log_i))` for an indication feature, with `P` the Bernoulli
/// fitted to that object's values over the rollouts (`sims[rollout][object]`).
pub(crate) fn indicator_likelihood(log: &[bool], sims: &[Vec<bool>]) -> f32 {
    let edges = BERNOULLI.edges();
    let as_value = |b: bool| if b { 1.0 } else { 0.0 };
    let mut sum = 0.0f64;
    for (i, &observed) in log.iter().enumerate() {
        let ln_p = BERNOULLI.log_probabilities(&edges, sims.iter().map(|s| as_value(s[i])));
        sum += f64::from(ln_p[BERNOULLI.bin(&edges, as_value(observed))]);
    }
    ((sum / log.len() as f64) as f32).exp()
}
