//! `scbg eval scbg`: the paper's Table II, the quantile → courtesy correlation and Figs. 4–5
//! for one or more generator variants sharing one predictor.

use std::path::{Path, PathBuf};

use anyhow::Context;
use scbg_generator::eval::{EVAL_QUANTILES, EvalOptions, MeanStd, VariantEval};
use scbg_generator::{Example, Scbg};
use scbg_scene::Pose2;
use scbg_train::data::Split;
use serde_json::json;

use crate::cli::EvalScbgArgs;

/// Results of every variant on the same held-out examples.
pub struct ScbgEval {
    /// (variant name, result), in the order given.
    pub variants: Vec<(String, VariantEval)>,
    pub examples: usize,
    pub high_threshold_psi: f32,
    pub psi_range: (f32, f32),
    /// Figure files written (relative names inside the figures folder).
    pub figures: Vec<String>,
    /// Why nothing was evaluated (the demo goes on without generators on data without pairs).
    pub not_evaluated: Option<String>,
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

/// The variant's name in figures (the bundled font has no circled digits).
fn plot_label(name: &str) -> &str {
    match name {
        "baseline" => "(1) baseline",
        "aug" => "(1)+(2) augmentation",
        "full" => "(1)+(2)+(3) courtesy loss",
        other => other,
    }
}

fn label_of(name: &str) -> &str {
    match name {
        "baseline" => "① baseline",
        "aug" => "①+② augmentation",
        "full" => "①+②+③ courtesy loss",
        other => other,
    }
}

impl ScbgEval {
    pub fn not_evaluated(why: String) -> Self {
        Self {
            variants: Vec::new(),
            examples: 0,
            high_threshold_psi: f32::NAN,
            psi_range: (f32::NAN, f32::NAN),
            figures: Vec::new(),
            not_evaluated: Some(why),
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

    pub fn to_json(&self) -> serde_json::Value {
        json!({
            "variants": self.variants_json(),
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

/// Evaluates the generator folders `models` on `data` and writes figures to `figures`.
pub fn evaluate_scbg(
    models: &[PathBuf],
    data: &Path,
    predictor: Option<&Path>,
    split: Option<Split>,
    seed: u64,
    figures: Option<&Path>,
) -> anyhow::Result<ScbgEval> {
    anyhow::ensure!(!models.is_empty(), "no generator folder given");
    let mut loaded = Vec::new();
    for dir in models {
        loaded.push(super::generator::load_scbg(dir, predictor)?);
    }
    let first = &loaded[0];
    for (dir, l) in models.iter().zip(&loaded).skip(1) {
        if l.checkpoint.predictor != first.checkpoint.predictor && predictor.is_none() {
            anyhow::bail!(
                "{} was trained with predictor {}, {} with {}: variants must share one predictor",
                dir.display(),
                l.checkpoint.predictor,
                models[0].display(),
                first.checkpoint.predictor
            );
        }
    }
    let examples = super::generator::examples_for_split(
        &first.scbg.predictor,
        &first.predictor,
        &first.device,
        data,
        split,
        first.checkpoint.label_options()?,
        seed,
    )?;
    anyhow::ensure!(
        !examples.is_empty(),
        "no interacting pairs in the evaluated split of {}",
        data.display()
    );
    let refs: Vec<&Example> = examples.iter().collect();
    let high = first.checkpoint.threshold_psi;
    let psi_range = (first.checkpoint.psi_min, first.checkpoint.psi_max);
    let mut variants = Vec::new();
    for l in &loaded {
        let pb = crate::progress::spinner(&format!("evaluating {}", l.checkpoint.variant));
        let v = scbg_generator::eval::evaluate(
            &l.scbg.generator,
            &l.scbg.range,
            &l.scbg.predictor,
            &refs,
            &EvalOptions {
                arbitrary_min: l.checkpoint.psi_min,
                arbitrary_max: l.checkpoint.psi_max,
                high_threshold: high,
                reward: l.scbg.labels.reward,
            },
            &l.device,
        );
        pb.finish_and_clear();
        variants.push((l.checkpoint.variant.clone(), v));
    }
    let mut written = Vec::new();
    if let Some(dir) = figures {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        written = write_figures(dir, data, &variants, &loaded, &refs)?;
    }
    Ok(ScbgEval {
        variants,
        examples: examples.len(),
        high_threshold_psi: high,
        psi_range,
        figures: written,
        not_evaluated: None,
    })
}

/// Fig. 4 (quantile → achieved ψ per variant), Fig. 5a (three cases with B generated at five
/// quantiles, last variant) and Fig. 5b (A's expected speed vs quantile for those cases).
fn write_figures(
    dir: &Path,
    data: &Path,
    variants: &[(String, VariantEval)],
    loaded: &[super::generator::LoadedScbg],
    examples: &[&Example],
) -> anyhow::Result<Vec<String>> {
    let mut written = Vec::new();
    // Fig. 4: the high-courtesy subset as in the paper, all pairs when it is empty.
    let use_high = variants
        .iter()
        .all(|(_, v)| !v.per_quantile_high.is_empty());
    let series: Vec<scbg_plot::Series> = variants
        .iter()
        .map(|(name, v)| {
            let curve = if use_high {
                &v.per_quantile_high
            } else {
                &v.per_quantile
            };
            scbg_plot::Series {
                label: format!("{} (mean ± std)", plot_label(name)),
                points: curve
                    .iter()
                    .map(|p| (f64::from(p.quantile), p.achieved_psi.mean))
                    .collect(),
                band: Some(curve.iter().map(|p| p.achieved_psi.std).collect()),
            }
        })
        .collect();
    let name = "fig4_quantile_courtesy.png";
    scbg_plot::line_chart(
        &series,
        "input quantile",
        "courtesy of the generated trajectory, ψ (m/s)",
        if use_high {
            "Fig. 4: quantile → courtesy (high-courtesy pairs)"
        } else {
            "Fig. 4: quantile → courtesy (all pairs)"
        },
        &dir.join(name),
    )?;
    written.push(name.to_string());

    // Fig. 5: the three held-out pairs with the largest |ψ_logged|, distinct scenarios.
    let mut order: Vec<usize> = (0..examples.len()).collect();
    order.sort_by(|&i, &j| {
        examples[j].psi[0]
            .abs()
            .total_cmp(&examples[i].psi[0].abs())
    });
    let mut cases: Vec<usize> = Vec::new();
    for i in order {
        if cases.len() == 3 {
            break;
        }
        if cases
            .iter()
            .all(|&c| examples[c].scenario_id != examples[i].scenario_id)
        {
            cases.push(i);
        }
    }
    let last = loaded.last().expect("at least one model");
    let scbg: &Scbg = &last.scbg;
    let quantiles = [0.1f32, 0.3, 0.5, 0.7, 0.9];
    let roads = case_roads(
        data,
        cases.iter().map(|&i| examples[i].scenario_id.as_str()),
    )?;
    let mut speed_series = Vec::new();
    for (k, &i) in cases.iter().enumerate() {
        let e = examples[i];
        let ranges = scbg_generator::eval::predicted_ranges(&scbg.range, &[e], &last.device);
        let (lo, hi) = ranges[0];
        let nine: Vec<f32> = EVAL_QUANTILES
            .iter()
            .map(|&q| scbg_generator::psi_for_quantile(q, lo, hi))
            .collect();
        let measured = scbg_generator::eval::generate_and_measure(
            &scbg.generator,
            &scbg.predictor,
            &[e],
            std::slice::from_ref(&nine),
            scbg.labels.reward,
            &last.device,
        );
        speed_series.push(scbg_plot::Series {
            label: format!("case {} ({})", k + 1, e.scenario_id),
            points: EVAL_QUANTILES
                .iter()
                .zip(&measured.e_cond[0])
                .map(|(&q, &v)| (f64::from(q), f64::from(v)))
                .collect(),
            band: None,
        });
        // Everything in A's frame.
        let b_pose = Pose2::new(
            f64::from(e.a_from_b[1]),
            f64::from(e.a_from_b[2]),
            f64::from(e.a_from_b[0]),
        );
        let in_a = |pts: &[[f32; 2]]| -> Vec<(f64, f64)> {
            pts.iter()
                .map(|p| b_pose.world_from_agent(f64::from(p[0]), f64::from(p[1])))
                .collect()
        };
        let a_future: Vec<(f64, f64)> =
            e.a.future_valid
                .iter()
                .enumerate()
                .filter(|(_, v)| **v)
                .map(|(s, _)| {
                    (
                        f64::from(e.a.future_xy_m[2 * s]),
                        f64::from(e.a.future_xy_m[2 * s + 1]),
                    )
                })
                .collect();
        let b_logged: Vec<[f32; 2]> = e.futures_b[0]
            .iter()
            .zip(&e.logged_valid)
            .filter(|(_, v)| **v)
            .map(|(p, _)| *p)
            .collect();
        let line = |label: String, rgb: (u8, u8, u8), points: Vec<(f64, f64)>| scbg_plot::Line {
            label,
            rgb,
            points,
        };
        let mut lines = vec![
            line("A logged".into(), (220, 20, 30), a_future),
            line("B logged".into(), (60, 60, 60), in_a(&b_logged)),
        ];
        for (qi, q) in quantiles.iter().enumerate() {
            let j = EVAL_QUANTILES
                .iter()
                .position(|x| (x - q).abs() < 1e-6)
                .expect("quantile in the evaluation grid");
            let shade = 230 - (qi as u8) * 45;
            lines.push(line(
                format!(
                    "B q={q:.1} (ψ {:+.3}, A {:.2} m/s)",
                    measured.psi[0][j], measured.e_cond[0][j]
                ),
                (shade / 3, shade / 2 + 40, 255 - qi as u8 * 20),
                in_a(&measured.futures_b[0][j]),
            ));
        }
        let background: Vec<Vec<(f64, f64)>> = roads
            .get(e.scenario_id.as_str())
            .into_iter()
            .flatten()
            .map(|line| {
                line.iter()
                    .map(|&(x, y)| e.a.world_from_agent.agent_from_world(x, y))
                    .collect()
            })
            .collect();
        let name = format!("fig5a_case{}.png", k + 1);
        scbg_plot::trajectories(
            &background,
            &lines,
            &format!(
                "Fig. 5a case {}: {} ({} variant, A's frame)",
                k + 1,
                e.scenario_id,
                last.checkpoint.variant
            ),
            &dir.join(&name),
        )?;
        written.push(name);
    }
    if !speed_series.is_empty() {
        let name = "fig5b_quantile_speed.png";
        scbg_plot::line_chart(
            &speed_series,
            "input quantile",
            "A's expected average speed given ŷ_B (m/s)",
            "Fig. 5b: quantile → A's expected speed",
            &dir.join(name),
        )?;
        written.push(name.to_string());
    }
    Ok(written)
}

/// Polylines, world frame, metres.
type Polylines = Vec<Vec<(f64, f64)>>;

/// World-frame road polylines of the given scenarios, by scenario id (one scan of the cache).
fn case_roads<'a>(
    data: &Path,
    ids: impl Iterator<Item = &'a str>,
) -> anyhow::Result<std::collections::HashMap<&'a str, Polylines>> {
    let mut wanted: std::collections::HashMap<&str, Polylines> =
        ids.map(|id| (id, Vec::new())).collect();
    if wanted.is_empty() {
        return Ok(wanted);
    }
    let dataset = scbg_features::cache::PreparedDataset::open(data)?;
    let mut found = 0;
    for i in 0..dataset.len() {
        let scene = dataset.scene(i)?;
        let Some(road) = wanted.get_mut(scene.scenario_id.as_str()) else {
            continue;
        };
        let [ox, oy] = scene.origin_xy_m;
        *road = scene
            .road
            .iter()
            .map(|r| {
                r.xy_m
                    .iter()
                    .map(|p| (ox + f64::from(p[0]), oy + f64::from(p[1])))
                    .collect()
            })
            .collect();
        found += 1;
        if found == wanted.len() {
            break;
        }
    }
    Ok(wanted)
}

/// `scbg eval scbg`.
pub fn eval(args: &EvalScbgArgs) -> anyhow::Result<ScbgEval> {
    let split = (args.split == "validation").then_some(Split::Validation);
    let result = evaluate_scbg(
        &args.model,
        &args.data,
        args.predictor.as_deref(),
        split,
        args.seed,
        args.figures.as_deref(),
    )?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&result.to_json())?);
    } else {
        print!("{}", result.to_markdown());
    }
    Ok(result)
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
