//! A fused LSTM kernel for the `flex` CPU backend, with a hand-written backward pass (BPTT).
//!
//! Why: built from tensor ops, one LSTM step is ~13 tracked ops (two matmuls, four gate slices,
//! three sigmoids, two tanh, the cell update), each allocating its output, recording a graph
//! node and, in the backward pass, allocating a zero gradient of the whole gate tensor per slice.
//! On `cpu-small` the two history LSTMs were ~45 % of a training step (measured by running one
//! step instead of eleven). PyTorch runs a fused LSTM kernel; this is ours. Per sequence: one
//! GEMM for every step's input projection, one `[n, h] × [h, 4h]` GEMM per step, and the gate
//! math in one pass; the backward runs the recurrence once in reverse and computes the weight
//! gradients with two GEMMs over all steps.
//!
//! The op is a burn *backend extension* ([`LstmBackend`]) implemented for `Flex` and for
//! `Autodiff<Flex>`; [`crate::blocks::FusedLstm`] calls it on a `flex` device and falls back to
//! the tensor-op formulation elsewhere (`tch`, `cuda`). `fused_lstm_matches_the_tensor_op_lstm`
//! checks the values and all five gradients against that formulation.
//!
//! Weight layout as burn's `Linear`: `w_ih: [d_in, 4h]`, `w_hh: [h, 4h]`, gates i, f, g, o.

use std::sync::Arc;

use burn::backend::ops::FloatTensorOps;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, Dispatch, DispatchDevice, backend_extension};
use burn::tensor::{DType, Device, Shape, Tensor, TensorData};
use burn_autodiff::Autodiff;
use burn_autodiff::checkpoint::base::Checkpointer;
use burn_autodiff::checkpoint::strategy::CheckpointStrategy;
use burn_autodiff::grads::Gradients;
use burn_autodiff::ops::{Backward, Ops, OpsKind};
use burn_flex::{Flex, FlexTensor};

/// The fused LSTM as a backend operation.
#[backend_extension(Flex, Autodiff)]
pub trait LstmBackend: Backend {
    /// The hidden state after the last step of an LSTM started from zero state.
    ///
    /// # Shapes
    /// `x: [n, steps, d_in]`, `w_ih: [d_in, 4h]`, `b_ih: [4h]`, `w_hh: [h, 4h]`, `b_hh: [4h]`
    /// `-> [n, h]`
    fn lstm_last_hidden(
        x: FloatTensor<Self>,
        w_ih: FloatTensor<Self>,
        b_ih: FloatTensor<Self>,
        w_hh: FloatTensor<Self>,
        b_hh: FloatTensor<Self>,
    ) -> FloatTensor<Self>;
}

/// Whether [`lstm_last_hidden`] has a fused kernel for this device (`flex`, with or without
/// autodiff).
pub fn has_fused_lstm(device: &Device) -> bool {
    match device.as_dispatch() {
        DispatchDevice::Flex(_) => true,
        DispatchDevice::Autodiff(inner) => matches!(&**inner, DispatchDevice::Flex(_)),
        #[allow(unreachable_patterns)]
        _ => false,
    }
}

/// The fused LSTM on `Tensor`s (see [`LstmBackend::lstm_last_hidden`]). Only call it where
/// [`has_fused_lstm`] holds, with `f32` tensors.
///
/// # Shapes
/// `x: [n, steps, d_in]`, `w_ih: [d_in, 4h]`, `b_ih: [4h]`, `w_hh: [h, 4h]`, `b_hh: [4h]`
/// `-> [n, h]`
pub fn lstm_last_hidden(
    x: Tensor<3>,
    w_ih: Tensor<2>,
    b_ih: Tensor<1>,
    w_hh: Tensor<2>,
    b_hh: Tensor<1>,
) -> Tensor<2> {
    Tensor::from_dispatch(<Dispatch as LstmBackend>::lstm_last_hidden(
        x.into_dispatch(),
        w_ih.into_dispatch(),
        b_ih.into_dispatch(),
        w_hh.into_dispatch(),
        b_hh.into_dispatch(),
    ))
}

