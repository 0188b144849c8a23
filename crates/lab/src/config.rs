//! The pipeline's settings (`scbg demo --config FILE`, and the tables `label`, `train
//! generator`, `sim` and `eval sim` read with theirs), with their defaults in one file,
//! `docs/pipeline.toml`, which the binary embeds.

use std::path::Path;

use scbg::sim::{EgoMode, ExportFormat, LoopOptions, OthersMode};
use scbg_courtesy::label::{LabelOptions, MarginalEstimate};
use scbg_generator::{Threshold, Variant};
use serde::{Deserialize, Serialize};

use crate::InvalidRequest;
use crate::generator::VariantSettings;

/// The defaults, as the documented file says them.
const DEFAULTS_TOML: &str = include_str!("../../../docs/pipeline.toml");

/// Every setting of the pipeline (see `docs/pipeline.toml` for what each does).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PipelineConfig {
    /// The data stage.
    pub data: DataConfig,
    /// The predictor's training.
    pub predictor: PredictorConfig,
    /// How courtesy is labelled.
    pub labels: LabelsConfig,
    /// The generator stage.
    pub generator: GeneratorStageConfig,
    /// The closed-loop stage.
    pub closed_loop: ClosedLoopConfig,
}

/// `[data]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataConfig {
    /// Synthetic scenes to generate when no data is given.
    pub scenarios: usize,
    /// The families they are drawn from.
    pub families: Vec<scbg_synth::Family>,
    /// Counterfactual siblings per synthetic scene for the predictor's training.
    pub counterfactuals: usize,
    /// Families held out of training, only evaluated.
    pub held_out_families: Vec<scbg_synth::Family>,
}

/// `[predictor]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PredictorConfig {
    /// Training epochs.
    pub epochs: usize,
    /// Samples per step.
    pub batch_size: usize,
    /// Peak learning rate (cosine schedule).
    pub learning_rate: f64,
    /// Data-parallel chunks of each step.
    pub data_parallel_chunks: usize,
    /// B's future also in A's lane frame.
    pub lane_frame: bool,
    /// B's future acting step by step on A's decoder.
    pub stepwise: bool,
    /// Reaction siblings per scene (0: none).
    pub reaction_siblings: usize,
    /// The last this-many epochs train with the reaction siblings.
    pub reaction_epochs: usize,
    /// Weight of the speed contrast within each scene's siblings, counterfactual and reaction
    /// (0: none).
    pub sibling_contrast: f32,
}

/// `[labels]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LabelsConfig {
    /// Futures of B sampled per pair role.
    pub samples: usize,
    /// The estimator of E[r(Y_A) | x].
    pub marginal: MarginalEstimate,
    /// Whose reward counts: `pair` or `neighbours:RADIUS_M:WEIGHTS`.
    pub audience: String,
    /// More futures of B for the estimate of E[r(Y_A) | x].
    pub baseline_samples: usize,
    /// Label and keep those futures too.
    pub keep_baseline_samples: bool,
    /// Lane moves labelled after the sampled futures, completed within this many steps.
    pub lane_move_steps: usize,
}

/// `[generator]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeneratorStageConfig {
    /// Training epochs of each variant.
    pub epochs: usize,
    /// Seeds the demo trains side by side.
    pub seeds: usize,
    /// Examples per step.
    pub batch_size: usize,
    /// Adam's learning rate.
    pub learning_rate: f64,
    /// Weight of the sampled futures' trajectory loss.
    pub alpha: f32,
    /// Weight of the full variant's courtesy loss.
    pub beta: f32,
    /// High courtesy in the 50/50 batches.
    pub threshold: Threshold,
    /// Range-predictor optimisation steps.
    pub range_steps: usize,
}

