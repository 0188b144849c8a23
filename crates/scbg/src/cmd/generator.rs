//! `scbg train generator`, `scbg generate`, and the loading they share with `scbg eval scbg`
//! and the demo.

use std::path::{Path, PathBuf};

use anyhow::Context;
use burn::module::Module;
use burn::tensor::Device;
use rand::SeedableRng;
use scbg_courtesy::Reward;
use scbg_courtesy::label::LabelOptions;
use scbg_generator::{
    Example, GeneratorConfig, RangePredictor, Scbg, StepOptions, Threshold, Variant,
};
use scbg_model::Multipath;
use scbg_train::Checkpoint;
use scbg_train::data::{Split, split_of};

use crate::cli::{GenerateArgs, TrainGeneratorArgs};
use crate::progress;

/// Weights of the generator and the range predictor, and what they were trained with
/// (generator.json beside generator.bpk and range.bpk).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct GeneratorCheckpoint {
    pub variant: String,
    /// The predictor checkpoint folder (its encoder is frozen in the generator; it is J_φ).
    pub predictor: String,
    pub generator: GeneratorConfig,
    pub range_hidden: usize,
    pub samples: usize,
    pub alpha: f32,
    pub beta: f32,
    pub threshold: String,
    /// How the labels estimated E[r(Y_A) | x] (`direct` or `conditional-average`).
    #[serde(default = "direct")]
    pub marginal: String,
    /// Scale of the Gaussian part of B's sampled futures in the labels.
    #[serde(default = "one")]
    pub sample_noise: f32,
    /// |ψ| above which a logged future counted as high courtesy in training.
    #[serde(default)]
    pub threshold_psi: f32,
    /// Smallest and largest ψ label in training (the *arbitrary* range of the evaluation).
    #[serde(default)]
    pub psi_min: f32,
    #[serde(default)]
    pub psi_max: f32,
    pub seed: u64,
    /// Mean total / trajectory / courtesy loss per epoch.
    pub history: Vec<[f32; 3]>,
    pub range_loss: f32,
    pub examples: usize,
    #[serde(default)]
    pub seconds: f64,
}

pub const GENERATOR_JSON: &str = "generator.json";

fn direct() -> String {
    "direct".into()
}

fn one() -> f32 {
    1.0
}

impl GeneratorCheckpoint {
    /// The labelling settings the generator was trained with.
    pub fn label_options(&self) -> anyhow::Result<LabelOptions> {
        Ok(LabelOptions {
            samples: self.samples,
            reward: Reward::AverageSpeed,
            marginal: super::label::parse_marginal(&self.marginal)?,
            sample_noise: self.sample_noise,
        })
    }
}

/// The trained predictor twice: frozen on the autodiff device (J_φ passes gradients to ŷ) and
/// on the plain device (labels, embeddings, evaluation).
pub struct Predictors {
    pub dir: PathBuf,
    pub ckpt: Checkpoint,
    pub device: Device,
    pub frozen: Multipath,
    pub plain_device: Device,
    pub plain: Multipath,
}

pub fn load_predictors(dir: &Path) -> anyhow::Result<Predictors> {
    let ckpt = Checkpoint::read(dir)?;
    let device = scbg_model::device::training_device(&ckpt.train_config.backend)?;
    let frozen = ckpt.load_model(dir, &device)?.no_grad();
    let plain_device = scbg_model::device::device(&ckpt.train_config.backend)?;
    let plain = ckpt.load_model(dir, &plain_device)?;
    Ok(Predictors {
        dir: dir.to_path_buf(),
        ckpt,
        device,
        frozen,
        plain_device,
        plain,
    })
}

/// Labelled examples of every pair role in one split of a prepared cache (the split by
/// scenario id that the predictor was trained with; `None` = every scene). Run on the plain
/// device.
pub fn examples_for_split(
    predictor: &Multipath,
    ckpt: &Checkpoint,
    device: &Device,
    data: &Path,
    split: Option<Split>,
    labels: LabelOptions,
    seed: u64,
) -> anyhow::Result<Vec<Example>> {
    let dataset = scbg_features::cache::PreparedDataset::open(data)?;
    let vf = ckpt.train_config.validation_fraction;
    let features = ckpt.train_config.feature_config();
    let pb = progress::bar(dataset.len() as u64, "label");
    let mut out = Vec::new();
    for i in 0..dataset.len() {
        let scene = dataset.scene(i)?;
        pb.inc(1);
        if split.is_some_and(|split| split_of(&scene.scenario_id, vf) != split) {
            continue;
        }
        // One scene at a time for the progress bar; the seed depends on the scene's index only.
        out.extend(scbg_generator::build_examples(
            predictor,
            std::slice::from_ref(&scene),
            &ckpt.stats,
            &features,
            labels,
            seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            device,
        ));
    }
    pb.finish_and_clear();
    Ok(out)
}

