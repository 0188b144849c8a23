//! Closed-loop simulation with courtesy-controlled agents (the library behind `scbg sim`, the
//! server's sessions and the Python `Simulation`).
//!
//! A controlled agent is driven by the model's policy (the generator by default, or sample and
//! rank): every `replan_every` steps its future is planned from the *simulated* history (features rebuilt from the simulated states) at its
//! own quantile or ψ toward the ego, and followed through the kinematic bicycle of
//! [`scbg_sim::kinematics`]. See [`scbg_sim::rollout`] for the ego and the other agents.
//!
//! **Diversity of the 32 WOSAC rollouts.** The world is deterministic (the synthetic rule and
//! IDM have no noise of their own), so rollout `r` of 32 asks each controlled agent for the
//! quantile `q + spread · ((r + ½)/32 − ½)` (clamped to [0, 1]; spread 0.2 by default): the
//! rollouts spread evenly over a band around the requested quantile. An explicit ψ is used as
//! given in every rollout.

use std::path::Path;

use anyhow::Context;
use scbg_generator::Courtesy;
use scbg_metrics::wosac::{Rollouts, SimPose};
use scbg_scene::Scene;
use scbg_sim::{PlanError, Planner, SimError};
use scbg_synth::GroundTruth;
use serde::Serialize;

use crate::generator::LoadedScbg;
use crate::{InvalidRequest, ensure_request};

pub use scbg_sim::rollout::DEFAULT_LANE_KEEPING_M;
pub use scbg_sim::{
    AgentRolloutMetrics, AgentSnapshot, Contact, DEFAULT_REPLAN_EVERY, EgoMode, HORIZON_STEPS,
    OthersMode, SimConfig, Simulation, VehicleLimits,
};

/// Steps between the generator's plans by default (2 s). The generator commits to one of B's
/// modes at each plan ([`scbg_generator::GeneratorConfig::likeliest_mode`]); re-deciding every
/// second, a B near the middle of its range switches between yielding and going, where a
/// driver commits. Held-out synthetic scenes, three generator seeds (BENCHMARKS.md, "A
/// generator that knows which of B's modes helps A"): Spearman(quantile, realised courtesy)
/// +0.04 at 10 steps against +0.08 at 20, B's collisions at most 5.9 % against 2.0 %.
/// [`DEFAULT_REPLAN_EVERY`] (1 s, the simulator's own default) stays available through
/// `replan_every`.
pub const GENERATOR_REPLAN_EVERY: usize = 20;

/// Steps between the ranked policy's plans by default (2 s). Sample and rank re-chooses among
/// freshly sampled futures at every plan, and only the first `replan_every` steps of each
/// choice are driven: re-chosen every second, its intent is diluted (held-out synthetic scenes,
/// BENCHMARKS.md "Closed loop: how often sample and rank re-chooses": Spearman(quantile, realised courtesy) 0.08
/// at 10 steps, 0.20 at 20, 0.18 at 30, B's collisions 1.0 % → 0.3 %, WOSAC unchanged).
pub const RANKED_REPLAN_EVERY: usize = 20;

/// The default steps between a controlled agent's plans under `policy`:
/// [`GENERATOR_REPLAN_EVERY`] for the generator, [`RANKED_REPLAN_EVERY`] for sample and rank
/// (both 2 s).
pub fn default_replan_every(policy: scbg_generator::Policy) -> usize {
    match policy {
        scbg_generator::Policy::Generator => GENERATOR_REPLAN_EVERY,
        scbg_generator::Policy::Ranked => RANKED_REPLAN_EVERY,
    }
}

/// An agent the generator drives, and the courtesy asked of it toward the ego.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct ControlledAgent {
    /// Track id.
    pub id: i64,
    /// Its courtesy toward the ego: a quantile in [0, 1] or an explicit ψ.
    pub courtesy: Courtesy,
}

/// The courtesy-free part of the first plans ([`scbg_generator::PlanBasis`]) that rollouts of
/// one scene share: each rollout starts from the same logged history, whatever courtesy it
/// asks, so its first plan differs from the others' only in the choice. Keyed by the view
/// (a hash of its tracks' states up to its current step, its targets and the map's size) and
/// the pair: a rollout that starts elsewhere never shares. Later plans, from diverged
/// histories, are not kept. Use one per scene and model: the key does not hold the model, nor
/// the map's geometry. For one thread at a time (a [`RefCell`](std::cell::RefCell)); `scbg eval
/// sim` keeps two per scene (its curve's rollouts and its WOSAC rollouts), saving 15–19 % of its
/// time (BENCHMARKS.md *Shared first plans*).
#[derive(Debug, Default)]
pub struct FirstPlans {
    bases: std::cell::RefCell<
        std::collections::HashMap<(u64, i64, i64), std::rc::Rc<scbg_generator::PlanBasis>>,
    >,
}

