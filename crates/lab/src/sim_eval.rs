//! `scbg eval sim`: the courtesy knob in closed loop. For each scene and quantile, a rollout
//! with the controlled agent (B) driven by the model's policy (the generator by default) and A
//! reactive: A's realised average
//! speed, *realised courtesy* (A's realised speed minus A's realised speed in the same scene
//! with B at quantile 0.5 — the world is deterministic, so "same seeds" holds by
//! construction), B's collision, off-road, jerk and progress; on a subset of scenes the WOSAC
//! realism of 32 rollouts per quantile, beside log replay, constant velocity and IDM-only
//! agents on the same scenes.

mod curve;
mod figures;
mod realism;
mod scenes;

pub(crate) use curve::fmt_or_na;
pub use curve::{BCollision, BOffroad, KnobCurve, RESPONSIVE_SPEED_MPS};
use curve::{kept_counting_skips, world_scene};
pub use figures::write_figures;
pub use realism::{BaselineSim, PairedDifference, WosacSummary};
use scenes::Skips;
pub use scenes::{
    NO_PAIR, PairOrigin, SceneSources, SimScene, SkippedScene, TOO_SHORT, load_scenes,
};

use std::collections::BTreeMap;
use std::path::Path;

use rayon::prelude::*;
use scbg_metrics::wosac::WosacConfig;
use scbg_scene::Scene;
use scbg_sim::SimConfig;
use serde::Serialize;

