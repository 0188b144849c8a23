use burn::tensor::{Device, Tensor, TensorData};
use rand::SeedableRng;
use scbg_features::{
    AgentSample, FeatureConfig, FeatureStats, PairConfig, PreparedScene, SampleBuilder,
    WindowConfig,
};
use scbg_model::{Batch, BatchAugment, MultipathConfig};

use super::*;

mod audience;
mod labels;

/// burn's seeded RNG is process-global: tests that seed it must not interleave.
static SEED_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// The seed lock (hold it for the test), a flex device seeded with `seed` and an untrained
/// cpu-small model drawn from it.
fn seeded_cpu_small(
    seed: u64,
) -> (
    std::sync::MutexGuard<'static, ()>,
    Device,
    scbg_model::Multipath,
) {
    let guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex();
    device.seed(seed);
    let model = MultipathConfig::cpu_small().init(&device);
    (guard, device, model)
}
use crate::label::{SampleMixture, change_frame};
use scbg_model::Mixture;

#[test]
fn rewards_by_hand() {
    let d = Device::flex();
    // 10 steps at 1 m per 0.1 s along x: average speed 10 m/s, progress 10 m/s.
    let straight: Vec<f32> = (1..=10).flat_map(|i| [i as f32, 0.0]).collect();
    let xy = Tensor::<3>::from_data(TensorData::new(straight, [1, 10, 2]), &d);
    let v: f32 = Reward::AverageSpeed.evaluate(xy.clone(), 0.1).into_scalar();
    assert!((v - 10.0).abs() < 1e-3, "{v}");
    let p: f32 = Reward::Progress.evaluate(xy, 0.1).into_scalar();
    assert!((p - 10.0).abs() < 1e-4, "{p}");
    // Going sideways: speed 10, progress 0.
    let side: Vec<f32> = (1..=10).flat_map(|i| [0.0, i as f32]).collect();
    let xy = Tensor::<3>::from_data(TensorData::new(side, [1, 10, 2]), &d);
    assert!(
        (Reward::AverageSpeed
            .evaluate(xy.clone(), 0.1)
            .into_scalar::<f32>()
            - 10.0)
            .abs()
            < 1e-3
    );
    assert!(
        Reward::Progress
            .evaluate(xy, 0.1)
            .into_scalar::<f32>()
            .abs()
            < 1e-6
    );
    assert_eq!(Reward::parse("progress"), Some(Reward::Progress));
}

/// A from a synthetic merge/crossing/cut-in scene, conditioned on B; standardised.
fn pair_sample() -> AgentSample {
    let g = scbg_synth::generate(3, 1, &scbg_synth::Family::DEFAULT);
    let p = PreparedScene::from_scene(
        &g.scene,
        &WindowConfig::default(),
        &PairConfig::default(),
        4,
    )
    .unwrap();
    let cfg = FeatureConfig {
        max_other_agents: 4,
        max_road_segments: 16,
        ..Default::default()
    };
    let w = p.windows[0];
    let mut s = SampleBuilder::new(&p, &cfg).sample(&w, 0, Some(1)).unwrap();
    FeatureStats::fit([&s]).normalize(&mut s);
    s
}

#[test]
fn courtesy_gradient_matches_finite_differences() {
    use burn::optim::{AdamConfig, GradientsParams};
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex().autodiff();
    device.seed(11);
    let mut model = MultipathConfig::cpu_small().init(&device);
    let sample = pair_sample();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
    let batch = Batch::from_samples(&[&sample], &BatchAugment::default(), &mut rng, &device);
    // An untrained model's outputs are ~1e-3 m, too small for an f32 finite difference: fit the
    // pair briefly so that ψ and its gradient have realistic magnitudes.
    let mut optim = AdamConfig::new().init();
    for _ in 0..40 {
        let loss = scbg_model::gmm_nll(
            &model.forward(&batch),
            batch.future_xy.clone(),
            batch.future_valid.clone(),
        );
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        model = optim.step(3e-3, model, grads);
    }
    let t = sample.future_valid.len();
    let base: Vec<f32> = (0..t)
        .flat_map(|i| {
            [
                sample.condition_future_xy_m[2 * i],
                sample.condition_future_xy_m[2 * i + 1],
            ]
        })
        .collect();
    let psi_at = |values: Vec<f32>| -> f32 {
        let y = Tensor::<3>::from_data(TensorData::new(values, [1, t, 2]), &device);
        courtesy(&model, &batch, y, Reward::AverageSpeed, 0.1)
            .psi
            .into_scalar()
    };
    let y =
        Tensor::<3>::from_data(TensorData::new(base.clone(), [1, t, 2]), &device).require_grad();
    let terms = courtesy(&model, &batch, y.clone(), Reward::AverageSpeed, 0.1);
    let grads = terms.psi.sum().backward();
    let g: Vec<f32> = y
        .grad(&grads)
        .unwrap()
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    assert!(g.iter().any(|v| v.abs() > 0.0), "ψ does not depend on y_B");
    // Directional derivative along the normalised gradient: the finite-difference signal
    // |g|·h stays far above f32 rounding even when single coordinates barely matter.
    let norm = g.iter().map(|v| v * v).sum::<f32>().sqrt();
    // Max-pooling and ReLU kinks make very large steps unreliable and f32 rounding very small
    // ones: the check passes when some step in the usual range agrees within 5 %.
    let errors: Vec<(f32, f32)> = [0.02f32, 0.05, 0.1, 0.2, 0.5]
        .iter()
        .map(|&h| {
            let plus: Vec<f32> = base
                .iter()
                .zip(&g)
                .map(|(b, gi)| b + h * gi / norm)
                .collect();
            let minus: Vec<f32> = base
                .iter()
                .zip(&g)
                .map(|(b, gi)| b - h * gi / norm)
                .collect();
            let fd = (psi_at(plus) - psi_at(minus)) / (2.0 * h);
            (h, (fd - norm).abs() / norm)
        })
        .collect();
    assert!(
        errors.iter().any(|&(_, e)| e <= 0.05),
        "autodiff |∇ψ| = {norm}; relative errors of directional finite differences by step: {errors:?}"
    );
    // And one coordinate with a large step, for the sign of the biggest component.
    let i = (0..g.len())
        .max_by(|&a, &b| g[a].abs().total_cmp(&g[b].abs()))
        .unwrap();
    let (mut plus, mut minus) = (base.clone(), base.clone());
    plus[i] += 1.0;
    minus[i] -= 1.0;
    let fd = (psi_at(plus) - psi_at(minus)) / 2.0;
    assert_eq!(
        fd.signum(),
        g[i].signum(),
        "coordinate {i}: autodiff {} vs finite difference {fd}",
        g[i]
    );
}

