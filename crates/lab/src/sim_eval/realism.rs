//! WOSAC realism of `eval sim`: per WOSAC scene, scbg's 32 rollouts around each WOSAC
//! quantile and with the knob drawn from its prior, and the log replay, constant velocity and
//! IDM-only baselines; then their summaries over scenes and scbg's per-scene differences to
//! IDM-only.

use std::collections::BTreeMap;

use scbg_metrics::wosac::{DatasetMetrics, Rollouts, ScenarioMetrics, WosacConfig};
use scbg_scene::Scene;
use scbg_sim::{SimConfig, Simulation};
use serde::Serialize;

use super::{SimEval, SimEvalOptions, SimScene, mean_std, rate, rollout_at};
use crate::generator::LoadedScbg;
use scbg::sim::{
    AgentRolloutMetrics, EgoMode, FirstPlans, OthersMode, report, rollout_quantiles,
    scene_of_rollout, wosac_rollouts,
};

/// WOSAC numbers of one method over the WOSAC scenes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WosacSummary {
    /// Scenes scored.
    pub scenes: usize,
    /// Mean realism meta-metric.
    pub metametric: f32,
    /// Kinematic bucket.
    pub kinematic: f32,
    /// Interactive bucket.
    pub interactive: f32,
    /// Map-based bucket.
    pub map_based: f32,
    /// Mean minADE, m.
    pub min_ade_m: f32,
    /// Simulated collision rate (evaluated objects).
    pub collision_rate: f32,
    /// Simulated off-road rate (evaluated objects).
    pub offroad_rate: f32,
}

impl WosacSummary {
    fn of(m: &DatasetMetrics) -> Self {
        Self {
            scenes: m.num_scenarios,
            metametric: m.metametric,
            kinematic: m.buckets.kinematic,
            interactive: m.buckets.interactive,
            map_based: m.buckets.map_based,
            min_ade_m: m.min_average_displacement_error_m,
            collision_rate: m.simulated_collision_rate,
            offroad_rate: m.simulated_offroad_rate,
        }
    }
}

/// A baseline on the WOSAC scenes (`None` where no scene was scored).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BaselineSim {
    /// A's realised average speed, m/s.
    pub a_avg_speed_mps: Option<f64>,
    /// Fraction of scenes in which B collides.
    pub b_collision_rate: Option<f64>,
    /// Fraction of scenes in which B goes off-road (over the scenes whose map has road
    /// edges).
    pub b_offroad_rate: Option<f64>,
    /// WOSAC realism.
    pub wosac: Option<WosacSummary>,
}

/// A per-scene difference of two methods' meta-metrics on the same scenes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairedDifference {
    /// Scenes with both methods scored.
    pub scenes: usize,
    /// Mean difference.
    pub mean: f64,
    /// Standard error of the mean (sample standard deviation / √scenes; 0 for one scene).
    pub std_error: f64,
}

impl PairedDifference {
    fn of(diffs: &[f64]) -> Option<Self> {
        let n = diffs.len();
        if n == 0 {
            return None;
        }
        let mean = diffs.iter().sum::<f64>() / n as f64;
        let var = if n > 1 {
            diffs.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (n - 1) as f64
        } else {
            0.0
        };
        Some(Self {
            scenes: n,
            mean,
            std_error: (var / n as f64).sqrt(),
        })
    }
}

impl SimEval {
    /// One line on realism: scbg's WOSAC meta-metric over its quantiles and with the knob
    /// drawn from its prior, each with its per-scene difference to IDM-only, and the baselines.
    pub fn realism_line(&self) -> String {
        let meta =
            |w: Option<&WosacSummary>| w.map_or("n/a".into(), |w| format!("{:.4}", w.metametric));
        let diff = |d: &Option<PairedDifference>| {
            d.as_ref().map_or(String::new(), |d| {
                format!(
                    " (minus IDM-only per scene {:+.4} ± {:.4} s.e.)",
                    d.mean, d.std_error
                )
            })
        };
        let baseline = |name: &str| meta(self.baselines.get(name).and_then(|b| b.wosac.as_ref()));
        format!(
            "WOSAC meta-metric on {} scenes: scbg over its quantiles {}{}; scbg with the knob drawn from its prior {}{}; IDM-only {}, constant velocity {}, log replay {}",
            self.baselines
                .get("idm_only")
                .and_then(|b| b.wosac.as_ref())
                .map_or(0, |w| w.scenes),
            meta(self.wosac_scbg.as_ref()),
            diff(&self.wosac_scbg_minus_idm),
            meta(self.wosac_scbg_prior.as_ref()),
            diff(&self.wosac_prior_minus_idm),
            baseline("idm_only"),
            baseline("constant_velocity"),
            baseline("log_replay"),
        )
    }
}

