//! Checkpoints: `checkpoint.json` (configs, feature statistics, training state) pointing at
//! `model-NNNN.bpk` and `optimizer-NNNN.bpk`. Every file is written to a temporary name and
//! renamed; the JSON pointer is renamed last, so a crash leaves the previous checkpoint intact.

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::optim::ModuleOptimizer;
use burn::tensor::Device;
use scbg_base::atomic::AtomicFile;
use scbg_features::FeatureStats;
use scbg_model::{Multipath, MultipathConfig};
use serde::{Deserialize, Serialize};

use crate::config::TrainConfig;

/// Name of the checkpoint description inside a checkpoint folder.
pub const CHECKPOINT_FILE: &str = "checkpoint.json";
/// `kind` of a predictor checkpoint's `checkpoint.json`.
pub const CHECKPOINT_KIND: &str = "scbg-predictor";
/// The format of `checkpoint.json` this build reads and writes.
pub const CHECKPOINT_FORMAT_VERSION: u32 = 2;

/// Where training stands after a completed epoch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainState {
    /// Epochs completed.
    pub epoch: usize,
    /// Optimizer steps taken (batches, skipped ones included); seeds the batch augmentation.
    pub step: u64,
    /// Base learning rate after plateau reductions and divergence halvings (the cosine
    /// schedule's factor is applied on top).
    pub learning_rate: f64,
    /// Best validation NLL so far (`None` before the first validation).
    pub best_val_loss: Option<f64>,
    /// Consecutive epochs whose validation loss did not beat `best_val_loss`.
    pub epochs_without_improvement: usize,
}

/// One epoch's numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpochReport {
    /// The epoch, 0-based.
    pub epoch: usize,
    /// Mean training loss of the finite batches (NaN when none was).
    pub train_loss: f64,
    /// Mean conditional-mode GMM NLL on the validation set (nats per sample); `None` without
    /// validation samples.
    pub val_loss: Option<f64>,
    /// Marginal minADE at 8 s (metres) on up to 512 validation samples.
    pub val_min_ade_8s: Option<f32>,
    /// Learning rate at the epoch's last step (schedule applied).
    pub learning_rate: f64,
    /// Batches skipped for a non-finite loss.
    pub skipped_batches: usize,
    /// Wall-clock time of the epoch, validation included (seconds).
    pub seconds: f64,
}

/// A predictor checkpoint as described by `checkpoint.json`: everything needed to rebuild the
/// model (configs, feature statistics) and to resume training (state, optimizer file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// Always [`CHECKPOINT_KIND`]: tells a predictor folder from other scbg artefacts.
    pub kind: String,
    /// [`CHECKPOINT_FORMAT_VERSION`] when written by this build.
    pub format_version: u32,
    /// The training configuration (`--resume` requires the same one).
    pub train_config: TrainConfig,
    /// The model widths the weights belong to.
    pub model_config: MultipathConfig,
    /// Feature standardisation statistics fitted on the training samples; inputs must be
    /// standardised with them before inference.
    pub stats: FeatureStats,
    /// Training state after the last completed epoch.
    pub state: TrainState,
    /// One report per completed epoch.
    pub history: Vec<EpochReport>,
    /// Model weights file in the checkpoint folder (`model-NNNN.bpk`, NNNN = epochs done).
    pub model_file: String,
    /// Optimizer state file in the checkpoint folder (`optimizer-NNNN.bpk`).
    pub optimizer_file: String,
}