#[test]
fn marginal_terms_do_not_depend_on_the_condition() {
    let (_guard, device, model) = seeded_cpu_small(11);
    let sample = pair_sample();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
    let batch = Batch::from_samples(&[&sample], &BatchAugment::default(), &mut rng, &device);
    let t = sample.future_valid.len();
    let y1 = Tensor::<3>::zeros([1, t, 2], &device);
    let y2 = Tensor::<3>::ones([1, t, 2], &device) * 5.0;
    let a = courtesy(&model, &batch, y1, Reward::Progress, 0.1);
    let b = courtesy(&model, &batch, y2, Reward::Progress, 0.1);
    assert_eq!(a.e_marg.into_scalar::<f32>(), b.e_marg.into_scalar::<f32>());
    assert_ne!(a.e_cond.into_scalar::<f32>(), b.e_cond.into_scalar::<f32>());
}

#[test]
fn frames_and_smooth_samples() {
    let a = scbg_scene::Pose2::new(10.0, 0.0, 0.0);
    let b = scbg_scene::Pose2::new(0.0, 0.0, std::f64::consts::FRAC_PI_2);
    // One metre ahead of B (heading +y) is world (0, 1) = (−10, 1) in A's frame.
    let p = change_frame(&[[1.0, 0.0]], &b, &a)[0];
    assert!((p[0] + 10.0).abs() < 1e-5 && (p[1] - 1.0).abs() < 1e-5);
    let mix = Mixture {
        xy: vec![(1..=80).map(|i| [i as f32, 0.0]).collect(); 2],
        abc: vec![vec![[0.0, 0.0, 0.0]; 80]; 2],
        probs: vec![0.5, 0.5],
    };
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
    let draws = mix.sample(50, 1.0, &mut rng);
    assert_eq!(draws.len(), 50);
    // One shared z per draw: the offset from the mean is the same at every step (Σ constant).
    for d in &draws {
        let off0 = [d[0][0] - 1.0, d[0][1]];
        assert!(
            d.iter()
                .enumerate()
                .all(|(i, p)| ((p[0] - (i + 1) as f32) - off0[0]).abs() < 1e-4
                    && (p[1] - off0[1]).abs() < 1e-4)
        );
    }
    let spread: f32 = draws.iter().map(|d| d[0][1].abs()).sum::<f32>() / 50.0;
    assert!(spread > 0.3 && spread < 1.5, "{spread}");
    // noise 0: mode means only.
    let means = mix.sample(10, 0.0, &mut rng);
    assert!(means.iter().all(|d| {
        d.iter()
            .enumerate()
            .all(|(i, p)| p[0] == (i + 1) as f32 && p[1] == 0.0)
    }));
}

/// The first synthetic merge scene with at least two background vehicles valid at the first
/// window's current step, and a feature configuration.
fn audience_setup() -> (PreparedScene, FeatureConfig) {
    let p = (0..50)
        .map(|i| {
            let g = scbg_synth::generate(3, i, &[scbg_synth::Family::Merge]);
            PreparedScene::from_scene(
                &g.scene,
                &WindowConfig::default(),
                &PairConfig::default(),
                4,
            )
            .unwrap()
        })
        .find(|p| {
            let now = p.windows[0].current_step as isize;
            !p.pairs[0].is_empty() && p.tracks.iter().filter(|t| t.valid_at(now)).count() >= 4
        })
        .expect("a merge scene with background traffic");
    let cfg = FeatureConfig {
        max_other_agents: 4,
        max_road_segments: 16,
        ..Default::default()
    };
    (p, cfg)
}

/// A (conditioned on B) and B of the first pair of `scene`'s first window, standardised by
/// A's own statistics (returned too), and B's marginal mixture under `model`.
fn standardised_pair(
    model: &scbg_model::Multipath,
    scene: &PreparedScene,
    cfg: &FeatureConfig,
    device: &Device,
) -> (AgentSample, AgentSample, FeatureStats, Mixture) {
    let w = scene.windows[0];
    let pair = scene.pairs[0][0];
    let mut builder = SampleBuilder::new(scene, cfg);
    let mut a = builder.sample(&w, pair.first, Some(pair.second)).unwrap();
    let mut b = builder.sample(&w, pair.second, None).unwrap();
    let stats = FeatureStats::fit([&a]);
    stats.normalize(&mut a);
    stats.normalize(&mut b);
    let mixture = crate::label::marginal_mixtures(model, &[&b], device).remove(0);
    (a, b, stats, mixture)
}
