//! Synthetic interactive traffic with drivers of known courtesy.
//!
//! [`generate`] builds scenario `index` of a run deterministically from `(seed, index)`: a map
//! with real geometry (lanes with types, speed limits and links; road lines; road edges; stop
//! signs and crosswalks where they belong; procedural roads in the following family), its
//! detail varied as other maps vary it (`map_detail`), vehicle A (the SDC, IDM with a reaction
//! delay), vehicle B with a latent courtesy `c ∈ [0, 1]`, and background traffic. The result is a
//! [`Scene`] (91 steps at 10 Hz, current step 10, `objects_of_interest = [A, B]`, both in
//! `tracks_to_predict`) plus its [`GroundTruth`], including A's average future speed in a
//! re-simulation without B. See [`families`] for how courtesy acts in each scene family.
//!
//! **Architecture invariant:** produces `Scene` values only; writing them as WOMD files is the
//! caller's business (this crate does not know protobuf or TFRecord).

#![warn(missing_docs)]

mod closed_loop;
pub mod families;
mod family;
mod map_detail;
mod path;
mod sim;

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use scbg_scene::{PredictionDifficulty, PredictionTarget, Scene};

pub use closed_loop::{BPrefix, ClosedLoop};
pub use families::{A_ID, B_ID, CUT_IN_REACTION_S, LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2, NUM_STEPS};
pub use family::{Family, UnknownFamily};
pub use path::RefPath;
pub use sim::{Idm, STEP_SECS, boxes_overlap, closer};

use families::{BPlan, Run};

/// History steps including the current one.
pub const CURRENT_STEP: usize = 10;

/// What the generator knows about a scenario and a model has to discover: one line of the
/// `ground_truth.jsonl` sidecar.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GroundTruth {
    /// Id of the generated scene (`synth-<seed hex>-<index>`).
    pub scenario_id: String,
    /// Seed of the run the scene belongs to.
    pub seed: u64,
    /// Index of the scene in its run.
    pub index: u64,
    /// The families the run drew from (with `seed` and `index`, what [`Scenario::draw`] needs
    /// to rebuild the scene for the [`Scenario`] oracle).
    pub families: Vec<Family>,
    /// The scene's family.
    pub family: Family,
    /// Track id of vehicle A (the SDC).
    pub a_id: i64,
    /// Track id of vehicle B (the one with the latent courtesy).
    pub b_id: i64,
    /// B's latent courtesy.
    pub courtesy: f64,
    /// A's average speed over the 80 future steps.
    pub a_avg_speed_mps: f64,
    /// The same with B absent (re-simulated with every other draw unchanged).
    pub a_avg_speed_alone_mps: f64,
    /// The oracle's A reward for B's logged future: B replayed from the scene's track, A
    /// re-simulated ([`Scenario::a_avg_speed_mps`]). Equal to `a_avg_speed_mps` up to the
    /// replay's error (the oracle-consistency check).
    pub a_avg_speed_replayed_mps: f64,
    /// `E_c'[r_A(y_B(c'))]`: the oracle's A reward averaged over B re-simulated from the
    /// current step with courtesy `c'` from its prior ([`Scenario::expected_a_avg_speed_mps`]).
    pub a_avg_speed_expected_mps: f64,
    /// ψ_true of B's logged future: `a_avg_speed_replayed_mps − a_avg_speed_expected_mps`.
    pub psi_true: f64,
    /// Whether A's and B's boxes overlapped at some step.
    pub collision: bool,
    /// Whether the scene's family is held out of training in its run (its id then ends with
    /// [`scbg_base::split::HELD_OUT_MARK`], and it is only ever evaluated).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub held_out: bool,
}

/// One generated scenario.
#[derive(Debug, Clone)]
pub struct Generated {
    /// The scene (91 steps at 10 Hz, current step 10).
    pub scene: Scene,
    /// What the generator knows about it.
    pub truth: GroundTruth,
}

/// The random draws of one scene, whichever family it is.
#[derive(Debug, Clone)]
enum Params {
    Merge(families::MergeParams),
    Crossing(families::CrossingParams),
    Cutin(families::CutinParams),
    Following(families::FollowingParams),
    Letin(families::LetinParams),
    Roundabout(families::RoundaboutParams),
    Leftturn(families::LeftTurnParams),
    Zipper(families::LetinParams),
}

/// Draws of the courtesy prior `c' ∈ [0, 1]` behind ψ_true's expectation: stratified, the
/// midpoints of [`PRIOR_DRAWS`] equal bins (the prior is uniform).
pub const PRIOR_DRAWS: usize = 16;

