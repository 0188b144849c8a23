//! WOSAC realism of anyone's rollouts (`scbg eval wosac`, Python's `scbg.score_wosac`), and the
//! log-replay and constant-velocity baselines written as submissions (`scbg data
//! wosac-baseline`).
//!
//! [`score_submission`] reads a submission — `SimAgentsChallengeSubmission` shard files
//! (`shared/spec/wosac.md` §3), or `.tar.gz` archives of them — and the WOMD files that hold the
//! logged scenarios. Each submitted scenario is matched by id to its logged scene, checked with
//! the challenge's rules ([`scbg_womd::wosac::validate_rollouts`]) and scored with the functions
//! the closed loop uses ([`scbg_metrics::wosac::scenario_metrics`], then
//! [`scbg_metrics::wosac::aggregate`] over the scored scenarios), in the 2025 definition.
//!
//! **Bad input is skipped, never fatal.** A scenario missing from the scenario files, rollouts
//! that break a rule (joint-scene count, agents, steps, non-finite values), a scene that cannot
//! be scored (no road edge, an evaluated object that is not a sim agent, not 91 steps), a
//! scenario repeated in the submission, a shard that is not a submission, an archive that
//! cannot be read, an unreadable scenario record: each is left out, counted by reason and
//! listed with the file, the scenario and the full message naming the field. Only inputs that
//! match no file at all are an error ([`crate::InvalidRequest`]); the caller decides what
//! nothing scored means (the binary exits with code 2).
//!
//! Memory stays bounded by one shard: the scenario files are memory-mapped and indexed by
//! scenario id (each record decoded once to learn its id, and again when it is scored), and
//! shards are read one at a time, their scenarios scored in parallel on the rayon pool.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use rayon::prelude::*;
use scbg_metrics::wosac::{SimPose, WosacConfig};
use scbg_womd::wosac::{ObjectTrajectory, WosacExportError};
use serde::Serialize;

mod index;
mod report;
mod shards;

pub use report::{ScoredScenario, Skipped, WosacScore};
pub use scbg_metrics::wosac::{
    BucketScores, DatasetMetrics, FeatureLikelihoods, Rollouts, ScenarioMetrics,
};
pub use scbg_womd::wosac::{ScenarioRolloutsInput, SubmissionHeader};

use index::ScenarioIndex;

/// The challenge definition every score here uses: WOSAC 2025.
pub const CHALLENGE: WosacConfig = WosacConfig::V2025;

/// Why a submitted scenario is left out when no scenario file holds its id.
pub const NOT_IN_SCENARIO_FILES: &str = "not in the scenario files";

/// The submission form of `rollouts` for `scenario_id`: each joint scene lists the objects in
/// the order of [`Rollouts::object_ids`].
pub fn submission_input(scenario_id: &str, rollouts: &Rollouts) -> ScenarioRolloutsInput {
    ScenarioRolloutsInput {
        scenario_id: scenario_id.to_string(),
        joint_scenes: rollouts
            .trajectories
            .iter()
            .map(|joint| {
                rollouts
                    .object_ids
                    .iter()
                    .zip(joint)
                    .map(|(&object_id, poses)| ObjectTrajectory {
                        object_id,
                        x_m: poses.iter().map(|p| p.x_m).collect(),
                        y_m: poses.iter().map(|p| p.y_m).collect(),
                        z_m: poses.iter().map(|p| p.z_m).collect(),
                        heading_rad: poses.iter().map(|p| p.heading_rad).collect(),
                    })
                    .collect()
            })
            .collect(),
    }
}

