//! WOMD files in, the prepared feature cache out: inspect, render and prepare.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::Context;
use rayon::prelude::*;
use scbg_features::cache::{Manifest, ShardSummary, ShardWriter, finished_shard};
use scbg_features::{PairConfig, PreparedScene, WindowConfig, marginal_targets};
use scbg_scene::{ObjectType, Scene};
use scbg_womd::WomdFile;
use serde::Serialize;

use crate::{Progress, ROAD_SUBSAMPLE, ensure_request, inputs};

/// Tracks of a scene by object type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[allow(missing_docs)]
pub struct TracksByType {
    pub vehicle: usize,
    pub pedestrian: usize,
    pub cyclist: usize,
    pub other: usize,
    pub unset: usize,
}

/// Map features of a scene by kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[allow(missing_docs)]
pub struct MapFeaturesByType {
    pub lane: usize,
    pub road_line: usize,
    pub road_edge: usize,
    pub stop_sign: usize,
    pub crosswalk: usize,
    pub speed_bump: usize,
    pub driveway: usize,
}

/// What `scbg data inspect` says of one scenario (one JSON object per line with `--json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneSummary {
    /// The file the scenario was read from.
    pub file: String,
    /// `scenario` or `tf.Example`.
    pub format: String,
    /// The scenario id.
    pub scenario_id: String,
    /// Time steps (91 in WOMD's training scenarios).
    pub num_steps: usize,
    /// Index of the current step (10 in WOMD).
    pub current_time_index: usize,
    /// Track index of the autonomous vehicle, if any.
    pub sdc_track_index: Option<usize>,
    /// Number of tracks.
    pub num_tracks: usize,
    /// Tracks by object type.
    pub tracks_by_type: TracksByType,
    /// Number of map features.
    pub num_map_features: usize,
    /// Map features by kind.
    pub map_features_by_type: MapFeaturesByType,
    /// Steps that carry traffic-signal states.
    pub signal_steps: usize,
    /// Track ids of the objects of interest (the labelled interacting pair in WOMD).
    pub objects_of_interest: Vec<i64>,
    /// Object type of each object of interest (`missing` when no track has the id).
    pub objects_of_interest_types: Vec<&'static str>,
    /// Track indices to predict.
    pub tracks_to_predict: Vec<usize>,
}

/// Every scene of a WOMD file (Scenario or tf.Example TFRecord); errors name the file, record
/// and field.
pub fn read_scenes(path: &Path) -> anyhow::Result<Vec<Scene>> {
    let womd = scbg_womd::WomdFile::open(path)?;
    Ok(womd.scenes().collect::<Result<Vec<_>, _>>()?)
}

/// Every scene of uploaded bytes: a TFRecord file (Scenario or tf.Example records) or one bare
/// serialized `Scenario` message. Malformed bytes are an [`crate::InvalidRequest`] saying what
/// is wrong.
pub fn scenes_from_bytes(bytes: Vec<u8>) -> anyhow::Result<Vec<Scene>> {
    let bare = scbg_womd::decode_record(&bytes, scbg_womd::Format::Scenario).ok();
    let file = scbg_womd::WomdFile::from_bytes("upload", bytes)
        .and_then(|f| f.scenes().collect::<Result<Vec<_>, _>>());
    match (file, bare) {
        (Ok(scenes), _) if !scenes.is_empty() => Ok(scenes),
        (_, Some(scene)) => Ok(vec![scene]),
        (Ok(_), None) => Err(anyhow::Error::new(crate::InvalidRequest(
            "the upload holds no scenario".into(),
        ))),
        (Err(e), None) => Err(anyhow::Error::new(crate::InvalidRequest(format!(
            "the upload is neither a WOMD TFRecord file nor a Scenario message: {e}"
        )))),
    }
}

/// Summaries of every scenario of a WOMD file (Scenario or tf.Example TFRecords).
pub fn inspect(path: &Path) -> anyhow::Result<Vec<SceneSummary>> {
    let file = WomdFile::open(path)?;
    let format = file.detect_format()?;
    file.scenes()
        .map(|scene| Ok(summarize(&scene?, path, format)))
        .collect()
}

/// The summary of one scene.
pub fn summarize(scene: &Scene, file: &Path, format: scbg_womd::Format) -> SceneSummary {
    let count = |t: ObjectType| scene.tracks.iter().filter(|tr| tr.object_type == t).count();
    let m = &scene.map;
    SceneSummary {
        file: file.display().to_string(),
        format: format.to_string(),
        scenario_id: scene.scenario_id.clone(),
        num_steps: scene.num_steps(),
        current_time_index: scene.current_step,
        sdc_track_index: scene.sdc_track_index,
        num_tracks: scene.tracks.len(),
        tracks_by_type: TracksByType {
            vehicle: count(ObjectType::Vehicle),
            pedestrian: count(ObjectType::Pedestrian),
            cyclist: count(ObjectType::Cyclist),
            other: count(ObjectType::Other),
            unset: count(ObjectType::Unset),
        },
        num_map_features: m.num_features(),
        map_features_by_type: MapFeaturesByType {
            lane: m.lanes.len(),
            road_line: m.road_lines.len(),
            road_edge: m.road_edges.len(),
            stop_sign: m.stop_signs.len(),
            crosswalk: m.crosswalks.len(),
            speed_bump: m.speed_bumps.len(),
            driveway: m.driveways.len(),
        },
        signal_steps: scene
            .signals_per_step
            .iter()
            .filter(|s| !s.is_empty())
            .count(),
        objects_of_interest: scene.objects_of_interest.clone(),
        objects_of_interest_types: scene
            .objects_of_interest
            .iter()
            .map(|id| {
                scene
                    .track_index(*id)
                    .map_or("missing", |i| scene.tracks[i].object_type.name())
            })
            .collect(),
        tracks_to_predict: scene
            .tracks_to_predict
            .iter()
            .map(|t| t.track_index)
            .collect(),
    }
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

/// Draws scenario `index` of `file` as a bird's-eye PNG at `out` (interacting pair
/// highlighted); returns the scenario id and the pair drawn.
pub fn render(
    file: &Path,
    index: usize,
    size_px: u32,
    out: &Path,
) -> anyhow::Result<(String, Option<(usize, usize)>)> {
    let womd = WomdFile::open(file)?;
    let scene = womd.scenes().nth(index).ok_or_else(|| {
        anyhow::Error::new(crate::InvalidRequest(format!(
            "{} has no scenario at index {index}",
            file.display()
        )))
    })??;
    let pair = interacting_pair(&scene);
    let options = scbg_plot::RenderOptions {
        size_px,
        pair,
        ..Default::default()
    };
    scbg_plot::render_scene(&scene, out, &options)?;
    Ok((scene.scenario_id, pair))
}

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
