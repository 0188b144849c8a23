//! The demo's report: the sections of `report.json` and the stages' wall times.

use std::collections::BTreeMap;
use std::time::Instant;

use serde::Serialize;

use super::Check;
use crate::labels::LabelSummary;
use crate::predictor::PredictorEval;
use crate::scbg_eval::ScbgEval;

/// The report's `data` section.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DataReport {
    /// The inputs (the synthetic folder or the user's patterns).
    pub inputs: Vec<String>,
    /// Scenarios in the cache.
    pub scenarios: usize,
    /// Windows in the cache.
    pub windows: usize,
    /// Interacting pairs in the cache.
    pub pairs: usize,
    /// Skipped inputs by reason.
    pub skipped: BTreeMap<String, usize>,
    /// Synthetic families held out of training (`[data] held_out_families`): their per-family
    /// results measure transfer.
    pub held_out_families: Vec<scbg_synth::Family>,
}

/// The report's `labels` section.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LabelsReport {
    /// Labelled futures.
    pub futures: usize,
    /// Logged futures (pair roles).
    pub logged: usize,
    /// The part of ψ's spread that B's future decides.
    pub psi_within_pair_std: f64,
    /// Predictors whose ψ is averaged (the ensemble's size; 1 by default).
    pub predictors: usize,
}

/// The report's `scbg_eval` section.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScbgEvalSummary {
    /// Held-out pair roles.
    pub examples: usize,
    /// |ψ_logged| above which a pair is high courtesy.
    pub high_threshold_psi: f32,
    /// Smallest training label.
    pub psi_min: f32,
    /// Largest training label.
    pub psi_max: f32,
    /// Figure files written in `figures/`.
    pub figures: Vec<String>,
}

/// Everything the demo measured: `report.json` (stable keys, documented in the README).
#[derive(Debug, Clone, Serialize)]
pub struct DemoReport {
    /// The data.
    pub data: DataReport,
    /// Table I.
    pub predictor: PredictorEval,
    /// The labels.
    pub labels: LabelsReport,
    /// Spearman(ψ of the logged future, latent courtesy) per family.
    pub spearman_latent: BTreeMap<String, Option<f64>>,
    /// ψ_label against the simulator's ψ_true on the held-out split (synthetic data only;
    /// `null` otherwise).
    pub fidelity: Option<crate::fidelity::Fidelity>,
    /// The same over every labelled scene (the predictor's training split included), as
    /// `labels/summary.json` has it.
    pub fidelity_all_scenes: Option<crate::fidelity::Fidelity>,
    /// With reaction siblings: `fidelity` of the predictor's checkpoint they were made with,
    /// before they joined (held-out split); `null` otherwise.
    pub fidelity_stage1: Option<crate::fidelity::Fidelity>,
    /// The generator stage's seeds.
    pub generator_seeds: Vec<u64>,
    /// Table II and the correlations per variant: every number is the mean over the seeds.
    pub variants: serde_json::Value,
    /// The same layout with the standard deviation over the seeds.
    pub variants_seed_std: serde_json::Value,
    /// `variants` of each seed, in seed order.
    pub variants_per_seed: Vec<serde_json::Value>,
    /// Per variant, the generated futures scored by the simulator's oracle (synthetic data),
    /// seed mean.
    pub truth_control: serde_json::Value,
    /// The same with the standard deviation over the seeds.
    pub truth_control_seed_std: serde_json::Value,
    /// The yardstick of `truth_control`: the same scoring of the synthetic world's own B at
    /// courtesy c = q ([`crate::fidelity::WorldKnob`]); `null` without a ground truth.
    pub truth_control_world: Option<crate::fidelity::WorldKnob>,
    /// The other yardsticks of `truth_control`: choosing among B's labelled futures (the
    /// generators' training candidates) by the labels and by ψ_true
    /// ([`crate::fidelity::SelectionControl`]); `null` without a ground truth.
    pub truth_control_selection: Option<crate::fidelity::SelectionControl>,
    /// The same two selectors among the full generator's own candidates (B's modes and their
    /// copies; first generator seed), by J_φ and by ψ_true
    /// ([`crate::fidelity::candidate_control`]); `null` without a ground truth.
    pub truth_control_candidates: Option<crate::fidelity::SelectionControl>,
    /// The evaluation's settings and figures.
    pub scbg_eval: ScbgEvalSummary,
    /// The closed-loop stage (full variant, first seed, held-out scenes): realised courtesy,
    /// A's speed, B's collisions and off-road per quantile, WOSAC realism beside log replay,
    /// constant velocity and IDM-only agents; `null` when skipped.
    pub closed_loop: Option<crate::sim_eval::SimEval>,
    /// The same closed-loop stage with sample and rank driving B (the ranked policy of the full
    /// variant's first seed, re-planning at its own cadence, [`scbg::sim::RANKED_REPLAN_EVERY`]
    /// steps; without the knob-from-its-prior WOSAC score); `null` when skipped.
    pub closed_loop_ranked: Option<crate::sim_eval::SimEval>,
    /// Acceptance checks: key → passed.
    pub checks: BTreeMap<&'static str, bool>,
    /// Training time of each generator variant of the first seed, seconds.
    pub generator_seconds: BTreeMap<String, f64>,
    /// Wall time of the whole generator stage (every seed, side by side), seconds.
    pub generator_stage_seconds: f64,
    /// Wall time of each stage that ran, seconds, by [`STAGE_NAMES`].
    pub stage_seconds: BTreeMap<&'static str, f64>,
    /// Wall time of the demo, seconds.
    pub seconds: f64,
    /// The checks with their texts (report.md).
    #[serde(skip)]
    pub check_list: Vec<Check>,
    /// The SCBG evaluation of the first seed (report.md's detailed tables and figures).
    #[serde(skip)]
    pub scbg: ScbgEval,
    /// The label summary (report.md).
    #[serde(skip)]
    pub label_summary: LabelSummary,
}

/// The demo's stages, in order: the keys of [`DemoReport::stage_seconds`].
pub const STAGE_NAMES: [&str; 9] = [
    "data",
    "cache",
    "predictor",
    "predictor_eval",
    "labels",
    "generators",
    "generator_eval",
    "closed_loop",
    "report",
];

/// Each stage's wall time from when the stages began (`(stage number, start)`, in order) and
/// when the last one ended.
pub(super) fn stage_seconds(
    marks: &[(usize, Instant)],
    end: Instant,
) -> BTreeMap<&'static str, f64> {
    marks
        .iter()
        .enumerate()
        .map(|(i, &(n, began))| {
            let until = marks.get(i + 1).map_or(end, |m| m.1);
            (STAGE_NAMES[n - 1], (until - began).as_secs_f64())
        })
        .collect()
}
