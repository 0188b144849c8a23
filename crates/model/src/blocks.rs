//! Multipath++ building blocks: MLPs, context gating (CG) and multi-context gating (MCG).

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::{relu, sigmoid};
use burn::tensor::{Device, Tensor};

/// A stack of linear layers with ReLU between them (not after the last).
#[derive(Module, Debug)]
pub struct Mlp {
    /// The linear layers, input first.
    pub layers: Vec<Linear>,
}

impl Mlp {
    /// `dims = [d_in, d_hidden..., d_out]`.
    pub fn init(dims: &[usize], device: &Device) -> Self {
        assert!(dims.len() >= 2, "an MLP needs input and output widths");
        Self {
            layers: dims
                .windows(2)
                .map(|w| LinearConfig::new(w[0], w[1]).init(device))
                .collect(),
        }
    }

    /// Runs on rows (see [`on_rows`]).
    ///
    /// # Shapes
    /// `[..., d_in] -> [..., d_out]`
    pub fn forward<const D: usize>(&self, x: Tensor<D>) -> Tensor<D> {
        on_rows(x, |mut x| {
            let n = self.layers.len();
            for (i, layer) in self.layers.iter().enumerate() {
                x = layer.forward(x);
                if i + 1 < n {
                    x = relu(x);
                }
            }
            x
        })
    }
}

impl Mlp {
    /// [`Self::forward`] with the last layer computing only the output columns in `columns`
    /// (concatenated in that order): the other columns' products are skipped, not computed
    /// and dropped.
    ///
    /// # Shapes
    /// `[..., d_in] -> [..., Σ column range lengths]`
    pub fn forward_columns<const D: usize>(
        &self,
        x: Tensor<D>,
        columns: &[std::ops::Range<usize>],
    ) -> Tensor<D> {
        let (last, hidden) = self
            .layers
            .split_last()
            .expect("an MLP has at least one layer");
        let pick = |t: Tensor<2>| {
            Tensor::cat(
                columns
                    .iter()
                    .map(|r| t.clone().narrow(1, r.start, r.len()))
                    .collect(),
                1,
            )
        };
        on_rows(x, |mut x| {
            for layer in hidden {
                x = relu(layer.forward(x));
            }
            let mut y = x.matmul(pick(last.weight.val()));
            if let Some(bias) = &last.bias {
                let b = bias.val();
                let n = b.dims()[0];
                y = y + pick(b.reshape([1, n]));
            }
            y
        })
    }
}

/// Applies a row-wise `f` with the leading dimensions of `x` folded into rows, so each linear
/// layer inside is one `[rows, d_in] × [d_in, d_out]` GEMM (forward and backward) rather than a
/// batched product against a broadcast weight, whose backward sums per-batch weight gradients
/// (the paper preset's step went from 381 to 240 ms).
///
/// # Shapes
/// `x: [..., d_in]`, `f: [rows, d_in] -> [rows, d_out]` `-> [..., d_out]`
pub fn on_rows<const D: usize>(x: Tensor<D>, f: impl FnOnce(Tensor<2>) -> Tensor<2>) -> Tensor<D> {
    let dims = x.dims();
    let y = f(x.reshape([-1, dims[D - 1] as i32]));
    let mut out_dims = dims;
    out_dims[D - 1] = y.dims()[1];
    y.reshape(out_dims)
}

/// Masked max over the set dimension; sets with no valid element give zeros.
///
/// # Shapes
/// `x: [batch, n, d]`, `mask: [batch, n]` (1 valid, 0 not) `-> [batch, d]`
pub fn masked_max(x: Tensor<3>, mask: Tensor<2>) -> Tensor<2> {
    let [b, n, d] = x.dims();
    let m = mask.clone().reshape([b, n, 1]);
    let filled = x * m.clone() + (m - 1.0) * 1e9;
    let any = mask.max_dim(1); // [b, 1]
    filled.max_dim(1).reshape([b, d]) * any
}

/// One context-gating block: `s' = MLP_s(s) ⊙ MLP_c(c)`, `c' = max over the set of s'`.
#[derive(Module, Debug)]
pub struct ContextGating {
    /// Three-layer MLP applied to each set element (`d_in → d_out`).
    pub mlp_s: Mlp,
    /// Three-layer MLP applied to the context, giving the gate (`d_context → d_out`).
    pub mlp_c: Mlp,
}