/// Training settings of one variant.
#[derive(Debug, Clone)]
pub struct VariantSettings {
    pub variant: Variant,
    pub epochs: usize,
    pub batch_size: usize,
    pub alpha: f32,
    pub beta: f32,
    /// `qX` (quantile of the logged |ψ|) or a number in m/s.
    pub threshold: String,
    pub learning_rate: f64,
    pub range_steps: usize,
    pub seed: u64,
    /// How the examples were labelled (recorded in generator.json).
    pub labels: LabelOptions,
}

pub fn variant_name(v: Variant) -> &'static str {
    match v {
        Variant::Baseline => "baseline",
        Variant::Augmented => "aug",
        Variant::Full => "full",
    }
}

pub fn parse_variant(text: &str) -> anyhow::Result<Variant> {
    match text {
        "baseline" => Ok(Variant::Baseline),
        "aug" => Ok(Variant::Augmented),
        "full" => Ok(Variant::Full),
        _ => anyhow::bail!("unknown variant {text:?} (baseline, aug or full)"),
    }
}

pub fn parse_threshold(text: &str) -> anyhow::Result<Threshold> {
    match text.strip_prefix('q') {
        Some(q) => {
            let q: f32 = q
                .parse()
                .with_context(|| format!("--threshold {text:?}: expected qX with X in [0, 1]"))?;
            anyhow::ensure!(
                (0.0..=1.0).contains(&q),
                "--threshold {text:?}: quantile outside [0, 1]"
            );
            Ok(Threshold::Quantile(q))
        }
        None => Ok(Threshold::Absolute(text.parse().with_context(|| {
            format!("--threshold {text:?}: expected a number or qX")
        })?)),
    }
}

/// Spread of the labels (population std over every ψ, logged and sampled); the generator's
/// `psi_scale`.
fn psi_spread(examples: &[Example]) -> f32 {
    let all: Vec<f64> = examples
        .iter()
        .flat_map(|e| e.psi.iter().map(|&v| f64::from(v)))
        .collect();
    scbg_generator::eval::MeanStd::of(&all).map_or(1.0, |m| m.std.max(1e-6) as f32)
}

