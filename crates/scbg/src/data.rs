//! Scenes from files and bytes: reading, inspecting and drawing WOMD files, and the synthetic
//! world's ground-truth sidecar.

use std::io::{BufRead, Write};
use std::path::Path;

use anyhow::Context;
use scbg_features::{PairConfig, PreparedScene, WindowConfig};
use scbg_scene::{ObjectType, Scene};
use scbg_synth::GroundTruth;
use scbg_womd::WomdFile;
use serde::Serialize;

use crate::ROAD_SUBSAMPLE;

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

/// The ground-truth sidecar of a synthetic data folder (one [`GroundTruth`] per line).
pub const GROUND_TRUTH_FILE: &str = "ground_truth.jsonl";

/// Writes the sidecar: one JSON object per line, atomically.
pub fn write_ground_truth(path: &Path, truths: &[GroundTruth]) -> anyhow::Result<()> {
    scbg_base::atomic::write_with(path, |file| -> std::io::Result<()> {
        let mut out = std::io::BufWriter::new(file);
        for t in truths {
            serde_json::to_writer(&mut out, t)?;
            out.write_all(b"\n")?;
        }
        out.flush()
    })?;
    Ok(())
}

/// Reads a sidecar; a bad line is an error naming the file and line.
pub fn read_ground_truth(path: &Path) -> anyhow::Result<Vec<GroundTruth>> {
    let file = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
    let mut out = Vec::new();
    for (i, line) in std::io::BufReader::new(file).lines().enumerate() {
        let line = line.with_context(|| format!("reading {}", path.display()))?;
        if line.trim().is_empty() {
            continue;
        }
        out.push(
            serde_json::from_str(&line)
                .with_context(|| format!("{}: line {}", path.display(), i + 1))?,
        );
    }
    Ok(out)
}