/// The metrics' form of submitted rollouts: the objects in the order of the first joint scene,
/// every joint scene's trajectories put in that order (a submission may order each joint scene
/// differently). Run [`scbg_womd::wosac::validate_rollouts`] first: an object missing from a
/// joint scene, or fields of different lengths, give trajectories of the wrong length, which
/// [`scbg_metrics::wosac::scenario_metrics`] then refuses.
pub fn rollouts_of_submission(input: &ScenarioRolloutsInput) -> Rollouts {
    let object_ids: Vec<i64> = input
        .joint_scenes
        .first()
        .map(|joint| joint.iter().map(|t| t.object_id).collect())
        .unwrap_or_default();
    let poses = |t: &ObjectTrajectory| -> Vec<SimPose> {
        t.x_m
            .iter()
            .zip(&t.y_m)
            .zip(&t.z_m)
            .zip(&t.heading_rad)
            .map(|(((&x_m, &y_m), &z_m), &heading_rad)| SimPose {
                x_m,
                y_m,
                z_m,
                heading_rad,
            })
            .collect()
    };
    let trajectories = input
        .joint_scenes
        .iter()
        .map(|joint| {
            let by_id: std::collections::HashMap<i64, &ObjectTrajectory> =
                joint.iter().map(|t| (t.object_id, t)).collect();
            object_ids
                .iter()
                .map(|id| by_id.get(id).map_or_else(Vec::new, |t| poses(t)))
                .collect()
        })
        .collect();
    Rollouts {
        object_ids,
        trajectories,
    }
}

/// Scores a WOSAC submission against the logged scenarios (see the module documentation).
///
/// `scenario_files` and `submission` are paths, folders or glob patterns
/// ([`crate::inputs::expand`]); a submission file is a shard, or a gzip-compressed tar archive
/// of shards (recognised by its content). Fails only when an argument matches no file.
pub fn score_submission(
    scenario_files: &[String],
    submission: &[String],
    progress: &dyn crate::Progress,
) -> anyhow::Result<WosacScore> {
    let start = Instant::now();
    let scenario_paths = crate::inputs::expand(scenario_files).context("scenario files")?;
    let submission_paths = crate::inputs::expand(submission).context("submission files")?;
    let mut skipped = Vec::new();
    let files = index::open_files(&scenario_paths, &mut skipped);
    let index = ScenarioIndex::build(&files, &mut skipped, progress);

    // Scenarios wait until a few per thread are decoded (one shard may hold a single one),
    // then are scored in parallel: memory holds one shard and one batch.
    let batch = 4 * rayon::current_num_threads();
    let mut pending: Vec<(String, ScenarioRolloutsInput)> = Vec::new();
    let mut scored = Vec::new();
    let mut seen = HashSet::new();
    let mut shards = 0usize;
    for path in &submission_paths {
        let read = shards::for_each_shard(path, |name, bytes| {
            shards += 1;
            for r in decode_shard(&name, &bytes, &mut seen, &mut skipped) {
                pending.push((name.clone(), r));
            }
            if pending.len() >= batch {
                score_batch(&mut pending, &index, &mut scored, &mut skipped, progress);
            }
        });
        if let Err(e) = read {
            skipped.push(Skipped {
                file: path.display().to_string(),
                scenario_id: None,
                reason: e.reason.into(),
                detail: e.detail,
            });
        }
    }
    score_batch(&mut pending, &index, &mut scored, &mut skipped, progress);

    let metrics: Vec<ScenarioMetrics> = scored.iter().map(|s| s.metrics.clone()).collect();
    let seconds_per_scenario = (!scored.is_empty())
        .then(|| scored.iter().map(|s| s.seconds).sum::<f64>() / scored.len() as f64);
    let by_reason = scbg_base::skips::count_by_reason(skipped.iter().map(|s| s.reason.as_str()));
    Ok(WosacScore {
        challenge: "2025",
        scenario_files: scenario_paths.len(),
        scenarios_in_files: index.len(),
        submission_files: submission_paths.len(),
        shards,
        not_submitted: index.ids().filter(|id| !seen.contains(*id)).count(),
        aggregate: scbg_metrics::wosac::aggregate(&metrics, CHALLENGE),
        per_scenario: scored,
        skipped: by_reason,
        skipped_items: skipped,
        seconds: start.elapsed().as_secs_f64(),
        seconds_per_scenario,
        threads: rayon::current_num_threads(),
    })
}