/// 32 rollouts of scbg around `q`, as WOSAC rollouts.
fn scbg_rollouts(
    model: &LoadedScbg,
    s: &SimScene,
    q: f32,
    spread: f32,
    options: &SimEvalOptions,
    first_plans: &FirstPlans,
) -> anyhow::Result<Rollouts> {
    let scenes = rollout_quantiles(q, options.rollouts, spread)
        .into_iter()
        .map(|qr| rollout_at(model, s, qr, options.config, first_plans))
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok(wosac_rollouts(&s.scene, &scenes))
}

/// The WOSAC method name of scbg with the knob drawn from its prior.
const PRIOR: &str = "prior";

/// IDM-only agents: nobody controlled, A and the others IDM along their logged paths.
fn idm_only(s: &SimScene) -> anyhow::Result<Scene> {
    let config = SimConfig {
        ego: EgoMode::Reactive,
        others: OthersMode::Reactive,
        ..SimConfig::default()
    };
    let mut sim = Simulation::reset(&s.scene, Some(s.ego), &[], config, None)?;
    struct Nobody;
    impl scbg_sim::Planner for Nobody {
        fn plan(&mut self, _: &Scene, id: i64) -> Result<Vec<[f64; 2]>, scbg_sim::PlanError> {
            Err(scbg_sim::PlanError(format!("agent {id} is not controlled")))
        }
    }
    sim.run(&mut Nobody)?;
    Ok(sim.to_scene())
}

pub(super) type Scored = (
    BTreeMap<String, (AgentRolloutMetrics, AgentRolloutMetrics)>,
    BTreeMap<String, ScenarioMetrics>,
);

/// The WOSAC part of one scene: metrics per method (`q=0.1`, …, baselines) and the baselines'
/// rollout metrics (ego, B).
pub(super) fn wosac_scene(
    model: &LoadedScbg,
    s: &SimScene,
    options: &SimEvalOptions,
) -> anyhow::Result<Scored> {
    let n = options.rollouts;
    let mut metrics = BTreeMap::new();
    let mut rollout_metrics = BTreeMap::new();
    let score = |r: &Rollouts| scbg_metrics::wosac::scenario_metrics(&s.scene, r, options.wosac);
    // Every rollout of the scene shares its first plan.
    let first_plans = FirstPlans::default();
    for &q in &options.wosac_quantiles {
        let r = scbg_rollouts(model, s, q, options.spread, options, &first_plans)?;
        metrics.insert(quantile_method(q), score(&r)?);
    }
    if options.wosac_prior {
        let r = scbg_rollouts(model, s, 0.5, 1.0, options, &first_plans)?;
        metrics.insert(PRIOR.to_string(), score(&r)?);
    }
    let idm_scene = idm_only(s)?;
    let idm = wosac_rollouts(&s.scene, &vec![idm_scene; n]);
    for (name, r) in [
        (
            "log_replay",
            scbg_metrics::wosac::log_replay_rollouts(&s.scene, n)?,
        ),
        (
            "constant_velocity",
            scbg_metrics::wosac::constant_velocity_rollouts(&s.scene, n)?,
        ),
        ("idm_only", idm),
    ] {
        metrics.insert(name.to_string(), score(&r)?);
        let mut scene = scene_of_rollout(&s.scene, &r, 0);
        if name == "log_replay" {
            // The replay copies the log's placeholders of invalid steps; they are no motion.
            keep_log_validity(&mut scene, &s.scene);
        }
        let rep = report(&scene, s.ego, &[s.controlled])?;
        rollout_metrics.insert(name.to_string(), (rep.ego, rep.controlled[0]));
    }
    Ok((rollout_metrics, metrics))
}

/// Marks invalid every future state of `scene` whose state in `log` is invalid (or missing),
/// and gives the first valid state after an invalid one the log's velocity (the finite
/// difference from a placeholder is no speed).
fn keep_log_validity(scene: &mut Scene, log: &Scene) {
    let start = log.current_step;
    for (tr, logged) in scene.tracks.iter_mut().zip(&log.tracks) {
        let valid = |t: usize| logged.states.get(t).is_some_and(|s| s.valid);
        for (t, state) in tr.states.iter_mut().enumerate().skip(start + 1) {
            if !valid(t) {
                state.valid = false;
            } else if !valid(t - 1) {
                state.velocity_x_mps = logged.states[t].velocity_x_mps;
                state.velocity_y_mps = logged.states[t].velocity_y_mps;
            }
        }
    }
}

/// The WOSAC method name of scbg around quantile `q`.
fn quantile_method(q: f32) -> String {
    format!("q={q:.1}")
}

fn is_quantile_method(name: &str) -> bool {
    name.starts_with("q=")
}

/// The baselines, by WOSAC method name.
const BASELINES: [&str; 3] = ["log_replay", "constant_velocity", "idm_only"];

