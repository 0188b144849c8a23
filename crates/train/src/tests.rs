//! Training end to end on a tiny synthetic cache.

use std::path::Path;

use burn::module::Module;
use scbg_features::cache::{Manifest, ShardSummary, ShardWriter};
use scbg_features::{PairConfig, PreparedScene, WindowConfig};

use crate::config::TrainConfig;
use crate::{Checkpoint, NoProgress, Progress, train};

/// Writes a prepared cache of `n` synthetic scenarios.
pub(crate) fn tiny_cache(dir: &Path, n: u64) {
    cache_of(
        dir,
        (0..n).map(|i| scbg_synth::generate(42, i, &scbg_synth::Family::DEFAULT).scene),
    );
}

/// Writes a prepared cache of these scenes.
fn cache_of(dir: &Path, scenes: impl Iterator<Item = scbg_scene::Scene>) {
    std::fs::create_dir_all(dir).unwrap();
    let mut w = ShardWriter::create(&dir.join("shard-00000.bin")).unwrap();
    let mut n = 0;
    for scene in scenes {
        n += 1;
        let p =
            PreparedScene::from_scene(&scene, &WindowConfig::default(), &PairConfig::default(), 4)
                .unwrap();
        w.append(&p).unwrap();
    }
    let bytes = w.finish().unwrap();
    let shard = ShardSummary {
        file: "shard-00000.bin".into(),
        scenarios: n,
        bytes,
        ..Default::default()
    };
    Manifest {
        format_version: 1,
        settings: Default::default(),
        shards: vec![shard.clone()],
        total: shard,
    }
    .write(dir)
    .unwrap();
}

/// burn's seeded RNG is process-global: training tests must not interleave their model inits.
static SEED_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn tiny_config(epochs: usize) -> TrainConfig {
    let mut model = scbg_model::MultipathConfig::cpu_small();
    model.lstm_hidden = 8;
    model.step_mlp = vec![8, 16];
    model.target_width = 16;
    model.interaction_width = 16;
    model.road_mlp = vec![8, 16];
    model.road_context_hidden = 16;
    model.decoder_width = 32;
    model.decoder_hidden = 32;
    model.mcg_blocks = 1;
    model.future_hidden = 16;
    TrainConfig {
        model: Some(model),
        epochs,
        batch_size: 8,
        max_other_agents: 4,
        max_road_segments: 16,
        validation_fraction: 0.25,
        seed: 3,
        ..Default::default()
    }
}

fn weights(dir: &Path) -> Vec<f32> {
    let ckpt = Checkpoint::read(dir).unwrap();
    weights_of(&ckpt.load_model(dir, &burn::tensor::Device::flex()).unwrap())
}

/// Every weight of the model, in visiting order.
fn weights_of(model: &scbg_model::Multipath) -> Vec<f32> {
    let mut out = Vec::new();
    struct Collect<'a>(&'a mut Vec<f32>);
    impl burn::module::ModuleVisitor for Collect<'_> {
        fn visit_float<const D: usize>(
            &mut self,
            p: &burn::module::Param<burn::tensor::Tensor<D>>,
        ) {
            self.0
                .extend(p.val().into_data().try_to_vec::<f32>().unwrap());
        }
    }
    model.visit(&mut Collect(&mut out));
    out
}

