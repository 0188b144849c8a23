//! Courtesy fidelity: how the learned courtesy (labels ψ, generated futures) agrees with
//! ψ_true, the synthetic simulator's counterfactual oracle ([`scbg_synth::Scenario`]).
//!
//! Only the pair role a ground-truth line describes (A = the SDC, B = the vehicle with the
//! latent courtesy, in the window at the scene's current step) has a ψ_true: the oracle knows
//! how A reacts to B, not how B reacts to A.

use std::collections::BTreeMap;
use std::path::Path;

use scbg_courtesy::label::LabelledRole;
use scbg_scene::Pose2;
use scbg_synth::{CURRENT_STEP, GroundTruth, Scenario};
use serde::Serialize;

use crate::label_table::LabelRow;

/// Key of the pooled entry beside the per-family ones.
pub const POOLED: &str = "all";

/// The ground-truth lines of a synthetic run by scenario id.
#[derive(Debug, Clone)]
pub struct TruthIndex<'a>(BTreeMap<&'a str, &'a GroundTruth>);

impl<'a> TruthIndex<'a> {
    /// Indexes `truth` by scenario id.
    pub fn new(truth: &'a [GroundTruth]) -> Self {
        Self(truth.iter().map(|t| (t.scenario_id.as_str(), t)).collect())
    }

    /// The line of a scenario.
    pub fn get(&self, scenario_id: &str) -> Option<&'a GroundTruth> {
        self.0.get(scenario_id).copied()
    }
}

/// Points in an agent's frame moved to the scenario's world frame (a sample's
/// `world_from_agent` is in the scenario's own world frame).
pub fn world_points(world_from_agent: &Pose2, points: &[[f32; 2]]) -> Vec<[f64; 2]> {
    points
        .iter()
        .map(|p| {
            let (x, y) = world_from_agent.world_from_agent(f64::from(p[0]), f64::from(p[1]));
            [x, y]
        })
        .collect()
}

/// Whether a pair role in a window is the one `truth` describes.
pub fn is_truth_role(truth: &GroundTruth, window_step: usize, a_id: i64, b_id: i64) -> bool {
    window_step == CURRENT_STEP && a_id == truth.a_id && b_id == truth.b_id
}

/// ψ_true of each labelled future of a role (logged first, then the sampled ones); empty when
/// the role is not the ground truth's, `None` for a future the oracle cannot score.
pub fn psi_true_of_role(truth: &GroundTruth, role: &LabelledRole) -> Vec<Option<f32>> {
    if !is_truth_role(truth, role.window_step, role.a_id, role.b_id) {
        return Vec::new();
    }
    let Ok(scenario) = Scenario::of_truth(truth) else {
        return Vec::new();
    };
    let oracle = scenario.oracle();
    role.labels
        .futures_in_a
        .iter()
        .map(|f| {
            let world = world_points(&role.a.world_from_agent, f);
            oracle.psi_true(&world).ok().map(|v| v as f32)
        })
        .collect()
}

/// Reaction siblings of a ground-truth role: for each of B's first `per_role` *sampled*
/// futures (the logged one is the scene itself), and each of its first `per_role` lane moves
/// (the labelled futures after the `samples` sampled ones,
/// [`scbg_courtesy::label::LabelOptions::lane_move_steps`]), the scene replayed with B
/// following that future and A and the others reacting by the synthetic world's rule
/// ([`scbg_synth::ClosedLoop::replayed_scene`], id `<scene>~rx<k>`, `k` the future's index). As
/// training data they show the conditional predictor what A does when B drives the kind of
/// future B's marginal samples are — the futures whose labels the generators rank. Empty for
/// a role the ground truth does not describe; a future the oracle cannot replay is skipped.
pub fn reaction_scenes(
    truth: &GroundTruth,
    role: &LabelledRole,
    samples: usize,
    per_role: usize,
) -> Vec<scbg_scene::Scene> {
    if per_role == 0 || !is_truth_role(truth, role.window_step, role.a_id, role.b_id) {
        return Vec::new();
    }
    let Ok(scenario) = Scenario::of_truth(truth) else {
        return Vec::new();
    };
    let world = scenario.closed_loop();
    let futures = role.labels.futures_in_a.iter().enumerate();
    let sampled = futures.clone().skip(1).take(per_role.min(samples));
    let moves = futures.skip(1 + samples).take(per_role);
    sampled
        .chain(moves)
        .filter_map(|(k, f)| {
            let future = world_points(&role.a.world_from_agent, f);
            world.replayed_scene(&future, &format!("rx{k}")).ok()
        })
        .collect()
}

