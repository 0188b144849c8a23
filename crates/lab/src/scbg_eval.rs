//! The SCBG evaluation (paper Table II, the quantile → courtesy correlation, Figs. 4–5) of one
//! or more generator variants sharing one predictor, as a report that serialises to the report
//! JSON.

use std::path::{Path, PathBuf};

use anyhow::Context;
use scbg_courtesy::label::LabelOptions;
use scbg_generator::Example;
use scbg_generator::eval::{EvalOptions, MeanStd, VariantEval};
use scbg_train::data::Split;
use serde::Serialize;
use serde::ser::SerializeMap;
use serde_json::json;

use crate::generator::{LoadedScbg, examples_for_split, load_scbg};
use crate::{Progress, ensure_request};

/// Results of every variant on the same held-out examples.
#[derive(Debug, Clone)]
pub struct ScbgEval {
    /// (variant name, result), in the order given.
    pub variants: Vec<(String, VariantEval)>,
    /// Held-out pair roles evaluated.
    pub examples: usize,
    /// |ψ_logged| above which a pair counts as high courtesy.
    pub high_threshold_psi: f32,
    /// Smallest and largest training label (the *arbitrary* ψ range).
    pub psi_range: (f32, f32),
    /// Figure files written (relative names inside the figures folder).
    pub figures: Vec<String>,
    /// Why nothing was evaluated (the demo goes on without generators on data without pairs).
    pub not_evaluated: Option<String>,
    /// Per variant (same order), the generated futures scored by the synthetic simulator's
    /// oracle (synthetic data with its ground truth only).
    pub truth_control: Vec<(String, crate::fidelity::TruthControl)>,
    /// The same scoring of the synthetic world's own B at courtesy c = q: the yardstick of
    /// `truth_control` (synthetic data with its ground truth only).
    pub truth_control_world: Option<crate::fidelity::WorldKnob>,
    /// What a selector among the labelled futures of B reaches: ranked by ψ_true (the
    /// candidates' ceiling) and by the labels (a perfect follower of J_φ) — synthetic data only.
    pub truth_control_selection: Option<crate::fidelity::SelectionControl>,
    /// What a selector among the first mode-selecting variant's own candidates (B's modes and
    /// their copies) reaches, ranked by ψ_true and by J_φ — synthetic data only.
    pub truth_control_candidates: Option<crate::fidelity::SelectionControl>,
}

fn ms_json(m: &Option<MeanStd>) -> serde_json::Value {
    m.map_or(
        serde_json::Value::Null,
        |m| json!({"mean": m.mean, "std": m.std}),
    )
}

/// Three significant digits, scientific below 0.01.
fn num(v: f64) -> String {
    if v != 0.0 && v.abs() < 0.01 {
        format!("{v:.2e}")
    } else {
        format!("{v:.3}")
    }
}

fn ms_text(m: &Option<MeanStd>) -> String {
    m.map_or("-".into(), |m| format!("{} ± {}", num(m.mean), num(m.std)))
}

fn label_of(name: &str) -> &str {
    match name {
        "baseline" => "① baseline",
        "aug" => "①+② augmentation",
        "full" => "①+②+③ courtesy loss",
        "ranked" => "sample and rank (B's sampled futures by ψ label; no generator)",
        other => other,
    }
}

impl ScbgEval {
    /// A report that says why nothing was evaluated.
    pub fn not_evaluated(why: String) -> Self {
        Self {
            variants: Vec::new(),
            examples: 0,
            high_threshold_psi: f32::NAN,
            psi_range: (f32::NAN, f32::NAN),
            figures: Vec::new(),
            not_evaluated: Some(why),
            truth_control: Vec::new(),
            truth_control_world: None,
            truth_control_selection: None,
            truth_control_candidates: None,
        }
    }