impl FirstPlans {
    /// Bases kept (one per distinct first view and pair).
    pub fn len(&self) -> usize {
        self.bases.borrow().len()
    }

    /// Whether none is kept.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A hash of what a planner reads from `view`: the scenario, its current step, the SDC, every
/// track's id, type and states up to the current step, the signals, the objects of interest
/// and prediction targets, and the map's feature counts (not its geometry: within one
/// scenario the map is the log's).
fn view_key(view: &Scene) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    view.scenario_id.hash(&mut h);
    view.current_step.hash(&mut h);
    view.sdc_track_index.hash(&mut h);
    for tr in &view.tracks {
        tr.id.hash(&mut h);
        (tr.object_type as i64).hash(&mut h);
        for s in tr.states.iter().take(view.current_step + 1) {
            [s.x_m.to_bits(), s.y_m.to_bits(), s.z_m.to_bits()].hash(&mut h);
            [
                s.length_m,
                s.width_m,
                s.height_m,
                s.heading_rad,
                s.velocity_x_mps,
                s.velocity_y_mps,
            ]
            .map(f32::to_bits)
            .hash(&mut h);
            s.valid.hash(&mut h);
        }
    }
    for signals in view.signals_per_step.iter().take(view.current_step + 1) {
        format!("{signals:?}").hash(&mut h);
    }
    view.objects_of_interest.hash(&mut h);
    format!("{:?}", view.tracks_to_predict).hash(&mut h);
    let m = &view.map;
    [
        m.lanes.len(),
        m.road_lines.len(),
        m.road_edges.len(),
        m.stop_signs.len(),
        m.crosswalks.len(),
        m.speed_bumps.len(),
        m.driveways.len(),
    ]
    .hash(&mut h);
    h.finish()
}

/// The generator as the planner of the controlled agents.
#[derive(Debug)]
pub struct GeneratorPlanner<'m> {
    model: &'m LoadedScbg,
    ego: i64,
    controlled: Vec<ControlledAgent>,
    /// First plans shared with other rollouts of the scene, and the agents planned so far.
    first_plans: Option<(&'m FirstPlans, Vec<i64>)>,
}

impl<'m> GeneratorPlanner<'m> {
    /// Plans `controlled` toward `ego` with `model`.
    pub fn new(model: &'m LoadedScbg, ego: i64, controlled: Vec<ControlledAgent>) -> Self {
        Self {
            model,
            ego,
            controlled,
            first_plans: None,
        }
    }

    /// The same, sharing each agent's first plan with other rollouts of the scene through
    /// `first_plans`: the same futures, computed once.
    pub fn sharing_first_plans(mut self, first_plans: &'m FirstPlans) -> Self {
        self.first_plans = Some((first_plans, Vec::new()));
        self
    }
}

impl Planner for GeneratorPlanner<'_> {
    fn plan(&mut self, view: &Scene, agent_id: i64) -> Result<Vec<[f64; 2]>, PlanError> {
        let courtesy = self
            .controlled
            .iter()
            .find(|c| c.id == agent_id)
            .ok_or_else(|| PlanError(format!("agent {agent_id} is not controlled")))?
            .courtesy;
        let err = |e: anyhow::Error| PlanError(format!("{e:#}"));
        if let Some((shared, planned)) = &mut self.first_plans
            && !planned.contains(&agent_id)
        {
            planned.push(agent_id);
            let key = (view_key(view), self.ego, agent_id);
            let known = shared.bases.borrow().get(&key).cloned();
            let basis = match known {
                Some(b) => b,
                None => {
                    let b = std::rc::Rc::new(
                        crate::generate::plan_basis(self.model, view, self.ego, agent_id)
                            .map_err(err)?,
                    );
                    shared.bases.borrow_mut().insert(key, b.clone());
                    b
                }
            };
            return crate::generate::plan_from(self.model, &basis, courtesy).map_err(err);
        }
        crate::generate::plan(self.model, view, self.ego, agent_id, courtesy).map_err(err)
    }
}

/// Maps a simulation error to a request error when it is the caller's fault.
fn sim_error(err: SimError) -> anyhow::Error {
    match err {
        SimError::Plan { .. } => anyhow::Error::new(err),
        other => anyhow::Error::new(InvalidRequest(other.to_string())),
    }
}

