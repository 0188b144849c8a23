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
    let g = GeneratorConfig::new(24, 2).init(&device);
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

/// B's two modes ([`two_modes`]: straight, and turning to end 8 m left) in `rows` rows, with
/// these log-probabilities and courtesies in every row.
fn two(device: &Device, rows: usize, log_prob: [f32; 2], psi: [f32; 2]) -> BModes {
    BModes {
        xy: two_modes(device).reshape([1, 2, 80, 2]).repeat_dim(0, rows),
        log_prob: Tensor::from_data([log_prob], device).repeat_dim(0, rows),
        psi: Some(Tensor::from_data([psi], device).repeat_dim(0, rows)),
        mixture_modes: 2,
    }
}

/// A generator config for an embedding of 24 choosing among [`two`]'s modes alone (no slowed
/// copies).
fn two_mode_config() -> GeneratorConfig {
    let mut config = GeneratorConfig::new(24, 2);
    config.mode_slowdowns.clear();
    config
}

/// The softmax blend of the candidates the courtesy loss scores in training.
fn blend(c: &CandidateFutures) -> Tensor<3> {
    let [b, k, t, _] = c.futures.dims();
    burn::tensor::activation::softmax(c.logits.clone(), 1)
        .reshape([b, 1, k])
        .matmul(c.futures.clone().reshape([b, k, t * 2]))
        .reshape([b, t, 2])
}

#[test]
fn forward_shape() {
    let device = Device::flex();
    let g = two_mode_config().init(&device);
    let out = g.forward(
        Tensor::zeros([3, 24], &device),
        Tensor::zeros([3], &device),
        two(&device, 3, [0.0, 0.0], [0.0, 0.0]),
    );
    assert_eq!(out.dims(), [3, 80, 2]);
}

/// Zeroes the decoder's last layer: the regressed displacement is 0, so the generator's
/// future is its chosen candidate alone.
fn zero_displacement(g: &mut Generator) {
    let last = g.decoder.layers.last_mut().unwrap();
    last.weight = last.weight.clone().map(|w| w.zeros_like());
    if let Some(bias) = &mut last.bias {
        *bias = bias.clone().map(|b| b.zeros_like());
    }
}

