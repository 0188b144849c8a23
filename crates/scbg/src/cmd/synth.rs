//! `scbg synth`: synthetic interactive scenarios as WOMD Scenario TFRecords + ground truth.

use std::io::Write;

use anyhow::Context;
use rayon::prelude::*;
use scbg_synth::{Family, generate};
use serde_json::json;

use crate::cli::SynthArgs;
use crate::progress;

/// Ground-truth sidecar file name in the output folder.
pub const GROUND_TRUTH_FILE: &str = "ground_truth.jsonl";

pub fn synth(args: &SynthArgs) -> anyhow::Result<()> {
    let families: Vec<Family> = args
        .families
        .iter()
        .map(|f| Family::parse(f))
        .collect::<Result<_, _>>()?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let per_file = args.scenarios_per_file.max(1);
    let n_files = args.scenarios.div_ceil(per_file);
    let pb = progress::bar(args.scenarios as u64, "synth");
    let started = std::time::Instant::now();
    // Each file is generated and written by one worker; scenario i depends only on (seed, i).
    let truths: Vec<Vec<scbg_synth::GroundTruth>> = (0..n_files)
        .into_par_iter()
        .map(|f| {
            let range = f * per_file..((f + 1) * per_file).min(args.scenarios);
            let generated: Vec<_> = range
                .map(|i| generate(args.seed, i as u64, &families))
                .collect();
            let path = args.out.join(format!("synth-{f:05}.tfrecord"));
            scbg_womd::write_scenes(&path, generated.iter().map(|g| &g.scene))?;
            pb.inc(generated.len() as u64);
            Ok(generated.into_iter().map(|g| g.truth).collect())
        })
        .collect::<anyhow::Result<_>>()?;
    pb.finish_and_clear();
    let path = args.out.join(GROUND_TRUTH_FILE);
    let mut tmp = tempfile::NamedTempFile::new_in(&args.out)?;
    let mut collisions = 0;
    for t in truths.iter().flatten() {
        collisions += usize::from(t.collision);
        let line = json!({
            "scenario_id": t.scenario_id,
            "family": t.family.name(),
            "a_id": t.a_id,
            "b_id": t.b_id,
            "courtesy": t.courtesy,
            "a_avg_speed_mps": t.a_avg_speed_mps,
            "a_avg_speed_alone_mps": t.a_avg_speed_alone_mps,
            "collision": t.collision,
        });
        writeln!(tmp, "{line}")?;
    }
    tmp.persist(&path)
        .with_context(|| format!("writing {}", path.display()))?;
    let secs = started.elapsed().as_secs_f64();
    eprintln!(
        "wrote {} scenarios in {n_files} file(s) to {} in {secs:.2}s ({:.0} scenarios/s); A–B collisions: {collisions}",
        args.scenarios,
        args.out.display(),
        args.scenarios as f64 / secs.max(1e-9)
    );
    Ok(())
}
