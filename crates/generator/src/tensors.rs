//! Small tensor helpers shared by training, evaluation and inference.

use burn::tensor::Tensor;

/// The values of an f32 tensor, row-major, on the host.
pub(crate) fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().expect("f32 tensor")
}

/// `x` `times` times over along dim 0, block after block.
pub(crate) fn repeat_rows(x: Tensor<2>, times: usize) -> Tensor<2> {
    if times == 1 {
        x
    } else {
        Tensor::cat(vec![x; times], 0)
    }
}