/// Checks the controlled agents' courtesies (quantile in [0, 1], finite ψ).
fn check_courtesy(controlled: &[ControlledAgent]) -> anyhow::Result<()> {
    for c in controlled {
        match c.courtesy {
            Courtesy::Quantile(q) => ensure_request!(
                (0.0..=1.0).contains(&q),
                "agent {}: quantile {q} is outside [0, 1]",
                c.id
            ),
            Courtesy::Psi(p) => {
                ensure_request!(
                    p.is_finite(),
                    "agent {}: ψ {p} is not a finite number",
                    c.id
                )
            }
        }
    }
    Ok(())
}

/// Starts a closed-loop simulation of `scene`: `ego` (default: the SDC) and the controlled
/// agents with their courtesies; `truth` (a synthetic scene's ground truth) makes the
/// synthetic world's rule the reactive one.
pub fn start(
    scene: &Scene,
    ego: Option<i64>,
    controlled: &[ControlledAgent],
    config: SimConfig,
    truth: Option<&GroundTruth>,
) -> anyhow::Result<Simulation> {
    check_courtesy(controlled)?;
    let world = truth
        .map(|t| {
            scbg_synth::Scenario::of_truth(t)
                .map(scbg_synth::Scenario::closed_loop)
                .map_err(|e| anyhow::Error::new(InvalidRequest(e.to_string())))
        })
        .transpose()?;
    let ids: Vec<i64> = controlled.iter().map(|c| c.id).collect();
    Simulation::reset(scene, ego, &ids, config, world).map_err(sim_error)
}

/// One step of a started simulation with the generator planning its controlled agents;
/// `ego_state` when the ego is driven from outside. Errors that are the caller's fault (no
/// ego state, finished) are [`InvalidRequest`]s.
pub fn step(
    model: &LoadedScbg,
    sim: &mut Simulation,
    controlled: &[ControlledAgent],
    ego_state: Option<scbg_scene::AgentState>,
) -> anyhow::Result<Vec<AgentSnapshot>> {
    let mut planner = GeneratorPlanner::new(model, sim.ego_id(), controlled.to_vec());
    sim.step(&mut planner, ego_state).map_err(sim_error)
}

/// One whole rollout: the scene with the simulated future.
pub fn rollout(
    model: &LoadedScbg,
    scene: &Scene,
    ego: Option<i64>,
    controlled: &[ControlledAgent],
    config: SimConfig,
    truth: Option<&GroundTruth>,
) -> anyhow::Result<Scene> {
    run_rollout(model, scene, ego, controlled, config, truth, None)
}

/// [`rollout`], sharing the first plans with other rollouts of `scene` through `first_plans`
/// (the same simulated scene, faster when several rollouts share them; one [`FirstPlans`] per
/// scene and model).
pub fn rollout_sharing(
    model: &LoadedScbg,
    scene: &Scene,
    ego: Option<i64>,
    controlled: &[ControlledAgent],
    config: SimConfig,
    truth: Option<&GroundTruth>,
    first_plans: &FirstPlans,
) -> anyhow::Result<Scene> {
    run_rollout(
        model,
        scene,
        ego,
        controlled,
        config,
        truth,
        Some(first_plans),
    )
}

fn run_rollout(
    model: &LoadedScbg,
    scene: &Scene,
    ego: Option<i64>,
    controlled: &[ControlledAgent],
    config: SimConfig,
    truth: Option<&GroundTruth>,
    first_plans: Option<&FirstPlans>,
) -> anyhow::Result<Scene> {
    ensure_request!(
        config.ego != EgoMode::External,
        "a whole rollout cannot have an ego driven from outside (step the simulation instead)"
    );
    let mut sim = start(scene, ego, controlled, config, truth)?;
    let mut planner = GeneratorPlanner::new(model, sim.ego_id(), controlled.to_vec());
    if let Some(first_plans) = first_plans {
        planner = planner.sharing_first_plans(first_plans);
    }
    sim.run(&mut planner).map_err(sim_error)?;
    Ok(sim.to_scene())
}

/// The metrics of a rollout: the ego first, then each controlled agent.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RolloutReport {
    /// The scenario.
    pub scenario_id: String,
    /// The ego's metrics (its `avg_speed_mps` is A's realised reward).
    pub ego: AgentRolloutMetrics,
    /// Each controlled agent's metrics, in the order asked.
    pub controlled: Vec<AgentRolloutMetrics>,
}

