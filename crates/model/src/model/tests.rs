//! Tests of the Multipath++ model: shapes and a learning step, the two conditioning paths,
//! the shared-scene and marginal shortcuts against the plain forward.

use super::*;
use crate::batch::{Batch, BatchAugment};
use crate::loss::gmm_nll;
use burn::optim::{AdamConfig, GradientsParams};
use rand::SeedableRng;
use scbg_features::AgentSample;

use crate::fixtures::{small_features, straight_sample};

/// A tensor's values, row-major.
fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().unwrap()
}

/// Two targets from the straight fixture (with B's future), the second's history moved.
fn two_targets(features: &scbg_features::FeatureConfig) -> (AgentSample, AgentSample) {
    let first = straight_sample(features, true);
    let mut second = first.clone();
    for v in second.target_history.iter_mut().step_by(3) {
        *v += 0.7;
    }
    (first, second)
}

/// The step-wise corrections' last layer starts at zero; these tests need it as after some
/// training.
fn with_random_corrections(model: &mut Multipath, device: &Device) {
    let block = model.stepwise.as_mut().expect("a step-wise model");
    let h = block.out.layers[0].weight.dims()[1];
    block.out.layers[1] = LinearConfig::new(h, 5 * CONDITION_STRIDE).init(device);
}

/// A cpu-small model with the given conditioning, seeded with `seed`, its step-wise
/// corrections (when it has them) as after some training.
fn seeded_model(stepwise: bool, lane_frame: bool, seed: u64, device: &Device) -> Multipath {
    device.seed(seed);
    let mut model = MultipathConfig {
        stepwise_condition: stepwise,
        lane_frame_condition: lane_frame,
        ..MultipathConfig::cpu_small()
    }
    .init(device);
    if stepwise {
        with_random_corrections(&mut model, device);
    }
    model
}

#[test]
fn shapes_param_counts_and_a_learning_step() {
    let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex().autodiff();
    device.seed(1);
    let config = MultipathConfig::cpu_small();
    let features = small_features();
    let model = config.init(&device);
    let samples = [
        straight_sample(&features, true),
        straight_sample(&features, false),
    ];
    let refs: Vec<&AgentSample> = samples.iter().collect();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
    let batch = Batch::from_samples(&refs, &BatchAugment::default(), &mut rng, &device);
    let out = model.forward(&batch);
    assert_eq!(out.xy.dims(), [2, 6, 80, 2]);
    assert_eq!(out.cov_abc.dims(), [2, 6, 80, 3]);
    assert_eq!(out.logits.dims(), [2, 6]);
    let loss = gmm_nll(&out, batch.future_xy.clone(), batch.future_valid.clone());
    let before: f32 = loss.clone().into_scalar();
    assert!(before.is_finite());
    let mut optim = AdamConfig::new().init();
    let grads = GradientsParams::from_grads(loss.backward(), &model);
    let model = optim.step(1e-3, model, grads);
    let after: f32 = gmm_nll(
        &model.forward(&batch),
        batch.future_xy.clone(),
        batch.future_valid.clone(),
    )
    .into_scalar();
    assert!(after < before, "{after} !< {before}");
    // The conditional input changes the prediction.
    let diff: f32 = (out.xy.clone().narrow(0, 0, 1) - out.xy.narrow(0, 1, 1))
        .abs()
        .sum()
        .into_scalar();
    assert!(diff > 0.0);
    let small = config.init(&Device::flex()).num_params();
    let paper = MultipathConfig::paper().init(&Device::flex()).num_params();
    eprintln!("parameters: cpu-small {small}, paper {paper}");
    assert!(
        small < paper && paper > 10_000_000,
        "paper preset has {paper} parameters"
    );
}