use crate::generator::LoadedScbg;
use scbg::sim::{
    AgentRolloutMetrics, ControlledAgent, FirstPlans, OthersMode, report, rollout_sharing,
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
    /// ([`scbg::sim::default_replan_every`]).
    pub fn of_policy(policy: scbg_generator::Policy) -> Self {
        let mut options = Self {
            policy,
            ..Self::default()
        };
        options.config.replan_every = scbg::sim::default_replan_every(policy);
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
                replan_every: scbg::sim::default_replan_every(scbg_generator::Policy::Generator),
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
    /// contact in the log's start state is none of the rollout's doing); `None` when B starts
    /// in contact in every scene.
    pub b_collision_rate_clear_start: Option<f64>,
    /// Fraction of scenes in which B goes off-road, over the scenes whose map has road edges
    /// (`None` when none has).
    pub b_offroad_rate: Option<f64>,
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
    /// Scenes skipped, counted by why; the scenes whose WOSAC realism is not applicable (or
    /// failed) under `WOSAC realism …` keys.
    pub skipped: BTreeMap<String, usize>,
    /// Each scene counted in `skipped`, with its reason (left out when there is none).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub skipped_scenes: Vec<SkippedScene>,
    /// Where the scenes came from, when some were cut from longer scenes or had their pair
    /// chosen by `data prepare`'s rule (left out when every scene is its own window with the
    /// pair its log names, as on synthetic data).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sources: Option<SceneSources>,
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

/// Mean and standard deviation; `None` for no value (never NaN).
fn mean_std(v: &[f64]) -> Option<(f64, f64)> {
    if v.is_empty() {
        return None;
    }
    let m = v.iter().sum::<f64>() / v.len() as f64;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64;
    Some((m, var.sqrt())).filter(|(m, s)| m.is_finite() && s.is_finite())
}

/// The share of `true`; `None` for no value (never NaN).
fn rate(v: impl Iterator<Item = bool>) -> Option<f64> {
    let (n, k) = v.fold((0usize, 0usize), |(n, k), b| (n + 1, k + usize::from(b)));
    (n > 0).then(|| k as f64 / n as f64)
}

/// One rollout of scene `s` with B asked for quantile `q` (A and the others as `config`).
fn rollout_at(
    model: &LoadedScbg,
    s: &SimScene,
    q: f32,
    config: SimConfig,
    first_plans: &FirstPlans,
) -> anyhow::Result<Scene> {
    let controlled = [ControlledAgent::new(
        s.controlled,
        scbg::Courtesy::quantile(q)?,
    )];
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
    let scenes = scenes::first_logged(scenes, options.scenes);
    let curve_started = std::time::Instant::now();
    let results: Vec<(&SimScene, anyhow::Result<SceneResult>)> = scenes
        .par_iter()
        .map(|s| {
            // The quantiles' rollouts share their first plan (`FirstPlans`).
            let first_plans = FirstPlans::default();
            let curve = quantiles
                .iter()
                .map(|&q| one_rollout(model, s, q, options.config, &first_plans))
                .collect::<anyhow::Result<Vec<_>>>();
            (s, curve.map(|curve| SceneResult::new(s, curve, base)))
        })
        .collect();
    let curve_seconds = curve_started.elapsed().as_secs_f64();
    let ran: Vec<&SimScene> = results
        .iter()
        .filter(|(_, r)| r.is_ok())
        .map(|(s, _)| *s)
        .collect();
    let sources = SceneSources::of(&ran);
    let mut skips = Skips::default();
    let done = kept_counting_skips(results, "", &mut skips);
    let mut curve = KnobCurve::of(&done, &quantiles);
    // WOSAC realism on the first scenes where it applies (the WOSAC layout, an evaluated
    // object, road edges), each logged scene's first window first; the others are counted as
    // not applicable.
    let applicable: Vec<Result<(), scbg_metrics::wosac::WosacError>> = scenes
        .par_iter()
        .map(|s| scbg_metrics::wosac::check_scene(&s.scene))
        .collect();
    for (s, check) in scenes.iter().zip(&applicable) {
        if let Err(e) = check {
            skips.add(
                &s.scene.scenario_id,
                format!("{REALISM_NA}{}", e.reason()),
                Some(e.to_string()),
            );
        }
    }
    let wosac_scenes: Vec<&SimScene> = scenes::spread_over_logged(scenes)
        .into_iter()
        .filter(|&i| applicable[i].is_ok())
        .take(options.wosac_scenes)
        .map(|i| &scenes[i])
        .collect();
    let scored: Vec<(&SimScene, anyhow::Result<realism::Scored>)> = wosac_scenes
        .par_iter()
        .map(|s| (*s, realism::wosac_scene(model, s, options)))
        .collect();
    let mut realism_scored = Vec::new();
    for (s, r) in scored {
        match r {
            Ok(r) => realism_scored.push(r),
            Err(e) => skips.error(REALISM_FAILED, &s.scene.scenario_id, &e),
        }
    }
    let realism = realism::Realism::of(&realism_scored, options.wosac);
    for row in &mut curve.per_quantile {
        row.wosac = realism.at_quantile(row.quantile);
    }
    // The world's own knob on the same scenes (synthetic scenes only).
    let world = kept_counting_skips(
        scenes
            .par_iter()
            .filter_map(|s| Some((s, world_scene(s, &quantiles, base)?)))
            .collect(),
        "world knob: ",
        &mut skips,
    );
    let world_knob = (!world.is_empty()).then(|| KnobCurve::of(&world, &quantiles));
    let rollouts_done = done.len() * quantiles.len();
    Ok(SimEval {
        policy: model.scbg.policy.name(),
        curve,
        skipped: skips.counts,
        skipped_scenes: skips.scenes,
        sources,
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

/// The prefix of the reasons a scene's WOSAC realism is not applicable.
pub const REALISM_NA: &str = "WOSAC realism n/a: ";
/// The prefix of the reasons a scene's WOSAC realism failed.
pub const REALISM_FAILED: &str = "WOSAC realism failed: ";

impl SimEval {
    /// Counts and lists `skipped` (scenes left out before the evaluation, as
    /// [`load_scenes`] returns them) beside the evaluation's own.
    pub fn add_skipped(&mut self, skipped: Vec<SkippedScene>) {
        for s in &skipped {
            *self.skipped.entry(s.reason.clone()).or_insert(0) += 1;
        }
        self.skipped_scenes.splice(0..0, skipped);
    }

    /// One line on what was left out, by reason (`nothing` when nothing was).
    pub fn skipped_line(&self) -> String {
        format!(
            "skipped: {}",
            scbg_base::skips::by_reason_text(&self.skipped)
        )
    }
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
    model.set_policy(options.policy);
    let truth = ground_truth
        .map(crate::synth::read_ground_truth)
        .transpose()?;
    let (scenes, skipped) = load_scenes(
        inputs,
        truth.as_deref(),
        split,
        model.predictor.train_config.validation_fraction,
        options.scenes,
    )?;
    progress.note(&format!(
        "closed loop on {} scenes ({} left out before simulating)",
        scenes.len(),
        skipped.len()
    ));
    let mut eval = evaluate_sim(&model, &scenes, options)?;
    eval.add_skipped(skipped);
    std::fs::create_dir_all(out)?;
    crate::write_json(out.join("eval_sim.json"), &eval)?;
    anyhow::ensure!(
        eval.curve.scenes > 0,
        "no scene could be simulated ({}; eval_sim.json lists each scene)",
        eval.skipped_line()
    );
    write_figures(&eval, out)?;
    Ok(eval)
}
