//! `scbg demo`: the README's main command — the pipeline end to end, with a report.
//!
//! Today: synthetic data (or the user's WOMD files) → prepared cache → Multipath++ predictor
//! (marginal + conditional, cpu-small) → evaluation beside the baselines → report. The
//! courtesy labelling, the SCBG generator and its evaluation join here as they land.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use serde_json::json;

use crate::cli::{DemoArgs, PrepareArgs, SynthArgs};

fn stage(n: usize, total: usize, what: &str) {
    eprintln!("\n[{n}/{total}] {what}");
}

fn write_atomic(path: &Path, text: &str) -> anyhow::Result<()> {
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
    let out = &args.out;
    std::fs::create_dir_all(out.join("figures"))
        .with_context(|| format!("creating {}", out.display()))?;
    let total = 6;
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
        condition_dropout: 0.5,
        plateau_patience: 3,
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
        seed: args.seed,
        ground_truth,
    })?;
    std::fs::copy(
        labels_dir.join("psi_histogram.png"),
        out.join("figures/psi_histogram.png"),
    )?;

    stage(6, total, "writing figures and the report");
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
    let report_json = json!({
        "data": {"inputs": inputs, "scenarios": manifest.total.scenarios, "windows": manifest.total.windows, "pairs": manifest.total.pairs, "skipped": manifest.total.skipped},
        "predictor": predictor_json,
        "labels": {"futures": labels.rows.len(), "logged": logged.len()},
        "spearman_latent": spearman,
        "seconds": started.elapsed().as_secs_f64(),
    });
    write_atomic(
        &out.join("report.json"),
        &serde_json::to_string_pretty(&report_json)?,
    )?;
    let md = format!(
        "# scbg demo report\n\nData: {} scenarios, {} windows, {} interacting pairs (skipped: {:?}).\n\n\
         ## Predictor (paper Table I layout, held-out scenarios)\n\n{}\n\
         ## Courtesy labels (paper Fig. 3)\n\n{} labelled futures ({} logged).\n\n![psi](figures/psi_histogram.png)\n\n\
         Ground-truth check — Spearman(ψ of the logged future, latent courtesy of the generator):\n\n{}\n\
         ![scene](figures/scene.png)\n\nRun time: {:.0} s.\n",
        manifest.total.scenarios,
        manifest.total.windows,
        manifest.total.pairs,
        manifest.total.skipped,
        eval.to_markdown(),
        labels.rows.len(),
        logged.len(),
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
    eprintln!("report: {}", out.join("report.md").display());
    Ok(())
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