/// A future of B that the oracle cannot score.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OracleError {
    /// The future has the wrong number of steps.
    #[error("B's future has {got} steps, the oracle needs {expected}")]
    Steps {
        /// Steps given.
        got: usize,
        /// Steps needed (the scene's future steps).
        expected: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("B's future has a non-finite coordinate at future step {0}")]
    NotFinite(usize),
    /// The ground-truth line does not rebuild the scene it names.
    #[error("ground truth of {0} does not rebuild its scene (seed, index or families wrong)")]
    Mismatch(String),
}

/// One synthetic scenario as drawn (its family, B's latent courtesy, every random draw): the
/// generator of its scene and **the counterfactual oracle** of its courtesy.
///
/// The oracle scores any world-frame future of B (logged, sampled or generated): B is
/// replayed along it, A and the other agents are re-simulated with their own parameters,
/// reaction delay and noise draws, reacting to B through the family's documented rule, which
/// looks at B's observable motion only (`families::merging_into_lane`,
/// `families::committed_to_cross`, and lane occupancy on the cut-in road). A uses that same rule
/// when the scene is generated, so replaying B's logged future reproduces A's logged reward up
/// to the replay's rounding. Then
/// `ψ_true(y_B) = r_A(y_B) − E_c'[r_A(y_B(c'))]`, the expectation over B re-simulated from the
/// current step with courtesy `c'` from its prior ([`PRIOR_DRAWS`] stratified draws), every
/// other draw unchanged, and each `y_B(c')` scored by the same replay.
#[derive(Debug, Clone)]
pub struct Scenario {
    seed: u64,
    index: u64,
    families: Vec<Family>,
    /// The scene's family.
    pub family: Family,
    /// B's latent courtesy.
    pub courtesy: f64,
    /// Whether the scene's family is held out of training ([`Scenario::held_out_if`]).
    pub held_out: bool,
    params: Params,
}

fn a_future_speed(track: &scbg_scene::Track) -> f64 {
    let future = &track.states[CURRENT_STEP + 1..NUM_STEPS];
    future.iter().map(|s| f64::from(s.speed_mps())).sum::<f64>() / future.len() as f64
}

impl Scenario {
    /// Draws scenario `index` of the run with this `seed`, its family from `families`.
    ///
    /// # Panics
    /// If `families` is empty.
    pub fn draw(seed: u64, index: u64, families: &[Family]) -> Self {
        assert!(!families.is_empty(), "at least one family");
        let mut rng = Pcg64Mcg::seed_from_u64(scbg_base::seed::mix(seed, index));
        let family = families[rng.random_range(0..families.len())];
        let courtesy: f64 = rng.random();
        // Draw order is part of the data: keep it.
        let params = match family {
            Family::Merge => Params::Merge(families::merge_params(&mut rng)),
            Family::Crossing => Params::Crossing(families::crossing_params(&mut rng)),
            Family::Cutin => Params::Cutin(families::cutin_params(&mut rng)),
            Family::Following => Params::Following(families::following_params(&mut rng)),
            Family::Letin => Params::Letin(families::letin_params(&mut rng)),
            Family::Roundabout => Params::Roundabout(families::roundabout_params(&mut rng)),
            Family::Leftturn => Params::Leftturn(families::leftturn_params(&mut rng)),
            Family::Zipper => Params::Zipper(families::zipper_params(&mut rng)),
        };
        Self {
            seed,
            index,
            families: families.to_vec(),
            family,
            courtesy,
            held_out: false,
            params,
        }
    }

    /// The scenario, marked held out of training when its family is one of `held_out`: its id
    /// (and its siblings') then ends with [`scbg_base::split::HELD_OUT_MARK`], so every split
    /// puts it in validation. Nothing else about it changes.
    pub fn held_out_if(mut self, held_out: &[Family]) -> Self {
        self.held_out = held_out.contains(&self.family);
        self
    }

    /// The scenario a ground-truth line describes (checked against its id).
    pub fn of_truth(truth: &GroundTruth) -> Result<Self, OracleError> {
        if truth.families.is_empty() {
            return Err(OracleError::Mismatch(truth.scenario_id.clone()));
        }
        let mut s = Self::draw(truth.seed, truth.index, &truth.families);
        s.held_out = truth.held_out;
        if s.scenario_id() != truth.scenario_id || s.family != truth.family {
            return Err(OracleError::Mismatch(truth.scenario_id.clone()));
        }
        Ok(s)
    }