impl ContextGating {
    /// A block mapping elements of width `d_in` and a context of width `d_context` to width
    /// `d_out`.
    pub fn init(d_in: usize, d_context: usize, d_out: usize, device: &Device) -> Self {
        Self {
            mlp_s: Mlp::init(&[d_in, d_out, d_out, d_out], device),
            mlp_c: Mlp::init(&[d_context, d_out, d_out, d_out], device),
        }
    }

    /// Gates each element by the context and max-pools the result over the valid elements;
    /// invalid elements (`mask` 0) come out as zeros.
    ///
    /// # Shapes
    /// `s: [batch, n, d_in]`, `c: [batch, d_context]`, `mask: [batch, n]`
    /// `-> (s': [batch, n, d_out], c': [batch, d_out])`
    pub fn forward(&self, s: Tensor<3>, c: Tensor<2>, mask: Tensor<2>) -> (Tensor<3>, Tensor<2>) {
        let [b, n, _] = s.dims();
        let gate = self.mlp_c.forward(c);
        let d = gate.dims()[1];
        let s_out = self.mlp_s.forward(s) * gate.reshape([b, 1, d]);
        let s_out = s_out * mask.clone().reshape([b, n, 1]);
        let c_out = masked_max(s_out.clone(), mask);
        (s_out, c_out)
    }
}

/// Multi-context gating: a stack of CG blocks with skip connections.
///
/// Skip connections: the input of block k+1 is the *running mean* of the stack's input and
/// every block output so far (the public Multipath++ code accumulates a running sum while its
/// comments say mean; the mean keeps activations on one scale however deep the stack is).
#[derive(Module, Debug)]
pub struct Mcg {
    /// The CG blocks, all of the MCG width (at least one).
    pub blocks: Vec<ContextGating>,
    /// Projects the input elements to the block width (`d_in → width`).
    pub input_s: Linear,
    /// Projects the input context to the block width (`d_context → width`).
    pub input_c: Linear,
}

impl Mcg {
    /// An MCG of `num_blocks` CG blocks (at least one) of width `width`, taking elements of
    /// width `d_in` and a context of width `d_context`.
    pub fn init(
        d_in: usize,
        d_context: usize,
        width: usize,
        num_blocks: usize,
        device: &Device,
    ) -> Self {
        Self {
            blocks: (0..num_blocks.max(1))
                .map(|_| ContextGating::init(width, width, width, device))
                .collect(),
            input_s: LinearConfig::new(d_in, width).init(device),
            input_c: LinearConfig::new(d_context, width).init(device),
        }
    }

    /// Runs the stack; returns the elements and the context after the last block (each the
    /// running mean described on [`Mcg`]).
    ///
    /// # Shapes
    /// `s: [batch, n, d_in]`, `c: [batch, d_context]`, `mask: [batch, n]`
    /// `-> (s: [batch, n, width], c: [batch, width])`
    pub fn forward(&self, s: Tensor<3>, c: Tensor<2>, mask: Tensor<2>) -> (Tensor<3>, Tensor<2>) {
        let s_acc = on_rows(s, |s| self.input_s.forward(s));
        let c_acc = self.input_c.forward(c);
        continue_stack(&self.blocks, s_acc, c_acc, 1, mask)
    }

    /// [`Self::forward`] for one set of elements shared by every row, all valid (the
    /// decoder's learned anchors): the same outputs up to floating-point rounding, with the
    /// input projection and the first block's element MLP run once for the set instead of
    /// once per row (they do not depend on the context; half the decoder MCG's products).
    ///
    /// # Shapes
    /// `s: [n, d_in]`, `c: [batch, d_context]` `-> (s: [batch, n, width], c: [batch, width])`
    pub fn forward_shared(&self, s: Tensor<2>, c: Tensor<2>) -> (Tensor<3>, Tensor<2>) {
        let [n, _] = s.dims();
        let [b, _] = c.dims();
        let s0 = self.input_s.forward(s);
        let w = s0.dims()[1];
        let c_acc = self.input_c.forward(c);
        let (first, rest) = self
            .blocks
            .split_first()
            .expect("an MCG has at least one block");
        // The first block on the shared set: its element MLP once, its gate per row.
        let gate = first.mlp_c.forward(c_acc.clone());
        let s_out = first.mlp_s.forward(s0.clone()).reshape([1, n, w]) * gate.reshape([b, 1, w]);
        let c_out = s_out.clone().max_dim(1).reshape([b, w]);
        let s_acc = s_out + s0.reshape([1, n, w]);
        let mask = Tensor::ones([b, n], &c_acc.device());
        continue_stack(rest, s_acc, c_acc + c_out, 2, mask)
    }
}