/// Why a checkpoint could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// A file-system error.
    #[error("{error}: {}", path.display())]
    Io {
        /// The file or folder concerned.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// Not a (current-format) predictor checkpoint, or a record that failed to save or load.
    #[error("{message}: {}", path.display())]
    Format {
        /// The file or folder concerned.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The model's weights are not all finite; nothing was written.
    #[error("refusing to save non-finite weights (epoch {epoch})")]
    NonFinite {
        /// Epochs completed by the state being saved.
        epoch: usize,
    },
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> CheckpointError + '_ {
    move |error| CheckpointError::Io {
        path: path.to_path_buf(),
        error,
    }
}

/// True when every parameter of the module is finite.
pub fn weights_finite(model: &Multipath) -> bool {
    struct Check(bool);
    impl burn::module::ModuleVisitor for Check {
        fn visit_float<const D: usize>(
            &mut self,
            param: &burn::module::Param<burn::tensor::Tensor<D>>,
        ) {
            if self.0 {
                let s: f32 = param.val().sum().into_scalar();
                self.0 = s.is_finite();
            }
        }
    }
    let mut c = Check(true);
    model.visit(&mut c);
    c.0
}

/// A single path component naming a file: not empty, no separator, not `.` or `..`.
pub fn is_plain_file_name(name: &str) -> bool {
    let mut parts = Path::new(name).components();
    matches!(
        (parts.next(), parts.next()),
        (Some(std::path::Component::Normal(_)), None)
    ) && !name.contains(['/', '\\'])
}

/// The optimizer's state as burnpack bytes with its tensors in name order. burn lists them
/// in a hash map's order, which differs between processes: the same state would otherwise be
/// different bytes in every run.
fn ordered_optimizer_record(optimizer: &ModuleOptimizer) -> Result<Vec<u8>, CheckpointError> {
    let format = |e: String| CheckpointError::Format {
        path: PathBuf::from("optimizer state"),
        message: e,
    };
    let bytes = optimizer
        .into_bytes()
        .map_err(|e| format(format!("{e:?}")))?;
    let reader = burn_pack::Reader::from_bytes(bytes).map_err(|e| format(format!("{e:?}")))?;
    let (scalars, metadata) = (reader.scalars().clone(), reader.metadata().clone());
    let mut tensors = reader
        .into_tensors()
        .map_err(|e| format(format!("{e:?}")))?;
    tensors.sort_by(|a, b| a.name.cmp(&b.name));
    let mut writer = burn_pack::Writer::new(tensors);
    for (key, value) in &scalars {
        writer = writer.with_scalar(key, *value);
    }
    for (key, value) in &metadata {
        writer = writer.with_metadata(key, value);
    }
    let bytes = writer.into_bytes().map_err(|e| format(format!("{e:?}")))?;
    Ok(bytes.to_vec())
}

/// Saves one record file atomically: `save` writes to a temporary name in `dir`, which is
/// renamed to `name` when complete (and removed when `save` fails).
pub fn save_record(
    dir: &Path,
    name: &str,
    save: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), CheckpointError> {
    let path = dir.join(name);
    let file = AtomicFile::create(&path).map_err(|e| io(&path)(e.into()))?;
    // The temporary name has an extension, so burnpack does not add its own.
    save(file.temp_path()).map_err(|message| CheckpointError::Format {
        path: path.clone(),
        message,
    })?;
    file.commit().map_err(|e| io(&path)(e.into()))
}

impl Checkpoint {
    /// Saves the model, the optimizer and this description into `dir` (as
    /// `model-NNNN.bpk`, `optimizer-NNNN.bpk` for NNNN = `state.epoch`, then
    /// `checkpoint.json`), and removes every other checkpoint's record files.
    pub fn save(
        mut self,
        dir: &Path,
        model: &Multipath,
        optimizer: &ModuleOptimizer,
    ) -> Result<(), CheckpointError> {
        if !weights_finite(model) {
            return Err(CheckpointError::NonFinite {
                epoch: self.state.epoch,
            });
        }
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        self.model_file = format!("model-{:04}.bpk", self.state.epoch);
        self.optimizer_file = format!("optimizer-{:04}.bpk", self.state.epoch);
        save_record(dir, &self.model_file, |p| {
            model.clone().save_file(p).map_err(|e| format!("{e:?}"))
        })?;
        let optimizer_bytes = ordered_optimizer_record(optimizer)?;
        let path = dir.join(&self.optimizer_file);
        scbg_base::atomic::write(&path, &optimizer_bytes).map_err(|e| io(&path)(e.into()))?;
        let path = dir.join(CHECKPOINT_FILE);
        let json = serde_json::to_vec_pretty(&self).map_err(|e| CheckpointError::Format {
            path: path.clone(),
            message: e.to_string(),
        })?;
        scbg_base::atomic::write(&path, json).map_err(|e| io(&path)(e.into()))?;
        // Every other checkpoint's record files go, not only the previous one's: a run killed
        // between writing `checkpoint.json` and this sweep left the one before, and the resumed
        // run's previous checkpoint is the newer one.
        let stale = |name: &str| {
            name != self.model_file
                && name != self.optimizer_file
                && (name.starts_with("model-") || name.starts_with("optimizer-"))
                && name.ends_with(".bpk")
        };
        if let Ok(entries) = std::fs::read_dir(dir) {
            for entry in entries.flatten() {
                if entry.file_name().to_str().is_some_and(stale) {
                    let _ = std::fs::remove_file(entry.path());
                }
            }
        }
        Ok(())
    }

    /// Reads `dir/checkpoint.json`; a folder without one, an old format or another kind of
    /// artefact is a [`CheckpointError::Format`] that says which.
    pub fn read(dir: &Path) -> Result<Self, CheckpointError> {
        let path = dir.join(CHECKPOINT_FILE);
        let text = std::fs::read_to_string(&path).map_err(|error| {
            if error.kind() == std::io::ErrorKind::NotFound {
                CheckpointError::Format {
                    path: dir.to_path_buf(),
                    message: format!("not a predictor checkpoint folder (no {CHECKPOINT_FILE})"),
                }
            } else {
                io(&path)(error)
            }
        })?;
        Self::from_json(&text, &path)
    }

    /// A checkpoint description from the text of a `checkpoint.json` (`path` names it in
    /// errors): the same checks as [`Self::read`], and the record files must be plain names
    /// inside the folder.
    pub fn from_json(text: &str, path: &Path) -> Result<Self, CheckpointError> {
        let path = path.to_path_buf();
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| CheckpointError::Format {
                path: path.clone(),
                message: e.to_string(),
            })?;
        let kind = value.get("kind").and_then(|k| k.as_str());
        let version = value.get("format_version").and_then(|v| v.as_u64());
        let refuse = |message: String| CheckpointError::Format {
            path: path.clone(),
            message,
        };
        match (kind, version) {
            (Some(CHECKPOINT_KIND), Some(v)) if v == u64::from(CHECKPOINT_FORMAT_VERSION) => {}
            (Some(CHECKPOINT_KIND), Some(v)) => {
                return Err(refuse(format!(
                    "predictor checkpoint format {v}, this build reads format {CHECKPOINT_FORMAT_VERSION}: retrain with `scbg train predictor`"
                )));
            }
            (None, None) if value.get("train_config").is_some() => {
                return Err(refuse(
                    "written by an older scbg (before format versions): retrain with `scbg train predictor`".into(),
                ));
            }
            _ => {
                return Err(refuse(format!(
                    "not a scbg predictor checkpoint (kind {kind:?})"
                )));
            }
        }
        let ckpt: Self = serde_json::from_value(value).map_err(|e| CheckpointError::Format {
            path: path.clone(),
            message: e.to_string(),
        })?;
        for (key, name) in [
            ("model_file", &ckpt.model_file),
            ("optimizer_file", &ckpt.optimizer_file),
        ] {
            if !is_plain_file_name(name) {
                return Err(refuse(format!(
                    "{key} {name:?} is not a file name inside the checkpoint folder"
                )));
            }
        }
        Ok(ckpt)
    }

    /// The model with its weights, on `device`.
    pub fn load_model(&self, dir: &Path, device: &Device) -> Result<Multipath, CheckpointError> {
        let path = dir.join(&self.model_file);
        self.model_config
            .init(device)
            .try_load_file(&path)
            .map_err(|e| CheckpointError::Format {
                path,
                message: format!("{e:?}"),
            })
    }

    /// The optimizer state from [`Self::optimizer_file`], loaded into `optimizer`.
    pub fn load_optimizer(
        &self,
        dir: &Path,
        optimizer: ModuleOptimizer,
    ) -> Result<ModuleOptimizer, CheckpointError> {
        let path = dir.join(&self.optimizer_file);
        optimizer.load(&path).map_err(|e| CheckpointError::Format {
            path,
            message: format!("{e:?}"),
        })
    }
}