impl LstmBackend for Flex {
    fn lstm_last_hidden(
        x: FlexTensor,
        w_ih: FlexTensor,
        b_ih: FlexTensor,
        w_hh: FlexTensor,
        b_hh: FlexTensor,
    ) -> FlexTensor {
        forward(&x, &w_ih, &b_ih, &w_hh, &b_hh, false).0
    }
}

/// What the backward pass needs from the forward pass (sizes come from `x` and `w_hh`).
#[derive(Debug)]
struct Tape {
    /// Activated gates i, f, g, o: `[steps, n, 4h]`.
    gates: Vec<f32>,
    /// Cell states `c_0 = 0, c_1, …, c_steps`: `[steps + 1, n, h]`.
    cells: Vec<f32>,
    /// `tanh(c_1), …, tanh(c_steps)`: `[steps, n, h]`.
    tanh_cells: Vec<f32>,
    /// The hidden state entering each step, `h_{t−1}`, in `x`'s row order: `[n·steps, h]`.
    h_prev: FlexTensor,
}

#[derive(Clone, Debug)]
struct LstmState {
    x: FlexTensor,
    w_ih: FlexTensor,
    w_hh: FlexTensor,
    tape: Arc<Tape>,
}

#[derive(Debug)]
struct LstmBackward;

impl Backward<Flex, 5> for LstmBackward {
    type State = LstmState;

    fn backward(self, ops: Ops<Self::State, 5>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x, node_w_ih, node_b_ih, node_w_hh, node_b_hh] = ops.parents;
        let grad = grads.consume::<Flex>(&ops.node);
        let st = ops.state;
        let g = backward(&st, &grad, node_x.is_some());
        if let (Some(node), Some(dx)) = (node_x, g.x) {
            grads.register::<Flex>(node.id, dx);
        }
        if let Some(node) = node_w_ih {
            grads.register::<Flex>(node.id, g.w_ih);
        }
        if let Some(node) = node_b_ih {
            grads.register::<Flex>(node.id, g.bias.clone());
        }
        if let Some(node) = node_w_hh {
            grads.register::<Flex>(node.id, g.w_hh);
        }
        if let Some(node) = node_b_hh {
            grads.register::<Flex>(node.id, g.bias);
        }
    }
}

impl<C: CheckpointStrategy> LstmBackend for Autodiff<Flex, C> {
    fn lstm_last_hidden(
        x: FloatTensor<Self>,
        w_ih: FloatTensor<Self>,
        b_ih: FloatTensor<Self>,
        w_hh: FloatTensor<Self>,
        b_hh: FloatTensor<Self>,
    ) -> FloatTensor<Self> {
        let prep = LstmBackward
            .prepare::<C>([x.node(), w_ih.node(), b_ih.node(), w_hh.node(), b_hh.node()])
            .compute_bound()
            .stateful();
        let tracked = matches!(prep, OpsKind::Tracked(_));
        let (h, tape) = forward(
            x.primitive(),
            w_ih.primitive(),
            b_ih.primitive(),
            w_hh.primitive(),
            b_hh.primitive(),
            tracked,
        );
        match prep {
            OpsKind::Tracked(prep) => {
                let state = LstmState {
                    x: x.primitive().clone(),
                    w_ih: w_ih.primitive().clone(),
                    w_hh: w_hh.primitive().clone(),
                    tape: Arc::new(tape.expect("the tape was asked for")),
                };
                prep.finish(state, h)
            }
            OpsKind::UnTracked(prep) => prep.finish(h),
        }
    }
}

fn f32_tensor(values: Vec<f32>, shape: impl Into<Shape>) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(values, shape.into()))
}

