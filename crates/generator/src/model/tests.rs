//! Tests of the generator network.

use burn::optim::AdamConfig;

use super::*;
use crate::modes::two_modes;

#[test]
fn knots_are_interpolated_linearly() {
    let _guard = crate::tests::SEED_LOCK
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let device = Device::flex();
    let g = GeneratorConfig::new(24).init(&device);
    let w: Vec<f32> = g.interpolation.val().into_data().try_to_vec().unwrap();
    let knots = 16;
    let row = |s: usize| &w[s * knots..(s + 1) * knots];
    // Step 1 (index 0) is a fifth of the way from the origin to knot 0.
    assert!((row(0)[0] - 0.2).abs() < 1e-6 && row(0)[1..].iter().all(|v| *v == 0.0));
    // Step 5 is knot 0; step 8 is 40 % knot 0 + 60 % knot 1; step 80 is the last knot.
    assert!((row(4)[0] - 1.0).abs() < 1e-6);
    assert!((row(7)[0] - 0.4).abs() < 1e-6 && (row(7)[1] - 0.6).abs() < 1e-6);
    assert!((row(79)[15] - 1.0).abs() < 1e-6);
    // Every row's weights sum to at most 1 (the origin takes the rest).
    assert!((0..80).all(|s| row(s).iter().sum::<f32>() <= 1.0 + 1e-6));
}

#[test]
fn forward_shape() {
    let device = Device::flex();
    let g = GeneratorConfig::new(24).init(&device);
    let out = g.forward(
        Tensor::zeros([3, 24], &device),
        Tensor::zeros([3], &device),
        None,
    );
    assert_eq!(out.dims(), [3, 80, 2]);
}

/// Zeroes the decoder's last layer: the regressed displacement is 0, so a mode-selecting
/// generator's future is its (weighted) modes alone.
fn zero_displacement(g: &mut Generator) {
    let last = g.decoder.layers.last_mut().unwrap();
    last.weight = last.weight.clone().map(|w| w.zeros_like());
    if let Some(bias) = &mut last.bias {
        *bias = bias.clone().map(|b| b.zeros_like());
    }
}

/// The mode-selecting generator's future is the softmax-weighted modes plus the regressed
/// displacement: with the displacement's last layer zeroed and a mode log-probability far
/// below the other, it is the likelier mode, whatever ψ and the learned logits say.
#[test]
fn mode_selection_weights_the_modes() {
    let device = Device::flex();
    let mut config = GeneratorConfig::new(24);
    config.modes = 2;
    let mut g = config.init(&device);
    assert!(g.selects_modes());
    zero_displacement(&mut g);
    let modes = |favoured: usize| BModes {
        xy: two_modes(&device).reshape([1, 2, 80, 2]),
        log_prob: Tensor::from_data(
            [[
                if favoured == 0 { 0.0f32 } else { -60.0 },
                if favoured == 1 { 0.0 } else { -60.0 },
            ]],
            &device,
        ),
        psi: None,
        mixture_modes: 2,
    };
    let want: Vec<f32> = two_modes(&device).into_data().try_to_vec().unwrap();
    for favoured in [0, 1] {
        for psi in [-3.0f32, 0.0, 3.0] {
            let out: Vec<f32> = g
                .forward(
                    Tensor::ones([1, 24], &device),
                    Tensor::from_data([psi], &device),
                    Some(modes(favoured)),
                )
                .into_data()
                .try_to_vec()
                .unwrap();
            let want = &want[favoured * 160..(favoured + 1) * 160];
            assert!(
                out.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-4),
                "mode {favoured}, psi {psi}: {:?} vs {:?}",
                &out[150..],
                &want[150..]
            );
        }
    }
}

