//! A trained SCBG model folder (`generator.json` beside `generator.bpk` and `range.bpk`, and the
//! predictor it names, or `ensemble.json` naming several such folders): its description and
//! loading.

use std::path::{Path, PathBuf};

use anyhow::Context;
use burn::module::Module;
use burn::tensor::Device;
use scbg_courtesy::label::LabelOptions;
use scbg_generator::{GeneratorConfig, RangePredictor, Scbg, Threshold, Variant};
use scbg_train::Checkpoint;
use serde::{Deserialize, Serialize};

use crate::ensure_request;

/// The generator folder's description file.
pub const GENERATOR_JSON: &str = "generator.json";
/// The generator weights in a generator folder.
pub const GENERATOR_WEIGHTS: &str = "generator.bpk";
/// The range-predictor weights in a generator folder.
pub const RANGE_WEIGHTS: &str = "range.bpk";
/// `kind` of a generator folder's `generator.json`.
pub const GENERATOR_KIND: &str = "scbg-generator";
/// The format of `generator.json` this build reads and writes.
pub const GENERATOR_FORMAT_VERSION: u32 = 3;

/// The description file of an ensemble folder: generator folders planning together.
pub const ENSEMBLE_JSON: &str = "ensemble.json";
/// `kind` of an ensemble folder's `ensemble.json`.
pub const ENSEMBLE_KIND: &str = "scbg-ensemble";
/// The format of `ensemble.json` this build reads.
pub const ENSEMBLE_FORMAT_VERSION: u32 = 1;

/// An ensemble folder's description (`ensemble.json`): generator folders trained by one recipe
/// with different seeds, whose plans the runtime chooses among by their medoid
/// (`crate::generate`; docs/reference.md, *Ensembles*).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EnsembleManifest {
    /// Always [`ENSEMBLE_KIND`].
    pub kind: String,
    /// [`ENSEMBLE_FORMAT_VERSION`].
    pub format_version: u32,
    /// The member generator folders, each relative to the ensemble folder (or absolute).
    pub members: Vec<String>,
}

impl EnsembleManifest {
    /// Reads `dir/ensemble.json`, `None` when there is none; a foreign or malformed file is an
    /// error naming it and the field.
    pub fn read(dir: &Path) -> anyhow::Result<Option<Self>> {
        let json = dir.join(ENSEMBLE_JSON);
        if !json.is_file() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&json)
            .with_context(|| format!("reading {}", json.display()))?;
        let manifest: Self =
            serde_json::from_str(&text).with_context(|| format!("parsing {}", json.display()))?;
        ensure_request!(
            manifest.kind == ENSEMBLE_KIND,
            "{}: kind {:?}, expected {ENSEMBLE_KIND:?}",
            json.display(),
            manifest.kind
        );
        ensure_request!(
            manifest.format_version == ENSEMBLE_FORMAT_VERSION,
            "{}: ensemble format {}, this build reads format {ENSEMBLE_FORMAT_VERSION}",
            json.display(),
            manifest.format_version
        );
        ensure_request!(
            !manifest.members.is_empty(),
            "{}: members: an ensemble needs at least one generator folder",
            json.display()
        );
        Ok(Some(manifest))
    }
}

/// Weights of the generator and the range predictor, and what they were trained with
/// (`generator.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GeneratorCheckpoint {
    /// Always [`GENERATOR_KIND`]: tells a generator folder from a predictor folder.
    pub kind: String,
    /// [`GENERATOR_FORMAT_VERSION`] when written by this build.
    pub format_version: u32,
    /// Which of the paper's three training variants.
    pub variant: Variant,
    /// The predictor checkpoint folder (its encoder is frozen in the generator; it is J_φ).
    /// Training records it absolute; a relative path is relative to the generator folder (a
    /// model shipped with its predictor beside it, as `models/` in the repository).
    pub predictor: String,
    /// The generator's architecture.
    pub generator: GeneratorConfig,
    /// Hidden width of the range predictor.
    pub range_hidden: usize,
    /// How the training labels were made (futures sampled per pair role, reward, estimator of
    /// E[r(Y_A) | x], audience): inference labels the same way.
    pub labels: LabelOptions,
    /// Weight α of the sampled futures' trajectory loss.
    pub alpha: f32,
    /// Weight β of the courtesy loss.
    pub beta: f32,
    /// The high-courtesy threshold of the 50/50 batches as given (`q0.8` or m/s).
    pub threshold: Threshold,
    /// That threshold in ψ units: |ψ| above it counted as high courtesy in training.
    pub threshold_psi: f32,
    /// Smallest ψ label in training (the *arbitrary* range of the evaluation starts here).
    pub psi_min: f32,
    /// Largest ψ label in training.
    pub psi_max: f32,
    /// Seed of initialisation, batches and labels.
    pub seed: u64,
    /// Mean total / trajectory / courtesy loss per epoch.
    pub history: Vec<[f32; 3]>,
    /// Final pinball loss of the range predictor.
    pub range_loss: f32,
    /// Training examples (pair roles).
    pub examples: usize,
    /// Training time, seconds.
    pub seconds: f64,
}

