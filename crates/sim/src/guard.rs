//! The safety guard's rules for an agent following a plan: crossing conflicts along its path
//! (another agent at constant velocity in the plan's corridor while the agent's box is there,
//! never stopping inside a crossing agent's way) and steering bounds beside another agent
//! (and gap acceptance: none toward the lane of a follower that could not stay behind).
//! The rollout caps the tracker's acceleration by IDM toward the nearest conflict (with the
//! corridor leader of [`crate::idm`]) and clamps its steering to the bounds.

mod crossing;
mod side;
#[cfg(test)]
mod tests;

pub(crate) use crossing::crossing_conflict;
pub(crate) use side::{planned_gap_speed_mps, side_steer_bounds};
