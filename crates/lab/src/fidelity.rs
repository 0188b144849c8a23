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

mod control;
pub use control::{
    QuantileTruth, RESPONSIVE_PSI_MPS, SelectionControl, TruthControl, WorldKnob,
    candidate_control, selection_control, truth_control, world_future_of_b, world_truth_control,
};
pub(crate) use control::{ordered_pooled_spearman, within_group_spearman};

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
/// ([`scbg_synth::ClosedLoop::replayed_scene`], id `<scene>~rx<k>`, `k` the future's index).
/// The sampled futures take turns being followed as they are and slowed by each of the
/// generator's [`scbg_generator::DEFAULT_MODE_SLOWDOWNS`] ([`scbg_generator::slowed_future`]):
/// the first as it is, the second at 0.75, the third at 0.5. As training data they show the
/// conditional predictor what A does when B drives the kinds of future the generator chooses
/// among — B's modes and their slowed copies, whose courtesy J_φ ranks. Empty for
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
    // B's sampled futures as they are, then slowed as the generator slows its modes.
    let (x0, y0) = role.b.world_from_agent.world_from_agent(0.0, 0.0);
    let factors: Vec<f32> = std::iter::once(1.0)
        .chain(scbg_generator::DEFAULT_MODE_SLOWDOWNS)
        .collect();
    let sampled = sampled.enumerate().map(|(i, (k, f))| {
        let future = world_points(&role.a.world_from_agent, f);
        let w = factors[i % factors.len()];
        (k, scbg_generator::slowed_future(&future, [x0, y0], w))
    });
    let moves = moves.map(|(k, f)| (k, world_points(&role.a.world_from_agent, f)));
    sampled
        .chain(moves)
        .filter_map(|(k, future)| world.replayed_scene(&future, &format!("rx{k}")).ok())
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
    fn oracle_scores_the_logged_future_of_a_truth_role() {
        use scbg_synth::{Family, generate};
        let g = generate(3, 1, &Family::DEFAULT);
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
            let g = generate(5, i, &Family::DEFAULT);
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