/// Trained on "ψ −1 → the straight mode, ψ +1 → the turning mode" from equally likely modes,
/// the selector learns to pick by ψ (the end points differ by 8 m; a regression without the
/// modes would have to learn both shapes).
#[test]
fn mode_selection_learns_to_pick_by_psi() {
    use burn::optim::GradientsParams;
    let device = scbg_model::device::training_device("flex").unwrap();
    let _lock = crate::tests::SEED_LOCK
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    device.seed(5);
    let mut config = GeneratorConfig::new(8);
    config.modes = 2;
    config.hidden = vec![32, 32];
    let mut g = config.init(&device);
    let mut optim = AdamConfig::new().init();
    let n = 16;
    let psi: Vec<f32> = (0..n)
        .map(|i| if i % 2 == 0 { -1.0 } else { 1.0 })
        .collect();
    let modes = || BModes {
        xy: two_modes(&device).reshape([1, 2, 80, 2]).repeat_dim(0, n),
        log_prob: Tensor::from_data([[0.0f32, 0.0]], &device).repeat_dim(0, n),
        psi: None,
        mixture_modes: 2,
    };
    let all = two_modes(&device);
    let target = Tensor::cat((0..n).map(|i| all.clone().narrow(0, i % 2, 1)).collect(), 0);
    let embedding = Tensor::<2>::ones([n, 8], &device);
    let error = |g: &Generator| -> f32 {
        let out = g.forward(
            embedding.clone(),
            Tensor::from_data(psi.as_slice(), &device),
            Some(modes()),
        );
        (out - target.clone()).abs().max().into_scalar()
    };
    let before = error(&g);
    for _ in 0..150 {
        let out = g.forward(
            embedding.clone(),
            Tensor::from_data(psi.as_slice(), &device),
            Some(modes()),
        );
        let loss = (out - target.clone()).powi_scalar(2).mean();
        let grads = GradientsParams::from_grads(loss.backward(), &g);
        g = optim.step(1e-2, g, grads);
    }
    let after = error(&g);
    assert!(
        after < 0.5 && after < 0.1 * before,
        "max error {before} m → {after} m"
    );
}

/// The same request (ψ +1) and the same embedding in every example, but which of B's two
/// modes is the courteous one (ψ_k +1 against −1) alternates between examples: a selector
/// that sees the embedding alone cannot tell them apart and ends between the modes (its
/// error stays metres), one that scores the modes' courtesy picks the right one.
#[test]
fn scoring_the_modes_courtesy_tells_which_mode_helps() {
    use burn::optim::GradientsParams;
    let device = scbg_model::device::training_device("flex").unwrap();
    let _lock = crate::tests::SEED_LOCK
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let n = 16;
    let mode_psi: Vec<f32> = (0..n)
        .flat_map(|i| {
            if i % 2 == 0 {
                [1.0f32, -1.0]
            } else {
                [-1.0, 1.0]
            }
        })
        .collect();
    let all = two_modes(&device);
    let target = Tensor::cat((0..n).map(|i| all.clone().narrow(0, i % 2, 1)).collect(), 0);
    let embedding = Tensor::<2>::ones([n, 8], &device);
    let psi = || Tensor::<1>::ones([n], &device);
    let train = |mode_courtesy: bool| -> f32 {
        device.seed(5);
        let mut config = GeneratorConfig::new(8);
        config.modes = 2;
        config.mode_courtesy = mode_courtesy;
        config.hidden = vec![32, 32];
        let mut g = config.init(&device);
        assert_eq!(g.scores_mode_courtesy(), mode_courtesy);
        let modes = || BModes {
            xy: two_modes(&device).reshape([1, 2, 80, 2]).repeat_dim(0, n),
            log_prob: Tensor::from_data([[0.0f32, 0.0]], &device).repeat_dim(0, n),
            psi: Some(Tensor::from_data(
                burn::tensor::TensorData::new(mode_psi.clone(), [n, 2]),
                &device,
            )),
            mixture_modes: 2,
        };
        let mut optim = AdamConfig::new().init();
        for _ in 0..200 {
            let out = g.forward(embedding.clone(), psi(), Some(modes()));
            let loss = (out - target.clone()).powi_scalar(2).mean();
            let grads = GradientsParams::from_grads(loss.backward(), &g);
            g = optim.step(1e-2, g, grads);
        }
        let out = g.forward(embedding.clone(), psi(), Some(modes()));
        (out - target.clone()).abs().max().into_scalar()
    };
    let (blind, scored) = (train(false), train(true));
    assert!(
        blind > 2.0,
        "the embedding alone cannot tell: max error {blind} m"
    );
    assert!(scored < 0.5, "scored by courtesy: max error {scored} m");
}

