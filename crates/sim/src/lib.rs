//! Closed-loop traffic simulation around courtesy-controlled agents.
//!
//! - [`kinematics`]: the kinematic bicycle (bounded acceleration, jerk, steering angle and
//!   rate) and the tracker that follows a plan;
//! - [`idm`]: reactive agents for any scene (IDM along the agent's logged path, corridor
//!   leaders);
//! - [`guard`]: the safety guard's crossing conflicts and steering bounds for an agent
//!   following a plan;
//! - [`rollout`]: the step-wise [`Simulation`] (`reset → step → … → to_scene`) with a
//!   [`Planner`] for the controlled agents; on a synthetic scene the synthetic world's own
//!   reaction rule ([`scbg_synth::ClosedLoop`]) drives the reactive agents;
//! - [`lanes`]: lane keeping of a plan before it is followed;
//! - [`metrics`]: collision, off-road, progress, jerk and speed of an agent in a rollout.
//!
//! **Architecture invariant:** no models, tensors or file formats: a planner is anything that
//! maps a scene to a future (the app library plugs the generator in).

#![warn(missing_docs)]

pub mod guard;
pub mod idm;
pub mod kinematics;
pub mod lanes;
pub mod metrics;
pub mod rollout;

pub use kinematics::{Bicycle, VehicleLimits};
pub use metrics::{AgentRolloutMetrics, Contact, agent_metrics};
pub use rollout::{
    AgentSnapshot, DEFAULT_LANE_KEEPING_M, DEFAULT_REPLAN_EVERY, EgoMode, HISTORY_STEPS,
    HORIZON_STEPS, OthersMode, PlanError, Planner, SimConfig, SimError, Simulation,
};

#[cfg(test)]
mod tests;
