//! `scbg eval predictor | metrics`.

use std::collections::BTreeMap;

use anyhow::{Context, bail};
use scbg_features::AgentSample;
use scbg_features::cache::PreparedDataset;
use scbg_metrics::{ClassifierThresholds, GroundTruth, MetricTable, Metrics, Prediction};
use scbg_train::Checkpoint;
use scbg_train::eval::{
    Mode, constant_velocity, constant_yaw_rate_accel, mean_nll, predict, score,
};
use serde::Deserialize;
use serde_json::json;

use crate::cli::{EvalMetricsArgs, EvalPredictorArgs};
use crate::inputs;

fn fmt(v: Option<f32>, pct: bool) -> String {
    match v {
        Some(x) if pct => format!("{:.1}", 100.0 * x),
        Some(x) => format!("{x:.3}"),
        None => "-".into(),
    }
}

fn metrics_json(m: &Metrics) -> serde_json::Value {
    json!({"ade": m.ade, "min_ade": m.min_ade, "min_fde": m.min_fde, "miss_rate": m.miss_rate, "map": m.map, "soft_map": m.soft_map})
}

/// The JSON object `eval metrics --json` prints: top-level means plus `by_time`.
pub fn table_json(t: &MetricTable) -> serde_json::Value {
    let mut v = metrics_json(&t.mean);
    let by_time: serde_json::Map<String, serde_json::Value> = t
        .by_time
        .iter()
        .map(|(s, m)| (s.to_string(), metrics_json(m)))
        .collect();
    v["by_time"] = serde_json::Value::Object(by_time);
    v["num_objects"] = json!(t.num_objects);
    v
}

/// Prints rows shaped like the paper's Table I (8 s values) plus the 3/5/8 s mean of minADE and MR.
fn print_table(rows: &[(String, MetricTable)]) {
    println!(
        "{:<34} {:>8} {:>8} {:>8} {:>7} {:>7} | {:>12} {:>8} {:>7}",
        "mode (8 s)",
        "ADE m",
        "minADE",
        "minFDE",
        "MR %",
        "mAP",
        "minADE mean",
        "MR mean",
        "objects"
    );
    for (name, t) in rows {
        let m = &t.by_time[2].1;
        println!(
            "{:<34} {:>8} {:>8} {:>8} {:>7} {:>7} | {:>12} {:>8} {:>7}",
            name,
            fmt(m.ade, false),
            fmt(m.min_ade, false),
            fmt(m.min_fde, false),
            fmt(m.miss_rate, true),
            fmt(m.map, false),
            fmt(t.mean.min_ade, false),
            fmt(t.mean.miss_rate, true),
            t.num_objects
        );
    }
}

/// The predictor evaluation: metric rows (model modes and baselines) and the NLL of the
/// interacting agents' futures in each mode.
#[derive(Debug)]
pub struct PredictorEval {
    pub rows: Vec<(String, MetricTable)>,
    pub nll_interacting: Vec<(String, Option<f64>)>,
}

impl PredictorEval {
    pub fn to_json(&self) -> serde_json::Value {
        let mut obj: serde_json::Map<String, serde_json::Value> = self
            .rows
            .iter()
            .map(|(n, t)| (n.clone(), table_json(t)))
            .collect();
        obj.insert(
            "nll_interacting".into(),
            json!(
                self.nll_interacting
                    .iter()
                    .cloned()
                    .collect::<BTreeMap<String, Option<f64>>>()
            ),
        );
        serde_json::Value::Object(obj)
    }

    /// Markdown table in the layout of the paper's Table I (8 s values).
    pub fn to_markdown(&self) -> String {
        let mut out = String::from(
            "| mode (8 s) | ADE (m) | minADE (m) | minFDE (m) | MR (%) | mAP | objects |\n|---|---|---|---|---|---|---|\n",
        );
        for (name, t) in &self.rows {
            let m = &t.by_time[2].1;
            out += &format!(
                "| {name} | {} | {} | {} | {} | {} | {} |\n",
                fmt(m.ade, false),
                fmt(m.min_ade, false),
                fmt(m.min_fde, false),
                fmt(m.miss_rate, true),
                fmt(m.map, false),
                t.num_objects
            );
        }
        for (mode, v) in &self.nll_interacting {
            out += &format!(
                "\nNLL of the interacting agents' futures, {mode} mode: {}\n",
                v.map_or("-".into(), |v| format!("{v:.2}"))
            );
        }
        out
    }
}