/// How one set of learned values agrees with the true ones.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Agreement {
    /// Number of (learned, true) pairs.
    pub n: usize,
    /// Spearman's ρ.
    pub spearman: Option<f64>,
    /// Pearson's r.
    pub pearson: Option<f64>,
    /// Least-squares slope of the learned values on the true ones (1 = same scale).
    pub slope: Option<f64>,
    /// std(learned) / std(true).
    pub spread_ratio: Option<f64>,
}

/// [`Agreement`] of `learned` with `truth` (same length).
pub fn agreement(learned: &[f64], truth: &[f64]) -> Agreement {
    let n = learned.len().min(truth.len());
    let (l, t) = (&learned[..n], &truth[..n]);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let (ml, mt) = (mean(l), mean(t));
    let var_t = t.iter().map(|x| (x - mt).powi(2)).sum::<f64>();
    let var_l = l.iter().map(|x| (x - ml).powi(2)).sum::<f64>();
    let cov = l
        .iter()
        .zip(t)
        .map(|(a, b)| (a - ml) * (b - mt))
        .sum::<f64>();
    let defined = n >= 2 && var_t > 0.0;
    Agreement {
        n,
        spearman: scbg_metrics::spearman(l, t),
        pearson: scbg_metrics::pearson(l, t),
        slope: defined.then(|| cov / var_t),
        spread_ratio: defined.then(|| (var_l / var_t).sqrt()),
    }
}

/// The fidelity report of a label table (`scbg label --ground-truth`, the demo).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Fidelity {
    /// ψ_label vs ψ_true of B's logged futures, per family and pooled ([`POOLED`]).
    pub logged: BTreeMap<String, Agreement>,
    /// The same over B's futures sampled from its marginal prediction.
    pub sampled: BTreeMap<String, Agreement>,
    /// The same over the lane moves of the sampled futures
    /// ([`scbg_courtesy::label::LabelOptions::lane_move_steps`]); absent without them.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub lane_moves: BTreeMap<String, Agreement>,
    /// Spearman(ψ_label of the logged future, latent courtesy c), per family and pooled.
    pub spearman_label_latent: BTreeMap<String, Option<f64>>,
    /// Spearman(ψ_true of the logged future, latent courtesy c): how much of c the oracle
    /// itself sees in B's future, the ceiling for the labels.
    pub spearman_true_latent: BTreeMap<String, Option<f64>>,
    /// Share of scenes where replaying B's logged future reproduces A's logged average speed
    /// within 0.2 m/s (oracle consistency), per family and pooled, with the scene count.
    pub oracle_consistency: BTreeMap<String, (f64, usize)>,
}

#[derive(Default)]
struct Columns {
    logged: (Vec<f64>, Vec<f64>),
    sampled: (Vec<f64>, Vec<f64>),
    lane_moves: (Vec<f64>, Vec<f64>),
    latent: (Vec<f64>, Vec<f64>, Vec<f64>),
}