/// A contiguous `f32` copy-free view where possible.
fn contiguous(t: &FlexTensor) -> FlexTensor {
    assert_eq!(t.dtype(), DType::F32, "the fused LSTM runs in f32");
    if t.as_slice::<f32>().is_some() {
        t.clone()
    } else {
        t.to_contiguous()
    }
}

fn slice(t: &FlexTensor) -> &[f32] {
    t.as_slice::<f32>().expect("contiguous f32 tensor")
}

/// `e^x` for `f32`, written so that loops over slices vectorize (the libm `expf`/`tanhf` calls
/// were a fifth of the step): `2^k · p(r)` with `x = k·ln 2 + r`, `|r| ≤ ln 2 / 2`, and a degree-6
/// Taylor polynomial (relative error < 3e-7, about 2 ulp, over the clamped range; see the tests).
#[inline(always)]
fn exp_f32(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    // Round-to-nearest by the 1.5·2^23 trick (no branch, no call).
    const SHIFTER: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 88.0);
    let kf = x * LOG2E + SHIFTER;
    let k = kf.to_bits() as i32 - SHIFTER.to_bits() as i32;
    let kf = kf - SHIFTER;
    let r = x - kf * LN2_HI - kf * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    f32::from_bits(((k + 127) << 23) as u32) * p
}

#[inline(always)]
fn sigmoid_f32(z: f32) -> f32 {
    1.0 / (1.0 + exp_f32(-z))
}

#[inline(always)]
fn tanh_f32(z: f32) -> f32 {
    1.0 - 2.0 / (exp_f32(2.0 * z) + 1.0)
}

/// In place, on rows of `[i | f | g | o]` pre-activations: σ on i, f, o and tanh on g.
#[inline(always)]
fn activate_gates(z: &mut [f32], h_width: usize) {
    for row in z.chunks_exact_mut(4 * h_width) {
        let (ifg, o) = row.split_at_mut(3 * h_width);
        let (i_f, g) = ifg.split_at_mut(2 * h_width);
        for v in i_f.iter_mut().chain(o.iter_mut()) {
            *v = sigmoid_f32(*v);
        }
        for v in g.iter_mut() {
            *v = tanh_f32(*v);
        }
    }
}

/// Defines `$name`, which runs `$impl` (an `#[inline(always)]` function) compiled for AVX-512 or
/// AVX2 + FMA when the CPU has them, else for the build's baseline: the gate loops then vectorize 16 or 8
/// lanes wide instead of SSE2's 4. (Runtime detection, as burn's own `x86-v4` GEMM does.)
macro_rules! multiversion {
    ($name:ident, ($($arg:ident: $ty:ty),*) -> $ret:ty, $impl:ident) => {
        fn $name($($arg: $ty),*) -> $ret {
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx512f,avx2,fma")]
                fn avx512($($arg: $ty),*) -> $ret {
                    $impl($($arg),*)
                }
                #[target_feature(enable = "avx2,fma")]
                fn avx2($($arg: $ty),*) -> $ret {
                    $impl($($arg),*)
                }
                if std::arch::is_x86_feature_detected!("avx512f") {
                    // SAFETY: the CPU supports the features the function is compiled for.
                    #[allow(unsafe_code)]
                    return unsafe { avx512($($arg),*) };
                }
                if std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                {
                    // SAFETY: as above.
                    #[allow(unsafe_code)]
                    return unsafe { avx2($($arg),*) };
                }
            }
            $impl($($arg),*)
        }
    };
}

multiversion!(
    forward,
    (
        x: &FlexTensor,
        w_ih: &FlexTensor,
        b_ih: &FlexTensor,
        w_hh: &FlexTensor,
        b_hh: &FlexTensor,
        keep_tape: bool
    ) -> (FlexTensor, Option<Tape>),
    forward_impl
);

multiversion!(
    backward,
    (st: &LstmState, grad_h: &FlexTensor, need_x: bool) -> LstmGrads,
    backward_impl
);