/// Evaluates a checkpoint on a prepared cache (see `scbg eval predictor --help`).
pub fn evaluate_predictor(
    model_dir: &std::path::Path,
    data_dir: &std::path::Path,
    mode: &str,
    split: &str,
    current_thresholds: bool,
) -> anyhow::Result<PredictorEval> {
    let ckpt = Checkpoint::read(model_dir)?;
    let device = scbg_model::device::device(&ckpt.train_config.backend)?;
    let model = ckpt.load_model(model_dir, &device)?;
    let dataset = PreparedDataset::open(data_dir)?;
    let mut config = ckpt.train_config.clone();
    if split == "all" {
        config.validation_fraction = 0.0;
    }
    let (train, val) = scbg_train::data::load_samples(&dataset, &config)?;
    let raw: Vec<AgentSample> = if split == "all" {
        train.samples
    } else {
        val.samples
    };
    if raw.is_empty() {
        bail!(
            "no samples to evaluate in {} ({split} split)",
            data_dir.display()
        );
    }
    let mut norm = raw.clone();
    for s in &mut norm {
        ckpt.stats.normalize(s);
    }
    let thresholds = if current_thresholds {
        ClassifierThresholds::CURRENT
    } else {
        ClassifierThresholds::PRE_2024
    };
    let pair_idx: Vec<usize> = (0..raw.len()).filter(|&i| raw[i].has_condition()).collect();
    let pick =
        |idx: &[usize], v: &[AgentSample]| idx.iter().map(|&i| &v[i]).cloned().collect::<Vec<_>>();
    let (pair_raw, pair_norm) = (pick(&pair_idx, &raw), pick(&pair_idx, &norm));
    let pr: Vec<&AgentSample> = pair_raw.iter().collect();
    let pn: Vec<&AgentSample> = pair_norm.iter().collect();
    let bs = ckpt.train_config.batch_size;
    let mut rows: Vec<(String, MetricTable)> = Vec::new();
    if !pr.is_empty() {
        if mode != "conditional" {
            rows.push((
                "Marginal (interacting agents)".into(),
                score(
                    &predict(&model, &pn, Mode::Marginal, bs, &device),
                    &pr,
                    &thresholds,
                ),
            ));
        }
        if mode != "marginal" {
            rows.push((
                "Conditional (interacting agents)".into(),
                score(
                    &predict(&model, &pn, Mode::Conditional, bs, &device),
                    &pr,
                    &thresholds,
                ),
            ));
        }
        let cv: Vec<_> = pr.iter().map(|s| constant_velocity(s, 80)).collect();
        rows.push((
            "Const. velocity (interacting)".into(),
            score(&cv, &pr, &thresholds),
        ));
        let ctra: Vec<_> = pr.iter().map(|s| constant_yaw_rate_accel(s, 80)).collect();
        rows.push((
            "Const. yaw rate+accel (interacting)".into(),
            score(&ctra, &pr, &thresholds),
        ));
    }
    let all_raw: Vec<&AgentSample> = raw.iter().filter(|s| !s.has_condition()).collect();
    let all_norm: Vec<&AgentSample> = norm.iter().filter(|s| !s.has_condition()).collect();
    if !all_raw.is_empty() && mode != "conditional" {
        rows.push((
            "Marginal (all vehicle targets)".into(),
            score(
                &predict(&model, &all_norm, Mode::Marginal, bs, &device),
                &all_raw,
                &thresholds,
            ),
        ));
        let cv: Vec<_> = all_raw.iter().map(|s| constant_velocity(s, 80)).collect();
        rows.push((
            "Const. velocity (all targets)".into(),
            score(&cv, &all_raw, &thresholds),
        ));
    }
    let nll_interacting = if pn.is_empty() {
        Vec::new()
    } else {
        vec![
            (
                "marginal".into(),
                mean_nll(&model, &pn, Mode::Marginal, bs, &device),
            ),
            (
                "conditional".into(),
                mean_nll(&model, &pn, Mode::Conditional, bs, &device),
            ),
        ]
    };
    Ok(PredictorEval {
        rows,
        nll_interacting,
    })
}

pub fn predictor(args: &EvalPredictorArgs) -> anyhow::Result<()> {
    let eval = evaluate_predictor(
        &args.model,
        &args.data,
        &args.mode,
        &args.split,
        args.current_thresholds,
    )?;
    if args.json {
        println!("{}", eval.to_json());
    } else {
        print_table(&eval.rows);
        for (mode, v) in &eval.nll_interacting {
            println!(
                "NLL of the interacting agents' futures, {mode} mode: {}",
                v.map_or("-".into(), |v| format!("{v:.2}"))
            );
        }
    }
    Ok(())
}

