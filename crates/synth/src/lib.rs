//! Synthetic interactive two-vehicle traffic with drivers of known courtesy.
//!
//! [`generate`] builds scenario `index` of a run deterministically from `(seed, index)`: a map
//! with real geometry (lanes with types, speed limits and links; road lines; road edges; stop
//! signs and crosswalks where they belong), vehicle A (the SDC, IDM with a reaction delay),
//! vehicle B with a latent courtesy `c ∈ [0, 1]`, and background traffic. The result is a
//! [`Scene`] (91 steps at 10 Hz, current step 10, `objects_of_interest = [A, B]`, both in
//! `tracks_to_predict`) plus its [`GroundTruth`], including A's average future speed in a
//! re-simulation without B. See [`families`] for how courtesy acts in each scene family.
//!
//! **Architecture invariant:** produces `Scene` values only; writing them as WOMD files is the
//! caller's business (this crate does not know protobuf or TFRecord).

#![warn(missing_docs)]

pub mod families;
mod path;
mod sim;

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use scbg_scene::{PredictionDifficulty, PredictionTarget, Scene};

pub use path::RefPath;
pub use sim::{STEP_SECS, boxes_overlap};

use families::{A_ID, B_ID, NUM_STEPS, Run};

/// History steps including the current one.
pub const CURRENT_STEP: usize = 10;

/// The scene families.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Family {
    /// On-ramp merge into A's highway lane.
    Merge,
    /// Unprotected crossing at a stop-controlled intersection.
    Crossing,
    /// Lane change / cut-in on a two-lane road.
    Cutin,
}

impl Family {
    /// Every family.
    pub const ALL: [Family; 3] = [Family::Merge, Family::Crossing, Family::Cutin];

    /// The family's name (`merge`, `crossing`, `cutin`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Merge => "merge",
            Self::Crossing => "crossing",
            Self::Cutin => "cutin",
        }
    }

    /// The family of a name.
    pub fn parse(name: &str) -> Result<Self, UnknownFamily> {
        Self::ALL
            .into_iter()
            .find(|f| f.name() == name.trim())
            .ok_or_else(|| UnknownFamily(name.to_string()))
    }
}

/// A family name that is not `merge`, `crossing` or `cutin` (holds the name given).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown scene family {0:?} (expected merge, crossing or cutin)")]
pub struct UnknownFamily(pub String);

/// What the generator knows about a scenario and a model has to discover: one line of the
/// `ground_truth.jsonl` sidecar.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GroundTruth {
    /// Id of the generated scene (`synth-<seed hex>-<index>`).
    pub scenario_id: String,
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
    /// Whether A's and B's boxes overlapped at some step.
    pub collision: bool,
}

/// One generated scenario.
#[derive(Debug, Clone)]
pub struct Generated {
    /// The scene (91 steps at 10 Hz, current step 10).
    pub scene: Scene,
    /// What the generator knows about it.
    pub truth: GroundTruth,
}

fn run(family: Family, rng: &mut Pcg64Mcg, courtesy: f64) -> (Run, Run) {
    match family {
        Family::Merge => {
            let p = families::merge_params(rng);
            (
                families::simulate_merge(&p, courtesy, true),
                families::simulate_merge(&p, courtesy, false),
            )
        }
        Family::Crossing => {
            let p = families::crossing_params(rng);
            (
                families::simulate_crossing(&p, courtesy, true),
                families::simulate_crossing(&p, courtesy, false),
            )
        }
        Family::Cutin => {
            let p = families::cutin_params(rng);
            (
                families::simulate_cutin(&p, courtesy, true),
                families::simulate_cutin(&p, courtesy, false),
            )
        }
    }
}

fn a_future_speed(track: &scbg_scene::Track) -> f64 {
    let future = &track.states[CURRENT_STEP + 1..NUM_STEPS];
    future.iter().map(|s| f64::from(s.speed_mps())).sum::<f64>() / future.len() as f64
}

/// Generates scenario `index` of the run with this `seed`, drawing its family from `families`.
///
/// # Panics
/// If `families` is empty.
pub fn generate(seed: u64, index: u64, families: &[Family]) -> Generated {
    assert!(!families.is_empty(), "at least one family");
    let mut rng = Pcg64Mcg::seed_from_u64(scbg_base::seed::mix(seed, index));
    let family = families[rng.random_range(0..families.len())];
    let courtesy: f64 = rng.random();
    let (with_b, alone) = run(family, &mut rng, courtesy);
    let tracks: Vec<_> = with_b
        .agents
        .iter()
        .map(|a| sim::record_track(a, &with_b.paths, NUM_STEPS))
        .collect();
    let alone_a = sim::record_track(&alone.agents[0], &alone.paths, NUM_STEPS);
    let a = &tracks[0];
    let b = &tracks[1];
    let collision = a
        .states
        .iter()
        .zip(&b.states)
        .any(|(sa, sb)| boxes_overlap(sa, sb));
    let scenario_id = format!("synth-{seed:x}-{index:07}");
    let truth = GroundTruth {
        scenario_id: scenario_id.clone(),
        family,
        a_id: A_ID,
        b_id: B_ID,
        courtesy,
        a_avg_speed_mps: a_future_speed(a),
        a_avg_speed_alone_mps: a_future_speed(&alone_a),
        collision,
    };
    let scene = Scene {
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
        map: with_b.map,
        signals_per_step: Vec::new(),
        tracks,
    };
    Generated { scene, truth }
}

#[cfg(test)]
mod tests;