/// The fidelity report of `rows` against `truth`, labelled with `samples` sampled futures per
/// role (the futures after them are lane moves); `None` when no row has a ψ_true.
pub fn fidelity(rows: &[LabelRow], truth: &[GroundTruth], samples: usize) -> Option<Fidelity> {
    let index = TruthIndex::new(truth);
    let mut by: BTreeMap<String, Columns> = BTreeMap::new();
    for r in rows {
        let (Some(pt), Some(t)) = (r.psi_true, index.get(&r.scenario_id)) else {
            continue;
        };
        for key in [t.family.name(), POOLED] {
            let c = by.entry(key.to_string()).or_default();
            let (l, tr) = match r.sample as usize {
                0 => &mut c.logged,
                k if k <= samples => &mut c.sampled,
                _ => &mut c.lane_moves,
            };
            l.push(f64::from(r.psi));
            tr.push(f64::from(pt));
            if r.sample == 0 {
                c.latent.0.push(f64::from(r.psi));
                c.latent.1.push(f64::from(pt));
                c.latent.2.push(t.courtesy);
            }
        }
    }
    if by.is_empty() {
        return None;
    }
    let mut consistency: BTreeMap<String, (usize, usize)> = BTreeMap::new();
    for t in truth {
        let ok = usize::from((t.a_avg_speed_replayed_mps - t.a_avg_speed_mps).abs() <= 0.2);
        for key in [t.family.name(), POOLED] {
            let e = consistency.entry(key.to_string()).or_default();
            e.0 += ok;
            e.1 += 1;
        }
    }
    Some(Fidelity {
        logged: by
            .iter()
            .map(|(k, c)| (k.clone(), agreement(&c.logged.0, &c.logged.1)))
            .collect(),
        sampled: by
            .iter()
            .map(|(k, c)| (k.clone(), agreement(&c.sampled.0, &c.sampled.1)))
            .collect(),
        lane_moves: by
            .iter()
            .filter(|(_, c)| !c.lane_moves.0.is_empty())
            .map(|(k, c)| (k.clone(), agreement(&c.lane_moves.0, &c.lane_moves.1)))
            .collect(),
        spearman_label_latent: by
            .iter()
            .map(|(k, c)| (k.clone(), scbg_metrics::spearman(&c.latent.0, &c.latent.2)))
            .collect(),
        spearman_true_latent: by
            .iter()
            .map(|(k, c)| (k.clone(), scbg_metrics::spearman(&c.latent.1, &c.latent.2)))
            .collect(),
        oracle_consistency: consistency
            .into_iter()
            .map(|(k, (ok, n))| (k, (ok as f64 / n.max(1) as f64, n)))
            .collect(),
    })
}

impl Fidelity {
    /// A Markdown table: one row per family and the pooled one.
    pub fn to_markdown(&self) -> String {
        let f = |x: Option<f64>| x.map_or("-".into(), |x| format!("{x:.3}"));
        let mut s = String::from(
            "| family | n | Spearman logged | Pearson logged | slope | spread ratio | Spearman sampled (n) | Spearman(ψ_label, c) | Spearman(ψ_true, c) | oracle consistency |\n|---|---|---|---|---|---|---|---|---|---|\n",
        );
        for (k, a) in &self.logged {
            let sampled = self.sampled.get(k);
            s += &format!(
                "| {k} | {} | {} | {} | {} | {} | {} ({}) | {} | {} | {} |\n",
                a.n,
                f(a.spearman),
                f(a.pearson),
                f(a.slope),
                f(a.spread_ratio),
                f(sampled.and_then(|a| a.spearman)),
                sampled.map_or(0, |a| a.n),
                f(self.spearman_label_latent.get(k).copied().flatten()),
                f(self.spearman_true_latent.get(k).copied().flatten()),
                self.oracle_consistency
                    .get(k)
                    .map_or("-".into(), |(p, n)| format!("{:.1} % of {n}", 100.0 * p)),
            );
        }
        if !self.lane_moves.is_empty() {
            let moves: Vec<String> = self
                .lane_moves
                .iter()
                .map(|(k, a)| format!("{k} {} ({})", f(a.spearman), a.n))
                .collect();
            s += &format!(
                "\nSpearman(ψ_label, ψ_true) on the lane moves of the sampled futures: {}\n",
                moves.join(", ")
            );
        }
        s
    }
}

/// The fidelity scatter: ψ_label against ψ_true of logged futures, coloured by family.
pub fn write_scatter(rows: &[LabelRow], truth: &[GroundTruth], path: &Path) -> anyhow::Result<()> {
    let index = TruthIndex::new(truth);
    let mut groups: BTreeMap<&str, Vec<(f64, f64)>> = BTreeMap::new();
    for r in rows.iter().filter(|r| r.sample == 0) {
        if let (Some(pt), Some(t)) = (r.psi_true, index.get(&r.scenario_id)) {
            groups
                .entry(t.family.name())
                .or_default()
                .push((f64::from(pt), f64::from(r.psi)));
        }
    }
    let series: Vec<scbg_plot::Series> = groups
        .into_iter()
        .map(|(family, points)| scbg_plot::Series {
            label: family.to_string(),
            points,
            band: None,
        })
        .collect();
    scbg_plot::scatter_series(
        &series,
        "ψ_true of the logged future (oracle, m/s)",
        "ψ_label (learned, m/s)",
        "courtesy labels against the simulator's ground truth",
        path,
    )?;
    Ok(())
}

/// The smallest range of ψ_true (m/s) over one example's futures for the input quantiles that
/// counts as B's choice changing A's reward ([`WorldKnob::spearman_within_example`]).
pub const RESPONSIVE_PSI_MPS: f64 = 0.01;

