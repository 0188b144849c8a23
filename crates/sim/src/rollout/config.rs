//! The simulation's settings, the planner interface of its controlled agents, and its errors.

use scbg_scene::Scene;
use serde::{Deserialize, Serialize};

use crate::kinematics::VehicleLimits;

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
    /// followed, and a plan that leaves every lane goes on along its lane's route; `None`
    /// follows the plans as generated. Default 0.25 m.
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
    pub(super) fn reacts(&self, i: usize, ego: usize) -> bool {
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
