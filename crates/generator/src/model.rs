//! The generator network.

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use scbg_model::blocks::Mlp;
use serde::{Deserialize, Serialize};

/// Widths of the generator decoder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GeneratorConfig {
    /// Width of the predictor's scene embedding (its `embedding_width()`).
    pub embedding_width: usize,
    /// Width of the ψ embedding.
    pub psi_width: usize,
    /// Hidden widths of the decoder MLP.
    pub hidden: Vec<usize>,
    pub future_steps: usize,
}

impl GeneratorConfig {
    pub fn new(embedding_width: usize) -> Self {
        Self {
            embedding_width,
            psi_width: 32,
            hidden: vec![256, 256],
            future_steps: 80,
        }
    }

    pub fn init(&self, device: &Device) -> Generator {
        let mut dims = vec![self.embedding_width + self.psi_width];
        dims.extend(&self.hidden);
        dims.push(2 * self.future_steps);
        Generator {
            psi_mlp: Mlp::init(&[1, self.psi_width, self.psi_width], device),
            decoder: Mlp::init(&dims, device),
            future_steps: self.future_steps,
        }
    }
}

/// `g(x, ψ)`: one trajectory of B for a requested courtesy.
#[derive(Module, Debug)]
pub struct Generator {
    pub psi_mlp: Mlp,
    pub decoder: Mlp,
    pub future_steps: usize,
}

impl Generator {
    /// # Shapes
    /// `embedding: [batch, e]` (B's frozen scene embedding), `psi: [batch]`
    /// `-> [batch, T, 2]` positions in B's frame (metres)
    pub fn forward(&self, embedding: Tensor<2>, psi: Tensor<1>) -> Tensor<3> {
        let [b, _] = embedding.dims();
        let psi = self.psi_mlp.forward(psi.reshape([b, 1]));
        let out = self.decoder.forward(Tensor::cat(vec![embedding, psi], 1));
        out.reshape([b, self.future_steps, 2]).cumsum(1)
    }
}
