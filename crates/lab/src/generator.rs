//! Training the SCBG generator variants and the range predictor on labelled pair roles (paper
//! eq. (1), Sec. III-D) into a generator folder that [`scbg::model`] loads.

use std::path::{Path, PathBuf};

use anyhow::Context;
use burn::module::Module;
use burn::tensor::Device;
use rand::SeedableRng;
use scbg_courtesy::label::LabelOptions;
use scbg_features::cache::PreparedDataset;
use scbg_generator::{Example, GeneratorConfig, RangePredictor, StepOptions, Threshold, Variant};
use scbg_model::Multipath;
use scbg_train::Checkpoint;
use scbg_train::data::{Split, split_of};

use crate::labels::{SceneLabels, label_scenes};
use crate::{Progress, ensure_request};

pub use scbg::model::*;

/// The trained predictor twice: frozen on the autodiff device (J_φ passes gradients to ŷ) and
/// on the plain device (labels, embeddings, evaluation).
#[derive(Debug)]
pub struct Predictors {
    /// The checkpoint folder.
    pub dir: PathBuf,
    /// Its description.
    pub ckpt: Checkpoint,
    /// The training device (with autodiff).
    pub device: Device,
    /// The predictor on `device`, frozen.
    pub frozen: Multipath,
    /// The plain device.
    pub plain_device: Device,
    /// The predictor on `plain_device`.
    pub plain: Multipath,
}

/// Loads a predictor checkpoint folder for generator training.
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

/// Generator examples (with B's frozen embedding) of labelled scenes.
pub fn examples_of(
    predictor: &Multipath,
    device: &Device,
    labelled: Vec<SceneLabels>,
) -> Vec<Example> {
    labelled
        .into_iter()
        .flat_map(|s| {
            let id = s.scenario_id;
            s.roles.into_iter().map(move |role| (id.clone(), role))
        })
        .map(|(id, role)| Example::from_role(id, role, predictor, device))
        .collect()
}

/// Labelled examples of every pair role in one split of a prepared cache (the split by
/// scenario id that the predictor was trained with; `None` = every scene), through the one
/// labelling path ([`label_scenes`]). Runs on the plain device.
#[allow(clippy::too_many_arguments)]
pub fn examples_for_split(
    predictor: &Multipath,
    ckpt: &Checkpoint,
    device: &Device,
    data: &Path,
    split: Option<Split>,
    labels: LabelOptions,
    seed: u64,
    progress: &dyn Progress,
) -> anyhow::Result<Vec<Example>> {
    let labelled = labelled_split(predictor, ckpt, device, data, split, labels, seed, progress)?;
    Ok(examples_of(predictor, device, labelled))
}

/// Every pair role in one split of a prepared cache (`None` = every scene), labelled through
/// the one labelling path ([`label_scenes`]); [`examples_for_split`] before the examples are
/// made. Runs on the plain device.
#[allow(clippy::too_many_arguments)]
pub fn labelled_split(
    predictor: &Multipath,
    ckpt: &Checkpoint,
    device: &Device,
    data: &Path,
    split: Option<Split>,
    labels: LabelOptions,
    seed: u64,
    progress: &dyn Progress,
) -> anyhow::Result<Vec<SceneLabels>> {
    let dataset = PreparedDataset::open(data)?;
    let vf = ckpt.train_config.validation_fraction;
    let keep = |scene: &scbg_features::PreparedScene| {
        split.is_none_or(|split| split_of(&scene.scenario_id, vf) == split)
    };
    label_scenes(
        predictor,
        ckpt,
        device,
        &dataset,
        0..dataset.len(),
        &keep,
        labels,
        seed,
        progress,
    )
}

/// Training settings of one variant.
#[derive(Debug, Clone, PartialEq)]
pub struct VariantSettings {
    /// Which variant.
    pub variant: Variant,
    /// Epochs.
    pub epochs: usize,
    /// Batch size.
    pub batch_size: usize,
    /// Weight α of the sampled futures' trajectory loss.
    pub alpha: f32,
    /// Weight β of the courtesy loss.
    pub beta: f32,
    /// High-courtesy threshold of the 50/50 batches.
    pub threshold: Threshold,
    /// Adam's learning rate.
    pub learning_rate: f64,
    /// Range-predictor optimisation steps (full batch).
    pub range_steps: usize,
    /// Seed of initialisation and batches.
    pub seed: u64,
    /// How the examples were labelled (recorded in generator.json).
    pub labels: LabelOptions,
}

