//! The fused LSTM against the tensor-op formulation, and its fast activations against `std`.

use burn::module::Module;

use super::*;
use crate::blocks::FusedLstm;

#[test]
fn exp_sigmoid_and_tanh_match_std() {
    let mut worst = (0.0f32, 0.0f32, 0.0f32);
    for i in -80_000..=80_000 {
        let x = i as f32 / 1000.0;
        let rel = ((exp_f32(x) - x.exp()) / x.exp()).abs();
        let sig = (sigmoid_f32(x) - 1.0 / (1.0 + (-x).exp())).abs();
        let th = (tanh_f32(x) - x.tanh()).abs();
        worst = (worst.0.max(rel), worst.1.max(sig), worst.2.max(th));
    }
    assert!(worst.0 < 3e-7, "exp relative error {}", worst.0);
    assert!(worst.1 < 2e-7, "sigmoid error {}", worst.1);
    assert!(worst.2 < 3e-7, "tanh error {}", worst.2);
    // Saturation instead of NaN at the ends.
    assert!(sigmoid_f32(-1e4) < 1e-30);
    assert_eq!(sigmoid_f32(1e4), 1.0);
    assert_eq!(tanh_f32(1e4), 1.0);
    assert_eq!(tanh_f32(-1e4), -1.0);
}

/// The fused kernel against the tensor-op LSTM (same weights): outputs, and the gradients of
/// all four parameters and of the input, on the autodiff flex device.
#[test]
fn fused_lstm_matches_the_tensor_op_lstm() {
    let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let device = Device::flex().autodiff();
    assert!(has_fused_lstm(&device) && has_fused_lstm(&Device::flex()));
    device.seed(11);
    let (n, steps, d_in, h) = (5, 7, 3, 4);
    let lstm = FusedLstm::init(d_in, h, &device);
    let xs: Vec<f32> = (0..n * steps * d_in)
        .map(|i| ((i * 37) % 23) as f32 / 4.0 - 2.5)
        .collect();
    let weights: Vec<f32> = (0..n * h).map(|i| ((i * 5) % 7) as f32 - 3.0).collect();
    let run = |fused: bool| {
        let x = Tensor::<3>::from_data(TensorData::new(xs.clone(), [n, steps, d_in]), &device)
            .require_grad();
        let out = if fused {
            lstm.forward(x.clone())
        } else {
            lstm.forward_ops(x.clone())
        };
        let w = Tensor::<2>::from_data(TensorData::new(weights.clone(), [n, h]), &device);
        let grads = (out.clone() * w).sum().backward();
        let v = |t: Tensor<2>| t.into_data().try_to_vec::<f32>().unwrap();
        let v1 = |t: Tensor<1>| t.into_data().try_to_vec::<f32>().unwrap();
        let g2 = |p: &burn::module::Param<Tensor<2>>| v(p.val().grad(&grads).unwrap());
        let g1 = |p: &burn::module::Param<Tensor<1>>| v1(p.val().grad(&grads).unwrap());
        vec![
            v(out),
            g2(&lstm.input.weight),
            g1(lstm.input.bias.as_ref().unwrap()),
            g2(&lstm.hidden.weight),
            g1(lstm.hidden.bias.as_ref().unwrap()),
            x.grad(&grads)
                .unwrap()
                .into_data()
                .try_to_vec::<f32>()
                .unwrap(),
        ]
    };
    let (fused, ops) = (run(true), run(false));
    let names = ["h", "dW_ih", "db_ih", "dW_hh", "db_hh", "dx"];
    for ((name, a), b) in names.iter().zip(&fused).zip(&ops) {
        assert_eq!(a.len(), b.len(), "{name}");
        let scale = b.iter().fold(1.0f32, |m, v| m.max(v.abs()));
        for (u, w) in a.iter().zip(b) {
            assert!((u - w).abs() <= 1e-5 * scale, "{name}: {a:?} vs {b:?}");
        }
        assert!(
            b.iter().any(|v| v.abs() > 1e-3),
            "{name} is all zero: {b:?}"
        );
    }
    // Without autodiff (inference) the kernel gives the same hidden state.
    let plain = lstm.valid();
    let x = Tensor::<3>::from_data(
        TensorData::new(xs.clone(), [n, steps, d_in]),
        &Device::flex(),
    );
    let h_plain: Vec<f32> = plain.forward(x).into_data().try_to_vec::<f32>().unwrap();
    for (u, w) in h_plain.iter().zip(&fused[0]) {
        assert!((u - w).abs() <= 1e-6, "{h_plain:?} vs {:?}", fused[0]);
    }
}

