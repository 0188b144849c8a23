//! The oracle's rule as a closed-loop world: A and the other agents re-simulated step by step
//! around a B driven from outside.

use scbg_scene::Scene;

use crate::families::{BPlan, Run};
use crate::{
    COUNTERFACTUAL_MARK, CURRENT_STEP, NUM_STEPS, OracleError, RefPath, STEP_SECS, Scenario, sim,
};

/// The oracle's rule as a closed-loop world ([`Scenario::closed_loop`]): A and the other
/// agents re-simulated around a B that is driven from outside, step by step.
#[derive(Debug)]
pub struct ClosedLoop {
    scenario: Scenario,
    logged: Run,
}

impl ClosedLoop {
    /// The scenario.
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// Every agent's track ([`NUM_STEPS`] states, in the scene's track order: A, B, the
    /// others) when B, after its logged history, has been at `b_prefix` (world frame, one
    /// point per step from [`CURRENT_STEP`]` + 1` on; at most the 80 future steps). The tracks
    /// of A and the others are exact up to step `CURRENT_STEP + b_prefix.len() + 1` (each
    /// agent's step `t + 1` depends on B's states up to `t` only); later steps continue B at
    /// its last speed. B's own track is its prefix projected onto its reference path.
    pub fn tracks(&self, b_prefix: &[[f64; 2]]) -> Result<Vec<scbg_scene::Track>, OracleError> {
        let mut prefix = BPrefix::default();
        for &p in b_prefix {
            self.push_b(&mut prefix, p)?;
        }
        let run = self.replayed(&prefix, NUM_STEPS);
        Ok(run
            .agents
            .iter()
            .map(|a| sim::record_track(a, &run.paths, NUM_STEPS))
            .collect())
    }

    /// The scene as it would have been logged had B followed `b_future` (world frame, steps
    /// 11..=90) after its logged history, A and everyone else reacting by the oracle's rule:
    /// a counterfactual sibling for *any* future of B (one sampled from a predictor, say),
    /// where [`Scenario::counterfactual`] re-draws B's courtesy. A's track is the one whose
    /// average speed [`Scenario::a_avg_speed_mps`] scores. Its id is the scene's with
    /// `~<tag>` appended, so it lands in the scene's split. The logged run is the world's
    /// own, computed once for any number of futures.
    pub fn replayed_scene(&self, b_future: &[[f64; 2]], tag: &str) -> Result<Scene, OracleError> {
        let states = Scenario::checked_b_states(&self.logged, b_future)?;
        let mut run =
            self.scenario
                .simulate_on(self.logged.paths.clone(), BPlan::Replayed(&states), true);
        Ok(self.scenario.scene_of(
            &mut run,
            format!("{}{COUNTERFACTUAL_MARK}{tag}", self.scenario.scenario_id()),
        ))
    }

    /// Appends B's position at the next future step (world frame) to `prefix`: the step-wise
    /// way to build what [`Self::tracks`] takes, projecting each point onto B's path once.
    pub fn push_b(&self, prefix: &mut BPrefix, p: [f64; 2]) -> Result<(), OracleError> {
        let expected = NUM_STEPS - CURRENT_STEP - 1;
        if prefix.sd.len() >= expected {
            return Err(OracleError::Steps {
                got: prefix.sd.len() + 1,
                expected,
            });
        }
        if !(p[0].is_finite() && p[1].is_finite()) {
            return Err(OracleError::NotFinite(prefix.sd.len()));
        }
        let b = &self.logged.agents[1];
        prefix.push(b, &self.logged.paths[b.path], p);
        Ok(())
    }

    /// Every agent's state (track order) at the first step B's `prefix` does not fix, step
    /// `CURRENT_STEP + prefix.len() + 1`: what [`Self::tracks`] gives there, simulating only
    /// up to the step after it (the one its central-difference velocity needs) instead of the
    /// whole scene, so a closed-loop rollout's step costs what the steps so far cost.
    pub fn next_states(&self, prefix: &BPrefix) -> Vec<scbg_scene::AgentState> {
        let step = CURRENT_STEP + prefix.sd.len() + 1;
        let steps = (step + 2).min(NUM_STEPS);
        let run = self.replayed(prefix, steps);
        run.agents
            .iter()
            .map(|a| sim::recorded_state(a, &run.paths, steps, step))
            .collect()
    }

    /// The scene's first `steps` steps with B replayed along `prefix`.
    fn replayed(&self, prefix: &BPrefix, steps: usize) -> Run {
        let states = prefix.states(&self.logged.agents[1], steps);
        // The logged run's paths: copying them is cheaper than building them again.
        self.scenario
            .simulate_on(self.logged.paths.clone(), BPlan::Replayed(&states), false)
    }
}

/// B's future so far in a closed-loop run of a [`ClosedLoop`] world, as arclength and lateral
/// offset along B's reference path (built with [`ClosedLoop::push_b`]).
#[derive(Debug, Clone, Default)]
pub struct BPrefix {
    /// `(s, d)` of each future step so far.
    sd: Vec<(f64, f64)>,
}

impl BPrefix {
    /// Future steps so far.
    pub fn len(&self) -> usize {
        self.sd.len()
    }

    /// Whether no future step is known yet.
    pub fn is_empty(&self) -> bool {
        self.sd.is_empty()
    }

    /// Appends `p` projected onto `path`, searching near the previous point.
    pub(crate) fn push(&mut self, logged_b: &sim::Agent, path: &RefPath, p: [f64; 2]) {
        let hint = self
            .sd
            .last()
            .map_or(logged_b.history[CURRENT_STEP].0, |&(s, _)| s);
        self.sd.push(path.project(p[0], p[1], Some(hint)));
    }

    /// B's `(s, d, v)` for the first `steps` steps (at least the history): the logged history,
    /// the prefix (speeds by finite differences, central but at the last point), then its last
    /// speed and offset.
    pub(crate) fn states(&self, logged_b: &sim::Agent, steps: usize) -> Vec<(f64, f64, f64)> {
        let mut states: Vec<(f64, f64, f64)> = logged_b.history[..=CURRENT_STEP].to_vec();
        states.extend(self.sd.iter().map(|&(s, d)| (s, d, 0.0)));
        let n = states.len();
        for t in CURRENT_STEP + 1..n {
            let (a, b) = if t + 1 < n {
                (t - 1, t + 1)
            } else {
                (t - 1, t)
            };
            let v = (states[b].0 - states[a].0) / ((b - a) as f64 * STEP_SECS);
            states[t].2 = v.max(0.0);
        }
        while states.len() < steps {
            let (s, d, v) = *states.last().expect("the history is there");
            states.push((s + v * STEP_SECS, d, v));
        }
        states.truncate(steps.max(CURRENT_STEP + 1));
        states
    }
}

impl Scenario {
    /// This scenario as a closed-loop world (keeps its logged run).
    pub fn closed_loop(self) -> ClosedLoop {
        let logged = self.logged();
        ClosedLoop {
            scenario: self,
            logged,
        }
    }
}
