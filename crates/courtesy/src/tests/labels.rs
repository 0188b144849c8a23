//! Labelling options: the baseline's extra futures, lane moves of the sampled futures, and
//! ensembles of predictors.

use super::*;

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
    b.lane_path_beside = vec![[true, true]; 40];
    let path = scbg_features::sample_lane_path(&b);
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
