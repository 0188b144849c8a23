//! One step of the simulation: the controlled agents' plans, their safety guard, the reactive
//! agents' next states.

use scbg_scene::{AgentState, Scene};

use super::{AgentSnapshot, EgoMode, HORIZON_STEPS, PlanError, Planner, SimError, Simulation};
use crate::guard::{crossing_conflict, planned_gap_speed_mps, side_steer_bounds};
use crate::idm::{leader_on_path, polyline_path};
use crate::kinematics::STEP_SECS;

/// The safety guard's IDM (a free road never limits: the desired speed is out of reach).
const GUARD: scbg_synth::Idm = scbg_synth::Idm {
    desired_speed_mps: 1e3,
    max_accel_mps2: 3.0,
    comfort_brake_mps2: 3.0,
    time_headway_s: 1.0,
    min_gap_m: 2.0,
};

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
            let heading = view.current_state(id).map(|s| f64::from(s.heading_rad));
            lanes.keep_near_from(&mut plan, max_offset_m, heading);
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
}
