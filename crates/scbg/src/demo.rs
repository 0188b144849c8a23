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
use scbg_generator::{Threshold, Variant};
use scbg_train::data::{Split, split_of};
use serde::Serialize;

use crate::data::PrepareOptions;
use crate::generator::{VariantSettings, examples_of, load_predictors, load_scbg, train_variant};
use crate::labels::{LabelSummary, label_scenes, write_label_outputs};
use crate::predictor::{ModeSelection, PredictorEval, SplitSelection};
use crate::scbg_eval::ScbgEval;
use crate::synth::{GROUND_TRUTH_FILE, SynthOptions};
use crate::{Progress, predictor};

/// The demo's settings (the `scbg demo` flags).
#[derive(Debug, Clone, PartialEq)]
pub struct DemoOptions {
    /// Output folder (data, cache, checkpoints, figures, report.md, report.json).
    pub out: PathBuf,
    /// WOMD files (globs, folders or paths) instead of generated data.
    pub data: Vec<String>,
    /// Synthetic scenarios to generate when `data` is empty.
    pub scenarios: usize,
    /// Predictor training epochs.
    pub epochs: usize,
    /// Training epochs of each generator variant.
    pub generator_epochs: usize,
    /// Weight β of the courtesy loss of the full variant.
    pub beta: f32,
    /// How courtesy is labelled (8 sampled futures per pair role by default).
    pub labels: LabelOptions,
    /// Seed of everything.
    pub seed: u64,
}

/// The report's `data` section.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DataReport {
    /// The inputs (the synthetic folder or the user's patterns).
    pub inputs: Vec<String>,
    /// Scenarios in the cache.
    pub scenarios: usize,
    /// Windows in the cache.
    pub windows: usize,
    /// Interacting pairs in the cache.
    pub pairs: usize,
    /// Skipped inputs by reason.
    pub skipped: BTreeMap<String, usize>,
}

/// The report's `labels` section.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LabelsReport {
    /// Labelled futures.
    pub futures: usize,
    /// Logged futures (pair roles).
    pub logged: usize,
    /// The part of ψ's spread that B's future decides.
    pub psi_within_pair_std: f64,
}

/// The report's `scbg_eval` section.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScbgEvalSummary {
    /// Held-out pair roles.
    pub examples: usize,
    /// |ψ_logged| above which a pair is high courtesy.
    pub high_threshold_psi: f32,
    /// Smallest training label.
    pub psi_min: f32,
    /// Largest training label.
    pub psi_max: f32,
    /// Figure files written in `figures/`.
    pub figures: Vec<String>,
}

/// One acceptance point as measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    /// Stable key in report.json's `checks`.
    pub key: &'static str,
    /// Whether it holds.
    pub passed: bool,
    /// What was compared, with the numbers.
    pub text: String,
}

/// Everything the demo measured: `report.json` (stable keys, documented in the README).
#[derive(Debug, Clone, Serialize)]
pub struct DemoReport {
    /// The data.
    pub data: DataReport,
    /// Table I.
    pub predictor: PredictorEval,
    /// The labels.
    pub labels: LabelsReport,
    /// Spearman(ψ of the logged future, latent courtesy) per family.
    pub spearman_latent: BTreeMap<String, Option<f64>>,
    /// Table II and the correlations per variant.
    pub variants: serde_json::Value,
    /// The evaluation's settings and figures.
    pub scbg_eval: ScbgEvalSummary,
    /// Acceptance checks: key → passed.
    pub checks: BTreeMap<&'static str, bool>,
    /// Training time of each generator variant, seconds.
    pub generator_seconds: BTreeMap<String, f64>,
    /// Wall time of the demo, seconds.
    pub seconds: f64,
    /// The checks with their texts (report.md).
    #[serde(skip)]
    pub check_list: Vec<Check>,
    /// The SCBG evaluation (report.md).
    #[serde(skip)]
    pub scbg: ScbgEval,
    /// The label summary (report.md).
    #[serde(skip)]
    pub label_summary: LabelSummary,
}

