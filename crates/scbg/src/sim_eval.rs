//! `scbg eval sim`: the courtesy knob in closed loop. For each scene and quantile, a rollout
//! with the controlled agent (B) driven by the model's policy (the generator by default) and A
//! reactive: A's realised average
//! speed, *realised courtesy* (A's realised speed minus A's realised speed in the same scene
//! with B at quantile 0.5 — the world is deterministic, so "same seeds" holds by
//! construction), B's collision, off-road, jerk and progress; on a subset of scenes the WOSAC
//! realism of 32 rollouts per quantile, beside log replay, constant velocity and IDM-only
//! agents on the same scenes.

mod figures;
mod realism;

pub use figures::write_figures;
pub use realism::{BaselineSim, PairedDifference, WosacSummary};

use std::collections::BTreeMap;
use std::path::Path;

use rayon::prelude::*;
use scbg_generator::Courtesy;
use scbg_metrics::wosac::WosacConfig;
use scbg_scene::Scene;
use scbg_sim::SimConfig;
use scbg_synth::GroundTruth;
use serde::Serialize;

use crate::generator::LoadedScbg;
use crate::sim::{
    AgentRolloutMetrics, Contact, ControlledAgent, FirstPlans, OthersMode, report, rollout_sharing,
};

/// What `eval sim` runs.
#[derive(Debug, Clone, PartialEq)]
pub struct SimEvalOptions {
    /// How the controlled agent's courtesy becomes its plans ([`eval_sim_files`] applies it
    /// to the model it loads; [`evaluate_sim`] uses the model's own).
    pub policy: scbg_generator::Policy,
    /// Quantiles of the courtesy curve (0.5 is added for realised courtesy when missing).
    pub quantiles: Vec<f32>,
    /// Scenes of the courtesy curve (the first ones given).
    pub scenes: usize,
    /// Scenes (of those) scored with WOSAC realism.
    pub wosac_scenes: usize,
    /// Quantiles scored with WOSAC (32 rollouts each).
    pub wosac_quantiles: Vec<f32>,
    /// Rollouts per scene and quantile for WOSAC.
    pub rollouts: usize,
    /// Width of the band of quantiles the rollouts spread over.
    pub spread: f32,
    /// Also score scbg with the knob drawn from its prior: rollout `r` of `n` at quantile
    /// `(r + ½)/n`, the whole range (`wosac_scbg_prior`).
    pub wosac_prior: bool,
    /// Closed-loop settings (default: the generator's cadence, every 20 steps, A and the
    /// others reactive; [`SimEvalOptions::of_policy`] sets a policy's own cadence).
    pub config: SimConfig,
    /// The WOSAC definition.
    pub wosac: WosacConfig,
}

impl SimEvalOptions {
    /// The defaults with `policy` and its default re-planning cadence
    /// ([`crate::sim::default_replan_every`]).
    pub fn of_policy(policy: scbg_generator::Policy) -> Self {
        let mut options = Self {
            policy,
            ..Self::default()
        };
        options.config.replan_every = crate::sim::default_replan_every(policy);
        options
    }
}

impl Default for SimEvalOptions {
    fn default() -> Self {
        Self {
            policy: scbg_generator::Policy::Generator,
            quantiles: (1..=9).map(|k| k as f32 / 10.0).collect(),
            scenes: 40,
            wosac_scenes: 8,
            wosac_quantiles: vec![0.1, 0.5, 0.9],
            rollouts: scbg_metrics::wosac::ROLLOUTS_PER_SCENARIO,
            spread: 0.2,
            wosac_prior: true,
            config: SimConfig {
                others: OthersMode::Reactive,
                replan_every: crate::sim::default_replan_every(scbg_generator::Policy::Generator),
                ..SimConfig::default()
            },
            wosac: WosacConfig::V2025,
        }
    }
}