/// Under the step-wise conditioning, changing the other agent's future from step 40 on
/// changes nothing of the target's prediction before step 45 (the 0.5 s block that starts
/// at step 45 is the first to see it: B's point at step 44) and leaves the mode
/// probabilities alone, while it does change the later steps; the fused (CBP) model lets
/// the same change move every step. Marginal rows are not corrected.
#[test]
fn stepwise_conditioning_is_temporally_causal() {
    let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let features = small_features();
    let device = Device::flex();
    let base = straight_sample(&features, true);
    let mut late = base.clone();
    for t in 40..80 {
        late.condition_future_xy_m[2 * t + 1] += 3.0 + 0.2 * (t - 40) as f32;
    }
    let marginal = straight_sample(&features, false);
    let refs = [&base, &late, &marginal];
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
    let batch = Batch::from_samples(&refs, &BatchAugment::default(), &mut rng, &device);
    let max_diff = |out: &GmmOutput, steps: std::ops::Range<usize>| -> f32 {
        let xy = out.xy.clone().narrow(2, steps.start, steps.len());
        let (a, b) = (xy.clone().narrow(0, 0, 1), xy.narrow(0, 1, 1));
        (a - b).abs().max().into_scalar()
    };
    for stepwise in [true, false] {
        device.seed(7);
        let mut model = MultipathConfig {
            stepwise_condition: stepwise,
            ..MultipathConfig::cpu_small()
        }
        .init(&device);
        if stepwise {
            with_random_corrections(&mut model, &device);
        }
        let out = model.forward(&batch);
        let (early, later) = (max_diff(&out, 0..45), max_diff(&out, 45..80));
        let logits = out.logits.clone();
        let logit_diff: f32 = (logits.clone().narrow(0, 0, 1) - logits.narrow(0, 1, 1))
            .abs()
            .max()
            .into_scalar();
        eprintln!("stepwise {stepwise}: early {early:e}, later {later:e}, logits {logit_diff:e}");
        assert!(later > 1e-7, "the late change must reach the late steps");
        if stepwise {
            assert!(early < 1e-7 && logit_diff < 1e-7, "{early} {logit_diff}");
            // The marginal row is the plain decode of the marginal embedding.
            let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
            let alone =
                Batch::from_samples(&[&marginal], &BatchAugment::default(), &mut rng, &device);
            let plain = model.decode(model.encode(&alone));
            let d: f32 = (plain.xy - out.xy.clone().narrow(0, 2, 1))
                .abs()
                .max()
                .into_scalar();
            assert!(d < 1e-5, "{d}");
        } else {
            assert!(early > 1e-7, "the fused model anticipates: {early}");
        }
    }
}

/// The marginal embedding from the scene encoding, without the future encoder, is the
/// embedding `encode` gives a marginal batch (the zero flag discards that encoder's output),
/// and `forward_marginal` is `forward` of that batch, to the bit.
#[test]
fn marginal_shortcuts_equal_encode_and_forward_of_a_marginal_batch() {
    let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let features = small_features();
    let device = Device::flex();
    let (first, second) = two_targets(&features);
    for (stepwise, lane_frame) in [(false, false), (true, true)] {
        let model = seeded_model(stepwise, lane_frame, 12, &device);
        let batch = Batch::for_mode(&[&first, &second], crate::Mode::Marginal, &device);
        let expected = values(model.encode(&batch));
        let got = values(model.encode_marginal(model.encode_scene(&batch)));
        assert_eq!(got, expected, "stepwise {stepwise}");
        let (full, fast) = (model.forward(&batch), model.forward_marginal(&batch));
        assert_eq!(
            values(fast.xy),
            values(full.xy.clone()),
            "stepwise {stepwise}"
        );
        assert_eq!(values(fast.cov_abc), values(full.cov_abc));
        assert_eq!(values(fast.logits), values(full.logits.clone()));
        // The means-only paths: the same means and logits, the covariances skipped.
        for means in [
            model.forward_means(&batch),
            model.forward_marginal_means(&batch),
        ] {
            assert_close(&values(means.xy), &values(full.xy.clone()));
            assert_close(&values(means.logits), &values(full.logits.clone()));
        }
        // A conditional batch's embedding is another one: the test can tell them apart.
        let conditional = Batch::for_mode(&[&first, &second], crate::Mode::Conditional, &device);
        assert_ne!(got, values(model.encode(&conditional)));
    }
}