#[test]
fn resume_gives_the_same_weights_as_an_uninterrupted_run() {
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    tiny_cache(&data, 24);
    let straight = dir.path().join("straight");
    let ckpt = train(&data, &straight, &tiny_config(2), false, &NoProgress).unwrap();
    assert_eq!(ckpt.state.epoch, 2);
    assert!(
        ckpt.history.iter().all(|r| r.train_loss.is_finite()),
        "{:?}",
        ckpt.history
    );
    // The same 2-epoch run, interrupted after its first epoch, then resumed.
    struct StopAfterOne;
    impl Progress for StopAfterOne {
        fn stop_requested(&self) -> bool {
            true
        }
    }
    let resumed = dir.path().join("resumed");
    let first = train(&data, &resumed, &tiny_config(2), false, &StopAfterOne).unwrap();
    assert_eq!(first.state.epoch, 1);
    // A run killed after writing `checkpoint.json` but before removing the checkpoint before
    // it leaves that one's record files too.
    for (from, to) in [
        (&first.model_file, "model-0000.bpk"),
        (&first.optimizer_file, "optimizer-0000.bpk"),
    ] {
        std::fs::copy(resumed.join(from), resumed.join(to)).unwrap();
    }
    train(&data, &resumed, &tiny_config(2), true, &NoProgress).unwrap();
    let (a, b) = (weights(&straight), weights(&resumed));
    assert_eq!(a.len(), b.len());
    assert!(a == b, "weights differ after resume");
    // Only the latest model and optimizer files remain, the killed run's leftovers swept too.
    let files: Vec<String> = std::fs::read_dir(&resumed)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        files.iter().filter(|f| f.ends_with(".bpk")).count(),
        2,
        "{files:?}"
    );
    // No temporary file is left behind, and the files have `File::create`'s permissions.
    assert_eq!(files.len(), 3, "{files:?}");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = |p: &std::path::Path| std::fs::metadata(p).unwrap().permissions().mode();
        let reference = dir.path().join("reference");
        std::fs::File::create(&reference).unwrap();
        for f in &files {
            assert_eq!(mode(&resumed.join(f)), mode(&reference), "{f}");
        }
    }
}

#[test]
fn resume_refuses_a_different_config() {
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    tiny_cache(&data, 8);
    let out = dir.path().join("out");
    train(&data, &out, &tiny_config(1), false, &NoProgress).unwrap();
    let mut other = tiny_config(1);
    other.learning_rate = 0.5;
    assert!(matches!(
        train(&data, &out, &other, true, &NoProgress),
        Err(crate::TrainError::ConfigMismatch(_))
    ));
}

#[test]
fn fine_tuning_starts_from_the_checkpoint_and_keeps_its_statistics() {
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    tiny_cache(&data, 8);
    let first = dir.path().join("first");
    train(&data, &first, &tiny_config(1), false, &NoProgress).unwrap();
    // Fine-tuned with a vanishing learning rate on other data: the first model's weights and
    // feature statistics, whatever the new data's statistics would be.
    let other = dir.path().join("other");
    cache_of(
        &other,
        (20..30).map(|i| scbg_synth::generate(43, i, &scbg_synth::Family::DEFAULT).scene),
    );
    let tuned = dir.path().join("tuned");
    let config = TrainConfig {
        init_from: Some(first.clone()),
        learning_rate: 1e-30,
        seed: 9,
        ..tiny_config(1)
    };
    let ckpt = train(&other, &tuned, &config, false, &NoProgress).unwrap();
    assert_eq!(ckpt.stats, Checkpoint::read(&first).unwrap().stats);
    let (a, b) = (weights(&first), weights(&tuned));
    assert_eq!(a.len(), b.len());
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max);
    assert!(worst < 1e-6, "weights moved by {worst}");
    // A fresh run on that data fits its own statistics.
    let fresh = train(
        &other,
        &dir.path().join("fresh"),
        &tiny_config(1),
        false,
        &NoProgress,
    )
    .unwrap();
    assert_ne!(fresh.stats, ckpt.stats);
    // Another model configuration is refused, naming the checkpoint.
    let mut wider = tiny_config(1);
    wider.model.as_mut().unwrap().decoder_width = 48;
    let err = train(
        &other,
        &dir.path().join("wider"),
        &TrainConfig {
            init_from: Some(first.clone()),
            ..wider
        },
        false,
        &NoProgress,
    )
    .unwrap_err();
    assert!(matches!(err, crate::TrainError::InitMismatch(_)), "{err}");
    assert!(err.to_string().contains("first"), "{err}");
}