/// Trains one generator variant and the range predictor on `examples` and saves them in `out`.
pub fn train_variant(
    p: &Predictors,
    examples: &[Example],
    s: &VariantSettings,
    out: &Path,
) -> anyhow::Result<GeneratorCheckpoint> {
    let started = std::time::Instant::now();
    anyhow::ensure!(!examples.is_empty(), "no labelled pairs to train on");
    let threshold = parse_threshold(&s.threshold)?;
    let marginal = s.labels.marginal;
    let device = &p.device;
    device.seed(s.seed);
    let mut gen_config = GeneratorConfig::new(p.ckpt.model_config.embedding_width());
    gen_config.psi_scale = psi_spread(examples);
    let mut generator = gen_config.init(device);
    let mut optim = burn::optim::AdamConfig::new().init();
    let options = StepOptions {
        variant: s.variant,
        alpha: s.alpha,
        beta: s.beta,
        huber_delta: 1.0,
        trajectory_weight: 1.0,
        reward: Reward::AverageSpeed,
        learning_rate: s.learning_rate,
    };
    let name = variant_name(s.variant);
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(s.seed);
    let per_epoch = examples.len().div_ceil(s.batch_size.max(1));
    let mut history = Vec::new();
    for epoch in 0..s.epochs {
        let pb = progress::bar(per_epoch as u64, &format!("{name} {epoch}"));
        let mut sums = [0.0f32; 3];
        let mut skipped = 0usize;
        for batch in
            scbg_generator::balanced_batches(examples, threshold, s.batch_size, per_epoch, &mut rng)
        {
            let refs: Vec<&Example> = batch.iter().map(|&i| &examples[i]).collect();
            let (g, l) = scbg_generator::train_step(
                generator, &mut optim, &p.frozen, &refs, &options, device,
            );
            generator = g;
            if l.total.is_finite() {
                for (acc, v) in sums.iter_mut().zip([l.total, l.trajectory, l.courtesy]) {
                    *acc += v / per_epoch as f32;
                }
            } else {
                skipped += 1;
            }
            pb.set_message(format!("loss {:.3}", l.total));
            pb.inc(1);
        }
        pb.finish_and_clear();
        eprintln!(
            "{name} epoch {epoch:>3}: loss {:.4} (trajectory {:.4}, courtesy {:.4}){}",
            sums[0],
            sums[1],
            sums[2],
            if skipped > 0 {
                format!(", {skipped} non-finite batches skipped")
            } else {
                String::new()
            }
        );
        history.push(sums);
    }
    let refs: Vec<&Example> = examples.iter().collect();
    let embedding = scbg_generator::stored_embeddings(&refs, device);
    let labels: Vec<&[f32]> = examples.iter().map(|e| e.psi.as_slice()).collect();
    let range_hidden = 64;
    let mut range =
        RangePredictor::init(p.ckpt.model_config.embedding_width(), range_hidden, device);
    let mut range_optim = burn::optim::AdamConfig::new().init();
    let mut range_loss = f32::NAN;
    for _ in 0..s.range_steps {
        let (r, l) =
            scbg_generator::range_step(range, &mut range_optim, embedding.clone(), &labels, 1e-2);
        range = r;
        range_loss = l;
    }
    eprintln!(
        "{name}: range predictor pinball loss {range_loss:.5} after {} steps",
        s.range_steps
    );
    let (psi_min, psi_max) = examples
        .iter()
        .flat_map(|e| e.psi.iter().copied())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    scbg_train::checkpoint::save_record(out, "generator.bpk", |path| {
        generator
            .clone()
            .save_file(path)
            .map_err(|e| format!("{e:?}"))
    })?;
    scbg_train::checkpoint::save_record(out, "range.bpk", |path| {
        range.clone().save_file(path).map_err(|e| format!("{e:?}"))
    })?;
    let predictor = std::fs::canonicalize(&p.dir).unwrap_or_else(|_| p.dir.clone());
    let saved = GeneratorCheckpoint {
        variant: name.into(),
        predictor: predictor.display().to_string(),
        generator: gen_config,
        range_hidden,
        samples: examples[0].psi.len() - 1,
        alpha: s.alpha,
        beta: s.beta,
        threshold: s.threshold.clone(),
        marginal: marginal.name().into(),
        sample_noise: s.labels.sample_noise,
        threshold_psi: scbg_generator::threshold_value(examples, threshold),
        psi_min,
        psi_max,
        seed: s.seed,
        history,
        range_loss,
        examples: examples.len(),
        seconds: started.elapsed().as_secs_f64(),
    };
    scbg_features::cache::write_json_atomic(&out.join(GENERATOR_JSON), &saved)?;
    eprintln!(
        "generator ({name}) and range predictor saved in {} ({:.0} s)",
        out.display(),
        saved.seconds
    );
    Ok(saved)
}

/// `scbg train generator`.
pub fn train(args: &TrainGeneratorArgs) -> anyhow::Result<GeneratorCheckpoint> {
    let variant = parse_variant(&args.variant)?;
    parse_threshold(&args.threshold)?;
    let labels = super::label::label_options(&args.estimator, args.samples, Reward::AverageSpeed)?;
    let p = load_predictors(&args.predictor)?;
    eprintln!(
        "labelling the training split ({} futures of B per pair role)",
        1 + args.samples
    );
    let examples = examples_for_split(
        &p.plain,
        &p.ckpt,
        &p.plain_device,
        &args.data,
        Some(Split::Train),
        labels,
        args.seed,
    )?;
    anyhow::ensure!(
        !examples.is_empty(),
        "no interacting pairs in the training split of {}",
        args.data.display()
    );
    train_variant(
        &p,
        &examples,
        &VariantSettings {
            variant,
            epochs: args.epochs,
            batch_size: args.batch_size,
            alpha: args.alpha,
            beta: args.beta,
            threshold: args.threshold.clone(),
            learning_rate: args.learning_rate,
            range_steps: args.range_steps,
            seed: args.seed,
            labels,
        },
        &args.out,
    )
}

/// A trained SCBG model folder, loaded on the plain device.
pub struct LoadedScbg {
    pub scbg: Scbg,
    pub checkpoint: GeneratorCheckpoint,
    pub predictor: Checkpoint,
    pub device: Device,
}

