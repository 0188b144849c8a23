//! The demo: the pipeline end to end, with a report.
//!
//! Synthetic data (or the user's WOMD files) → prepared cache → Multipath++ predictor, marginal
//! and conditional, cpu-small → evaluation beside the baselines → courtesy labels of every pair
//! role (labelled once: the label table, the generator's training set and the held-out
//! evaluation set all come from this one pass), with the ground-truth check on synthetic data →
//! the three generator variants and the range predictor → the paper's evaluation (Table II,
//! Figs. 4–5) → report.md and report.json.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use scbg_courtesy::label::LabelOptions;
use scbg_features::cache::PreparedDataset;
use scbg_generator::Variant;
use scbg_train::data::{Split, split_of};

use crate::config::PipelineConfig;
use crate::generator::{examples_of, load_predictors, load_scbg, train_variant};
use crate::labels::{label_scenes, write_label_outputs};
use crate::predictor::{ModeSelection, SplitSelection};
use crate::prepare::PrepareOptions;
use crate::scbg_eval::ScbgEval;
use crate::synth::{GROUND_TRUTH_FILE, SynthOptions};
use crate::{Progress, predictor};

mod checks;
mod closed_loop_stage;
mod predictor_stage;
mod report;
mod text;
pub use checks::{Check, acceptance_checks, seed_mean_std};
pub use report::{DataReport, DemoReport, LabelsReport, STAGE_NAMES, ScbgEvalSummary};

/// One demo run: where it writes, its data and seed, and the pipeline settings.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoOptions {
    /// Output folder (data, cache, checkpoints, figures, report.md, report.json).
    pub out: PathBuf,
    /// WOMD files (globs, folders or paths) instead of generated data.
    pub data: Vec<String>,
    /// Seed of everything (the generator stage's seeds are `seed`, `seed + 1`, …).
    pub seed: u64,
    /// The pipeline settings.
    pub config: PipelineConfig,
    /// The labelling options of `config` (checked).
    pub labels: LabelOptions,
}

impl DemoOptions {
    /// A run of `config` writing to `out`; the settings are checked before any work.
    pub fn new(
        out: PathBuf,
        data: Vec<String>,
        seed: u64,
        config: PipelineConfig,
    ) -> anyhow::Result<Self> {
        let labels = config.label_options()?;
        Ok(Self {
            out,
            data,
            seed,
            config,
            labels,
        })
    }
}

/// Closed-loop scenes on which the demo scores the generator's WOSAC realism (at most): scbg
/// at three quantiles and with the knob drawn from its prior, and three baselines, 32
/// rollouts each (~0.3 s a scene on 2 cores with shared first plans). The per-scene
/// difference between scbg and IDM-only has a standard deviation of ~0.14, so 10 scenes could
/// not tell them apart (± 0.04); on 60 (± 0.014–0.02) scbg is above both baselines in each of
/// four data seeds, though in seed 0 within one standard error of IDM-only around the
/// quantiles (BENCHMARKS.md *WOSAC on 60 of the demo's scenes*). The demo's closed-loop stage
/// took 30 s with 60, against 17 s with 10 before the shared plans. `scbg eval sim
/// --wosac-scenes 400` scores every held-out scene.
pub const DEMO_WOSAC_SCENES: usize = 60;

/// The same for sample and rank, whose rollouts cost about twice the generator's: at three
/// quantiles, no prior. 10 scenes (± 0.04) could not tell it from IDM-only; 60 cost 40–45 s
/// more on a 2-vCPU Intel Xeon, where the flushed subnormals had saved 130 s of the predictor's
/// training (BENCHMARKS.md *Subnormal numbers*).
pub const DEMO_RANKED_WOSAC_SCENES: usize = 60;