impl GeneratorCheckpoint {
    /// Reads `dir/generator.json`; an old, foreign or unreadable file is an error that says
    /// which and what to do.
    pub fn read(dir: &Path) -> anyhow::Result<Self> {
        let json = dir.join(GENERATOR_JSON);
        if !json.is_file() {
            let hint = if dir.join(scbg_train::checkpoint::CHECKPOINT_FILE).is_file() {
                " (it is a predictor checkpoint; pass a folder from `scbg train generator`)"
            } else {
                ""
            };
            return Err(anyhow::Error::new(crate::InvalidRequest(format!(
                "{} is not a generator folder: no {GENERATOR_JSON}{hint}",
                dir.display()
            ))));
        }
        let text = std::fs::read_to_string(&json)
            .with_context(|| format!("reading {}", json.display()))?;
        Self::from_json(&text, &json)
    }

    /// A generator description from the text of a `generator.json` (`json` names it in
    /// errors), with the same checks as [`Self::read`].
    pub fn from_json(text: &str, json: &Path) -> anyhow::Result<Self> {
        let value: serde_json::Value =
            serde_json::from_str(text).with_context(|| format!("parsing {}", json.display()))?;
        let kind = value.get("kind").and_then(|k| k.as_str());
        let version = value.get("format_version").and_then(|v| v.as_u64());
        match (kind, version) {
            (Some(GENERATOR_KIND), Some(v)) if v == u64::from(GENERATOR_FORMAT_VERSION) => {}
            (Some(GENERATOR_KIND), Some(v)) => anyhow::bail!(
                "{}: generator format {v}, this build reads format {GENERATOR_FORMAT_VERSION}: retrain with `scbg train generator`",
                json.display()
            ),
            (None, None) if value.get("variant").is_some() => anyhow::bail!(
                "{}: written by an older scbg (before format versions): retrain with `scbg train generator`",
                json.display()
            ),
            _ => anyhow::bail!(
                "{}: not a scbg generator description (kind {kind:?})",
                json.display()
            ),
        }
        let checkpoint: Self =
            serde_json::from_value(value).with_context(|| format!("parsing {}", json.display()))?;
        checkpoint
            .labels
            .lane_move_room
            .checked()
            .map_err(|e| anyhow::anyhow!("{}: labels.lane_move_room: {e}", json.display()))?;
        Ok(checkpoint)
    }

    /// Writes `dir/generator.json` atomically.
    pub fn write(&self, dir: &Path) -> anyhow::Result<()> {
        scbg_base::atomic::write_json(dir.join(GENERATOR_JSON), self)?;
        Ok(())
    }
}

/// A trained SCBG model folder, loaded on the plain device: one generator with its predictor,
/// and for an ensemble folder the other members beside it.
#[derive(Debug)]
pub struct LoadedScbg {
    /// Predictor, generator and range predictor with their feature settings.
    pub scbg: Scbg,
    /// The generator folder's description.
    pub checkpoint: GeneratorCheckpoint,
    /// The predictor's description.
    pub predictor: Checkpoint,
    /// The device everything is on.
    pub device: Device,
    /// An ensemble's other members, in `ensemble.json`'s order (empty for one generator).
    pub others: Vec<LoadedScbg>,
}

impl LoadedScbg {
    /// Every member: this one first, then [`Self::others`].
    pub fn members(&self) -> impl Iterator<Item = &LoadedScbg> {
        std::iter::once(self).chain(&self.others)
    }

    /// Sets how a courtesy becomes B's future, for every member.
    pub fn set_policy(&mut self, policy: scbg_generator::Policy) {
        self.scbg.policy = policy;
        for other in &mut self.others {
            other.scbg.policy = policy;
        }
    }
}

