//! The courtesy knob's curve over scenes, for scbg's B and the synthetic world's own.

use std::collections::BTreeMap;

use scbg_synth::GroundTruth;
use serde::Serialize;

use super::scenes::Skips;
use super::{PerFamily, QuantileSim, SceneResult, SimScene, mean_std, rate};
use scbg::sim::{AgentRolloutMetrics, Contact, report};

/// The courtesy knob's curve over scenes: the numbers per quantile and the correlations.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct KnobCurve {
    /// Scenes of the curve.
    pub scenes: usize,
    /// Per quantile.
    pub per_quantile: Vec<QuantileSim>,
    /// Spearman(quantile, A's realised average speed) over every (scene, quantile).
    pub spearman_quantile_a_speed: PerFamily,
    /// Spearman(quantile, realised courtesy) over every (scene, quantile): the same, with
    /// each scene's own level removed.
    pub spearman_quantile_realised_courtesy: PerFamily,
    /// `spearman_quantile_a_speed` with each scene's A speeds re-ordered to rise with the
    /// quantile: the most a knob that orders these rollouts' outcomes perfectly within every
    /// scene reaches (`crate::fidelity::ordered_pooled_spearman`). Below 1 by the spread of
    /// A's speed from scene to scene against the knob's reach within a scene.
    pub spearman_quantile_a_speed_ordered: PerFamily,
    /// The knob within a scene: the mean over scenes of Spearman(quantile, A's realised
    /// average speed) across the scene's own quantiles, 0 for a scene in which A's speed does
    /// not change by [`RESPONSIVE_SPEED_MPS`] over them; per family and pooled.
    pub spearman_within_scene_a_speed: PerFamily,
    /// Share of scenes in which A's realised speed changes by at least
    /// [`RESPONSIVE_SPEED_MPS`] over the quantiles, per family and pooled.
    pub responsive_fraction: PerFamily,
    /// Whether the mean of A's realised speed never falls from one quantile to the next
    /// (`None` without a scene).
    pub a_speed_curve_rises: Option<bool>,
    /// The largest B collision rate over the quantiles (`None` without a scene).
    pub max_b_collision_rate: Option<f64>,
    /// The largest over the quantiles of B's collision rate in the scenes where B starts clear
    /// of every other agent ([`QuantileSim::b_collision_rate_clear_start`]; `None` without
    /// such a scene).
    pub max_b_collision_rate_clear_start: Option<f64>,
    /// Every rollout in which B collides: the scene, the quantile and B's first contact
    /// (with whom, at which step, both speeds, the geometry) — what a diagnosis needs.
    pub b_collisions: Vec<BCollision>,
    /// Share of B's rollouts (every scene at every quantile) in which B leaves the road (the
    /// WOSAC off-road rule), per family and pooled; a family without road edges is left out.
    pub b_offroad_rate_per_family: PerFamily,
    /// Every rollout in which B leaves the road: the scene, its family and the quantile.
    pub b_offroads: Vec<BOffroad>,
}

/// One rollout of the curve in which B left the road.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BOffroad {
    /// The scene.
    pub scenario_id: String,
    /// Its family (synthetic) or `womd`.
    pub family: String,
    /// The quantile asked of B.
    pub quantile: f32,
}

/// One rollout of the curve in which B collided.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BCollision {
    /// The scene.
    pub scenario_id: String,
    /// Its family (synthetic) or `womd`.
    pub family: String,
    /// The quantile asked of B.
    pub quantile: f32,
    /// B's first box overlap.
    pub contact: Contact,
    /// Whether B's box already overlapped another's at the current step (the log's start).
    pub starts_in_contact: bool,
}

impl KnobCurve {
    /// One line on B's collisions: the largest rate over the quantiles, and the same over
    /// the scenes where B starts clear of every other agent.
    pub fn collision_line(&self) -> String {
        let at_start = self.b_collisions.iter().filter(|b| b.starts_in_contact);
        let scenes: std::collections::BTreeSet<&str> =
            at_start.map(|b| b.scenario_id.as_str()).collect();
        format!(
            "B's collision rate at most {} over the quantiles; {} in the scenes where B starts clear of every other agent ({} scene(s) start with B's box overlapping another in the log)",
            fmt_or_na(self.max_b_collision_rate, 3),
            fmt_or_na(self.max_b_collision_rate_clear_start, 3),
            scenes.len()
        )
    }

