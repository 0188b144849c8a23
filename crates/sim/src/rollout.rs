//! The step-wise closed-loop simulation: `reset(scene, …) → Simulation`, `step(ego) → state`.
//!
//! From the scene's current step, [`HORIZON_STEPS`] steps at 10 Hz. Controlled agents follow
//! plans from a [`Planner`] (in the product: the courtesy generator), re-planned every
//! `replan_every` steps from the *simulated* history, through the kinematic bicycle
//! ([`crate::kinematics`]). The ego (A) is reactive, replayed from the log, or driven from
//! outside; the other agents are replayed from the log or reactive. "Reactive" is the
//! synthetic world's own rule ([`scbg_synth::ClosedLoop`], the rule of the counterfactual
//! courtesy oracle) for a synthetic scene whose world is given, and IDM along the agent's
//! logged path ([`crate::idm`]) otherwise. Agents not valid at the current step are always
//! replayed from the log.

use scbg_scene::{AgentState, Scene};
use scbg_synth::ClosedLoop;
use serde::{Deserialize, Serialize};

use crate::guard::{crossing_conflict, planned_gap_speed_mps, side_steer_bounds};
use crate::idm::{IdmAgent, leader_on_path, polyline_path};

/// The safety guard's IDM (a free road never limits: the desired speed is out of reach).
const GUARD: scbg_synth::Idm = scbg_synth::Idm {
    desired_speed_mps: 1e3,
    max_accel_mps2: 3.0,
    comfort_brake_mps2: 3.0,
    time_headway_s: 1.0,
    min_gap_m: 2.0,
};
use crate::kinematics::{Bicycle, STEP_SECS, VehicleLimits};

/// Steps simulated after the current one (8 s at 10 Hz).
pub const HORIZON_STEPS: usize = 80;
/// History steps a plan is made from, the current one included.
pub const HISTORY_STEPS: usize = 11;

/// How the ego (A) moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum EgoMode {
    /// Reacts to the others (the synthetic rule, or IDM along its logged path).
    #[default]
    Reactive,
    /// Replays its logged future.
    Log,
    /// Its next state is given with every step (a simulator drives it).
    External,
}

/// How the agents that are neither controlled nor the ego move.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum OthersMode {
    /// Replay their logged futures.
    #[default]
    Log,
    /// React (the synthetic rule, or IDM along their logged paths).
    Reactive,
}

impl std::str::FromStr for EgoMode {
    type Err = String;

    /// `reactive`, `log` or `external`.
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "reactive" => Ok(Self::Reactive),
            "log" => Ok(Self::Log),
            "external" => Ok(Self::External),
            other => Err(format!(
                "ego_mode {other:?}: expected external, reactive or log"
            )),
        }
    }
}

impl std::str::FromStr for OthersMode {
    type Err = String;

    /// `log` or `reactive`.
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "log" => Ok(Self::Log),
            "reactive" => Ok(Self::Reactive),
            other => Err(format!("others {other:?}: expected log or reactive")),
        }
    }
}