/// Outside training the future is the likeliest candidate plus the displacement: with the
/// displacement's last layer zeroed and a mode log-probability far below the other, it is
/// the likelier mode, whatever ψ and the learned logits say.
#[test]
fn the_likeliest_candidate_is_the_future() {
    let device = Device::flex();
    let mut g = two_mode_config().init(&device);
    zero_displacement(&mut g);
    let want: Vec<f32> = two_modes(&device).into_data().try_to_vec().unwrap();
    for favoured in [0, 1] {
        let log_prob = if favoured == 0 {
            [0.0, -60.0]
        } else {
            [-60.0, 0.0]
        };
        for psi in [-3.0f32, 0.0, 3.0] {
            let out: Vec<f32> = g
                .forward(
                    Tensor::ones([1, 24], &device),
                    Tensor::from_data([psi], &device),
                    two(&device, 1, log_prob, [0.5, -0.5]),
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

/// Trains as the generator does: the candidate assigned to each target (`assigned[i]`) plus
/// the displacement against the target, and the selector's cross-entropy against the
/// assignment.
fn train_choice(
    g: Generator,
    embedding: &Tensor<2>,
    psi: &Tensor<1>,
    modes: impl Fn() -> BModes,
    assigned: &[usize],
    steps: usize,
) -> Generator {
    use burn::optim::GradientsParams;
    let device = embedding.device();
    let n = assigned.len();
    let onehot = Tensor::<2>::from_data(
        burn::tensor::TensorData::new(
            assigned
                .iter()
                .flat_map(|&j| (0..2).map(move |c| f32::from(u8::from(c == j))))
                .collect(),
            [n, 2],
        ),
        &device,
    );
    let all = two_modes(&device);
    let target = Tensor::cat(
        assigned
            .iter()
            .map(|&j| all.clone().narrow(0, j, 1))
            .collect(),
        0,
    );
    let mut g = g;
    let mut optim = AdamConfig::new().init();
    for _ in 0..steps {
        let c = g.forward_candidates(embedding.clone(), psi.clone(), modes());
        let chosen = (c.futures * onehot.clone().reshape([n, 2, 1, 1]))
            .sum_dim(1)
            .reshape([n, 80, 2]);
        let ce = (burn::tensor::activation::log_softmax(c.logits, 1) * onehot.clone())
            .sum_dim(1)
            .mean()
            .neg();
        let loss = (chosen - target.clone()).powi_scalar(2).mean() + ce;
        let grads = GradientsParams::from_grads(loss.backward(), &g);
        g = optim.step(1e-2, g, grads);
    }
    g
}

/// The largest distance (m) of the generator's futures from mode `want[i]` of each row.
fn error(
    g: &Generator,
    embedding: &Tensor<2>,
    psi: &Tensor<1>,
    modes: BModes,
    want: &[usize],
) -> f32 {
    let all = two_modes(&embedding.device());
    let target = Tensor::cat(
        want.iter().map(|&j| all.clone().narrow(0, j, 1)).collect(),
        0,
    );
    (g.forward(embedding.clone(), psi.clone(), modes) - target)
        .abs()
        .max()
        .into_scalar()
}

/// Trained on "ψ −1 → the straight mode, ψ +1 → the turning mode" from equally likely modes
/// of equal courtesy, the selector learns to pick by ψ (the end points differ by 8 m), and a
/// reversed request picks the other mode.
#[test]
fn the_choice_learns_to_pick_by_psi() {
    let device = scbg_model::device::training_device("flex").unwrap();
    let _lock = crate::tests::SEED_LOCK
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    device.seed(5);
    let mut config = GeneratorConfig::new(8, 2);
    config.mode_slowdowns.clear();
    config.hidden = vec![32, 32];
    let n = 16;
    let assigned: Vec<usize> = (0..n).map(|i| i % 2).collect();
    let psi_of = |sign: f32| -> Tensor<1> {
        let v: Vec<f32> = (0..n)
            .map(|i| sign * if i % 2 == 0 { -1.0 } else { 1.0 })
            .collect();
        Tensor::from_data(v.as_slice(), &device)
    };
    let embedding = Tensor::<2>::ones([n, 8], &device);
    let modes = || two(&device, n, [0.0, 0.0], [0.0, 0.0]);
    let g = config.init(&device);
    let before = error(&g, &embedding, &psi_of(1.0), modes(), &assigned);
    let g = train_choice(g, &embedding, &psi_of(1.0), modes, &assigned, 150);
    let after = error(&g, &embedding, &psi_of(1.0), modes(), &assigned);
    assert!(
        after < 0.5 && after < 0.1 * before,
        "max error {before} m → {after} m"
    );
    let flipped: Vec<usize> = assigned.iter().map(|j| 1 - j).collect();
    let reversed = error(&g, &embedding, &psi_of(-1.0), modes(), &flipped);
    assert!(reversed < 0.5, "reversed requests: max error {reversed} m");
}

/// The same request (ψ +1) and the same embedding in every example, but which of B's two
/// modes is the courteous one (ψ_k +1 against −1) alternates between examples: the embedding
/// alone cannot tell them apart, the candidates' scored courtesy does, and swapping the
/// scores swaps the choice.
#[test]
fn scoring_the_candidates_courtesy_tells_which_mode_helps() {
    let device = scbg_model::device::training_device("flex").unwrap();
    let _lock = crate::tests::SEED_LOCK
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let n = 16;
    let assigned: Vec<usize> = (0..n).map(|i| i % 2).collect();
    let modes_with = |swap: bool| -> BModes {
        let mode_psi: Vec<f32> = (0..n)
            .flat_map(|i| {
                if (i % 2 == 0) != swap {
                    [1.0f32, -1.0]
                } else {
                    [-1.0, 1.0]
                }
            })
            .collect();
        BModes {
            psi: Some(Tensor::from_data(
                burn::tensor::TensorData::new(mode_psi, [n, 2]),
                &device,
            )),
            ..two(&device, n, [0.0, 0.0], [0.0, 0.0])
        }
    };
    let embedding = Tensor::<2>::ones([n, 8], &device);
    let psi = Tensor::<1>::ones([n], &device);
    device.seed(5);
    let mut config = GeneratorConfig::new(8, 2);
    config.mode_slowdowns.clear();
    config.hidden = vec![32, 32];
    let g = train_choice(
        config.init(&device),
        &embedding,
        &psi,
        || modes_with(false),
        &assigned,
        200,
    );
    let scored = error(&g, &embedding, &psi, modes_with(false), &assigned);
    assert!(scored < 0.5, "scored by courtesy: max error {scored} m");
    let flipped: Vec<usize> = assigned.iter().map(|j| 1 - j).collect();
    let swapped = error(&g, &embedding, &psi, modes_with(true), &flipped);
    assert!(swapped < 0.5, "scores swapped: max error {swapped} m");
}

/// Outside training the generator gives exactly one of B's modes (the displacement zeroed),
/// where the blend it trains its courtesy with lies between them.
#[test]
fn the_future_is_one_mode_not_a_blend() {
    let device = Device::flex();
    let mut g = two_mode_config().init(&device);
    zero_displacement(&mut g);
    let modes = || two(&device, 1, [0.0, 0.0], [0.2, -0.2]);
    let end_y = |out: Tensor<3>| -> f32 {
        let v: Vec<f32> = out.into_data().try_to_vec().unwrap();
        v[159]
    };
    let (embedding, psi) = (
        Tensor::ones([1, 24], &device),
        Tensor::from_data([0.5f32], &device),
    );
    // The modes end at y = 0 (straight) and y = 8 (turning).
    let likeliest = end_y(g.forward(embedding.clone(), psi.clone(), modes()));
    assert!(
        likeliest.abs() < 1e-4 || (likeliest - 8.0).abs() < 1e-4,
        "{likeliest}"
    );
    let blend = end_y(blend(&g.forward_candidates(embedding, psi, modes())));
    assert!(blend > 1e-3 && blend < 8.0 - 1e-3, "{blend}");
}

/// A generator with slowed copies chooses among `K · (1 + S)` candidates, and outside
/// training its future is one of them (the displacement zeroed).
#[test]
fn a_generator_chooses_among_the_slowed_copies_too() {
    let device = Device::flex();
    let mut config = GeneratorConfig::new(24, 2);
    config.mode_slowdowns = vec![0.5];
    assert_eq!(config.candidates(), 4);
    let mut g = config.init(&device);
    zero_displacement(&mut g);
    let mut modes = g.candidates_of(BModes {
        psi: None,
        ..two(&device, 1, [0.0, 0.0], [0.0, 0.0])
    });
    modes.psi = Some(Tensor::from_data([[0.3f32, -0.3, 0.1, -0.1]], &device));
    let all: Vec<f32> = modes.xy.clone().into_data().try_to_vec().unwrap();
    let out: Vec<f32> = g
        .forward(
            Tensor::ones([1, 24], &device),
            Tensor::from_data([0.3f32], &device),
            modes,
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
    // Without slowdowns: B's modes alone.
    config.mode_slowdowns.clear();
    assert_eq!(config.candidates(), 2);
    assert!(config.init(&device).mode_warp.is_none());
}

/// A ψ far outside the labels (here 1000 spreads) is read as the clamp's 20 spreads, so a
/// wild request or range extrapolation cannot drive the decoder into metres per step.
#[test]
fn a_psi_far_outside_the_labels_is_clamped() {
    let device = Device::flex();
    let mut config = two_mode_config();
    config.psi_scale = 0.5;
    let g = config.init(&device);
    let future = |psi: f32| -> Vec<f32> {
        g.forward(
            Tensor::ones([1, 24], &device),
            Tensor::from_data([psi], &device),
            two(&device, 1, [0.0, 0.0], [0.2, -0.2]),
        )
        .into_data()
        .try_to_vec()
        .unwrap()
    };
    assert_eq!(future(500.0), future(0.5 * PSI_INPUT_RANGE));
    assert_eq!(future(-500.0), future(-0.5 * PSI_INPUT_RANGE));
    assert_ne!(future(0.5 * PSI_INPUT_RANGE), future(0.0));
}

/// A `generator.json` describing another architecture (a field this build does not know)
/// is an error, not silently a different network.
#[test]
fn configs_with_unknown_fields_are_rejected() {
    let mut json = serde_json::to_value(GeneratorConfig::new(24, 6)).unwrap();
    let back: GeneratorConfig = serde_json::from_value(json.clone()).unwrap();
    assert_eq!(back, GeneratorConfig::new(24, 6));
    json.as_object_mut()
        .unwrap()
        .insert("a_context_width".into(), 7.into());
    let err = serde_json::from_value::<GeneratorConfig>(json).unwrap_err();
    assert!(err.to_string().contains("a_context_width"), "{err}");
}

/// The likeliest of the candidates' futures is what the generator gives outside training.
#[test]
fn the_likeliest_candidate_future_is_the_forward() {
    let _guard = crate::tests::SEED_LOCK
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let device = Device::flex();
    device.seed(3);
    let mut config = GeneratorConfig::new(24, 2);
    config.mode_slowdowns = vec![0.5];
    let g = config.init(&device);
    let modes = || {
        let mut m = g.candidates_of(BModes {
            xy: Tensor::cat(vec![two_modes(&device), two_modes(&device) * 0.5], 0)
                .reshape([2, 2, 80, 2]),
            log_prob: Tensor::from_data([[-0.3f32, -1.4], [-1.0, -0.5]], &device),
            psi: None,
            mixture_modes: 2,
        });
        m.psi = Some(Tensor::from_data(
            [[0.4f32, -0.2, 0.1, 0.0], [-0.3, 0.2, 0.0, 0.5]],
            &device,
        ));
        m
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
    let likeliest = g.forward(embedding, psi, modes());
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

/// The scorer's third input is ψ relative to the row's choices, which a shift of every
/// courtesy leaves unchanged. With the selector's own logits and the scorer's weights of ψ
/// and ψ_k zeroed, two scenes alike but for such a shift (J_φ's courtesy of every choice
/// 0.3 higher, and the request with it) get the same logits, and the logits still tell the
/// choices apart.
#[test]
fn the_scorer_reads_psi_relative_to_the_choices() {
    let device = Device::flex();
    let mut g = two_mode_config().init(&device);
    let selector = g.selector.layers.last_mut().unwrap();
    selector.weight = selector.weight.clone().map(|w| w.zeros_like());
    if let Some(bias) = &mut selector.bias {
        *bias = bias.clone().map(|b| b.zeros_like());
    }
    let first = &mut g.mode_scorer.layers[0];
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
        psi: Some(Tensor::from_data([[1.0f32, -1.0], [1.3, -0.7]], &device)),
        ..two(&device, 2, [0.0, 0.0], [0.0, 0.0])
    };
    let logits: Vec<f32> = g
        .forward_candidates(
            Tensor::ones([2, 24], &device),
            Tensor::from_data([0.5f32, 0.8], &device),
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
