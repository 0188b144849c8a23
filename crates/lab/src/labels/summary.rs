//! What `scbg label` reports of its labels: the spread of ψ, its agreement with the latent
//! courtesy and with the oracle (`summary.json`).

use std::collections::BTreeMap;

use scbg_courtesy::Reward;
use scbg_courtesy::label::LabelOptions;
use scbg_synth::GroundTruth;
use serde::Serialize;

use super::LabelRow;

/// Spearman(ψ of the logged y_B with roles (A, B) as in the ground truth, latent courtesy c)
/// per family: `{family: (rho, n)}`.
pub fn spearman_latent(
    rows: &[LabelRow],
    truth: &[GroundTruth],
) -> BTreeMap<String, (Option<f64>, usize)> {
    let truth: BTreeMap<&str, &GroundTruth> =
        truth.iter().map(|t| (t.scenario_id.as_str(), t)).collect();
    let mut by_family: BTreeMap<String, (Vec<f64>, Vec<f64>)> = BTreeMap::new();
    for r in rows.iter().filter(|r| r.sample == 0) {
        if let Some(t) = truth.get(r.scenario_id.as_str())
            && r.a_id == t.a_id
            && r.b_id == t.b_id
        {
            let e = by_family.entry(t.family.name().to_string()).or_default();
            e.0.push(f64::from(r.psi));
            e.1.push(t.courtesy);
        }
    }
    by_family
        .into_iter()
        .map(|(f, (x, y))| (f, (scbg_metrics::spearman(&x, &y), x.len())))
        .collect()
}

/// The spread of ψ that B's future causes: the square root of the mean, over pair roles, of
/// the variance of ψ across that role's futures (logged and sampled). When it is small next to
/// the overall std, ψ says more about the scene than about what B does.
pub fn within_pair_std(rows: &[LabelRow]) -> f64 {
    let mut groups: BTreeMap<(&str, u32, i64, i64), Vec<f64>> = BTreeMap::new();
    for r in rows {
        groups
            .entry((r.scenario_id.as_str(), r.window_step, r.a_id, r.b_id))
            .or_default()
            .push(f64::from(r.psi));
    }
    let vars: Vec<f64> = groups
        .values()
        .filter(|v| v.len() > 1)
        .map(|v| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64
        })
        .collect();
    (vars.iter().sum::<f64>() / vars.len().max(1) as f64).sqrt()
}

/// Mean and population standard deviation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Spread {
    /// Mean.
    pub mean: f64,
    /// Population standard deviation.
    pub std: f64,
}

/// ψ over every future, logged and sampled.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PsiAll {
    /// Mean.
    pub mean: f64,
    /// Population standard deviation.
    pub std: f64,
    /// Smallest ψ.
    pub min: f64,
    /// Largest ψ.
    pub max: f64,
    /// Share of futures with |ψ| > 2 m/s (the paper's high-courtesy threshold).
    pub fraction_abs_gt_2: f64,
}

/// Spearman's ρ of one family and the number of pairs it is over.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FamilyRho {
    /// Spearman's ρ (`None` when undefined: fewer than two pairs or no spread).
    pub rho: Option<f64>,
    /// Number of pairs.
    pub n: usize,
}

/// `summary.json` of a label run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LabelSummary {
    /// Labelled futures.
    pub rows: usize,
    /// Predictors whose ψ is averaged (1, or the size of the ensemble of `scbg label --model
    /// P1 --model P2 …`).
    pub predictors: usize,
    /// Labelled pair roles (= logged futures).
    pub pairs_roles: usize,
    /// Futures sampled from B's marginal prediction per pair role and labelled
    /// ([`LabelOptions::labelled_samples`]).
    pub samples_per_pair: usize,
    /// More futures of B sampled per pair role for the estimate of E[r(Y_A) | x] alone, not
    /// labelled ([`LabelOptions::baseline_futures`]; 0 with the direct estimate, or when they
    /// are kept, [`LabelOptions::keep_baseline`]).
    pub baseline_samples: usize,
    /// Whether the baseline's futures are labelled and kept after the first sampled ones
    /// ([`LabelOptions::keep_baseline`]; then `samples_per_pair` counts them).
    pub keep_baseline: bool,
    /// Steps of the lane moves labelled after the sampled futures
    /// ([`LabelOptions::lane_move_steps`]; 0: none).
    pub lane_move_steps: usize,
    /// What a lane move may ask of A ([`LabelOptions::lane_move_room`]).
    pub lane_move_room: scbg_features::FollowerRoom,
    /// Lane moves labelled (rows after the sampled futures of their role).
    pub lane_moves: usize,
    /// The reward r(y_A).
    pub reward: Reward,
    /// How E[r(Y_A) | x] was estimated.
    pub marginal: scbg_courtesy::label::MarginalEstimate,
    /// Whose reward counts (A alone, or B's neighbours).
    pub audience: scbg_courtesy::Audience,
    /// Mean number of agents whose reward a logged future's ψ counts (1 for the pair).
    pub audience_size_mean: f64,
    /// ψ of the logged futures.
    pub psi_logged: Spread,
    /// See [`within_pair_std`].
    pub psi_within_pair_std: f64,
    /// ψ of every future.
    pub psi_all: PsiAll,
    /// Spearman(ψ of the logged future, latent courtesy) per family (synthetic data only).
    pub spearman_latent: BTreeMap<String, FamilyRho>,
    /// Agreement with the simulator's ψ_true (synthetic data with its ground truth only).
    pub fidelity: Option<crate::fidelity::Fidelity>,
    /// The same on the predictor's held-out (validation) scenes only, which it never trained
    /// on (`scbg label`; absent where the split is not known).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fidelity_held_out: Option<crate::fidelity::Fidelity>,
}