    /// The scene's id (`synth-<seed hex>-<index>`, with
    /// [`scbg_base::split::HELD_OUT_MARK`] appended when held out).
    pub fn scenario_id(&self) -> String {
        let mark = if self.held_out {
            scbg_base::split::HELD_OUT_MARK
        } else {
            ""
        };
        format!("synth-{:x}-{:07}{mark}", self.seed, self.index)
    }

    /// A run without the map (what the oracle's many runs need).
    fn simulate(&self, b: BPlan<'_>) -> Run {
        self.simulate_with(b, false)
    }

    fn simulate_with(&self, b: BPlan<'_>, with_map: bool) -> Run {
        self.simulate_on(self.paths(), b, with_map)
    }

    /// The scene's reference paths (what every run of it moves along).
    fn paths(&self) -> Vec<RefPath> {
        match &self.params {
            Params::Merge(p) => families::merge_paths(p),
            Params::Crossing(p) => families::crossing_paths(p),
            Params::Cutin(p) => families::cutin_paths(p),
            Params::Following(p) => families::following_paths(p),
            Params::Letin(p) | Params::Zipper(p) => families::letin_paths(p),
            Params::Roundabout(p) => families::roundabout_paths(p),
            Params::Leftturn(p) => families::leftturn_paths(p),
        }
    }

    /// A run on `paths` (the scene's own, [`Self::paths`], built once by a caller that runs
    /// the scene many times).
    fn simulate_on(&self, paths: Vec<RefPath>, b: BPlan<'_>, with_map: bool) -> Run {
        match &self.params {
            Params::Merge(p) => families::simulate_merge(p, paths, b, with_map),
            Params::Crossing(p) => families::simulate_crossing(p, paths, b, with_map),
            Params::Cutin(p) => families::simulate_cutin(p, paths, b, with_map),
            Params::Following(p) => families::simulate_following(p, paths, b, with_map),
            Params::Letin(p) | Params::Zipper(p) => families::simulate_letin(p, paths, b, with_map),
            Params::Roundabout(p) => families::simulate_roundabout(p, paths, b, with_map),
            Params::Leftturn(p) => families::simulate_leftturn(p, paths, b, with_map),
        }
    }

