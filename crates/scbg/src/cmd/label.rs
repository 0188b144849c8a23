//! `scbg label`: courtesy auto-labelling (paper Sec. III-C, Fig. 3) written as Parquet.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, bail};
use arrow_array::{ArrayRef, Float32Array, Int64Array, RecordBatch, StringArray, UInt32Array};
use arrow_schema::{DataType, Field, Schema};
use rand::SeedableRng;
use scbg_courtesy::Reward;
use scbg_courtesy::label::{LabelOptions, MarginalEstimate, label_pair, marginal_mixtures};
use scbg_features::SampleBuilder;
use scbg_features::cache::{PreparedDataset, Shard};
use scbg_train::Checkpoint;
use serde_json::json;

use crate::cli::{EstimatorArgs, LabelArgs};
use crate::progress;

/// One labelled future of B for target A.
#[derive(Debug, Clone)]
pub struct LabelRow {
    pub scenario_id: String,
    pub window_step: u32,
    pub a_id: i64,
    pub b_id: i64,
    /// 0 = logged future, 1.. = sampled from B's marginal prediction.
    pub sample: u32,
    pub psi: f32,
    pub e_marg: f32,
    pub e_cond: f32,
}

fn schema() -> Arc<Schema> {
    Arc::new(Schema::new(vec![
        Field::new("scenario_id", DataType::Utf8, false),
        Field::new("window_step", DataType::UInt32, false),
        Field::new("a_id", DataType::Int64, false),
        Field::new("b_id", DataType::Int64, false),
        Field::new("sample", DataType::UInt32, false),
        Field::new("psi", DataType::Float32, false),
        Field::new("e_marg", DataType::Float32, false),
        Field::new("e_cond", DataType::Float32, false),
    ]))
}

/// Writes rows as Parquet via a temporary file renamed into place.
pub fn write_parquet(path: &Path, rows: &[LabelRow]) -> anyhow::Result<()> {
    let schema = schema();
    let columns: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from(
            rows.iter()
                .map(|r| r.scenario_id.as_str())
                .collect::<Vec<_>>(),
        )),
        Arc::new(UInt32Array::from(
            rows.iter().map(|r| r.window_step).collect::<Vec<_>>(),
        )),
        Arc::new(Int64Array::from(
            rows.iter().map(|r| r.a_id).collect::<Vec<_>>(),
        )),
        Arc::new(Int64Array::from(
            rows.iter().map(|r| r.b_id).collect::<Vec<_>>(),
        )),
        Arc::new(UInt32Array::from(
            rows.iter().map(|r| r.sample).collect::<Vec<_>>(),
        )),
        Arc::new(Float32Array::from(
            rows.iter().map(|r| r.psi).collect::<Vec<_>>(),
        )),
        Arc::new(Float32Array::from(
            rows.iter().map(|r| r.e_marg).collect::<Vec<_>>(),
        )),
        Arc::new(Float32Array::from(
            rows.iter().map(|r| r.e_cond).collect::<Vec<_>>(),
        )),
    ];
    let batch = RecordBatch::try_new(schema.clone(), columns)?;
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let tmp = tempfile::NamedTempFile::new_in(dir)?;
    let mut writer = parquet::arrow::ArrowWriter::try_new(tmp, schema, None)?;
    writer.write(&batch)?;
    let tmp = writer.into_inner()?;
    tmp.persist(path)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Reads rows back (for the summary, resumed shards and tests).
pub fn read_parquet(path: &Path) -> anyhow::Result<Vec<LabelRow>> {
    use arrow_array::Array;
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let reader =
        parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)?.build()?;
    let mut rows = Vec::new();
    for batch in reader {
        let b = batch?;
        let col = |name: &str| {
            b.column_by_name(name)
                .with_context(|| format!("{}: no column {name}", path.display()))
                .cloned()
        };
        let ids = col("scenario_id")?;
        let ids = ids
            .as_any()
            .downcast_ref::<StringArray>()
            .context("scenario_id type")?;
        let ws = col("window_step")?;
        let ws = ws
            .as_any()
            .downcast_ref::<UInt32Array>()
            .context("window_step type")?;
        let a = col("a_id")?;
        let a = a
            .as_any()
            .downcast_ref::<Int64Array>()
            .context("a_id type")?;
        let bb = col("b_id")?;
        let bb = bb
            .as_any()
            .downcast_ref::<Int64Array>()
            .context("b_id type")?;
        let s = col("sample")?;
        let s = s
            .as_any()
            .downcast_ref::<UInt32Array>()
            .context("sample type")?;
        let f = |n: &str| -> anyhow::Result<Float32Array> {
            Ok(col(n)?
                .as_any()
                .downcast_ref::<Float32Array>()
                .context("f32 column")?
                .clone())
        };
        let (psi, em, ec) = (f("psi")?, f("e_marg")?, f("e_cond")?);
        for i in 0..b.num_rows() {
            rows.push(LabelRow {
                scenario_id: ids.value(i).to_string(),
                window_step: ws.value(i),
                a_id: a.value(i),
                b_id: bb.value(i),
                sample: s.value(i),
                psi: psi.value(i),
                e_marg: em.value(i),
                e_cond: ec.value(i),
            });
        }
        let _ = ids.len();
    }
    Ok(rows)
}

