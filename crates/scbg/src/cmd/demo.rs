//! `scbg demo`: the README's main command — the pipeline end to end, with a report.
//!
//! Synthetic data (or the user's WOMD files) → prepared cache → Multipath++ predictor, marginal
//! and conditional, cpu-small → evaluation beside the baselines → courtesy labels, with the
//! ground-truth check on synthetic data → the three generator variants and the range
//! predictor → the paper's evaluation (Table II, Figs. 4–5) → report.md and report.json.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use serde_json::json;

use crate::cli::{DemoArgs, PrepareArgs, SynthArgs};

fn stage(n: usize, total: usize, what: &str) {
    eprintln!("\n[{n}/{total}] {what}");
}

pub(crate) fn write_atomic(path: &Path, text: &str) -> anyhow::Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir)?;
    tmp.write_all(text.as_bytes())?;
    tmp.persist(path)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

pub fn demo(args: &DemoArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    // Checked before any work: a bad flag must not cost a predictor training.
    let label_options =
        super::label::label_options(&args.estimator, 8, scbg_courtesy::Reward::AverageSpeed)?;
    let out = &args.out;
    std::fs::create_dir_all(out.join("figures"))
        .with_context(|| format!("creating {}", out.display()))?;
    let total = 8;
    let inputs: Vec<String> = if args.data.is_empty() {
        stage(
            1,
            total,
            &format!(
                "generating {} synthetic interactive scenarios",
                args.scenarios
            ),
        );
        let synth_dir = out.join("synth");
        super::synth::synth(&SynthArgs {
            scenarios: args.scenarios,
            seed: args.seed,
            out: synth_dir.clone(),
            families: vec!["merge".into(), "crossing".into(), "cutin".into()],
            scenarios_per_file: 250,
        })?;
        vec![synth_dir.display().to_string()]
    } else {
        stage(1, total, "using your data");
        args.data.clone()
    };

    stage(2, total, "preparing the feature cache");
    let cache = out.join("cache");
    let manifest = super::data::prepare(&PrepareArgs {
        input: inputs.clone(),
        out: cache.clone(),
        shard_index: 0,
        num_shards: 1,
        files_per_shard: 4,
        stride_steps: 10,
        pair_distance_m: 3.0,
        pair_time_gap_s: 4.0,
    })?;

    stage(
        3,
        total,
        &format!(
            "training the Multipath++ predictor (cpu-small, {} epochs)",
            args.epochs
        ),
    );
    let config = scbg_train::TrainConfig {
        epochs: args.epochs,
        seed: args.seed,
        ..Default::default()
    };
    let predictor_dir = out.join("predictor");
    let train_config_path = out.join("predictor.toml");
    write_atomic(&train_config_path, &toml_of(&config)?)?;
    super::train::predictor(&crate::cli::TrainPredictorArgs {
        config: Some(train_config_path),
        data: cache.clone(),
        out: predictor_dir.clone(),
        resume: false,
    })?;

    stage(
        4,
        total,
        "evaluating the predictor (held-out scenarios) beside the baselines",
    );
    let eval =
        super::eval::evaluate_predictor(&predictor_dir, &cache, "both", "validation", false)?;

    stage(
        5,
        total,
        "auto-labelling the courtesy ψ of every interacting pair (logged + 8 sampled futures of B)",
    );
    let labels_dir = out.join("labels");
    let ground_truth = inputs
        .iter()
        .map(|i| Path::new(i).join(super::synth::GROUND_TRUTH_FILE))
        .find(|p| p.is_file());
    let labels = super::label::label(&crate::cli::LabelArgs {
        model: predictor_dir.clone(),
        data: cache.clone(),
        out: labels_dir.clone(),
        samples: 8,
        reward: "average_speed".into(),
        estimator: args.estimator.clone(),
        seed: args.seed,
        ground_truth,
    })?;
    std::fs::copy(
        labels_dir.join("psi_histogram.png"),
        out.join("figures/psi_histogram.png"),
    )?;

    stage(
        6,
        total,
        &format!(
            "training the SCBG generator variants (baseline, aug, full; {} epochs each) and the range predictor",
            args.generator_epochs
        ),
    );
    let predictors = super::generator::load_predictors(&predictor_dir)?;
    eprintln!("labelling the training split for the generator (logged + 8 sampled futures of B)");
    let examples = super::generator::examples_for_split(
        &predictors.plain,
        &predictors.ckpt,
        &predictors.plain_device,
        &cache,
        Some(scbg_train::data::Split::Train),
        label_options,
        args.seed,
    )?;
    let mut generator_dirs = Vec::new();
    let mut generator_seconds = serde_json::Map::new();
    let mut skipped: Option<String> = None;
    if examples.is_empty() {
        let why = "no interacting pair in the training split: the generators are not trained";
        eprintln!("{why}");
        skipped = Some(why.into());
    }
    let variants = if examples.is_empty() {
        Vec::new()
    } else {
        vec![
            scbg_generator::Variant::Baseline,
            scbg_generator::Variant::Augmented,
            scbg_generator::Variant::Full,
        ]
    };
    for variant in variants {
        let name = super::generator::variant_name(variant);
        let dir = out.join(format!("generator_{name}"));
        let saved = super::generator::train_variant(
            &predictors,
            &examples,
            &super::generator::VariantSettings {
                variant,
                epochs: args.generator_epochs,
                batch_size: 32,
                alpha: 0.5,
                beta: args.beta,
                threshold: "q0.8".into(),
                learning_rate: 1e-3,
                range_steps: 300,
                seed: args.seed,
                labels: label_options,
            },
            &dir,
        )?;
        generator_seconds.insert(name.into(), json!(saved.seconds));
        generator_dirs.push(dir);
    }
    drop(predictors);

    stage(
        7,
        total,
        "evaluating the generators on held-out pairs (CourtesyMSE, TrajADE, correlation; Figs. 4–5)",
    );
    let scbg_eval = match skipped {
        Some(why) => super::eval_scbg::ScbgEval::not_evaluated(why),
        None => super::eval_scbg::evaluate_scbg(
            &generator_dirs,
            &cache,
            None,
            Some(scbg_train::data::Split::Validation),
            args.seed,
            Some(&out.join("figures")),
        )
        .unwrap_or_else(|err| {
            let why = format!("the generators were not evaluated: {err:#}");
            eprintln!("{why}");
            super::eval_scbg::ScbgEval::not_evaluated(why)
        }),
    };

    stage(8, total, "writing figures and the report");
    let first_file = crate::inputs::expand(&inputs)?
        .into_iter()
        .next()
        .context("no input file")?;
    let scene = scbg_womd::WomdFile::open(&first_file)?
        .scenes()
        .next()
        .context("empty input")??;
    let pair = super::data::interacting_pair(&scene);
    let figure = out.join("figures/scene.png");
    scbg_plot::render_scene(
        &scene,
        &figure,
        &scbg_plot::RenderOptions {
            size_px: 800,
            pair,
            ..Default::default()
        },
    )?;

    let predictor_json = eval.to_json();
    let spearman: serde_json::Map<String, serde_json::Value> = labels
        .spearman_latent
        .iter()
        .map(|(f, (rho, _))| (f.clone(), json!(rho)))
        .collect();
    let logged: Vec<f64> = labels
        .rows
        .iter()
        .filter(|r| r.sample == 0)
        .map(|r| f64::from(r.psi))
        .collect();
    let within = super::label::within_pair_std(&labels.rows);
    let checks = acceptance_checks(&scbg_eval);
    let report_json = json!({
        "data": {"inputs": inputs, "scenarios": manifest.total.scenarios, "windows": manifest.total.windows, "pairs": manifest.total.pairs, "skipped": manifest.total.skipped},
        "predictor": predictor_json,
        "labels": {"futures": labels.rows.len(), "logged": logged.len(), "psi_within_pair_std": within},
        "spearman_latent": spearman,
        "variants": scbg_eval.variants_json(),
        "scbg_eval": {"examples": scbg_eval.examples, "high_threshold_psi": scbg_eval.high_threshold_psi, "psi_min": scbg_eval.psi_range.0, "psi_max": scbg_eval.psi_range.1, "figures": scbg_eval.figures},
        "checks": checks.iter().map(|(k, v, _)| (k.to_string(), json!(v))).collect::<serde_json::Map<_, _>>(),
        "generator_seconds": generator_seconds,
        "seconds": started.elapsed().as_secs_f64(),
    });
    write_atomic(
        &out.join("report.json"),
        &serde_json::to_string_pretty(&report_json)?,
    )?;
    let fig5a: String = scbg_eval
        .figures
        .iter()
        .filter(|f| f.starts_with("fig5a"))
        .map(|f| format!("![{f}](figures/{f})\n"))
        .collect();
    let md = format!(
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
        manifest.total.scenarios,
        manifest.total.windows,
        manifest.total.pairs,
        manifest.total.skipped,
        eval.to_markdown(),
        labels.rows.len(),
        logged.len(),
        within,
        if labels.spearman_latent.is_empty() {
            "(no synthetic ground truth for this data)".to_string()
        } else {
            labels
                .spearman_latent
                .iter()
                .map(|(f, (rho, n))| {
                    format!(
                        "- {f}: {} (n = {n})",
                        rho.map_or("-".into(), |r| format!("{r:.3}"))
                    )
                })
                .collect::<Vec<_>>()
                .join("\n")
        },
        scbg_eval.to_markdown(),
        checks
            .iter()
            .map(|(_, ok, text)| format!("- [{}] {text}", if *ok { "x" } else { " " }))
            .collect::<Vec<_>>()
            .join("\n"),
        fig5a,
        started.elapsed().as_secs_f64()
    );
    write_atomic(&out.join("report.md"), &md)?;

    eprintln!(
        "\n=== scbg demo: done in {:.0} s ===",
        started.elapsed().as_secs_f64()
    );
    eprintln!(
        "data: {} scenarios, {} pairs",
        manifest.total.scenarios, manifest.total.pairs
    );
    for (name, t) in &eval.rows {
        let m = &t.by_time[2].1;
        eprintln!(
            "{name:<36} minADE@8s {:>6}  MR@8s {:>6}",
            m.min_ade.map_or("-".into(), |v| format!("{v:.2}")),
            m.miss_rate
                .map_or("-".into(), |v| format!("{:.1}%", 100.0 * v))
        );
    }
    for (f, (rho, n)) in &labels.spearman_latent {
        eprintln!(
            "Spearman(ψ, latent courtesy) {f:<9} {} (n = {n})",
            rho.map_or("-".into(), |r| format!("{r:.3}"))
        );
    }
    eprint!("{}", scbg_eval.to_markdown());
    for (_, ok, text) in &checks {
        eprintln!("[{}] {text}", if *ok { "ok" } else { "MISS" });
    }
    eprintln!("report: {}", out.join("report.md").display());
    Ok(())
}