/// Settings of one closed-loop simulation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SimConfig {
    /// Steps between plans of a controlled agent (1 ..= 80; default [`DEFAULT_REPLAN_EVERY`]).
    pub replan_every: usize,
    /// How the ego moves.
    pub ego: EgoMode,
    /// How the other agents move.
    pub others: OthersMode,
    /// Limits of the controlled agents' bicycle.
    pub limits: VehicleLimits,
    /// The safety guard of the controlled agents: the tracker's acceleration is capped by
    /// IDM's (headway 1 s, standstill gap 2 m, comfortable braking 3 m/s²) toward the nearest
    /// agent ahead along the current plan (the leader rule of [`crate::idm`]) and toward the
    /// nearest crossing conflict (another agent that, at constant velocity, will be in the
    /// plan's corridor, up to 5 s ahead, within 2 s of when the agent's box is there (with 2 m
    /// to spare at either end) — for good when the plan stops there — taken as a standing
    /// obstacle at that point, or before
    /// the way of another crossing agent in between; a follower behind counts only while it is
    /// faster and in the next lane; [`crate::guard`]),
    /// and the steering is bounded so as not to turn toward an agent alongside, or one coming
    /// up from behind in the next lane, or into the lane of a follower there that could not
    /// stay behind it braking at 7 m/s² (gap acceptance; [`crate::guard`]'s
    /// `side_steer_bounds`), so a plan that runs into another agent is followed at a safe
    /// distance instead. On by default.
    pub safety_guard: bool,
    /// Lane keeping of the controlled agents' plans ([`crate::lanes`]): every plan point is
    /// pulled to within this many metres of the nearest car-lane centre line before it is
    /// followed; `None` follows the plans as generated. Default 0.25 m.
    #[serde(default = "default_lane_keeping_m")]
    pub lane_keeping_m: Option<f64>,
    /// The guard lets the synthetic world's B take the right of way at a crossing from a
    /// reacting A (the world's rule, which yields to a B committed to cross, as the
    /// counterfactual oracle's A does): A is no crossing conflict while its front can still
    /// stop before B's corridor braking at most 7 m/s² (what the world's least courteous B
    /// asks of it) after 0.7 s, with 2 m to spare (`guard::yields_in_time`). B's plan then
    /// decides who goes first, so its courtesy shows in the loop; without it the guard made
    /// every B yield like a courteous one. Only for the world's B, with A reacting by the
    /// world's rule (not controlled; the ego or another agent in reactive mode): nobody else
    /// is known to yield. Default true (also for a serialised config without the field).
    #[serde(default = "yes")]
    pub take_right_of_way: bool,
}

fn yes() -> bool {
    true
}

impl SimConfig {
    /// Whether track `i` reacts (the ego's mode for the ego, the others' for the rest); a
    /// controlled agent is driven whatever this says.
    fn reacts(&self, i: usize, ego: usize) -> bool {
        if i == ego {
            self.ego == EgoMode::Reactive
        } else {
            self.others == OthersMode::Reactive
        }
    }
}

/// The default lane keeping (0.25 m; what a serialised config without the field gets).
pub const DEFAULT_LANE_KEEPING_M: f64 = 0.25;

fn default_lane_keeping_m() -> Option<f64> {
    Some(DEFAULT_LANE_KEEPING_M)
}

/// The default number of steps between a controlled agent's plans (1 s at 10 Hz).
pub const DEFAULT_REPLAN_EVERY: usize = 10;

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            replan_every: DEFAULT_REPLAN_EVERY,
            ego: EgoMode::Reactive,
            others: OthersMode::Log,
            limits: VehicleLimits::default(),
            safety_guard: true,
            lane_keeping_m: default_lane_keeping_m(),
            take_right_of_way: true,
        }
    }
}

/// A plan that could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct PlanError(pub String);

/// Plans the controlled agents' futures.
pub trait Planner {
    /// The future of controlled agent `agent_id`: [`HORIZON_STEPS`] world-frame points at
    /// 10 Hz, the first 0.1 s after the current step of `view` — a scene of
    /// [`HISTORY_STEPS`] simulated history steps and [`HORIZON_STEPS`] invalid future steps
    /// (current step 10), on the scenario's map, with the ego as its SDC.
    fn plan(&mut self, view: &Scene, agent_id: i64) -> Result<Vec<[f64; 2]>, PlanError>;
}