    /// `{"<variant>": {courtesy_mse_data: {mean, std}, …, traj_ade, corr_quantile,
    /// corr_quantile_high, examples, high_examples, per_quantile, per_quantile_high}}`.
    pub fn variants_json(&self) -> serde_json::Value {
        let map: serde_json::Map<String, serde_json::Value> = self
            .variants
            .iter()
            .map(|(name, v)| {
                (
                    name.clone(),
                    json!({
                        "courtesy_mse_data": ms_json(&v.courtesy_mse_data),
                        "courtesy_mse_range": ms_json(&v.courtesy_mse_range),
                        "courtesy_mse_arbitrary": ms_json(&v.courtesy_mse_arbitrary),
                        "traj_ade": ms_json(&v.traj_ade),
                        "corr_quantile": v.corr_quantile,
                        "corr_quantile_high": v.corr_quantile_high,
                        "corr_quantile_within": v.corr_quantile_within,
                        "examples": v.examples,
                        "high_examples": v.high_examples,
                        "per_quantile": v.per_quantile,
                        "per_quantile_high": v.per_quantile_high,
                    }),
                )
            })
            .collect();
        serde_json::Value::Object(map)
    }

    /// `{"<variant>": TruthControl}` for the variants scored by the oracle.
    pub fn truth_control_json(&self) -> serde_json::Value {
        serde_json::Value::Object(
            self.truth_control
                .iter()
                .map(|(name, t)| (name.clone(), serde_json::to_value(t).expect("plain data")))
                .collect(),
        )
    }

    /// The report JSON: `{variants, truth_control, truth_control_world,
    /// truth_control_selection, examples, high_threshold_psi, psi_min, psi_max, figures}`.
    pub fn to_json(&self) -> serde_json::Value {
        json!({
            "variants": self.variants_json(),
            "truth_control": self.truth_control_json(),
            "truth_control_world": self.truth_control_world,
            "truth_control_selection": self.truth_control_selection,
            "truth_control_candidates": self.truth_control_candidates,
            "examples": self.examples,
            "high_threshold_psi": self.high_threshold_psi,
            "psi_min": self.psi_range.0,
            "psi_max": self.psi_range.1,
            "figures": self.figures,
        })
    }

    /// Table II of the paper, plus the correlation columns.
    pub fn to_markdown(&self) -> String {
        if let Some(why) = &self.not_evaluated {
            return format!("(not evaluated: {why})\n");
        }
        let mut s = String::from(
            "| model | CourtesyMSE *data* | CourtesyMSE *range* | CourtesyMSE *arbitrary* | TrajADE (m) | corr(q, ψ) all | corr(q, ψ) high | corr(q, ψ) within a pair |\n|---|---|---|---|---|---|---|---|\n",
        );
        for (name, v) in &self.variants {
            let c = |x: Option<f64>| x.map_or("-".into(), |x| format!("{x:.3}"));
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
                label_of(name),
                ms_text(&v.courtesy_mse_data),
                ms_text(&v.courtesy_mse_range),
                ms_text(&v.courtesy_mse_arbitrary),
                ms_text(&v.traj_ade),
                c(v.corr_quantile),
                c(v.corr_quantile_high),
                c(v.corr_quantile_within),
            ));
        }
        if !self.truth_control.is_empty() {
            // A column per family the evaluated scenes hold.
            let families: Vec<&str> = scbg_synth::Family::ALL
                .map(scbg_synth::Family::name)
                .into_iter()
                .filter(|f| {
                    self.truth_control
                        .iter()
                        .any(|(_, t)| t.knob.spearman_quantile_psi_true.contains_key(*f))
                })
                .collect();
            s.push_str(&format!("\nControl in truth — Spearman(input quantile, ψ_true of the generated future), oracle of the synthetic simulator; pooled over examples, and within an example (the mean over examples of the Spearman across its own futures, 0 where they all give A the same reward; the share of examples where they do not):\n\n| model | all | {0} | within an example: all | {0} | responsive | each example ordered by q: all | scored pair roles | Pearson(achieved ψ, ψ_true) |\n|---|---|{1}---|{1}---|---|---|---|\n", families.join(" | "), "---|".repeat(families.len())));
            let row = |label: &str, w: &crate::fidelity::WorldKnob, pearson: Option<f64>| {
                let c = |x: Option<f64>| x.map_or("-".into(), |x| format!("{x:.3}"));
                let at = |k: &str| c(w.spearman_quantile_psi_true.get(k).copied().flatten());
                let within = |k: &str| c(w.spearman_within_example.get(k).copied());
                let each = |f: &dyn Fn(&str) -> String| {
                    families
                        .iter()
                        .map(|k| f(k))
                        .collect::<Vec<_>>()
                        .join(" | ")
                };
                format!(
                    "| {label} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                    at(crate::fidelity::POOLED),
                    each(&at),
                    within(crate::fidelity::POOLED),
                    each(&within),
                    c(w.responsive_fraction.get(crate::fidelity::POOLED).copied()),
                    c(w.spearman_quantile_psi_true_ordered
                        .get(crate::fidelity::POOLED)
                        .copied()
                        .flatten()),
                    w.examples
                        .get(crate::fidelity::POOLED)
                        .copied()
                        .unwrap_or(0),
                    c(pearson),
                )
            };
            for (name, t) in &self.truth_control {
                s.push_str(&row(label_of(name), &t.knob, t.achieved_vs_true.pearson));
            }
            if let Some(w) = &self.truth_control_world {
                s.push_str(&row("the world's own B at c = q (yardstick)", w, None));
            }
            let selection = self
                .truth_control_selection
                .iter()
                .flat_map(|sel| sel.yardsticks());
            let candidates = self
                .truth_control_candidates
                .iter()
                .flat_map(|sel| sel.candidate_yardsticks());
            for (label, w) in selection.chain(candidates) {
                s.push_str(&row(label, w, None));
            }
        }
        s.push_str(&format!(
            "\n{} held-out pair roles; high courtesy = |ψ_logged| > {} ({} of them); arbitrary ψ from {} to {} (training labels).\n",
            self.examples,
            num(f64::from(self.high_threshold_psi)),
            self.variants.first().map_or(0, |v| v.1.high_examples),
            num(f64::from(self.psi_range.0)),
            num(f64::from(self.psi_range.1)),
        ));
        s
    }
}

