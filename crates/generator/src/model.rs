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
    /// ψ is divided by this before the network sees it (the spread of the training labels;
    /// ψ's scale depends on the data and the predictor, from ~0.03 to several m/s).
    #[serde(default = "one")]
    pub psi_scale: f32,
}

fn one() -> f32 {
    1.0
}

impl GeneratorConfig {
    pub fn new(embedding_width: usize) -> Self {
        Self {
            embedding_width,
            psi_width: 32,
            hidden: vec![256, 256],
            future_steps: 80,
            psi_scale: 1.0,
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
            psi_scale: self.psi_scale,
        }
    }
}

/// `g(x, ψ)`: one trajectory of B for a requested courtesy.
#[derive(Module, Debug)]
pub struct Generator {
    pub psi_mlp: Mlp,
    pub decoder: Mlp,
    pub future_steps: usize,
    pub psi_scale: f32,
}

impl Generator {
    /// # Shapes
    /// `embedding: [batch, e]` (B's frozen scene embedding), `psi: [batch]`
    /// `-> [batch, T, 2]` positions in B's frame (metres)
    pub fn forward(&self, embedding: Tensor<2>, psi: Tensor<1>) -> Tensor<3> {
        let [b, _] = embedding.dims();
        let psi = self
            .psi_mlp
            .forward(psi.reshape([b, 1]) / self.psi_scale.max(1e-12));
        let out = self.decoder.forward(Tensor::cat(vec![embedding, psi], 1));
        out.reshape([b, self.future_steps, 2]).cumsum(1)
    }
}