    /// One line on B leaving the road: the share of its rollouts, pooled and per family.
    pub fn offroad_line(&self) -> String {
        let pct = |x: &Option<f64>| fmt_or_na(x.map(|x| 100.0 * x), 1);
        let families: Vec<String> = self
            .b_offroad_rate_per_family
            .iter()
            .filter(|(f, _)| f.as_str() != "all")
            .map(|(f, x)| format!("{f} {} %", pct(x)))
            .collect();
        format!(
            "B off the road in {} % of its rollouts ({})",
            pct(self.b_offroad_rate_per_family.get("all").unwrap_or(&None)),
            families.join(", ")
        )
    }

    /// The curve of `done` scenes, each with one (A, B) result per quantile of `quantiles`
    /// (no row without a scene).
    pub(super) fn of(done: &[SceneResult], quantiles: &[f32]) -> Self {
        let quantiles = if done.is_empty() { &[][..] } else { quantiles };
        let mut speed_points = Vec::new();
        let mut courtesy_points = Vec::new();
        let mut per_quantile = Vec::new();
        for (k, &q) in quantiles.iter().enumerate() {
            let speeds: Vec<f64> = done.iter().map(|r| r.curve[k].0.avg_speed_mps).collect();
            let realised: Vec<f64> = done
                .iter()
                .map(|r| r.curve[k].0.avg_speed_mps - r.base_a_speed)
                .collect();
            for (r, (&v, &c)) in done.iter().zip(speeds.iter().zip(&realised)) {
                speed_points.push((r.family.clone(), f64::from(q), v));
                courtesy_points.push((r.family.clone(), f64::from(q), c));
            }
            let (a_avg_speed_mps, a_avg_speed_std_mps) = mean_std(&speeds).unwrap_or_default();
            let (realised_courtesy_mps, realised_courtesy_std_mps) =
                mean_std(&realised).unwrap_or_default();
            let b = || done.iter().map(|r| &r.curve[k].1);
            per_quantile.push(QuantileSim {
                quantile: q,
                a_avg_speed_mps,
                a_avg_speed_std_mps,
                realised_courtesy_mps,
                realised_courtesy_std_mps,
                b_collision_rate: rate(b().map(|m| m.collision)).unwrap_or_default(),
                b_collision_rate_clear_start: rate(
                    b().filter(|m| !m.starts_in_contact).map(|m| m.collision),
                ),
                b_offroad_rate: rate(b().filter_map(|m| m.offroad)),
                b_mean_abs_jerk_mps3: mean_std(
                    &b().map(|m| m.mean_abs_jerk_mps3).collect::<Vec<_>>(),
                )
                .unwrap_or_default()
                .0,
                b_progress_m: mean_std(&b().map(|m| m.progress_m).collect::<Vec<_>>())
                    .unwrap_or_default()
                    .0,
                wosac: None,
            });
        }
        let b_collisions = quantiles
            .iter()
            .enumerate()
            .flat_map(|(k, &q)| {
                done.iter().filter_map(move |r| {
                    let b = &r.curve[k].1;
                    b.first_contact.map(|contact| BCollision {
                        scenario_id: r.scenario_id.clone(),
                        family: r.family.clone(),
                        quantile: q,
                        contact,
                        starts_in_contact: b.starts_in_contact,
                    })
                })
            })
            .collect();
        let offroad: Vec<(&SceneResult, f32, bool)> = quantiles
            .iter()
            .enumerate()
            .flat_map(|(k, &q)| {
                done.iter()
                    .filter_map(move |r| r.curve[k].1.offroad.map(|off| (r, q, off)))
            })
            .collect();
        let mut b_offroad_rate_per_family = PerFamily::new();
        b_offroad_rate_per_family.insert("all".into(), rate(offroad.iter().map(|o| o.2)));
        for (r, ..) in &offroad {
            b_offroad_rate_per_family
                .entry(r.family.clone())
                .or_insert_with(|| {
                    rate(
                        offroad
                            .iter()
                            .filter(|o| o.0.family == r.family)
                            .map(|o| o.2),
                    )
                });
        }
        let b_offroads = offroad
            .iter()
            .filter(|o| o.2)
            .map(|(r, q, _)| BOffroad {
                scenario_id: r.scenario_id.clone(),
                family: r.family.clone(),
                quantile: *q,
            })
            .collect();
        let (spearman_within_scene_a_speed, responsive_fraction, spearman_quantile_a_speed_ordered) =
            within_scene(done, quantiles);
        Self {
            b_offroad_rate_per_family,
            b_offroads,
            scenes: done.len(),
            spearman_within_scene_a_speed,
            responsive_fraction,
            b_collisions,
            a_speed_curve_rises: (!per_quantile.is_empty()).then(|| {
                per_quantile
                    .windows(2)
                    .all(|w| w[1].a_avg_speed_mps >= w[0].a_avg_speed_mps)
            }),
            max_b_collision_rate: per_quantile
                .iter()
                .map(|r| r.b_collision_rate)
                .reduce(f64::max),
            max_b_collision_rate_clear_start: per_quantile
                .iter()
                .filter_map(|r| r.b_collision_rate_clear_start)
                .reduce(f64::max),
            per_quantile,
            spearman_quantile_a_speed: spearman_per_family(&speed_points),
            spearman_quantile_realised_courtesy: spearman_per_family(&courtesy_points),
            spearman_quantile_a_speed_ordered,
        }
    }
}

