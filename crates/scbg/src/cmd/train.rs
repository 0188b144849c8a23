//! `scbg train predictor`.

use anyhow::Context;
use indicatif::ProgressBar;
use scbg_train::{EpochReport, Progress, TrainConfig};

use crate::cli::TrainPredictorArgs;
use crate::progress;

struct Bar(std::cell::RefCell<Option<ProgressBar>>);

impl Progress for Bar {
    fn epoch_start(&self, epoch: usize, batches: usize) {
        let pb = progress::bar(batches as u64, &format!("epoch {epoch}"));
        *self.0.borrow_mut() = Some(pb);
    }
    fn batch_done(&self, loss: f64) {
        if let Some(pb) = self.0.borrow().as_ref() {
            pb.set_message(format!("loss {loss:.3}"));
            pb.inc(1);
        }
    }
    fn epoch_end(&self, r: &EpochReport) {
        if let Some(pb) = self.0.borrow_mut().take() {
            pb.finish_and_clear();
        }
        eprintln!(
            "epoch {:>3}: train NLL {:.3}  val NLL {}  val minADE@8s {}  lr {:.2e}  skipped {}  {:.1}s",
            r.epoch,
            r.train_loss,
            r.val_loss.map_or("-".into(), |v| format!("{v:.3}")),
            r.val_min_ade_8s.map_or("-".into(), |v| format!("{v:.2} m")),
            r.learning_rate,
            r.skipped_batches,
            r.seconds
        );
    }
}

pub fn load_config(path: Option<&std::path::Path>) -> anyhow::Result<TrainConfig> {
    match path {
        Some(p) => {
            let text =
                std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            TrainConfig::from_toml(&text).with_context(|| format!("in {}", p.display()))
        }
        None => Ok(TrainConfig::default()),
    }
}

pub fn predictor(args: &TrainPredictorArgs) -> anyhow::Result<()> {
    let config = load_config(args.config.as_deref())?;
    let model = config.model_config()?;
    let params = {
        use burn::module::Module;
        model.init(&burn::tensor::Device::flex()).num_params()
    };
    eprintln!(
        "model: {} ({params} parameters), backend {}",
        args.config
            .as_ref()
            .map_or(config.preset.clone(), |p| p.display().to_string()),
        config.backend
    );
    let ckpt = scbg_train::train(
        &args.data,
        &args.out,
        &config,
        args.resume,
        &Bar(Default::default()),
    )?;
    eprintln!(
        "checkpoint after epoch {} in {}",
        ckpt.state.epoch,
        args.out.display()
    );
    Ok(())
}

/// What `scbg train generator` saves beside the weights (generator.json).
#[derive(Debug, serde::Serialize, serde::Deserialize)]
pub struct GeneratorCheckpoint {
    pub variant: String,
    pub predictor: String,
    pub generator: scbg_generator::GeneratorConfig,
    pub range_hidden: usize,
    pub samples: usize,
    pub alpha: f32,
    pub beta: f32,
    pub threshold: String,
    pub seed: u64,
    /// Mean total / trajectory / courtesy loss per epoch.
    pub history: Vec<[f32; 3]>,
    pub range_loss: f32,
    pub examples: usize,
}

fn parse_threshold(text: &str) -> anyhow::Result<scbg_generator::Threshold> {
    match text.strip_prefix('q') {
        Some(q) => {
            let q: f32 = q
                .parse()
                .with_context(|| format!("--threshold {text:?}: expected qX with X in [0, 1]"))?;
            anyhow::ensure!(
                (0.0..=1.0).contains(&q),
                "--threshold {text:?}: quantile outside [0, 1]"
            );
            Ok(scbg_generator::Threshold::Quantile(q))
        }
        None => Ok(scbg_generator::Threshold::Absolute(
            text.parse()
                .with_context(|| format!("--threshold {text:?}: expected a number or qX"))?,
        )),
    }
}