/// Rows that share their scene give the same prediction through `forward_shared` (the
/// scene encoded once per target) as through `forward` of the repeated rows, for the fused
/// and the step-wise model, with and without the lane frame.
#[test]
fn forward_shared_matches_forward_of_the_repeated_rows() {
    let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let features = small_features();
    let device = Device::flex();
    let (first, mut second) = two_targets(&features);
    for k in 0..second.lane_path_xy_m.len() / 2 {
        second.lane_path_xy_m[2 * k + 1] += 1.5;
    }
    let targets = [&first, &second];
    let rows = [1usize, 0, 1, 1, 0];
    // Each row its own future of the other agent.
    let repeated: Vec<AgentSample> = rows
        .iter()
        .enumerate()
        .map(|(r, &t)| {
            let mut s = targets[t].clone();
            for (k, v) in s.condition_future_xy_m.iter_mut().enumerate() {
                *v += 0.3 * r as f32 * (k % 2) as f32 + 0.01 * (k / 2) as f32 * r as f32;
            }
            s
        })
        .collect();
    let repeated_refs: Vec<&AgentSample> = repeated.iter().collect();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
    let full = Batch::from_samples(&repeated_refs, &BatchAugment::default(), &mut rng, &device);
    let base = Batch::from_samples(&targets, &BatchAugment::default(), &mut rng, &device);
    let index = Tensor::<1, burn::tensor::Int>::from_data(
        TensorData::new(rows.iter().map(|&r| r as i64).collect(), [rows.len()]),
        &device,
    );
    for (stepwise, lane_frame) in [(false, false), (false, true), (true, false), (true, true)] {
        let model = seeded_model(stepwise, lane_frame, 11, &device);
        let expected = model.forward(&full);
        let shared = model.forward_shared(&base, index.clone(), full.condition.clone());
        let diff = |a: Tensor<4>, b: Tensor<4>| -> f32 { (a - b).abs().max().into_scalar() };
        let (dxy, dcov) = (
            diff(expected.xy.clone(), shared.xy.clone()),
            diff(expected.cov_abc.clone(), shared.cov_abc.clone()),
        );
        let dlogits: f32 = (expected.logits.clone() - shared.logits.clone())
            .abs()
            .max()
            .into_scalar();
        assert!(
            dxy < 1e-4 && dcov < 1e-4 && dlogits < 1e-4,
            "stepwise {stepwise}, lane frame {lane_frame}: {dxy} {dcov} {dlogits}"
        );
        // The means-only paths, shared and not, give the same means and logits.
        let means = model.forward_encoded_means(
            model.encode_scene(&base),
            base.lane_path.as_ref(),
            index.clone(),
            full.condition.clone(),
        );
        assert_close(&values(means.xy), &values(shared.xy.clone()));
        assert_close(&values(means.logits), &values(shared.logits.clone()));
        let means = model.forward_means(&full);
        assert_close(&values(means.xy), &values(expected.xy.clone()));
        assert_close(&values(means.logits), &values(expected.logits.clone()));
        // The rows do differ: the test would notice a row taken from the wrong target.
        let rows_differ: f32 = (expected.xy.clone().narrow(0, 0, 1)
            - expected.xy.clone().narrow(0, 1, 1))
        .abs()
        .max()
        .into_scalar();
        assert!(rows_differ > 1e-3, "{rows_differ}");
    }
}

/// The courtesy loss back-propagates through the conditional prediction into B's future:
/// the step-wise model must pass gradients to every conditioning point but the last
/// (which no block of A's steps sees).
#[test]
fn stepwise_conditioning_passes_gradients_to_the_condition() {
    let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let features = small_features();
    let device = Device::flex().autodiff();
    device.seed(9);
    let mut model = MultipathConfig {
        stepwise_condition: true,
        ..MultipathConfig::cpu_small()
    }
    .init(&device);
    with_random_corrections(&mut model, &device);
    let sample = straight_sample(&features, true);
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
    let batch = Batch::from_samples(&[&sample], &BatchAugment::default(), &mut rng, &device);
    let condition = batch.condition.clone().detach().require_grad();
    let out = model.forward(&batch.with_condition(Some(condition.clone())));
    let grads = out.xy.sum().backward();
    let g = condition.grad(&grads).unwrap(); // [1, 80, 3]
    let per_step: Vec<f32> = g
        .narrow(2, 0, 2)
        .abs()
        .sum_dim(2)
        .reshape([80])
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    // Points at steps 4, 9, …, 74 (and the steps before them, for the velocities) are
    // seen by some block; the last point (step 79, with step 78) by none.
    for t in [3, 4, 8, 9, 73, 74] {
        assert!(per_step[t] > 0.0, "no gradient at step {t}: {per_step:?}");
    }
    assert_eq!(per_step[78] + per_step[79], 0.0, "{per_step:?}");
}

