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

use scbg_scene::Scene;
use scbg_sim::{PlanError, Planner, SimError};
use scbg_synth::GroundTruth;
use serde::Serialize;

use crate::artefact::LoadedScbg;
use crate::{Courtesy, InvalidRequest, ensure_request};

mod export;
mod run;

pub use export::{ExportFormat, scene_of_rollout, wosac_rollouts, write_scenarios, write_wosac};
pub use run::{SimOutput, SimRun, run_sim};

pub use scbg_sim::{
    AgentRolloutMetrics, AgentSnapshot, Contact, DEFAULT_LANE_KEEPING_M, DEFAULT_REPLAN_EVERY,
    EgoMode, HORIZON_STEPS, OthersMode, SimConfig, Simulation, VehicleLimits,
};

/// Keeps a plan in lane as the closed loop keeps a controlled agent's plans before following
/// them ([`scbg_sim::lanes`]): every point (world frame, metres) is pulled to within
/// `max_offset_m` of the nearest car-lane centre line of `scene`'s map that heads the plan's
/// way, and where the plan leaves every such lane (a roundabout's island, past an on-ramp's
/// end, off a highway's outer lane) the rest goes on along its lane's route at the plan's own
/// progress; returns how many points moved. A simulator that drives B from [`crate::Model::generate`]'s
/// futures should follow the kept plan (with [`DEFAULT_LANE_KEEPING_M`]): B then drives as in
/// scbg's own closed loop. `agent`, the track whose plan it is, starts the plan on the lane
/// under it heading its way at the current step (else on the lane the plan's own first move
/// heads along): a plan that turns where its lane goes straight on then keeps to its lane.
/// A negative or non-finite offset, or an agent the scene does not hold, is an
/// [`InvalidRequest`].
pub fn keep_in_lane(
    scene: &Scene,
    agent: Option<i64>,
    plan_world_m: &mut [[f64; 2]],
    max_offset_m: f64,
) -> anyhow::Result<usize> {
    ensure_request!(
        max_offset_m.is_finite() && max_offset_m >= 0.0,
        "max_offset_m {max_offset_m} is not a finite number ≥ 0"
    );
    ensure_request!(
        plan_world_m.iter().flatten().all(|v| v.is_finite()),
        "the plan has a non-finite coordinate"
    );
    if let Some(id) = agent {
        ensure_request!(
            scene.track_index(id).is_some(),
            "the scene has no track {id}"
        );
    }
    let heading = agent
        .and_then(|id| scene.current_state(id))
        .map(|s| f64::from(s.heading_rad));
    Ok(
        scbg_sim::lanes::LaneSegments::new(&scene.map).keep_near_from(
            plan_world_m,
            max_offset_m,
            heading,
        ),
    )
}

/// Steps between the generator's plans by default (2 s). The generator commits to one of B's
/// modes at each plan ([`scbg_generator::Generator::forward`]); re-deciding every
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

/// How a closed-loop simulation runs, as a front end asks for it: who drives the ego and the
/// others, and how often the controlled agents re-plan (by default the policy's own cadence,
/// [`default_replan_every`]); the controlled agents' safety guard, lane keeping and the world's
/// right of way are the simulator's defaults.
/// [`LoopOptions::config`] is the one place a front end's request becomes a [`SimConfig`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopOptions {
    /// How the ego moves.
    pub ego: EgoMode,
    /// How the other agents move.
    pub others: OthersMode,
    /// Steps between a controlled agent's plans (`None`: the policy's default).
    pub replan_every: Option<usize>,
}

impl Default for LoopOptions {
    fn default() -> Self {
        let config = SimConfig::default();
        Self {
            ego: config.ego,
            others: config.others,
            replan_every: None,
        }
    }
}

impl LoopOptions {
    /// The simulator's settings for these options under `policy`.
    pub fn config(&self, policy: scbg_generator::Policy) -> SimConfig {
        SimConfig {
            replan_every: self
                .replan_every
                .unwrap_or_else(|| default_replan_every(policy)),
            ego: self.ego,
            others: self.others,
            ..SimConfig::default()
        }
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

impl ControlledAgent {
    /// Agent `id` driven at `courtesy` toward the ego.
    pub fn new(id: i64, courtesy: Courtesy) -> Self {
        Self { id, courtesy }
    }
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
        std::collections::HashMap<(u64, i64, i64), std::rc::Rc<crate::generate::PlanBasis>>,
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

#[cfg(test)]
mod tests {
    use super::*;
    use scbg_generator::Policy;

    #[test]
    fn each_policy_replans_at_its_own_cadence_unless_told() {
        let cadence = |policy, replan_every| {
            LoopOptions {
                replan_every,
                ..LoopOptions::default()
            }
            .config(policy)
            .replan_every
        };
        assert_eq!(cadence(Policy::Generator, None), GENERATOR_REPLAN_EVERY);
        assert_eq!(cadence(Policy::Generator, None), 20);
        assert_eq!(cadence(Policy::Ranked, None), RANKED_REPLAN_EVERY);
        assert_eq!(cadence(Policy::Ranked, None), 20);
        assert_eq!(cadence(Policy::Ranked, Some(5)), 5);
        assert_eq!(cadence(Policy::Generator, Some(1)), 1);
        // The simulator's own default differs: the options always say which they mean.
        assert_ne!(SimConfig::default().replan_every, GENERATOR_REPLAN_EVERY);
    }

    #[test]
    fn a_plan_beside_the_lane_is_kept_in_it() {
        use scbg_scene::{Lane, LaneType, Map, MapPoint};
        let point = |x_m: f64| MapPoint {
            x_m,
            y_m: 0.0,
            z_m: 0.0,
        };
        let scene = Scene {
            map: Map {
                lanes: vec![Lane {
                    id: 1,
                    lane_type: LaneType::Freeway,
                    polyline: (0..=10).map(|k| point(10.0 * f64::from(k))).collect(),
                    ..Default::default()
                }],
                ..Default::default()
            },
            ..Default::default()
        };
        // Drifting 3 m off the lane (within reach): pulled to 0.25 m of it; the timing along
        // the lane is kept.
        let mut plan: Vec<[f64; 2]> = (0..5).map(|k| [10.0 * f64::from(k), 3.0]).collect();
        assert_eq!(
            keep_in_lane(&scene, None, &mut plan, DEFAULT_LANE_KEEPING_M).unwrap(),
            5
        );
        for (k, p) in plan.iter().enumerate() {
            assert!(
                (p[0] - 10.0 * k as f64).abs() < 1e-9 && (p[1] - 0.25).abs() < 1e-9,
                "{p:?}"
            );
        }
        let err = keep_in_lane(&scene, None, &mut plan, -1.0).unwrap_err();
        assert!(crate::is_invalid_request(&err) && err.to_string().contains("-1"));
        plan[2][0] = f64::NAN;
        assert!(crate::is_invalid_request(
            &keep_in_lane(&scene, None, &mut plan, 0.25).unwrap_err()
        ));
    }
}