/// The realism part of [`SimEval`], summarised over the WOSAC scenes.
pub(super) struct Realism {
    /// Every method's summary, by WOSAC method name.
    by_method: BTreeMap<String, WosacSummary>,
    pub(super) wosac_scbg: Option<WosacSummary>,
    pub(super) baselines: BTreeMap<String, BaselineSim>,
    pub(super) wosac_above_baselines: Option<bool>,
    pub(super) wosac_scbg_minus_idm: Option<PairedDifference>,
    pub(super) wosac_scbg_prior: Option<WosacSummary>,
    pub(super) wosac_prior_minus_idm: Option<PairedDifference>,
    pub(super) wosac_prior_above_baselines: Option<bool>,
}

impl Realism {
    /// The summaries of the `scored` WOSAC scenes.
    pub(super) fn of(scored: &[Scored], config: WosacConfig) -> Self {
        let summary = |m: &[ScenarioMetrics]| {
            scbg_metrics::wosac::aggregate(m, config).map(|m| WosacSummary::of(&m))
        };
        let mut names: Vec<&String> = scored.iter().flat_map(|s| s.1.keys()).collect();
        names.sort_unstable();
        names.dedup();
        let by_method: BTreeMap<String, WosacSummary> = names
            .into_iter()
            .filter_map(|name| {
                let m: Vec<ScenarioMetrics> = scored
                    .iter()
                    .filter_map(|s| s.1.get(name).cloned())
                    .collect();
                Some((name.clone(), summary(&m)?))
            })
            .collect();
        let all_scbg: Vec<ScenarioMetrics> = scored
            .iter()
            .flat_map(|s| {
                s.1.iter()
                    .filter(|(k, _)| is_quantile_method(k))
                    .map(|(_, v)| v.clone())
            })
            .collect();
        let wosac_scbg = summary(&all_scbg);
        let baselines: BTreeMap<String, BaselineSim> = BASELINES
            .into_iter()
            .map(|name| {
                let rm: Vec<&(AgentRolloutMetrics, AgentRolloutMetrics)> =
                    scored.iter().filter_map(|s| s.0.get(name)).collect();
                let baseline = BaselineSim {
                    a_avg_speed_mps: mean_std(
                        &rm.iter().map(|m| m.0.avg_speed_mps).collect::<Vec<_>>(),
                    )
                    .map(|(mean, _)| mean),
                    b_collision_rate: rate(rm.iter().map(|m| m.1.collision)),
                    b_offroad_rate: rate(rm.iter().filter_map(|m| m.1.offroad)),
                    wosac: by_method.get(name).cloned(),
                };
                (name.to_string(), baseline)
            })
            .collect();
        let above_baselines = |w: &Option<WosacSummary>| {
            let w = w.as_ref()?;
            let cv = baselines["constant_velocity"].wosac.as_ref()?.metametric;
            let idm = baselines["idm_only"].wosac.as_ref()?.metametric;
            Some(w.metametric > cv && w.metametric > idm)
        };
        // Per scene: the mean meta-metric of the chosen scbg runs minus IDM-only's.
        let minus_idm = |pick: &dyn Fn(&str) -> bool| {
            let diffs: Vec<f64> = scored
                .iter()
                .filter_map(|(_, m)| {
                    let idm = f64::from(m.get("idm_only")?.metametric);
                    let ours: Vec<f64> = m
                        .iter()
                        .filter(|(k, _)| pick(k))
                        .map(|(_, v)| f64::from(v.metametric))
                        .collect();
                    (!ours.is_empty()).then(|| ours.iter().sum::<f64>() / ours.len() as f64 - idm)
                })
                .collect();
            PairedDifference::of(&diffs)
        };
        let wosac_scbg_prior = by_method.get(PRIOR).cloned();
        Self {
            wosac_above_baselines: above_baselines(&wosac_scbg),
            wosac_prior_above_baselines: above_baselines(&wosac_scbg_prior),
            wosac_scbg_minus_idm: minus_idm(&is_quantile_method),
            wosac_prior_minus_idm: minus_idm(&|k| k == PRIOR),
            wosac_scbg,
            wosac_scbg_prior,
            baselines,
            by_method,
        }
    }

    /// scbg's summary around quantile `q` (a WOSAC quantile), if scored.
    pub(super) fn at_quantile(&self, q: f32) -> Option<WosacSummary> {
        self.by_method.get(&quantile_method(q)).cloned()
    }
}

#[cfg(test)]
mod tests {
    use super::PairedDifference;

    #[test]
    fn paired_difference_is_mean_and_standard_error() {
        assert_eq!(PairedDifference::of(&[]), None);
        let one = PairedDifference::of(&[0.25]).unwrap();
        assert_eq!((one.scenes, one.mean, one.std_error), (1, 0.25, 0.0));
        // 1, 2, 3, 6: mean 3, sample variance (4 + 1 + 0 + 9) / 3 = 14/3.
        let d = PairedDifference::of(&[1.0, 2.0, 3.0, 6.0]).unwrap();
        assert_eq!((d.scenes, d.mean), (4, 3.0));
        assert!((d.std_error - (14.0f64 / 3.0 / 4.0).sqrt()).abs() < 1e-12);
    }
}