/// ψ_true of generated futures at one input quantile.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct QuantileTruth {
    /// The input quantile.
    pub quantile: f32,
    /// Mean ψ_true of the generated futures (m/s).
    pub psi_true_mean: f64,
    /// Their standard deviation.
    pub psi_true_std: f64,
}

/// Control in truth: the generator's futures for the input quantiles, scored by the oracle.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TruthControl {
    /// Spearman(input quantile, ψ_true of the generated future) pooled and within examples,
    /// the scored examples (pair roles with a ground truth) and the mean ψ_true per quantile:
    /// the same scoring as the yardsticks'.
    #[serde(flatten)]
    pub knob: WorldKnob,
    /// J_φ's achieved ψ against ψ_true over the same generated futures.
    pub achieved_vs_true: Agreement,
}

/// A scored example: its family and ψ_true of B's future at each of `EVAL_QUANTILES`.
type QuantileRow = (&'static str, Vec<f64>);

/// Spearman(input quantile, ψ_true) per family and pooled, over all examples and within each
/// one (with the share of examples that respond), the examples per family and the mean ψ_true
/// per quantile of `rows` (the fields of a [`WorldKnob`], and of a [`TruthControl`] beside
/// J_φ's agreement).
fn quantile_summary(rows: &[QuantileRow]) -> WorldKnob {
    use scbg_generator::eval::EVAL_QUANTILES;
    let mut q_by: BTreeMap<String, (Vec<f64>, Vec<f64>)> = BTreeMap::new();
    for (family, truths) in rows {
        for key in [*family, POOLED] {
            let e = q_by.entry(key.to_string()).or_default();
            for (j, v) in truths.iter().enumerate() {
                e.0.push(f64::from(EVAL_QUANTILES[j]));
                e.1.push(*v);
            }
        }
    }
    let per_quantile = EVAL_QUANTILES
        .iter()
        .enumerate()
        .filter_map(|(j, &q)| {
            let v: Vec<f64> = rows.iter().map(|s| s.1[j]).collect();
            let m = scbg_generator::eval::MeanStd::of(&v)?;
            Some(QuantileTruth {
                quantile: q,
                psi_true_mean: m.mean,
                psi_true_std: m.std,
            })
        })
        .collect();
    let q: Vec<f64> = EVAL_QUANTILES.iter().map(|&q| f64::from(q)).collect();
    let (spearman_within_example, responsive_fraction) = within_group_spearman(
        rows.iter()
            .map(|(family, truths)| (*family, truths.as_slice())),
        &q,
        RESPONSIVE_PSI_MPS,
    );
    WorldKnob {
        spearman_quantile_psi_true: q_by
            .iter()
            .map(|(k, (q, t))| (k.clone(), scbg_metrics::spearman(q, t)))
            .collect(),
        spearman_within_example,
        responsive_fraction,
        examples: q_by
            .iter()
            .map(|(k, (q, _))| (k.clone(), q.len() / EVAL_QUANTILES.len()))
            .collect(),
        per_quantile,
    }
}

/// The knob within groups (one example's futures, one scene's rollouts), per family and
/// pooled ([`POOLED`]): the mean over groups of Spearman(`x`, the group's values) — 0 for a
/// group whose values span less than `min_range`, where B's choice changes nothing — and the
/// share of groups whose values span it.
pub(crate) fn within_group_spearman<'a>(
    groups: impl IntoIterator<Item = (&'a str, &'a [f64])>,
    x: &[f64],
    min_range: f64,
) -> (BTreeMap<String, f64>, BTreeMap<String, f64>) {
    // Per key: (Σ Spearman, responsive groups, groups).
    let mut by: BTreeMap<String, (f64, usize, usize)> = BTreeMap::new();
    for (family, values) in groups {
        let rho = scbg_metrics::spearman_if_responsive(x, values, min_range);
        for key in [family, POOLED] {
            let e = by.entry(key.to_string()).or_default();
            e.0 += rho.unwrap_or(0.0);
            e.1 += usize::from(rho.is_some());
            e.2 += 1;
        }
    }
    let of =
        |f: fn(&(f64, usize, usize)) -> f64| by.iter().map(|(k, v)| (k.clone(), f(v))).collect();
    (of(|v| v.0 / v.2 as f64), of(|v| v.1 as f64 / v.2 as f64))
}