/// Metrics of a simulated scene for the ego and the controlled agents.
pub fn report(simulated: &Scene, ego: i64, controlled: &[i64]) -> anyhow::Result<RolloutReport> {
    let edges = scbg_metrics::wosac::RoadEdges::new(&simulated.map);
    let metrics = |id: i64| {
        simulated
            .track_index(id)
            .map(|i| scbg_sim::agent_metrics(simulated, i, edges.as_ref()))
            .ok_or_else(|| anyhow::Error::new(InvalidRequest(format!("no agent with id {id}"))))
    };
    Ok(RolloutReport {
        scenario_id: simulated.scenario_id.clone(),
        ego: metrics(ego)?,
        controlled: controlled
            .iter()
            .map(|&c| metrics(c))
            .collect::<anyhow::Result<_>>()?,
    })
}

/// The quantiles of the `n` rollouts around `q` (see the module docs).
pub fn rollout_quantiles(q: f32, n: usize, spread: f32) -> Vec<f32> {
    (0..n)
        .map(|r| (q + spread * ((r as f32 + 0.5) / n as f32 - 0.5)).clamp(0.0, 1.0))
        .collect()
}

/// The WOSAC form of simulated scenes of one scenario: every sim agent of `log` (valid at the
/// current step), 80 poses per rollout; a pose the simulation left invalid (an agent replayed
/// past the end of its log) repeats the last valid one.
pub fn wosac_rollouts(log: &Scene, simulated: &[Scene]) -> Rollouts {
    let object_ids = scbg_metrics::wosac::sim_agent_ids(log);
    let start = log.current_step;
    let trajectories = simulated
        .iter()
        .map(|scene| {
            object_ids
                .iter()
                .map(|&id| {
                    let states = scene
                        .track_index(id)
                        .map(|i| &scene.tracks[i].states[..])
                        .unwrap_or_default();
                    let mut last = states.get(start).copied().unwrap_or_default();
                    (start + 1..=start + HORIZON_STEPS)
                        .map(|t| {
                            if let Some(s) = states.get(t).filter(|s| s.valid) {
                                last = *s;
                            }
                            SimPose {
                                x_m: last.x_m as f32,
                                y_m: last.y_m as f32,
                                z_m: last.z_m as f32,
                                heading_rad: last.heading_rad,
                            }
                        })
                        .collect()
                })
                .collect()
        })
        .collect();
    Rollouts {
        object_ids,
        trajectories,
    }
}

/// `log` with one rollout's poses as its future (velocities by finite differences), for the
/// rollout metrics of a baseline given as WOSAC rollouts.
pub fn scene_of_rollout(log: &Scene, rollouts: &Rollouts, r: usize) -> Scene {
    let start = log.current_step;
    let mut scene = log.clone();
    let len = start + 1 + HORIZON_STEPS;
    for tr in &mut scene.tracks {
        tr.states.truncate(start + 1);
        tr.states.resize(len, scbg_scene::AgentState::default());
    }
    scene.timestamps_secs = (0..len)
        .map(|k| log.timestamps_secs.first().copied().unwrap_or(0.0) + k as f64 * 0.1)
        .collect();
    if !scene.signals_per_step.is_empty() {
        scene.signals_per_step.resize(len, Vec::new());
    }
    for (o, &id) in rollouts.object_ids.iter().enumerate() {
        let Some(i) = scene.track_index(id) else {
            continue;
        };
        let tr = &mut scene.tracks[i];
        for (k, p) in rollouts.trajectories[r][o].iter().enumerate() {
            let prev = tr.states[start + k];
            let (x, y) = (f64::from(p.x_m), f64::from(p.y_m));
            tr.states[start + k + 1] = scbg_scene::AgentState {
                x_m: x,
                y_m: y,
                z_m: f64::from(p.z_m),
                heading_rad: p.heading_rad,
                velocity_x_mps: ((x - prev.x_m) / 0.1) as f32,
                velocity_y_mps: ((y - prev.y_m) / 0.1) as f32,
                valid: true,
                ..prev
            };
        }
    }
    scene
}

/// Writes simulated scenes as WOMD Scenario TFRecords (the simulated future in place of the
/// logged one), atomically.
pub fn write_scenarios(path: &Path, scenes: &[Scene]) -> anyhow::Result<usize> {
    scbg_womd::write_scenes(path, scenes).with_context(|| format!("writing {}", path.display()))
}