/// The forward recurrence; with `keep_tape`, also what the backward pass needs.
#[inline(always)]
fn forward_impl(
    x: &FlexTensor,
    w_ih: &FlexTensor,
    b_ih: &FlexTensor,
    w_hh: &FlexTensor,
    b_hh: &FlexTensor,
    keep_tape: bool,
) -> (FlexTensor, Option<Tape>) {
    let [n, steps, d_in] = x.layout().shape().dims();
    let [h_width, four_h] = w_hh.layout().shape().dims();
    debug_assert_eq!(four_h, 4 * h_width);
    let x = contiguous(x);
    let w_hh = contiguous(w_hh);
    // Every step's input projection in one GEMM: rows in x's order (b·steps + t).
    let xw = Flex::float_matmul(x.reshape(Shape::new([n * steps, d_in])), contiguous(w_ih));
    let xw = contiguous(&xw);
    let xw = slice(&xw);
    let bias: Vec<f32> = slice(&contiguous(b_ih))
        .iter()
        .zip(slice(&contiguous(b_hh)))
        .map(|(a, b)| a + b)
        .collect();

    let mut h = vec![0.0f32; n * h_width];
    let mut c = vec![0.0f32; n * h_width];
    let mut tanh_c = vec![0.0f32; n * h_width];
    let mut z = vec![0.0f32; n * four_h];
    // The tape, filled step by step when asked for: gates, c_0..c_steps, tanh(c_t), h_{t−1}.
    let mut tape = keep_tape.then(|| {
        (
            Vec::with_capacity(steps * n * four_h),
            vec![0.0f32; n * h_width],
            Vec::with_capacity(steps * n * h_width),
            vec![0.0f32; n * steps * h_width],
        )
    });
    for t in 0..steps {
        // h_0 = 0: the first step has no recurrent product.
        let hw = (t > 0).then(|| {
            let hw = Flex::float_matmul(f32_tensor(h.clone(), [n, h_width]), w_hh.clone());
            contiguous(&hw)
        });
        let hw = hw.as_ref().map(slice);
        for (b, z_row) in z.chunks_exact_mut(four_h).enumerate() {
            let x_row = &xw[(b * steps + t) * four_h..][..four_h];
            match hw {
                Some(hw) => {
                    let hw_row = &hw[b * four_h..][..four_h];
                    for (((zv, xv), hv), bv) in z_row.iter_mut().zip(x_row).zip(hw_row).zip(&bias) {
                        *zv = xv + hv + bv;
                    }
                }
                None => {
                    for ((zv, xv), bv) in z_row.iter_mut().zip(x_row).zip(&bias) {
                        *zv = xv + bv;
                    }
                }
            }
        }
        activate_gates(&mut z, h_width);
        for (b, gate_row) in z.chunks_exact(four_h).enumerate() {
            let (i, rest) = gate_row.split_at(h_width);
            let (f, rest) = rest.split_at(h_width);
            let (g, _) = rest.split_at(h_width);
            let c_row = &mut c[b * h_width..][..h_width];
            for j in 0..h_width {
                c_row[j] = f[j] * c_row[j] + i[j] * g[j];
            }
        }
        for (tc, cv) in tanh_c.iter_mut().zip(&c) {
            *tc = tanh_f32(*cv);
        }
        if let Some((gates, cells, tanh_cells, h_prev)) = tape.as_mut() {
            for b in 0..n {
                h_prev[(b * steps + t) * h_width..][..h_width]
                    .copy_from_slice(&h[b * h_width..][..h_width]);
            }
            gates.extend_from_slice(&z);
            cells.extend_from_slice(&c);
            tanh_cells.extend_from_slice(&tanh_c);
        }
        for (b, gate_row) in z.chunks_exact(four_h).enumerate() {
            let o = &gate_row[3 * h_width..];
            let h_row = &mut h[b * h_width..][..h_width];
            let tc_row = &tanh_c[b * h_width..][..h_width];
            for j in 0..h_width {
                h_row[j] = o[j] * tc_row[j];
            }
        }
    }
    let tape = tape.map(|(gates, cells, tanh_cells, h_prev)| Tape {
        gates,
        cells,
        tanh_cells,
        h_prev: f32_tensor(h_prev, [n * steps, h_width]),
    });
    (f32_tensor(h, [n, h_width]), tape)
}