/// Scores the quantile futures of an evaluation (`measured` as
/// [`scbg_generator::eval::evaluate_measured`] returns it) with the oracle; `None` when no
/// example is a ground-truth role.
pub fn truth_control(
    examples: &[&scbg_generator::Example],
    measured: &scbg_generator::eval::Measured,
    truth: &TruthIndex<'_>,
) -> Option<TruthControl> {
    use rayon::prelude::*;
    use scbg_generator::eval::EVAL_QUANTILES;
    // Per scored example: (family, [ψ_true per quantile]) and [achieved ψ per quantile].
    let scored: Vec<(QuantileRow, Vec<f64>)> = examples
        .par_iter()
        .enumerate()
        .filter_map(|(i, e)| {
            let (t, scenario) = truth_scenario(e, truth)?;
            let oracle = scenario.oracle();
            let mut truths = Vec::new();
            let mut achieved = Vec::new();
            for j in 0..EVAL_QUANTILES.len() {
                let future = measured.futures_b[i].get(1 + j)?;
                let world = world_points(&e.b.world_from_agent, future);
                truths.push(oracle.psi_true(&world).ok()?);
                achieved.push(f64::from(measured.psi[i][1 + j]));
            }
            Some(((t.family.name(), truths), achieved))
        })
        .collect();
    if scored.is_empty() {
        return None;
    }
    let (rows, achieved): (Vec<_>, Vec<_>) = scored.into_iter().unzip();
    let all_true: Vec<f64> = rows.iter().flat_map(|r| r.1.iter().copied()).collect();
    let all_achieved: Vec<f64> = achieved.into_iter().flatten().collect();
    Some(TruthControl {
        knob: quantile_summary(&rows),
        achieved_vs_true: agreement(&all_achieved, &all_true),
    })
}

/// The ground truth of an evaluation example and its rebuilt scenario, when the example is the
/// role the ground truth describes.
fn truth_scenario<'t>(
    e: &scbg_generator::Example,
    truth: &TruthIndex<'t>,
) -> Option<(&'t GroundTruth, Scenario)> {
    let t = truth.get(&e.scenario_id)?;
    is_truth_role(
        t,
        e.a.window.current_step,
        e.a.target_track_id,
        e.b.target_track_id,
    )
    .then(|| Scenario::of_truth(t).ok())
    .flatten()
    .map(|s| (t, s))
}

/// B's world-frame future (the steps after the scene's current step, where the oracle's roles
/// are) when the synthetic world's own B drives with courtesy `c` from the current step on,
/// everyone else reacting ([`Scenario::tracks_with_courtesy`]); `None` when the scene has no
/// track `b_id`.
pub fn world_future_of_b(scenario: &Scenario, b_id: i64, c: f64) -> Option<Vec<[f64; 2]>> {
    let tracks = scenario.tracks_with_courtesy(c);
    let b = tracks.iter().find(|t| t.id == b_id)?;
    Some(
        b.states
            .get(CURRENT_STEP + 1..)?
            .iter()
            .map(|s| [s.x_m, s.y_m])
            .collect(),
    )
}

/// The world's own knob in open loop, the yardstick of [`TruthControl`]: for the same scored
/// examples, B is the synthetic world's B driving with courtesy `c = q` (B's prior is uniform,
/// so its q-quantile is q) for every input quantile q, and its future is scored by the oracle
/// like a generated one. A generator whose futures follow the quantile as faithfully as the
/// world's B does reaches these Spearman values; the gap between B's courtesy and A's reward
/// that the scene's own draws leave is in them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WorldKnob {
    /// Spearman(q, ψ_true of the world's B at c = q), per family and pooled.
    pub spearman_quantile_psi_true: BTreeMap<String, Option<f64>>,
    /// The knob within an example (a pair role): the mean over examples of Spearman(q, ψ_true)
    /// across the example's own futures for the input quantiles, 0 for an example whose
    /// futures all give A the same reward (ψ_true's range under [`RESPONSIVE_PSI_MPS`]); per
    /// family and pooled.
    /// Free of the scene-to-scene spread of ψ_true that the pooled Spearman mixes in.
    pub spearman_within_example: BTreeMap<String, f64>,
    /// Share of examples whose futures for the input quantiles differ in ψ_true by at least
    /// [`RESPONSIVE_PSI_MPS`], per family and pooled.
    pub responsive_fraction: BTreeMap<String, f64>,
    /// Scored examples per family and pooled.
    pub examples: BTreeMap<String, usize>,
    /// Mean ψ_true per quantile (pooled).
    pub per_quantile: Vec<QuantileTruth>,
}

