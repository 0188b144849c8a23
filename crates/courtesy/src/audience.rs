//! Whose reward B's courtesy counts: the paper's one agent A, or every vehicle near B.
//!
//! With [`Audience::Neighbours`], ψ of a future `y_B` is a weighted sum over B's *audience*
//! `N(B)`: A (the pair's other member, always counted) and every other vehicle valid at the
//! window's current step within `radius_m` of B (nearest first, at most
//! [`MAX_NEIGHBOURS`] besides A):
//!
//! `ψ_N(y_B) = Σ_{j ∈ N(B)} w_j · (E[r(Y_j) | x, y_B] − E[r(Y_j) | x])`
//!
//! with `w_j = 1` ([`Weighting::Sum`]: the total change of the neighbours' rewards) or
//! `w_j = 1 / (1 + d_j / radius_m)` ([`Weighting::Proximity`], `d_j` the distance from B at the
//! current step: 1 next to B, ½ at the radius). Each term is the paper's ψ toward one agent,
//! computed through the same frozen predictor and estimator, so `ψ_N` stays differentiable
//! in `y_B`. [`Audience::Pair`] (the default) is the paper's ψ toward A alone.

use scbg_features::{PreparedScene, Window};
use scbg_scene::ObjectType;

/// Most neighbours counted besides A (nearest first): bounds the labelling and training cost,
/// which grow with the audience (one conditional forward per member and future).
pub const MAX_NEIGHBOURS: usize = 7;

/// How the audience's terms are weighted.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Weighting {
    /// Every member counts fully: ψ is the total change of the audience's rewards.
    #[default]
    Sum,
    /// `w = 1 / (1 + d / radius)`: nearer members count more.
    Proximity,
}

/// Whose reward B's courtesy counts.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum Audience {
    /// A alone (the paper).
    #[default]
    Pair,
    /// A and every vehicle within `radius_m` of B at the current step.
    Neighbours {
        /// Radius around B's current position, metres.
        radius_m: f32,
        /// How the members' terms are weighted.
        weighting: Weighting,
    },
}

impl Audience {
    /// The audience of `--audience pair|neighbours` with its radius and weighting; `None`
    /// with a reason for a bad radius or name.
    pub fn parse(kind: &str, radius_m: f32, weighting: Weighting) -> Result<Self, String> {
        match kind {
            "pair" => Ok(Self::Pair),
            "neighbours" | "neighbors" => {
                if radius_m.is_finite() && radius_m > 0.0 {
                    Ok(Self::Neighbours {
                        radius_m,
                        weighting,
                    })
                } else {
                    Err(format!(
                        "audience radius {radius_m} m: expected a finite number > 0"
                    ))
                }
            }
            _ => Err(format!("audience {kind:?}: expected pair or neighbours")),
        }
    }

    /// A short name: `pair`, or `neighbours <radius> m <weighting>` (e.g. `neighbours 30 m sum`).
    pub fn describe(self) -> String {
        match self {
            Self::Pair => "pair".into(),
            Self::Neighbours {
                radius_m,
                weighting,
            } => format!(
                "neighbours {radius_m} m {}",
                match weighting {
                    Weighting::Sum => "sum",
                    Weighting::Proximity => "proximity",
                }
            ),
        }
    }

    /// A member's weight at `distance_m` from B.
    pub fn weight(self, distance_m: f64) -> f32 {
        match self {
            Self::Pair
            | Self::Neighbours {
                weighting: Weighting::Sum,
                ..
            } => 1.0,
            Self::Neighbours {
                radius_m,
                weighting: Weighting::Proximity,
            } => (1.0 / (1.0 + distance_m / f64::from(radius_m))) as f32,
        }
    }

    /// The members of B's audience besides A, as `(track index, distance from B in metres)`,
    /// nearest first: vehicles other than A and B, valid at the window's current step, within
    /// the radius; at most [`MAX_NEIGHBOURS`]. Empty for [`Audience::Pair`] or when B is not
    /// valid now.
    pub fn others(
        self,
        scene: &PreparedScene,
        window: &Window,
        a: usize,
        b: usize,
    ) -> Vec<(usize, f64)> {
        let Self::Neighbours { radius_m, .. } = self else {
            return Vec::new();
        };
        let now = window.current_step;
        let Some(tb) = scene.tracks.get(b).filter(|t| t.valid_at(now as isize)) else {
            return Vec::new();
        };
        let mut near: Vec<(usize, f64)> = scene
            .tracks
            .iter()
            .enumerate()
            .filter(|&(j, t)| {
                j != a && j != b && t.object_type == ObjectType::Vehicle && t.valid_at(now as isize)
            })
            .map(|(j, t)| (j, distance_m(t, tb, now)))
            .filter(|&(_, d)| d <= f64::from(radius_m))
            .collect();
        near.sort_by(|x, y| x.1.total_cmp(&y.1).then(x.0.cmp(&y.0)));
        near.truncate(MAX_NEIGHBOURS);
        near
    }

    /// A's distance from B at the window's current step (for its weight).
    pub fn distance_between(scene: &PreparedScene, window: &Window, a: usize, b: usize) -> f64 {
        distance_m(&scene.tracks[a], &scene.tracks[b], window.current_step)
    }
}

fn distance_m(
    p: &scbg_features::PreparedTrack,
    q: &scbg_features::PreparedTrack,
    step: usize,
) -> f64 {
    f64::from(p.x_m[step] - q.x_m[step]).hypot(f64::from(p.y_m[step] - q.y_m[step]))
}
