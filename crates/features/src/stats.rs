//! Feature standardisation: per-channel mean and standard deviation over valid entries,
//! applied as `clamp((v - mean) / std, -15, 15)` (`shared/spec/multipathpp.md`).

use serde::{Deserialize, Serialize};

use crate::sample::{AGENT_FEATURES, AgentSample, DIFF_FEATURES, ROAD_FEATURES};

/// Mean and standard deviation of each feature channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeatureStats {
    /// `[AGENT_FEATURES]` mean of the per-step agent features.
    pub agent_mean: Vec<f32>,
    /// `[AGENT_FEATURES]` standard deviation of the per-step agent features (≥ 1e-3).
    pub agent_std: Vec<f32>,
    /// `[DIFF_FEATURES]` mean of the per-step difference features.
    pub diff_mean: Vec<f32>,
    /// `[DIFF_FEATURES]` standard deviation of the difference features (≥ 1e-3).
    pub diff_std: Vec<f32>,
    /// `[ROAD_FEATURES]` mean of the road-segment features.
    pub road_mean: Vec<f32>,
    /// `[ROAD_FEATURES]` standard deviation of the road-segment features (≥ 1e-3).
    pub road_std: Vec<f32>,
}

/// Running sums for one group of channels.
struct Acc {
    n: Vec<f64>,
    sum: Vec<f64>,
    sum2: Vec<f64>,
}

impl Acc {
    fn new(d: usize) -> Self {
        Self {
            n: vec![0.0; d],
            sum: vec![0.0; d],
            sum2: vec![0.0; d],
        }
    }
    fn add(&mut self, row: &[f32]) {
        for (k, &v) in row.iter().enumerate() {
            self.n[k] += 1.0;
            self.sum[k] += f64::from(v);
            self.sum2[k] += f64::from(v) * f64::from(v);
        }
    }
    fn finish(self) -> (Vec<f32>, Vec<f32>) {
        let mean: Vec<f64> = self
            .sum
            .iter()
            .zip(&self.n)
            .map(|(s, n)| if *n > 0.0 { s / n } else { 0.0 })
            .collect();
        let std = self
            .sum2
            .iter()
            .zip(&self.n)
            .zip(&mean)
            .map(|((s2, n), m)| {
                if *n > 1.0 {
                    (s2 / n - m * m).max(0.0).sqrt().max(1e-3)
                } else {
                    1.0
                }
            })
            .map(|v| v as f32)
            .collect();
        (mean.into_iter().map(|v| v as f32).collect(), std)
    }
}

impl FeatureStats {
    /// Identity statistics (mean 0, std 1).
    pub fn identity() -> Self {
        Self {
            agent_mean: vec![0.0; AGENT_FEATURES],
            agent_std: vec![1.0; AGENT_FEATURES],
            diff_mean: vec![0.0; DIFF_FEATURES],
            diff_std: vec![1.0; DIFF_FEATURES],
            road_mean: vec![0.0; ROAD_FEATURES],
            road_std: vec![1.0; ROAD_FEATURES],
        }
    }

    /// Fits statistics over the valid rows of the given samples (target and other agents).
    pub fn fit<'a>(samples: impl IntoIterator<Item = &'a AgentSample>) -> Self {
        let (mut agent, mut diff, mut road) = (
            Acc::new(AGENT_FEATURES),
            Acc::new(DIFF_FEATURES),
            Acc::new(ROAD_FEATURES),
        );
        for s in samples {
            for rows in [&s.target_history, &s.others_history] {
                for row in rows.chunks_exact(AGENT_FEATURES).filter(|r| r[6] > 0.0) {
                    agent.add(row);
                }
            }
            for rows in [&s.target_diffs, &s.others_diffs] {
                for row in rows.chunks_exact(DIFF_FEATURES).filter(|r| r[4] > 0.0) {
                    diff.add(row);
                }
            }
            for (row, _) in s
                .road_segments
                .chunks_exact(ROAD_FEATURES)
                .zip(&s.road_valid)
                .filter(|(_, v)| **v)
            {
                road.add(row);
            }
        }
        let (agent_mean, agent_std) = agent.finish();
        let (diff_mean, diff_std) = diff.finish();
        let (road_mean, road_std) = road.finish();
        Self {
            agent_mean,
            agent_std,
            diff_mean,
            diff_std,
            road_mean,
            road_std,
        }
    }

    fn apply(
        rows: &mut [f32],
        width: usize,
        mean: &[f32],
        std: &[f32],
        keep: impl Fn(&[f32]) -> bool,
    ) {
        for row in rows.chunks_exact_mut(width) {
            if keep(row) {
                for k in 0..width {
                    row[k] = ((row[k] - mean[k]) / std[k]).clamp(-15.0, 15.0);
                }
            }
        }
    }

    /// Standardises a sample's inputs in place; invalid rows stay zero.
    pub fn normalize(&self, s: &mut AgentSample) {
        for rows in [&mut s.target_history, &mut s.others_history] {
            Self::apply(
                rows,
                AGENT_FEATURES,
                &self.agent_mean,
                &self.agent_std,
                |r| r[6] > 0.0,
            );
        }
        for rows in [&mut s.target_diffs, &mut s.others_diffs] {
            Self::apply(rows, DIFF_FEATURES, &self.diff_mean, &self.diff_std, |r| {
                r[4] > 0.0
            });
        }
        for (row, v) in s
            .road_segments
            .chunks_exact_mut(ROAD_FEATURES)
            .zip(&s.road_valid)
        {
            if *v {
                for ((x, m), sd) in row.iter_mut().zip(&self.road_mean).zip(&self.road_std) {
                    *x = ((*x - m) / sd).clamp(-15.0, 15.0);
                }
            }
        }
    }
}
