use burn::optim::AdamConfig;
use burn::tensor::{Device, Tensor};
use rand::SeedableRng;
use scbg_courtesy::Reward;
use scbg_courtesy::label::{LabelOptions, MarginalEstimate};
use scbg_features::{
    FeatureConfig, FeatureStats, PairConfig, PreparedScene, SampleBuilder, WindowConfig,
};
use scbg_model::MultipathConfig;

use super::*;

mod audience;
mod candidates;
mod infer;

/// Held while a test seeds the device and draws from its random stream.
pub(crate) static SEED_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// The families of the tests' scenes: the ones the tolerances of these small-model checks were set
/// on (the let-in family is checked in `scbg-synth` and by the demo).
const FAMILIES: [scbg_synth::Family; 4] = [
    scbg_synth::Family::Merge,
    scbg_synth::Family::Crossing,
    scbg_synth::Family::Cutin,
    scbg_synth::Family::Following,
];

fn scenes(n: u64) -> Vec<PreparedScene> {
    (0..n)
        .map(|i| {
            let g = scbg_synth::generate(21, i, &FAMILIES);
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

/// Labelled examples of the first `n_scenes` test scenes (the paper's direct estimator, B's
/// futures sampled from the full mixture).
/// Takes the seed lock, seeds `device` and builds the small predictor on it: the setup of
/// every test here that draws a predictor's initial weights. Hold the guard for the test.
fn seeded_predictor(
    device: &Device,
    seed: u64,
) -> (
    std::sync::MutexGuard<'static, ()>,
    MultipathConfig,
    scbg_model::Multipath,
) {
    let guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    device.seed(seed);
    let config = MultipathConfig::cpu_small();
    let predictor = config.init(device);
    (guard, config, predictor)
}

fn labelled(
    predictor: &scbg_model::Multipath,
    n_scenes: u64,
    samples: usize,
    reward: Reward,
    seed: u64,
    device: &Device,
) -> Vec<Example> {
    let scenes = scenes(n_scenes);
    build_examples(
        predictor,
        &scenes,
        &stats(&scenes),
        &features(),
        LabelOptions {
            samples,
            reward,
            marginal: MarginalEstimate::Direct,
            audience: Default::default(),
            baseline_samples: 0,
            lane_move_steps: 0,
            keep_baseline: false,
            lane_move_room: scbg_features::FollowerRoom::HARD_BRAKING,
        },
        seed,
        device,
    )
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
fn variants_train_and_losses_fall() {
    let device = Device::flex().autodiff();
    let (_guard, config, predictor) = seeded_predictor(&device, 5);
    let examples = labelled(&predictor, 3, 3, Reward::AverageSpeed, 1, &device);
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
        let mut generator =
            GeneratorConfig::new(config.embedding_width(), config.num_modes).init(&device);
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
        // vs sampled futures) cannot be told apart by ψ: the best single output is a compromise
        // between them, close to where training starts. Only the baseline can fit closely.
        let bound = if variant == Variant::Baseline {
            0.5
        } else {
            1.0
        };
        assert!(last < bound * first, "{variant:?}: loss {first} -> {last}");
    }
    // The courtesy loss alone (trajectory weight 0) must send gradients into the generator
    // through J_φ (with an untrained predictor they are tiny, but they must not be zero).
    let generator = GeneratorConfig::new(config.embedding_width(), config.num_modes).init(&device);
    let losses = assert_courtesy_loss_reaches_generator(&generator, &predictor, &refs, &device);
    assert!(losses.trajectory > 0.0);
}

/// With the classification loss the generator learns which of B's modes each logged future
/// is. Each example's logged future is replaced by its least likely mode, so
/// the modes' probabilities alone pick another: after training, the likeliest candidate of
/// every example is that mode, and the loss has fallen.
#[test]
fn the_classification_loss_picks_the_nearest_mode() {
    let device = Device::flex().autodiff();
    let (_guard, config, predictor) = seeded_predictor(&device, 5);
    let mut examples = labelled(&predictor, 3, 3, Reward::AverageSpeed, 1, &device);
    device.seed(9);
    // B's modes alone: a slowed copy of the target mode would be as near as the mode early on.
    let mut gen_config = GeneratorConfig::new(config.embedding_width(), config.num_modes);
    gen_config.mode_slowdowns.clear();
    let mut generator = gen_config.init(&device);
    let to_vec = |t: Tensor<2>| -> Vec<f32> { t.into_data().try_to_vec::<f32>().unwrap() };
    let (want, mode_xy): (Vec<usize>, Vec<f32>) = {
        let refs: Vec<&Example> = examples.iter().collect();
        let modes =
            crate::b_modes_for(&generator, &predictor, &refs, Reward::AverageSpeed, &device);
        let lp = to_vec(modes.log_prob);
        let k = config.num_modes;
        let want = (0..refs.len())
            .map(|i| {
                (0..k)
                    .min_by(|&a, &b| lp[i * k + a].total_cmp(&lp[i * k + b]))
                    .unwrap()
            })
            .collect();
        (want, modes.xy.into_data().try_to_vec::<f32>().unwrap())
    };
    let (k, t) = (config.num_modes, examples[0].logged_valid.len());
    for (i, e) in examples.iter_mut().enumerate() {
        e.futures_b[0] = (0..t)
            .map(|s| {
                let m = ((i * k + want[i]) * t + s) * 2;
                [mode_xy[m], mode_xy[m + 1]]
            })
            .collect();
        e.logged_valid = vec![true; t];
    }
    let refs: Vec<&Example> = examples.iter().collect();
    let likeliest = |g: &Generator| -> Vec<usize> {
        let modes = crate::b_modes_for(g, &predictor, &refs, Reward::AverageSpeed, &device);
        let psi = Tensor::<1>::from_data(
            burn::tensor::TensorData::new(refs.iter().map(|e| e.psi[0]).collect(), [refs.len()]),
            &device,
        );
        g.forward_candidates(stored_embeddings(&refs, &device), psi, modes)
            .likeliest()
    };
    assert_ne!(
        likeliest(&generator),
        want,
        "the modes' probabilities alone pick them"
    );
    let options = step_options(Variant::Baseline, 1.0);
    let mut optim = AdamConfig::new().init();
    let mut losses = Vec::new();
    for _ in 0..60 {
        let (g, l) = train_step(generator, &mut optim, &predictor, &refs, &options, &device);
        generator = g;
        assert!(l.total.is_finite(), "{l:?}");
        losses.push(l.total);
    }
    assert!(
        losses[59] < 0.5 * losses[0],
        "loss {} -> {}",
        losses[0],
        losses[59]
    );
    assert_eq!(likeliest(&generator), want);
}

/// The full variant's loss with trajectory weight 0 (the courtesy loss alone): positive, and
/// its gradient reaches the generator's first decoder layer, finite and not all zero.
fn assert_courtesy_loss_reaches_generator(
    generator: &Generator,
    predictor: &scbg_model::Multipath,
    examples: &[&Example],
    device: &Device,
) -> StepLosses {
    let options = step_options(Variant::Full, 0.0);
    let (loss, losses) = step_loss(generator, predictor, examples, &options, device);
    assert!(
        losses.courtesy > 0.0 && losses.courtesy.is_finite(),
        "{losses:?}"
    );
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
    losses
}

#[test]
fn balanced_batches_mix_high_and_low() {
    let mut ex = Vec::new();
    let device = Device::flex();
    let (_guard, _, predictor) = seeded_predictor(&device, 5);
    let base = labelled(&predictor, 2, 1, Reward::Progress, 1, &device);
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
    let device = Device::flex().autodiff();
    let (_guard, config, predictor) = seeded_predictor(&device, 5);
    let mut examples = labelled(&predictor, 2, 1, Reward::Progress, 1, &device);
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
    for _ in 0..2000 {
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

/// `generate_and_measure` must agree with an independent path: the generator's forward, a
/// frame change through the samples' world poses, and `scbg_courtesy::courtesy`.
#[test]
fn measured_courtesy_matches_the_courtesy_function() {
    let device = Device::flex();
    let (_guard, config, predictor) = seeded_predictor(&device, 11);
    let examples = labelled(&predictor, 3, 2, Reward::AverageSpeed, 3, &device);
    let refs: Vec<&Example> = examples.iter().collect();
    let generator = GeneratorConfig::new(config.embedding_width(), config.num_modes).init(&device);
    let psi: Vec<Vec<f32>> = refs.iter().map(|_| vec![-0.5, 0.0, 0.7]).collect();
    let m = eval::generate_and_measure(
        &generator,
        &predictor,
        &refs,
        &psi,
        Reward::AverageSpeed,
        &device,
    );
    assert_eq!(m.psi.len(), refs.len());
    for (i, e) in refs.iter().enumerate() {
        for (j, &p) in psi[i].iter().enumerate() {
            let emb = stored_embeddings(&[e], &device);
            let modes =
                crate::b_modes_for(&generator, &predictor, &[e], Reward::AverageSpeed, &device);
            let direct: Vec<f32> = generator
                .forward(emb, Tensor::from_data([p], &device), modes)
                .into_data()
                .try_to_vec::<f32>()
                .unwrap();
            let ours: Vec<f32> = m.futures_b[i][j].iter().flat_map(|q| *q).collect();
            assert!(
                direct.iter().zip(&ours).all(|(a, b)| (a - b).abs() < 1e-4),
                "generated future differs"
            );
            // B's frame → A's frame via the world poses (not via a_from_b).
            let in_a = scbg_courtesy::label::change_frame(
                &m.futures_b[i][j],
                &e.b.world_from_agent,
                &e.a.world_from_agent,
            );
            let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
            let batch = scbg_model::Batch::from_samples(
                &[&e.a],
                &scbg_model::BatchAugment::default(),
                &mut rng,
                &device,
            );
            let terms = scbg_courtesy::courtesy(
                &predictor,
                &batch,
                scbg_courtesy::trajectories_tensor(&[in_a], &device),
                Reward::AverageSpeed,
                0.1,
            );
            let expected: f32 = terms.psi.into_scalar();
            let e_cond: f32 = terms.e_cond.into_scalar();
            assert!(
                (m.psi[i][j] - expected).abs() < 1e-4 * (1.0 + expected.abs()),
                "ψ {} vs courtesy() {expected}",
                m.psi[i][j]
            );
            assert!((m.e_cond[i][j] - e_cond).abs() < 1e-3 * (1.0 + e_cond.abs()));
        }
    }
    // The evaluation aggregates these numbers: CourtesyMSE(data) by hand.
    let range = RangePredictor::init(config.embedding_width(), 16, &device);
    let result = eval::evaluate(
        &generator,
        &range,
        &predictor,
        &refs,
        &eval::EvalOptions {
            arbitrary_min: -1.0,
            arbitrary_max: 1.0,
            high_threshold: 0.0,
            reward: Reward::AverageSpeed,
        },
        &device,
    );
    let data_psi: Vec<Vec<f32>> = refs.iter().map(|e| vec![e.psi[0]]).collect();
    let md = eval::generate_and_measure(
        &generator,
        &predictor,
        &refs,
        &data_psi,
        Reward::AverageSpeed,
        &device,
    );
    let by_hand: f64 = refs
        .iter()
        .enumerate()
        .map(|(i, e)| f64::from(e.psi[0] - md.psi[i][0]).powi(2))
        .sum::<f64>()
        / refs.len() as f64;
    let got = result.courtesy_mse_data.unwrap().mean;
    assert!(
        (got - by_hand).abs() <= 1e-6 * (1.0 + by_hand),
        "{got} vs {by_hand}"
    );
    assert_eq!(result.examples, refs.len());
    assert_eq!(result.per_quantile.len(), 9);
    assert!(result.traj_ade.unwrap().mean > 0.0);
    assert!(result.courtesy_mse_arbitrary.unwrap().mean.is_finite());
    // The ranked choice through the same evaluation: its futures are the examples' sampled
    // ones, J_φ measures each at its label, and the chosen labels rise with the quantile.
    let options = eval::EvalOptions {
        arbitrary_min: -1.0,
        arbitrary_max: 1.0,
        high_threshold: 0.0,
        reward: Reward::AverageSpeed,
    };
    let (ranked, m) =
        crate::ranked::evaluate_ranked(&range, &predictor, &refs, &options, &device).unwrap();
    assert_eq!(ranked.examples, refs.len());
    for (i, e) in refs.iter().enumerate() {
        let mut previous = f32::NEG_INFINITY;
        for j in 1..=9 {
            let k = e.futures_b[1..]
                .iter()
                .position(|f| *f == m.futures_b[i][j])
                .expect("a sampled future of the example");
            let label = e.psi[1 + k];
            assert!((m.psi[i][j] - label).abs() < 1e-4 * (1.0 + label.abs()));
            assert!(label >= previous);
            previous = label;
        }
    }
    assert!(ranked.corr_quantile.unwrap() > 0.0);
}
