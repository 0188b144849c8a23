//! Model configuration and the `paper` / `cpu-small` presets.

use serde::{Deserialize, Serialize};

/// Multipath++ widths (`shared/spec/multipathpp.md`). `paper` is the full-size model;
/// `cpu-small` keeps the structure with narrower layers and fewer MCG blocks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MultipathConfig {
    pub history_steps: usize,
    pub future_steps: usize,
    /// Hidden width of each of the two history LSTMs.
    pub lstm_hidden: usize,
    /// Per-step MLP widths ending at the history MCG width (paper: 32, 64, 128).
    pub step_mlp: Vec<usize>,
    /// Target-agent MCG width (paper: 256; equals 2·lstm_hidden + history MCG width).
    pub target_width: usize,
    pub interaction_width: usize,
    /// Road MLP widths ending at the road MCG width (paper: 32, 64, 128).
    pub road_mlp: Vec<usize>,
    /// Hidden width of the road-context MLP (paper: 256).
    pub road_context_hidden: usize,
    pub decoder_width: usize,
    pub decoder_hidden: usize,
    pub num_modes: usize,
    /// CG blocks per MCG (paper: 5).
    pub mcg_blocks: usize,
    /// Hidden width of the conditional future encoder.
    pub future_hidden: usize,
}

impl MultipathConfig {
    pub fn paper() -> Self {
        Self {
            history_steps: 11,
            future_steps: 80,
            lstm_hidden: 64,
            step_mlp: vec![32, 64, 128],
            target_width: 256,
            interaction_width: 256,
            road_mlp: vec![32, 64, 128],
            road_context_hidden: 256,
            decoder_width: 640,
            decoder_hidden: 512,
            num_modes: 6,
            mcg_blocks: 5,
            future_hidden: 256,
        }
    }

    pub fn cpu_small() -> Self {
        Self {
            history_steps: 11,
            future_steps: 80,
            lstm_hidden: 16,
            step_mlp: vec![16, 32],
            target_width: 64,
            interaction_width: 64,
            road_mlp: vec![16, 32],
            road_context_hidden: 64,
            decoder_width: 160,
            decoder_hidden: 128,
            num_modes: 6,
            mcg_blocks: 2,
            future_hidden: 64,
        }
    }

    /// A preset by name: `paper` or `cpu-small`.
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "paper" => Some(Self::paper()),
            "cpu-small" => Some(Self::cpu_small()),
            _ => None,
        }
    }

    pub fn history_width(&self) -> usize {
        *self.step_mlp.last().expect("step_mlp is not empty")
    }

    pub fn road_width(&self) -> usize {
        *self.road_mlp.last().expect("road_mlp is not empty")
    }

    /// Width of the scene embedding: target + interaction + road.
    pub fn embedding_width(&self) -> usize {
        self.target_width + self.interaction_width + self.road_width()
    }

    /// Per-mode decoder output: x, y and (a, b, c) per future step, plus one logit.
    pub fn mode_outputs(&self) -> usize {
        self.future_steps * 5 + 1
    }
}
