//! The scene families and their names.

/// The scene families.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Family {
    /// On-ramp merge into A's highway lane.
    Merge,
    /// Unprotected crossing at a stop-controlled intersection.
    Crossing,
    /// Lane change / cut-in on a two-lane road.
    Cutin,
    /// B leading A in A's lane on a procedural road.
    Following,
    /// B on the main lane letting A in from an on-ramp.
    Letin,
    /// A and B meeting at a roundabout's entry, one circulating, one entering.
    Roundabout,
    /// B, oncoming on A's road, turning left across A's lane into a side road.
    Leftturn,
    /// B in the through lane at a lane drop letting A, whose lane ends, in.
    Zipper,
}

impl Family {
    /// Every family.
    pub const ALL: [Family; 8] = [
        Family::Merge,
        Family::Crossing,
        Family::Cutin,
        Family::Following,
        Family::Letin,
        Family::Roundabout,
        Family::Leftturn,
        Family::Zipper,
    ];

    /// The families of the default world (the demo's and `scbg synth`'s unless told): every
    /// family but the left turn and the zipper, which are drawn only when asked for (`--families`, or a
    /// config's `[data] families`), e.g. to measure transfer to it (`docs/transfer.toml`).
    pub const DEFAULT: [Family; 6] = [
        Family::Merge,
        Family::Crossing,
        Family::Cutin,
        Family::Following,
        Family::Letin,
        Family::Roundabout,
    ];

    /// The family's name (`merge`, `crossing`, `cutin`, `following`, `letin`, `roundabout`,
    /// `leftturn`, `zipper`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Merge => "merge",
            Self::Crossing => "crossing",
            Self::Cutin => "cutin",
            Self::Following => "following",
            Self::Letin => "letin",
            Self::Roundabout => "roundabout",
            Self::Leftturn => "leftturn",
            Self::Zipper => "zipper",
        }
    }

    /// The family of a name.
    pub fn parse(name: &str) -> Result<Self, UnknownFamily> {
        Self::ALL
            .into_iter()
            .find(|f| f.name() == name.trim())
            .ok_or_else(|| UnknownFamily(name.to_string()))
    }
}

/// A family name that is not `merge`, `crossing`, `cutin`, `following`, `letin`,
/// `roundabout`, `leftturn` or `zipper` (holds the name given).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown scene family {0:?} (expected merge, crossing, cutin, following, letin, roundabout, leftturn or zipper)"
)]
pub struct UnknownFamily(pub String);
