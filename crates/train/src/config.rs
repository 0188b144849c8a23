//! Training configuration (TOML).

use scbg_features::FeatureConfig;
use scbg_model::MultipathConfig;
use serde::{Deserialize, Serialize};

/// Everything a training run depends on; saved into every checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// Model preset (`cpu-small` or `paper`), used when `model` is absent.
    pub preset: String,
    /// Explicit model widths (overrides `preset`).
    pub model: Option<MultipathConfig>,
    /// Seed of the weight initialisation, the data order and the batch augmentation.
    pub seed: u64,
    /// Number of passes over the training samples.
    pub epochs: usize,
    /// Samples per batch (training and evaluation).
    pub batch_size: usize,
    /// Initial (Adam) learning rate.
    pub learning_rate: f64,
    /// Multiply the learning rate by this after `plateau_patience` epochs without a better
    /// validation loss.
    pub plateau_factor: f64,
    /// Epochs without a better validation loss before the `plateau` schedule lowers the rate.
    pub plateau_patience: usize,
    /// Gradient-norm clipping (Multipath++: 0.4).
    pub grad_clip_norm: f32,
    /// Probability of dropping the condition of a pair sample (trains both modes at once).
    pub condition_dropout: f64,
    /// Probability of masking each past history step of the target (Multipath++: 0.15).
    pub history_mask_prob: f64,
    /// Fraction of scenarios (by id hash) held out for validation.
    pub validation_fraction: f64,
    /// Targets need at least this many valid future steps.
    pub min_future_valid_steps: usize,
    /// Other agents kept per sample (the closest; see `FeatureConfig`).
    pub max_other_agents: usize,
    /// Road segments kept per sample (the closest; see `FeatureConfig`).
    pub max_road_segments: usize,
    /// Cap on marginal samples per window (all vehicles when 0).
    pub max_targets_per_window: usize,
    /// `plateau` (multiply by `plateau_factor` after `plateau_patience` epochs without a better
    /// validation loss) or `cosine` (per step from `learning_rate` down to 1 % of it at the
    /// last step).
    pub lr_schedule: String,
    /// Weight of the mode-classification cross-entropy added to the GMM NLL
    /// (`scbg_model::loss::mode_classification_loss`; 0 = NLL only).
    pub classification_weight: f32,
    /// Weight of the within-group speed contrast added for the conditional samples of one
    /// scene, window, target and condition: the logged sample with its counterfactual and
    /// reaction siblings (`scbg_model::loss::group_speed_contrast`: how B's future moves A's
    /// expected average speed, the difference the courtesy measure ranks by; 0 = none).
    /// Checkpoints written by earlier versions name it `reaction_contrast_weight`.
    #[serde(alias = "reaction_contrast_weight")]
    pub sibling_contrast_weight: f32,
    /// `flex`, `tch`, `cuda` or `vulkan` (each when built with it).
    pub backend: String,
    /// Data-parallel chunks per step: 1 (default) runs the batch in one graph; N > 1 splits
    /// it into N chunks whose forward and backward passes run in parallel, each on its own
    /// fork of the model, and sums their gradients (weighted by chunk size, so the step is the
    /// batch mean's step up to rounding). Lets a step use many cores (docs/findings.md,
    /// *Data-parallel chunks*).
    pub data_parallel_chunks: usize,
    /// A second prepared cache of *counterfactual siblings* (scenes whose id is a training
    /// scene's id + `~…`, sharing its history, with another future of one agent, e.g.
    /// `scbg synth --counterfactuals K` → `counterfactual/`). From each sibling of a
    /// training-split scene, only the SDC's sample conditioned on the other member of each of
    /// its pairs is used: interventions on the condition, which the logged data alone cannot
    /// show. Siblings of validation scenes are left out.
    pub counterfactual_cache: Option<std::path::PathBuf>,
    /// A prepared cache of *reaction siblings* (`scbg label --reaction-siblings`: a training
    /// scene replayed with B following a future sampled from a predictor, A and the others
    /// reacting by the synthetic world's rule). Used like `counterfactual_cache`, except that
    /// training never drops their condition: A's future there is a reaction to an imposed B,
    /// which must teach the conditional mode only, not A's marginal behaviour.
    pub reaction_cache: Option<std::path::PathBuf>,
    /// With `reaction_cache`: the epoch (0-based) from which its samples join the training.
    /// Absent (the default): from the start, on top of the other samples. Given: the cache is
    /// read only when that epoch begins, so it may be made from this very run's checkpoint
    /// after the previous epoch (stop there, write the siblings, `--resume`), and each such
    /// epoch trains on every reaction sample plus a seeded random subset of the other
    /// training samples, as many samples in all as before, so the epoch length and the
    /// learning-rate schedule do not change.
    pub reaction_from_epoch: Option<usize>,
    /// Start from this checkpoint's weights and feature statistics instead of a fresh
    /// initialisation (fine-tuning, e.g. on a `counterfactual_cache` made with the first
    /// model): a fresh optimizer and learning-rate schedule over `epochs`. Its model
    /// configuration must be this run's.
    pub init_from: Option<std::path::PathBuf>,
    /// Place B's future in A's lane frame in the future encoder (turns on
    /// `MultipathConfig::lane_frame_condition` of the preset or the `[model]` table).
    pub lane_frame_condition: bool,
    /// Condition A's decoder step by step on B's future up to each step (interventional; turns
    /// on `MultipathConfig::stepwise_condition` of the preset or the `[model]` table).
    pub stepwise_condition: bool,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            preset: "cpu-small".into(),
            model: None,
            seed: 0,
            epochs: 8,
            batch_size: 32,
            learning_rate: 1e-3,
            plateau_factor: 0.5,
            plateau_patience: 2,
            grad_clip_norm: 0.4,
            condition_dropout: 0.3,
            history_mask_prob: 0.15,
            validation_fraction: 0.2,
            min_future_valid_steps: 10,
            max_other_agents: 16,
            max_road_segments: 64,
            max_targets_per_window: 4,
            lr_schedule: "cosine".into(),
            classification_weight: 1.0,
            sibling_contrast_weight: 0.0,
            backend: "flex".into(),
            data_parallel_chunks: 1,
            counterfactual_cache: None,
            reaction_cache: None,
            reaction_from_epoch: None,
            init_from: None,
            lane_frame_condition: false,
            stepwise_condition: false,
        }
    }
}