/// What stops a simulation from starting or stepping; every variant names what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// The scene has fewer than 11 steps up to its current one.
    #[error(
        "scenario {scenario_id}: current step {current_step} leaves fewer than 11 history steps (needs a scenario of at least 11 steps, current step ≥ 10)"
    )]
    TooShort {
        /// The scenario.
        scenario_id: String,
        /// Its current step.
        current_step: usize,
    },
    /// No track with this id.
    #[error("scenario {scenario_id}: no agent with id {id}")]
    UnknownAgent {
        /// The scenario.
        scenario_id: String,
        /// The id asked for.
        id: i64,
    },
    /// The agent has no valid state at the current step.
    #[error("scenario {scenario_id}: agent {id} is not valid at the current step {step}")]
    NotValid {
        /// The scenario.
        scenario_id: String,
        /// The agent.
        id: i64,
        /// The current step.
        step: usize,
    },
    /// No ego was named and the scene has no SDC.
    #[error("scenario {0}: no ego given and the scenario has no SDC")]
    NoEgo(String),
    /// The ego is also a controlled agent.
    #[error("agent {0} is the ego and cannot also be controlled")]
    EgoControlled(i64),
    /// An agent is controlled twice.
    #[error("agent {0} is controlled twice")]
    Duplicate(i64),
    /// `replan_every` outside 1 ..= 80.
    #[error("replan_every {0} is outside 1..=80")]
    ReplanEvery(usize),
    /// A lane-keeping offset that is negative or not finite.
    #[error("lane_keeping_m {0} is not a finite number ≥ 0")]
    LaneKeeping(f64),
    /// The synthetic world does not belong to this scene.
    #[error("scenario {0}: the synthetic world given is not this scenario's")]
    WorldMismatch(String),
    /// All [`HORIZON_STEPS`] steps are done.
    #[error("the simulation has finished its {HORIZON_STEPS} steps")]
    Finished,
    /// The ego is driven from outside and no state (or an invalid one) was given.
    #[error("the ego is driven from outside: {0}")]
    EgoState(String),
    /// A controlled agent's plan failed or is malformed.
    #[error("agent {id} at step {step}: plan failed: {message}")]
    Plan {
        /// The agent.
        id: i64,
        /// The step it planned at.
        step: usize,
        /// What went wrong.
        message: String,
    },
}

#[derive(Debug, Clone)]
struct Controlled {
    track: usize,
    bicycle: Bicycle,
    plan: Vec<[f64; 2]>,
    /// The plan as a path (from where it started), for the safety guard.
    path: Option<scbg_synth::RefPath>,
    /// Arclength of each plan point along `path`.
    plan_s: Vec<f64>,
    plan_start_xy: [f64; 2],
    plan_step: usize,
}

/// The synthetic world and the track it follows as B.
#[derive(Debug)]
struct Synthetic {
    world: ClosedLoop,
    b_track: usize,
    /// The world's A, when it reacts by the world's rule (not controlled, and the ego or an
    /// other agent in reactive mode): it yields to B ([`SimConfig::take_right_of_way`]).
    a_yields: Option<usize>,
    /// B's simulated states so far, projected on its path once each.
    b_prefix: scbg_synth::BPrefix,
}

/// One agent's state at the simulation's current step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AgentSnapshot {
    /// Track id.
    pub id: i64,
    /// Its state (invalid when the log has none and it is replayed).
    pub state: AgentState,
}

/// A closed-loop simulation in progress.
#[derive(Debug)]
pub struct Simulation {
    log: Scene,
    /// `[tracks][start + 81]`: the log up to the current step, then the simulated states.
    states: Vec<Vec<AgentState>>,
    start: usize,
    t: usize,
    ego: usize,
    config: SimConfig,
    controlled: Vec<Controlled>,
    idm: Vec<Option<IdmAgent>>,
    synthetic: Option<Synthetic>,
    /// The map's car-lane segments, when plans are lane-kept.
    lanes: Option<crate::lanes::LaneSegments>,
}

fn finite(s: &AgentState) -> bool {
    [s.x_m, s.y_m, s.z_m].iter().all(|v| v.is_finite())
        && [
            s.heading_rad,
            s.velocity_x_mps,
            s.velocity_y_mps,
            s.length_m,
            s.width_m,
        ]
        .iter()
        .all(|v| v.is_finite())
}