#[test]
fn counterfactual_siblings_add_conditional_samples_of_the_sdc_in_the_training_split() {
    let dir = tempfile::tempdir().unwrap();
    let cf = dir.path().join("cf");
    let n = 24;
    cache_of(
        &cf,
        (0..n).flat_map(|i| {
            let s = scbg_synth::Scenario::draw(42, i, &scbg_synth::Family::DEFAULT);
            (0..2).map(move |k| s.counterfactual(k, 2))
        }),
    );
    let config = TrainConfig {
        counterfactual_cache: Some(cf.clone()),
        ..tiny_config(1)
    };
    let dataset = scbg_features::cache::PreparedDataset::open(&cf).unwrap();
    let samples = crate::data::counterfactual_samples(&dataset, &config).unwrap();
    let train_ids: Vec<String> = (0..n)
        .map(|i| scbg_synth::Scenario::draw(42, i, &scbg_synth::Family::DEFAULT).scenario_id())
        .filter(|id| {
            crate::data::split_of(id, config.validation_fraction) == crate::data::Split::Train
        })
        .collect();
    assert!(!train_ids.is_empty() && train_ids.len() < n as usize);
    // One sample per sibling of a training scene: A (the SDC) conditioned on B.
    assert_eq!(samples.len(), 2 * train_ids.len());
    for s in &samples {
        assert_eq!(s.target_track_id, scbg_synth::A_ID);
        assert_eq!(s.condition_track_id, Some(scbg_synth::B_ID));
        let base = s.scenario_id.split('~').next().unwrap();
        assert!(train_ids.iter().any(|id| id == base), "{}", s.scenario_id);
    }
    // The loader adds them to the training set only.
    tiny_cache(&dir.path().join("data"), 8);
    let data = scbg_features::cache::PreparedDataset::open(&dir.path().join("data")).unwrap();
    let (with, val_with) = crate::data::load_samples(&data, &config).unwrap();
    let (without, val_without) = crate::data::load_samples(
        &data,
        &TrainConfig {
            counterfactual_cache: None,
            ..config.clone()
        },
    )
    .unwrap();
    assert_eq!(with.len(), without.len() + samples.len());
    assert_eq!(val_with.len(), val_without.len());
    assert!(with.samples.iter().all(|s| !s.condition_required));
    // The same siblings as a reaction cache: the same samples, whose condition training keeps.
    let (reacting, _) = crate::data::load_samples(
        &data,
        &TrainConfig {
            counterfactual_cache: None,
            reaction_cache: Some(cf.clone()),
            ..config.clone()
        },
    )
    .unwrap();
    assert_eq!(reacting.len(), with.len());
    let required: Vec<_> = reacting
        .samples
        .iter()
        .filter(|s| s.condition_required)
        .collect();
    assert_eq!(required.len(), samples.len());
    assert!(required.iter().all(|s| s.scenario_id.contains('~')));
}

/// The model of `config` on an autodiff device seeded 5, and no batch augmentation.
fn seeded_model(
    config: &TrainConfig,
) -> (
    scbg_model::Multipath,
    burn::tensor::Device,
    scbg_model::BatchAugment,
) {
    let device = burn::tensor::Device::flex().autodiff();
    device.seed(5);
    let model = config.model_config().unwrap().init(&device);
    let augment = scbg_model::BatchAugment {
        condition_dropout: 0.0,
        history_mask_prob: 0.0,
    };
    (model, device, augment)
}

#[test]
fn data_parallel_chunks_sum_to_the_whole_batch_gradient() {
    use burn::optim::SgdConfig;
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    tiny_cache(dir.path(), 12);
    let config = tiny_config(1);
    let dataset = scbg_features::cache::PreparedDataset::open(dir.path()).unwrap();
    let (train_set, _) = crate::data::load_samples(&dataset, &config).unwrap();
    let refs: Vec<&scbg_features::AgentSample> = train_set.samples.iter().take(11).collect();
    assert_eq!(refs.len(), 11, "a batch that 3 chunks split unevenly");
    // No augmentation: every chunking sees the same samples.
    let (model, device, augment) = seeded_model(&config);
    let step = |chunks: usize| {
        let config = TrainConfig {
            data_parallel_chunks: chunks,
            ..config.clone()
        };
        let mut rng = <rand_pcg::Pcg64Mcg as rand::SeedableRng>::seed_from_u64(0);
        let (value, grads) =
            crate::trainer::loss_and_grads(&model, &refs, &augment, &mut rng, &device, &config);
        // Plain SGD with rate 1: the new weights are the old ones minus the gradient.
        let mut sgd = SgdConfig::new().init();
        let stepped = sgd.step(1.0, model.clone(), grads.expect("a finite loss"));
        (value, weights_of(&stepped.valid()))
    };
    let (whole, w1) = step(1);
    assert!(whole.is_finite());
    for chunks in [2, 3] {
        let (value, w) = step(chunks);
        assert!(
            (value - whole).abs() <= 1e-4 * (1.0 + whole.abs()),
            "{chunks} chunks: loss {value}, whole batch {whole}"
        );
        assert_eq!(w.len(), w1.len());
        let worst = w
            .iter()
            .zip(&w1)
            .map(|(a, b)| (a - b).abs() / (1.0 + b.abs()))
            .fold(0.0f32, f32::max);
        assert!(worst <= 1e-4, "{chunks} chunks: weights differ by {worst}");
        assert!(w != w1 || chunks == 1, "the chunked path ran");
    }
}