/// Runs `blocks` of an MCG on top of the running sums of its first `terms` terms (the stack's
/// input and the blocks before), each block taking the running mean; returns the means after
/// the last block (the sums' means when there is none).
fn continue_stack(
    blocks: &[ContextGating],
    mut s_acc: Tensor<3>,
    mut c_acc: Tensor<2>,
    terms: usize,
    mask: Tensor<2>,
) -> (Tensor<3>, Tensor<2>) {
    let mean = |s: &Tensor<3>, c: &Tensor<2>, count: usize| {
        if count == 1 {
            (s.clone(), c.clone())
        } else {
            (s.clone() / count as f64, c.clone() / count as f64)
        }
    };
    let (mut s_in, mut c_in) = mean(&s_acc, &c_acc, terms);
    for (k, block) in blocks.iter().enumerate() {
        let (s_out, c_out) = block.forward(s_in, c_in, mask.clone());
        s_acc = s_acc + s_out;
        c_acc = c_acc + c_out;
        (s_in, c_in) = mean(&s_acc, &c_acc, terms + k + 1);
    }
    (s_in, c_in)
}

/// An LSTM that returns its final hidden state, with the four gates fused (`[d_in, 4h]` and
/// `[h, 4h]` weights; burn's `Lstm` keeps eight matrices and writes every step's output). Same
/// parameters as a PyTorch LSTM (input and hidden weights and biases for the i, f, g, o gates,
/// in that order). On `flex` it runs as one fused op with a hand-written backward
/// ([`crate::lstm_kernel`]).
#[derive(Module, Debug)]
pub struct FusedLstm {
    /// `d_in → 4h`
    pub input: Linear,
    /// `h → 4h`
    pub hidden: Linear,
    /// Hidden (and cell) state width `h`.
    pub d_hidden: usize,
}

impl FusedLstm {
    /// An LSTM from `d_input` features to a hidden state of width `d_hidden`.
    pub fn init(d_input: usize, d_hidden: usize, device: &Device) -> Self {
        Self {
            input: LinearConfig::new(d_input, 4 * d_hidden).init(device),
            hidden: LinearConfig::new(d_hidden, 4 * d_hidden).init(device),
            d_hidden,
        }
    }

    /// Runs the LSTM from a zero state and returns its last hidden state. On a `flex` device
    /// with `f32` inputs this runs the fused kernel of [`crate::lstm_kernel`]; elsewhere the
    /// tensor-op formulation [`Self::forward_ops`].
    ///
    /// # Shapes
    /// `x: [batch, steps, d_in]` `-> [batch, d_hidden]` (the hidden state after the last step)
    pub fn forward(&self, x: Tensor<3>) -> Tensor<2> {
        if let (Some(b_ih), Some(b_hh)) = (&self.input.bias, &self.hidden.bias)
            && x.dtype() == burn::tensor::DType::F32
            && crate::lstm_kernel::has_fused_lstm(&x.device())
        {
            return crate::lstm_kernel::lstm_last_hidden(
                x,
                self.input.weight.val(),
                b_ih.val(),
                self.hidden.weight.val(),
                b_hh.val(),
            );
        }
        self.forward_ops(x)
    }