fn label_shard(
    shard: &Shard,
    ckpt: &Checkpoint,
    model: &scbg_model::Multipath,
    args: &LabelArgs,
    options: LabelOptions,
    shard_index: usize,
    pb: &indicatif::ProgressBar,
) -> anyhow::Result<Vec<LabelRow>> {
    let device = scbg_model::device::device(&ckpt.train_config.backend)?;
    let features = ckpt.train_config.feature_config();
    let mut rows = Vec::new();
    for i in 0..shard.len() {
        let scene = shard.get(i)?;
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(scbg_train::trainer::mix(
            args.seed,
            (shard_index as u64) << 32 | i as u64,
        ));
        let mut builder = SampleBuilder::new(&scene, &features);
        for (w, pairs) in scene.windows.iter().zip(&scene.pairs) {
            for p in pairs {
                for (a, b) in [(p.first, p.second), (p.second, p.first)] {
                    let (Ok(mut sa), Ok(mut sb)) =
                        (builder.sample(w, a, Some(b)), builder.sample(w, b, None))
                    else {
                        continue;
                    };
                    ckpt.stats.normalize(&mut sa);
                    ckpt.stats.normalize(&mut sb);
                    let mixture = marginal_mixtures(model, &[&sb], &device).remove(0);
                    let labels = label_pair(model, &sa, &sb, &mixture, options, &mut rng, &device);
                    for (k, psi) in labels.psi.iter().enumerate() {
                        rows.push(LabelRow {
                            scenario_id: scene.scenario_id.clone(),
                            window_step: w.current_step as u32,
                            a_id: scene.tracks[a].id,
                            b_id: scene.tracks[b].id,
                            sample: k as u32,
                            psi: *psi,
                            e_marg: labels.e_marg,
                            e_cond: labels.e_cond[k],
                        });
                    }
                }
            }
        }
        pb.inc(1);
    }
    Ok(rows)
}

/// Latent courtesy and family per scenario from a synthetic ground-truth sidecar.
fn read_ground_truth(path: &Path) -> anyhow::Result<BTreeMap<String, (String, i64, i64, f64)>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut out = BTreeMap::new();
    for (i, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let v: serde_json::Value = serde_json::from_str(line)
            .with_context(|| format!("{}: line {}", path.display(), i + 1))?;
        let get = |k: &str| {
            v.get(k)
                .with_context(|| format!("{}: line {}: no `{k}`", path.display(), i + 1))
        };
        out.insert(
            get("scenario_id")?
                .as_str()
                .context("scenario_id")?
                .to_string(),
            (
                get("family")?.as_str().context("family")?.to_string(),
                get("a_id")?.as_i64().context("a_id")?,
                get("b_id")?.as_i64().context("b_id")?,
                get("courtesy")?.as_f64().context("courtesy")?,
            ),
        );
    }
    Ok(out)
}

/// Spearman(ψ of the logged y_B with roles (A, B) as labelled, latent courtesy) per family.
pub fn spearman_latent(
    rows: &[LabelRow],
    truth: &BTreeMap<String, (String, i64, i64, f64)>,
) -> BTreeMap<String, (Option<f64>, usize)> {
    let mut by_family: BTreeMap<String, (Vec<f64>, Vec<f64>)> = BTreeMap::new();
    for r in rows.iter().filter(|r| r.sample == 0) {
        if let Some((family, a, b, c)) = truth.get(&r.scenario_id)
            && r.a_id == *a
            && r.b_id == *b
        {
            let e = by_family.entry(family.clone()).or_default();
            e.0.push(f64::from(r.psi));
            e.1.push(*c);
        }
    }
    by_family
        .into_iter()
        .map(|(f, (x, y))| (f, (scbg_metrics::spearman(&x, &y), x.len())))
        .collect()
}

/// The summary `scbg label` prints and writes to summary.json.
#[derive(Debug)]
pub struct LabelSummary {
    pub rows: Vec<LabelRow>,
    pub spearman_latent: BTreeMap<String, (Option<f64>, usize)>,
}

/// The spread of ψ that B's future causes: the square root of the mean, over pair roles, of
/// the variance of ψ across that role's futures (logged and sampled). When it is small next to
/// the overall std, ψ says more about the scene than about what B does.
pub fn within_pair_std(rows: &[LabelRow]) -> f64 {
    let mut groups: BTreeMap<(&str, u32, i64, i64), Vec<f64>> = BTreeMap::new();
    for r in rows {
        groups
            .entry((r.scenario_id.as_str(), r.window_step, r.a_id, r.b_id))
            .or_default()
            .push(f64::from(r.psi));
    }
    let vars: Vec<f64> = groups
        .values()
        .filter(|v| v.len() > 1)
        .map(|v| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64
        })
        .collect();
    (vars.iter().sum::<f64>() / vars.len().max(1) as f64).sqrt()
}