/// Loads `dir` (from `scbg train generator`) and its predictor (`predictor` overrides the
/// folder recorded in generator.json).
pub fn load_scbg(dir: &Path, predictor: Option<&Path>) -> anyhow::Result<LoadedScbg> {
    let json = dir.join(GENERATOR_JSON);
    let text =
        std::fs::read_to_string(&json).with_context(|| format!("reading {}", json.display()))?;
    let checkpoint: GeneratorCheckpoint =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", json.display()))?;
    let predictor_dir =
        predictor.map_or_else(|| PathBuf::from(&checkpoint.predictor), Path::to_path_buf);
    let ckpt = Checkpoint::read(&predictor_dir)
        .with_context(|| format!("predictor of {} (override with --predictor)", dir.display()))?;
    let device = scbg_model::device::device(&ckpt.train_config.backend)?;
    let model = ckpt.load_model(&predictor_dir, &device)?;
    let load = |name: &str| dir.join(name);
    let generator = checkpoint
        .generator
        .init(&device)
        .try_load_file(load("generator.bpk"))
        .map_err(|e| anyhow::anyhow!("{}: {e:?}", load("generator.bpk").display()))?;
    let range = RangePredictor::init(
        ckpt.model_config.embedding_width(),
        checkpoint.range_hidden,
        &device,
    )
    .try_load_file(load("range.bpk"))
    .map_err(|e| anyhow::anyhow!("{}: {e:?}", load("range.bpk").display()))?;
    Ok(LoadedScbg {
        scbg: Scbg {
            predictor: model,
            generator,
            range,
            stats: ckpt.stats.clone(),
            features: ckpt.train_config.feature_config(),
            labels: checkpoint.label_options()?,
        },
        checkpoint,
        predictor: ckpt,
        device,
    })
}

/// `scbg generate`.
pub fn generate(args: &GenerateArgs) -> anyhow::Result<()> {
    let loaded = load_scbg(&args.model, args.predictor.as_deref())?;
    let file = scbg_womd::WomdFile::open(&args.scenario)?;
    let mut chosen = None;
    for (index, scene) in file.scenes().enumerate() {
        let scene = scene?;
        let wanted = match &args.scenario_id {
            Some(id) => &scene.scenario_id == id,
            None => scene.track_index(args.a).is_some() && scene.track_index(args.b).is_some(),
        };
        if wanted {
            chosen = Some((index, scene));
            break;
        }
    }
    let (index, scene) = chosen.with_context(|| match &args.scenario_id {
        Some(id) => format!("{}: no scenario {id:?}", args.scenario.display()),
        None => format!(
            "{}: no scenario has both track {} and track {}",
            args.scenario.display(),
            args.a,
            args.b
        ),
    })?;
    let window_config = scbg_features::WindowConfig::default();
    let prepared = scbg_features::PreparedScene::for_inference(
        &scene,
        &window_config,
        super::data::ROAD_SUBSAMPLE,
    );
    let generated = loaded
        .scbg
        .generate(
            &prepared,
            &prepared.windows[0],
            args.a,
            args.b,
            &args.quantile,
            &loaded.device,
        )
        .with_context(|| format!("{} (record {index})", args.scenario.display()))?;
    let doc = serde_json::json!({
        "scenario_id": scene.scenario_id,
        "a_id": args.a,
        "b_id": args.b,
        "current_step": scene.current_step,
        "variant": loaded.checkpoint.variant,
        "trajectories": generated,
    });
    let text = serde_json::to_string_pretty(&doc)?;
    match &args.out {
        Some(path) => super::demo::write_atomic(path, &text)?,
        None => println!("{text}"),
    }
    for g in &generated {
        eprintln!(
            "quantile {:.2} → ψ {:+.4} (range {:+.4} … {:+.4}); achieved ψ {:+.4}; A's expected speed {:.2} m/s (marginal {:.2})",
            g.quantile,
            g.psi,
            g.psi_low,
            g.psi_high,
            g.achieved_psi,
            g.a_expected_reward_conditional,
            g.a_expected_reward_marginal
        );
    }
    if let Some(png) = &args.render {
        let pair = (
            scene.track_index(args.a).context("A vanished")?,
            scene.track_index(args.b).context("B vanished")?,
        );
        let overlays = generated
            .iter()
            .map(|g| {
                (
                    format!("B q={:.1}", g.quantile),
                    g.world_xy_m.iter().map(|p| (p[0], p[1])).collect(),
                )
            })
            .collect();
        scbg_plot::render_scene(
            &scene,
            png,
            &scbg_plot::RenderOptions {
                size_px: 900,
                pair: Some(pair),
                overlays,
                title: format!("{}: B generated at quantiles", scene.scenario_id),
            },
        )?;
        eprintln!("rendered {}", png.display());
    }
    Ok(())
}