    /// The same LSTM from tensor ops (any backend).
    ///
    /// # Shapes
    /// `x: [batch, steps, d_in]` `-> [batch, d_hidden]`
    pub fn forward_ops(&self, x: Tensor<3>) -> Tensor<2> {
        let [n, steps, _] = x.dims();
        let h_width = self.d_hidden;
        let device = x.device();
        let d_in = x.dims()[2];
        let mut h = Tensor::<2>::zeros([n, h_width], &device);
        let mut c = Tensor::<2>::zeros([n, h_width], &device);
        for t in 0..steps {
            // Per step rather than one [n, steps, 4h] product sliced per step: slicing a tracked
            // tensor makes every step's backward allocate a zero gradient of the whole product
            // (the inputs need no gradient, so slicing them is free).
            let x_t = x.clone().narrow(1, t, 1).reshape([n, d_in]);
            let g = self.input.forward(x_t) + self.hidden.forward(h);
            let i = sigmoid(g.clone().narrow(1, 0, h_width));
            let f = sigmoid(g.clone().narrow(1, h_width, h_width));
            let cand = g.clone().narrow(1, 2 * h_width, h_width).tanh();
            let o = sigmoid(g.narrow(1, 3 * h_width, h_width));
            c = f * c + i * cand;
            h = o * c.clone().tanh();
        }
        h
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::TensorData;

    #[test]
    fn masked_max_ignores_invalid_elements() {
        let device = Device::flex();
        let x = Tensor::<3>::from_data(
            TensorData::new(vec![1.0f32, 5.0, 3.0, -2.0, 7.0, 9.0], [2, 3, 1]),
            &device,
        );
        let mask = Tensor::<2>::from_data(
            TensorData::new(vec![1.0f32, 0.0, 1.0, 0.0, 0.0, 0.0], [2, 3]),
            &device,
        );
        let out: Vec<f32> = masked_max(x, mask).into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(out, vec![3.0, 0.0]);
    }

    /// Computing some output columns gives those columns of the whole output.
    #[test]
    fn mlp_columns_are_those_of_the_whole_output() {
        let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let device = Device::flex();
        device.seed(5);
        let mlp = Mlp::init(&[4, 6, 9], &device);
        let x = Tensor::<3>::random([2, 3, 4], burn::tensor::Distribution::Default, &device);
        let whole = mlp.forward(x.clone());
        let want = Tensor::cat(
            vec![whole.clone().narrow(2, 1, 3), whole.narrow(2, 8, 1)],
            2,
        );
        let got = mlp.forward_columns(x, &[1..4, 8..9]);
        assert_eq!(got.dims(), [2, 3, 4]);
        let want: Vec<f32> = want.into_data().try_to_vec().unwrap();
        let got: Vec<f32> = got.into_data().try_to_vec().unwrap();
        for (w, g) in want.iter().zip(&got) {
            assert!((w - g).abs() <= 1e-6 * (1.0 + w.abs()), "{w} vs {g}");
        }
    }

    /// The shared-set path gives what the general one gives for the set expanded to every
    /// row, all valid (for one block and for several), and gradients reach the set.
    #[test]
    fn mcg_on_a_shared_set_matches_the_expanded_set() {
        let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let device = Device::flex().autodiff();
        let grad = |s: &Tensor<2>, out: (Tensor<3>, Tensor<2>)| {
            let loss = out.0.sum() + (out.1 * 0.5).sum();
            s.grad(&loss.backward()).unwrap().reshape([1, 4, 5])
        };
        for blocks in [1, 3] {
            device.seed(11);
            let mcg = Mcg::init(5, 3, 8, blocks, &device);
            let s = Tensor::<2>::random([4, 5], burn::tensor::Distribution::Default, &device)
                .require_grad();
            let c = Tensor::<2>::random([2, 3], burn::tensor::Distribution::Default, &device);
            let expanded = |s: Tensor<2>| s.reshape([1, 4, 5]).expand([2, 4, 5]);
            let ones = Tensor::ones([2, 4], &device);
            let (s_a, c_a) = mcg.forward(expanded(s.clone()), c.clone(), ones.clone());
            let (s_b, c_b) = mcg.forward_shared(s.clone(), c.clone());
            assert_eq!(s_b.dims(), [2, 4, 8]);
            assert_eq!(c_b.dims(), [2, 8]);
            let g_a = grad(&s, mcg.forward(expanded(s.clone()), c.clone(), ones));
            let g_b = grad(&s, mcg.forward_shared(s.clone(), c));
            let pairs = [
                (s_a, s_b),
                (c_a.reshape([2, 1, 8]), c_b.reshape([2, 1, 8])),
                (g_a, g_b),
            ];
            for (a, b) in pairs {
                let a: Vec<f32> = a.into_data().try_to_vec().unwrap();
                let b: Vec<f32> = b.into_data().try_to_vec().unwrap();
                assert!(a.iter().any(|v| v.abs() > 1e-3), "not all zero");
                for (x, y) in a.iter().zip(&b) {
                    assert!(
                        (x - y).abs() <= 1e-5 * (1.0 + x.abs()),
                        "{blocks}: {x} vs {y}"
                    );
                }
            }
        }
    }

    #[test]
    fn mcg_shapes_and_seeded_init() {
        let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let device = Device::flex();
        device.seed(7);
        let mcg = Mcg::init(5, 3, 8, 3, &device);
        let s = Tensor::<3>::ones([2, 4, 5], &device);
        let c = Tensor::<2>::ones([2, 3], &device);
        let mask = Tensor::<2>::ones([2, 4], &device);
        let (s_out, c_out) = mcg.forward(s, c, mask);
        assert_eq!(s_out.dims(), [2, 4, 8]);
        assert_eq!(c_out.dims(), [2, 8]);
        device.seed(7);
        let again = Mcg::init(5, 3, 8, 3, &device);
        let a: Vec<f32> = mcg
            .input_s
            .weight
            .val()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let b: Vec<f32> = again
            .input_s
            .weight
            .val()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn fused_lstm_matches_the_textbook_cell() {
        // The seed is process-wide: hold the lock like every other seeding test.
        let _guard = crate::SEED_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let device = Device::flex();
        device.seed(4);
        let (d_in, h, steps, n) = (3, 2, 4, 2);
        let lstm = FusedLstm::init(d_in, h, &device);
        let xs: Vec<f32> = (0..n * steps * d_in)
            .map(|i| ((i * 7) % 11) as f32 / 5.0 - 1.0)
            .collect();
        let x = Tensor::<3>::from_data(TensorData::new(xs.clone(), [n, steps, d_in]), &device);
        let out: Vec<f32> = lstm.forward(x).into_data().try_to_vec().unwrap();
        let v = |t: Tensor<2>| t.into_data().try_to_vec::<f32>().unwrap();
        let v1 = |t: Tensor<1>| t.into_data().try_to_vec::<f32>().unwrap();
        // burn's Linear weight is [d_in, d_out]: y = x W + b.
        let (wi, bi) = (
            v(lstm.input.weight.val()),
            v1(lstm.input.bias.as_ref().unwrap().val()),
        );
        let (wh, bh) = (
            v(lstm.hidden.weight.val()),
            v1(lstm.hidden.bias.as_ref().unwrap().val()),
        );
        let sig = |z: f32| 1.0 / (1.0 + (-z).exp());
        for b in 0..n {
            let (mut hs, mut cs) = (vec![0.0f32; h], vec![0.0f32; h]);
            for t in 0..steps {
                let xt = &xs[(b * steps + t) * d_in..(b * steps + t + 1) * d_in];
                let gate = |k: usize, j: usize| {
                    let col = k * h + j;
                    let mut z = bi[col] + bh[col];
                    for (d, xv) in xt.iter().enumerate() {
                        z += xv * wi[d * 4 * h + col];
                    }
                    for (d, hv) in hs.iter().enumerate() {
                        z += hv * wh[d * 4 * h + col];
                    }
                    z
                };
                let mut next_h = vec![0.0f32; h];
                for j in 0..h {
                    let (i, f, g, o) = (
                        sig(gate(0, j)),
                        sig(gate(1, j)),
                        gate(2, j).tanh(),
                        sig(gate(3, j)),
                    );
                    cs[j] = f * cs[j] + i * g;
                    next_h[j] = o * cs[j].tanh();
                }
                hs = next_h;
            }
            for j in 0..h {
                assert!((out[b * h + j] - hs[j]).abs() < 1e-5, "{out:?} vs {hs:?}");
            }
        }
    }
}