/// The closed-loop numbers at one quantile (means over scenes).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct QuantileSim {
    /// The quantile asked of B.
    pub quantile: f32,
    /// A's realised average speed, m/s.
    pub a_avg_speed_mps: f64,
    /// Its standard deviation over scenes.
    pub a_avg_speed_std_mps: f64,
    /// Realised courtesy: A's realised speed minus A's at quantile 0.5, m/s.
    pub realised_courtesy_mps: f64,
    /// Its standard deviation over scenes.
    pub realised_courtesy_std_mps: f64,
    /// Fraction of scenes in which B collides.
    pub b_collision_rate: f64,
    /// The same over the scenes in which B's box overlaps no other at the current step (a
    /// contact in the log's start state is none of the rollout's doing).
    pub b_collision_rate_clear_start: f64,
    /// Fraction of scenes in which B goes off-road.
    pub b_offroad_rate: f64,
    /// B's mean |jerk|, m/s³.
    pub b_mean_abs_jerk_mps3: f64,
    /// B's distance travelled, m.
    pub b_progress_m: f64,
    /// WOSAC realism of 32 rollouts around this quantile (WOSAC quantiles only).
    pub wosac: Option<WosacSummary>,
}

/// Spearman correlations per family and pooled (`all`).
pub type PerFamily = BTreeMap<String, Option<f64>>;

/// Everything `eval sim` measures (`eval_sim.json`; the demo's `closed_loop`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimEval {
    /// What drove B: `generator` or `ranked` (the model's policy).
    pub policy: &'static str,
    /// The generator's courtesy curve: scenes, per quantile, the correlations (its fields
    /// appear at the top level of the JSON).
    #[serde(flatten)]
    pub curve: KnobCurve,
    /// Scenes skipped, with why.
    pub skipped: BTreeMap<String, usize>,
    /// Steps between plans.
    pub replan_every: usize,
    /// The same curve with B driven by the synthetic world's own rule at courtesy `c = q`
    /// (A and the others reacting alike) on the scenes with ground truth: what a B faithful
    /// to its courtesy achieves in this world, the ceiling of the generator's curve.
    pub world_knob: Option<KnobCurve>,
    /// scbg over every WOSAC quantile together (its `scenes` counts scene × quantile runs).
    pub wosac_scbg: Option<WosacSummary>,
    /// Baselines on the WOSAC scenes: `log_replay`, `constant_velocity`, `idm_only`.
    pub baselines: BTreeMap<String, BaselineSim>,
    /// Whether scbg's WOSAC meta-metric beats constant velocity and IDM-only.
    pub wosac_above_baselines: Option<bool>,
    /// scbg's meta-metric minus IDM-only's, per WOSAC scene (scbg's over every WOSAC quantile
    /// of the scene), with its standard error over scenes.
    pub wosac_scbg_minus_idm: Option<PairedDifference>,
    /// scbg with the knob drawn from its prior (the 32 rollouts' quantiles cover [0, 1]
    /// evenly): the distribution of drivers the logged B was drawn from, so the like-for-like
    /// realism comparison with the baselines (`SimEvalOptions::wosac_prior`).
    pub wosac_scbg_prior: Option<WosacSummary>,
    /// `wosac_scbg_prior`'s meta-metric minus IDM-only's, per WOSAC scene.
    pub wosac_prior_minus_idm: Option<PairedDifference>,
    /// Whether `wosac_scbg_prior` beats constant velocity and IDM-only.
    pub wosac_prior_above_baselines: Option<bool>,
    /// Mean wall time of one courtesy-curve rollout, ms (all threads busy).
    pub rollout_ms: f64,
    /// Wall time of the whole evaluation, s.
    pub seconds: f64,
}

/// One scene to evaluate: the scene, its ego and controlled agent, its family.
#[derive(Debug, Clone)]
pub struct SimScene {
    /// The scene (WOSAC layout for the realism part: 91 steps, current step 10).
    pub scene: Scene,
    /// A.
    pub ego: i64,
    /// B.
    pub controlled: i64,
    /// The synthetic ground truth (the reactive rule, and the family).
    pub truth: Option<GroundTruth>,
}

impl SimScene {
    /// A (the SDC) and B (the first other object of interest valid at the current step) of a
    /// scene; `None` when it has no such pair.
    pub fn of(scene: Scene, truth: Option<GroundTruth>) -> Option<Self> {
        let sdc = scene.sdc_track_index?;
        let ego = scene.tracks[sdc].id;
        let valid = |id: i64| {
            scene
                .track_index(id)
                .is_some_and(|i| scene.tracks[i].states[scene.current_step].valid)
        };
        let controlled = scene
            .objects_of_interest
            .iter()
            .copied()
            .find(|&id| id != ego && valid(id))?;
        Some(Self {
            scene,
            ego,
            controlled,
            truth,
        })
    }