/// A configuration that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// `preset` names no preset (and no explicit `model` was given).
    #[error("unknown model preset {0:?} (expected cpu-small or paper)")]
    UnknownPreset(String),
    /// A value out of range; the message says which.
    #[error("{0}")]
    Invalid(String),
    /// The TOML did not parse into a [`TrainConfig`] (syntax, types or unknown fields).
    #[error("config: {0}")]
    Parse(String),
}

impl TrainConfig {
    /// Parses a TOML configuration (absent fields take their defaults) and validates it.
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        let config: Self = toml::from_str(text).map_err(|e| ConfigError::Parse(e.to_string()))?;
        config.validate()?;
        Ok(config)
    }

    /// Checks the preset, positive `batch_size` and `epochs`, `validation_fraction` in
    /// `[0, 1)`, a known `lr_schedule`, finite, non-negative loss weights and a
    /// `reaction_cache` wherever `reaction_from_epoch` is set.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.model_config()?;
        if self.batch_size == 0 || self.epochs == 0 || self.data_parallel_chunks == 0 {
            return Err(ConfigError::Invalid(
                "batch_size, epochs and data_parallel_chunks must be positive".into(),
            ));
        }
        if !(0.0..1.0).contains(&self.validation_fraction) {
            return Err(ConfigError::Invalid(
                "validation_fraction must be in [0, 1)".into(),
            ));
        }
        if !["plateau", "cosine"].contains(&self.lr_schedule.as_str()) {
            return Err(ConfigError::Invalid(format!(
                "lr_schedule {:?}: expected \"plateau\" or \"cosine\"",
                self.lr_schedule
            )));
        }
        if !self.sibling_contrast_weight.is_finite() || self.sibling_contrast_weight < 0.0 {
            return Err(ConfigError::Invalid(
                "sibling_contrast_weight must be finite and >= 0".into(),
            ));
        }
        if !self.classification_weight.is_finite() || self.classification_weight < 0.0 {
            return Err(ConfigError::Invalid(
                "classification_weight must be finite and >= 0".into(),
            ));
        }
        if self.reaction_from_epoch.is_some() && self.reaction_cache.is_none() {
            return Err(ConfigError::Invalid(
                "reaction_from_epoch needs a reaction_cache".into(),
            ));
        }
        Ok(())
    }

    /// The model widths: `model` if given, else the `preset`; with `lane_frame_condition`,
    /// the future encoder's lane frame on, with `stepwise_condition` the step-wise decoder
    /// conditioning.
    pub fn model_config(&self) -> Result<MultipathConfig, ConfigError> {
        let mut config = match &self.model {
            Some(m) => m.clone(),
            None => MultipathConfig::preset(&self.preset)
                .ok_or_else(|| ConfigError::UnknownPreset(self.preset.clone()))?,
        };
        config.lane_frame_condition |= self.lane_frame_condition;
        config.stepwise_condition |= self.stepwise_condition;
        if config.stepwise_condition
            && !config
                .future_steps
                .is_multiple_of(scbg_model::CONDITION_STRIDE)
        {
            return Err(ConfigError::Invalid(format!(
                "stepwise_condition needs future_steps divisible by {} (got {})",
                scbg_model::CONDITION_STRIDE,
                config.future_steps
            )));
        }
        Ok(config)
    }

    /// The feature extraction settings (agent and road caps, lane paths for the lane frame;
    /// other settings default).
    pub fn feature_config(&self) -> FeatureConfig {
        FeatureConfig {
            max_other_agents: self.max_other_agents,
            max_road_segments: self.max_road_segments,
            // Lane paths only for a model that reads them.
            lane_path: self.model_config().is_ok_and(|m| m.lane_frame_condition),
            ..Default::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The step-wise conditioning is a top-level switch like the lane frame: off by default,
    /// on in the model when the TOML says so, refused for a horizon the 0.5 s blocks do not
    /// divide.
    #[test]
    fn stepwise_condition_switches_the_model_and_checks_the_horizon() {
        assert!(
            !TrainConfig::default()
                .model_config()
                .unwrap()
                .stepwise_condition
        );
        let on = TrainConfig::from_toml("stepwise_condition = true\nlane_frame_condition = true")
            .unwrap();
        let model = on.model_config().unwrap();
        assert!(model.stepwise_condition && model.lane_frame_condition);
        let odd = TrainConfig {
            model: Some(MultipathConfig {
                future_steps: 42,
                ..MultipathConfig::cpu_small()
            }),
            stepwise_condition: true,
            ..Default::default()
        };
        let err = odd.validate().unwrap_err().to_string();
        assert!(err.contains("future_steps"), "{err}");
        // Without the option the same horizon is fine.
        assert!(
            TrainConfig {
                stepwise_condition: false,
                ..odd
            }
            .validate()
            .is_ok()
        );
    }

    /// The speed contrast's weight reads under its name and under the one older checkpoints
    /// carry; a negative weight is refused.
    #[test]
    fn sibling_contrast_weight_reads_both_names_and_is_checked() {
        for text in [
            "sibling_contrast_weight = 4.0",
            "reaction_contrast_weight = 4.0",
        ] {
            assert_eq!(
                TrainConfig::from_toml(text)
                    .unwrap()
                    .sibling_contrast_weight,
                4.0
            );
        }
        let err = TrainConfig::from_toml("sibling_contrast_weight = -1.0")
            .unwrap_err()
            .to_string();
        assert!(err.contains("sibling_contrast_weight"), "{err}");
    }
}