/// Outside training a generator with `likeliest_mode` gives exactly one of B's modes (the
/// displacement zeroed), where the blend it trains with lies between them.
#[test]
fn the_likeliest_mode_is_one_mode_not_a_blend() {
    let device = Device::flex();
    let mut config = GeneratorConfig::new(24);
    config.modes = 2;
    config.likeliest_mode = true;
    let mut g = config.init(&device);
    zero_displacement(&mut g);
    let modes = || BModes {
        xy: two_modes(&device).reshape([1, 2, 80, 2]),
        log_prob: Tensor::from_data([[0.0f32, 0.0]], &device),
        psi: None,
        mixture_modes: 2,
    };
    let end_y = |out: Tensor<3>| -> f32 {
        let v: Vec<f32> = out.into_data().try_to_vec().unwrap();
        v[159]
    };
    let (embedding, psi) = (
        Tensor::ones([1, 24], &device),
        Tensor::from_data([0.5f32], &device),
    );
    // The modes end at y = 0 (straight) and y = 8 (turning).
    let likeliest = end_y(g.forward(embedding.clone(), psi.clone(), Some(modes())));
    assert!(
        likeliest.abs() < 1e-4 || (likeliest - 8.0).abs() < 1e-4,
        "{likeliest}"
    );
    let blend = end_y(g.forward_blend(embedding, psi, Some(modes())));
    assert!(blend > 1e-3 && blend < 8.0 - 1e-3, "{blend}");
}

/// A generator with slowed copies chooses among `K · (1 + S)` candidates, and outside
/// training its future is one of them (the displacement zeroed).
#[test]
fn a_generator_chooses_among_the_slowed_copies_too() {
    let device = Device::flex();
    let mut config = GeneratorConfig::new(24);
    config.modes = 2;
    config.likeliest_mode = true;
    config.mode_slowdowns = vec![0.5];
    assert_eq!(config.candidates(), 4);
    let mut g = config.init(&device);
    zero_displacement(&mut g);
    let modes = g.candidates_of(
        BModes {
            xy: two_modes(&device).reshape([1, 2, 80, 2]),
            log_prob: Tensor::from_data([[0.0f32, 0.0]], &device),
            psi: None,
            mixture_modes: 2,
        },
        &[],
    );
    let all: Vec<f32> = modes.xy.clone().into_data().try_to_vec().unwrap();
    let out: Vec<f32> = g
        .forward(
            Tensor::ones([1, 24], &device),
            Tensor::from_data([0.3f32], &device),
            Some(modes),
        )
        .into_data()
        .try_to_vec()
        .unwrap();
    // At the knots (every 5th step; linear between them, and a slowed copy is not).
    let at_knots = |v: &[f32]| -> Vec<f32> {
        (4..80)
            .step_by(5)
            .flat_map(|s| [v[2 * s], v[2 * s + 1]])
            .collect()
    };
    let out = at_knots(&out);
    assert!(
        all.chunks_exact(160).any(|c| at_knots(c)
            .iter()
            .zip(&out)
            .all(|(a, b)| (a - b).abs() < 1e-4)),
        "one of the four candidates"
    );
    // Generators saved before the option have no slowed copies.
    let mut json = serde_json::to_value(&config).unwrap();
    json.as_object_mut().unwrap().remove("mode_slowdowns");
    let old: GeneratorConfig = serde_json::from_value(json).unwrap();
    assert_eq!(old.candidates(), 2);
    assert!(old.init(&device).mode_warp.is_none());
}

/// A ψ far outside the labels (here 1000 spreads) is read as the clamp's 20 spreads, so a
/// wild request or range extrapolation cannot drive the decoder into metres per step.
#[test]
fn a_psi_far_outside_the_labels_is_clamped() {
    let device = Device::flex();
    let mut config = GeneratorConfig::new(24);
    config.psi_scale = 0.5;
    let g = config.init(&device);
    let future = |psi: f32| -> Vec<f32> {
        g.forward(
            Tensor::ones([1, 24], &device),
            Tensor::from_data([psi], &device),
            None,
        )
        .into_data()
        .try_to_vec()
        .unwrap()
    };
    assert_eq!(future(500.0), future(0.5 * PSI_INPUT_RANGE));
    assert_eq!(future(-500.0), future(-0.5 * PSI_INPUT_RANGE));
    assert_ne!(future(0.5 * PSI_INPUT_RANGE), future(0.0));
}