    fn family(&self) -> String {
        self.truth
            .as_ref()
            .map_or_else(|| "womd".into(), |t| t.family.name().to_string())
    }
}

struct SceneResult {
    scenario_id: String,
    family: String,
    /// `[quantile]` (ego, B) metrics.
    curve: Vec<(AgentRolloutMetrics, AgentRolloutMetrics)>,
    base_a_speed: f64,
}

impl SceneResult {
    /// The curve of scene `s`; `base` is the index of quantile 0.5 (realised courtesy's zero).
    fn new(
        s: &SimScene,
        curve: Vec<(AgentRolloutMetrics, AgentRolloutMetrics)>,
        base: usize,
    ) -> Self {
        Self {
            scenario_id: s.scene.scenario_id.clone(),
            family: s.family(),
            base_a_speed: curve[base].0.avg_speed_mps,
            curve,
        }
    }
}

fn mean_std(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let m = v.iter().sum::<f64>() / v.len() as f64;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64;
    (m, var.sqrt())
}

fn rate(v: impl Iterator<Item = bool>) -> f64 {
    let (n, k) = v.fold((0usize, 0usize), |(n, k), b| (n + 1, k + usize::from(b)));
    if n == 0 {
        f64::NAN
    } else {
        k as f64 / n as f64
    }
}

/// One rollout of scene `s` with B asked for quantile `q` (A and the others as `config`).
fn rollout_at(
    model: &LoadedScbg,
    s: &SimScene,
    q: f32,
    config: SimConfig,
    first_plans: &FirstPlans,
) -> anyhow::Result<Scene> {
    let controlled = [ControlledAgent {
        id: s.controlled,
        courtesy: Courtesy::Quantile(q),
    }];
    rollout_sharing(
        model,
        &s.scene,
        Some(s.ego),
        &controlled,
        config,
        s.truth.as_ref(),
        first_plans,
    )
}