/// One object's predictions in the external JSON schema.
#[derive(Debug, Deserialize)]
struct ExternalPrediction {
    scenario_id: String,
    object_id: i64,
    /// `[K][points][2]` world-frame positions: 80 points (10 Hz) or 16 (2 Hz).
    trajectories: Vec<Vec<[f32; 2]>>,
    scores: Vec<f32>,
}

#[derive(Debug, Deserialize)]
struct ExternalPredictions {
    predictions: Vec<ExternalPrediction>,
}

pub fn metrics(args: &EvalMetricsArgs) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.predictions)
        .with_context(|| format!("reading {}", args.predictions.display()))?;
    let preds: ExternalPredictions = serde_json::from_str(&text)
        .with_context(|| format!("parsing {}", args.predictions.display()))?;
    let mut scenes = BTreeMap::new();
    for path in inputs::expand(&args.scenarios)? {
        let file = scbg_womd::WomdFile::open(&path)?;
        for scene in file.scenes() {
            let scene = scene?;
            scenes.insert(scene.scenario_id.clone(), scene);
        }
    }
    let (mut ps, mut gs) = (Vec::new(), Vec::new());
    for (i, p) in preds.predictions.iter().enumerate() {
        let scene = scenes.get(&p.scenario_id).with_context(|| {
            format!(
                "prediction {i}: scenario {} is not in the given files",
                p.scenario_id
            )
        })?;
        let track = scene
            .tracks
            .iter()
            .find(|t| t.id == p.object_id)
            .with_context(|| {
                format!(
                    "prediction {i}: object {} is not in scenario {}",
                    p.object_id, p.scenario_id
                )
            })?;
        let now = scene.current_step;
        let cur = track.states[now];
        if !cur.valid {
            bail!(
                "prediction {i}: object {} is not valid at the current step of {}",
                p.object_id,
                p.scenario_id
            );
        }
        let points = p.trajectories.first().map_or(0, Vec::len);
        let step_indices = match points {
            80 => Prediction::steps_10hz(),
            16 => Prediction::steps_2hz(),
            n => bail!(
                "prediction {i}: trajectories have {n} points; expected 80 (10 Hz) or 16 (2 Hz)"
            ),
        };
        if p.trajectories.iter().any(|t| t.len() != points)
            || p.scores.len() != p.trajectories.len()
        {
            bail!("prediction {i}: every trajectory needs {points} points and one score each");
        }
        let future: Vec<scbg_scene::AgentState> = (1..=80)
            .map(|f| track.states.get(now + f).copied().unwrap_or_default())
            .collect();
        let rel = |x: f64, y: f64| [(x - cur.x_m) as f32, (y - cur.y_m) as f32];
        gs.push(GroundTruth {
            current_xy_m: [0.0, 0.0],
            current_heading_rad: cur.heading_rad,
            current_velocity_mps: [cur.velocity_x_mps, cur.velocity_y_mps],
            future_xy_m: future.iter().map(|s| rel(s.x_m, s.y_m)).collect(),
            future_heading_rad: future.iter().map(|s| s.heading_rad).collect(),
            future_velocity_mps: future
                .iter()
                .map(|s| [s.velocity_x_mps, s.velocity_y_mps])
                .collect(),
            future_valid: future.iter().map(|s| s.valid).collect(),
        });
        ps.push(Prediction {
            step_indices,
            trajectories: p
                .trajectories
                .iter()
                .map(|t| {
                    t.iter()
                        .map(|q| [q[0] - cur.x_m as f32, q[1] - cur.y_m as f32])
                        .collect()
                })
                .collect(),
            scores: p.scores.clone(),
        });
    }
    let thresholds = if args.current_thresholds {
        ClassifierThresholds::CURRENT
    } else {
        ClassifierThresholds::PRE_2024
    };
    let table = scbg_metrics::evaluate(&ps, &gs, &thresholds);
    if args.json {
        println!("{}", table_json(&table));
    } else {
        println!(
            "{:<6} {:>8} {:>8} {:>8} {:>7} {:>7} {:>8}",
            "time", "ADE", "minADE", "minFDE", "MR %", "mAP", "softmAP"
        );
        for (label, m) in table
            .by_time
            .iter()
            .map(|(s, m)| (format!("{s} s"), m))
            .chain(std::iter::once(("mean".to_string(), &table.mean)))
        {
            println!(
                "{:<6} {:>8} {:>8} {:>8} {:>7} {:>7} {:>8}",
                label,
                fmt(m.ade, false),
                fmt(m.min_ade, false),
                fmt(m.min_fde, false),
                fmt(m.miss_rate, true),
                fmt(m.map, false),
                fmt(m.soft_map, false)
            );
        }
    }
    Ok(())
}
