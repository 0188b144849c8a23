//! Control in truth: generated (or chosen) futures of B for the input quantiles, scored by
//! the oracle's ψ_true — the generator's, the world's own B at c = q, and what a choice
//! among labelled futures or a generator's own candidates allows.

use std::collections::BTreeMap;

use scbg_synth::{CURRENT_STEP, GroundTruth, Scenario};
use serde::Serialize;

use super::{Agreement, POOLED, TruthIndex, agreement, is_truth_role, world_points};

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
        spearman_quantile_psi_true_ordered: ordered_pooled_spearman(
            rows.iter()
                .map(|(family, truths)| (*family, truths.as_slice())),
            &q,
        ),
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

/// The most the pooled Spearman(`x`, value) over `groups` (one example's futures, one
/// scene's rollouts, each a value per element of `x`) can be with these values: each group's
/// values re-ordered to rise with `x`, per family and pooled ([`POOLED`]). No other order
/// within the groups gives more (the rearrangement inequality on the pooled ranks, which keep
/// each group's order), so it is the ceiling of a knob that ranks perfectly within every group
/// but reaches only these outcomes; what is left below 1 is the spread between groups. A group
/// with a non-finite value or not one value per `x` is left out; `POOLED` is always there
/// (`None` without a group).
pub(crate) fn ordered_pooled_spearman<'a>(
    groups: impl IntoIterator<Item = (&'a str, &'a [f64])>,
    x: &[f64],
) -> BTreeMap<String, Option<f64>> {
    let mut x_sorted = x.to_vec();
    x_sorted.sort_by(f64::total_cmp);
    let mut by: BTreeMap<String, (Vec<f64>, Vec<f64>)> = BTreeMap::new();
    by.insert(POOLED.to_string(), Default::default());
    for (family, values) in groups {
        if values.len() != x.len() || !values.iter().all(|v| v.is_finite()) {
            continue;
        }
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        for key in [family, POOLED] {
            let e = by.entry(key.to_string()).or_default();
            e.0.extend(&x_sorted);
            e.1.extend(&sorted);
        }
    }
    by.into_iter()
        .map(|(k, (x, v))| (k, scbg_metrics::spearman(&x, &v)))
        .collect()
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
    /// The same with each example's ψ_true re-ordered to rise with q
    /// ([`ordered_pooled_spearman`]): the most a knob that orders these futures perfectly
    /// within every example reaches; per family and pooled.
    pub spearman_quantile_psi_true_ordered: BTreeMap<String, Option<f64>>,
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
        // Re-ordered, it rises perfectly.
        assert!((k.spearman_quantile_psi_true_ordered["cutin"].unwrap() - 1.0).abs() < 1e-12);
    }

    /// The ordered ceiling by hand: two groups on levels 0–2 and 10–12 at three x's give
    /// x ranks (1.5, 3.5, 5.5) twice against value ranks 1…6: 8 / √(16 · 17.5). It is the
    /// same whatever order the values come in, and no within-group order of random values
    /// gives a higher pooled Spearman.
    #[test]
    fn ordered_pooled_spearman_is_the_best_order_within_groups() {
        let x = [0.9, 0.1, 0.5];
        let (a, b) = ([2.0, 1.0, 0.0], [11.0, 12.0, 10.0]);
        let r = ordered_pooled_spearman([("merge", &a[..]), ("cutin", &b[..])], &x);
        let want = 8.0 / (16.0f64 * 17.5).sqrt();
        assert!((r[POOLED].unwrap() - want).abs() < 1e-12, "{r:?}");
        assert!((r["merge"].unwrap() - 1.0).abs() < 1e-12);
        // Any order of random groups ranks no higher than the ordered one.
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let x: Vec<f64> = (1..=9).map(|k| f64::from(k) / 10.0).collect();
        let groups: Vec<Vec<f64>> = (0..12)
            .map(|g| (0..9).map(|_| 5.0 * f64::from(g % 4) + next()).collect())
            .collect();
        let ordered = ordered_pooled_spearman(groups.iter().map(|v| ("merge", v.as_slice())), &x)
            [POOLED]
            .unwrap();
        let (xs, vs): (Vec<f64>, Vec<f64>) = groups
            .iter()
            .flat_map(|v| x.iter().copied().zip(v.iter().copied()))
            .unzip();
        let as_given = scbg_metrics::spearman(&xs, &vs).unwrap();
        assert!(ordered > as_given + 0.05, "{ordered} vs {as_given}");
        assert!(ordered < 1.0);
        // Every order of two groups of three, one with a tie: none beats the ordered one,
        // and the ordered one is among them.
        let (a, b) = ([1.0, 1.0, 3.0], [2.0, 5.0, 0.0]);
        let x = [0.5, 0.1, 0.9];
        let perms = [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ];
        let mut best = f64::NEG_INFINITY;
        for pa in &perms {
            for pb in &perms {
                let vs: Vec<f64> = pa
                    .iter()
                    .map(|&i| a[i])
                    .chain(pb.iter().map(|&i| b[i]))
                    .collect();
                let xs: Vec<f64> = x.iter().chain(&x).copied().collect();
                best = best.max(scbg_metrics::spearman(&xs, &vs).unwrap());
            }
        }
        let ordered =
            ordered_pooled_spearman([("merge", &a[..]), ("merge", &b[..])], &x)[POOLED].unwrap();
        assert!((ordered - best).abs() < 1e-12, "{ordered} vs {best}");
        // A group that is not one value per x, or holds a NaN, is left out.
        let r = ordered_pooled_spearman(
            [("merge", &[1.0, 2.0][..]), ("cutin", &[f64::NAN; 3][..])],
            &x,
        );
        assert_eq!(r[POOLED], None);
        assert!(!r.contains_key("merge") && !r.contains_key("cutin"));
    }

    /// The world's B at the scene's own courtesy drives the logged future (so the world knob
    /// at c = the latent courtesy scores ψ_true of the log); other courtesies change it in
    /// some scenes (in others B's decision does not depend on it).
    #[test]
    fn the_worlds_b_at_its_own_courtesy_drives_the_logged_future() {
        use scbg_synth::{Family, generate};
        let mut changed = 0;
        for index in 0..6 {
            let g = generate(5, index, &Family::DEFAULT);
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
}