/// `x` with `decimals` decimals, or `n/a`.
pub(crate) fn fmt_or_na(x: Option<f64>, decimals: usize) -> String {
    x.map_or("n/a".into(), |x| format!("{x:.decimals$}"))
}

/// The synthetic world's own knob on a scene: B driven by the world's rule with courtesy
/// `c = q` (B's prior is uniform, so its q-quantile is q) from the current step on, A and the
/// others reacting by the same rule as in the closed loop; `None` without ground truth.
pub(super) fn world_scene(
    s: &SimScene,
    quantiles: &[f32],
    base: usize,
) -> Option<anyhow::Result<SceneResult>> {
    let truth = s.truth.as_ref()?;
    Some(world_curve(s, truth, quantiles).map(|curve| SceneResult::new(s, curve, base)))
}

/// The (A, B) metrics of scene `s` at each quantile with B driven by the world's rule.
fn world_curve(
    s: &SimScene,
    truth: &GroundTruth,
    quantiles: &[f32],
) -> anyhow::Result<Vec<(AgentRolloutMetrics, AgentRolloutMetrics)>> {
    let scenario = scbg_synth::Scenario::of_truth(truth)?;
    let mut scene = s.scene.clone();
    quantiles
        .iter()
        .map(|&q| {
            let tracks = scenario.tracks_with_courtesy(f64::from(q));
            anyhow::ensure!(
                tracks.len() == s.scene.tracks.len()
                    && tracks
                        .iter()
                        .zip(&s.scene.tracks)
                        .all(|(a, b)| a.id == b.id),
                "scenario {}: the world's tracks are not the scene's",
                s.scene.scenario_id
            );
            scene.tracks = tracks;
            let r = report(&scene, s.ego, &[s.controlled])?;
            Ok((r.ego, r.controlled[0]))
        })
        .collect()
}

/// The scenes that ran; each one that failed is counted in `skips` under `prefix` and its
/// reason.
pub(super) fn kept_counting_skips(
    results: Vec<(&SimScene, anyhow::Result<SceneResult>)>,
    prefix: &str,
    skips: &mut Skips,
) -> Vec<SceneResult> {
    let mut kept = Vec::new();
    for (s, r) in results {
        match r {
            Ok(r) => kept.push(r),
            Err(e) => skips.error(prefix, &s.scene.scenario_id, &e),
        }
    }
    kept
}

/// The smallest change of A's realised average speed (m/s) over a scene's quantiles that
/// counts as the knob acting in that scene ([`KnobCurve::spearman_within_scene_a_speed`]).
pub const RESPONSIVE_SPEED_MPS: f64 = 0.01;