/// `--marginal direct|conditional-average`.
pub fn parse_marginal(text: &str) -> anyhow::Result<MarginalEstimate> {
    MarginalEstimate::parse(text)
        .with_context(|| format!("--marginal {text:?}: expected direct or conditional-average"))
}

/// The labelling options of `--marginal` and `--sample-noise` (a finite scale ≥ 0).
pub fn label_options(
    estimator: &EstimatorArgs,
    samples: usize,
    reward: Reward,
) -> anyhow::Result<LabelOptions> {
    let noise = estimator.sample_noise;
    anyhow::ensure!(
        noise.is_finite() && noise >= 0.0,
        "--sample-noise {noise}: expected a finite number >= 0"
    );
    Ok(LabelOptions {
        samples,
        reward,
        marginal: parse_marginal(&estimator.marginal)?,
        sample_noise: noise,
    })
}

pub fn label(args: &LabelArgs) -> anyhow::Result<LabelSummary> {
    let reward = Reward::parse(&args.reward)
        .with_context(|| format!("unknown reward {:?} (average_speed, progress)", args.reward))?;
    let options = label_options(&args.estimator, args.samples, reward)?;
    let ckpt = Checkpoint::read(&args.model)?;
    let device = scbg_model::device::device(&ckpt.train_config.backend)?;
    let model = ckpt.load_model(&args.model, &device)?;
    let dataset = PreparedDataset::open(&args.data)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let total: u64 = dataset
        .manifest
        .shards
        .iter()
        .map(|s| s.scenarios as u64)
        .sum();
    let pb = progress::bar(total, "label");
    let mut rows = Vec::new();
    for (si, entry) in dataset.manifest.shards.iter().enumerate() {
        let out_path: PathBuf = args.out.join(format!("labels-{si:05}.parquet"));
        if out_path.is_file() {
            rows.extend(read_parquet(&out_path)?);
            pb.inc(entry.scenarios as u64);
            continue;
        }
        let shard = Shard::open(&args.data.join(&entry.file))?;
        let shard_rows = label_shard(&shard, &ckpt, &model, args, options, si, &pb)?;
        write_parquet(&out_path, &shard_rows)?;
        rows.extend(shard_rows);
    }
    pb.finish_and_clear();
    if rows.is_empty() {
        bail!("no interacting pairs to label in {}", args.data.display());
    }
    let logged: Vec<f64> = rows
        .iter()
        .filter(|r| r.sample == 0)
        .map(|r| f64::from(r.psi))
        .collect();
    let all: Vec<f64> = rows.iter().map(|r| f64::from(r.psi)).collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let std = |v: &[f64]| {
        (v.iter().map(|x| (x - mean(v)).powi(2)).sum::<f64>() / v.len().max(1) as f64).sqrt()
    };
    let high = all.iter().filter(|p| p.abs() > 2.0).count();
    let within = within_pair_std(&rows);
    scbg_plot::histogram(
        &logged,
        40,
        "courtesy ψ of logged trajectories (m/s)",
        &args.out.join("psi_histogram.png"),
    )?;
    let spearman = match &args.ground_truth {
        Some(p) => spearman_latent(&rows, &read_ground_truth(p)?),
        None => BTreeMap::new(),
    };
    let summary = json!({
        "rows": rows.len(),
        "pairs_roles": logged.len(),
        "samples_per_pair": args.samples,
        "reward": reward.name(),
        "marginal": options.marginal.name(),
        "sample_noise": options.sample_noise,
        "psi_logged": {"mean": mean(&logged), "std": std(&logged)},
        "psi_within_pair_std": within,
        "psi_all": {"mean": mean(&all), "std": std(&all), "min": all.iter().copied().fold(f64::INFINITY, f64::min), "max": all.iter().copied().fold(f64::NEG_INFINITY, f64::max), "fraction_abs_gt_2": high as f64 / all.len() as f64},
        "spearman_latent": spearman.iter().map(|(f, (rho, n))| (f.clone(), json!({"rho": rho, "n": n}))).collect::<serde_json::Map<_, _>>(),
    });
    scbg_features::cache::write_json_atomic(&args.out.join("summary.json"), &summary)?;
    eprintln!(
        "labelled {} futures ({} pair roles × {} each); ψ of logged futures: mean {:.3}, std {:.3}; std within a pair role {:.3}; |ψ| > 2 for {:.1} % of all",
        rows.len(),
        logged.len(),
        1 + args.samples,
        mean(&logged),
        std(&logged),
        within,
        100.0 * high as f64 / all.len() as f64
    );
    for (family, (rho, n)) in &spearman {
        eprintln!(
            "Spearman(ψ, latent courtesy) {family}: {} (n = {n})",
            rho.map_or("-".into(), |r| format!("{r:.3}"))
        );
    }
    Ok(LabelSummary {
        rows,
        spearman_latent: spearman,
    })
}