/// The multiversioned entry point (AVX-512 on this project's machines) and the baseline
/// build of the same code agree, so the fallback path is tested too.
#[test]
fn dispatched_and_baseline_builds_agree() {
    let (n, steps, d_in, h) = (3, 5, 2, 3);
    let vals = |len: usize, k: usize| -> Vec<f32> {
        (0..len)
            .map(|i| ((i * k) % 13) as f32 / 6.0 - 1.0)
            .collect()
    };
    let x = f32_tensor(vals(n * steps * d_in, 7), [n, steps, d_in]);
    let w_ih = f32_tensor(vals(d_in * 4 * h, 5), [d_in, 4 * h]);
    let b_ih = f32_tensor(vals(4 * h, 3), [4 * h]);
    let w_hh = f32_tensor(vals(h * 4 * h, 11), [h, 4 * h]);
    let b_hh = f32_tensor(vals(4 * h, 2), [4 * h]);
    let (out_a, tape_a) = forward(&x, &w_ih, &b_ih, &w_hh, &b_hh, true);
    let (out_b, tape_b) = forward_impl(&x, &w_ih, &b_ih, &w_hh, &b_hh, true);
    let close = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(u, v)| (u - v).abs() < 1e-6);
    assert!(close(slice(&out_a), slice(&out_b)));
    let st = |tape: Option<Tape>| LstmState {
        x: x.clone(),
        w_ih: w_ih.clone(),
        w_hh: w_hh.clone(),
        tape: Arc::new(tape.unwrap()),
    };
    let grad = f32_tensor(vals(n * h, 3), [n, h]);
    let (ga, gb) = (
        backward(&st(tape_a), &grad, true),
        backward_impl(&st(tape_b), &grad, true),
    );
    assert!(close(slice(&ga.w_ih), slice(&gb.w_ih)));
    assert!(close(slice(&ga.w_hh), slice(&gb.w_hh)));
    assert!(close(slice(&ga.bias), slice(&gb.bias)));
    assert!(close(slice(&ga.x.unwrap()), slice(&gb.x.unwrap())));
}

/// Degenerate sizes: no sequences, and a single step.
#[test]
fn empty_batches_and_single_steps() {
    let device = Device::flex().autodiff();
    let lstm = FusedLstm::init(3, 2, &device);
    let empty = Tensor::<3>::zeros([0, 4, 3], &device);
    let out = lstm.forward(empty);
    assert_eq!(out.dims(), [0, 2]);
    let grads = out.sum().backward();
    let g: Vec<f32> = lstm
        .hidden
        .weight
        .val()
        .grad(&grads)
        .unwrap()
        .into_data()
        .try_to_vec()
        .unwrap();
    assert!(g.iter().all(|v| *v == 0.0), "{g:?}");
    let x = Tensor::<3>::ones([2, 1, 3], &device);
    let (a, b) = (lstm.forward(x.clone()), lstm.forward_ops(x));
    let (a, b): (Vec<f32>, Vec<f32>) = (
        a.into_data().try_to_vec().unwrap(),
        b.into_data().try_to_vec().unwrap(),
    );
    assert!(
        a.iter().zip(&b).all(|(u, v)| (u - v).abs() < 1e-6),
        "{a:?} vs {b:?}"
    );
}