struct LstmGrads {
    x: Option<FlexTensor>,
    w_ih: FlexTensor,
    w_hh: FlexTensor,
    /// The gradient of both biases (they enter the gates as a sum).
    bias: FlexTensor,
}

/// Backpropagation through time from the gradient of the last hidden state.
#[inline(always)]
fn backward_impl(st: &LstmState, grad_h: &FlexTensor, need_x: bool) -> LstmGrads {
    let Tape {
        ref gates,
        ref cells,
        ref tanh_cells,
        ref h_prev,
    } = *st.tape;
    let [n, steps, d_in] = st.x.layout().shape().dims();
    let [h_width, four_h] = st.w_hh.layout().shape().dims();
    let w_hh_t = Flex::float_transpose(st.w_hh.clone());
    let mut dh = slice(&contiguous(grad_h)).to_vec();
    let mut dc = vec![0.0f32; n * h_width];
    // Pre-activation gradients of every step, in x's row order (b·steps + t).
    let mut dz_all = vec![0.0f32; n * steps * four_h];
    let mut dz_t = vec![0.0f32; n * four_h];
    for t in (0..steps).rev() {
        for b in 0..n {
            let gate_row = &gates[(t * n + b) * four_h..][..four_h];
            let tc_row = &tanh_cells[(t * n + b) * h_width..][..h_width];
            let c_prev = &cells[(t * n + b) * h_width..][..h_width];
            let dz_row = &mut dz_t[b * four_h..][..four_h];
            for j in 0..h_width {
                let (i, f, g, o) = (
                    gate_row[j],
                    gate_row[h_width + j],
                    gate_row[2 * h_width + j],
                    gate_row[3 * h_width + j],
                );
                let tc = tc_row[j];
                let dh_j = dh[b * h_width + j];
                let dc_j = dc[b * h_width + j] + dh_j * o * (1.0 - tc * tc);
                dz_row[j] = dc_j * g * i * (1.0 - i);
                dz_row[h_width + j] = dc_j * c_prev[j] * f * (1.0 - f);
                dz_row[2 * h_width + j] = dc_j * i * (1.0 - g * g);
                dz_row[3 * h_width + j] = dh_j * tc * o * (1.0 - o);
                dc[b * h_width + j] = dc_j * f;
            }
            dz_all[(b * steps + t) * four_h..][..four_h].copy_from_slice(dz_row);
        }
        if t > 0 {
            let dh_prev = Flex::float_matmul(f32_tensor(dz_t.clone(), [n, four_h]), w_hh_t.clone());
            dh = slice(&contiguous(&dh_prev)).to_vec();
        }
    }
    let mut bias = vec![0.0f32; four_h];
    for row in dz_all.chunks_exact(four_h) {
        for (acc, v) in bias.iter_mut().zip(row) {
            *acc += v;
        }
    }
    let x_flat = contiguous(&st.x).reshape(Shape::new([n * steps, d_in]));
    let dz = f32_tensor(dz_all, [n * steps, four_h]);
    let w_ih = Flex::float_matmul(Flex::float_transpose(x_flat), dz.clone());
    let w_hh = Flex::float_matmul(Flex::float_transpose(h_prev.clone()), dz.clone());
    let x = need_x.then(|| {
        let dx = Flex::float_matmul(dz, Flex::float_transpose(st.w_ih.clone()));
        contiguous(&dx).reshape(Shape::new([n, steps, d_in]))
    });
    LstmGrads {
        x,
        w_ih,
        w_hh,
        bias: f32_tensor(bias, [four_h]),
    }
}

#[cfg(test)]
mod tests;