/// A folder recorded in `dir`'s description (a generator's predictor, an ensemble's member): an
/// absolute path as it is, a relative one joined to `dir`.
fn recorded_folder(dir: &Path, recorded: &str) -> PathBuf {
    let path = PathBuf::from(recorded);
    if path.is_absolute() {
        path
    } else {
        dir.join(path)
    }
}

/// Loads `dir` (from `scbg train generator`) and its predictor (`predictor` overrides the
/// folder recorded in generator.json), or, where `dir` holds an `ensemble.json` (read first),
/// each of its members (`predictor` overriding every member's). Members must agree on the
/// variant, on how their labels were made and on the horizon, so that their courtesies mean
/// the same.
pub fn load_scbg(dir: &Path, predictor: Option<&Path>) -> anyhow::Result<LoadedScbg> {
    let Some(manifest) = EnsembleManifest::read(dir)? else {
        return load_generator(dir, predictor);
    };
    let json = dir.join(ENSEMBLE_JSON);
    let mut members = Vec::with_capacity(manifest.members.len());
    for (k, member) in manifest.members.iter().enumerate() {
        let member_dir = recorded_folder(dir, member);
        let loaded = load_generator(&member_dir, predictor).with_context(|| {
            format!(
                "{}: members[{k}] ({})",
                json.display(),
                member_dir.display()
            )
        })?;
        members.push(loaded);
    }
    let mut first = members.remove(0);
    for (k, other) in members.iter().enumerate() {
        let (a, b) = (&first.checkpoint, &other.checkpoint);
        let differs = [
            ("variant", a.variant != b.variant),
            ("labels", a.labels != b.labels),
            (
                "generator.future_steps",
                a.generator.future_steps != b.generator.future_steps,
            ),
        ];
        if let Some((field, _)) = differs.iter().find(|(_, d)| *d) {
            return Err(anyhow::Error::new(crate::InvalidRequest(format!(
                "{}: members[{}] differs from members[0] in {field}: an ensemble's members \
                 share one recipe",
                json.display(),
                k + 1
            ))));
        }
    }
    first.others = members;
    Ok(first)
}

/// Loads one generator folder and its predictor ([`load_scbg`]).
fn load_generator(dir: &Path, predictor: Option<&Path>) -> anyhow::Result<LoadedScbg> {
    let checkpoint = GeneratorCheckpoint::read(dir)?;
    let predictor_dir = predictor.map_or_else(
        || recorded_folder(dir, &checkpoint.predictor),
        Path::to_path_buf,
    );
    let ckpt = Checkpoint::read(&predictor_dir)
        .with_context(|| format!("predictor of {} (override with --predictor)", dir.display()))?;
    let modes = checkpoint.generator.modes;
    ensure_request!(
        modes == ckpt.model_config.num_modes,
        "{}: the generator chooses among {modes} modes of B, but the predictor {} predicts {}",
        dir.display(),
        predictor_dir.display(),
        ckpt.model_config.num_modes
    );
    let device = scbg_model::device::device(&ckpt.train_config.backend)?;
    let model = ckpt.load_model(&predictor_dir, &device)?;
    let load = |name: &str| dir.join(name);
    let generator = checkpoint
        .generator
        .init(&device)
        .try_load_file(load(GENERATOR_WEIGHTS))
        .map_err(|e| anyhow::anyhow!("{}: {e:?}", load(GENERATOR_WEIGHTS).display()))?;
    let range = RangePredictor::init(
        ckpt.model_config.embedding_width(),
        checkpoint.range_hidden,
        &device,
    )
    .try_load_file(load(RANGE_WEIGHTS))
    .map_err(|e| anyhow::anyhow!("{}: {e:?}", load(RANGE_WEIGHTS).display()))?;
    Ok(LoadedScbg {
        scbg: Scbg {
            predictor: model,
            generator,
            range,
            stats: ckpt.stats.clone(),
            features: ckpt.train_config.feature_config(),
            labels: checkpoint.labels,
            policy: scbg_generator::Policy::Generator,
        },
        checkpoint,
        predictor: ckpt,
        device,
        others: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_relative_predictor_is_beside_the_generator() {
        let dir = Path::new("models/courtesy/seed0/generator");
        assert_eq!(
            recorded_folder(dir, "../predictor"),
            Path::new("models/courtesy/seed0/generator/../predictor")
        );
        assert_eq!(
            recorded_folder(dir, "/data/run/predictor"),
            Path::new("/data/run/predictor")
        );
    }
}