impl Simulation {
    /// Starts a simulation at the scene's current step. `ego`: A's track id (default: the SDC);
    /// `controlled`: the agents a [`Planner`] drives; `synthetic`: the synthetic world of this
    /// scene, when it is one (then "reactive" means the synthetic rule for A and the others,
    /// driven by the states of the scene's B).
    pub fn reset(
        scene: &Scene,
        ego: Option<i64>,
        controlled: &[i64],
        config: SimConfig,
        synthetic: Option<ClosedLoop>,
    ) -> Result<Self, SimError> {
        let id = scene.scenario_id.clone();
        let start = scene.current_step;
        if start + 1 < HISTORY_STEPS || scene.num_steps() <= start {
            return Err(SimError::TooShort {
                scenario_id: id,
                current_step: start,
            });
        }
        if !(1..=HORIZON_STEPS).contains(&config.replan_every) {
            return Err(SimError::ReplanEvery(config.replan_every));
        }
        if let Some(m) = config
            .lane_keeping_m
            .filter(|m| !(m.is_finite() && *m >= 0.0))
        {
            return Err(SimError::LaneKeeping(m));
        }
        let index = |agent: i64| {
            let i = scene.track_index(agent).ok_or(SimError::UnknownAgent {
                scenario_id: id.clone(),
                id: agent,
            })?;
            if !scene.tracks[i].states[start].valid {
                return Err(SimError::NotValid {
                    scenario_id: id.clone(),
                    id: agent,
                    step: start,
                });
            }
            Ok(i)
        };
        let ego = match ego {
            Some(e) => index(e)?,
            None => {
                let i = scene.sdc_track_index.ok_or(SimError::NoEgo(id.clone()))?;
                index(scene.tracks[i].id)?
            }
        };
        let mut taken = vec![false; scene.tracks.len()];
        let mut ctl = Vec::with_capacity(controlled.len());
        for &c in controlled {
            let i = index(c)?;
            if i == ego {
                return Err(SimError::EgoControlled(c));
            }
            if std::mem::replace(&mut taken[i], true) {
                return Err(SimError::Duplicate(c));
            }
            let states = &scene.tracks[i].states;
            let bicycle = Bicycle::from_state(&states[start], Some(&states[start - 1]));
            ctl.push(Controlled {
                track: i,
                bicycle,
                plan: Vec::new(),
                path: None,
                plan_s: Vec::new(),
                plan_start_xy: [states[start].x_m, states[start].y_m],
                plan_step: start,
            });
        }
        let synthetic = match synthetic {
            None => None,
            Some(world) => {
                let b = scene.track_index(scbg_synth::B_ID);
                let matches = world.scenario().scenario_id() == scene.scenario_id
                    && start == scbg_synth::CURRENT_STEP
                    && scene.tracks.len() == world.next_states(&Default::default()).len();
                let a_yields = scene
                    .track_index(scbg_synth::A_ID)
                    .filter(|&a| config.reacts(a, ego) && !taken[a]);
                match b {
                    Some(b_track) if matches => Some(Synthetic {
                        world,
                        b_track,
                        a_yields,
                        b_prefix: Default::default(),
                    }),
                    _ => return Err(SimError::WorldMismatch(id)),
                }
            }
        };
        let reactive_idm = |i: usize| config.reacts(i, ego) && !taken[i] && synthetic.is_none();
        let idm = scene
            .tracks
            .iter()
            .enumerate()
            .map(|(i, tr)| {
                if reactive_idm(i) {
                    IdmAgent::new(tr, start)
                } else {
                    None
                }
            })
            .collect();
        let len = start + 1 + HORIZON_STEPS;
        let states = scene
            .tracks
            .iter()
            .map(|tr| {
                let mut s = tr.states[..=start].to_vec();
                s.resize(len, AgentState::default());
                s
            })
            .collect();
        Ok(Self {
            log: scene.clone(),
            states,
            start,
            t: start,
            ego,
            config,
            controlled: ctl,
            idm,
            synthetic,
            lanes: config
                .lane_keeping_m
                .map(|_| crate::lanes::LaneSegments::new(&scene.map)),
        })
    }