/// Runs the demo and writes `report.md`, `report.json` and the figures in `options.out`.
pub fn run_demo(options: &DemoOptions, progress: &dyn Progress) -> anyhow::Result<DemoReport> {
    let started = Instant::now();
    let out = &options.out;
    std::fs::create_dir_all(out.join("figures"))
        .with_context(|| format!("creating {}", out.display()))?;
    let total = 9;
    // When each stage began (for `stage_seconds`).
    let marks: std::cell::RefCell<Vec<(usize, Instant)>> = Default::default();
    let stage = |n: usize, what: &str| {
        marks.borrow_mut().push((n, Instant::now()));
        progress.note(&format!("\n[{n}/{total}] {what}"));
    };
    let inputs: Vec<String> = if options.data.is_empty() {
        stage(
            1,
            &format!(
                "generating {} synthetic interactive scenarios",
                options.config.data.scenarios
            ),
        );
        let synth_dir = out.join("synth");
        crate::synth::write_synthetic(
            &SynthOptions {
                scenarios: options.config.data.scenarios,
                seed: options.seed,
                out: synth_dir.clone(),
                families: options.config.data.families.clone(),
                held_out: options.config.data.held_out_families.clone(),
                scenarios_per_file: 250,
                counterfactuals: options.config.data.counterfactuals,
            },
            progress,
        )?;
        vec![synth_dir.display().to_string()]
    } else {
        stage(1, "using your data");
        options.data.clone()
    };

    stage(2, "preparing the feature cache");
    let cache = out.join("cache");
    let manifest = crate::prepare::prepare(
        &PrepareOptions {
            files_per_shard: 4,
            ..PrepareOptions::new(inputs.clone(), cache.clone())
        },
        progress,
    )?;

    stage(
        3,
        &format!(
            "training the Multipath++ predictor (cpu-small, {} epochs)",
            options.config.predictor.epochs
        ),
    );
    let trained = predictor_stage::train_predictors(options, &cache, progress)?;

    stage(
        4,
        "evaluating the predictor (held-out scenarios) beside the baselines",
    );
    let eval = predictor::evaluate_predictor(
        &trained.dir,
        &cache,
        ModeSelection::Both,
        SplitSelection::Validation,
        &predictor::thresholds(false),
    )?;

    stage(
        5,
        &format!(
            "auto-labelling the courtesy ψ of every interacting pair (logged + {} sampled futures of B)",
            options.labels.labelled_samples()
        ),
    );
    let predictors = load_predictors(&trained.dir)?;
    let dataset = PreparedDataset::open(&cache)?;
    let labelled = label_scenes(
        &predictors.plain,
        &predictors.ckpt,
        &predictors.plain_device,
        &dataset,
        0..dataset.len(),
        &|_| true,
        options.labels,
        options.seed,
        progress,
    )?;
    let truth = inputs
        .iter()
        .map(|i| Path::new(i).join(GROUND_TRUTH_FILE))
        .find(|p| p.is_file())
        .map(|p| crate::synth::read_ground_truth(&p))
        .transpose()?;
    let labels_dir = out.join("labels");
    let (rows, label_summary) = write_label_outputs(
        &labels_dir,
        &dataset,
        &labelled,
        options.labels,
        truth.as_deref(),
        1,
    )?;
    progress.note(&label_summary.to_text());
    for figure in ["psi_histogram.png", "psi_fidelity.png"] {
        let from = labels_dir.join(figure);
        if from.is_file() {
            std::fs::copy(&from, out.join("figures").join(figure))?;
        }
    }
    let vf = predictors.ckpt.train_config.validation_fraction;
    let (train, validation): (Vec<_>, Vec<_>) = labelled
        .into_iter()
        .partition(|s| split_of(&s.scenario_id, vf) == Split::Train);
    let mut examples = examples_of(&predictors.plain, &predictors.plain_device, train);
    let mut held_out = examples_of(&predictors.plain, &predictors.plain_device, validation);
    // The modes' courtesy, once for every variant and seed (training and each evaluation
    // would measure them again).
    for set in [&mut examples, &mut held_out] {
        scbg_generator::fill_mode_courtesy(
            &predictors.plain,
            set,
            options.labels.reward,
            &scbg_generator::DEFAULT_MODE_SLOWDOWNS,
            &predictors.plain_device,
        );
    }

    stage(
        6,
        &format!(
            "training the SCBG generator variants (baseline, aug, full; {} epochs each) and the range predictor",
            options.config.generator.epochs
        ),
    );
    let seeds: Vec<u64> = (0..options.config.generator.seeds.max(1) as u64)
        .map(|k| options.seed + k)
        .collect();
    let mut generator_seconds = BTreeMap::new();
    let stage_started = Instant::now();
    let mut seed_dirs: Vec<Vec<PathBuf>> = Vec::new();
    let mut skipped: Option<String> = None;
    if examples.is_empty() {
        let why = "no interacting pair in the training split: the generators are not trained";
        progress.note(why);
        skipped = Some(why.into());
    } else {
        // One thread per seed: the stage is mostly single-threaded, and each seed's models
        // are seeded apart from the others (train_variant).
        let fp_mode = crate::fp::Mode::current();
        let trained: Vec<anyhow::Result<Vec<(PathBuf, String, f64)>>> =
            std::thread::scope(|scope| {
                let handles: Vec<_> = seeds
                    .iter()
                    .enumerate()
                    .map(|(k, &seed)| {
                        let (predictors, examples) = (&predictors, &examples);
                        scope.spawn(move || -> anyhow::Result<Vec<(PathBuf, String, f64)>> {
                            fp_mode.apply();
                            let mut done = Vec::new();
                            for variant in Variant::ALL {
                                let dir = out.join(generator_dir_name(variant, k));
                                let saved = train_variant(
                                    predictors,
                                    examples,
                                    &options
                                        .config
                                        .variant_settings(variant, options.labels, seed),
                                    &dir,
                                    progress,
                                )?;
                                done.push((dir, variant.name().to_string(), saved.seconds));
                            }
                            Ok(done)
                        })
                    })
                    .collect();
                handles
                    .into_iter()
                    .map(|h| h.join().expect("a generator thread panicked"))
                    .collect()
            });
        for (k, seed_result) in trained.into_iter().enumerate() {
            let done = seed_result?;
            if k == 0 {
                for (_, name, seconds) in &done {
                    generator_seconds.insert(name.clone(), *seconds);
                }
            }
            seed_dirs.push(done.into_iter().map(|(dir, _, _)| dir).collect());
        }
    }
    let generator_stage_seconds = stage_started.elapsed().as_secs_f64();
    drop(predictors);

    stage(
        7,
        "evaluating the generators on held-out pairs (CourtesyMSE, TrajADE, correlation; Figs. 4–5)",
    );
    let evaluate_seed = |k: usize, dirs: &[PathBuf]| -> ScbgEval {
        dirs.iter()
            .map(|d| load_scbg(d, None))
            .collect::<anyhow::Result<Vec<_>>>()
            .and_then(|loaded| {
                crate::scbg_eval::evaluate_examples(
                    &loaded,
                    &held_out,
                    &cache,
                    (k == 0).then(|| out.join("figures")).as_deref(),
                    truth.as_deref(),
                    progress,
                )
            })
            .unwrap_or_else(|err| {
                let why = format!("the generators were not evaluated: {err:#}");
                progress.note(&why);
                ScbgEval::not_evaluated(why)
            })
    };
    let generators_trained = skipped.is_none();
    let per_seed: Vec<ScbgEval> = match skipped {
        Some(why) => vec![ScbgEval::not_evaluated(why)],
        None => std::thread::scope(|scope| {
            let fp_mode = crate::fp::Mode::current();
            let handles: Vec<_> = seed_dirs
                .iter()
                .enumerate()
                .map(|(k, dirs)| {
                    let evaluate_seed = &evaluate_seed;
                    scope.spawn(move || {
                        fp_mode.apply();
                        evaluate_seed(k, dirs)
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().expect("an evaluation thread panicked"))
                .collect()
        }),
    };
    let scbg = per_seed[0].clone();
    let (variants_mean, variants_std) = seed_mean_std(
        &per_seed
            .iter()
            .map(ScbgEval::variants_json)
            .collect::<Vec<_>>(),
    );
    let (truth_mean, truth_std) = seed_mean_std(
        &per_seed
            .iter()
            .map(ScbgEval::truth_control_json)
            .collect::<Vec<_>>(),
    );

    let (closed_loop, closed_loop_ranked) = if options.config.closed_loop.scenes == 0
        || !generators_trained
    {
        (None, None)
    } else {
        stage(
            8,
            "closed loop: the full generator, then sample and rank, drive B among reactive agents on held-out scenes (realised courtesy, WOSAC realism)",
        );
        closed_loop_stage::closed_loop_stage(options, &inputs, truth.as_deref(), vf, progress)
    };

    stage(9, "writing figures and the report");
    let first_file = crate::inputs::expand(&inputs)?
        .into_iter()
        .next()
        .context("no input file")?;
    scbg::data::render(&first_file, 0, 800, &out.join("figures/scene.png"))?;

    // Fidelity on the held-out split (the scenes the predictor never trained on).
    let held_out_rows: Vec<_> = rows
        .iter()
        .filter(|r| split_of(&r.scenario_id, vf) == Split::Validation)
        .cloned()
        .collect();
    let fidelity = truth.as_deref().and_then(|t| {
        crate::fidelity::fidelity(&held_out_rows, t, options.labels.labelled_samples())
    });
    let check_list = acceptance_checks(
        &variants_mean,
        &truth_mean,
        fidelity.as_ref(),
        closed_loop.as_ref(),
        closed_loop_ranked.as_ref(),
    );
    let report = DemoReport {
        data: DataReport {
            inputs,
            scenarios: manifest.total.scenarios,
            windows: manifest.total.windows,
            pairs: manifest.total.pairs,
            skipped: manifest.total.skipped.clone(),
            held_out_families: if options.data.is_empty() {
                options.config.data.held_out_families.clone()
            } else {
                Vec::new()
            },
        },
        predictor: eval,
        labels: LabelsReport {
            futures: rows.len(),
            logged: label_summary.pairs_roles,
            psi_within_pair_std: label_summary.psi_within_pair_std,
            predictors: label_summary.predictors,
        },
        spearman_latent: label_summary
            .spearman_latent
            .iter()
            .map(|(f, r)| (f.clone(), r.rho))
            .collect(),
        fidelity,
        fidelity_all_scenes: label_summary.fidelity.clone(),
        fidelity_stage1: trained.fidelity_stage1,
        generator_seeds: seeds.clone(),
        variants: variants_mean,
        variants_seed_std: variants_std,
        variants_per_seed: per_seed.iter().map(ScbgEval::variants_json).collect(),
        truth_control: truth_mean,
        truth_control_seed_std: truth_std,
        truth_control_world: scbg.truth_control_world.clone(),
        truth_control_selection: scbg.truth_control_selection.clone(),
        truth_control_candidates: scbg.truth_control_candidates.clone(),
        scbg_eval: ScbgEvalSummary {
            examples: scbg.examples,
            high_threshold_psi: scbg.high_threshold_psi,
            psi_min: scbg.psi_range.0,
            psi_max: scbg.psi_range.1,
            figures: scbg.figures.clone(),
        },
        closed_loop,
        closed_loop_ranked,
        checks: check_list.iter().map(|c| (c.key, c.passed)).collect(),
        generator_seconds,
        generator_stage_seconds,
        stage_seconds: report::stage_seconds(&marks.borrow(), Instant::now()),
        seconds: started.elapsed().as_secs_f64(),
        check_list,
        scbg,
        label_summary,
    };
    scbg_base::atomic::write(
        out.join("report.json"),
        &serde_json::to_string_pretty(&report)?,
    )?;
    scbg_base::atomic::write(out.join("report.md"), report.to_markdown())?;
    progress.note(&report.summary_text(&out.join("report.md")));
    Ok(report)
}

/// The directory of a generator variant of seed number `k` (the first seed keeps the plain
/// `generator_<variant>` name).
fn generator_dir_name(variant: Variant, k: usize) -> String {
    if k == 0 {
        format!("generator_{}", variant.name())
    } else {
        format!("generator_{}_seed{k}", variant.name())
    }
}
