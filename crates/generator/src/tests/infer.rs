//! `Scbg`: generating from a scene, and the ranked policy.

use super::*;

/// An untrained model (cpu-small predictor) for the test scenes,
/// labelling `samples` futures of B; and the ids of A and B of the first scene's first pair.
fn untrained_scbg(
    scenes: &[PreparedScene],
    samples: usize,
    policy: crate::Policy,
    device: &Device,
) -> (Scbg, i64, i64) {
    let config = MultipathConfig::cpu_small();
    let pair = scenes[0].pairs[0][0];
    let ids = (
        scenes[0].tracks[pair.first].id,
        scenes[0].tracks[pair.second].id,
    );
    let scbg = Scbg {
        predictor: config.init(device),
        generator: GeneratorConfig::new(config.embedding_width(), config.num_modes).init(device),
        range: RangePredictor::init(config.embedding_width(), 16, device),
        stats: stats(scenes),
        features: features(),
        labels: LabelOptions {
            samples,
            reward: Reward::AverageSpeed,
            marginal: MarginalEstimate::ConditionalAverage,
            audience: Default::default(),
            baseline_samples: 0,
            lane_move_steps: 0,
            keep_baseline: false,
            lane_move_room: scbg_features::FollowerRoom::HARD_BRAKING,
        },
        policy,
    };
    (scbg, ids.0, ids.1)
}

#[test]
fn generate_maps_quantiles_and_reports_bad_requests() {
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex();
    device.seed(12);
    let scenes = scenes(2);
    let scene = &scenes[0];
    let (scbg, a_id, b_id) = untrained_scbg(&scenes, 3, crate::Policy::Generator, &device);
    let window = &scene.windows[0];
    let out = scbg
        .generate(
            scene,
            window,
            a_id,
            b_id,
            &[0.1, 0.5, 0.9].map(Courtesy::Quantile),
            &device,
        )
        .unwrap();
    assert_eq!(out.len(), 3);
    let (lo, hi) = (out[0].psi_low, out[0].psi_high);
    assert!(hi >= lo);
    assert!((out[0].psi - lo).abs() < 1e-5 && (out[2].psi - hi).abs() < 1e-5);
    assert!(out[1].psi >= out[0].psi && out[2].psi >= out[1].psi);
    for g in &out {
        assert_eq!(g.world_xy_m.len(), 80);
        assert!(
            g.world_xy_m
                .iter()
                .all(|p| p[0].is_finite() && p[1].is_finite())
        );
        assert!(
            (g.achieved_psi - (g.a_expected_reward_conditional - g.a_expected_reward_marginal))
                .abs()
                < 1e-5
        );
    }
    assert!(matches!(
        scbg.generate(
            scene,
            window,
            a_id,
            999_999,
            &[Courtesy::Quantile(0.5)],
            &device
        ),
        Err(GenerateError::NoSuchTrack(999_999, _))
    ));
    // An explicit ψ gives the same future as the quantile it corresponds to.
    let by_psi = scbg
        .generate(
            scene,
            window,
            a_id,
            b_id,
            &[Courtesy::Psi(out[2].psi)],
            &device,
        )
        .unwrap();
    assert!((by_psi[0].quantile - 0.9).abs() < 1e-4);
    assert_eq!(by_psi[0].world_xy_m, out[2].world_xy_m);
    // One inference path: the closed-loop plan is the future `generate` measured.
    let plan = scbg
        .plan(scene, window, a_id, b_id, Courtesy::Quantile(0.9), &device)
        .unwrap();
    assert_eq!(plan, out[2].world_xy_m);
    assert!(matches!(
        scbg.generate(
            scene,
            window,
            a_id,
            a_id,
            &[Courtesy::Quantile(0.5)],
            &device
        ),
        Err(GenerateError::SameTrack(_))
    ));
}

