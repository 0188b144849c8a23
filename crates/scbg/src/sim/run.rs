//! `scbg sim`: rollouts of one scenario from a file, exported, with their metrics.

use std::path::Path;

use anyhow::Context;
use scbg_synth::GroundTruth;
use serde::Serialize;

use super::{
    ControlledAgent, ExportFormat, LoopOptions, RolloutReport, report, rollout, rollout_quantiles,
    wosac_rollouts, write_scenarios, write_wosac,
};
use crate::ensure_request;

/// One `scbg sim` run.
#[derive(Debug, Clone)]
pub struct SimRun {
    /// Generator folder.
    pub model: std::path::PathBuf,
    /// Predictor folder overriding generator.json's.
    pub predictor: Option<std::path::PathBuf>,
    /// How the controlled agents' courtesy becomes their plans.
    pub policy: scbg_generator::Policy,
    /// WOMD file holding the scenario.
    pub scenario: std::path::PathBuf,
    /// Which scenario (default: the first with A and the first controlled agent).
    pub scenario_id: Option<String>,
    /// A, the ego (whose reward courtesy is about).
    pub ego: i64,
    /// The controlled agents (at least one).
    pub controlled: Vec<ControlledAgent>,
    /// Closed-loop settings (the replanning cadence defaults to the policy's).
    pub options: LoopOptions,
    /// Rollouts (32 for WOSAC).
    pub rollouts: usize,
    /// Band of quantiles the rollouts spread over.
    pub spread: f32,
    /// Output folder.
    pub out: std::path::PathBuf,
    /// Export format.
    pub format: ExportFormat,
    /// Method name of a WOSAC submission.
    pub name: String,
}

/// What `scbg sim` did (also `sim.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimOutput {
    /// The scenario.
    pub scenario_id: String,
    /// Whether the synthetic world's rule drove the reactive agents.
    pub synthetic_world: bool,
    /// Quantile each rollout asked of each controlled agent (`[rollout][agent]`; ψ requests
    /// are `null`).
    pub quantiles: Vec<Vec<Option<f32>>>,
    /// Metrics per rollout.
    pub reports: Vec<RolloutReport>,
    /// WOSAC 2025 realism of the rollouts, as `scbg eval wosac` scores them: with 32 rollouts
    /// of a scene that can be scored (`null` otherwise).
    pub wosac: Option<scbg_metrics::wosac::ScenarioMetrics>,
    /// Files written.
    pub files: Vec<std::path::PathBuf>,
}

/// The ground truth of `scenario_id` from `ground_truth.jsonl` beside `file`, if the file
/// is there and describes the scenario (a synthetic scene: its world's rule then drives the
/// reactive agents).
fn truth_for(file: &Path, scenario_id: &str) -> anyhow::Result<Option<GroundTruth>> {
    let path = match file
        .parent()
        .map(|d| d.join(crate::data::GROUND_TRUTH_FILE))
    {
        Some(p) if p.is_file() => p,
        _ => return Ok(None),
    };
    let truth = crate::data::read_ground_truth(&path)?;
    Ok(truth.into_iter().find(|t| t.scenario_id == scenario_id))
}

/// Runs `scbg sim`: `rollouts` closed-loop rollouts of one scenario, exported as Scenario
/// TFRecords or a WOSAC shard, with `sim.json` (metrics per rollout) beside them.
pub fn run_sim(run: &SimRun, progress: &dyn crate::Progress) -> anyhow::Result<SimOutput> {
    ensure_request!(
        !run.controlled.is_empty(),
        "at least one controlled agent (--b)"
    );
    ensure_request!(run.rollouts >= 1, "at least one rollout");
    ensure_request!(
        run.format != ExportFormat::Wosac
            || run.rollouts == scbg_metrics::wosac::ROLLOUTS_PER_SCENARIO,
        "a WOSAC submission needs {} rollouts per scenario (got {})",
        scbg_metrics::wosac::ROLLOUTS_PER_SCENARIO,
        run.rollouts
    );
    let mut model = crate::artefact::load_scbg(&run.model, run.predictor.as_deref())?;
    model.set_policy(run.policy);
    let config = run.options.config(run.policy);
    let (_, scene) = crate::generate::find_scene(
        &run.scenario,
        run.scenario_id.as_deref(),
        run.ego,
        run.controlled[0].id,
    )?;
    let truth = truth_for(&run.scenario, &scene.scenario_id)?;
    let bar = progress.bar("closed-loop rollouts", run.rollouts as u64);
    let mut scenes = Vec::with_capacity(run.rollouts);
    let mut quantiles = Vec::with_capacity(run.rollouts);
    for r in 0..run.rollouts {
        let controlled: Vec<ControlledAgent> = run
            .controlled
            .iter()
            .map(|c| ControlledAgent {
                courtesy: match c.courtesy.as_quantile() {
                    Some(q) if run.rollouts > 1 => c
                        .courtesy
                        .with_quantile(rollout_quantiles(q, run.rollouts, run.spread)[r]),
                    _ => c.courtesy,
                },
                ..*c
            })
            .collect();
        quantiles.push(
            controlled
                .iter()
                .map(|c| c.courtesy.as_quantile())
                .collect(),
        );
        scenes.push(rollout(
            &model,
            &scene,
            Some(run.ego),
            &controlled,
            config,
            truth.as_ref(),
        )?);
        bar.inc(1);
    }
    drop(bar);
    let ids: Vec<i64> = run.controlled.iter().map(|c| c.id).collect();
    let reports = scenes
        .iter()
        .map(|s| report(s, run.ego, &ids))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let wosac_form = (run.rollouts == scbg_metrics::wosac::ROLLOUTS_PER_SCENARIO)
        .then(|| wosac_rollouts(&scene, &scenes));
    let wosac = wosac_form.as_ref().and_then(|r| {
        scbg_metrics::wosac::scenario_metrics(&scene, r, crate::wosac::CHALLENGE).ok()
    });
    std::fs::create_dir_all(&run.out).with_context(|| format!("creating {}", run.out.display()))?;
    let files = match run.format {
        ExportFormat::Scenario => {
            let path = run.out.join("rollouts.tfrecord");
            write_scenarios(&path, &scenes)?;
            vec![path]
        }
        ExportFormat::Wosac => {
            let header = scbg_womd::wosac::SubmissionHeader {
                account_name: String::new(),
                unique_method_name: run.name.clone(),
                authors: vec!["scbg".into()],
                affiliation: String::new(),
                description: format!(
                    "scbg: courtesy-controlled agents (generator re-planning every {} steps, kinematic bicycle), reactive others",
                    config.replan_every
                ),
                method_link: String::new(),
                uses_lidar_data: false,
                uses_camera_data: false,
                uses_public_model_pretraining: false,
                num_model_parameters: String::new(),
                public_model_names: Vec::new(),
                // The challenge asks for a policy that acts on the simulated state every step.
                acknowledge_closed_loop: config.replan_every == 1,
            };
            let rollouts = wosac_form.unwrap_or_else(|| wosac_rollouts(&scene, &scenes));
            write_wosac(
                &run.out,
                &run.name,
                &header,
                &[(scene.clone(), rollouts)],
                1,
            )?
        }
    };
    let output = SimOutput {
        scenario_id: scene.scenario_id.clone(),
        synthetic_world: truth.is_some(),
        quantiles,
        reports,
        wosac,
        files,
    };
    crate::write_json(run.out.join("sim.json"), &output)?;
    Ok(output)
}