/// Evaluates the generator folders `models` on the pair roles of `split` of the cache `data`
/// (labelled as in training, with `samples` futures of B per role when given) and writes the
/// figures to `figures`; with a synthetic ground truth the generated futures are also scored by
/// the oracle.
#[allow(clippy::too_many_arguments)]
pub fn evaluate_scbg(
    models: &[PathBuf],
    data: &Path,
    predictor: Option<&Path>,
    split: Option<Split>,
    seed: u64,
    samples: Option<usize>,
    figures: Option<&Path>,
    truth: Option<&[scbg_synth::GroundTruth]>,
    progress: &dyn Progress,
) -> anyhow::Result<ScbgEval> {
    ensure_request!(!models.is_empty(), "no generator folder given");
    let mut loaded = Vec::new();
    for dir in models {
        let model = load_scbg(dir, predictor)?;
        ensure_request!(
            model.others.is_empty(),
            "{} is an ensemble ({}): this evaluation measures one generator, so pass its members",
            dir.display(),
            scbg::model::ENSEMBLE_JSON
        );
        loaded.push(model);
    }
    let first = &loaded[0];
    for (dir, l) in models.iter().zip(&loaded).skip(1) {
        ensure_request!(
            l.checkpoint.predictor == first.checkpoint.predictor || predictor.is_some(),
            "{} was trained with predictor {}, {} with {}: variants must share one predictor",
            dir.display(),
            l.checkpoint.predictor,
            models[0].display(),
            first.checkpoint.predictor
        );
    }
    let examples = examples_for_split(
        &first.scbg.predictor,
        &first.predictor,
        &first.device,
        data,
        split,
        LabelOptions {
            samples: samples.unwrap_or(first.checkpoint.labels.samples),
            ..first.checkpoint.labels
        },
        seed,
        progress,
    )?;
    evaluate_examples(&loaded, &examples, data, figures, truth, progress)
}