/// The acceptance points on the demo's held-out split: (key, passed, description).
fn acceptance_checks(e: &super::eval_scbg::ScbgEval) -> Vec<(&'static str, bool, String)> {
    let get = |name: &str| e.variants.iter().find(|(n, _)| n == name).map(|(_, v)| v);
    let mut out = Vec::new();
    if let Some(full) = get("full") {
        let mean = |m: &Option<scbg_generator::eval::MeanStd>| m.map_or(f64::NAN, |m| m.mean);
        let (range, arb) = (
            mean(&full.courtesy_mse_range),
            mean(&full.courtesy_mse_arbitrary),
        );
        out.push((
            "range_below_arbitrary",
            range < arb,
            format!("full: CourtesyMSE(range) {range:.3e} < CourtesyMSE(arbitrary) {arb:.3e}"),
        ));
        let corr = full.corr_quantile.unwrap_or(f64::NAN);
        out.push((
            "corr_quantile_at_least_0_5",
            corr >= 0.5,
            format!("full: corr(quantile, courtesy) {corr:.3} ≥ 0.5"),
        ));
        if let Some(base) = get("baseline") {
            let (fd, bd) = (mean(&full.courtesy_mse_data), mean(&base.courtesy_mse_data));
            out.push((
                "full_courtesy_mse_data_no_worse",
                fd <= bd,
                format!("CourtesyMSE(data): full {fd:.3e} ≤ baseline {bd:.3e}"),
            ));
            let (ft, bt) = (mean(&full.traj_ade), mean(&base.traj_ade));
            out.push((
                "full_traj_ade_no_worse",
                ft <= bt,
                format!("TrajADE: full {ft:.3} m ≤ baseline {bt:.3} m"),
            ));
        }
    }
    out
}

fn toml_of(config: &scbg_train::TrainConfig) -> anyhow::Result<String> {
    // `model = None` uses the preset; TOML has no null, so the key is simply left out.
    let mut value = serde_json::to_value(config)?;
    if let Some(obj) = value.as_object_mut() {
        obj.retain(|_, v| !v.is_null());
    }
    let text: toml::Value = serde_json::from_value(value)?;
    Ok(toml::to_string(&text)?)
}