/// `[closed_loop]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClosedLoopConfig {
    /// Held-out scenes the demo drives in closed loop (0 skips the stage).
    pub scenes: usize,
    /// How the ego moves.
    pub ego: EgoMode,
    /// How the other agents move (`None`: the command's own).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub others: Option<OthersMode>,
    /// Steps between a controlled agent's plans (`None`: its policy's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replan_every: Option<usize>,
    /// `sim`'s rollouts (`None`: 1, or 32 for the WOSAC format).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rollouts: Option<usize>,
    /// Band of quantiles `sim`'s rollouts spread over.
    pub spread: f32,
    /// What `sim` writes.
    pub format: ExportFormat,
    /// Method name of a WOSAC submission.
    pub name: String,
    /// Quantiles `eval sim` scores with WOSAC realism.
    pub wosac_quantiles: Vec<f32>,
}

impl ClosedLoopConfig {
    /// The closed-loop options, with `others` when the file leaves it out.
    pub fn loop_options(&self, others: OthersMode) -> LoopOptions {
        LoopOptions {
            ego: self.ego,
            others: self.others.unwrap_or(others),
            replan_every: self.replan_every,
        }
    }
}

impl Default for PipelineConfig {
    fn default() -> Self {
        toml::from_str(DEFAULTS_TOML).expect("docs/pipeline.toml holds every setting")
    }
}

