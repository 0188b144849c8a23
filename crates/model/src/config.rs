//! Model configuration and the `paper` / `cpu-small` presets.

use serde::{Deserialize, Serialize};

/// The named model sizes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Preset {
    /// The paper's widths ([`MultipathConfig::paper`]).
    #[serde(rename = "paper")]
    #[cfg_attr(feature = "clap", value(name = "paper"))]
    Paper,
    /// Narrower layers and fewer MCG blocks for a CPU ([`MultipathConfig::cpu_small`]).
    #[serde(rename = "cpu-small")]
    #[cfg_attr(feature = "clap", value(name = "cpu-small"))]
    CpuSmall,
}

impl Preset {
    /// Every preset.
    pub const ALL: [Preset; 2] = [Preset::CpuSmall, Preset::Paper];

    /// The preset's name (`paper`, `cpu-small`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Paper => "paper",
            Self::CpuSmall => "cpu-small",
        }
    }

    /// Its configuration.
    pub fn config(self) -> MultipathConfig {
        match self {
            Self::Paper => MultipathConfig::paper(),
            Self::CpuSmall => MultipathConfig::cpu_small(),
        }
    }
}

impl std::str::FromStr for Preset {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| format!("unknown preset {s:?} (paper, cpu-small)"))
    }
}

/// Multipath++ widths (`shared/spec/multipathpp.md`). `paper` is the full-size model;
/// `cpu-small` keeps the structure with narrower layers and fewer MCG blocks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MultipathConfig {
    /// History steps per agent, the current one included (11: the current step and 1 s before
    /// it, at 10 Hz).
    pub history_steps: usize,
    /// Predicted future steps (80 = 8 s at 10 Hz).
    pub future_steps: usize,
    /// Hidden width of each of the two history LSTMs.
    pub lstm_hidden: usize,
    /// Per-step MLP widths ending at the history MCG width (paper: 32, 64, 128).
    pub step_mlp: Vec<usize>,
    /// Target-agent MCG width (paper: 256; equals 2·lstm_hidden + history MCG width).
    pub target_width: usize,
    /// Interaction MCG width over the other agents' history encodings (paper: 256).
    pub interaction_width: usize,
    /// Road MLP widths ending at the road MCG width (paper: 32, 64, 128).
    pub road_mlp: Vec<usize>,
    /// Hidden width of the road-context MLP (paper: 256).
    pub road_context_hidden: usize,
    /// Width of the decoder MCG over the learned anchors (paper: 640).
    pub decoder_width: usize,
    /// Hidden width of the decoder's output MLP (paper: 512).
    pub decoder_hidden: usize,
    /// Number of mixture modes K, one learned anchor each (paper: 6).
    pub num_modes: usize,
    /// CG blocks per MCG (paper: 5).
    pub mcg_blocks: usize,
    /// Hidden width of the conditional future encoder.
    pub future_hidden: usize,
    /// Whether the future encoder also sees each conditioning point in the target's lane frame
    /// (arc length along and offset from its lane path; see `FutureEncoder`). Off in the
    /// presets (docs/findings.md, *B's future in A's lane frame*: it lifts the labels' fidelity
    /// on sampled futures but made one of three predictor trainings ignore B in two families);
    /// a checkpoint written before it existed reads as off.
    #[serde(default)]
    pub lane_frame_condition: bool,
    /// Whether the conditioning future acts step by step on the decoder (interventional, see
    /// `StepwiseCondition`: the target's displacements in each 0.5 s block react only to the
    /// other agent's future up to the block's start) instead of through one fused vector (the
    /// CBP default). Off in the presets; a checkpoint written before it existed reads as off.
    #[serde(default)]
    pub stepwise_condition: bool,
}

impl MultipathConfig {
    /// The full-size model of the paper (`paper` preset).
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
            lane_frame_condition: false,
            stepwise_condition: false,
        }
    }

    /// The same structure with narrower layers and 2 MCG blocks (`cpu-small` preset), small
    /// enough to train on a CPU.
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
            lane_frame_condition: false,
            stepwise_condition: false,
        }
    }

    /// A preset by name: `paper` or `cpu-small`.
    pub fn preset(name: &str) -> Option<Self> {
        name.parse::<Preset>().ok().map(Preset::config)
    }

    /// Number of parameters of a model with this configuration.
    pub fn num_params(&self) -> usize {
        use burn::module::Module;
        self.init(&crate::device::parameter_count_device())
            .num_params()
    }

    /// Width of the history MCG (the last of [`Self::step_mlp`]).
    pub fn history_width(&self) -> usize {
        *self.step_mlp.last().expect("step_mlp is not empty")
    }

    /// Width of the road MCG (the last of [`Self::road_mlp`]).
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The lane frame is an option: off in the presets and in a configuration written before
    /// the key existed (an older checkpoint, whose weights must still load), 3 more features
    /// per conditioning point when on.
    #[test]
    fn the_lane_frame_is_an_option_off_in_presets_and_older_configs() {
        assert!(!MultipathConfig::paper().lane_frame_condition);
        assert!(!MultipathConfig::cpu_small().lane_frame_condition);
        let on = MultipathConfig {
            lane_frame_condition: true,
            ..MultipathConfig::cpu_small()
        };
        let mut json = serde_json::to_value(&on).unwrap();
        json.as_object_mut().unwrap().remove("lane_frame_condition");
        let old: MultipathConfig = serde_json::from_value(json).unwrap();
        assert!(!old.lane_frame_condition);
        let device = crate::device::parameter_count_device();
        let (new, old) = (on.init(&device), old.init(&device));
        assert_eq!(
            (
                new.future_encoder.point_features,
                old.future_encoder.point_features
            ),
            (8, 5)
        );
    }
}
