//! The Multipath++ predictor (paper Sec. III-B): training from a TOML config, the evaluation
//! beside the baselines (paper Table I) and the Waymo metrics of external predictions.

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Context;
use scbg_features::AgentSample;
use scbg_features::cache::PreparedDataset;
use scbg_metrics::{ClassifierThresholds, GroundTruth, MetricTable, Metrics, Prediction};
use scbg_model::Mode;
use scbg_train::eval::{constant_velocity, constant_yaw_rate_accel, mean_nll, predict, score};
use scbg_train::{Checkpoint, EpochReport};
use serde::ser::SerializeMap;
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::{Bar, InvalidRequest, Progress, ensure_request, inputs};

pub use scbg_train::TrainConfig;

/// Which modes of the predictor an evaluation reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum ModeSelection {
    /// Marginal only.
    Marginal,
    /// Conditional only.
    Conditional,
    /// Both (default).
    #[default]
    Both,
}

impl ModeSelection {
    fn includes(self, mode: Mode) -> bool {
        match self {
            Self::Both => true,
            Self::Marginal => mode == Mode::Marginal,
            Self::Conditional => mode == Mode::Conditional,
        }
    }
}

/// Which scenes an evaluation covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum SplitSelection {
    /// The held-out split by scenario id, as in training (default).
    #[default]
    Validation,
    /// Every scene.
    All,
}

impl SplitSelection {
    /// The training split it selects (`None` = every scene).
    pub fn split(self) -> Option<scbg_train::data::Split> {
        match self {
            Self::Validation => Some(scbg_train::data::Split::Validation),
            Self::All => None,
        }
    }
}

/// The trajectory-classifier thresholds of the mAP buckets: Waymo's current set, or the
/// pre-2024 one (default).
pub fn thresholds(current: bool) -> ClassifierThresholds {
    if current {
        ClassifierThresholds::CURRENT
    } else {
        ClassifierThresholds::PRE_2024
    }
}