    /// The step the simulation is at (the scene's current step after `reset`).
    pub fn step_index(&self) -> usize {
        self.t
    }

    /// Whether all [`HORIZON_STEPS`] steps are done.
    pub fn finished(&self) -> bool {
        self.t == self.start + HORIZON_STEPS
    }

    /// The ego's track id.
    pub fn ego_id(&self) -> i64 {
        self.log.tracks[self.ego].id
    }

    /// The ego's state for [`Self::step`] when it is driven from outside: this pose and
    /// velocity (world frame), valid, with everything else (box, z) kept from the ego's
    /// current state.
    pub fn external_ego_state(
        &self,
        x_m: f64,
        y_m: f64,
        heading_rad: f32,
        velocity_mps: [f32; 2],
    ) -> AgentState {
        AgentState {
            x_m,
            y_m,
            heading_rad,
            velocity_x_mps: velocity_mps[0],
            velocity_y_mps: velocity_mps[1],
            valid: true,
            ..self.states[self.ego][self.t]
        }
    }

    /// Every agent's state at the current step.
    pub fn snapshot(&self) -> Vec<AgentSnapshot> {
        self.log
            .tracks
            .iter()
            .zip(&self.states)
            .map(|(tr, s)| AgentSnapshot {
                id: tr.id,
                state: s[self.t],
            })
            .collect()
    }

    /// The scene a planner sees at step `t`: the last [`HISTORY_STEPS`] simulated steps, then
    /// [`HORIZON_STEPS`] invalid ones; current step 10; the ego as SDC.
    pub fn view(&self) -> Scene {
        let t = self.t;
        let from = t + 1 - HISTORY_STEPS;
        let n = HISTORY_STEPS + HORIZON_STEPS;
        let tracks = self
            .log
            .tracks
            .iter()
            .zip(&self.states)
            .map(|(tr, s)| {
                let mut states = s[from..=t].to_vec();
                states.resize(n, AgentState::default());
                scbg_scene::Track {
                    id: tr.id,
                    object_type: tr.object_type,
                    states,
                }
            })
            .collect();
        let signals_per_step = if self.log.signals_per_step.is_empty() {
            Vec::new()
        } else {
            (from..from + n)
                .map(|k| {
                    self.log
                        .signals_per_step
                        .get(k.min(t))
                        .cloned()
                        .unwrap_or_default()
                })
                .collect()
        };
        Scene {
            scenario_id: self.log.scenario_id.clone(),
            timestamps_secs: (0..n).map(|k| k as f64 * STEP_SECS).collect(),
            current_step: HISTORY_STEPS - 1,
            sdc_track_index: Some(self.ego),
            tracks,
            objects_of_interest: self.log.objects_of_interest.clone(),
            tracks_to_predict: self.log.tracks_to_predict.clone(),
            map: self.log.map.clone(),
            signals_per_step,
        }
    }

