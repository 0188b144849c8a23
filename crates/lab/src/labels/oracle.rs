//! Synthetic data only: labels replaced by the simulator's ψ_true, and B's sampled futures by
//! the world's own (an upper bound for "are the labels what limits control?").

use scbg_courtesy::label::LabelledRole;
use scbg_synth::GroundTruth;
use serde::Serialize;

use super::SceneLabels;

/// What [`oracle_labelled`] kept and dropped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct OracleLabelCount {
    /// Pair roles kept (the ground truth's role of a scene, its logged future scored).
    pub roles: usize,
    /// Futures of B kept with their ψ_true (logged, and sampled or the world's own).
    pub futures: usize,
    /// Pair roles dropped: not a ground-truth role, or no ground truth for the scene.
    pub dropped_roles: usize,
    /// Futures other than the logged one dropped because the oracle could not score them.
    pub dropped_futures: usize,
}

/// Synthetic data only: the labelled scenes with every learned ψ replaced by the simulator's
/// ψ_true ([`crate::fidelity::psi_true_of_role`]) — the labels a perfect J_φ would give. Only
/// the role the ground truth describes is kept in each scene (the oracle scores B toward A
/// alone), and of its futures those the oracle can score; a role whose logged future it cannot
/// score is dropped. `e_cond` is left as the predictor's (the full variant's courtesy loss
/// still goes through J_φ, whose scale differs from ψ_true's).
///
/// With `world_futures` K > 0, B's sampled futures are replaced by the synthetic world's own
/// futures of B at courtesy `c' = (k + 0.5) / K` ([`world_futures_in_a`]): what B does when it
/// is faithful to a courtesy, everyone else reacting (their `e_cond` is NaN: J_φ does not see
/// them).
///
/// An upper bound for the experiment "are the labels what limits control?", not the paper's
/// method: real data has no oracle.
pub fn oracle_labelled(
    labelled: Vec<SceneLabels>,
    truth: &[GroundTruth],
    world_futures: usize,
) -> (Vec<SceneLabels>, OracleLabelCount) {
    use rayon::prelude::*;
    let index = crate::fidelity::TruthIndex::new(truth);
    let scenes: Vec<(SceneLabels, OracleLabelCount)> = labelled
        .into_par_iter()
        .map(|mut scene| {
            let mut count = OracleLabelCount::default();
            let t = index.get(&scene.scenario_id);
            for mut role in std::mem::take(&mut scene.roles) {
                if let Some(world) = t
                    .filter(|_| world_futures > 0)
                    .and_then(|t| world_futures_in_a(t, &role, world_futures))
                {
                    let labels = &mut role.labels;
                    labels.futures_in_a.truncate(1);
                    labels.e_cond.truncate(1);
                    labels.e_cond.resize(1 + world.len(), f32::NAN);
                    labels.futures_in_a.extend(world);
                }
                // One score per future of B, in order (empty for another role).
                let scores = t
                    .map(|t| crate::fidelity::psi_true_of_role(t, &role))
                    .unwrap_or_default();
                if scores.first().copied().flatten().is_none() {
                    count.dropped_roles += 1;
                    continue;
                }
                let labels = &mut role.labels;
                let futures = std::mem::take(&mut labels.futures_in_a);
                let (mut psi, mut e_cond) = (Vec::new(), Vec::new());
                for ((score, e), future) in scores.iter().zip(&labels.e_cond).zip(futures) {
                    match score {
                        Some(v) => {
                            psi.push(*v);
                            e_cond.push(*e);
                            labels.futures_in_a.push(future);
                        }
                        None => count.dropped_futures += 1,
                    }
                }
                (labels.psi, labels.e_cond) = (psi, e_cond);
                count.roles += 1;
                count.futures += labels.psi.len();
                scene.roles.push(role);
            }
            (scene, count)
        })
        .collect();
    let mut total = OracleLabelCount::default();
    let mut kept = Vec::new();
    for (scene, c) in scenes {
        total.roles += c.roles;
        total.futures += c.futures;
        total.dropped_roles += c.dropped_roles;
        total.dropped_futures += c.dropped_futures;
        if !scene.roles.is_empty() {
            kept.push(scene);
        }
    }
    (kept, total)
}

/// B's futures (the steps after the window's, in A's frame of `role`) when the synthetic
/// world's B drives with courtesy `(k + 0.5) / count` for k in 0..count from the current step
/// on, everyone else reacting ([`crate::fidelity::world_future_of_b`]); `None` when `role` is
/// not the role `truth` describes or the scenario cannot be rebuilt.
pub fn world_futures_in_a(
    truth: &GroundTruth,
    role: &LabelledRole,
    count: usize,
) -> Option<Vec<Vec<[f32; 2]>>> {
    if !crate::fidelity::is_truth_role(truth, role.window_step, role.a_id, role.b_id) {
        return None;
    }
    let scenario = scbg_synth::Scenario::of_truth(truth).ok()?;
    let frame = &role.a.world_from_agent;
    (0..count)
        .map(|k| {
            let c = (k as f64 + 0.5) / count as f64;
            let world = crate::fidelity::world_future_of_b(&scenario, role.b_id, c)?;
            Some(
                world
                    .iter()
                    .map(|p| {
                        let (x, y) = frame.agent_from_world(p[0], p[1]);
                        [x as f32, y as f32]
                    })
                    .collect(),
            )
        })
        .collect()
}