    fn logged_plan(&self) -> BPlan<'static> {
        BPlan::Simulated {
            history: self.courtesy,
            future: self.courtesy,
        }
    }

    fn logged(&self) -> Run {
        self.simulate(self.logged_plan())
    }

    /// A's average future speed when B, after its logged history, follows `run_b`'s states
    /// (`(s, d, v)` along B's path for every step).
    fn replayed_a_speed(&self, b_states: &[(f64, f64, f64)], paths: &[RefPath]) -> f64 {
        let run = self.simulate_on(paths.to_vec(), BPlan::Replayed(b_states), false);
        a_future_speed(&sim::record_track(&run.agents[0], paths, NUM_STEPS))
    }

    /// B's states along its path: the logged history, then `future` (world frame, one point
    /// per future step) projected onto B's path, speeds by finite differences.
    ///
    /// A `future` shorter than the scene's (a closed-loop prefix) is continued at its last
    /// speed and lateral offset up to [`NUM_STEPS`] states, so a run can use it; every agent's
    /// state at step `t + 1` depends on B's states up to `t` only.
    fn b_states(
        logged_b: &sim::Agent,
        path: &RefPath,
        future: &[[f64; 2]],
    ) -> Vec<(f64, f64, f64)> {
        let mut prefix = BPrefix::default();
        for &p in future {
            prefix.push(logged_b, path, p);
        }
        prefix.states(logged_b, NUM_STEPS)
    }

    /// The oracle: A's realised average future speed (m/s, over the 80 future steps) when B
    /// follows `b_future` — B's world-frame positions at the future steps 11..=90 — after its
    /// logged history.
    pub fn a_avg_speed_mps(&self, b_future: &[[f64; 2]]) -> Result<f64, OracleError> {
        let logged = self.logged();
        self.a_avg_speed_given(&logged, b_future)
    }

    fn a_avg_speed_given(&self, logged: &Run, b_future: &[[f64; 2]]) -> Result<f64, OracleError> {
        let states = Self::checked_b_states(logged, b_future)?;
        Ok(self.replayed_a_speed(&states, &logged.paths))
    }

    /// B's states for a complete world-frame future (steps 11..=90), checked: 80 finite points.
    fn checked_b_states(
        logged: &Run,
        b_future: &[[f64; 2]],
    ) -> Result<Vec<(f64, f64, f64)>, OracleError> {
        let expected = NUM_STEPS - CURRENT_STEP - 1;
        if b_future.len() != expected {
            return Err(OracleError::Steps {
                got: b_future.len(),
                expected,
            });
        }
        if let Some(t) = b_future
            .iter()
            .position(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(OracleError::NotFinite(t));
        }
        let b = &logged.agents[1];
        Ok(Self::b_states(b, &logged.paths[b.path], b_future))
    }

    /// B's world-frame future (steps 11..=90) in a run.
    fn b_future_of(run: &Run) -> Vec<[f64; 2]> {
        let b = &run.agents[1];
        let path = &run.paths[b.path];
        b.history[CURRENT_STEP + 1..NUM_STEPS]
            .iter()
            .map(|&(s, d, _)| {
                let (x, y) = path.pose(s, d);
                [x, y]
            })
            .collect()
    }

    /// `E_c'[r_A(y_B(c'))]`: the oracle's reward averaged over B re-simulated from the current
    /// step with courtesy `c'` at the midpoints of `draws` equal bins of its uniform prior,
    /// each future scored by replay like any other.
    pub fn expected_a_avg_speed_mps(&self, draws: usize) -> f64 {
        let logged = self.logged();
        self.expected_given(&logged, draws)
    }

    fn expected_given(&self, logged: &Run, draws: usize) -> f64 {
        let draws = draws.max(1);
        (0..draws)
            .map(|k| {
                let run = self.simulate_on(
                    logged.paths.clone(),
                    BPlan::Simulated {
                        history: self.courtesy,
                        future: (k as f64 + 0.5) / draws as f64,
                    },
                    false,
                );
                self.a_avg_speed_given(logged, &Self::b_future_of(&run))
                    .expect("a simulated future is complete and finite")
            })
            .sum::<f64>()
            / draws as f64
    }

    /// ψ_true of a world-frame future of B (steps 11..=90): the oracle's A reward for it minus
    /// its expectation over B's behaviour ([`PRIOR_DRAWS`] draws).
    pub fn psi_true(&self, b_future: &[[f64; 2]]) -> Result<f64, OracleError> {
        let logged = self.logged();
        Ok(self.a_avg_speed_given(&logged, b_future)? - self.expected_given(&logged, PRIOR_DRAWS))
    }

    /// An oracle that keeps the logged run and the expectation, for scoring many futures of
    /// B in this scene.
    pub fn oracle(&self) -> Oracle<'_> {
        let logged = self.logged();
        let expected_a_avg_speed_mps = self.expected_given(&logged, PRIOR_DRAWS);
        Oracle {
            scenario: self,
            logged,
            expected_a_avg_speed_mps,
        }
    }

    /// The scene and its ground truth.
    pub fn generate(&self) -> Generated {
        let mut with_b = self.simulate_with(self.logged_plan(), true);
        let alone = self.simulate(BPlan::Absent);
        let alone_a = sim::record_track(&alone.agents[0], &alone.paths, NUM_STEPS);
        let scene = self.scene_of(&mut with_b, self.scenario_id());
        let (a, b) = (&scene.tracks[0], &scene.tracks[1]);
        // B's logged future as written (the recorded track), as a reader of the file sees it.
        let logged_future: Vec<[f64; 2]> = b.states[CURRENT_STEP + 1..NUM_STEPS]
            .iter()
            .map(|s| [s.x_m, s.y_m])
            .collect();
        let replayed = self
            .a_avg_speed_given(&with_b, &logged_future)
            .expect("a logged future is complete and finite");
        let expected = self.expected_given(&with_b, PRIOR_DRAWS);
        let collision = a
            .states
            .iter()
            .zip(&b.states)
            .any(|(sa, sb)| boxes_overlap(sa, sb));
        let truth = GroundTruth {
            scenario_id: scene.scenario_id.clone(),
            seed: self.seed,
            index: self.index,
            families: self.families.clone(),
            family: self.family,
            a_id: A_ID,
            b_id: B_ID,
            courtesy: self.courtesy,
            a_avg_speed_mps: a_future_speed(a),
            a_avg_speed_alone_mps: a_future_speed(&alone_a),
            a_avg_speed_replayed_mps: replayed,
            a_avg_speed_expected_mps: expected,
            psi_true: replayed - expected,
            collision,
            held_out: self.held_out,
        };
        Generated { scene, truth }
    }

    /// Counterfactual sibling `k` of `of` of the scene: the same history and every draw
    /// unchanged, but B continuing from the current step with courtesy `c' = (k + 0.5) / of`
    /// (the midpoints of `of` equal bins of its prior, as in ψ_true's expectation), and
    /// everyone else reacting to that B. Its id is the scene's with `~cf<k>` appended, so it
    /// lands in the scene's split. These are interventions on B's future: where the logged
    /// data only shows how A's and B's futures co-vary, siblings show what A does when B's
    /// future alone is changed.
    ///
    /// # Panics
    /// If `k >= of`.
    pub fn counterfactual(&self, k: usize, of: usize) -> Scene {
        assert!(k < of, "sibling {k} of {of}");
        let mut run = self.simulate_with(
            BPlan::Simulated {
                history: self.courtesy,
                future: (k as f64 + 0.5) / of as f64,
            },
            true,
        );
        self.scene_of(
            &mut run,
            format!("{}{COUNTERFACTUAL_MARK}cf{k}", self.scenario_id()),
        )
    }

    /// Every agent's track ([`NUM_STEPS`] states, in the scene's track order: A, B, the
    /// others) when B, after its logged history, drives with courtesy `c` from the current step
    /// on and everyone else reacts: the world's own courtesy knob, what a B that is faithful to
    /// its courtesy does here (the ceiling any generated B is measured against). `c` is
    /// clamped to B's prior, [0, 1].
    pub fn tracks_with_courtesy(&self, c: f64) -> Vec<scbg_scene::Track> {
        let run = self.simulate(BPlan::Simulated {
            history: self.courtesy,
            future: c.clamp(0.0, 1.0),
        });
        run.agents
            .iter()
            .map(|a| sim::record_track(a, &run.paths, NUM_STEPS))
            .collect()
    }

    /// The scene of a run with the map (moved out of the run; the oracle's replays need none).
    fn scene_of(&self, run: &mut Run, scenario_id: String) -> Scene {
        let tracks: Vec<_> = run
            .agents
            .iter()
            .map(|a| sim::record_track(a, &run.paths, NUM_STEPS))
            .collect();
        Scene {
            scenario_id,
            timestamps_secs: (0..NUM_STEPS).map(|i| i as f64 * STEP_SECS).collect(),
            current_step: CURRENT_STEP,
            sdc_track_index: Some(0),
            objects_of_interest: vec![A_ID, B_ID],
            tracks_to_predict: vec![
                PredictionTarget {
                    track_index: 0,
                    difficulty: PredictionDifficulty::Level1,
                },
                PredictionTarget {
                    track_index: 1,
                    difficulty: PredictionDifficulty::Level1,
                },
            ],
            map: {
                let mut map = std::mem::take(&mut run.map);
                families::orient_road_edges(&mut map);
                let parallel_edges = matches!(
                    self.family,
                    Family::Cutin | Family::Following | Family::Zipper
                );
                map_detail::vary(&mut map, self.seed, self.index, parallel_edges);
                map
            },
            signals_per_step: Vec::new(),
            tracks,
        }
    }
}