/// Writes WOSAC submission shards (`name.binproto-0000i-of-0000N` in `dir`) for scenarios with
/// 32 rollouts each, after checking each against the challenge's rules.
pub fn write_wosac(
    dir: &Path,
    name: &str,
    header: &scbg_womd::wosac::SubmissionHeader,
    scenarios: &[(Scene, Rollouts)],
    shards: usize,
) -> anyhow::Result<Vec<std::path::PathBuf>> {
    let inputs = scenarios
        .iter()
        .map(|(log, r)| {
            let input = scbg_womd::wosac::ScenarioRolloutsInput {
                scenario_id: log.scenario_id.clone(),
                joint_scenes: r
                    .trajectories
                    .iter()
                    .map(|joint| {
                        r.object_ids
                            .iter()
                            .zip(joint)
                            .map(|(&id, poses)| scbg_womd::wosac::ObjectTrajectory {
                                object_id: id,
                                x_m: poses.iter().map(|p| p.x_m).collect(),
                                y_m: poses.iter().map(|p| p.y_m).collect(),
                                z_m: poses.iter().map(|p| p.z_m).collect(),
                                heading_rad: poses.iter().map(|p| p.heading_rad).collect(),
                            })
                            .collect()
                    })
                    .collect(),
            };
            scbg_womd::wosac::validate_rollouts(log, &input)
                .with_context(|| format!("rollouts of {}", log.scenario_id))?;
            Ok(input)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    scbg_womd::wosac::write_submission_shards(dir, name, header, &inputs, shards)
        .with_context(|| format!("writing WOSAC shards into {}", dir.display()))
}

/// What `scbg sim` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum ExportFormat {
    /// WOMD Scenario TFRecord (`rollouts.tfrecord`, one scenario per rollout).
    #[default]
    Scenario,
    /// WOSAC submission shard (`NAME.binproto-00000-of-00001`, 32 rollouts).
    Wosac,
}

/// One `scbg sim` run.
#[derive(Debug, Clone)]
pub struct SimRun {
    /// Generator folder.
    pub model: std::path::PathBuf,
    /// Predictor folder overriding generator.json's.
    pub predictor: Option<std::path::PathBuf>,
    /// How the controlled agents' courtesy becomes their plans.
    pub policy: scbg_generator::Policy,
    /// WOMD file holding the scenario.
    pub scenario: std::path::PathBuf,
    /// Which scenario (default: the first with A and the first controlled agent).
    pub scenario_id: Option<String>,
    /// A, the ego (whose reward courtesy is about).
    pub ego: i64,
    /// The controlled agents (at least one).
    pub controlled: Vec<ControlledAgent>,
    /// Closed-loop settings.
    pub config: SimConfig,
    /// Synthetic ground truth: the synthetic world's rule drives the reactive agents. Default:
    /// `ground_truth.jsonl` beside the scenario file, when it describes the scenario.
    pub ground_truth: Option<std::path::PathBuf>,
    /// Do not look for a ground truth beside the file (IDM everywhere).
    pub no_synthetic_world: bool,
    /// Rollouts (32 for WOSAC).
    pub rollouts: usize,
    /// Band of quantiles the rollouts spread over.
    pub spread: f32,
    /// Output folder.
    pub out: std::path::PathBuf,
    /// Export format.
    pub format: ExportFormat,
    /// Method name of a WOSAC submission.
    pub name: String,
}

/// What `scbg sim` did (also `sim.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimOutput {
    /// The scenario.
    pub scenario_id: String,
    /// Whether the synthetic world's rule drove the reactive agents.
    pub synthetic_world: bool,
    /// Quantile each rollout asked of each controlled agent (`[rollout][agent]`; ψ requests
    /// are `null`).
    pub quantiles: Vec<Vec<Option<f32>>>,
    /// Metrics per rollout.
    pub reports: Vec<RolloutReport>,
    /// Files written.
    pub files: Vec<std::path::PathBuf>,
}

/// The ground truth of `scenario_id` from `path`, or from `ground_truth.jsonl` beside `file`.
fn truth_for(
    file: &Path,
    explicit: Option<&Path>,
    scenario_id: &str,
) -> anyhow::Result<Option<GroundTruth>> {
    let path = match explicit {
        Some(p) => p.to_path_buf(),
        None => match file
            .parent()
            .map(|d| d.join(crate::synth::GROUND_TRUTH_FILE))
        {
            Some(p) if p.is_file() => p,
            _ => return Ok(None),
        },
    };
    let truth = crate::synth::read_ground_truth(&path)?;
    let found = truth.into_iter().find(|t| t.scenario_id == scenario_id);
    ensure_request!(
        found.is_some() || explicit.is_none(),
        "{}: no ground truth for scenario {scenario_id}",
        path.display()
    );
    Ok(found)
}