    /// One step. `ego_state`: the ego's next state when it is driven from outside (ignored
    /// otherwise). On an error nothing has changed.
    pub fn step(
        &mut self,
        planner: &mut dyn Planner,
        ego_state: Option<AgentState>,
    ) -> Result<Vec<AgentSnapshot>, SimError> {
        if self.finished() {
            return Err(SimError::Finished);
        }
        let t = self.t;
        let ego_next = match self.config.ego {
            EgoMode::External => {
                let s = ego_state
                    .ok_or_else(|| SimError::EgoState("no state given for this step".into()))?;
                if !finite(&s) {
                    return Err(SimError::EgoState("a field is not finite".into()));
                }
                Some(AgentState { valid: true, ..s })
            }
            _ => None,
        };
        // Plans first, so that a failed plan leaves the simulation as it was.
        let mut plans: Vec<Option<Vec<[f64; 2]>>> = vec![None; self.controlled.len()];
        let mut view: Option<Scene> = None;
        for (k, c) in self.controlled.iter().enumerate() {
            if c.plan.is_empty() || t - c.plan_step >= self.config.replan_every {
                let view = view.get_or_insert_with(|| self.view());
                let id = self.log.tracks[c.track].id;
                let fail = |message: String| SimError::Plan {
                    id,
                    step: t,
                    message,
                };
                let plan = self
                    .plan_checked(planner, view, id)
                    .map_err(|e| fail(e.0))?;
                plans[k] = Some(plan);
            }
        }
        let log_state = |i: usize| {
            self.log.tracks[i]
                .states
                .get(t + 1)
                .copied()
                .unwrap_or_default()
        };
        let mut next: Vec<AgentState> = (0..self.states.len()).map(log_state).collect();
        let current: Vec<&AgentState> = self.states.iter().map(|s| &s[t]).collect();
        let others_of = |i: usize| -> Vec<&AgentState> {
            current
                .iter()
                .enumerate()
                .filter(|&(j, s)| j != i && s.valid)
                .map(|(_, s)| *s)
                .collect()
        };
        for (c, plan) in self.controlled.iter_mut().zip(plans) {
            if let Some(plan) = plan {
                c.plan_start_xy = [c.bicycle.x_m, c.bicycle.y_m];
                if self.config.safety_guard {
                    let mut points = vec![c.plan_start_xy];
                    points.extend_from_slice(&plan);
                    let path = polyline_path(&points, c.bicycle.heading_rad);
                    let mut hint = 0.0;
                    c.plan_s = plan
                        .iter()
                        .map(|p| {
                            hint = path.project(p[0], p[1], Some(hint)).0;
                            hint
                        })
                        .collect();
                    c.path = Some(path);
                }
                c.plan = plan;
                c.plan_step = t;
            }
            let (mut a, mut d) = c.bicycle.track(c.plan_start_xy, &c.plan, t - c.plan_step);
            if let Some(path) = c.path.as_ref().filter(|_| self.config.safety_guard) {
                let (s, _) = path.project(c.bicycle.x_m, c.bicycle.y_m, None);
                let me = current[c.track];
                let others = others_of(c.track);
                // When the plan reaches each arclength of its path, seconds from now.
                let k_now = t - c.plan_step;
                let arrival = |s_at: f64| {
                    c.plan_s
                        .iter()
                        .position(|&ps| ps >= s_at)
                        .map(|k| (k as f64 + 1.0 - k_now as f64) * STEP_SECS)
                };
                // The synthetic world's reacting A yields to its B (the oracle's rule); the
                // reference is the one `others` holds.
                let yielding = self
                    .synthetic
                    .as_ref()
                    .filter(|syn| self.config.take_right_of_way && syn.b_track == c.track)
                    .and_then(|syn| syn.a_yields)
                    .map(|a| current[a])
                    .filter(|a| a.valid);
                let leader = scbg_synth::closer(
                    leader_on_path(path, s, 0.0, me, &others),
                    crossing_conflict(path, s, me, &others, yielding, arrival),
                );
                if leader.is_some() {
                    a = a.min(GUARD.accel(c.bicycle.speed_mps, leader));
                }
                // The plan's point for now is `k_now - 1` (its first is a step after its start).
                let gap_speed = planned_gap_speed_mps(&c.plan, k_now.saturating_sub(1), STEP_SECS)
                    .unwrap_or(c.bicycle.speed_mps);
                if let Some((lo, hi)) = side_steer_bounds(
                    me,
                    c.bicycle.speed_mps,
                    gap_speed,
                    c.bicycle.wheelbase_m,
                    &others,
                ) {
                    d = d.clamp(lo, hi);
                }
            }
            c.bicycle.step(a, d, &self.config.limits);
            next[c.track] = c.bicycle.state(&self.states[c.track][t]);
        }
        for (i, agent) in self.idm.iter_mut().enumerate() {
            if let Some(agent) = agent {
                next[i] = agent.step(current[i], &others_of(i));
            }
        }
        if let Some(syn) = &mut self.synthetic {
            // B's states from the step after the current one up to `t`, each added once.
            let known = t - self.start;
            if syn.b_prefix.len() > known {
                syn.b_prefix = Default::default();
            }
            while syn.b_prefix.len() < known {
                let s = &self.states[syn.b_track][self.start + syn.b_prefix.len() + 1];
                syn.world
                    .push_b(&mut syn.b_prefix, [s.x_m, s.y_m])
                    .map_err(|e| SimError::Plan {
                        id: scbg_synth::B_ID,
                        step: t,
                        message: e.to_string(),
                    })?;
            }
            let world_next = syn.world.next_states(&syn.b_prefix);
            let controlled: Vec<usize> = self.controlled.iter().map(|c| c.track).collect();
            for (i, p) in world_next.iter().enumerate() {
                // B follows the world only as the ego (it is replayed otherwise).
                let reactive =
                    self.config.reacts(i, self.ego) && (i == self.ego || i != syn.b_track);
                if !reactive || controlled.contains(&i) {
                    continue;
                }
                let q = &self.states[i][t];
                let (vx, vy) = ((p.x_m - q.x_m) / STEP_SECS, (p.y_m - q.y_m) / STEP_SECS);
                next[i] = AgentState {
                    velocity_x_mps: vx as f32,
                    velocity_y_mps: vy as f32,
                    ..*p
                };
            }
        }
        if let Some(s) = ego_next {
            next[self.ego] = s;
        }
        for (s, n) in self.states.iter_mut().zip(next) {
            s[t + 1] = n;
        }
        self.t = t + 1;
        Ok(self.snapshot())
    }

