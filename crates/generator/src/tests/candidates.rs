//! B's modes as a generator's choices, and their courtesy.

use super::*;

/// Slowed copies of B's modes are scored against the mixture's own mean: adding them leaves
/// the modes' courtesy as it was, and a copy's courtesy is J_φ of the copy against that mean.
#[test]
fn slowed_copies_are_scored_against_the_mixtures_own_mean() {
    let device = Device::flex();
    let (_guard, config, predictor) = seeded_predictor(&device, 13);
    let mut plain = labelled(&predictor, 2, 2, Reward::AverageSpeed, 2, &device);
    let mut slowed = plain.clone();
    crate::fill_mode_courtesy(&predictor, &mut plain, Reward::AverageSpeed, &[], &device);
    crate::fill_mode_courtesy(
        &predictor,
        &mut slowed,
        Reward::AverageSpeed,
        &[0.5],
        &device,
    );
    let k = config.num_modes;
    for (p, s) in plain.iter().zip(&slowed) {
        assert_eq!((p.mode_psi.len(), s.mode_psi.len()), (k, 2 * k));
        assert!(
            p.mode_psi
                .iter()
                .zip(&s.mode_psi)
                .all(|(a, b)| (a - b).abs() < 1e-5),
            "{:?} vs {:?}",
            p.mode_psi,
            &s.mode_psi[..k]
        );
    }
    // A copy's courtesy by hand: J_φ of the slowed mode minus the modes' π-weighted mean.
    let refs: Vec<&Example> = slowed.iter().collect();
    let modes = crate::b_modes(&predictor, &refs, &device);
    let warp = crate::slowdown_warp(&[0.5], modes.xy.dims()[2], &device);
    let all = modes.with_slowdowns(warp.as_ref());
    let psi: Vec<f32> = crate::tensors::to_vec(crate::mode_courtesy(
        &predictor,
        &refs,
        &all,
        Reward::AverageSpeed,
        &device,
    ));
    let stored: Vec<f32> = slowed.iter().flat_map(|e| e.mode_psi.clone()).collect();
    assert!(psi.iter().zip(&stored).all(|(a, b)| (a - b).abs() < 1e-5));
}

/// The generator's scored candidates are its modes and their slowed copies, in
/// [`crate::Generator::candidates_of`]'s order, each with the courtesy `fill_mode_courtesy`
/// stores for it (measured alike when none is stored).
#[test]
fn scored_candidates_are_the_modes_and_copies_with_their_courtesy() {
    let device = Device::flex();
    let (_guard, config, predictor) = seeded_predictor(&device, 13);
    let mut examples = labelled(&predictor, 2, 2, Reward::AverageSpeed, 2, &device);
    crate::fill_mode_courtesy(
        &predictor,
        &mut examples,
        Reward::AverageSpeed,
        &[0.5],
        &device,
    );
    let refs: Vec<&Example> = examples.iter().collect();
    let mut gen_config = GeneratorConfig::new(config.embedding_width(), config.num_modes);
    gen_config.mode_slowdowns = vec![0.5];
    let generator = gen_config.init(&device);
    // Measured here for examples without a stored courtesy of their choices; read back
    // where there is one.
    let bare: Vec<Example> = examples
        .iter()
        .cloned()
        .map(|mut e| {
            e.mode_psi.clear();
            e
        })
        .collect();
    let bare_refs: Vec<&Example> = bare.iter().collect();
    let scored = crate::scored_candidates(
        &generator,
        &predictor,
        &bare_refs,
        Reward::AverageSpeed,
        &device,
    );
    let stored =
        crate::scored_candidates(&generator, &predictor, &refs, Reward::AverageSpeed, &device);
    for (a, b) in scored.iter().zip(&stored) {
        for (a, b) in a.iter().zip(b) {
            assert_eq!(a.xy, b.xy);
            assert!((a.psi - b.psi).abs() < 1e-5);
        }
    }
    let modes = generator.candidates_of(crate::b_modes(&predictor, &refs, &device));
    let [n, k, t, _] = modes.xy.dims();
    assert_eq!((scored.len(), k), (refs.len(), gen_config.candidates()));
    let xy = crate::tensors::to_vec(modes.xy);
    for (i, (choices, e)) in scored.iter().zip(&examples).enumerate() {
        assert_eq!(choices.len(), k);
        for (j, c) in choices.iter().enumerate() {
            assert!((c.psi - e.mode_psi[j]).abs() < 1e-5, "{i} {j}");
            assert_eq!(c.xy.len(), t);
            let base = (i * k + j) * t * 2;
            assert_eq!(c.xy[t - 1], [xy[base + 2 * t - 2], xy[base + 2 * t - 1]]);
        }
    }
    assert_eq!(n, refs.len());
}