/// [`WorldKnob`] over the ground-truth roles among `examples`; `None` when there is none.
pub fn world_truth_control(
    examples: &[&scbg_generator::Example],
    truth: &TruthIndex<'_>,
) -> Option<WorldKnob> {
    use rayon::prelude::*;
    use scbg_generator::eval::EVAL_QUANTILES;
    let rows: Vec<QuantileRow> = examples
        .par_iter()
        .filter_map(|e| {
            let (t, scenario) = truth_scenario(e, truth)?;
            let oracle = scenario.oracle();
            let truths = EVAL_QUANTILES
                .iter()
                .map(|&q| {
                    let world = world_future_of_b(&scenario, t.b_id, f64::from(q))?;
                    oracle.psi_true(&world).ok()
                })
                .collect::<Option<Vec<f64>>>()?;
            Some((t.family.name(), truths))
        })
        .collect();
    if rows.is_empty() {
        return None;
    }
    Some(quantile_summary(&rows))
}

/// How much control in truth a *selector* among each example's labelled futures of B (the
/// logged one and those sampled from B's marginal prediction — the candidates the generator is
/// trained on) would reach: at input quantile q, the candidate at rank ⌊q·n⌋ of n by a key.
/// It splits the generator's control in truth into what the candidates offer and what the
/// labels rank right: a generator that follows its labels perfectly reaches `by_label`, and
/// no choice among these candidates beats `by_truth`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SelectionControl {
    /// Spearman(q, ψ_true) when the candidates are ranked by ψ_true itself (the ceiling).
    pub by_truth: WorldKnob,
    /// The same ranked by the labels ψ_label (J_φ), i.e. a perfect follower of the labels.
    pub by_label: WorldKnob,
    /// Candidates per example (1 logged + M sampled, those the oracle could score).
    pub candidates_mean: f64,
}

