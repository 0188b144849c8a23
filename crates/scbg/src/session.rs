//! A closed-loop session: a model, one scene's simulation and its courtesy-controlled agents,
//! stepped by a front end (the HTTP server's sessions, the Python `Simulation`).

use std::sync::Arc;

use scbg_scene::Scene;

use crate::model::Model;
use crate::sim::{ControlledAgent, LoopOptions, SimConfig, Simulation};

/// One agent's state at a session's current step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Snapshot {
    /// Track id.
    pub id: i64,
    /// Its state (invalid when the log has none and it is replayed).
    pub state: scbg_scene::AgentState,
}

fn snapshots(agents: Vec<crate::sim::AgentSnapshot>) -> Vec<Snapshot> {
    agents
        .into_iter()
        .map(|a| Snapshot {
            id: a.id,
            state: a.state,
        })
        .collect()
}

/// The ego's next state when the caller drives it ([`crate::sim::EgoMode::External`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgoPose {
    /// World x, metres.
    pub x_m: f64,
    /// World y, metres.
    pub y_m: f64,
    /// Heading, radians.
    pub heading_rad: f32,
    /// World-frame velocity (x, y), m/s.
    pub velocity_mps: [f32; 2],
}

/// A closed-loop simulation of one scene with its controlled agents, planned by the model's
/// policy at each agent's courtesy. Its [`SimConfig`] comes from [`LoopOptions::config`] under
/// the model's policy, so every front end runs the same settings.
#[derive(Debug)]
pub struct Session {
    model: Arc<Model>,
    scene: Arc<Scene>,
    ego: Option<i64>,
    controlled: Vec<ControlledAgent>,
    config: SimConfig,
    sim: Simulation,
}

impl Session {
    /// Starts a simulation of `scene`: `ego` (default: the SDC) and the controlled agents, each
    /// with its courtesy toward the ego.
    pub fn start(
        model: Arc<Model>,
        scene: Arc<Scene>,
        ego: Option<i64>,
        mut controlled: Vec<ControlledAgent>,
        options: &LoopOptions,
    ) -> anyhow::Result<Self> {
        controlled.sort_by_key(|c| c.id);
        let config = options.config(model.policy());
        let sim = crate::sim::start(&scene, ego, &controlled, config, None)?;
        Ok(Self {
            model,
            scene,
            ego,
            controlled,
            config,
            sim,
        })
    }

    /// Starts the same simulation again from the scene's current step.
    pub fn reset(&mut self) -> anyhow::Result<()> {
        self.sim = crate::sim::start(&self.scene, self.ego, &self.controlled, self.config, None)?;
        Ok(())
    }

    /// One step (0.1 s): the controlled agents re-plan when due, everyone moves; `ego` is the
    /// ego's new state when the caller drives it. Returns every agent's state after the step.
    pub fn step(&mut self, ego: Option<EgoPose>) -> anyhow::Result<Vec<Snapshot>> {
        let ego_state = ego.map(|p| {
            self.sim
                .external_ego_state(p.x_m, p.y_m, p.heading_rad, p.velocity_mps)
        });
        crate::sim::step(
            self.model.loaded(),
            &mut self.sim,
            &self.controlled,
            ego_state,
        )
        .map(snapshots)
    }

    /// Steps taken since the scene's current step.
    pub fn step_index(&self) -> usize {
        self.sim.step_index()
    }

    /// Whether the horizon is reached.
    pub fn finished(&self) -> bool {
        self.sim.finished()
    }

    /// The ego's track id.
    pub fn ego_id(&self) -> i64 {
        self.sim.ego_id()
    }

    /// Every agent's current state.
    pub fn snapshot(&self) -> Vec<Snapshot> {
        snapshots(self.sim.snapshot())
    }

    /// The scene with the simulated steps as its future.
    pub fn to_scene(&self) -> Scene {
        self.sim.to_scene()
    }

    /// The controlled agents, by id.
    pub fn controlled(&self) -> &[ControlledAgent] {
        &self.controlled
    }

    /// The simulator's settings it runs with.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }
}
