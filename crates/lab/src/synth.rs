//! Synthetic interactive scenarios written as WOMD Scenario TFRecords, with the ground-truth
//! sidecar (`ground_truth.jsonl`, one [`GroundTruth`] per line).

use std::path::PathBuf;

use anyhow::Context;
use rayon::prelude::*;
use scbg_synth::{Family, Scenario, generate};

pub use scbg_synth::GroundTruth;

use crate::Progress;

pub use scbg::data::{GROUND_TRUTH_FILE, read_ground_truth, write_ground_truth};

/// What to generate (the `scbg synth` flags).
#[derive(Debug, Clone, PartialEq)]
pub struct SynthOptions {
    /// Number of scenarios.
    pub scenarios: usize,
    /// Random seed; scenario `i` depends on `(seed, i)` only.
    pub seed: u64,
    /// Output folder.
    pub out: PathBuf,
    /// Scene families to draw from.
    pub families: Vec<Family>,
    /// Families among `families` held out of training: their scenes' ids carry
    /// [`scbg_base::split::HELD_OUT_MARK`], so every stage only evaluates them.
    pub held_out: Vec<Family>,
    /// Scenarios per output TFRecord file.
    pub scenarios_per_file: usize,
    /// Counterfactual siblings per scenario ([`scbg_synth::Scenario::counterfactual`]),
    /// written to the [`COUNTERFACTUAL_DIR`] subfolder (0: none). A folder input does not
    /// descend into it, so siblings only reach a cache prepared from that subfolder.
    pub counterfactuals: usize,
}

/// Subfolder of the synthetic output holding the counterfactual siblings.
pub const COUNTERFACTUAL_DIR: &str = "counterfactual";

/// What `write_synthetic` wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthSummary {
    /// TFRecord files written.
    pub files: usize,
    /// Scenarios whose A and B boxes overlapped at some step.
    pub collisions: usize,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// Generates the scenarios in parallel (one worker per file) and writes them with the sidecar.
pub fn write_synthetic(
    options: &SynthOptions,
    progress: &dyn Progress,
) -> anyhow::Result<SynthSummary> {
    std::fs::create_dir_all(&options.out)
        .with_context(|| format!("creating {}", options.out.display()))?;
    if options.counterfactuals > 0 {
        let dir = options.out.join(COUNTERFACTUAL_DIR);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let per_file = options.scenarios_per_file.max(1);
    let n_files = options.scenarios.div_ceil(per_file);
    let pb = progress.bar("synth", options.scenarios as u64);
    let started = std::time::Instant::now();
    let truths: Vec<Vec<GroundTruth>> = (0..n_files)
        .into_par_iter()
        .map(|f| {
            let range = f * per_file..((f + 1) * per_file).min(options.scenarios);
            let drawn: Vec<_> = range
                .map(|i| {
                    Scenario::draw(options.seed, i as u64, &options.families)
                        .held_out_if(&options.held_out)
                })
                .collect();
            let generated: Vec<_> = drawn.iter().map(Scenario::generate).collect();
            let path = options.out.join(format!("synth-{f:05}.tfrecord"));
            scbg_womd::write_scenes(&path, generated.iter().map(|g| &g.scene))?;
            if options.counterfactuals > 0 {
                let k = options.counterfactuals;
                let siblings: Vec<_> = drawn
                    .iter()
                    .flat_map(|s| (0..k).map(move |j| s.counterfactual(j, k)))
                    .collect();
                let path = options
                    .out
                    .join(COUNTERFACTUAL_DIR)
                    .join(format!("synth-cf-{f:05}.tfrecord"));
                scbg_womd::write_scenes(&path, siblings.iter())?;
            }
            pb.inc(generated.len() as u64);
            Ok(generated.into_iter().map(|g| g.truth).collect())
        })
        .collect::<anyhow::Result<_>>()?;
    drop(pb);
    let truths: Vec<GroundTruth> = truths.into_iter().flatten().collect();
    write_ground_truth(&options.out.join(GROUND_TRUTH_FILE), &truths)?;
    let summary = SynthSummary {
        files: n_files,
        collisions: truths.iter().filter(|t| t.collision).count(),
        seconds: started.elapsed().as_secs_f64(),
    };
    progress.note(&format!(
        "wrote {} scenarios in {n_files} file(s) to {} in {:.2}s ({:.0} scenarios/s); A–B collisions: {}",
        options.scenarios,
        options.out.display(),
        summary.seconds,
        options.scenarios as f64 / summary.seconds.max(1e-9),
        summary.collisions
    ));
    Ok(summary)
}

/// Synthetic scenario `index` of the run with `seed` as the bytes of a one-record WOMD
/// Scenario TFRecord file, with its ground truth (what a client would upload).
pub fn scenario_bytes(seed: u64, index: u64) -> anyhow::Result<(Vec<u8>, GroundTruth)> {
    let g = generate(seed, index, &Family::DEFAULT);
    let bytes = scbg_womd::scenes_to_tfrecord_bytes([&g.scene])?;
    Ok((bytes, g.truth))
}
