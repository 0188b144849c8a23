//! What a caller asks of a generated future of B: a [`Courtesy`], and the [`Policy`] that
//! turns it into the future.

/// The courtesy asked of a generated future. The generator takes it as given: the runtime's
/// `scbg::Courtesy` is the checked form a front end makes (a quantile in [0, 1], a finite ψ).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Courtesy {
    /// A quantile in [0, 1] of the predicted range (0.1 and 0.9 are its ends).
    Quantile(f32),
    /// An explicit ψ (m/s for the default reward).
    Psi(f32),
}

/// How a [`Scbg`](crate::Scbg) turns a requested courtesy into B's future.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Policy {
    /// The learned generator g(x, ψ) (the paper).
    #[default]
    Generator,
    /// Sample and rank: B's sampled future whose ψ label has the requested rank, or is nearest
    /// the requested ψ (no generator).
    Ranked,
}

impl Policy {
    /// Both policies.
    pub const ALL: [Policy; 2] = [Policy::Generator, Policy::Ranked];

    /// The policy's name (`generator`, `ranked`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Generator => "generator",
            Self::Ranked => "ranked",
        }
    }
}

impl std::str::FromStr for Policy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| format!("unknown policy {s:?} (generator or ranked)"))
    }
}