/// Separates a counterfactual sibling's id from its scene's id (`<scene id>~cf<k>`).
pub const COUNTERFACTUAL_MARK: char = '~';

/// The oracle of one scenario with its logged run and `E_c'[r_A(y_B(c'))]` computed once
/// ([`Scenario::oracle`]).
#[derive(Debug)]
pub struct Oracle<'a> {
    scenario: &'a Scenario,
    logged: Run,
    /// `E_c'[r_A(y_B(c'))]`, m/s.
    pub expected_a_avg_speed_mps: f64,
}

impl Oracle<'_> {
    /// A's realised average future speed when B follows `b_future` (world frame, steps
    /// 11..=90); see [`Scenario::a_avg_speed_mps`].
    pub fn a_avg_speed_mps(&self, b_future: &[[f64; 2]]) -> Result<f64, OracleError> {
        self.scenario.a_avg_speed_given(&self.logged, b_future)
    }

    /// ψ_true of `b_future`; see [`Scenario::psi_true`].
    pub fn psi_true(&self, b_future: &[[f64; 2]]) -> Result<f64, OracleError> {
        Ok(self.a_avg_speed_mps(b_future)? - self.expected_a_avg_speed_mps)
    }
}

/// Generates scenario `index` of the run with this `seed`, drawing its family from `families`.
///
/// # Panics
/// If `families` is empty.
pub fn generate(seed: u64, index: u64, families: &[Family]) -> Generated {
    Scenario::draw(seed, index, families).generate()
}

#[cfg(test)]
mod tests;