#[test]
fn an_epoch_with_joined_samples_keeps_its_length_and_takes_them_all() {
    // Nothing joined: one shuffle of every sample, as always.
    let plain = crate::trainer::epoch_order(50, 50, 7, 3);
    let mut sorted = plain.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, (0..50).collect::<Vec<_>>());
    assert_ne!(plain, sorted);
    // 20 joined samples: all of them and 30 of the others, each once.
    let order = crate::trainer::epoch_order(50, 70, 7, 3);
    assert_eq!(order.len(), 50);
    let mut sorted = order.clone();
    sorted.sort_unstable();
    sorted.dedup();
    assert_eq!(sorted.len(), 50);
    assert!((50..70).all(|i| order.contains(&i)));
    assert_eq!(order.iter().filter(|&&i| i < 50).count(), 30);
    // More joined samples than others: just the joined ones.
    let order = crate::trainer::epoch_order(10, 35, 7, 3);
    assert_eq!(order.len(), 25);
    assert!(order.iter().all(|&i| i >= 10));
}

#[test]
fn siblings_of_one_role_share_a_group_and_a_batch() {
    let dir = tempfile::tempdir().unwrap();
    tiny_cache(dir.path(), 3);
    let config = tiny_config(1);
    let dataset = scbg_features::cache::PreparedDataset::open(dir.path()).unwrap();
    let (train_set, _) = crate::data::load_samples(&dataset, &config).unwrap();
    let base = train_set
        .samples
        .iter()
        .find(|s| s.has_condition() && s.future_valid.iter().all(|&v| v))
        .expect("a fully valid pair sample")
        .clone();
    let variant = |mark: &str| scbg_features::AgentSample {
        scenario_id: format!("{}~{mark}", base.scenario_id),
        ..base.clone()
    };
    let sibling = |k: usize| scbg_features::AgentSample {
        condition_required: true,
        ..variant(&format!("rx{k}"))
    };
    use crate::trainer::group_key;
    // The logged sample, its counterfactual siblings and its reaction siblings share a group;
    // another target, another condition, no condition or a partial future do not.
    assert!(group_key(&base).is_some());
    assert_eq!(group_key(&base), group_key(&variant("cf0")));
    assert_eq!(group_key(&base), group_key(&sibling(1)));
    assert_eq!(group_key(&sibling(1)), group_key(&sibling(7)));
    let other = scbg_features::AgentSample {
        target_track_id: base.target_track_id + 1,
        ..sibling(1)
    };
    assert_ne!(group_key(&other), group_key(&sibling(1)));
    let other_condition = scbg_features::AgentSample {
        condition_track_id: base.condition_track_id.map(|id| id + 1),
        ..sibling(1)
    };
    assert_ne!(group_key(&other_condition), group_key(&sibling(1)));
    let marginal = scbg_features::AgentSample {
        condition_track_id: None,
        ..base.clone()
    };
    assert_eq!(group_key(&marginal), None);
    let mut partial = sibling(2);
    partial.future_valid[3] = false;
    assert_eq!(group_key(&partial), None);
    // Members move up to their first one; the rest keep their order; nothing is lost.
    let keys = [
        None,
        Some(1),
        None,
        Some(2),
        Some(1),
        None,
        Some(1),
        Some(2),
    ];
    let order = crate::trainer::keep_groups_together(vec![0, 1, 2, 3, 4, 5, 6, 7], &keys);
    assert_eq!(order, [0, 1, 4, 6, 2, 3, 7, 5]);
    let order = crate::trainer::keep_groups_together(vec![7, 5, 4, 0, 1, 2, 3, 6], &keys);
    assert_eq!(order, [7, 3, 5, 4, 1, 6, 0, 2]);
    // In a batch, two siblings whose A drives at different speeds add the contrast.
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let faster = |s: &scbg_features::AgentSample| {
        let mut s = s.clone();
        s.future_xy_m.iter_mut().for_each(|v| *v *= 1.5);
        s
    };
    let (model, device, augment) = seeded_model(&config);
    let loss = |refs: &[&scbg_features::AgentSample], weight: f32, chunks: usize, dropout: f64| {
        let config = TrainConfig {
            sibling_contrast_weight: weight,
            data_parallel_chunks: chunks,
            ..config.clone()
        };
        let augment = scbg_model::BatchAugment {
            condition_dropout: dropout,
            ..augment
        };
        let mut rng = <rand_pcg::Pcg64Mcg as rand::SeedableRng>::seed_from_u64(0);
        crate::trainer::loss_and_grads(&model, refs, &augment, &mut rng, &device, &config).0
    };
    let same = |a: f32, b: f32| (a - b).abs() <= 1e-4 * (1.0 + a.abs());
    let refs = [&sibling(1), &marginal, &faster(&sibling(2))];
    let (plain, with) = (loss(&refs, 0.0, 1, 0.0), loss(&refs, 1.0, 1, 0.0));
    assert!(with > plain + 1e-3, "{with} vs {plain}");
    // Split across chunks (one sibling in each), the group has nothing to compare with.
    let split = loss(&refs, 1.0, 2, 0.0);
    assert!(same(split, loss(&refs, 0.0, 2, 0.0)), "{split}");
    // A logged sample and a counterfactual sibling count only while the batch keeps their
    // condition (a reaction sibling's is never dropped).
    let refs = [&base, &faster(&variant("cf0"))];
    let with = loss(&refs, 1.0, 1, 0.0);
    assert!(with > loss(&refs, 0.0, 1, 0.0) + 1e-3, "{with}");
    let dropped = loss(&refs, 1.0, 1, 1.0);
    assert!(same(dropped, loss(&refs, 0.0, 1, 1.0)), "{dropped}");
}

