//! How to label: the futures of B, the reward and the estimate of E[r(Y_A) | x].

use scbg_features::FollowerRoom;

use crate::{Audience, Reward};

/// How `E[r(Y_A) | x]`, the second term of ψ, is estimated.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum MarginalEstimate {
    /// The predictor's marginal mode (paper eq. 4).
    Direct,
    /// The law of total expectation through the conditional mode:
    /// `E[r(Y_A) | x] = E_{y_B ~ p(y_B | x)} E[r(Y_A) | x, y_B]`, averaged over the sampled
    /// futures of B (falls back to [`MarginalEstimate::Direct`] without samples). The two
    /// modes of one network are not consistent with each other: with `Direct`, ψ carries a
    /// per-scene offset (the conditional mode's bias) that is the same for every y_B. This
    /// estimator removes it, so ψ measures what B's future changes for A relative to B's
    /// plausible behaviours.
    #[default]
    ConditionalAverage,
}

impl MarginalEstimate {
    /// The estimator of a name (`direct`, `conditional-average`).
    pub fn parse(text: &str) -> Option<Self> {
        match text {
            "direct" => Some(Self::Direct),
            "conditional-average" => Some(Self::ConditionalAverage),
            _ => None,
        }
    }

    /// The estimator's name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Direct => "direct",
            Self::ConditionalAverage => "conditional-average",
        }
    }
}

/// How to label: how many futures of B to sample, which reward, and how E[r(Y_A) | x] is
/// estimated.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LabelOptions {
    /// Futures sampled from B's marginal prediction per pair role (M).
    pub samples: usize,
    /// The reward r(y_A).
    pub reward: Reward,
    /// How E[r(Y_A) | x] is estimated.
    pub marginal: MarginalEstimate,
    /// Whose reward counts: A alone (the paper, the default) or B's neighbours.
    #[serde(default)]
    pub audience: Audience,
    /// More futures of B sampled for [`MarginalEstimate::ConditionalAverage`]: E[r(Y_A) | x]
    /// averages the conditional expectations over `samples + baseline_samples` futures, of
    /// which only the first `samples` are labelled and kept unless
    /// [`LabelOptions::keep_baseline`] keeps them all. The estimate's noise is the same
    /// for every future of a role but not across roles, so it blurs how ψ ranks scenes (with 8
    /// futures against 32 the demo's labels ranked held-out logged futures like the oracle at
    /// 0.685 against 0.712 over four data seeds; docs/findings.md, *Sampled futures for the
    /// mean*). 0 (the default of a serialised config without the field) averages over the
    /// labelled futures only.
    #[serde(default)]
    pub baseline_samples: usize,
    /// Above 0: each labelled sampled future of B ([`LabelOptions::labelled_samples`]) that
    /// drifts off B's lane path (1–5 m
    /// at the horizon) also joins the labelled futures with its lane move completed within
    /// this many steps along that path ([`scbg_features::lane_move`]), after the sampled ones,
    /// if it leaves A room where it enters A's lane ([`scbg_features::leaves_room`], A driving
    /// on at its current velocity). A predictor's samples of a lane change are often half a lane over, where A still has B
    /// ahead; the completed move is the courteous one, and a generator that chooses among
    /// completed moves ([`scbg_features::lane_move`] again) needs such labelled targets to
    /// learn when to pick them. They are not samples of B's marginal, so they never enter
    /// E[r(Y_A) | x]. Needs B's lane path ([`scbg_features::FeatureConfig::lane_path`]); none
    /// without one. 0 (the default, and every config serialised before the option): none.
    #[serde(default)]
    pub lane_move_steps: usize,
    /// Label and keep the `baseline_samples` futures too, after the `samples` sampled ones
    /// (and take lane moves from all of them): the futures E[r(Y_A) | x] already scores
    /// become candidates of sample and rank (their own ψ costs no extra forward; their lane
    /// moves add rows to it, about 5 per role against 1.3 on the demo). The generator and range
    /// predictor still train on the first `samples` alone. `false` (the default of a
    /// serialised config without the field): the baseline's futures are scored for E[r(Y_A)
    /// | x] and dropped.
    #[serde(default)]
    pub keep_baseline: bool,
    /// What a lane move ([`LabelOptions::lane_move_steps`]) may ask of A when it enters A's
    /// lane ([`scbg_features::leaves_room`]). `scbg label` and the demo take
    /// [`FollowerRoom::HARD_BRAKING`]: MOBIL's polite limit ([`FollowerRoom::MOBIL_SAFE`], the
    /// default of a serialised config without the field) drops the boldest cut-ins, which are
    /// the discourteous end of what B does (docs/findings.md, *How much braking a lane move
    /// may ask of A*).
    #[serde(default = "mobil_safe")]
    pub lane_move_room: FollowerRoom,
}

fn mobil_safe() -> FollowerRoom {
    FollowerRoom::MOBIL_SAFE
}

impl LabelOptions {
    /// The futures of B drawn for E[r(Y_A) | x] alone: `baseline_samples` with
    /// [`MarginalEstimate::ConditionalAverage`], none with the direct estimate (it uses none).
    pub fn baseline_futures(&self) -> usize {
        match self.marginal {
            MarginalEstimate::ConditionalAverage => self.baseline_samples,
            MarginalEstimate::Direct => 0,
        }
    }

    /// The sampled futures of B labelled and kept per role (rows `1..=` this of a role's
    /// labels; the lane moves follow): `samples`, and the baseline's futures with
    /// [`LabelOptions::keep_baseline`].
    pub fn labelled_samples(&self) -> usize {
        self.samples
            + if self.keep_baseline {
                self.baseline_futures()
            } else {
                0
            }
    }
}