/// Copies every key of `over` into `base`, table by table.
fn merge(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

impl PipelineConfig {
    /// The paper's setting: the defaults with the paper's predictor (no counterfactual or
    /// reaction siblings, B's whole future fused in A's frame) and labels (E[r(Y_A) | x] from
    /// the marginal mode, the M sampled futures alone).
    pub fn paper() -> Self {
        let mut c = Self::default();
        c.data.counterfactuals = 0;
        c.predictor.lane_frame = false;
        c.predictor.stepwise = false;
        c.predictor.reaction_siblings = 0;
        c.labels.marginal = MarginalEstimate::Direct;
        c.labels.baseline_samples = 0;
        c.labels.keep_baseline_samples = false;
        c.labels.lane_move_steps = 0;
        c
    }

    /// A settings file's text over the defaults: keys it leaves out keep their defaults; an
    /// unknown key or a wrong type is an error naming it.
    pub fn from_toml(text: &str) -> Result<Self, InvalidRequest> {
        let mut base: toml::Table =
            toml::from_str(DEFAULTS_TOML).expect("docs/pipeline.toml parses");
        let over: toml::Table =
            toml::from_str(text).map_err(|e| InvalidRequest(e.message().to_string()))?;
        merge(&mut base, over);
        let config: Self = toml::Value::Table(base)
            .try_into()
            .map_err(|e: toml::de::Error| InvalidRequest(e.message().to_string()))?;
        if config.data.families.is_empty() {
            return Err(InvalidRequest(
                "[data] families: at least one family is needed".into(),
            ));
        }
        config.label_options()?;
        Ok(config)
    }

    /// `paper`, the settings file at `path` over the defaults, or (`None`) the defaults.
    pub fn load(name_or_path: Option<&Path>) -> anyhow::Result<Self> {
        let Some(path) = name_or_path else {
            return Ok(Self::default());
        };
        if path == Path::new("paper") {
            return Ok(Self::paper());
        }
        let text = std::fs::read_to_string(path)
            .map_err(|e| InvalidRequest(format!("reading {}: {e}", path.display())))?;
        Ok(Self::from_toml(&text)
            .map_err(|e| InvalidRequest(format!("{}: {}", path.display(), e.0)))?)
    }

    /// How a generator variant trains under these settings, seeded with `seed`.
    pub fn variant_settings(
        &self,
        variant: Variant,
        labels: LabelOptions,
        seed: u64,
    ) -> VariantSettings {
        let g = &self.generator;
        VariantSettings {
            epochs: g.epochs,
            batch_size: g.batch_size,
            alpha: g.alpha,
            beta: g.beta,
            threshold: g.threshold,
            learning_rate: g.learning_rate,
            range_steps: g.range_steps,
            seed,
            ..VariantSettings::new(variant, labels)
        }
    }

    /// The labelling options these settings give, with A's average speed as the reward.
    pub fn label_options(&self) -> Result<LabelOptions, InvalidRequest> {
        self.label_options_with(scbg_courtesy::Reward::AverageSpeed)
    }

    /// The labelling options these settings give with `reward`.
    pub fn label_options_with(
        &self,
        reward: scbg_courtesy::Reward,
    ) -> Result<LabelOptions, InvalidRequest> {
        let l = &self.labels;
        let audience = crate::labels::parse_audience(&l.audience)
            .map_err(|e| InvalidRequest(format!("labels.audience: {e}")))?;
        Ok(LabelOptions {
            baseline_samples: l.baseline_samples,
            keep_baseline: l.keep_baseline_samples,
            lane_move_steps: l.lane_move_steps,
            audience,
            ..crate::labels::label_options(l.samples, reward, l.marginal)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_documented_defaults_are_complete_and_are_the_demos() {
        let c = PipelineConfig::default();
        assert_eq!(c.data.scenarios, 1500);
        assert_eq!(c.data.families, scbg_synth::Family::DEFAULT);
        assert_eq!(c.predictor.epochs, 34);
        assert_eq!(c.generator.seeds, 3);
        assert_eq!(c.closed_loop.scenes, 60);
        // The generator's training is `VariantSettings::new`'s, but for the demo's epochs.
        let labels = c.label_options().unwrap();
        assert_eq!(
            c.variant_settings(Variant::Full, labels, 4),
            VariantSettings {
                epochs: 6,
                seed: 4,
                ..VariantSettings::new(Variant::Full, labels)
            }
        );
        // What `scbg label` uses by default is what the demo uses.
        let labels = c.label_options().unwrap();
        assert_eq!(
            labels,
            crate::labels::default_label_options(8, scbg_courtesy::Reward::AverageSpeed)
        );
        // Every key of the file is a setting, and every setting is in the file.
        assert_eq!(
            toml::to_string(&c)
                .unwrap()
                .lines()
                .filter(|l| l.contains('='))
                .count(),
            DEFAULTS_TOML
                .lines()
                .filter(|l| !l.trim_start().starts_with('#') && l.contains('='))
                .count()
        );
    }

    #[test]
    fn a_file_changes_only_what_it_names() {
        let c = PipelineConfig::from_toml("[predictor]\nepochs = 2\n[closed_loop]\nscenes = 0\n")
            .unwrap();
        assert_eq!(c.predictor.epochs, 2);
        assert_eq!(c.closed_loop.scenes, 0);
        assert_eq!(
            c.predictor.batch_size,
            PipelineConfig::default().predictor.batch_size
        );
        assert!(c.predictor.stepwise);
        let bad = PipelineConfig::from_toml("[predictor]\nepoch = 2\n").unwrap_err();
        assert!(bad.0.contains("epoch"), "{bad}");
        let bad = PipelineConfig::from_toml("[labels]\naudience = \"crowd\"\n").unwrap_err();
        assert!(bad.0.contains("crowd"), "{bad}");
        assert!(PipelineConfig::from_toml("[data]\nscenarios = \"many\"\n").is_err());
        let none = PipelineConfig::from_toml("[data]\nfamilies = []\n").unwrap_err();
        assert!(none.0.contains("[data] families"), "{none}");
        let transfer = include_str!("../../../docs/transfer.toml");
        let t = PipelineConfig::from_toml(transfer).unwrap();
        assert!(t.data.families.contains(&scbg_synth::Family::Leftturn));
    }

    #[test]
    fn paper_is_the_papers_predictor_and_labels() {
        let p = PipelineConfig::paper();
        assert!(!p.predictor.stepwise && !p.predictor.lane_frame);
        assert_eq!(
            (p.data.counterfactuals, p.predictor.reaction_siblings),
            (0, 0)
        );
        let labels = p.label_options().unwrap();
        assert_eq!(labels.marginal, MarginalEstimate::Direct);
        assert_eq!((labels.baseline_samples, labels.lane_move_steps), (0, 0));
        assert_eq!(p.generator, PipelineConfig::default().generator);
    }
}