/// Runs `scbg sim`: `rollouts` closed-loop rollouts of one scenario, exported as Scenario
/// TFRecords or a WOSAC shard, with `sim.json` (metrics per rollout) beside them.
pub fn run_sim(run: &SimRun, progress: &dyn crate::Progress) -> anyhow::Result<SimOutput> {
    ensure_request!(
        !run.controlled.is_empty(),
        "at least one controlled agent (--b)"
    );
    ensure_request!(run.rollouts >= 1, "at least one rollout");
    ensure_request!(
        run.format != ExportFormat::Wosac
            || run.rollouts == scbg_metrics::wosac::ROLLOUTS_PER_SCENARIO,
        "a WOSAC submission needs {} rollouts per scenario (got {})",
        scbg_metrics::wosac::ROLLOUTS_PER_SCENARIO,
        run.rollouts
    );
    check_courtesy(&run.controlled)?;
    let mut model = crate::generator::load_scbg(&run.model, run.predictor.as_deref())?;
    model.scbg.policy = run.policy;
    let (_, scene) = crate::generate::find_scene(
        &run.scenario,
        run.scenario_id.as_deref(),
        run.ego,
        run.controlled[0].id,
    )?;
    let truth = if run.no_synthetic_world {
        None
    } else {
        truth_for(
            &run.scenario,
            run.ground_truth.as_deref(),
            &scene.scenario_id,
        )?
    };
    let bar = progress.bar("closed-loop rollouts", run.rollouts as u64);
    let mut scenes = Vec::with_capacity(run.rollouts);
    let mut quantiles = Vec::with_capacity(run.rollouts);
    for r in 0..run.rollouts {
        let controlled: Vec<ControlledAgent> = run
            .controlled
            .iter()
            .map(|c| ControlledAgent {
                courtesy: match c.courtesy {
                    Courtesy::Quantile(q) if run.rollouts > 1 => {
                        Courtesy::Quantile(rollout_quantiles(q, run.rollouts, run.spread)[r])
                    }
                    other => other,
                },
                ..*c
            })
            .collect();
        quantiles.push(
            controlled
                .iter()
                .map(|c| match c.courtesy {
                    Courtesy::Quantile(q) => Some(q),
                    Courtesy::Psi(_) => None,
                })
                .collect(),
        );
        scenes.push(rollout(
            &model,
            &scene,
            Some(run.ego),
            &controlled,
            run.config,
            truth.as_ref(),
        )?);
        bar.inc(1);
    }
    drop(bar);
    let ids: Vec<i64> = run.controlled.iter().map(|c| c.id).collect();
    let reports = scenes
        .iter()
        .map(|s| report(s, run.ego, &ids))
        .collect::<anyhow::Result<Vec<_>>>()?;
    std::fs::create_dir_all(&run.out).with_context(|| format!("creating {}", run.out.display()))?;
    let files = match run.format {
        ExportFormat::Scenario => {
            let path = run.out.join("rollouts.tfrecord");
            write_scenarios(&path, &scenes)?;
            vec![path]
        }
        ExportFormat::Wosac => {
            let header = scbg_womd::wosac::SubmissionHeader {
                account_name: String::new(),
                unique_method_name: run.name.clone(),
                authors: vec!["scbg".into()],
                affiliation: String::new(),
                description: format!(
                    "scbg: courtesy-controlled agents (generator re-planning every {} steps, kinematic bicycle), reactive others",
                    run.config.replan_every
                ),
                method_link: String::new(),
                uses_lidar_data: false,
                uses_camera_data: false,
                uses_public_model_pretraining: false,
                num_model_parameters: String::new(),
                public_model_names: Vec::new(),
                // The challenge asks for a policy that acts on the simulated state every step.
                acknowledge_closed_loop: run.config.replan_every == 1,
            };
            let rollouts = wosac_rollouts(&scene, &scenes);
            write_wosac(
                &run.out,
                &run.name,
                &header,
                &[(scene.clone(), rollouts)],
                1,
            )?
        }
    };
    let output = SimOutput {
        scenario_id: scene.scenario_id.clone(),
        synthetic_world: truth.is_some(),
        quantiles,
        reports,
        files,
    };
    crate::write_json(run.out.join("sim.json"), &output)?;
    Ok(output)
}