impl SelectionControl {
    /// The two selectors with the label their rows carry in the reports.
    pub fn yardsticks(&self) -> [(&'static str, &WorldKnob); 2] {
        [
            (
                "choosing among B's labelled futures, the logged one included, by ψ_label (a perfect follower of the labels)",
                &self.by_label,
            ),
            (
                "choosing among B's labelled futures, the logged one included, by ψ_true (what the candidates allow)",
                &self.by_truth,
            ),
        ]
    }

    /// The same two selectors over a generator's own choices ([`candidate_control`]), with
    /// the labels their rows carry in the reports.
    pub fn candidate_yardsticks(&self) -> [(&'static str, &WorldKnob); 2] {
        [
            (
                "choosing among the generator's own candidates (B's modes and their copies) by J_φ (a perfect follower of J_φ)",
                &self.by_label,
            ),
            (
                "choosing among the generator's own candidates by ψ_true (what they allow)",
                &self.by_truth,
            ),
        ]
    }
}

/// [`SelectionControl`] over the ground-truth roles among `examples`; `None` when there is
/// none.
pub fn selection_control(
    examples: &[&scbg_generator::Example],
    truth: &TruthIndex<'_>,
) -> Option<SelectionControl> {
    // Each example's labelled futures with their labels ψ_label.
    let labelled: Vec<Vec<scbg_generator::ScoredCandidate>> = examples
        .iter()
        .map(|e| {
            e.futures_b
                .iter()
                .zip(&e.psi)
                .map(|(future, &psi)| scbg_generator::ScoredCandidate {
                    xy: future.clone(),
                    psi,
                })
                .collect()
        })
        .collect();
    candidate_control(examples, &labelled, truth)
}

/// [`SelectionControl`] for any choices of B with their courtesy by J_φ (`candidates[i]`
/// belongs to `examples[i]`; a mode-selecting generator's own, B's modes and their copies,
/// from [`scbg_generator::scored_candidates`]), ranked by J_φ and by ψ_true: what a perfect
/// follower of J_φ among them reaches, and what they allow at all. `None` when no example is
/// a ground-truth role with two choices the oracle can score.
pub fn candidate_control(
    examples: &[&scbg_generator::Example],
    candidates: &[Vec<scbg_generator::ScoredCandidate>],
    truth: &TruthIndex<'_>,
) -> Option<SelectionControl> {
    use rayon::prelude::*;
    // Per scored example: family, and (ψ by J_φ, ψ_true) of every choice it could score.
    let scored: Vec<(&'static str, Vec<(f64, f64)>)> = examples
        .par_iter()
        .zip(candidates.par_iter())
        .filter_map(|(e, choices)| {
            let (t, scenario) = truth_scenario(e, truth)?;
            let oracle = scenario.oracle();
            let pairs: Vec<(f64, f64)> = choices
                .iter()
                .filter_map(|c| {
                    let world = world_points(&e.b.world_from_agent, &c.xy);
                    Some((f64::from(c.psi), oracle.psi_true(&world).ok()?))
                })
                .collect();
            (pairs.len() >= 2).then_some((t.family.name(), pairs))
        })
        .collect();
    select_control(&scored)
}

/// Per scored example (family, (key, ψ_true) of each candidate), the candidate at rank ⌊q·n⌋
/// for every input quantile q, ranked by ψ_true and by the key.
fn select_control(scored: &[(&'static str, Vec<(f64, f64)>)]) -> Option<SelectionControl> {
    use scbg_generator::eval::EVAL_QUANTILES;
    if scored.is_empty() {
        return None;
    }
    let select = |key: fn(&(f64, f64)) -> f64| -> Vec<QuantileRow> {
        scored
            .iter()
            .map(|(family, pairs)| {
                let mut ranked = pairs.clone();
                ranked.sort_by(|a, b| key(a).total_cmp(&key(b)));
                let truths = EVAL_QUANTILES
                    .iter()
                    .map(|&q| ranked[scbg_generator::ranked::rank_at(q, ranked.len())].1)
                    .collect();
                (*family, truths)
            })
            .collect()
    };
    Some(SelectionControl {
        by_truth: quantile_summary(&select(|p| p.1)),
        by_label: quantile_summary(&select(|p| p.0)),
        candidates_mean: scored.iter().map(|s| s.1.len() as f64).sum::<f64>() / scored.len() as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agreement_of_a_scaled_copy() {
        let t = [0.0, 1.0, 2.0, 3.0, 4.0];
        let l: Vec<f64> = t.iter().map(|x| 0.5 * x + 1.0).collect();
        let a = agreement(&l, &t);
        assert_eq!(a.n, 5);
        assert!((a.spearman.unwrap() - 1.0).abs() < 1e-12);
        assert!((a.pearson.unwrap() - 1.0).abs() < 1e-12);
        assert!((a.slope.unwrap() - 0.5).abs() < 1e-12);
        assert!((a.spread_ratio.unwrap() - 0.5).abs() < 1e-12);
        let flat = agreement(&[1.0, 2.0], &[3.0, 3.0]);
        assert_eq!((flat.slope, flat.spread_ratio), (None, None));
    }

    #[test]
    fn within_example_spearman_removes_the_scene_level() {
        // Two examples that each rise perfectly with q, but the second sits so far below the
        // first that the pooled Spearman is only moderate; a third does not respond at all.
        let rising =
            |offset: f64| -> Vec<f64> { (0..9).map(|j| offset + 0.1 * j as f64).collect() };
        let rows: Vec<QuantileRow> = vec![
            ("merge", rising(10.0)),
            ("merge", rising(-10.0)),
            ("crossing", vec![0.5; 9]),
        ];
        let k = quantile_summary(&rows);
        let pooled = k.spearman_quantile_psi_true[POOLED].unwrap();
        assert!(pooled < 0.75, "pooled {pooled}");
        assert!((k.spearman_within_example["merge"] - 1.0).abs() < 1e-12);
        assert_eq!(k.spearman_within_example["crossing"], 0.0);
        assert!((k.spearman_within_example[POOLED] - 2.0 / 3.0).abs() < 1e-12);
        assert!((k.responsive_fraction[POOLED] - 2.0 / 3.0).abs() < 1e-12);
        assert_eq!(k.responsive_fraction["crossing"], 0.0);
        // A falling example counts against the knob.
        let mut falling = rising(0.0);
        falling.reverse();
        let k = quantile_summary(&[("cutin", falling)]);
        assert!((k.spearman_within_example["cutin"] + 1.0).abs() < 1e-12);
    }

    /// The world's B at the scene's own courtesy drives the logged future (so the world knob
    /// at c = the latent courtesy scores ψ_true of the log); other courtesies change it in
    /// some scenes (in others B's decision does not depend on it).
    #[test]
    fn the_worlds_b_at_its_own_courtesy_drives_the_logged_future() {
        use scbg_synth::{Family, generate};
        let mut changed = 0;
        for index in 0..6 {
            let g = generate(5, index, &Family::ALL);
            let t = &g.truth;
            let scenario = Scenario::of_truth(t).unwrap();
            let logged: Vec<[f64; 2]> = g.scene.tracks[1].states[CURRENT_STEP + 1..]
                .iter()
                .map(|s| [s.x_m, s.y_m])
                .collect();
            let own = world_future_of_b(&scenario, t.b_id, t.courtesy).unwrap();
            assert_eq!(own.len(), logged.len());
            for (p, q) in own.iter().zip(&logged) {
                assert!((p[0] - q[0]).abs() < 1e-3 && (p[1] - q[1]).abs() < 1e-3);
            }
            let psi = scenario.oracle().psi_true(&own).unwrap();
            assert!((psi - t.psi_true).abs() < 1e-3, "{psi} vs {}", t.psi_true);
            let other = world_future_of_b(&scenario, t.b_id, 1.0 - t.courtesy);
            changed += usize::from(other.unwrap() != own);
            assert!(world_future_of_b(&scenario, 999, 0.5).is_none());
        }
        assert!(changed >= 2, "{changed} of 6 scenes");
    }

    #[test]
    fn oracle_scores_the_logged_future_of_a_truth_role() {
        use scbg_synth::{Family, generate};
        let g = generate(3, 1, &Family::ALL);
        let t = &g.truth;
        let b = &g.scene.tracks[1];
        // B's logged future in A's frame at the current step.
        let a_now = &g.scene.tracks[0].states[CURRENT_STEP];
        let pose = Pose2::new(a_now.x_m, a_now.y_m, f64::from(a_now.heading_rad));
        let in_a: Vec<[f32; 2]> = b.states[CURRENT_STEP + 1..]
            .iter()
            .map(|s| {
                let (x, y) = pose.agent_from_world(s.x_m, s.y_m);
                [x as f32, y as f32]
            })
            .collect();
        let world = world_points(&pose, &in_a);
        let scenario = Scenario::of_truth(t).unwrap();
        let oracle = scenario.oracle();
        let psi = oracle.psi_true(&world).unwrap();
        // f32 rounding of the frame change moves ψ_true by far less than the 0.2 m/s check.
        assert!((psi - t.psi_true).abs() < 0.05, "{psi} vs {}", t.psi_true);
        assert!(is_truth_role(t, CURRENT_STEP, t.a_id, t.b_id));
        assert!(!is_truth_role(t, CURRENT_STEP, t.b_id, t.a_id));
    }

    #[test]
    fn the_labelling_frames_reach_the_oracle_unchanged() {
        use scbg_features::{
            FeatureConfig, PairConfig, PreparedScene, SampleBuilder, WindowConfig,
        };
        use scbg_synth::{Family, generate};
        for i in 0..6 {
            let g = generate(5, i, &Family::ALL);
            let t = &g.truth;
            let prepared = PreparedScene::from_scene(
                &g.scene,
                &WindowConfig::default(),
                &PairConfig::default(),
                1,
            )
            .unwrap();
            let config = FeatureConfig::default();
            let mut builder = SampleBuilder::new(&prepared, &config);
            let w = prepared.windows[0];
            let (ia, ib) = (
                prepared.track_index(t.a_id).unwrap(),
                prepared.track_index(t.b_id).unwrap(),
            );
            let a = builder.sample(&w, ia, Some(ib)).unwrap();
            let in_a: Vec<[f32; 2]> = a
                .condition_future_xy_m
                .chunks_exact(2)
                .map(|p| [p[0], p[1]])
                .collect();
            let world = world_points(&a.world_from_agent, &in_a);
            let logged = &g.scene.tracks[1].states[CURRENT_STEP + 1..];
            for (p, s) in world.iter().zip(logged) {
                assert!(
                    (p[0] - s.x_m).abs() < 0.01 && (p[1] - s.y_m).abs() < 0.01,
                    "{p:?} vs {} {}",
                    s.x_m,
                    s.y_m
                );
            }
            let psi = Scenario::of_truth(t).unwrap().psi_true(&world).unwrap();
            assert!((psi - t.psi_true).abs() < 0.05, "{psi} vs {}", t.psi_true);
        }
    }
}