/// Runs the demo and writes `report.md`, `report.json` and the figures in `options.out`.
pub fn run_demo(options: &DemoOptions, progress: &dyn Progress) -> anyhow::Result<DemoReport> {
    let started = Instant::now();
    let out = &options.out;
    std::fs::create_dir_all(out.join("figures"))
        .with_context(|| format!("creating {}", out.display()))?;
    let total = 8;
    let stage = |n: usize, what: &str| progress.note(&format!("\n[{n}/{total}] {what}"));
    let inputs: Vec<String> = if options.data.is_empty() {
        stage(
            1,
            &format!(
                "generating {} synthetic interactive scenarios",
                options.scenarios
            ),
        );
        let synth_dir = out.join("synth");
        crate::synth::write_synthetic(
            &SynthOptions {
                scenarios: options.scenarios,
                seed: options.seed,
                out: synth_dir.clone(),
                families: scbg_synth::Family::ALL.to_vec(),
                scenarios_per_file: 250,
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
    let manifest = crate::data::prepare(
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
            options.epochs
        ),
    );
    let config = scbg_train::TrainConfig {
        epochs: options.epochs,
        seed: options.seed,
        ..Default::default()
    };
    let predictor_dir = out.join("predictor");
    scbg_base::atomic::write(
        out.join("predictor.toml"),
        &predictor::train_config_toml(&config)?,
    )?;
    predictor::train_predictor(&cache, &predictor_dir, &config, false, progress)?;

    stage(
        4,
        "evaluating the predictor (held-out scenarios) beside the baselines",
    );
    let eval = predictor::evaluate_predictor(
        &predictor_dir,
        &cache,
        ModeSelection::Both,
        SplitSelection::Validation,
        &predictor::thresholds(false),
    )?;

    stage(
        5,
        &format!(
            "auto-labelling the courtesy ψ of every interacting pair (logged + {} sampled futures of B)",
            options.labels.samples
        ),
    );
    let predictors = load_predictors(&predictor_dir)?;
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
    )?;
    progress.note(&label_summary.to_text());
    std::fs::copy(
        labels_dir.join("psi_histogram.png"),
        out.join("figures/psi_histogram.png"),
    )?;
    let vf = predictors.ckpt.train_config.validation_fraction;
    let (train, validation): (Vec<_>, Vec<_>) = labelled
        .into_iter()
        .partition(|s| split_of(&s.scenario_id, vf) == Split::Train);
    let examples = examples_of(&predictors.plain, &predictors.plain_device, train);
    let held_out = examples_of(&predictors.plain, &predictors.plain_device, validation);

    stage(
        6,
        &format!(
            "training the SCBG generator variants (baseline, aug, full; {} epochs each) and the range predictor",
            options.generator_epochs
        ),
    );
    let mut generator_dirs = Vec::new();
    let mut generator_seconds = BTreeMap::new();
    let mut skipped: Option<String> = None;
    if examples.is_empty() {
        let why = "no interacting pair in the training split: the generators are not trained";
        progress.note(why);
        skipped = Some(why.into());
    } else {
        for variant in Variant::ALL {
            let dir = out.join(format!("generator_{}", variant.name()));
            let saved = train_variant(
                &predictors,
                &examples,
                &VariantSettings {
                    epochs: options.generator_epochs,
                    beta: options.beta,
                    threshold: Threshold::Quantile(0.8),
                    seed: options.seed,
                    ..VariantSettings::new(variant, options.labels)
                },
                &dir,
                progress,
            )?;
            generator_seconds.insert(variant.name().to_string(), saved.seconds);
            generator_dirs.push(dir);
        }
    }
    drop(predictors);

    stage(
        7,
        "evaluating the generators on held-out pairs (CourtesyMSE, TrajADE, correlation; Figs. 4–5)",
    );
    let scbg = match skipped {
        Some(why) => ScbgEval::not_evaluated(why),
        None => generator_dirs
            .iter()
            .map(|d| load_scbg(d, None))
            .collect::<anyhow::Result<Vec<_>>>()
            .and_then(|loaded| {
                crate::scbg_eval::evaluate_examples(
                    &loaded,
                    &held_out,
                    &cache,
                    Some(&out.join("figures")),
                    progress,
                )
            })
            .unwrap_or_else(|err| {
                let why = format!("the generators were not evaluated: {err:#}");
                progress.note(&why);
                ScbgEval::not_evaluated(why)
            }),
    };

    stage(8, "writing figures and the report");
    let first_file = crate::inputs::expand(&inputs)?
        .into_iter()
        .next()
        .context("no input file")?;
    crate::data::render(&first_file, 0, 800, &out.join("figures/scene.png"))?;

    let check_list = acceptance_checks(&scbg);
    let report = DemoReport {
        data: DataReport {
            inputs,
            scenarios: manifest.total.scenarios,
            windows: manifest.total.windows,
            pairs: manifest.total.pairs,
            skipped: manifest.total.skipped.clone(),
        },
        predictor: eval,
        labels: LabelsReport {
            futures: rows.len(),
            logged: label_summary.pairs_roles,
            psi_within_pair_std: label_summary.psi_within_pair_std,
        },
        spearman_latent: label_summary
            .spearman_latent
            .iter()
            .map(|(f, r)| (f.clone(), r.rho))
            .collect(),
        variants: scbg.variants_json(),
        scbg_eval: ScbgEvalSummary {
            examples: scbg.examples,
            high_threshold_psi: scbg.high_threshold_psi,
            psi_min: scbg.psi_range.0,
            psi_max: scbg.psi_range.1,
            figures: scbg.figures.clone(),
        },
        checks: check_list.iter().map(|c| (c.key, c.passed)).collect(),
        generator_seconds,
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

impl DemoReport {
    /// report.md.
    pub fn to_markdown(&self) -> String {
        let fig5a: String = self
            .scbg
            .figures
            .iter()
            .filter(|f| f.starts_with("fig5a"))
            .map(|f| format!("![{f}](figures/{f})\n"))
            .collect();
        format!(
            "# scbg demo report\n\nData: {} scenarios, {} windows, {} interacting pairs (skipped: {:?}).\n\n\
             ## Predictor (paper Table I layout, held-out scenarios)\n\n{}\n\
             ## Courtesy labels (paper Fig. 3)\n\n{} labelled futures ({} logged); ψ std within a pair role (the part B's future decides): {:.4}.\n\n![psi](figures/psi_histogram.png)\n\n\
             Ground-truth check — Spearman(ψ of the logged future, latent courtesy of the generator):\n\n{}\n\n\
             ## SCBG generator (paper Table II layout, held-out pairs)\n\n{}\n\
             Acceptance checks (as measured):\n\n{}\n\n\
             ### Fig. 4 — input quantile → courtesy of the generated trajectory\n\n![fig4](figures/fig4_quantile_courtesy.png)\n\n\
             ### Fig. 5a — B generated at quantiles 0.1…0.9 (full variant), A's logged future in red\n\n{}\n\
             ### Fig. 5b — A's expected speed vs quantile\n\n![fig5b](figures/fig5b_quantile_speed.png)\n\n\
             ![scene](figures/scene.png)\n\nRun time: {:.0} s.\n",
            self.data.scenarios,
            self.data.windows,
            self.data.pairs,
            self.data.skipped,
            self.predictor.to_markdown(),
            self.labels.futures,
            self.labels.logged,
            self.labels.psi_within_pair_std,
            if self.label_summary.spearman_latent.is_empty() {
                "(no synthetic ground truth for this data)".to_string()
            } else {
                self.label_summary
                    .spearman_latent
                    .iter()
                    .map(|(f, r)| {
                        format!(
                            "- {f}: {} (n = {})",
                            r.rho.map_or("-".into(), |r| format!("{r:.3}")),
                            r.n
                        )
                    })
                    .collect::<Vec<_>>()
                    .join("\n")
            },
            self.scbg.to_markdown(),
            self.check_list
                .iter()
                .map(|c| format!("- [{}] {}", if c.passed { "x" } else { " " }, c.text))
                .collect::<Vec<_>>()
                .join("\n"),
            fig5a,
            self.seconds
        )
    }

    /// The one-screen summary printed at the end of a run.
    pub fn summary_text(&self, report_md: &Path) -> String {
        let mut s = format!(
            "\n=== scbg demo: done in {:.0} s ===\ndata: {} scenarios, {} pairs\n",
            self.seconds, self.data.scenarios, self.data.pairs
        );
        for (name, t) in &self.predictor.rows {
            let m = &t.by_time[2].1;
            s += &format!(
                "{name:<36} minADE@8s {:>6}  MR@8s {:>6}\n",
                m.min_ade.map_or("-".into(), |v| format!("{v:.2}")),
                m.miss_rate
                    .map_or("-".into(), |v| format!("{:.1}%", 100.0 * v))
            );
        }
        for (f, r) in &self.label_summary.spearman_latent {
            s += &format!(
                "Spearman(ψ, latent courtesy) {f:<9} {} (n = {})\n",
                r.rho.map_or("-".into(), |r| format!("{r:.3}")),
                r.n
            );
        }
        s += &self.scbg.to_markdown();
        for c in &self.check_list {
            s += &format!("[{}] {}\n", if c.passed { "ok" } else { "MISS" }, c.text);
        }
        s += &format!("report: {}", report_md.display());
        s
    }
}

/// The SCBG issue's acceptance points on the demo's held-out split, as measured.
pub fn acceptance_checks(e: &ScbgEval) -> Vec<Check> {
    let get = |name: &str| e.variants.iter().find(|(n, _)| n == name).map(|(_, v)| v);
    let mut out = Vec::new();
    if let Some(full) = get("full") {
        let mean = |m: &Option<scbg_generator::eval::MeanStd>| m.map_or(f64::NAN, |m| m.mean);
        let (range, arb) = (
            mean(&full.courtesy_mse_range),
            mean(&full.courtesy_mse_arbitrary),
        );
        out.push(Check {
            key: "range_below_arbitrary",
            passed: range < arb,
            text: format!(
                "full: CourtesyMSE(range) {range:.3e} < CourtesyMSE(arbitrary) {arb:.3e}"
            ),
        });
        let corr = full.corr_quantile.unwrap_or(f64::NAN);
        out.push(Check {
            key: "corr_quantile_at_least_0_5",
            passed: corr >= 0.5,
            text: format!("full: corr(quantile, courtesy) {corr:.3} ≥ 0.5"),
        });
        if let Some(base) = get("baseline") {
            let (fd, bd) = (mean(&full.courtesy_mse_data), mean(&base.courtesy_mse_data));
            out.push(Check {
                key: "full_courtesy_mse_data_no_worse",
                passed: fd <= bd,
                text: format!("CourtesyMSE(data): full {fd:.3e} ≤ baseline {bd:.3e}"),
            });
            let (ft, bt) = (mean(&full.traj_ade), mean(&base.traj_ade));
            out.push(Check {
                key: "full_traj_ade_no_worse",
                passed: ft <= bt,
                text: format!("TrajADE: full {ft:.3} m ≤ baseline {bt:.3} m"),
            });
        }
    }
    out
}