impl VariantSettings {
    /// The `scbg train generator` defaults for a variant.
    pub fn new(variant: Variant, labels: LabelOptions) -> Self {
        Self {
            variant,
            epochs: 10,
            batch_size: 32,
            alpha: 0.5,
            beta: 1.0,
            threshold: Threshold::Quantile(0.8),
            learning_rate: 1e-3,
            range_steps: 300,
            seed: 0,
            labels,
        }
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

/// `examples` with B's logged and first `samples` sampled futures alone: the kept baseline
/// futures after them ([`LabelOptions::keep_baseline`]) leave the generator's training as it
/// was, and the labelled lane moves after those ([`LabelOptions::lane_move_steps`]) are not
/// samples of B's marginal, so the generator and range predictor do not learn from either
/// (sample and rank chooses among both).
fn training_futures(examples: &[Example], samples: usize) -> std::borrow::Cow<'_, [Example]> {
    if examples.iter().all(|e| e.psi.len() <= 1 + samples) {
        return std::borrow::Cow::Borrowed(examples);
    }
    let mut owned = examples.to_vec();
    for e in &mut owned {
        e.psi.truncate(1 + samples);
        e.futures_b.truncate(1 + samples);
    }
    std::borrow::Cow::Owned(owned)
}

/// Trains one generator variant and the range predictor on `examples` and saves them in `out`.
pub fn train_variant(
    p: &Predictors,
    examples: &[Example],
    s: &VariantSettings,
    out: &Path,
    progress: &dyn Progress,
) -> anyhow::Result<GeneratorCheckpoint> {
    let started = std::time::Instant::now();
    ensure_request!(!examples.is_empty(), "no labelled pairs to train on");
    let examples = &*training_futures(examples, s.labels.samples);
    let device = &p.device;
    let mut gen_config = GeneratorConfig::new(
        p.ckpt.model_config.embedding_width(),
        p.ckpt.model_config.num_modes,
    );
    gen_config.psi_scale = psi_spread(examples);
    // The generator reads its candidates' courtesy at every step: measure them once (callers
    // that train several variants fill their examples first, see
    // `scbg_generator::fill_mode_courtesy`).
    let filled: Vec<Example>;
    let examples = if examples
        .iter()
        .any(|e| e.mode_psi.len() != gen_config.candidates())
    {
        let mut owned = examples.to_vec();
        scbg_generator::fill_mode_courtesy(
            &p.plain,
            &mut owned,
            s.labels.reward,
            &gen_config.mode_slowdowns,
            &p.plain_device,
        );
        filled = owned;
        &filled[..]
    } else {
        examples
    };
    let range_hidden = 64;
    // The backend's random stream is the device's, shared by every thread: seed and draw the
    // initial weights of both models under one lock, so that variants trained side by side
    // (the demo's generator seeds) get the weights their seed says. Training itself draws
    // nothing from it.
    let (mut generator, mut range) = {
        let _stream = DEVICE_STREAM
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        device.seed(s.seed);
        let generator = gen_config.init(device);
        let range = RangePredictor::init(gen_config.embedding_width, range_hidden, device);
        // burn initialises parameters lazily, at first use: draw them now, inside the lock.
        scbg_model::materialize(&generator);
        scbg_model::materialize(&range);
        (generator, range)
    };
    let mut optim = burn::optim::AdamConfig::new().init();
    let options = StepOptions {
        variant: s.variant,
        alpha: s.alpha,
        beta: s.beta,
        huber_delta: 1.0,
        trajectory_weight: 1.0,
        reward: s.labels.reward,
        learning_rate: s.learning_rate,
    };
    let name = s.variant.name();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(s.seed);
    let per_epoch = examples.len().div_ceil(s.batch_size.max(1));
    let mut history = Vec::new();
    for epoch in 0..s.epochs {
        let pb = progress.bar(&format!("{name} {epoch}"), per_epoch as u64);
        let mut sums = [0.0f32; 3];
        let mut skipped = 0usize;
        for batch in scbg_generator::balanced_batches(
            examples,
            s.threshold,
            s.batch_size,
            per_epoch,
            &mut rng,
        ) {
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
        drop(pb);
        progress.note(&format!(
            "{name} epoch {epoch:>3}: loss {:.4} (trajectory {:.4}, courtesy {:.4}){}",
            sums[0],
            sums[1],
            sums[2],
            if skipped > 0 {
                format!(", {skipped} non-finite batches skipped")
            } else {
                String::new()
            }
        ));
        history.push(sums);
    }
    let refs: Vec<&Example> = examples.iter().collect();
    let embedding = scbg_generator::stored_embeddings(&refs, device);
    let labels: Vec<&[f32]> = examples.iter().map(|e| e.psi.as_slice()).collect();
    let mut range_optim = burn::optim::AdamConfig::new().init();
    let mut range_loss = f32::NAN;
    for _ in 0..s.range_steps {
        let (r, l) =
            scbg_generator::range_step(range, &mut range_optim, embedding.clone(), &labels, 1e-2);
        range = r;
        range_loss = l;
    }
    progress.note(&format!(
        "{name}: range predictor pinball loss {range_loss:.5} after {} steps",
        s.range_steps
    ));
    let (psi_min, psi_max) = examples
        .iter()
        .flat_map(|e| e.psi.iter().copied())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    scbg_train::checkpoint::save_record(out, GENERATOR_WEIGHTS, |path| {
        generator
            .clone()
            .save_file(path)
            .map_err(|e| format!("{e:?}"))
    })?;
    scbg_train::checkpoint::save_record(out, RANGE_WEIGHTS, |path| {
        range.clone().save_file(path).map_err(|e| format!("{e:?}"))
    })?;
    let predictor = std::fs::canonicalize(&p.dir).unwrap_or_else(|_| p.dir.clone());
    let saved = GeneratorCheckpoint {
        kind: GENERATOR_KIND.into(),
        format_version: GENERATOR_FORMAT_VERSION,
        variant: s.variant,
        predictor: predictor.display().to_string(),
        generator: gen_config,
        range_hidden,
        labels: s.labels,
        alpha: s.alpha,
        beta: s.beta,
        threshold: s.threshold,
        threshold_psi: scbg_generator::threshold_value(examples, s.threshold),
        psi_min,
        psi_max,
        seed: s.seed,
        history,
        range_loss,
        examples: examples.len(),
        seconds: started.elapsed().as_secs_f64(),
    };
    saved.write(out)?;
    progress.note(&format!(
        "generator ({name}) and range predictor saved in {} ({:.0} s)",
        out.display(),
        saved.seconds
    ));
    Ok(saved)
}

/// Guards the backend's shared random stream while a model is seeded and initialised.
static DEVICE_STREAM: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// What `scbg train generator` does: labels the training split of `data` with the predictor
/// in `predictor` and trains one variant into `out`.
pub fn train_generator(
    predictor: &Path,
    data: &Path,
    out: &Path,
    settings: &VariantSettings,
    progress: &dyn Progress,
) -> anyhow::Result<GeneratorCheckpoint> {
    let p = load_predictors(predictor)?;
    progress.note(&format!(
        "labelling the training split ({} futures of B per pair role)",
        1 + settings.labels.samples,
    ));
    // The generator trains on the logged and first `samples` futures alone
    // (`training_futures`): kept baseline futures would only cost their lane moves' labels, so
    // the training split is labelled without them; `settings` still records them for sample
    // and rank at inference.
    let labelled = labelled_split(
        &p.plain,
        &p.ckpt,
        &p.plain_device,
        data,
        Some(Split::Train),
        LabelOptions {
            keep_baseline: false,
            ..settings.labels
        },
        settings.seed,
        progress,
    )?;
    let mut examples = examples_of(&p.plain, &p.plain_device, labelled);
    scbg_generator::fill_mode_courtesy(
        &p.plain,
        &mut examples,
        settings.labels.reward,
        &scbg_generator::DEFAULT_MODE_SLOWDOWNS,
        &p.plain_device,
    );
    ensure_request!(
        !examples.is_empty(),
        "no interacting pairs in the training split of {}",
        data.display()
    );
    train_variant(&p, &examples, settings, out, progress)
}
