//! Training the SCBG generator variants and the range predictor on labelled pair roles (paper
//! eq. (1), Sec. III-D) into a generator folder that [`scbg::model`] loads.

use std::path::{Path, PathBuf};

use anyhow::Context;
use burn::module::Module;
use burn::tensor::Device;
use rand::SeedableRng;
use scbg_courtesy::label::LabelOptions;
use scbg_features::cache::PreparedDataset;
use scbg_generator::{
    Example, GeneratorConfig, RangePredictor, SelectorLoss, StepOptions, Threshold, Variant,
};
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

/// Generator examples (with B's frozen embedding) of labelled scenes; with `condition_on_a`
/// they keep A's context (`scbg_generator::a_context`), and [`train_variant`] then trains a
/// generator and range predictor told who A is. Off in every command (docs/findings.md, *Telling the generator who A is*: it
/// removes most of the closed-loop reversal but B collides more).
pub fn examples_of(
    predictor: &Multipath,
    device: &Device,
    labelled: Vec<SceneLabels>,
    condition_on_a: bool,
) -> Vec<Example> {
    labelled
        .into_iter()
        .flat_map(|s| {
            let id = s.scenario_id;
            s.roles.into_iter().map(move |role| (id.clone(), role))
        })
        .map(|(id, role)| {
            let mut e = Example::from_role(id, role, predictor, device);
            if !condition_on_a {
                e.a_context.clear();
            }
            e
        })
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
    condition_on_a: bool,
    progress: &dyn Progress,
) -> anyhow::Result<Vec<Example>> {
    let labelled = labelled_split(predictor, ckpt, device, data, split, labels, seed, progress)?;
    Ok(examples_of(predictor, device, labelled, condition_on_a))
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

/// How `scbg train generator` and the demo train a mode-selecting generator's choice among
/// B's candidates by default ([`SelectorLoss`]; BENCHMARKS.md, *Training the choice among B's
/// modes as a classification*).
pub const DEFAULT_SELECTOR_LOSS: SelectorLoss = SelectorLoss::Classify;

/// The slowed copies of B's modes that `scbg train generator` and the demo add to a
/// mode-selecting generator's choices by default ([`VariantSettings::mode_slowdowns`];
/// BENCHMARKS.md, *J_φ cheaper per future of B, and the slowed copies by default*).
pub const DEFAULT_MODE_SLOWDOWNS: [f32; 2] = [0.75, 0.5];

/// The largest factor of a mode's copy ([`scbg_generator::slowdown_warp`]).
pub const MAX_MODE_SPEEDUP: f32 = scbg_generator::MAX_SPEEDUP;

/// The lane moves of B's modes that `scbg train generator` and the demo add to a
/// mode-selecting generator's choices by default: none (0). With 30 (3 s) they lift what the
/// choices allow in truth, but the trained generators follow the truth less
/// ([`VariantSettings::lane_move_steps`]; BENCHMARKS.md, *Lane moves among the generator's
/// choices*).
pub const DEFAULT_LANE_MOVE_STEPS: usize = 0;

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
    /// The examples carry the oracle's ψ_true (recorded in generator.json).
    pub oracle_labels: bool,
    /// With `oracle_labels`: B's sampled futures replaced by this many of the synthetic
    /// world's own futures of B ([`crate::labels::oracle_labelled`]; 0: none).
    pub world_futures: usize,
    /// Train a mode-selecting generator ([`GeneratorConfig::modes`] = the predictor's modes;
    /// the default), else a plain regression.
    pub select_modes: bool,
    /// With `select_modes`: the selector also scores each of B's modes by its own courtesy
    /// ([`GeneratorConfig::mode_courtesy`]), and B's future is its likeliest mode rather than
    /// the blend outside training ([`GeneratorConfig::likeliest_mode`]).
    pub mode_courtesy: bool,
    /// With `mode_courtesy`: the scorer also sees the requested ψ relative to the scene's
    /// choices ([`GeneratorConfig::relative_courtesy_floor`], floor
    /// [`scbg_generator::RELATIVE_COURTESY_FLOOR`]).
    pub relative_mode_courtesy: bool,
    /// With `select_modes`: slowed copies of B's modes join the choices, one per factor
    /// ([`GeneratorConfig::mode_slowdowns`]; empty: none).
    pub mode_slowdowns: Vec<f32>,
    /// With `select_modes`: each of B's modes that leaves its lane also joins the choices with
    /// the move completed within this many steps ([`GeneratorConfig::lane_move_steps`]; 0:
    /// none).
    pub lane_move_steps: usize,
    /// With `select_modes`: how the trajectory loss trains the choice
    /// ([`SelectorLoss`]; the default blends).
    pub selector_loss: SelectorLoss,
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
            oracle_labels: false,
            world_futures: 0,
            select_modes: true,
            mode_courtesy: true,
            relative_mode_courtesy: true,
            mode_slowdowns: DEFAULT_MODE_SLOWDOWNS.to_vec(),
            lane_move_steps: DEFAULT_LANE_MOVE_STEPS,
            selector_loss: DEFAULT_SELECTOR_LOSS,
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
    // Examples with A's context train a generator and range predictor that read
    // B's embedding ‖ A's context.
    let width = p.ckpt.model_config.embedding_width();
    let mut gen_config = if examples[0].a_context.is_empty() {
        GeneratorConfig::new(width)
    } else {
        GeneratorConfig::with_a_context(width)
    };
    gen_config.psi_scale = psi_spread(examples);
    if s.select_modes {
        gen_config.modes = p.ckpt.model_config.num_modes;
        gen_config.mode_courtesy = s.mode_courtesy;
        gen_config.likeliest_mode = s.mode_courtesy;
        gen_config.relative_courtesy_floor = (s.mode_courtesy && s.relative_mode_courtesy)
            .then_some(scbg_generator::RELATIVE_COURTESY_FLOOR);
        gen_config.mode_slowdowns.clone_from(&s.mode_slowdowns);
        gen_config.lane_move_steps = s.lane_move_steps;
    }
    // A generator scoring its modes' courtesy reads them at every step: measure them once
    // (callers that train several variants fill their examples first, see
    // `scbg_generator::fill_mode_courtesy`).
    let filled: Vec<Example>;
    let examples = if gen_config.mode_courtesy
        && examples
            .iter()
            .any(|e| e.mode_psi.len() != gen_config.candidates())
    {
        let mut owned = examples.to_vec();
        scbg_generator::fill_mode_courtesy(
            &p.plain,
            &mut owned,
            s.labels.reward,
            &gen_config.mode_slowdowns,
            gen_config.lane_move_steps,
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
        selector_loss: s.selector_loss,
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
        oracle_labels: s.oracle_labels,
        world_futures: s.world_futures,
        alpha: s.alpha,
        beta: s.beta,
        selector_loss: s.selector_loss,
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
/// in `predictor` and trains one variant into `out`, told who A is with `condition_on_a`
/// (see [`examples_of`]). With `oracle_truth` (the synthetic ground truth; requires
/// `settings.oracle_labels`) the labels are the simulator's ψ_true instead
/// ([`crate::labels::oracle_labelled`]).
pub fn train_generator(
    predictor: &Path,
    data: &Path,
    out: &Path,
    settings: &VariantSettings,
    condition_on_a: bool,
    oracle_truth: Option<&[scbg_synth::GroundTruth]>,
    progress: &dyn Progress,
) -> anyhow::Result<GeneratorCheckpoint> {
    ensure_request!(
        settings.oracle_labels == oracle_truth.is_some(),
        "oracle labels need the synthetic ground truth, and the ground truth is only read for them"
    );
    ensure_request!(
        settings.world_futures == 0 || settings.oracle_labels,
        "world futures are scored by the oracle: they need oracle labels"
    );
    let p = load_predictors(predictor)?;
    progress.note(&format!(
        "labelling the training split ({} futures of B per pair role{})",
        1 + settings.labels.samples,
        if settings.world_futures > 0 {
            format!(
                "; the sampled ones then replaced by {} of the world's own",
                settings.world_futures
            )
        } else {
            String::new()
        }
    ));
    // The generator trains on the logged and first `samples` futures alone
    // (`training_futures`): kept baseline futures would only cost their lane moves' labels
    // (and the oracle's scores), so the training split is labelled without them; `settings`
    // still records them for sample and rank at inference.
    let mut labelled = labelled_split(
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
    if let Some(truth) = oracle_truth {
        let (kept, count) = crate::labels::oracle_labelled(labelled, truth, settings.world_futures);
        progress.note(&format!(
            "oracle labels: {} roles ({} futures) kept with ψ_true; dropped: {} roles that are not a scene's ground-truth role, {} futures the oracle could not score",
            count.roles, count.futures, count.dropped_roles, count.dropped_futures
        ));
        labelled = kept;
    }
    let mut examples = examples_of(&p.plain, &p.plain_device, labelled, condition_on_a);
    if settings.select_modes && settings.mode_courtesy {
        scbg_generator::fill_mode_courtesy(
            &p.plain,
            &mut examples,
            settings.labels.reward,
            &settings.mode_slowdowns,
            settings.lane_move_steps,
            &p.plain_device,
        );
    }
    ensure_request!(
        !examples.is_empty(),
        "no interacting pairs in the training split of {}",
        data.display()
    );
    train_variant(&p, &examples, settings, out, progress)
}