impl LabelSummary {
    /// The summary of `rows` labelled with `options`; `truth` adds the latent-courtesy check.
    pub fn of(rows: &[LabelRow], options: LabelOptions, truth: Option<&[GroundTruth]>) -> Self {
        let logged: Vec<f64> = rows
            .iter()
            .filter(|r| r.sample == 0)
            .map(|r| f64::from(r.psi))
            .collect();
        let all: Vec<f64> = rows.iter().map(|r| f64::from(r.psi)).collect();
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        let std = |v: &[f64]| {
            (v.iter().map(|x| (x - mean(v)).powi(2)).sum::<f64>() / v.len().max(1) as f64).sqrt()
        };
        let high = all.iter().filter(|p| p.abs() > 2.0).count();
        Self {
            rows: rows.len(),
            predictors: 1,
            pairs_roles: logged.len(),
            samples_per_pair: options.labelled_samples(),
            baseline_samples: if options.keep_baseline {
                0
            } else {
                options.baseline_futures()
            },
            keep_baseline: options.keep_baseline,
            lane_move_steps: options.lane_move_steps,
            lane_move_room: options.lane_move_room,
            lane_moves: rows
                .iter()
                .filter(|r| r.sample as usize > options.labelled_samples())
                .count(),
            reward: options.reward,
            marginal: options.marginal,
            audience: options.audience,
            audience_size_mean: rows
                .iter()
                .filter(|r| r.sample == 0)
                .map(|r| f64::from(r.audience_size))
                .sum::<f64>()
                / logged.len().max(1) as f64,
            psi_logged: Spread {
                mean: mean(&logged),
                std: std(&logged),
            },
            psi_within_pair_std: within_pair_std(rows),
            psi_all: PsiAll {
                mean: mean(&all),
                std: std(&all),
                min: all.iter().copied().fold(f64::INFINITY, f64::min),
                max: all.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                fraction_abs_gt_2: high as f64 / all.len().max(1) as f64,
            },
            spearman_latent: truth
                .map(|t| spearman_latent(rows, t))
                .unwrap_or_default()
                .into_iter()
                .map(|(f, (rho, n))| (f, FamilyRho { rho, n }))
                .collect(),
            // The oracle scores ψ toward A alone: no fidelity for another audience.
            fidelity: truth
                .filter(|_| options.audience == scbg_courtesy::Audience::Pair)
                .and_then(|t| crate::fidelity::fidelity(rows, t, options.labelled_samples())),
            fidelity_held_out: None,
        }
    }

    /// The lines `scbg label` prints.
    pub fn to_text(&self) -> String {
        let moves = if self.lane_moves > 0 {
            format!(", then {} lane moves of them", self.lane_moves)
        } else {
            String::new()
        };
        let mut s = format!(
            "labelled {} futures ({} pair roles × {} each{moves}); ψ of logged futures: mean {:.3}, std {:.3}; std within a pair role {:.3}; |ψ| > 2 for {:.1} % of all",
            self.rows,
            self.pairs_roles,
            1 + self.samples_per_pair,
            self.psi_logged.mean,
            self.psi_logged.std,
            self.psi_within_pair_std,
            100.0 * self.psi_all.fraction_abs_gt_2
        );
        if self.baseline_samples > 0 {
            s += &format!(
                "; E[r | x] averaged over {} sampled futures of B",
                self.samples_per_pair + self.baseline_samples
            );
        }
        if self.predictors > 1 {
            s += &format!(
                "\nψ averaged over an ensemble of {} predictors",
                self.predictors
            );
        }
        for (family, r) in &self.spearman_latent {
            s += &format!(
                "\nSpearman(ψ, latent courtesy) {family}: {} (n = {})",
                r.rho.map_or("-".into(), |r| format!("{r:.3}")),
                r.n
            );
        }
        if self.audience != scbg_courtesy::Audience::Pair {
            s += &format!(
                "\naudience {:?}: {:.2} agents per ψ on average (A and B's neighbours); no ψ_true (the oracle scores A alone)",
                self.audience, self.audience_size_mean
            );
        }
        if let Some(f) = &self.fidelity {
            s += "\nfidelity of ψ_label against the simulator's ψ_true:\n";
            s += &f.to_markdown();
        }
        if let Some(f) = &self.fidelity_held_out {
            s += "\nthe same on the predictor's held-out scenes:\n";
            s += &f.to_markdown();
        }
        s
    }
}
