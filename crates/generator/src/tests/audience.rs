//! Courtesy toward B's neighbours: measured, and as the generator's loss.

use super::*;

/// Examples labelled toward B's neighbours (every vehicle of the scene, weighted by proximity).
fn labelled_toward_neighbours(
    predictor: &scbg_model::Multipath,
    n_scenes: u64,
    device: &Device,
) -> Vec<Example> {
    let scenes = scenes(n_scenes);
    let audience =
        scbg_courtesy::Audience::parse("neighbours", 60.0, scbg_courtesy::Weighting::Proximity)
            .unwrap();
    build_examples(
        predictor,
        &scenes,
        &stats(&scenes),
        &features(),
        LabelOptions {
            samples: 2,
            reward: Reward::AverageSpeed,
            marginal: MarginalEstimate::ConditionalAverage,
            audience,
            baseline_samples: 0,
            lane_move_steps: 0,
            keep_baseline: false,
            lane_move_room: scbg_features::FollowerRoom::HARD_BRAKING,
        },
        4,
        device,
    )
}

#[test]
fn measured_courtesy_toward_an_audience_sums_its_members() {
    let device = Device::flex();
    let (_guard, config, predictor) = seeded_predictor(&device, 13);
    let examples = labelled_toward_neighbours(&predictor, 8, &device);
    let crowded: Vec<&Example> = examples.iter().filter(|e| !e.others.is_empty()).collect();
    assert!(
        crowded.len() >= 2,
        "{} examples with neighbours",
        crowded.len()
    );
    for e in &examples {
        assert_eq!(e.terms.len(), 1 + e.others.len());
        let sum: f32 = e.terms.iter().map(|t| t.weight * t.e_marg).sum();
        assert!((sum - e.e_marg).abs() < 1e-4 * (1.0 + sum.abs()));
    }
    let generator = GeneratorConfig::new(config.embedding_width(), config.num_modes).init(&device);
    let psi: Vec<Vec<f32>> = crowded.iter().map(|_| vec![-0.5, 0.8]).collect();
    let m = eval::generate_and_measure(
        &generator,
        &predictor,
        &crowded,
        &psi,
        Reward::AverageSpeed,
        &device,
    );
    for (i, e) in crowded.iter().enumerate() {
        let members = std::iter::once(&e.a).chain(e.others.iter().map(|(s, _)| s));
        for j in 0..2 {
            // Each member's J_φ of the future moved into its frame through the world poses.
            let mut want = 0.0f64;
            let mut scale = 0.0f64;
            for (s, term) in members.clone().zip(&e.terms) {
                let moved = scbg_courtesy::label::change_frame(
                    &m.futures_b[i][j],
                    &e.b.world_from_agent,
                    &s.world_from_agent,
                );
                let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
                let batch = scbg_model::Batch::from_samples(
                    &[s],
                    &scbg_model::BatchAugment::default(),
                    &mut rng,
                    &device,
                );
                let y = scbg_courtesy::trajectories_tensor(&[moved], &device);
                let [n, t, _] = y.dims();
                let cond = Tensor::cat(vec![y, Tensor::ones([n, t, 1], &device)], 2);
                let e_cond: f32 = scbg_courtesy::expected_reward(
                    &predictor,
                    &batch,
                    Some(cond),
                    Reward::AverageSpeed,
                    0.1,
                )
                .into_scalar();
                let term_psi = f64::from(e_cond - term.e_marg);
                want += f64::from(term.weight) * term_psi;
                scale = scale.max(term_psi.abs());
            }
            let got = f64::from(m.psi[i][j]);
            // Relative, but not below f32's resolution of rewards near 10 m/s (~1e-6 m/s).
            assert!(
                (got - want).abs() < 0.02 * scale.max(1e-4),
                "example {i}, ψ {j}: measured {got} vs Σ w_j ψ_j {want}"
            );
        }
    }
    // A split into two half-weight copies of itself is A: the audience path agrees with the
    // paper's pair path.
    let pair = examples
        .iter()
        .find(|e| e.others.is_empty())
        .unwrap_or(crowded[0]);
    let mut plain = pair.clone();
    plain.others.clear();
    plain.terms = vec![scbg_courtesy::label::AudienceTerm {
        weight: 1.0,
        e_marg: plain.e_marg,
    }];
    let mut halves = plain.clone();
    halves.others = vec![(plain.a.clone(), plain.a_from_b)];
    halves.terms = vec![
        scbg_courtesy::label::AudienceTerm {
            weight: 0.5,
            e_marg: plain.e_marg,
        };
        2
    ];
    let q = vec![vec![0.3f32]];
    let one = eval::generate_and_measure(
        &generator,
        &predictor,
        &[&plain],
        &q,
        Reward::AverageSpeed,
        &device,
    );
    let two = eval::generate_and_measure(
        &generator,
        &predictor,
        &[&halves],
        &q,
        Reward::AverageSpeed,
        &device,
    );
    assert!(
        (one.psi[0][0] - two.psi[0][0]).abs() <= 1e-6 * (1e-3 + one.psi[0][0].abs()) + 1e-9,
        "pair path {} vs audience path {}",
        one.psi[0][0],
        two.psi[0][0]
    );
    assert!((one.e_cond[0][0] - two.e_cond[0][0]).abs() < 1e-5);
}

#[test]
fn the_courtesy_loss_toward_an_audience_reaches_the_generator() {
    let device = Device::flex().autodiff();
    let (_guard, config, predictor) = seeded_predictor(&device, 17);
    let examples = labelled_toward_neighbours(&predictor, 8, &device);
    let refs: Vec<&Example> = examples.iter().filter(|e| !e.others.is_empty()).collect();
    assert!(!refs.is_empty());
    let predictor = burn::module::Module::no_grad(predictor);
    let generator = GeneratorConfig::new(config.embedding_width(), config.num_modes).init(&device);
    assert_courtesy_loss_reaches_generator(&generator, &predictor, &refs, &device);
}