/// Evaluates loaded variants on labelled examples (e.g. the held-out split the demo labelled
/// once); `data` is the cache the examples come from (road geometry of the figures). With a
/// synthetic ground truth, the generated futures are also scored by the oracle.
pub fn evaluate_examples(
    loaded: &[LoadedScbg],
    examples: &[Example],
    data: &Path,
    figures: Option<&Path>,
    truth: Option<&[scbg_synth::GroundTruth]>,
    progress: &dyn Progress,
) -> anyhow::Result<ScbgEval> {
    let index = truth.map(crate::fidelity::TruthIndex::new);
    let mut truth_control = Vec::new();
    ensure_request!(
        !examples.is_empty(),
        "no interacting pairs in the evaluated split of {}",
        data.display()
    );
    let first = loaded.first().context("no generator to evaluate")?;
    let refs: Vec<&Example> = examples.iter().collect();
    let high = first.checkpoint.threshold_psi;
    let psi_range = (first.checkpoint.psi_min, first.checkpoint.psi_max);
    let mut variants = Vec::new();
    let options = |l: &LoadedScbg| EvalOptions {
        arbitrary_min: l.checkpoint.psi_min,
        arbitrary_max: l.checkpoint.psi_max,
        high_threshold: high,
        reward: l.scbg.labels.reward,
    };
    // A row of Table II, and its control in truth where there is a ground truth.
    let mut record = |name: &str, v: VariantEval, measured: &scbg_generator::eval::Measured| {
        if let Some(t) = index
            .as_ref()
            .and_then(|index| crate::fidelity::truth_control(&refs, measured, index))
        {
            truth_control.push((name.to_string(), t));
        }
        variants.push((name.to_string(), v));
    };
    for l in loaded {
        let name = l.checkpoint.variant.name();
        let pb = progress.bar(&format!("evaluating {name}"), 1);
        let (v, measured) = scbg_generator::eval::evaluate_measured(
            &l.scbg.generator,
            &l.scbg.range,
            &l.scbg.predictor,
            &refs,
            &options(l),
            &l.device,
        );
        pb.inc(1);
        record(name, v, &measured);
    }
    // Sample and rank, the untrained yardstick every variant is compared with: B's sampled
    // futures chosen by their labels (the first variant's range predictor turns the quantiles
    // into the requested ψ of CourtesyMSE *range*).
    if let Some((v, measured)) = scbg_generator::ranked::evaluate_ranked(
        &first.scbg.range,
        &first.scbg.predictor,
        &refs,
        &options(first),
        &first.device,
    ) {
        record(scbg_generator::ranked::RANKED, v, &measured);
    }
    // The choices of the first variant, scored by J_φ and by the oracle (the variants share
    // the predictor, so their modes; only copies could differ).
    let truth_control_candidates = index.as_ref().and_then(|index| {
        let l = loaded.first()?;
        let candidates = scbg_generator::scored_candidates(
            &l.scbg.generator,
            &l.scbg.predictor,
            &refs,
            l.scbg.labels.reward,
            &l.device,
        );
        crate::fidelity::candidate_control(&refs, &candidates, index)
    });
    let mut written = Vec::new();
    if let Some(dir) = figures {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        written = crate::figures::write_figures(dir, data, &variants, loaded, &refs)?;
    }
    Ok(ScbgEval {
        variants,
        examples: examples.len(),
        high_threshold_psi: high,
        psi_range,
        figures: written,
        not_evaluated: None,
        truth_control,
        truth_control_world: index
            .as_ref()
            .and_then(|index| crate::fidelity::world_truth_control(&refs, index)),
        truth_control_selection: index
            .as_ref()
            .and_then(|index| crate::fidelity::selection_control(&refs, index)),
        truth_control_candidates,
    })
}

impl Serialize for ScbgEval {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let value = self.to_json();
        let obj = value.as_object().expect("an object");
        let mut map = serializer.serialize_map(Some(obj.len()))?;
        for (k, v) in obj {
            map.serialize_entry(k, v)?;
        }
        map.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_skipped_evaluation_still_reports() {
        let e = ScbgEval::not_evaluated("no interacting pair".into());
        assert!(
            e.to_markdown()
                .contains("not evaluated: no interacting pair")
        );
        let j = e.to_json();
        assert_eq!(j["variants"], json!({}));
        assert_eq!(j["examples"], 0);
    }
}
