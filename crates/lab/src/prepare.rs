//! Preparing WOMD files into the feature cache (`scbg data prepare`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::Context;
use rayon::prelude::*;
use scbg::{ROAD_SUBSAMPLE, inputs};
use scbg_features::cache::{Manifest, ShardSummary, ShardWriter, finished_shard};
use scbg_features::{PairConfig, PreparedScene, WindowConfig, marginal_targets};
use scbg_womd::WomdFile;

use crate::{Progress, ensure_request};

/// How `prepare` builds the cache (the `scbg data prepare` flags).
#[derive(Debug, Clone, PartialEq)]
pub struct PrepareOptions {
    /// Input files: glob patterns, folders or paths.
    pub inputs: Vec<String>,
    /// Output folder for shards and the manifest.
    pub out: PathBuf,
    /// Prepare only the shards with `shard % num_shards == shard_index` (several machines).
    pub shard_index: usize,
    /// Number of workers sharing the input.
    pub num_shards: usize,
    /// Input files per shard.
    pub files_per_shard: usize,
    /// Window stride in steps for scenarios longer than one window.
    pub stride_steps: usize,
    /// Pair mining: maximum distance between the two future paths, metres.
    pub pair_distance_m: f64,
    /// Pair mining: maximum difference of arrival times at the conflict point, seconds.
    pub pair_time_gap_s: f64,
}

impl PrepareOptions {
    /// The defaults of `scbg data prepare` for these inputs and output folder.
    pub fn new(inputs: Vec<String>, out: PathBuf) -> Self {
        Self {
            inputs,
            out,
            shard_index: 0,
            num_shards: 1,
            files_per_shard: 16,
            stride_steps: 10,
            pair_distance_m: 3.0,
            pair_time_gap_s: 4.0,
        }
    }
}