#[test]
fn generators_saved_before_the_a_context_are_not_told_who_a_is() {
    let mut json = serde_json::to_value(GeneratorConfig::new(24)).unwrap();
    json.as_object_mut().unwrap().remove("a_context_width");
    json.as_object_mut().unwrap().remove("modes");
    let old: GeneratorConfig = serde_json::from_value(json).unwrap();
    assert_eq!(old.a_context_width, 0);
    // Nor do they select among B's modes.
    assert_eq!(old.modes, 0);
    assert!(!old.init(&Device::flex()).selects_modes());
    let new = GeneratorConfig::with_a_context(24);
    assert_eq!(
        (new.embedding_width, new.a_context_width),
        (24 + crate::A_CONTEXT_WIDTH, crate::A_CONTEXT_WIDTH)
    );
}

/// The candidates' futures weighted by the softmax of the selector's logits are the blend
/// the generator trains with, and the likeliest candidate is what it gives outside training.
#[test]
fn candidate_futures_make_the_blend_and_the_likeliest_mode() {
    let _guard = crate::tests::SEED_LOCK
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let device = Device::flex();
    device.seed(3);
    let mut config = GeneratorConfig::new(24);
    config.modes = 2;
    config.likeliest_mode = true;
    config.mode_slowdowns = vec![0.5];
    let g = config.init(&device);
    let modes = || {
        g.candidates_of(
            BModes {
                xy: Tensor::cat(vec![two_modes(&device), two_modes(&device) * 0.5], 0)
                    .reshape([2, 2, 80, 2]),
                log_prob: Tensor::from_data([[-0.3f32, -1.4], [-1.0, -0.5]], &device),
                psi: None,
                mixture_modes: 2,
            },
            &[],
        )
    };
    let embedding = Tensor::<2>::random(
        [2, 24],
        burn::tensor::Distribution::Normal(0.0, 1.0),
        &device,
    );
    let psi = Tensor::<1>::from_data([0.3f32, -0.8], &device);
    let c = g.forward_candidates(embedding.clone(), psi.clone(), modes());
    assert_eq!(c.logits.dims(), [2, 4]);
    assert_eq!(c.futures.dims(), [2, 4, 80, 2]);
    let weights = burn::tensor::activation::softmax(c.logits.clone(), 1);
    let blend = weights
        .reshape([2, 1, 4])
        .matmul(c.futures.clone().reshape([2, 4, 160]))
        .reshape([2, 80, 2]);
    let want = g.forward_blend(embedding.clone(), psi.clone(), Some(modes()));
    let gap: f32 = (blend - want).abs().max().into_scalar();
    assert!(gap < 1e-4, "blend differs by {gap} m");
    let likeliest = g.forward(embedding, psi, Some(modes()));
    for (row, k) in c.likeliest().into_iter().enumerate() {
        let chosen = c
            .futures
            .clone()
            .narrow(0, row, 1)
            .narrow(1, k, 1)
            .reshape([1, 80, 2]);
        let gap: f32 = (chosen - likeliest.clone().narrow(0, row, 1))
            .abs()
            .max()
            .into_scalar();
        assert!(gap < 1e-4, "row {row}: likeliest differs by {gap} m");
    }
}

/// ψ relative to a row's choices is `(ψ − ψ_k) / (std_j ψ_j + floor)`: the same ranks in a
/// scene whose choices span a tenth of a label spread as in one that spans ten times more,
/// and finite (÷ the floor) when every choice scores alike.
#[test]
fn relative_courtesy_is_psi_in_units_of_the_choices_spread() {
    let device = Device::flex();
    let choices = Tensor::<2>::from_data(
        [[-1.0f32, 0.0, 1.0], [-0.1, 0.0, 0.1], [0.5, 0.5, 0.5]],
        &device,
    );
    let psi = Tensor::<2>::from_data([[0.5f32], [0.05], [0.7]], &device);
    let rel: Vec<f32> = relative_courtesy(psi, choices, 0.0)
        .into_data()
        .try_to_vec()
        .unwrap();
    let std = (2.0f32 / 3.0).sqrt();
    let want = [1.5 / std, 0.5 / std, -0.5 / std];
    for row in 0..2 {
        for j in 0..3 {
            let got = rel[row * 3 + j];
            assert!(
                (got - want[j]).abs() < 1e-3,
                "row {row}, choice {j}: {got} vs {}",
                want[j]
            );
        }
    }
    // Every choice alike: ÷ the (tiny) floor, finite.
    assert!(
        rel[6..].iter().all(|v| v.is_finite() && *v > 0.0),
        "{rel:?}"
    );
    // With a floor, a narrow scene's spread is padded: 0.05 / (0.0816 + 0.1).
    let rel: Vec<f32> = relative_courtesy(
        Tensor::<2>::from_data([[0.05f32]], &device),
        Tensor::<2>::from_data([[-0.1f32, 0.0, 0.1]], &device),
        0.1,
    )
    .into_data()
    .try_to_vec()
    .unwrap();
    assert!((rel[1] - 0.05 / (0.1 * std + 0.1)).abs() < 1e-4, "{rel:?}");
}