/// The conditional mode must be able to use the *content* of y_B: here the target's future
/// (brake to a stop or keep 1 m/step) is decided only by whether the other agent crosses in
/// front or stays where it is; histories are identical. After a short training the
/// conditional mixture must put its weight on the right mode. (Without the direct
/// embedding → logits head this stayed at 50/50 for 1,500 steps; without the mode
/// classification term it took about twice as many steps. 600 steps pass for seeds 3, 4, 5.)
#[test]
fn conditional_mode_uses_the_content_of_the_condition() {
    conditional_mode_learns_the_oracle(false);
}

/// The same with the step-wise (interventional) conditioning: the target's steps react to
/// where the other agent has been, which here shows from its first point on.
#[test]
fn stepwise_conditional_mode_uses_the_content_of_the_condition() {
    conditional_mode_learns_the_oracle(true);
}

fn conditional_mode_learns_the_oracle(stepwise: bool) {
    let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex().autodiff();
    device.seed(3);
    let config = MultipathConfig {
        stepwise_condition: stepwise,
        ..MultipathConfig::cpu_small()
    };
    let features = small_features();
    let f = config.future_steps;
    let samples: Vec<AgentSample> = (0..32usize)
        .map(|i| {
            let mut s = straight_sample(&features, true);
            let crosses = i.is_multiple_of(2);
            // The other agent starts 30 m ahead, 10 m to the left; it either drives across
            // the target's path at 5 m/s or stays where it is.
            s.condition_future_xy_m = (0..f)
                .flat_map(|t| {
                    let y = if crosses {
                        10.0 - 0.5 * (t + 1) as f32
                    } else {
                        10.0
                    };
                    [30.0, y]
                })
                .collect();
            // The target brakes to a stop at 25 m when the other crosses, else keeps 1 m/step.
            s.future_xy_m = (0..f)
                .flat_map(|t| {
                    let x = (t + 1) as f32;
                    [if crosses { x.min(25.0) } else { x }, 0.0]
                })
                .collect();
            s
        })
        .collect();
    let refs: Vec<&AgentSample> = samples.iter().collect();
    let mut model = config.init(&device);
    let mut optim = AdamConfig::new().init();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
    let train = BatchAugment {
        condition_dropout: 0.5,
        history_mask_prob: 0.0,
    };
    for _ in 0..600 {
        let batch = Batch::from_samples(&refs, &train, &mut rng, &device);
        let out = model.forward(&batch);
        let loss = gmm_nll(&out, batch.future_xy.clone(), batch.future_valid.clone())
            + crate::loss::mode_classification_loss(
                &out,
                batch.future_xy.clone(),
                batch.future_valid.clone(),
            );
        let raw = loss.backward();
        let grads = GradientsParams::from_grads(raw, &model);
        model = optim.step(3e-3, model, grads);
    }
    // Error of the expected final position Σ_k π_k μ_k(T) along the road: the mixture can
    // only get it right when the condition moves the mode probabilities.
    let error = |dropout: f64| -> f32 {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
        let augment = BatchAugment {
            condition_dropout: dropout,
            history_mask_prob: 0.0,
        };
        let batch = Batch::from_samples(&refs, &augment, &mut rng, &device);
        let out = model.forward(&batch);
        let [b, k, t, _] = out.xy.dims();
        let pi = burn::tensor::activation::softmax(out.logits, 1);
        let last_x = out.xy.narrow(2, t - 1, 1).narrow(3, 0, 1).reshape([b, k]);
        let expected: Vec<f32> = (pi * last_x)
            .sum_dim(1)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let truth = |i: usize| if i.is_multiple_of(2) { 25.0 } else { t as f32 };
        expected
            .iter()
            .enumerate()
            .map(|(i, e)| (e - truth(i)).abs())
            .sum::<f32>()
            / b as f32
    };
    let (conditional, marginal) = (error(0.0), error(1.0));
    eprintln!("oracle: |E[x_T] − x_T| conditional {conditional:.2} m, marginal {marginal:.2} m");
    assert!(
        conditional < 0.5 * marginal,
        "the condition barely moves the prediction: {conditional} vs {marginal} m"
    );
}