/// A metric for a table: 3 decimals, or a percentage with 1; `-` when undefined.
pub fn fmt(v: Option<f32>, pct: bool) -> String {
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

/// Rows shaped like the paper's Table I (8 s values) plus the 3/5/8 s mean of minADE and MR,
/// as fixed-width text.
pub fn table_text(rows: &[(String, MetricTable)]) -> String {
    let mut out = format!(
        "{:<34} {:>8} {:>8} {:>8} {:>7} {:>7} | {:>12} {:>8} {:>7}\n",
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
        out += &format!(
            "{:<34} {:>8} {:>8} {:>8} {:>7} {:>7} | {:>12} {:>8} {:>7}\n",
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
    out
}

/// The predictor evaluation: metric rows (model modes and baselines) and the NLL of the
/// interacting agents' futures in each mode.
#[derive(Debug, Clone)]
pub struct PredictorEval {
    /// (row name, metrics), model modes first, then the baselines.
    pub rows: Vec<(String, MetricTable)>,
    /// (mode, mean NLL of the interacting agents' futures).
    pub nll_interacting: Vec<(String, Option<f64>)>,
}

impl Serialize for PredictorEval {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut map = serializer.serialize_map(Some(self.rows.len() + 1))?;
        for (name, table) in &self.rows {
            map.serialize_entry(name, &table_json(table))?;
        }
        let nll: BTreeMap<&str, Option<f64>> = self
            .nll_interacting
            .iter()
            .map(|(m, v)| (m.as_str(), *v))
            .collect();
        map.serialize_entry("nll_interacting", &nll)?;
        map.end()
    }
}

impl PredictorEval {
    /// `{<row name>: {ade, …, by_time}, nll_interacting: {mode: nll}}`.
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

/// Evaluates a checkpoint on a prepared cache: the model's modes on the interacting agents and
/// on every vehicle target, beside constant velocity and constant yaw rate + acceleration.
pub fn evaluate_predictor(
    model_dir: &Path,
    data_dir: &Path,
    modes: ModeSelection,
    split: SplitSelection,
    thresholds: &ClassifierThresholds,
) -> anyhow::Result<PredictorEval> {
    let ckpt = Checkpoint::read(model_dir)?;
    let device = scbg_model::device::device(&ckpt.train_config.backend)?;
    let model = ckpt.load_model(model_dir, &device)?;
    let dataset = PreparedDataset::open(data_dir)?;
    let mut config = ckpt.train_config.clone();
    // Only the scenes of `data_dir`: the sibling caches the model trained with are training
    // data (and need not exist where the model is evaluated).
    config.counterfactual_cache = None;
    config.reaction_cache = None;
    let all = split == SplitSelection::All;
    if all {
        config.validation_fraction = 0.0;
    }
    let (train, val) = scbg_train::data::load_samples(&dataset, &config)?;
    let raw: Vec<AgentSample> = if all { train.samples } else { val.samples };
    ensure_request!(
        !raw.is_empty(),
        "no samples to evaluate in {} ({split:?} split)",
        data_dir.display()
    );
    let mut norm = raw.clone();
    for s in &mut norm {
        ckpt.stats.normalize(s);
    }
    let pair_idx: Vec<usize> = (0..raw.len()).filter(|&i| raw[i].has_condition()).collect();
    let pick =
        |idx: &[usize], v: &[AgentSample]| idx.iter().map(|&i| &v[i]).cloned().collect::<Vec<_>>();
    let (pair_raw, pair_norm) = (pick(&pair_idx, &raw), pick(&pair_idx, &norm));
    let pr: Vec<&AgentSample> = pair_raw.iter().collect();
    let pn: Vec<&AgentSample> = pair_norm.iter().collect();
    let bs = ckpt.train_config.batch_size;
    let mut rows: Vec<(String, MetricTable)> = Vec::new();
    if !pr.is_empty() {
        if modes.includes(Mode::Marginal) {
            rows.push((
                "Marginal (interacting agents)".into(),
                score(
                    &predict(&model, &pn, Mode::Marginal, bs, &device),
                    &pr,
                    thresholds,
                ),
            ));
        }
        if modes.includes(Mode::Conditional) {
            rows.push((
                "Conditional (interacting agents)".into(),
                score(
                    &predict(&model, &pn, Mode::Conditional, bs, &device),
                    &pr,
                    thresholds,
                ),
            ));
        }
        let cv: Vec<_> = pr.iter().map(|s| constant_velocity(s, 80)).collect();
        rows.push((
            "Const. velocity (interacting)".into(),
            score(&cv, &pr, thresholds),
        ));
        let ctra: Vec<_> = pr.iter().map(|s| constant_yaw_rate_accel(s, 80)).collect();
        rows.push((
            "Const. yaw rate+accel (interacting)".into(),
            score(&ctra, &pr, thresholds),
        ));
    }
    let all_raw: Vec<&AgentSample> = raw.iter().filter(|s| !s.has_condition()).collect();
    let all_norm: Vec<&AgentSample> = norm.iter().filter(|s| !s.has_condition()).collect();
    if !all_raw.is_empty() && modes.includes(Mode::Marginal) {
        rows.push((
            "Marginal (all vehicle targets)".into(),
            score(
                &predict(&model, &all_norm, Mode::Marginal, bs, &device),
                &all_raw,
                thresholds,
            ),
        ));
        let cv: Vec<_> = all_raw.iter().map(|s| constant_velocity(s, 80)).collect();
        rows.push((
            "Const. velocity (all targets)".into(),
            score(&cv, &all_raw, thresholds),
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

/// One object's predictions in the external JSON schema.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
pub struct ExternalPrediction {
    /// The scenario.
    pub scenario_id: String,
    /// The track id predicted.
    pub object_id: i64,
    /// `[K][points][2]` world-frame positions: 80 points (10 Hz) or 16 (2 Hz).
    pub trajectories: Vec<Vec<[f32; 2]>>,
    /// `[K]` confidence of each trajectory.
    pub scores: Vec<f32>,
}

/// The external predictions file: `{"predictions": [...]}`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
pub struct ExternalPredictions {
    /// One entry per predicted object.
    pub predictions: Vec<ExternalPrediction>,
}

/// The Waymo motion metrics of external predictions (`predictions`, JSON) against the
/// scenarios of `scenarios` (files, folders or globs). A prediction that names a missing
/// scenario or object, or has the wrong shape, is an error naming it.
pub fn evaluate_external(
    scenarios: &[String],
    predictions: &Path,
    thresholds: &ClassifierThresholds,
) -> anyhow::Result<MetricTable> {
    let text = std::fs::read_to_string(predictions)
        .with_context(|| format!("reading {}", predictions.display()))?;
    let preds: ExternalPredictions = serde_json::from_str(&text)
        .with_context(|| format!("parsing {}", predictions.display()))?;
    let bad = |text: String| anyhow::Error::new(InvalidRequest(text));
    let mut scenes = BTreeMap::new();
    for path in inputs::expand(scenarios)? {
        let file = scbg_womd::WomdFile::open(&path)?;
        for scene in file.scenes() {
            let scene = scene?;
            scenes.insert(scene.scenario_id.clone(), scene);
        }
    }
    let (mut ps, mut gs) = (Vec::new(), Vec::new());
    for (i, p) in preds.predictions.iter().enumerate() {
        let scene = scenes.get(&p.scenario_id).ok_or_else(|| {
            bad(format!(
                "prediction {i}: scenario {} is not in the given files",
                p.scenario_id
            ))
        })?;
        let track = scene
            .tracks
            .iter()
            .find(|t| t.id == p.object_id)
            .ok_or_else(|| {
                bad(format!(
                    "prediction {i}: object {} is not in scenario {}",
                    p.object_id, p.scenario_id
                ))
            })?;
        let now = scene.current_step;
        let cur = track.states[now];
        ensure_request!(
            cur.valid,
            "prediction {i}: object {} is not valid at the current step of {}",
            p.object_id,
            p.scenario_id
        );
        let points = p.trajectories.first().map_or(0, Vec::len);
        let step_indices = match points {
            80 => Prediction::steps_10hz(),
            16 => Prediction::steps_2hz(),
            n => {
                return Err(bad(format!(
                    "prediction {i}: trajectories have {n} points; expected 80 (10 Hz) or 16 (2 Hz)"
                )));
            }
        };
        ensure_request!(
            p.trajectories.iter().all(|t| t.len() == points)
                && p.scores.len() == p.trajectories.len(),
            "prediction {i}: every trajectory needs {points} points and one score each"
        );
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
    Ok(scbg_metrics::evaluate(&ps, &gs, thresholds))
}

/// The `scbg eval metrics` table: 3/5/8 s rows and their mean.
pub fn metrics_text(table: &MetricTable) -> String {
    let mut out = format!(
        "{:<6} {:>8} {:>8} {:>8} {:>7} {:>7} {:>8}\n",
        "time", "ADE", "minADE", "minFDE", "MR %", "mAP", "softmAP"
    );
    for (label, m) in table
        .by_time
        .iter()
        .map(|(s, m)| (format!("{s} s"), m))
        .chain(std::iter::once(("mean".to_string(), &table.mean)))
    {
        out += &format!(
            "{:<6} {:>8} {:>8} {:>8} {:>7} {:>7} {:>8}\n",
            label,
            fmt(m.ade, false),
            fmt(m.min_ade, false),
            fmt(m.min_fde, false),
            fmt(m.miss_rate, true),
            fmt(m.map, false),
            fmt(m.soft_map, false)
        );
    }
    out
}

/// Reads a TOML training config (missing keys take their defaults); `None` = all defaults.
pub fn load_train_config(path: Option<&Path>) -> anyhow::Result<TrainConfig> {
    match path {
        Some(p) => {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            TrainConfig::from_toml(&text).with_context(|| format!("in {}", p.display()))
        }
        None => Ok(TrainConfig::default()),
    }
}

/// A training config as TOML (the demo writes the one it uses beside the checkpoint).
pub fn train_config_toml(config: &TrainConfig) -> anyhow::Result<String> {
    // `model = None` uses the preset; TOML has no null, so the key is simply left out.
    let mut value = serde_json::to_value(config)?;
    if let Some(obj) = value.as_object_mut() {
        obj.retain(|_, v| !v.is_null());
    }
    let text: toml::Value = serde_json::from_value(value)?;
    Ok(toml::to_string(&text)?)
}

/// Adapts a [`Progress`] to the trainer's epoch callbacks: a bar and a note per epoch.
struct EpochProgress<'a> {
    progress: &'a dyn Progress,
    bar: RefCell<Option<Box<dyn Bar + 'a>>>,
    /// Epochs done so far, and the count after which training stops (if any).
    done: std::cell::Cell<usize>,
    until: Option<usize>,
}

impl scbg_train::Progress for EpochProgress<'_> {
    fn epoch_start(&self, epoch: usize, batches: usize) {
        *self.bar.borrow_mut() = Some(self.progress.bar(&format!("epoch {epoch}"), batches as u64));
    }
    fn batch_done(&self, loss: f64) {
        if let Some(pb) = self.bar.borrow().as_ref() {
            pb.set_message(format!("loss {loss:.3}"));
            pb.inc(1);
        }
    }
    fn stop_requested(&self) -> bool {
        self.until.is_some_and(|until| self.done.get() >= until)
    }
    fn epoch_end(&self, r: &EpochReport) {
        self.done.set(r.epoch + 1);
        self.bar.borrow_mut().take();
        self.progress.note(&format!(
            "epoch {:>3}: train loss {:.3}  val NLL {}  val minADE@8s {}  lr {:.2e}  skipped {}  {:.1}s",
            r.epoch,
            r.train_loss,
            r.val_loss.map_or("-".into(), |v| format!("{v:.3}")),
            r.val_min_ade_8s.map_or("-".into(), |v| format!("{v:.2} m")),
            r.learning_rate,
            r.skipped_batches,
            r.seconds
        ));
    }
}

/// Trains the predictor on the cache `data` into the checkpoint folder `out` (`resume`
/// continues from the checkpoint there, to the same weights an uninterrupted run reaches).
pub fn train_predictor(
    data: &Path,
    out: &Path,
    config: &TrainConfig,
    resume: bool,
    progress: &dyn Progress,
) -> anyhow::Result<Checkpoint> {
    train_predictor_until(data, out, config, resume, None, progress)
}

/// [`train_predictor`] that stops once `until` epochs are done (if given), as an
/// interruption would: `resume` continues from there (e.g. once a
/// [`scbg_train::TrainConfig::reaction_cache`] joining at that epoch is made from the
/// checkpoint).
pub fn train_predictor_until(
    data: &Path,
    out: &Path,
    config: &TrainConfig,
    resume: bool,
    until: Option<usize>,
    progress: &dyn Progress,
) -> anyhow::Result<Checkpoint> {
    let model = config.model_config()?;
    progress.note(&format!(
        "model: {} ({} parameters), backend {}",
        config.preset,
        model.num_params(),
        config.backend
    ));
    let ckpt = scbg_train::train(
        data,
        out,
        config,
        resume,
        &EpochProgress {
            progress,
            bar: RefCell::new(None),
            done: Default::default(),
            until,
        },
    )?;
    progress.note(&format!(
        "checkpoint after epoch {} in {}",
        ckpt.state.epoch,
        out.display()
    ));
    Ok(ckpt)
}
