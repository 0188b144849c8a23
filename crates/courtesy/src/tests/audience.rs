//! Courtesy toward B's audience: its weights, names and members, and ψ as the weighted sum of
//! each member's ψ.

use super::*;

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
