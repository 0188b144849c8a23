use burn::optim::AdamConfig;
use burn::tensor::{Device, Tensor};
use rand::SeedableRng;
use scbg_courtesy::Reward;
use scbg_courtesy::label::LabelOptions;
use scbg_features::{
    FeatureConfig, FeatureStats, PairConfig, PreparedScene, SampleBuilder, WindowConfig,
};
use scbg_model::MultipathConfig;

use super::*;

static SEED_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn scenes(n: u64) -> Vec<PreparedScene> {
    (0..n)
        .map(|i| {
            let g = scbg_synth::generate(21, i, &scbg_synth::Family::ALL);
            PreparedScene::from_scene(
                &g.scene,
                &WindowConfig::default(),
                &PairConfig::default(),
                4,
            )
            .unwrap()
        })
        .collect()
}

fn features() -> FeatureConfig {
    FeatureConfig {
        max_other_agents: 4,
        max_road_segments: 16,
        ..Default::default()
    }
}

fn stats(scenes: &[PreparedScene]) -> FeatureStats {
    let f = features();
    let samples: Vec<_> = scenes
        .iter()
        .map(|s| {
            SampleBuilder::new(s, &f)
                .sample(&s.windows[0], 0, None)
                .unwrap()
        })
        .collect();
    FeatureStats::fit(samples.iter())
}

fn step_options(variant: Variant, trajectory_weight: f32) -> StepOptions {
    StepOptions {
        variant,
        alpha: 0.5,
        beta: 1.0,
        huber_delta: 1.0,
        trajectory_weight,
        reward: Reward::AverageSpeed,
        learning_rate: 3e-3,
    }
}

#[test]
fn forward_shape() {
    let device = Device::flex();
    let g = GeneratorConfig::new(24).init(&device);
    let out = g.forward(Tensor::zeros([3, 24], &device), Tensor::zeros([3], &device));
    assert_eq!(out.dims(), [3, 80, 2]);
}

#[test]
fn variants_train_and_losses_fall() {
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex().autodiff();
    device.seed(5);
    let config = MultipathConfig::cpu_small();
    let predictor = config.init(&device);
    let scenes = scenes(3);
    let examples = build_examples(
        &predictor,
        &scenes,
        &stats(&scenes),
        &features(),
        LabelOptions {
            samples: 3,
            reward: Reward::AverageSpeed,
        },
        1,
        &device,
    );
    assert_eq!(examples.len(), 6, "3 scenes × 1 pair × 2 roles");
    assert!(
        examples
            .iter()
            .all(|e| e.psi.len() == 4 && e.futures_b.len() == 4)
    );
    // The logged future in B's frame starts near B's origin and heads forward.
    let first = examples[0].futures_b[0][0];
    assert!(first[0].abs() < 5.0 && first[1].abs() < 2.0, "{first:?}");
    let refs: Vec<&Example> = examples.iter().collect();
    for variant in [Variant::Baseline, Variant::Augmented, Variant::Full] {
        device.seed(9);
        let mut generator = GeneratorConfig::new(config.embedding_width()).init(&device);
        let mut optim = AdamConfig::new().init();
        let options = step_options(variant, 1.0);
        let mut first = None;
        let mut last = None;
        for _ in 0..30 {
            let (g, losses) =
                train_step(generator, &mut optim, &predictor, &refs, &options, &device);
            generator = g;
            assert!(losses.total.is_finite(), "{variant:?}: {losses:?}");
            if variant == Variant::Full {
                assert!(losses.courtesy > 0.0);
            } else {
                assert_eq!(losses.courtesy, 0.0);
            }
            first.get_or_insert(losses.total);
            last = Some(losses.total);
        }
        let (first, last) = (first.unwrap(), last.unwrap());
        // With an untrained predictor the ψ labels are ~1e-5, so the augmented targets (logged
        // vs sampled futures) cannot be told apart by ψ: only the baseline can fit closely.
        let bound = if variant == Variant::Baseline {
            0.5
        } else {
            0.99
        };
        assert!(last < bound * first, "{variant:?}: loss {first} -> {last}");
    }
    // The courtesy loss alone (trajectory weight 0) must send gradients into the generator
    // through J_φ (with an untrained predictor they are tiny, but they must not be zero).
    let generator = GeneratorConfig::new(config.embedding_width()).init(&device);
    let options = step_options(Variant::Full, 0.0);
    let (loss, losses) = step_loss(&generator, &predictor, &refs, &options, &device);
    assert!(losses.courtesy > 0.0 && losses.trajectory > 0.0);
    let grads = loss.backward();
    let g: Vec<f32> = generator.decoder.layers[0]
        .weight
        .grad(&grads)
        .expect("gradient reaches the generator")
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    assert!(
        g.iter().any(|v| *v != 0.0),
        "the courtesy loss has no gradient in the generator"
    );
    assert!(g.iter().all(|v| v.is_finite()));
}