/// A generator with the relative input has a three-input scorer; one without (every
/// generator trained before the option: `relative_courtesy_floor` absent from its JSON)
/// keeps the two-input scorer its weights were saved for.
#[test]
fn the_relative_input_widens_the_scorer_and_older_configs_go_without() {
    let device = Device::flex();
    let mut config = GeneratorConfig::new(24);
    config.modes = 2;
    config.mode_courtesy = true;
    let inputs = |c: &GeneratorConfig| {
        let g = c.init(&device);
        g.mode_scorer.unwrap().layers[0].weight.val().dims()[0]
    };
    assert_eq!(inputs(&config), 2);
    config.relative_courtesy_floor = Some(RELATIVE_COURTESY_FLOOR);
    assert_eq!(inputs(&config), 3);
    let mut json = serde_json::to_value(&config).unwrap();
    json.as_object_mut()
        .unwrap()
        .remove("relative_courtesy_floor");
    let older: GeneratorConfig = serde_json::from_value(json).unwrap();
    assert_eq!(older.relative_courtesy_floor, None);
    assert_eq!(inputs(&older), 2);
    // Without the mode scorer the floor does nothing.
    config.mode_courtesy = false;
    assert!(config.init(&device).relative_courtesy_floor.is_none());
}

/// The scorer's third input is ψ relative to the row's choices. With the selector's own
/// logits and the scorer's weights of ψ and ψ_k zeroed, two scenes alike but for the scale of
/// their courtesy (the second's ψ and ψ_k a tenth of the first's, as J_φ spreads a cut-in
/// against a crossing) get the same logits, and the logits still tell the choices apart.
#[test]
fn the_scorer_reads_psi_relative_to_the_choices() {
    let device = Device::flex();
    let mut config = GeneratorConfig::new(24);
    config.modes = 2;
    config.mode_courtesy = true;
    config.relative_courtesy_floor = Some(1e-6);
    let mut g = config.init(&device);
    let selector = g.selector.as_mut().unwrap().layers.last_mut().unwrap();
    selector.weight = selector.weight.clone().map(|w| w.zeros_like());
    if let Some(bias) = &mut selector.bias {
        *bias = bias.clone().map(|b| b.zeros_like());
    }
    let first = &mut g.mode_scorer.as_mut().unwrap().layers[0];
    let [inputs, hidden] = first.weight.val().dims();
    assert_eq!(inputs, 3);
    let keep_relative = Tensor::<2>::from_data(
        burn::tensor::TensorData::new(
            (0..inputs)
                .flat_map(|i| std::iter::repeat_n(f32::from(u8::from(i == 2)), hidden))
                .collect(),
            [inputs, hidden],
        ),
        &device,
    );
    first.weight = first.weight.clone().map(|w| w * keep_relative);
    let modes = BModes {
        xy: two_modes(&device).reshape([1, 2, 80, 2]).repeat_dim(0, 2),
        log_prob: Tensor::<2>::zeros([2, 2], &device),
        psi: Some(Tensor::from_data([[1.0f32, -1.0], [0.1, -0.1]], &device)),
        mixture_modes: 2,
    };
    let logits: Vec<f32> = g
        .forward_candidates(
            Tensor::ones([2, 24], &device),
            Tensor::from_data([0.5f32, 0.05], &device),
            modes,
        )
        .logits
        .into_data()
        .try_to_vec()
        .unwrap();
    for k in 0..2 {
        assert!((logits[k] - logits[2 + k]).abs() < 1e-4, "{logits:?}");
    }
    assert!((logits[0] - logits[1]).abs() > 1e-6, "{logits:?}");
}