#[test]
fn the_ranked_policy_picks_sampled_futures_by_their_labels() {
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex();
    device.seed(13);
    let scenes = scenes(2);
    let scene = &scenes[0];
    let (mut scbg, a_id, b_id) = untrained_scbg(&scenes, 6, crate::Policy::Ranked, &device);
    let window = &scene.windows[0];
    let quantiles = [0.0, 0.2, 0.4, 0.6, 0.8, 1.0];
    let out = scbg
        .generate(
            scene,
            window,
            a_id,
            b_id,
            &quantiles.map(Courtesy::Quantile),
            &device,
        )
        .unwrap();
    // Six candidates, six quantiles 1/6 apart: every candidate once, in the order of their
    // labels, and J_φ measures each at its label.
    for w in out.windows(2) {
        assert!(w[1].psi > w[0].psi, "{} then {}", w[0].psi, w[1].psi);
        assert_ne!(w[0].world_xy_m, w[1].world_xy_m);
    }
    for g in &out {
        assert!(
            (g.achieved_psi - g.psi).abs() < 1e-4,
            "{} vs {}",
            g.achieved_psi,
            g.psi
        );
        assert_eq!(g.world_xy_m.len(), 80);
    }
    // An explicit ψ takes the candidate with the nearest label; plan() gives the same futures.
    let by_psi = scbg
        .generate(
            scene,
            window,
            a_id,
            b_id,
            &[Courtesy::Psi(out[3].psi)],
            &device,
        )
        .unwrap();
    assert_eq!(by_psi[0].world_xy_m, out[3].world_xy_m);
    let plan = scbg
        .plan(scene, window, a_id, b_id, Courtesy::Quantile(0.8), &device)
        .unwrap();
    assert_eq!(plan, out[4].world_xy_m);
    // Without sampled futures there is nothing to rank: a clear error, not a panic.
    scbg.labels.samples = 0;
    assert!(matches!(
        scbg.generate(
            scene,
            window,
            a_id,
            b_id,
            &[Courtesy::Quantile(0.5)],
            &device
        ),
        Err(GenerateError::NoCandidates(0))
    ));
    assert!(matches!(
        scbg.plan(scene, window, a_id, b_id, Courtesy::Quantile(0.5), &device),
        Err(GenerateError::NoCandidates(0))
    ));
}

#[test]
fn candidates_taken_out_are_never_chosen() {
    let _guard = SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex();
    device.seed(14);
    let scenes = scenes(2);
    let scene = &scenes[0];
    let (scbg, a_id, b_id) = untrained_scbg(&scenes, 6, crate::Policy::Ranked, &device);
    let window = &scene.windows[0];
    let basis = scbg.plan_basis(scene, window, a_id, b_id, &device).unwrap();
    let quantiles = [0.0, 0.2, 0.4, 0.6, 0.8, 1.0];
    let plans_of = |basis: &crate::PlanBasis| -> Vec<Vec<[f64; 2]>> {
        quantiles
            .iter()
            .map(|&q| {
                scbg.plan_from(basis, Courtesy::Quantile(q), &device)
                    .unwrap()
            })
            .collect()
    };
    let plans = plans_of(&basis);
    // Take out the most courteous candidate: the other five remain, in the same order, and the
    // top quantile takes the next one.
    let top = plans[5].clone();
    let mut fewer = basis.clone();
    assert_eq!(fewer.drop_candidates(|f| f == top.as_slice()), 1);
    let after = plans_of(&fewer);
    assert!(after.iter().all(|p| *p != top));
    assert_eq!(after[5], plans[4]);
    assert_eq!(after[0], plans[0]);
    // Taking out every candidate would leave nothing to choose: none is taken out.
    let mut all = basis.clone();
    assert_eq!(all.drop_candidates(|_| true), 0);
    assert_eq!(
        scbg.plan_from(&all, Courtesy::Quantile(1.0), &device)
            .unwrap(),
        top
    );
    // The generator's basis has no candidates to take out.
    let (generator, _, _) = untrained_scbg(&scenes, 3, crate::Policy::Generator, &device);
    let mut g = generator
        .plan_basis(scene, window, a_id, b_id, &device)
        .unwrap();
    assert_eq!(g.drop_candidates(|_| true), 0);
}