fn settings(
    args: &PrepareOptions,
    window: &WindowConfig,
    pair: &PairConfig,
) -> BTreeMap<String, String> {
    [
        ("history_steps", window.history_steps.to_string()),
        ("future_steps", window.future_steps.to_string()),
        ("stride_steps", window.stride_steps.to_string()),
        ("road_subsample", ROAD_SUBSAMPLE.to_string()),
        (
            "pair_max_path_distance_m",
            pair.max_path_distance_m.to_string(),
        ),
        ("pair_max_time_gap_s", pair.max_time_gap_s.to_string()),
        ("pair_min_travel_m", pair.min_travel_m.to_string()),
        (
            "pair_min_future_valid_steps",
            pair.min_future_valid_steps.to_string(),
        ),
        ("pair_max_pairs", pair.max_pairs.to_string()),
        ("files_per_shard", args.files_per_shard.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// Prepares one shard: decodes its files, keeps the scenes that yield windows, writes it.
fn prepare_shard(
    out: &Path,
    shard_file: &str,
    files: &[PathBuf],
    window: &WindowConfig,
    pair: &PairConfig,
    on_file_done: impl Fn(),
) -> anyhow::Result<ShardSummary> {
    let mut summary = ShardSummary {
        file: shard_file.to_string(),
        inputs: files.iter().map(|f| f.display().to_string()).collect(),
        ..Default::default()
    };
    let mut writer = ShardWriter::create(&out.join(shard_file))?;
    for path in files {
        summary.raw_bytes += std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
        let file = match WomdFile::open(path) {
            Ok(f) => f,
            Err(e) => {
                tracing::warn!("skipped: {e}");
                *summary.skipped.entry(e.reason().to_string()).or_default() += 1;
                on_file_done();
                continue;
            }
        };
        for scene in file.scenes() {
            let scene = match scene {
                Ok(s) => s,
                Err(e) => {
                    tracing::warn!("skipped: {e}");
                    *summary.skipped.entry(e.reason().to_string()).or_default() += 1;
                    continue;
                }
            };
            match PreparedScene::from_scene(&scene, window, pair, ROAD_SUBSAMPLE) {
                Ok(p) => {
                    summary.scenarios += 1;
                    summary.windows += p.windows.len();
                    summary.pairs += p.pairs.iter().map(Vec::len).sum::<usize>();
                    summary.targets += p
                        .windows
                        .iter()
                        .map(|w| marginal_targets(&p, w, window.future_steps, 1).len())
                        .sum::<usize>();
                    writer.append(&p)?;
                }
                Err(e) => *summary.skipped.entry(e.reason().to_string()).or_default() += 1,
            }
        }
        on_file_done();
    }
    summary.bytes = writer.finish()?;
    scbg_base::atomic::write_json(out.join(shard_file).with_extension("json"), &summary)?;
    Ok(summary)
}

/// Prepares the cache (resumable: finished shards are kept) and returns the manifest it wrote,
/// which lists every finished shard of the whole input, whoever made it.
pub fn prepare(args: &PrepareOptions, progress: &dyn Progress) -> anyhow::Result<Manifest> {
    ensure_request!(
        args.num_shards > 0 && args.shard_index < args.num_shards,
        "--shard-index {} must be below --num-shards {}",
        args.shard_index,
        args.num_shards
    );
    let files = inputs::expand(&args.inputs)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let window = WindowConfig {
        stride_steps: args.stride_steps,
        ..Default::default()
    };
    let pair = PairConfig {
        max_path_distance_m: args.pair_distance_m as f32,
        max_time_gap_s: args.pair_time_gap_s as f32,
        ..Default::default()
    };
    let groups: Vec<(String, Vec<PathBuf>)> = files
        .chunks(args.files_per_shard.max(1))
        .enumerate()
        .map(|(i, c)| (format!("shard-{i:05}.bin"), c.to_vec()))
        .collect();
    let mine: Vec<&(String, Vec<PathBuf>)> = groups
        .iter()
        .enumerate()
        .filter(|(i, _)| i % args.num_shards == args.shard_index)
        .map(|(_, g)| g)
        .collect();
    let pb = progress.bar("prepare", mine.iter().map(|g| g.1.len() as u64).sum());
    let resumed = Mutex::new(0usize);
    let started = std::time::Instant::now();
    mine.par_iter()
        .map(|(name, group)| {
            let names: Vec<String> = group.iter().map(|f| f.display().to_string()).collect();
            if let Some(done) = finished_shard(&args.out, name, &names) {
                *resumed.lock().expect("no poison") += 1;
                pb.inc(group.len() as u64);
                return Ok(done);
            }
            prepare_shard(&args.out, name, group, &window, &pair, || pb.inc(1))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    drop(pb);
    // The manifest lists every finished shard of the whole input, whoever made it.
    let shards: Vec<ShardSummary> = groups
        .iter()
        .filter_map(|(name, group)| {
            finished_shard(
                &args.out,
                name,
                &group
                    .iter()
                    .map(|f| f.display().to_string())
                    .collect::<Vec<_>>(),
            )
        })
        .collect();
    let mut total = ShardSummary {
        file: String::new(),
        ..Default::default()
    };
    for s in &shards {
        total.add(s);
    }
    let manifest = Manifest {
        format_version: 1,
        settings: settings(args, &window, &pair),
        shards,
        total,
    };
    manifest.write(&args.out)?;
    let t = &manifest.total;
    progress.note(&format!(
        "prepared {} of {} shard(s) ({} resumed) in {:.1}s: {} scenarios, {} windows, {} pairs, {} targets; skipped {:?}; {} raw bytes -> {} cache bytes ({:.3} B/B)",
        manifest.shards.len(),
        groups.len(),
        resumed.into_inner().expect("no poison"),
        started.elapsed().as_secs_f64(),
        t.scenarios,
        t.windows,
        t.pairs,
        t.targets,
        t.skipped,
        t.raw_bytes,
        t.bytes,
        t.bytes as f64 / t.raw_bytes.max(1) as f64,
    ));
    Ok(manifest)
}