/// The scenarios of one shard, in its order; a shard that does not decode, scenarios without
/// an id and scenarios seen before go to `skipped`.
fn decode_shard(
    name: &str,
    bytes: &[u8],
    seen: &mut HashSet<String>,
    skipped: &mut Vec<Skipped>,
) -> Vec<ScenarioRolloutsInput> {
    let rollouts = match scbg_womd::wosac::decode_submission(bytes) {
        Ok((_, rollouts)) => rollouts,
        Err(e) => {
            skipped.push(Skipped {
                file: name.to_string(),
                scenario_id: None,
                reason: e.reason().into(),
                detail: format!("{name}: {e}"),
            });
            return Vec::new();
        }
    };
    let mut out = Vec::with_capacity(rollouts.len());
    for (k, r) in rollouts.into_iter().enumerate() {
        let skip = |e: WosacExportError, detail: String| Skipped {
            file: name.to_string(),
            scenario_id: Some(r.scenario_id.clone()),
            reason: e.reason().into(),
            detail,
        };
        if r.scenario_id.is_empty() {
            let e = WosacExportError::MissingScenarioId {
                expected: String::new(),
            };
            skipped.push(skip(
                e,
                format!("scenario_rollouts[{k}] has no scenario_id"),
            ));
        } else if !seen.insert(r.scenario_id.clone()) {
            let e = WosacExportError::DuplicateScenario {
                scenario_id: r.scenario_id.clone(),
            };
            let detail = format!("scenario_rollouts[{k}]: {e}; the first one counts");
            skipped.push(skip(e, detail));
        } else {
            out.push(r);
        }
    }
    out
}

/// Scores the `pending` scenarios (each with its shard's name) in parallel and empties it; the
/// results keep its order.
fn score_batch(
    pending: &mut Vec<(String, ScenarioRolloutsInput)>,
    index: &ScenarioIndex<'_>,
    scored: &mut Vec<ScoredScenario>,
    skipped: &mut Vec<Skipped>,
    progress: &dyn crate::Progress,
) {
    if pending.is_empty() {
        return;
    }
    let bar = progress.bar("scoring scenarios", pending.len() as u64);
    let results: Vec<Result<ScoredScenario, Skipped>> = pending
        .par_drain(..)
        .map(|(shard, r)| {
            let result = score_one(index, &r, &shard);
            bar.inc(1);
            result
        })
        .collect();
    drop(bar);
    for result in results {
        match result {
            Ok(s) => scored.push(s),
            Err(s) => skipped.push(s),
        }
    }
}