pub fn generator(args: &crate::cli::TrainGeneratorArgs) -> anyhow::Result<GeneratorCheckpoint> {
    use burn::module::Module;
    use rand::SeedableRng;
    use scbg_courtesy::Reward;
    use scbg_courtesy::label::LabelOptions;
    use scbg_generator::{Example, GeneratorConfig, RangePredictor, StepOptions, Variant};

    let threshold = parse_threshold(&args.threshold)?;
    let variant = match args.variant.as_str() {
        "baseline" => Variant::Baseline,
        "aug" => Variant::Augmented,
        _ => Variant::Full,
    };
    let ckpt = scbg_train::Checkpoint::read(&args.predictor)?;
    let device = scbg_model::device::training_device(&ckpt.train_config.backend)?;
    let predictor = ckpt.load_model(&args.predictor, &device)?;
    // Labels and frozen embeddings need no gradients: computed on the plain device (burn's
    // autodiff graph would keep every forward that is never back-propagated).
    let plain_device = scbg_model::device::device(&ckpt.train_config.backend)?;
    let plain_predictor = ckpt.load_model(&args.predictor, &plain_device)?;
    let dataset = scbg_features::cache::PreparedDataset::open(&args.data)?;
    let vf = ckpt.train_config.validation_fraction;
    let scenes: Vec<_> = (0..dataset.len())
        .map(|i| dataset.scene(i))
        .filter(|s| {
            s.as_ref().map_or(true, |s| {
                scbg_train::data::split_of(&s.scenario_id, vf) == scbg_train::data::Split::Train
            })
        })
        .collect::<Result<_, _>>()?;
    eprintln!(
        "labelling {} training scenarios ({} futures of B per pair role)",
        scenes.len(),
        1 + args.samples
    );
    let examples = scbg_generator::build_examples(
        &plain_predictor,
        &scenes,
        &ckpt.stats,
        &ckpt.train_config.feature_config(),
        LabelOptions {
            samples: args.samples,
            reward: Reward::AverageSpeed,
        },
        args.seed,
        &plain_device,
    );
    anyhow::ensure!(
        !examples.is_empty(),
        "no interacting pairs in the training split of {}",
        args.data.display()
    );
    device.seed(args.seed);
    let gen_config = GeneratorConfig::new(ckpt.model_config.embedding_width());
    let mut generator = gen_config.init(&device);
    let mut optim = burn::optim::AdamConfig::new().init();
    let options = StepOptions {
        variant,
        alpha: args.alpha,
        beta: args.beta,
        huber_delta: 1.0,
        trajectory_weight: 1.0,
        reward: Reward::AverageSpeed,
        learning_rate: args.learning_rate,
    };
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(args.seed);
    let per_epoch = examples.len().div_ceil(args.batch_size.max(1));
    let mut history = Vec::new();
    for epoch in 0..args.epochs {
        let pb = progress::bar(per_epoch as u64, &format!("gen {epoch}"));
        let mut sums = [0.0f32; 3];
        for batch in scbg_generator::balanced_batches(
            &examples,
            threshold,
            args.batch_size,
            per_epoch,
            &mut rng,
        ) {
            let refs: Vec<&Example> = batch.iter().map(|&i| &examples[i]).collect();
            let (g, l) = scbg_generator::train_step(
                generator, &mut optim, &predictor, &refs, &options, &device,
            );
            generator = g;
            for (s, v) in sums.iter_mut().zip([l.total, l.trajectory, l.courtesy]) {
                *s += v / per_epoch as f32;
            }
            pb.set_message(format!("loss {:.3}", l.total));
            pb.inc(1);
        }
        pb.finish_and_clear();
        eprintln!(
            "generator epoch {epoch:>3}: loss {:.4} (trajectory {:.4}, courtesy {:.3e})",
            sums[0], sums[1], sums[2]
        );
        history.push(sums);
    }
    let refs: Vec<&Example> = examples.iter().collect();
    let embedding = scbg_generator::stored_embeddings(&refs, &device);
    let labels: Vec<&[f32]> = examples.iter().map(|e| e.psi.as_slice()).collect();
    let range_hidden = 64;
    let mut range =
        RangePredictor::init(ckpt.model_config.embedding_width(), range_hidden, &device);
    let mut range_optim = burn::optim::AdamConfig::new().init();
    let mut range_loss = f32::NAN;
    for _ in 0..args.range_steps {
        let (r, l) =
            scbg_generator::range_step(range, &mut range_optim, embedding.clone(), &labels, 1e-2);
        range = r;
        range_loss = l;
    }
    eprintln!(
        "range predictor: pinball loss {range_loss:.5} after {} steps",
        args.range_steps
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    scbg_train::checkpoint::save_record(&args.out, "generator.bpk", |p| {
        generator.clone().save_file(p).map_err(|e| format!("{e:?}"))
    })?;
    scbg_train::checkpoint::save_record(&args.out, "range.bpk", |p| {
        range.clone().save_file(p).map_err(|e| format!("{e:?}"))
    })?;
    let saved = GeneratorCheckpoint {
        variant: args.variant.clone(),
        predictor: args.predictor.display().to_string(),
        generator: gen_config,
        range_hidden,
        samples: args.samples,
        alpha: args.alpha,
        beta: args.beta,
        threshold: args.threshold.clone(),
        seed: args.seed,
        history,
        range_loss,
        examples: examples.len(),
    };
    scbg_features::cache::write_json_atomic(&args.out.join("generator.json"), &saved)?;
    eprintln!(
        "generator ({}) and range predictor saved in {}",
        args.variant,
        args.out.display()
    );
    Ok(saved)
}
