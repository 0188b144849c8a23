//! Rewards r(y_A) of a trajectory in A's frame at the current step (A at the origin, heading +x).

use burn::tensor::Tensor;

/// The reward registry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Reward {
    /// Average speed over the horizon, m/s: mean of |y_t − y_{t−1}| / Δt with y_0 = origin
    /// (the paper's default).
    #[cfg_attr(feature = "clap", value(name = "average_speed"))]
    AverageSpeed,
    /// Average progress along A's initial heading, m/s: x_T / (T·Δt).
    Progress,
}

impl Reward {
    /// Every reward.
    pub const ALL: [Reward; 2] = [Reward::AverageSpeed, Reward::Progress];

    /// The reward's name (`average_speed`, `progress`).
    pub fn name(self) -> &'static str {
        match self {
            Self::AverageSpeed => "average_speed",
            Self::Progress => "progress",
        }
    }

    /// The reward of a name.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|r| r.name() == name)
    }

    /// The reward (m/s) of each of `n` trajectories of positions (metres, A's frame) sampled
    /// every `step_secs` seconds after the current step.
    ///
    /// # Shapes
    /// `xy: [n, T, 2]` `-> [n]`
    pub fn evaluate(self, xy: Tensor<3>, step_secs: f32) -> Tensor<1> {
        let [n, t, _] = xy.dims();
        match self {
            Self::AverageSpeed => scbg_model::loss::average_speed(xy, step_secs),
            Self::Progress => {
                xy.narrow(1, t - 1, 1).narrow(2, 0, 1).reshape([n]) / (t as f32 * step_secs)
            }
        }
    }
}