/// One submitted scenario: its logged scene, the challenge's checks, the metrics.
fn score_one(
    index: &ScenarioIndex<'_>,
    rollouts: &ScenarioRolloutsInput,
    shard: &str,
) -> Result<ScoredScenario, Skipped> {
    let start = Instant::now();
    let id = &rollouts.scenario_id;
    let skip = |reason: &str, detail: String| Skipped {
        file: shard.to_string(),
        scenario_id: Some(id.clone()),
        reason: reason.into(),
        detail,
    };
    let Some(entry) = index.get(id) else {
        return Err(skip(
            NOT_IN_SCENARIO_FILES,
            format!(
                "scenario {id} is in none of the {} scenario files",
                index.num_files()
            ),
        ));
    };
    let scene = entry
        .decode()
        .map_err(|e| skip(&format!("unreadable ({})", e.reason()), e.to_string()))?;
    scbg_womd::wosac::validate_rollouts(&scene, rollouts)
        .map_err(|e| skip(e.reason(), e.to_string()))?;
    let metrics =
        scbg_metrics::wosac::scenario_metrics(&scene, &rollouts_of_submission(rollouts), CHALLENGE)
            .map_err(|e| skip(e.reason(), format!("scenario {id}: {e}")))?;
    Ok(ScoredScenario {
        metrics,
        shard: shard.to_string(),
        scenario_file: entry.path().display().to_string(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// A reference behaviour written as a submission.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum Baseline {
    /// Every sim agent's logged future, as stored (invalid states included), 32 times.
    LogReplay,
    /// Every sim agent at its current velocity, z and heading held, 32 times.
    ConstantVelocity,
}

/// What [`write_baseline`] wrote.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BaselineSubmission {
    /// The shard files, one per scenario file.
    pub files: Vec<PathBuf>,
    /// Scenarios written.
    pub scenarios: usize,
    /// Scenes left out (they cannot be scored), and unreadable files or records.
    pub skipped: Vec<Skipped>,
}

/// Writes `baseline` for every scene of `scenario_files` that can be scored, as submission
/// shards `dir/name.binproto-IIIII-of-NNNNN`: shard i holds the scenarios of scenario file i
/// (none when the file gave none), each shard written atomically as soon as its file is read,
/// so memory holds one file's rollouts. Scenes that cannot be scored (not 91 steps, no
/// evaluated object, no road edge, …) and unreadable files or records are left out and listed.
pub fn write_baseline(
    scenario_files: &[String],
    baseline: Baseline,
    dir: &Path,
    name: &str,
    progress: &dyn crate::Progress,
) -> anyhow::Result<BaselineSubmission> {
    let paths = crate::inputs::expand(scenario_files).context("scenario files")?;
    crate::ensure_request!(
        !name.is_empty() && !name.contains(['/', '\\']),
        "submission name {name:?} must be non-empty and contain no path separator"
    );
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let header = SubmissionHeader {
        unique_method_name: name.to_string(),
        description: format!("{baseline:?} baseline written by scbg"),
        ..Default::default()
    };
    let mut out = BaselineSubmission {
        files: Vec::with_capacity(paths.len()),
        scenarios: 0,
        skipped: Vec::new(),
    };
    let bar = progress.bar("baseline rollouts", paths.len() as u64);
    for (i, path) in paths.iter().enumerate() {
        let inputs = baseline_of_file(path, baseline, &mut out.skipped);
        out.scenarios += inputs.len();
        let bytes = scbg_womd::wosac::encode_submission(&header, &inputs)
            .with_context(|| format!("the {baseline:?} rollouts of {}", path.display()))?;
        let shard = dir.join(scbg_womd::wosac::shard_file_name(name, i, paths.len()));
        scbg_base::atomic::write(&shard, &bytes)
            .with_context(|| format!("writing {}", shard.display()))?;
        out.files.push(shard);
        bar.inc(1);
    }
    Ok(out)
}

/// The baseline rollouts of every scene of one file that can be scored.
fn baseline_of_file(
    path: &Path,
    baseline: Baseline,
    skipped: &mut Vec<Skipped>,
) -> Vec<ScenarioRolloutsInput> {
    let file = match scbg_womd::WomdFile::open(path) {
        Ok(f) => f,
        Err(e) => {
            skipped.push(Skipped::unreadable(&e));
            return Vec::new();
        }
    };
    let mut inputs = Vec::new();
    for scene in file.scenes() {
        let scene = match scene {
            Ok(s) => s,
            Err(e) => {
                skipped.push(Skipped::unreadable(&e));
                continue;
            }
        };
        let n = scbg_metrics::wosac::ROLLOUTS_PER_SCENARIO;
        let rollouts = scbg_metrics::wosac::check_scene(&scene).and_then(|()| match baseline {
            Baseline::LogReplay => scbg_metrics::wosac::log_replay_rollouts(&scene, n),
            Baseline::ConstantVelocity => {
                scbg_metrics::wosac::constant_velocity_rollouts(&scene, n)
            }
        });
        match rollouts {
            Ok(r) => inputs.push(submission_input(&scene.scenario_id, &r)),
            Err(e) => skipped.push(Skipped {
                file: path.display().to_string(),
                scenario_id: Some(scene.scenario_id.clone()),
                reason: e.reason().into(),
                detail: e.to_string(),
            }),
        }
    }
    inputs
}

#[cfg(test)]
mod tests;
