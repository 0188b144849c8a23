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

pub use curve::{BCollision, KnobCurve, RESPONSIVE_SPEED_MPS};
use curve::{kept_counting_skips, world_scene};
pub use figures::write_figures;
pub use realism::{BaselineSim, PairedDifference, WosacSummary};

use std::collections::BTreeMap;
use std::path::Path;

use rayon::prelude::*;
use scbg_metrics::wosac::WosacConfig;
use scbg_scene::Scene;
use scbg_sim::SimConfig;
use scbg_synth::GroundTruth;
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
