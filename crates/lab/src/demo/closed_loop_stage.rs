//! The demo's closed-loop stage: the full generator of the first seed, then sample and rank,
//! drive B among reactive agents on held-out scenes.

use std::path::Path;

use scbg_generator::Variant;

use super::{DEMO_RANKED_WOSAC_SCENES, DEMO_WOSAC_SCENES, DemoOptions, generator_dir_name};
use crate::Progress;
use crate::generator::load_scbg;
use crate::sim_eval::SimEval;

/// Runs both closed-loop evaluations on up to `options.config.closed_loop.scenes` held-out scenes of
/// `inputs`, writing their figures; a failure is noted and leaves its result `None`.
pub(super) fn closed_loop_stage(
    options: &DemoOptions,
    inputs: &[String],
    truth: Option<&[crate::synth::GroundTruth]>,
    validation_fraction: f64,
    progress: &dyn Progress,
) -> (Option<SimEval>, Option<SimEval>) {
    let out: &Path = &options.out;
    // The full variant of the first seed and the held-out scenes, once for both policies.
    let loaded = (|| -> anyhow::Result<_> {
        let model = load_scbg(&out.join(generator_dir_name(Variant::Full, 0)), None)?;
        let (scenes, skipped) = crate::sim_eval::load_scenes(
            inputs,
            truth,
            crate::predictor::SplitSelection::Validation,
            validation_fraction,
            options.config.closed_loop.scenes,
        )?;
        Ok((model, scenes, skipped))
    })();
    match loaded {
        Err(err) => {
            progress.note(&format!("the closed-loop stage failed: {err:#}"));
            (None, None)
        }
        Ok((mut model, scenes, skipped)) => {
            let mut run = |policy: crate::choices::Policy| {
                model.set_policy(policy);
                let eval_options = crate::sim_eval::SimEvalOptions {
                    scenes: options.config.closed_loop.scenes,
                    wosac_scenes: options.config.closed_loop.scenes.min(match policy {
                        crate::choices::Policy::Generator => DEMO_WOSAC_SCENES,
                        crate::choices::Policy::Ranked => DEMO_RANKED_WOSAC_SCENES,
                    }),
                    wosac_prior: policy == crate::choices::Policy::Generator,
                    ..crate::sim_eval::SimEvalOptions::of_policy(policy)
                };
                let figures = match policy {
                    crate::choices::Policy::Generator => out.join("figures"),
                    crate::choices::Policy::Ranked => out.join("figures/closed_loop_ranked"),
                };
                let result = crate::sim_eval::evaluate_sim(&model, &scenes, &eval_options)
                    .and_then(|mut eval| {
                        eval.add_skipped(skipped.clone());
                        crate::sim_eval::write_figures(&eval, &figures)?;
                        Ok(eval)
                    });
                match result {
                    Ok(eval) => {
                        progress.note(&format!(
                            "closed loop ({}): {} scenes in {:.0} s; Spearman(quantile, realised courtesy) {}{}",
                            eval.policy,
                            eval.curve.scenes,
                            eval.seconds,
                            eval.curve
                                .spearman_quantile_realised_courtesy
                                .get("all")
                                .copied()
                                .flatten()
                                .map_or("-".into(), |r| format!("{r:.3}")),
                            if eval.skipped.is_empty() {
                                String::new()
                            } else {
                                format!("; {}", eval.skipped_line())
                            }
                        ));
                        Some(eval)
                    }
                    Err(err) => {
                        progress.note(&format!(
                            "the closed-loop stage ({}) failed: {err:#}",
                            policy.name()
                        ));
                        None
                    }
                }
            };
            (
                run(crate::choices::Policy::Generator),
                run(crate::choices::Policy::Ranked),
            )
        }
    }
}