#[test]
fn balanced_batches_mix_high_and_low() {
    let mut ex = Vec::new();
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex();
    device.seed(5);
    let predictor = MultipathConfig::cpu_small().init(&device);
    let scenes = scenes(2);
    let base = build_examples(
        &predictor,
        &scenes,
        &stats(&scenes),
        &features(),
        LabelOptions {
            samples: 1,
            reward: Reward::Progress,
        },
        1,
        &device,
    );
    for (i, psi) in [0.1f32, 0.2, 3.0, 0.05, 2.5, 0.0, 0.3, 4.0]
        .iter()
        .enumerate()
    {
        let mut e = base[i % base.len()].clone();
        e.psi[0] = *psi;
        ex.push(e);
    }
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
    for b in balanced_batches(&ex, Threshold::Absolute(2.0), 4, 10, &mut rng) {
        assert_eq!(b.len(), 4);
        assert_eq!(
            b.iter().filter(|&&i| ex[i].psi[0].abs() > 2.0).count(),
            2,
            "{b:?}"
        );
    }
    // Quantile 0.75 of |ψ| = 2.5 → only 3.0 and 4.0 are "high".
    for b in balanced_batches(&ex, Threshold::Quantile(0.75), 4, 10, &mut rng) {
        assert!(b[..2].iter().all(|&i| ex[i].psi[0].abs() > 2.5), "{b:?}");
    }
}

#[test]
fn quantile_mapping() {
    assert!((psi_for_quantile(0.1, -1.0, 3.0) + 1.0).abs() < 1e-6);
    assert!((psi_for_quantile(0.9, -1.0, 3.0) - 3.0).abs() < 1e-6);
    assert!((psi_for_quantile(0.5, -1.0, 3.0) - 1.0).abs() < 1e-6);
    assert!((psi_for_quantile(0.0, -1.0, 3.0) + 1.5).abs() < 1e-6);
    assert!(psi_for_quantile(0.3, 0.0, 2.0) < psi_for_quantile(0.7, 0.0, 2.0));
}

#[test]
fn range_predictor_learns_the_quantiles_and_stays_ordered() {
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex().autodiff();
    device.seed(5);
    let config = MultipathConfig::cpu_small();
    let predictor = config.init(&device);
    let scenes = scenes(2);
    let mut examples = build_examples(
        &predictor,
        &scenes,
        &stats(&scenes),
        &features(),
        LabelOptions {
            samples: 1,
            reward: Reward::Progress,
        },
        1,
        &device,
    );
    // Replace the labels by a known distribution: ψ uniform on 0..10 in every example, so the
    // 0.1 and 0.9 quantiles are 1 and 9 whatever the scene.
    for e in &mut examples {
        e.psi = (0..=10).map(|v| v as f32).collect();
    }
    let refs: Vec<&Example> = examples.iter().collect();
    let embedding = stored_embeddings(&refs, &device);
    let labels: Vec<&[f32]> = examples.iter().map(|e| e.psi.as_slice()).collect();
    let mut range = RangePredictor::init(config.embedding_width(), 32, &device);
    let mut optim = AdamConfig::new().init();
    for _ in 0..400 {
        let (r, loss) = range_step(range, &mut optim, embedding.clone(), &labels, 2e-2);
        range = r;
        assert!(loss.is_finite());
    }
    let (low, high) = range.forward(embedding);
    let low: Vec<f32> = low.into_data().try_to_vec::<f32>().unwrap();
    let high: Vec<f32> = high.into_data().try_to_vec::<f32>().unwrap();
    for (l, h) in low.iter().zip(&high) {
        assert!(h >= l, "q0.9 {h} < q0.1 {l}");
        assert!(
            (l - 1.0).abs() < 0.6 && (h - 9.0).abs() < 0.6,
            "quantiles ({l}, {h}), expected (1, 9)"
        );
    }
}