/// The (A, B) metrics of one rollout of scene `s` at quantile `q`.
fn one_rollout(
    model: &LoadedScbg,
    s: &SimScene,
    q: f32,
    config: SimConfig,
    first_plans: &FirstPlans,
) -> anyhow::Result<(AgentRolloutMetrics, AgentRolloutMetrics)> {
    let out = rollout_at(model, s, q, config, first_plans)?;
    let r = report(&out, s.ego, &[s.controlled])?;
    Ok((r.ego, r.controlled[0]))
}

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
    /// Whether the mean of A's realised speed never falls from one quantile to the next.
    pub a_speed_curve_rises: bool,
    /// The largest B collision rate over the quantiles.
    pub max_b_collision_rate: f64,
    /// The largest over the quantiles of B's collision rate in the scenes where B starts clear
    /// of every other agent ([`QuantileSim::b_collision_rate_clear_start`]).
    pub max_b_collision_rate_clear_start: f64,
    /// Every rollout in which B collides: the scene, the quantile and B's first contact
    /// (with whom, at which step, both speeds, the geometry) — what a diagnosis needs.
    pub b_collisions: Vec<BCollision>,
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
            "B's collision rate at most {:.3} over the quantiles; {:.3} in the scenes where B starts clear of every other agent ({} scene(s) start with B's box overlapping another in the log)",
            self.max_b_collision_rate,
            self.max_b_collision_rate_clear_start,
            scenes.len()
        )
    }

    /// The curve of `done` scenes, each with one (A, B) result per quantile of `quantiles`.
    fn of(done: &[SceneResult], quantiles: &[f32]) -> Self {
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
            let (a_avg_speed_mps, a_avg_speed_std_mps) = mean_std(&speeds);
            let (realised_courtesy_mps, realised_courtesy_std_mps) = mean_std(&realised);
            let b = || done.iter().map(|r| &r.curve[k].1);
            per_quantile.push(QuantileSim {
                quantile: q,
                a_avg_speed_mps,
                a_avg_speed_std_mps,
                realised_courtesy_mps,
                realised_courtesy_std_mps,
                b_collision_rate: rate(b().map(|m| m.collision)),
                b_collision_rate_clear_start: rate(
                    b().filter(|m| !m.starts_in_contact).map(|m| m.collision),
                ),
                b_offroad_rate: rate(b().map(|m| m.offroad.unwrap_or(false))),
                b_mean_abs_jerk_mps3: mean_std(
                    &b().map(|m| m.mean_abs_jerk_mps3).collect::<Vec<_>>(),
                )
                .0,
                b_progress_m: mean_std(&b().map(|m| m.progress_m).collect::<Vec<_>>()).0,
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
        let (spearman_within_scene_a_speed, responsive_fraction, spearman_quantile_a_speed_ordered) =
            within_scene(done, quantiles);
        Self {
            scenes: done.len(),
            spearman_within_scene_a_speed,
            responsive_fraction,
            b_collisions,
            a_speed_curve_rises: per_quantile
                .windows(2)
                .all(|w| w[1].a_avg_speed_mps >= w[0].a_avg_speed_mps),
            max_b_collision_rate: per_quantile
                .iter()
                .map(|r| r.b_collision_rate)
                .fold(0.0, f64::max),
            max_b_collision_rate_clear_start: per_quantile
                .iter()
                .map(|r| r.b_collision_rate_clear_start)
                .fold(0.0, f64::max),
            per_quantile,
            spearman_quantile_a_speed: spearman_per_family(&speed_points),
            spearman_quantile_realised_courtesy: spearman_per_family(&courtesy_points),
            spearman_quantile_a_speed_ordered,
        }
    }
}

/// The synthetic world's own knob on a scene: B driven by the world's rule with courtesy
/// `c = q` (B's prior is uniform, so its q-quantile is q) from the current step on, A and the
/// others reacting by the same rule as in the closed loop; `None` without ground truth.
fn world_scene(
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

/// The scenes that ran; each one that failed is counted in `skipped` under `prefix` and the
/// first part of its error.
fn kept_counting_skips(
    results: Vec<anyhow::Result<SceneResult>>,
    prefix: &str,
    skipped: &mut BTreeMap<String, usize>,
) -> Vec<SceneResult> {
    let mut kept = Vec::new();
    for r in results {
        match r {
            Ok(r) => kept.push(r),
            Err(e) => {
                let why = format!("{e:#}");
                let key = why.split(':').next().unwrap_or("error");
                *skipped.entry(format!("{prefix}{key}")).or_insert(0) += 1;
            }
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

/// Runs the closed-loop evaluation over `scenes` (the first `options.scenes` of them).
pub fn evaluate_sim(
    model: &LoadedScbg,
    scenes: &[SimScene],
    options: &SimEvalOptions,
) -> anyhow::Result<SimEval> {
    let started = std::time::Instant::now();
    let mut quantiles = options.quantiles.clone();
    crate::ensure_request!(
        quantiles
            .iter()
            .chain(&options.wosac_quantiles)
            .all(|q| (0.0..=1.0).contains(q)),
        "every quantile must be in [0, 1]"
    );
    if !quantiles.iter().any(|&q| (q - 0.5).abs() < 1e-6) {
        quantiles.push(0.5);
    }
    quantiles.sort_by(f32::total_cmp);
    let base = quantiles
        .iter()
        .position(|&q| (q - 0.5).abs() < 1e-6)
        .expect("0.5 is there");
    let scenes = &scenes[..scenes.len().min(options.scenes)];
    let curve_started = std::time::Instant::now();
    let results: Vec<anyhow::Result<SceneResult>> = scenes
        .par_iter()
        .map(|s| {
            // The quantiles' rollouts share their first plan (`FirstPlans`).
            let first_plans = FirstPlans::default();
            let curve = quantiles
                .iter()
                .map(|&q| one_rollout(model, s, q, options.config, &first_plans))
                .collect::<anyhow::Result<Vec<_>>>()?;
            Ok(SceneResult::new(s, curve, base))
        })
        .collect();
    let curve_seconds = curve_started.elapsed().as_secs_f64();
    let mut skipped = BTreeMap::new();
    let done = kept_counting_skips(results, "", &mut skipped);
    anyhow::ensure!(
        !done.is_empty(),
        "no scene could be simulated (skipped: {skipped:?})"
    );
    let mut curve = KnobCurve::of(&done, &quantiles);
    // WOSAC realism on the first scenes.
    let wosac_scenes = &scenes[..scenes.len().min(options.wosac_scenes)];
    let scored: Vec<realism::Scored> = wosac_scenes
        .par_iter()
        .filter_map(|s| realism::wosac_scene(model, s, options).ok())
        .collect();
    let realism = realism::Realism::of(&scored, options.wosac);
    for row in &mut curve.per_quantile {
        row.wosac = realism.at_quantile(row.quantile);
    }
    // The world's own knob on the same scenes (synthetic scenes only).
    let world = kept_counting_skips(
        scenes
            .par_iter()
            .filter_map(|s| world_scene(s, &quantiles, base))
            .collect(),
        "world knob: ",
        &mut skipped,
    );
    let world_knob = (!world.is_empty()).then(|| KnobCurve::of(&world, &quantiles));
    let rollouts_done = done.len() * quantiles.len();
    Ok(SimEval {
        policy: model.scbg.policy.name(),
        curve,
        skipped,
        replan_every: options.config.replan_every,
        world_knob,
        wosac_scbg: realism.wosac_scbg,
        baselines: realism.baselines,
        wosac_above_baselines: realism.wosac_above_baselines,
        wosac_scbg_minus_idm: realism.wosac_scbg_minus_idm,
        wosac_scbg_prior: realism.wosac_scbg_prior,
        wosac_prior_minus_idm: realism.wosac_prior_minus_idm,
        wosac_prior_above_baselines: realism.wosac_prior_above_baselines,
        rollout_ms: 1e3 * curve_seconds / rollouts_done.max(1) as f64,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// The scenes of WOMD files for `eval sim`: each scene with its A (SDC) and B (first other
/// object of interest), its synthetic ground truth when `truth` has it, on the split asked
/// (by scenario id, with the predictor's validation fraction). Returns the scenes and the
/// count of scenes without such a pair.
pub fn load_scenes(
    inputs: &[String],
    truth: Option<&[GroundTruth]>,
    split: crate::predictor::SplitSelection,
    validation_fraction: f64,
    max: usize,
) -> anyhow::Result<(Vec<SimScene>, usize)> {
    let index = truth.map(crate::fidelity::TruthIndex::new);
    let mut scenes = Vec::new();
    let mut no_pair = 0;
    'files: for file in crate::inputs::expand(inputs)? {
        for scene in scbg_womd::WomdFile::open(&file)?.scenes() {
            let scene = scene?;
            if split == crate::predictor::SplitSelection::Validation
                && scbg_train::data::split_of(&scene.scenario_id, validation_fraction)
                    != scbg_train::data::Split::Validation
            {
                continue;
            }
            let t = index
                .as_ref()
                .and_then(|i| i.get(&scene.scenario_id))
                .cloned();
            match SimScene::of(scene, t) {
                Some(s) => scenes.push(s),
                None => no_pair += 1,
            }
            if scenes.len() >= max {
                break 'files;
            }
        }
    }
    Ok((scenes, no_pair))
}

/// `scbg eval sim`: loads the model and the scenes, evaluates, writes `eval_sim.json` and the
/// figures into `out`.
#[allow(clippy::too_many_arguments)]
pub fn eval_sim_files(
    model: &Path,
    predictor: Option<&Path>,
    inputs: &[String],
    ground_truth: Option<&Path>,
    split: crate::predictor::SplitSelection,
    options: &SimEvalOptions,
    out: &Path,
    progress: &dyn crate::Progress,
) -> anyhow::Result<SimEval> {
    let mut model = crate::generator::load_scbg(model, predictor)?;
    model.scbg.policy = options.policy;
    let truth = ground_truth
        .map(crate::synth::read_ground_truth)
        .transpose()?;
    let (scenes, no_pair) = load_scenes(
        inputs,
        truth.as_deref(),
        split,
        model.predictor.train_config.validation_fraction,
        options.scenes,
    )?;
    progress.note(&format!(
        "closed loop on {} scenes ({} without an SDC and another object of interest)",
        scenes.len(),
        no_pair
    ));
    let mut eval = evaluate_sim(&model, &scenes, options)?;
    if no_pair > 0 {
        eval.skipped.insert("no A–B pair".into(), no_pair);
    }
    std::fs::create_dir_all(out)?;
    crate::write_json(out.join("eval_sim.json"), &eval)?;
    write_figures(&eval, out)?;
    Ok(eval)
}
