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

use crate::idm::IdmAgent;
use crate::kinematics::{Bicycle, STEP_SECS};

mod config;
mod step;

pub use config::{
    DEFAULT_LANE_KEEPING_M, DEFAULT_REPLAN_EVERY, EgoMode, HISTORY_STEPS, HORIZON_STEPS,
    OthersMode, PlanError, Planner, SimConfig, SimError,
};

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