/// Per family and pooled: the mean over scenes of Spearman(quantile, A's realised speed)
/// within each scene (0 where it does not respond), the share of responsive scenes, and the
/// pooled Spearman with each scene's speeds ordered to rise with the quantile
/// ([`KnobCurve::spearman_quantile_a_speed_ordered`]).
fn within_scene(done: &[SceneResult], quantiles: &[f32]) -> (PerFamily, PerFamily, PerFamily) {
    let q: Vec<f64> = quantiles.iter().map(|&q| f64::from(q)).collect();
    let speeds: Vec<(&str, Vec<f64>)> = done
        .iter()
        .map(|r| {
            let v = r.curve.iter().map(|c| c.0.avg_speed_mps).collect();
            (r.family.as_str(), v)
        })
        .collect();
    let (within, responsive) = crate::fidelity::within_group_spearman(
        speeds.iter().map(|(family, v)| (*family, v.as_slice())),
        &q,
        RESPONSIVE_SPEED_MPS,
    );
    let ordered = crate::fidelity::ordered_pooled_spearman(
        speeds.iter().map(|(family, v)| (*family, v.as_slice())),
        &q,
    );
    let some = |m: BTreeMap<String, f64>| m.into_iter().map(|(k, v)| (k, Some(v))).collect();
    (some(within), some(responsive), ordered)
}

fn spearman_per_family(points: &[(String, f64, f64)]) -> PerFamily {
    let mut out = PerFamily::new();
    let mut families: Vec<&str> = points.iter().map(|p| p.0.as_str()).collect();
    families.sort_unstable();
    families.dedup();
    let corr = |f: Option<&str>| {
        let (x, y): (Vec<f64>, Vec<f64>) = points
            .iter()
            .filter(|p| f.is_none_or(|f| p.0 == f))
            .map(|p| (p.1, p.2))
            .unzip();
        scbg_metrics::spearman(&x, &y)
    };
    out.insert("all".into(), corr(None));
    for f in families {
        out.insert(f.to_string(), corr(Some(f)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn metrics(speed_mps: f64, offroad: Option<bool>) -> AgentRolloutMetrics {
        AgentRolloutMetrics {
            id: 0,
            collision: false,
            first_contact: None,
            starts_in_contact: false,
            offroad,
            progress_m: 10.0,
            avg_speed_mps: speed_mps,
            max_abs_jerk_mps3: 0.0,
            mean_abs_jerk_mps3: 0.0,
            valid_steps: 80,
        }
    }

    fn scene(id: &str, family: &str, b_offroad: [Option<bool>; 3]) -> SceneResult {
        SceneResult {
            scenario_id: id.into(),
            family: family.into(),
            curve: b_offroad
                .iter()
                .enumerate()
                .map(|(k, &off)| (metrics(10.0 + k as f64, Some(false)), metrics(8.0, off)))
                .collect(),
            base_a_speed: 11.0,
        }
    }

    #[test]
    fn off_road_rollouts_are_counted_per_family_and_listed() {
        let done = [
            scene("a", "crossing", [Some(false), Some(true), Some(false)]),
            scene("b", "crossing", [Some(false); 3]),
            scene("c", "merge", [Some(true), Some(true), Some(false)]),
            // A map without road edges: not counted either way.
            scene("d", "following", [None; 3]),
        ];
        let curve = KnobCurve::of(&done, &[0.1, 0.5, 0.9]);
        let rate = |f: &str| curve.b_offroad_rate_per_family[f];
        assert_eq!(rate("crossing"), Some(1.0 / 6.0));
        assert_eq!(rate("merge"), Some(2.0 / 3.0));
        assert_eq!(rate("all"), Some(3.0 / 9.0));
        assert!(!curve.b_offroad_rate_per_family.contains_key("following"));
        let listed: Vec<(&str, f32)> = curve
            .b_offroads
            .iter()
            .map(|o| (o.scenario_id.as_str(), o.quantile))
            .collect();
        assert_eq!(listed, [("c", 0.1), ("a", 0.5), ("c", 0.5)]);
        assert_eq!(
            curve.offroad_line(),
            "B off the road in 33.3 % of its rollouts (crossing 16.7 %, merge 66.7 %)"
        );
    }
}