#[test]
fn reaction_samples_join_at_their_epoch_made_from_the_run_itself() {
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let n = 16;
    tiny_cache(&data, n);
    let rx = dir.path().join("rx");
    let config = TrainConfig {
        reaction_cache: Some(rx.clone()),
        reaction_from_epoch: Some(1),
        ..tiny_config(2)
    };
    // Without a cache the option is refused.
    let err = TrainConfig {
        reaction_cache: None,
        ..config.clone()
    }
    .validate()
    .unwrap_err();
    assert!(err.to_string().contains("reaction_cache"), "{err}");
    struct Record(std::sync::Mutex<Vec<usize>>, bool);
    impl Progress for Record {
        fn epoch_start(&self, _epoch: usize, batches: usize) {
            self.0.lock().unwrap().push(batches);
        }
        fn stop_requested(&self) -> bool {
            self.1
        }
    }
    // The first epoch runs before the cache exists (it is made from its checkpoint)...
    let staged = dir.path().join("staged");
    let stop = Record(Default::default(), true);
    let first = train(&data, &staged, &config, false, &stop).unwrap();
    assert_eq!(first.state.epoch, 1);
    assert!(!rx.exists());
    cache_of(
        &rx,
        (0..n).flat_map(|i| {
            let s = scbg_synth::Scenario::draw(42, i, &scbg_synth::Family::DEFAULT);
            (0..3).map(move |k| s.counterfactual(k, 3))
        }),
    );
    // ... and the second, resumed, trains on the joined samples with as many batches.
    let rest = Record(Default::default(), false);
    train(&data, &staged, &config, true, &rest).unwrap();
    assert_eq!(*rest.0.lock().unwrap(), *stop.0.lock().unwrap());
    // The same as an uninterrupted run that finds the cache ready.
    let straight = dir.path().join("straight");
    train(&data, &straight, &config, false, &NoProgress).unwrap();
    assert!(weights(&straight) == weights(&staged), "staged run differs");
    // And not the same as a run without them.
    let without = dir.path().join("without");
    train(&data, &without, &tiny_config(2), false, &NoProgress).unwrap();
    assert!(weights(&without) != weights(&staged));
}