#[test]
fn a_required_condition_survives_condition_dropout() {
    let features = small_features();
    let plain = straight_sample(&features, true);
    let required = AgentSample {
        condition_required: true,
        ..plain.clone()
    };
    let refs = [&plain, &required];
    let augment = BatchAugment {
        condition_dropout: 1.0,
        history_mask_prob: 0.0,
    };
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
    let batch = Batch::from_samples(&refs, &augment, &mut rng, &Device::flex());
    assert_eq!(batch.condition_kept, [false, true]);
    let flags = batch
        .condition_flag
        .clone()
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    assert_eq!(flags, vec![0.0, 1.0]);
    // The host's copy follows the batch through a new condition and a repeat.
    assert_eq!(batch.repeat(2).condition_kept, [false, true, false, true]);
    assert_eq!(
        batch.clone().with_condition(None).condition_kept,
        [false; 2]
    );
}

/// Equal up to float rounding (relative 1e-5).
fn assert_close(got: &[f32], want: &[f32]) {
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() <= 1e-5 * (1.0 + w.abs()), "{g} vs {w}");
    }
}

/// A batch leaves out the trailing agent and road-segment slots no sample fills, and that
/// changes no prediction: a sample predicted alone (its two agents and five segments kept)
/// gets what it gets beside a sample that fills every slot.
#[test]
fn unfilled_slots_are_left_out_without_changing_the_prediction() {
    let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let features = small_features();
    let device = Device::flex();
    let h = features.history_steps;
    let per_agent = h * scbg_features::AGENT_FEATURES;
    let mut sparse = straight_sample(&features, true);
    let per_diff = (h - 1) * scbg_features::DIFF_FEATURES;
    // Agent `k`: the target's own history, `dy` to its left.
    let place = |s: &mut AgentSample, k: usize, dy: f32| {
        s.others_valid[k] = true;
        let mut hist = s.target_history.clone();
        for row in hist.chunks_mut(scbg_features::AGENT_FEATURES) {
            row[1] = dy;
        }
        s.others_history[k * per_agent..(k + 1) * per_agent].copy_from_slice(&hist);
        let diffs = s.target_diffs.clone();
        s.others_diffs[k * per_diff..(k + 1) * per_diff].copy_from_slice(&diffs);
    };
    place(&mut sparse, 0, 3.5);
    place(&mut sparse, 1, -3.5);
    sparse.road_valid[5..].fill(false);
    let mut full = sparse.clone();
    place(&mut full, features.max_other_agents - 1, 7.0);
    full.road_valid.fill(true);
    for (i, v) in full.road_segments.iter_mut().enumerate() {
        *v += 0.05 * (i % 5) as f32;
    }
    let alone = Batch::for_mode(&[&sparse], crate::Mode::Conditional, &device);
    assert_eq!(alone.others_history.dims()[1], 2);
    assert_eq!(alone.road.dims()[1], 5);
    let beside = Batch::for_mode(&[&sparse, &full], crate::Mode::Conditional, &device);
    assert_eq!(beside.others_history.dims()[1], features.max_other_agents);
    assert_eq!(beside.road.dims()[1], features.max_road_segments);
    for stepwise in [false, true] {
        let model = seeded_model(stepwise, false, 13, &device);
        let (a, b) = (model.forward(&alone), model.forward(&beside));
        assert_close(&values(a.xy), &values(b.xy.clone().narrow(0, 0, 1)));
        assert_close(&values(a.cov_abc), &values(b.cov_abc.narrow(0, 0, 1)));
        assert_close(&values(a.logits), &values(b.logits.clone().narrow(0, 0, 1)));
        // The scene encodings agree too, and the second sample's extra agent and segments
        // do count for it.
        let (a, b) = (
            model.encode_scene(&alone).scene,
            model.encode_scene(&beside).scene,
        );
        assert_close(&values(a), &values(b.clone().narrow(0, 0, 1)));
        let rows: f32 = (b.clone().narrow(0, 0, 1) - b.narrow(0, 1, 1))
            .abs()
            .max()
            .into_scalar();
        assert!(rows > 1e-4, "{rows}");
    }
}