    fn plan_checked(
        &self,
        planner: &mut dyn Planner,
        view: &Scene,
        id: i64,
    ) -> Result<Vec<[f64; 2]>, PlanError> {
        let mut plan = planner.plan(view, id)?;
        if plan.len() != HORIZON_STEPS {
            return Err(PlanError(format!(
                "{} points, expected {HORIZON_STEPS}",
                plan.len()
            )));
        }
        if let Some(k) = plan
            .iter()
            .position(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(PlanError(format!("point {k} is not finite")));
        }
        if let (Some(lanes), Some(max_offset_m)) = (&self.lanes, self.config.lane_keeping_m) {
            lanes.keep_near(&mut plan, max_offset_m);
        }
        Ok(plan)
    }

    /// Runs the remaining steps (the ego must not be driven from outside).
    pub fn run(&mut self, planner: &mut dyn Planner) -> Result<(), SimError> {
        while !self.finished() {
            self.step(planner, None)?;
        }
        Ok(())
    }

    /// The scene with the simulated steps in place of the logged future: `start + 81` steps
    /// (timestamps continued at 10 Hz past the log's end, signals kept where the log has them).
    pub fn to_scene(&self) -> Scene {
        let mut scene = self.log.clone();
        let len = self.start + 1 + HORIZON_STEPS;
        for (tr, s) in scene.tracks.iter_mut().zip(&self.states) {
            tr.states = s[..=self.t].to_vec();
            tr.states.resize(len, AgentState::default());
        }
        scene.timestamps_secs.truncate(len);
        while scene.timestamps_secs.len() < len {
            let last = *scene.timestamps_secs.last().expect("at least 11 steps");
            scene.timestamps_secs.push(last + STEP_SECS);
        }
        if !scene.signals_per_step.is_empty() {
            scene.signals_per_step.resize(len, Vec::new());
        }
        scene
    }

    /// The simulated future of `track` (steps after the scene's current one so far).
    pub fn future(&self, track: usize) -> &[AgentState] {
        &self.states[track][self.start + 1..=self.t]
    }
}
