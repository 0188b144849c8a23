//! The training loop.

use std::path::Path;
use std::time::Instant;

use burn::grad_clipping::GradientClippingConfig;
use burn::module::Module;
use burn::optim::{AdamConfig, GradientsAccumulator, GradientsParams, ModuleOptimizer};
use burn::tensor::{Device, Tensor};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rayon::prelude::*;
use scbg_features::AgentSample;
use scbg_features::cache::{CacheError, PreparedDataset};
use scbg_model::loss::{group_centring, group_speed_contrast, mode_classification_loss};
use scbg_model::{Batch, BatchAugment, Multipath, gmm_nll};

use crate::checkpoint::{Checkpoint, CheckpointError, EpochReport, TrainState};
use crate::config::{ConfigError, TrainConfig};
use crate::data::{load_samples, normalise, standardise};
use crate::eval::{Mode, mean_nll, predict, score};
use scbg_base::seed::mix;

/// Why [`train`] failed.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// The configuration is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The prepared cache could not be read.
    #[error(transparent)]
    Cache(#[from] CacheError),
    /// A checkpoint could not be read (`--resume`) or written.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// The configured backend is not available in this build.
    #[error(transparent)]
    Backend(#[from] scbg_model::device::UnknownBackend),
    /// The prepared data gave no training samples.
    #[error("no training samples in the prepared data")]
    NoSamples,
    /// `--resume` found a checkpoint (folder given) whose training configuration differs.
    #[error("--resume: the checkpoint in {0} was made with a different configuration")]
    ConfigMismatch(String),
    /// `init_from` names a checkpoint (folder given) of another model configuration.
    #[error("init_from: the checkpoint in {0} has another model configuration than this run")]
    InitMismatch(String),
}

/// Progress callbacks (the CLI draws a bar; tests pass [`NoProgress`]).
pub trait Progress {
    /// An epoch (0-based) of `_batches` batches begins.
    fn epoch_start(&self, _epoch: usize, _batches: usize) {}
    /// A batch was trained on, with this (finite) loss; skipped batches are not reported.
    fn batch_done(&self, _loss: f64) {}
    /// An epoch ended (after validation, before its checkpoint is saved).
    fn epoch_end(&self, _report: &EpochReport) {}
    /// Asked after each epoch's checkpoint is saved: `true` ends training there, as an
    /// interruption would (`--resume` continues from that checkpoint).
    fn stop_requested(&self) -> bool {
        false
    }
}

/// A [`Progress`] that ignores every callback.
#[derive(Debug)]
pub struct NoProgress;
impl Progress for NoProgress {}

fn optimizer(config: &TrainConfig) -> ModuleOptimizer {
    AdamConfig::new()
        .with_grad_clipping(Some(GradientClippingConfig::Norm(config.grad_clip_norm)))
        .init()
}

/// Trains on the prepared cache in `data_dir`, writing checkpoints to `out_dir` after every
/// epoch. With `resume`, continues from the checkpoint in `out_dir` if there is one (else starts
/// afresh); the result is the same as an uninterrupted run (data order and augmentation are
/// derived from (seed, epoch/step)).
pub fn train(
    data_dir: &Path,
    out_dir: &Path,
    config: &TrainConfig,
    resume: bool,
    progress: &dyn Progress,
) -> Result<Checkpoint, TrainError> {
    config.validate()?;
    let model_config = config.model_config()?;
    let dataset = PreparedDataset::open(data_dir)?;
    let (mut train_set, mut val_set) = load_samples(&dataset, config)?;
    if train_set.is_empty() {
        return Err(TrainError::NoSamples);
    }
    let raw_val: Vec<AgentSample> = val_set.samples.iter().take(512).cloned().collect();
    let init = config
        .init_from
        .as_deref()
        .map(|dir| Checkpoint::read(dir).map(|c| (dir, c)))
        .transpose()?;
    let stats = match &init {
        // Fine-tuning keeps the statistics the weights were trained with.
        Some((dir, ckpt)) => {
            if ckpt.model_config != model_config {
                return Err(TrainError::InitMismatch(dir.display().to_string()));
            }
            normalise(&ckpt.stats, &mut train_set, &mut val_set);
            ckpt.stats.clone()
        }
        None => standardise(&mut train_set, &mut val_set),
    };
    tracing::info!(
        "training samples: {} ({} conditional); validation: {}",
        train_set.len(),
        train_set.conditional().count(),
        val_set.len()
    );

    let device = scbg_model::device::training_device(&config.backend)?;
    let infer_device = scbg_model::device::device(&config.backend)?;
    device.seed(config.seed);
    let mut model = match &init {
        Some((dir, ckpt)) => ckpt.load_model(dir, &device)?,
        None => model_config.init(&device),
    };
    let mut optim = optimizer(config);
    let mut state = TrainState {
        epoch: 0,
        step: 0,
        learning_rate: config.learning_rate,
        best_val_loss: None,
        epochs_without_improvement: 0,
    };
    let mut history = Vec::new();
    // `--resume` with no checkpoint yet is a fresh start, so that re-running the same command
    // finishes an interrupted run whenever it was interrupted.
    if resume && out_dir.join(crate::checkpoint::CHECKPOINT_FILE).exists() {
        let ckpt = Checkpoint::read(out_dir)?;
        if &ckpt.train_config != config {
            return Err(TrainError::ConfigMismatch(out_dir.display().to_string()));
        }
        model = ckpt.load_model(out_dir, &device)?;
        optim = ckpt.load_optimizer(out_dir, optim)?;
        state = ckpt.state.clone();
        history = ckpt.history.clone();
    }
    let augment = BatchAugment {
        condition_dropout: config.condition_dropout,
        history_mask_prob: config.history_mask_prob,
    };
    let val_refs: Vec<&AgentSample> = val_set.samples.iter().collect();
    let raw_refs: Vec<&AgentSample> = raw_val.iter().collect();
    let mut last = None;
    // The samples every epoch draws from; reaction samples joining later come after them.
    let base_len = train_set.len();
    let batches = base_len.div_ceil(config.batch_size);
    let mut reaction_joined = false;
    // With the speed contrast: each training sample's sibling group (again when siblings join).
    let sibling_groups = |samples: &[AgentSample]| {
        (config.sibling_contrast_weight > 0.0).then(|| samples.iter().map(group_key).collect())
    };
    let mut group_keys: Option<Vec<Option<u64>>> = sibling_groups(&train_set.samples);
    for epoch in state.epoch..config.epochs {
        let started = Instant::now();
        if let (Some(dir), Some(from)) = (&config.reaction_cache, config.reaction_from_epoch)
            && epoch >= from
            && !reaction_joined
        {
            reaction_joined = true;
            let mut joining = crate::data::reaction_samples(dir, config)?;
            for s in &mut joining {
                stats.normalize(s);
            }
            tracing::info!(
                "epoch {epoch}: {} reaction samples join the training",
                joining.len()
            );
            train_set.samples.extend(joining);
            group_keys = sibling_groups(&train_set.samples);
        }
        let mut order = epoch_order(base_len, train_set.len(), config.seed, epoch);
        if let Some(keys) = &group_keys {
            order = keep_groups_together(order, keys);
        }
        progress.epoch_start(epoch, order.len().div_ceil(config.batch_size));
        let epoch_start_model = model.clone();
        let (mut loss_sum, mut loss_n, mut skipped) = (0.0f64, 0usize, 0usize);
        for chunk in order.chunks(config.batch_size) {
            let refs: Vec<&AgentSample> = chunk.iter().map(|&i| &train_set.samples[i]).collect();
            let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(mix(config.seed ^ 0x5CB6, state.step));
            let (value, grads) = loss_and_grads(&model, &refs, &augment, &mut rng, &device, config);
            state.step += 1;
            let Some(grads) = grads else {
                tracing::warn!(
                    "epoch {epoch} step {}: non-finite loss {value}; batch skipped",
                    state.step
                );
                skipped += 1;
                continue;
            };
            let lr = state.learning_rate * schedule_factor(config, state.step - 1, batches);
            model = optim.step(lr, model, grads);
            loss_sum += f64::from(value);
            loss_n += 1;
            progress.batch_done(f64::from(value));
        }
        if !crate::checkpoint::weights_finite(&model) {
            tracing::warn!(
                "epoch {epoch}: weights became non-finite; reverting the epoch and halving the learning rate"
            );
            model = epoch_start_model;
            state.learning_rate *= 0.5;
        }
        let valid_model = model.valid();
        let val_loss = mean_nll(
            &valid_model,
            &val_refs,
            Mode::Conditional,
            config.batch_size,
            &infer_device,
        );
        let val_min_ade_8s = (!raw_refs.is_empty())
            .then(|| {
                let modes = predict(
                    &valid_model,
                    &val_refs[..raw_refs.len()],
                    Mode::Marginal,
                    config.batch_size,
                    &infer_device,
                );
                score(
                    &modes,
                    &raw_refs,
                    &scbg_metrics::ClassifierThresholds::default(),
                )
                .by_time[2]
                    .1
                    .min_ade
            })
            .flatten();
        match (val_loss, state.best_val_loss) {
            (Some(v), Some(best)) if v >= best => {
                state.epochs_without_improvement += 1;
                if config.lr_schedule != "cosine"
                    && state.epochs_without_improvement >= config.plateau_patience
                {
                    state.learning_rate *= config.plateau_factor;
                    state.epochs_without_improvement = 0;
                }
            }
            (Some(v), _) => {
                state.best_val_loss = Some(v);
                state.epochs_without_improvement = 0;
            }
            (None, _) => {}
        }
        state.epoch = epoch + 1;
        let report = EpochReport {
            epoch,
            train_loss: if loss_n > 0 {
                loss_sum / loss_n as f64
            } else {
                f64::NAN
            },
            val_loss,
            val_min_ade_8s,
            learning_rate: state.learning_rate
                * schedule_factor(config, state.step.saturating_sub(1), batches),
            skipped_batches: skipped,
            seconds: started.elapsed().as_secs_f64(),
        };
        progress.epoch_end(&report);
        history.push(report);
        let ckpt = Checkpoint {
            kind: crate::checkpoint::CHECKPOINT_KIND.into(),
            format_version: crate::checkpoint::CHECKPOINT_FORMAT_VERSION,
            train_config: config.clone(),
            model_config: model_config.clone(),
            stats: stats.clone(),
            state: state.clone(),
            history: history.clone(),
            model_file: String::new(),
            optimizer_file: String::new(),
        };
        ckpt.clone().save(out_dir, &model, &optim)?;
        last = Some(Checkpoint::read(out_dir)?);
        if progress.stop_requested() {
            break;
        }
    }
    match last {
        Some(c) => Ok(c),
        None => Ok(Checkpoint::read(out_dir)?),
    }
}

/// The samples of `epoch` in training order: all `len` of them, shuffled by (`seed`,
/// `epoch`); when samples beyond the first `base_len` have joined (a reaction cache from some
/// epoch on), all of those plus a random subset of the first `base_len`, `base_len` in all
/// (or just the joined ones if they are more).
pub(crate) fn epoch_order(base_len: usize, len: usize, seed: u64, epoch: usize) -> Vec<usize> {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(mix(seed, epoch as u64));
    let mut order: Vec<usize> = (0..base_len).collect();
    order.shuffle(&mut rng);
    if len > base_len {
        order.truncate(base_len.saturating_sub(len - base_len));
        order.extend(base_len..len);
        order.shuffle(&mut rng);
    }
    order
}

/// The step of the samples' futures for [`group_speed_contrast`]'s speeds: WOMD's 10 Hz,
/// which the synthetic world shares (siblings come only from it).
const CONTRAST_STEP_SECS: f32 = 0.1;

/// The training loss of one batch (GMM NLL plus the weighted mode classification) on `model`;
/// with [`TrainConfig::sibling_contrast_weight`] and siblings of one role among `samples` (the
/// batch's; see [`group_key`]) whose condition the batch kept, also their
/// [`group_speed_contrast`].
fn batch_loss(
    model: &Multipath,
    batch: &Batch,
    samples: &[&AgentSample],
    config: &TrainConfig,
) -> Tensor<1> {
    let out = model.forward(batch);
    let mut loss = gmm_nll(&out, batch.future_xy.clone(), batch.future_valid.clone());
    if config.classification_weight != 0.0 {
        loss = loss
            + mode_classification_loss(&out, batch.future_xy.clone(), batch.future_valid.clone())
                * config.classification_weight;
    }
    if config.sibling_contrast_weight > 0.0 {
        // A sample whose condition the batch dropped has no B future to compare by.
        let keys: Vec<Option<u64>> = samples
            .iter()
            .zip(&batch.condition_kept)
            .map(|(s, &kept)| if kept { group_key(s) } else { None })
            .collect();
        let (centring, grouped) = group_centring(&keys);
        if grouped > 0 {
            let b = keys.len();
            let centring = Tensor::<2>::from_data(
                burn::tensor::TensorData::new(centring, [b, b]),
                &batch.future_xy.device(),
            );
            let contrast = group_speed_contrast(
                &out,
                batch.future_xy.clone(),
                centring,
                grouped,
                CONTRAST_STEP_SECS,
            );
            loss = loss + contrast * config.sibling_contrast_weight;
        }
    }
    loss
}

/// The group of a sample for [`group_speed_contrast`]: conditional samples of one scene
/// (the logged one and its `~` variants, counterfactual and reaction siblings), window, target
/// and condition, fully valid, share one; a sample without a condition or with a partial future
/// has none. Only B's future differs within a group (the synthetic world's siblings share
/// the history), so the contrast sees how B's future alone moves A's speed.
pub(crate) fn group_key(sample: &AgentSample) -> Option<u64> {
    let condition = sample.condition_track_id?;
    if !sample.future_valid.iter().all(|&v| v) {
        return None;
    }
    let h = crate::data::base_id_hash(&sample.scenario_id);
    Some(mix(
        mix(
            mix(h, sample.window.current_step as u64),
            sample.target_track_id as u64,
        ),
        condition as u64,
    ))
}

/// `order` with the members of each group moved up to where its first member stands (the
/// rest keep their order), so that a group's samples share a batch unless it ends there.
pub(crate) fn keep_groups_together(order: Vec<usize>, keys: &[Option<u64>]) -> Vec<usize> {
    let mut members: std::collections::HashMap<u64, Vec<usize>> = Default::default();
    for &i in &order {
        if let Some(k) = keys[i] {
            members.entry(k).or_default().push(i);
        }
    }
    let mut out = Vec::with_capacity(order.len());
    for i in order {
        match keys[i] {
            None => out.push(i),
            Some(k) => {
                if let Some(group) = members.remove(&k) {
                    out.extend(group);
                }
            }
        }
    }
    out
}

/// One step's loss value and gradients (`None` when the loss is not finite: the batch is
/// skipped), as [`train`] takes them. With [`TrainConfig::data_parallel_chunks`] > 1 the batch
/// is split into chunks whose forward and backward passes run in parallel rayon tasks, each on
/// a fork of `model` (its own autodiff graph), their losses weighted by chunk size; the chunks'
/// gradients are summed pairwise in a fixed tree (in parallel, and the same sum on every run).
pub fn loss_and_grads(
    model: &Multipath,
    refs: &[&AgentSample],
    augment: &BatchAugment,
    rng: &mut rand_pcg::Pcg64Mcg,
    device: &Device,
    config: &TrainConfig,
) -> (f32, Option<GradientsParams>) {
    let chunk_len = refs.len().div_ceil(config.data_parallel_chunks.max(1));
    if chunk_len >= refs.len() {
        let batch = Batch::from_samples(refs, augment, rng, device);
        let loss = batch_loss(model, &batch, refs, config);
        let value: f32 = loss.clone().into_scalar();
        let grads = value
            .is_finite()
            .then(|| GradientsParams::from_grads(loss.backward(), model));
        return (value, grads);
    }
    let work: Vec<(f32, Batch, &[&AgentSample], Multipath)> = refs
        .chunks(chunk_len)
        .map(|c| {
            (
                c.len() as f32 / refs.len() as f32,
                Batch::from_samples(c, augment, rng, device),
                c,
                model.clone().fork(device),
            )
        })
        .collect();
    let mut parts: Vec<(f32, Option<(GradientsParams, Multipath)>)> = work
        .into_par_iter()
        .map(|(share, batch, samples, local)| {
            let loss = batch_loss(&local, &batch, samples, config).mul_scalar(share);
            let value: f32 = loss.clone().into_scalar();
            let grads = value
                .is_finite()
                .then(|| (GradientsParams::from_grads(loss.backward(), &local), local));
            (value, grads)
        })
        .collect();
    let value: f32 = parts.iter().map(|p| p.0).sum();
    if !value.is_finite() || parts.iter().any(|p| p.1.is_none()) {
        return (value, None);
    }
    let mut level: Vec<(GradientsParams, Multipath)> =
        parts.drain(..).filter_map(|p| p.1).collect();
    while level.len() > 1 {
        level = level
            .into_par_iter()
            .chunks(2)
            .map(|pair| {
                let mut pair = pair.into_iter();
                let (a, module) = pair.next().expect("a chunk of 1 or 2");
                let Some((b, _)) = pair.next() else {
                    return (a, module);
                };
                let mut sum = GradientsAccumulator::new();
                sum.accumulate(&module, a);
                sum.accumulate(&module, b);
                (sum.grads(), module)
            })
            .collect();
    }
    (value, level.pop().map(|(g, _)| g))
}

/// The learning-rate multiplier of the schedule at optimizer step `step` (0-based).
fn schedule_factor(config: &TrainConfig, step: u64, batches_per_epoch: usize) -> f64 {
    if config.lr_schedule != "cosine" {
        return 1.0;
    }
    let total = (config.epochs * batches_per_epoch).max(1) as f64;
    let progress = (step as f64 / total).min(1.0);
    (0.5 * (1.0 + (std::f64::consts::PI * progress).cos())).max(0.01)
}
