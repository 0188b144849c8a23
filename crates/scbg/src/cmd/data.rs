//! `scbg data inspect | render | prepare`.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::{Context, bail};
use rayon::prelude::*;
use scbg_features::cache::{Manifest, ShardSummary, ShardWriter, finished_shard};
use scbg_features::{PairConfig, PreparedScene, WindowConfig, marginal_targets};
use scbg_scene::{ObjectType, Scene};
use scbg_womd::WomdFile;
use serde_json::json;

use crate::cli::{InspectArgs, PrepareArgs, RenderArgs};
use crate::{inputs, progress};

/// Road polylines keep every 4th point (Multipath++).
pub const ROAD_SUBSAMPLE: usize = 4;

fn scene_json(scene: &Scene, file: &Path, format: scbg_womd::Format) -> serde_json::Value {
    let count = |t: ObjectType| scene.tracks.iter().filter(|tr| tr.object_type == t).count();
    let m = &scene.map;
    json!({
        "file": file.display().to_string(),
        "format": format.to_string(),
        "scenario_id": scene.scenario_id,
        "num_steps": scene.num_steps(),
        "current_time_index": scene.current_step,
        "sdc_track_index": scene.sdc_track_index,
        "num_tracks": scene.tracks.len(),
        "tracks_by_type": {
            "vehicle": count(ObjectType::Vehicle),
            "pedestrian": count(ObjectType::Pedestrian),
            "cyclist": count(ObjectType::Cyclist),
            "other": count(ObjectType::Other),
            "unset": count(ObjectType::Unset),
        },
        "num_map_features": m.num_features(),
        "map_features_by_type": {
            "lane": m.lanes.len(),
            "road_line": m.road_lines.len(),
            "road_edge": m.road_edges.len(),
            "stop_sign": m.stop_signs.len(),
            "crosswalk": m.crosswalks.len(),
            "speed_bump": m.speed_bumps.len(),
            "driveway": m.driveways.len(),
        },
        "signal_steps": scene.signals_per_step.iter().filter(|s| !s.is_empty()).count(),
        "objects_of_interest": scene.objects_of_interest,
        "objects_of_interest_types": scene.objects_of_interest.iter()
            .map(|id| scene.track_index(*id).map_or("missing", |i| scene.tracks[i].object_type.name()))
            .collect::<Vec<_>>(),
        "tracks_to_predict": scene.tracks_to_predict.iter().map(|t| t.track_index).collect::<Vec<_>>(),
    })
}

pub fn inspect(args: &InspectArgs) -> anyhow::Result<()> {
    let mut failed = 0usize;
    let mut out = std::io::stdout().lock();
    for path in &args.files {
        let result = (|| -> anyhow::Result<()> {
            let file = WomdFile::open(path)?;
            let format = file.detect_format()?;
            for scene in file.scenes() {
                let scene = scene?;
                if args.json {
                    writeln!(out, "{}", scene_json(&scene, path, format))?;
                } else {
                    let c = |t| scene.tracks.iter().filter(|tr| tr.object_type == t).count();
                    writeln!(
                        out,
                        "{}  {}  [{format}]  steps {} (now {})  tracks {} (veh {} ped {} cyc {} other {})  map {} (lanes {})  interest {:?}  predict {}",
                        path.display(),
                        scene.scenario_id,
                        scene.num_steps(),
                        scene.current_step,
                        scene.tracks.len(),
                        c(ObjectType::Vehicle),
                        c(ObjectType::Pedestrian),
                        c(ObjectType::Cyclist),
                        c(ObjectType::Other),
                        scene.map.num_features(),
                        scene.map.lanes.len(),
                        scene.objects_of_interest,
                        scene.tracks_to_predict.len(),
                    )?;
                }
            }
            Ok(())
        })();
        if let Err(e) = result {
            if e.downcast_ref::<std::io::Error>()
                .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            {
                return Err(e);
            }
            eprintln!("error: {e:#}");
            failed += 1;
        }
    }
    if failed > 0 {
        bail!("{failed} of {} file(s) could not be read", args.files.len());
    }
    Ok(())
}

/// The interacting pair of a scene as scene track indices: the labelled pair, else the first
/// mined pair of the first window that has one.
pub fn interacting_pair(scene: &Scene) -> Option<(usize, usize)> {
    let prepared = PreparedScene::from_scene(
        scene,
        &WindowConfig::default(),
        &PairConfig::default(),
        ROAD_SUBSAMPLE,
    )
    .ok();
    let from_prepared = prepared.as_ref().and_then(|p| {
        let pair = p.pairs.iter().flatten().next()?;
        Some((
            scene.track_index(p.tracks[pair.first].id)?,
            scene.track_index(p.tracks[pair.second].id)?,
        ))
    });
    from_prepared.or_else(|| match scene.objects_of_interest.as_slice() {
        [a, b] => Some((scene.track_index(*a)?, scene.track_index(*b)?)),
        _ => None,
    })
}

pub fn render(args: &RenderArgs) -> anyhow::Result<()> {
    let file = WomdFile::open(&args.file)?;
    let scene = file.scenes().nth(args.index).with_context(|| {
        format!(
            "{} has no scenario at index {}",
            args.file.display(),
            args.index
        )
    })??;
    let pair = interacting_pair(&scene);
    let options = scbg_plot::RenderOptions {
        size_px: args.size_px,
        pair,
        ..Default::default()
    };
    scbg_plot::render_scene(&scene, &args.out, &options)?;
    eprintln!(
        "wrote {} (scenario {}, pair {:?})",
        args.out.display(),
        scene.scenario_id,
        pair
    );
    Ok(())
}

fn settings(
    args: &PrepareArgs,
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
    scbg_features::cache::write_json_atomic(
        &out.join(shard_file).with_extension("json"),
        &summary,
    )?;
    Ok(summary)
}

/// `scbg data prepare`: returns the manifest it wrote.
pub fn prepare(args: &PrepareArgs) -> anyhow::Result<Manifest> {
    if args.num_shards == 0 || args.shard_index >= args.num_shards {
        bail!(
            "--shard-index {} must be below --num-shards {}",
            args.shard_index,
            args.num_shards
        );
    }
    let files = inputs::expand(&args.input)?;
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
    let pb = progress::bar(mine.iter().map(|g| g.1.len() as u64).sum(), "prepare");
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
    pb.finish_and_clear();
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
    eprintln!(
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
    );
    Ok(manifest)
}
