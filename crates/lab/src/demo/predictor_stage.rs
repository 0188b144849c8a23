//! The demo's predictor stage: the Multipath++ predictor's one training run, with the
//! reaction siblings made from its own checkpoint partway.

use std::path::{Path, PathBuf};

use anyhow::Context;

use super::DemoOptions;
use crate::prepare::PrepareOptions;
use crate::synth::GROUND_TRUTH_FILE;
use crate::{Progress, predictor};

/// What the predictor stage leaves for the rest of the demo.
pub(super) struct TrainedPredictors {
    /// The predictor: the generators' J_φ, the labeller and the one evaluated.
    pub dir: PathBuf,
    /// With reaction siblings: the held-out fidelity of the checkpoint they were made with.
    pub fidelity_stage1: Option<crate::fidelity::Fidelity>,
}

/// Trains the predictor on `cache` (and the counterfactual and reaction siblings the options
/// ask for) into `out/predictor`, writing `out/predictor.toml`.
pub(super) fn train_predictors(
    options: &DemoOptions,
    cache: &Path,
    progress: &dyn Progress,
) -> anyhow::Result<TrainedPredictors> {
    let out = &options.out;
    let counterfactual_cache = if options.data.is_empty() && options.config.data.counterfactuals > 0
    {
        let dir = out.join("cache_counterfactual");
        crate::prepare::prepare(
            &PrepareOptions {
                files_per_shard: 4,
                ..PrepareOptions::new(
                    vec![
                        out.join("synth")
                            .join(crate::synth::COUNTERFACTUAL_DIR)
                            .display()
                            .to_string(),
                    ],
                    dir.clone(),
                )
            },
            progress,
        )?;
        Some(dir)
    } else {
        None
    };
    let reacting = options.config.predictor.reaction_siblings > 0 && options.data.is_empty();
    // With reaction siblings: they join for the last `reaction_epochs` epochs, made from the
    // checkpoint just before.
    let reaction_from = options
        .config
        .predictor
        .epochs
        .saturating_sub(options.config.predictor.reaction_epochs)
        .max(1);
    let reaction_cache = out.join("cache_reaction");
    let config = scbg_train::TrainConfig {
        epochs: options.config.predictor.epochs,
        seed: options.seed,
        counterfactual_cache,
        lane_frame_condition: options.config.predictor.lane_frame,
        stepwise_condition: options.config.predictor.stepwise,
        data_parallel_chunks: options.config.predictor.data_parallel_chunks.max(1),
        batch_size: options.config.predictor.batch_size.max(1),
        learning_rate: options.config.predictor.learning_rate,
        reaction_cache: reacting.then(|| reaction_cache.clone()),
        reaction_from_epoch: reacting.then_some(reaction_from),
        sibling_contrast_weight: options.config.predictor.sibling_contrast,
        ..Default::default()
    };
    let predictor_dir = out.join("predictor");
    scbg_base::atomic::write(
        out.join("predictor.toml"),
        &predictor::train_config_toml(&config)?,
    )?;
    let fidelity_stage1 = if reacting && reaction_from < options.config.predictor.epochs {
        // Another run's tables and siblings in this folder belong to another predictor.
        for stale in [
            out.join("labels_stage1"),
            out.join("synth").join("reaction"),
            reaction_cache.clone(),
        ] {
            if stale.is_dir() {
                std::fs::remove_dir_all(&stale)
                    .with_context(|| format!("removing {}", stale.display()))?;
            }
        }
        predictor::train_predictor_until(
            cache,
            &predictor_dir,
            &config,
            false,
            Some(reaction_from),
            progress,
        )?;
        let fidelity =
            make_reaction_siblings(options, cache, &predictor_dir, &reaction_cache, progress)?;
        progress.note(&format!(
            "training on with them (epochs {reaction_from}–{})",
            options.config.predictor.epochs - 1
        ));
        predictor::train_predictor(cache, &predictor_dir, &config, true, progress)?;
        fidelity
    } else {
        predictor::train_predictor(cache, &predictor_dir, &config, false, progress)?;
        None
    };
    Ok(TrainedPredictors {
        dir: predictor_dir,
        fidelity_stage1,
    })
}

/// The demo's reaction siblings ([`crate::config::PredictorConfig::reaction_siblings`]): labels the cache with
/// the predictor's checkpoint in `predictor` (the epoch they join at), writing
/// `labels_stage1/` and the siblings to `synth/reaction/`, and prepares them as
/// `reaction_cache`. Returns that checkpoint's held-out fidelity.
fn make_reaction_siblings(
    options: &DemoOptions,
    cache: &Path,
    predictor: &Path,
    reaction_cache: &Path,
    progress: &dyn Progress,
) -> anyhow::Result<Option<crate::fidelity::Fidelity>> {
    let root = &options.out;
    let siblings = root.join("synth").join("reaction");
    progress.note(&format!(
        "replaying {} sampled futures of B per scene in the synthetic world (reaction siblings)",
        options.config.predictor.reaction_siblings
    ));
    let (_, summary) = crate::labels::label_cache(
        &crate::labels::LabelRun {
            model: predictor.to_path_buf(),
            ensemble: Vec::new(),
            data: cache.to_path_buf(),
            out: root.join("labels_stage1"),
            options: crate::choices::LabelOptions {
                lane_move_steps: 0,
                keep_baseline: false,
                ..options.labels
            },
            seed: options.seed,
            ground_truth: Some(root.join("synth").join(GROUND_TRUTH_FILE)),
            shard_index: 0,
            num_shards: 1,
            reaction_siblings: Some((siblings.clone(), options.config.predictor.reaction_siblings)),
        },
        progress,
    )?;
    crate::prepare::prepare(
        &PrepareOptions {
            files_per_shard: 4,
            ..PrepareOptions::new(
                vec![siblings.display().to_string()],
                reaction_cache.to_path_buf(),
            )
        },
        progress,
    )?;
    Ok(summary.fidelity_held_out)
}
