use burn::tensor::{Device, Tensor, TensorData};
use rand::SeedableRng;
use scbg_features::{
    AgentSample, FeatureConfig, FeatureStats, PairConfig, PreparedScene, SampleBuilder,
    WindowConfig,
};
use scbg_model::{Batch, BatchAugment, MultipathConfig};

use super::*;

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
    let g = scbg_synth::generate(3, 1, &scbg_synth::Family::ALL);
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

#[test]
fn audience_weights_names_and_members() {
    use crate::audience::MAX_NEIGHBOURS;
    assert_eq!(Audience::Pair.weight(12.0), 1.0);
    let sum = Audience::parse("neighbours", 20.0, Weighting::Sum).unwrap();
    assert_eq!(sum.weight(15.0), 1.0);
    let prox = Audience::parse("neighbours", 20.0, Weighting::Proximity).unwrap();
    assert_eq!(prox.weight(0.0), 1.0);
    assert_eq!(prox.describe(), "neighbours 20 m proximity");
    assert_eq!(Audience::Pair.describe(), "pair");
    assert!((prox.weight(20.0) - 0.5).abs() < 1e-7);
    assert!(prox.weight(5.0) > prox.weight(10.0));
    for bad in [0.0, -3.0, f32::NAN, f32::INFINITY] {
        let e = Audience::parse("neighbours", bad, Weighting::Sum).unwrap_err();
        assert!(e.contains("radius"), "{e}");
    }
    assert!(Audience::parse("everyone", 20.0, Weighting::Sum).is_err());
    assert_eq!(
        Audience::parse("pair", f32::NAN, Weighting::Sum),
        Ok(Audience::Pair)
    );

    let (scene, _) = audience_setup();
    let w = scene.windows[0];
    let pair = scene.pairs[0][0];
    let (a, b) = (pair.first, pair.second);
    assert!(Audience::Pair.others(&scene, &w, a, b).is_empty());
    let now = w.current_step;
    let dist = |j: usize| {
        let (p, q) = (&scene.tracks[j], &scene.tracks[b]);
        f64::from(p.x_m[now] - q.x_m[now]).hypot(f64::from(p.y_m[now] - q.y_m[now]))
    };
    let mut checked_some = false;
    for radius in [5.0f32, 30.0, 80.0, 1e4] {
        let aud = Audience::parse("neighbours", radius, Weighting::Sum).unwrap();
        let got = aud.others(&scene, &w, a, b);
        // The brute-force audience: every other valid vehicle within the radius, nearest first.
        let mut all: Vec<(usize, f64)> = (0..scene.tracks.len())
            .filter(|&j| {
                j != a
                    && j != b
                    && scene.tracks[j].object_type == scbg_scene::ObjectType::Vehicle
                    && scene.tracks[j].valid_at(now as isize)
                    && dist(j) <= f64::from(radius)
            })
            .map(|j| (j, dist(j)))
            .collect();
        all.sort_by(|x, y| x.1.total_cmp(&y.1));
        all.truncate(MAX_NEIGHBOURS);
        assert_eq!(got, all, "radius {radius}");
        checked_some |= !got.is_empty();
    }
    assert!(checked_some, "the scene has no neighbours at any radius");
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

#[test]
fn audience_psi_is_the_weighted_sum_of_each_members_psi() {
    use crate::label::{LabelOptions, MarginalEstimate, audience_members, label_pair, label_role};
    let (_guard, device, model) = seeded_cpu_small(5);
    let (scene, cfg) = audience_setup();
    let w = scene.windows[0];
    let pair = scene.pairs[0][0];
    let (ia, ib) = (pair.first, pair.second);
    let (a, b, stats, mixture) = standardised_pair(&model, &scene, &cfg, &device);
    let mut builder = SampleBuilder::new(&scene, &cfg);
    // A radius that takes in every vehicle, the farthest at half weight.
    let far = Audience::parse("neighbours", 1e4, Weighting::Sum)
        .unwrap()
        .others(&scene, &w, ia, ib)
        .iter()
        .map(|&(_, d)| d)
        .fold(Audience::distance_between(&scene, &w, ia, ib), f64::max);
    let audience = Audience::parse("neighbours", far as f32 + 1e-3, Weighting::Proximity).unwrap();
    let others = audience_members(&mut builder, &scene, &stats, &w, ia, ib, audience);
    assert!(others.len() >= 2, "{} neighbours", others.len());
    let wa = audience.weight(Audience::distance_between(&scene, &w, ia, ib));
    for marginal in [
        MarginalEstimate::Direct,
        MarginalEstimate::ConditionalAverage,
    ] {
        let options = LabelOptions {
            samples: 3,
            reward: Reward::AverageSpeed,
            marginal,
            sample_noise: 1.0,
            audience,
            baseline_samples: 0,
            lane_move_steps: 0,
            keep_baseline: false,
            lane_move_room: scbg_features::FollowerRoom::HARD_BRAKING,
        };
        let rng = || rand_pcg::Pcg64Mcg::seed_from_u64(9);
        let all = label_role(
            &model,
            (&a, wa),
            &others,
            &b,
            &mixture,
            options,
            &mut rng(),
            &device,
        );
        assert_eq!(all.terms.len(), 1 + others.len());
        // Each member alone, with the same draws of B's futures.
        let members: Vec<(&AgentSample, f32)> = std::iter::once((&a, wa))
            .chain(others.iter().map(|m| (&m.sample, m.weight)))
            .collect();
        let mut psi = vec![0.0f64; all.psi.len()];
        let mut e_marg = 0.0f64;
        let mut scale = 0.0f64;
        for (j, &(s, weight)) in members.iter().enumerate() {
            let alone = label_role(
                &model,
                (s, 1.0),
                &[],
                &b,
                &mixture,
                options,
                &mut rng(),
                &device,
            );
            for (k, p) in alone.psi.iter().enumerate() {
                psi[k] += f64::from(weight) * f64::from(*p);
                scale = scale.max(f64::from(p.abs()));
            }
            e_marg += f64::from(weight) * f64::from(alone.e_marg);
            assert_eq!(all.terms[j].weight, weight);
            assert!((all.terms[j].e_marg - alone.e_marg).abs() < 1e-4);
            if j == 0 {
                // A alone is the paper's label.
                let paper = label_pair(&model, &a, &b, &mixture, options, &mut rng(), &device);
                assert_eq!(paper, alone);
                assert_eq!(all.futures_in_a, alone.futures_in_a);
            }
        }
        // An untrained model's ψ is tiny: compare on the scale of the members' terms.
        let scale = scale.max(1e-6);
        eprintln!(
            "{marginal:?}: weights {:?}, ψ {:?} (scale {scale})",
            all.terms, all.psi
        );
        for (k, (&got, want)) in all.psi.iter().zip(&psi).enumerate() {
            assert!(
                (f64::from(got) - want).abs() < 0.02 * scale,
                "{marginal:?} future {k}: ψ {got} vs Σ w ψ_j {want}"
            );
        }
        assert!((f64::from(all.e_marg) - e_marg).abs() < 1e-3 * (1.0 + e_marg.abs()));
    }
}

#[test]
fn baseline_samples_widen_the_marginal_estimate_and_label_only_the_first_futures() {
    use crate::label::{LabelOptions, MarginalEstimate, label_pair};
    let (_guard, device, model) = seeded_cpu_small(6);
    let (scene, cfg) = audience_setup();
    let (a, b, _, mixture) = standardised_pair(&model, &scene, &cfg, &device);
    let options = |samples, baseline_samples| LabelOptions {
        samples,
        reward: Reward::AverageSpeed,
        marginal: MarginalEstimate::ConditionalAverage,
        sample_noise: 1.0,
        audience: Audience::Pair,
        baseline_samples,
        lane_move_steps: 0,
        keep_baseline: false,
        lane_move_room: scbg_features::FollowerRoom::HARD_BRAKING,
    };
    let label = |o| {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(11);
        label_pair(&model, &a, &b, &mixture, o, &mut rng, &device)
    };
    // 3 labelled futures and 5 more for the baseline draw the same 8 futures as 8 labelled
    // ones: the first 4 (logged + 3) are the same, scored the same, against the same mean.
    let wide = label(options(3, 5));
    let all = label(options(8, 0));
    let narrow = label(options(3, 0));
    assert_eq!(wide.psi.len(), 4);
    assert_eq!(wide.futures_in_a, all.futures_in_a[..4].to_vec());
    assert_eq!(wide.e_cond, all.e_cond[..4].to_vec());
    assert_eq!(wide.e_marg, all.e_marg);
    let mean8 = all.e_cond[1..].iter().sum::<f32>() / 8.0;
    assert!((wide.e_marg - mean8).abs() < 1e-5 * (1.0 + mean8.abs()));
    for k in 0..4 {
        assert!((wide.psi[k] - (wide.e_cond[k] - wide.e_marg)).abs() < 1e-6);
    }
    // Without them the baseline is the mean over the 3 labelled futures alone.
    for (n, w) in narrow.e_cond.iter().zip(&wide.e_cond) {
        assert!((n - w).abs() < 1e-5 * (1.0 + w.abs()), "{n} vs {w}");
    }
    let mean3 = narrow.e_cond[1..].iter().sum::<f32>() / 3.0;
    assert!((narrow.e_marg - mean3).abs() < 1e-5 * (1.0 + mean3.abs()));
    assert_ne!(narrow.e_marg, wide.e_marg);
    // Kept, the baseline's futures are labelled after the first 3: the labels of 8 sampled
    // futures, to the last bit.
    let kept = label(LabelOptions {
        keep_baseline: true,
        ..options(3, 5)
    });
    assert_eq!(options(3, 5).labelled_samples(), 3);
    assert_eq!(
        LabelOptions {
            keep_baseline: true,
            ..options(3, 5)
        }
        .labelled_samples(),
        8
    );
    assert_eq!(kept.psi, all.psi);
    assert_eq!(kept.e_cond, all.e_cond);
    assert_eq!(kept.e_marg, all.e_marg);
    assert_eq!(kept.futures_in_a, all.futures_in_a);
}

/// With lane moves, the sampled futures that drift off B's lane path are labelled once more,
/// completed, after the sampled ones; the logged and sampled futures keep their labels and
/// E[r(Y_A) | x] is still the mean over the sampled futures alone.
#[test]
fn lane_moves_of_the_sampled_futures_are_labelled_after_them() {
    use crate::label::{LabelOptions, MarginalEstimate, SampleMixture, change_frame, label_pair};
    let (_guard, device, model) = seeded_cpu_small(6);
    let (scene, cfg) = audience_setup();
    let (a, mut b, _, mixture) = standardised_pair(&model, &scene, &cfg, &device);
    let options = |lane_move_steps| LabelOptions {
        samples: 4,
        reward: Reward::AverageSpeed,
        marginal: MarginalEstimate::ConditionalAverage,
        sample_noise: 1.0,
        audience: Audience::Pair,
        baseline_samples: 3,
        lane_move_steps,
        keep_baseline: false,
        lane_move_room: scbg_features::FollowerRoom::HARD_BRAKING,
    };
    let rng = || rand_pcg::Pcg64Mcg::seed_from_u64(11);
    // The futures label_pair draws (the same stream), in B's frame.
    let drawn = mixture.sample(4, 1.0, &mut rng());
    // B's lane path: a straight line through B, turned so that the drawn future reaching
    // furthest ends up to 2.5 m to its left (a drift a lane move completes; an untrained
    // predictor's futures are short).
    let end = drawn
        .iter()
        .map(|f| *f.last().unwrap())
        .max_by(|p, q| p[0].hypot(p[1]).total_cmp(&q[0].hypot(q[1])))
        .unwrap();
    let reach = end[0].hypot(end[1]);
    let drift = (0.7 * reach).min(2.5);
    assert!(drift > 1.1, "the sampled futures go nowhere: {drawn:?}");
    let heading = end[1].atan2(end[0]) - (drift / reach).asin();
    let (sin, cos) = heading.sin_cos();
    b.lane_path_xy_m = (0..40)
        .flat_map(|k| {
            let s = k as f32 * 5.0 - 20.0;
            [s * cos, s * sin]
        })
        .collect();
    b.lane_path_valid = vec![true; 40];
    let path = scbg_features::lane_path_points(&b);
    // Those that leave A room where they enter its lane (A driving on at its velocity).
    let a_now = change_frame(
        &[[0.0, 0.0], a.current_velocity_mps],
        &a.world_from_agent,
        &b.world_from_agent,
    );
    let a_velocity = [a_now[1][0] - a_now[0][0], a_now[1][1] - a_now[0][1]];
    let room = options(30).lane_move_room;
    let moves_of = |futures: &[Vec<[f32; 2]>]| -> Vec<Vec<[f32; 2]>> {
        futures
            .iter()
            .filter_map(|f| scbg_features::lane_move(f, &path, 30))
            .filter(|m| scbg_features::leaves_room(m, a_now[0], a_velocity, room))
            .collect()
    };
    let moved = moves_of(&drawn);
    assert!(!moved.is_empty() && moved.len() <= 4);
    let plain = label_pair(&model, &a, &b, &mixture, options(0), &mut rng(), &device);
    let with = label_pair(&model, &a, &b, &mixture, options(30), &mut rng(), &device);
    assert_eq!(plain.psi.len(), 5);
    assert_eq!(with.psi.len(), 5 + moved.len());
    assert_eq!(with.futures_in_a.len(), with.psi.len());
    assert_eq!(with.e_cond.len(), with.psi.len());
    assert_eq!(with.futures_in_a[..5], plain.futures_in_a[..]);
    assert_eq!(with.e_marg, plain.e_marg);
    for k in 0..5 {
        assert!((with.psi[k] - plain.psi[k]).abs() < 1e-5, "future {k}");
    }
    for (m, in_a) in moved.iter().zip(&with.futures_in_a[5..]) {
        let want = change_frame(m, &b.world_from_agent, &a.world_from_agent);
        for (p, q) in want.iter().zip(in_a) {
            assert!((p[0] - q[0]).abs() < 1e-4 && (p[1] - q[1]).abs() < 1e-4);
        }
    }
    for k in 0..with.psi.len() {
        assert!((with.psi[k] - (with.e_cond[k] - with.e_marg)).abs() < 1e-5);
    }
    // The baseline's 3 futures kept: labelled after the 4, and the moves taken from all 7
    // (the same draws), against the same E[r(Y_A) | x].
    let drawn_all = mixture.sample(7, 1.0, &mut rng());
    assert_eq!(drawn_all[..4], drawn[..]);
    let moves_all = moves_of(&drawn_all);
    let kept = LabelOptions {
        keep_baseline: true,
        ..options(30)
    };
    let kept = label_pair(&model, &a, &b, &mixture, kept, &mut rng(), &device);
    assert_eq!(kept.psi.len(), 8 + moves_all.len());
    assert_eq!(kept.futures_in_a[..5], with.futures_in_a[..5]);
    // Rows 5..8 are the baseline's draws, and the moves of all 7 follow them.
    for (f, in_a) in drawn_all[4..]
        .iter()
        .chain(&moves_all)
        .zip(&kept.futures_in_a[5..])
    {
        let want = change_frame(f, &b.world_from_agent, &a.world_from_agent);
        for (p, q) in want.iter().zip(in_a) {
            assert!((p[0] - q[0]).abs() < 1e-4 && (p[1] - q[1]).abs() < 1e-4);
        }
    }
    assert!((kept.e_marg - with.e_marg).abs() < 1e-5 * (1.0 + with.e_marg.abs()));
    for k in 0..5 {
        assert!((kept.psi[k] - with.psi[k]).abs() < 1e-5, "future {k}");
    }
}

#[test]
fn an_ensemble_scores_the_first_members_futures_with_every_member_and_averages() {
    use crate::label::{
        LabelOptions, MarginalEstimate, label_role, label_scene, label_scene_ensemble,
        marginal_mixtures,
    };
    use rand::Rng;
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex();
    device.seed(11);
    let first = MultipathConfig::cpu_small().init(&device);
    let second = MultipathConfig::cpu_small().init(&device);
    let (scene, cfg) = audience_setup();
    let w = scene.windows[0];
    let mut builder = SampleBuilder::new(&scene, &cfg);
    let pair = scene.pairs[0][0];
    let raw = builder.sample(&w, pair.first, Some(pair.second)).unwrap();
    // Different statistics per member: each member standardises its own inputs.
    let stats_first = FeatureStats::fit([&raw]);
    let everyone: Vec<AgentSample> = (0..scene.tracks.len())
        .filter_map(|t| builder.sample(&w, t, None).ok())
        .collect();
    assert!(everyone.len() > 2);
    let stats_second = FeatureStats::fit(&everyone);
    assert_ne!(stats_first, stats_second);
    let options = LabelOptions {
        samples: 3,
        reward: Reward::AverageSpeed,
        marginal: MarginalEstimate::ConditionalAverage,
        sample_noise: 1.0,
        audience: Audience::Pair,
        baseline_samples: 0,
        lane_move_steps: 0,
        keep_baseline: false,
        lane_move_room: scbg_features::FollowerRoom::HARD_BRAKING,
    };
    let rng = || rand_pcg::Pcg64Mcg::seed_from_u64(4);
    let label = |members: &[(&Multipath, &FeatureStats)]| {
        let mut r = rng();
        let roles = label_scene_ensemble(members, &scene, &cfg, options, &mut r, &device);
        (roles, r.random::<u64>())
    };
    let (alone, after_alone) = {
        let mut r = rng();
        let roles = label_scene(&first, &scene, &stats_first, &cfg, options, &mut r, &device);
        (roles, r.random::<u64>())
    };
    assert!(!alone.is_empty());

    // A member twice is that member: same labels, same futures, the same stream afterwards.
    let (twice, after_twice) = label(&[(&first, &stats_first), (&first, &stats_first)]);
    assert_eq!(after_twice, after_alone);
    assert_eq!(twice.len(), alone.len());
    for (t, a) in twice.iter().zip(&alone) {
        assert_eq!(t.labels, a.labels);
    }

    // Two members: each future's ψ and E[r | x, y_B] are the means of the members' on the
    // first member's futures, which the second standardises with its own statistics.
    let (both, after_both) = label(&[(&first, &stats_first), (&second, &stats_second)]);
    assert_eq!(after_both, after_alone);
    let mut r = rng();
    for (e, a) in both.iter().zip(&alone) {
        assert_eq!(e.labels.futures_in_a, a.labels.futures_in_a);
        assert_eq!((e.a_id, e.b_id), (a.a_id, a.b_id));
        // The second member on the first member's futures, by hand.
        let mut a2 = builder.sample(&w, e.a_index, Some(e.b_index)).unwrap();
        let mut b2 = builder.sample(&w, e.b_index, None).unwrap();
        stats_second.normalize(&mut a2);
        stats_second.normalize(&mut b2);
        let mixture = marginal_mixtures(&first, &[&a.b], &device).remove(0);
        let draws = r.clone();
        let by_hand = label_role(
            &second,
            (&a2, 1.0),
            &[],
            &b2,
            &mixture,
            options,
            &mut draws.clone(),
            &device,
        );
        // Advance the reference stream as the role's labelling did.
        let _ = label_role(
            &first,
            (&a.a, 1.0),
            &[],
            &a.b,
            &mixture,
            options,
            &mut r,
            &device,
        );
        assert_eq!(by_hand.futures_in_a, a.labels.futures_in_a);
        let close = |x: f32, y: f32| (x - y).abs() <= 1e-5 * (1.0 + x.abs().max(y.abs()));
        for k in 0..e.labels.psi.len() {
            let want = 0.5 * (a.labels.psi[k] + by_hand.psi[k]);
            assert!(
                close(e.labels.psi[k], want),
                "future {k}: {} vs {want}",
                e.labels.psi[k]
            );
            let want = 0.5 * (a.labels.e_cond[k] + by_hand.e_cond[k]);
            assert!(close(e.labels.e_cond[k], want));
        }
        assert!(close(
            e.labels.e_marg,
            0.5 * (a.labels.e_marg + by_hand.e_marg)
        ));
        // The members disagree: the mean is neither.
        assert_ne!(by_hand.psi, a.labels.psi);
    }
}
