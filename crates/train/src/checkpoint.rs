//! Checkpoints: `checkpoint.json` (configs, feature statistics, training state) pointing at
//! `model-NNNN.bpk` and `optimizer-NNNN.bpk`. Every file is written to a temporary name and
//! renamed; the JSON pointer is renamed last, so a crash leaves the previous checkpoint intact.

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::optim::ModuleOptimizer;
use burn::tensor::Device;
use scbg_features::FeatureStats;
use scbg_model::{Multipath, MultipathConfig};
use serde::{Deserialize, Serialize};

use crate::config::TrainConfig;

pub const CHECKPOINT_FILE: &str = "checkpoint.json";

/// Where training stands after a completed epoch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainState {
    /// Epochs completed.
    pub epoch: usize,
    pub step: u64,
    pub learning_rate: f64,
    pub best_val_loss: Option<f64>,
    pub epochs_without_improvement: usize,
}

/// One epoch's numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpochReport {
    pub epoch: usize,
    pub train_loss: f64,
    pub val_loss: Option<f64>,
    pub val_min_ade_8s: Option<f32>,
    pub learning_rate: f64,
    pub skipped_batches: usize,
    pub seconds: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    pub train_config: TrainConfig,
    pub model_config: MultipathConfig,
    pub stats: FeatureStats,
    pub state: TrainState,
    pub history: Vec<EpochReport>,
    pub model_file: String,
    pub optimizer_file: String,
}

#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("{error}: {}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{message}: {}", path.display())]
    Format { path: PathBuf, message: String },
    #[error("refusing to save non-finite weights (epoch {epoch})")]
    NonFinite { epoch: usize },
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

/// Saves one record file atomically: `save` writes to a temporary name in `dir`, which is
/// renamed to `name` when complete.
pub fn save_record(
    dir: &Path,
    name: &str,
    save: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), CheckpointError> {
    let tmp = dir.join(format!(".{name}.tmp"));
    let path = dir.join(name);
    save(&tmp).map_err(|message| CheckpointError::Format {
        path: tmp.clone(),
        message,
    })?;
    // burnpack may add its own extension to the name it is given.
    let written = if tmp.exists() {
        tmp.clone()
    } else {
        tmp.with_extension("tmp.bpk")
    };
    std::fs::rename(&written, &path).map_err(io(&path))
}

impl Checkpoint {
    /// Saves the model, the optimizer and this description into `dir`.
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
        let previous = Self::read(dir).ok();
        self.model_file = format!("model-{:04}.bpk", self.state.epoch);
        self.optimizer_file = format!("optimizer-{:04}.bpk", self.state.epoch);
        save_record(dir, &self.model_file, |p| {
            model.clone().save_file(p).map_err(|e| format!("{e:?}"))
        })?;
        save_record(dir, &self.optimizer_file, |p| {
            optimizer.save(p).map_err(|e| format!("{e:?}"))
        })?;
        let path = dir.join(CHECKPOINT_FILE);
        let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(io(dir))?;
        serde_json::to_writer_pretty(&mut tmp, &self).map_err(|e| CheckpointError::Format {
            path: path.clone(),
            message: e.to_string(),
        })?;
        tmp.persist(&path).map_err(|e| CheckpointError::Io {
            path: path.clone(),
            error: e.error,
        })?;
        if let Some(prev) = previous {
            for f in [prev.model_file, prev.optimizer_file] {
                if f != self.model_file && f != self.optimizer_file {
                    let _ = std::fs::remove_file(dir.join(f));
                }
            }
        }
        Ok(())
    }

    pub fn read(dir: &Path) -> Result<Self, CheckpointError> {
        let path = dir.join(CHECKPOINT_FILE);
        let text = std::fs::read_to_string(&path).map_err(io(&path))?;
        serde_json::from_str(&text).map_err(|e| CheckpointError::Format {
            path,
            message: e.to_string(),
        })
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
