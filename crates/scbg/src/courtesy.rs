//! A courtesy request, checked once when it is made.

use serde::{Deserialize, Serialize};

use crate::InvalidRequest;

/// The courtesy asked of B toward A: a quantile in [0, 1] of the model's predicted range of ψ
/// (0.1 and 0.9 are its ends), or an explicit ψ (m/s for the default reward, A's average
/// speed).
///
/// Only the constructors make one, and each checks its value, so every function that takes a
/// `Courtesy` trusts it: a front end turns the user's numbers into a `Courtesy` (one check per
/// call) and passes it on. Serialised as the generator's `{"quantile": q}` or `{"psi": p}`;
/// deserialising checks the same way.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(
    into = "scbg_generator::Courtesy",
    try_from = "scbg_generator::Courtesy"
)]
pub struct Courtesy(scbg_generator::Courtesy);

impl Courtesy {
    /// A quantile of the predicted range: finite and in [0, 1].
    pub fn quantile(q: f32) -> Result<Self, InvalidRequest> {
        if (0.0..=1.0).contains(&q) {
            Ok(Self(scbg_generator::Courtesy::Quantile(q)))
        } else {
            Err(InvalidRequest(format!("quantile {q} is outside [0, 1]")))
        }
    }

    /// An explicit ψ: a finite number of at most [`Self::PSI_LIMIT_MPS`] in size.
    pub fn psi(psi: f32) -> Result<Self, InvalidRequest> {
        if !psi.is_finite() {
            Err(InvalidRequest(format!("ψ {psi} is not a finite number")))
        } else if psi.abs() > Self::PSI_LIMIT_MPS {
            Err(InvalidRequest(format!(
                "ψ {psi} is outside [-{0}, {0}] m/s",
                Self::PSI_LIMIT_MPS
            )))
        } else {
            Ok(Self(scbg_generator::Courtesy::Psi(psi)))
        }
    }

    /// The largest |ψ| asked for, m/s. Both rewards are speeds, and B cannot change A's
    /// average speed by more than any car's speed; the predicted ranges span a few m/s.
    pub const PSI_LIMIT_MPS: f32 = 50.0;

    /// Exactly one of a quantile and a ψ, as a request carries them.
    pub fn from_request(quantile: Option<f32>, psi: Option<f32>) -> Result<Self, InvalidRequest> {
        match (quantile, psi) {
            (Some(q), None) => Self::quantile(q),
            (None, Some(p)) => Self::psi(p),
            (Some(_), Some(_)) => Err(InvalidRequest(
                "give either quantile or psi, not both".into(),
            )),
            (None, None) => Err(InvalidRequest("give quantile (in [0, 1]) or psi".into())),
        }
    }

    /// The quantile asked, if one was.
    pub fn as_quantile(self) -> Option<f32> {
        match self.0 {
            scbg_generator::Courtesy::Quantile(q) => Some(q),
            scbg_generator::Courtesy::Psi(_) => None,
        }
    }

    /// The same courtesy with its quantile replaced by `q` (a ψ stays as it is); `q` is
    /// clamped to [0, 1].
    pub fn with_quantile(self, q: f32) -> Self {
        match self.0 {
            scbg_generator::Courtesy::Quantile(_) => {
                Self(scbg_generator::Courtesy::Quantile(if q.is_nan() {
                    0.5
                } else {
                    q.clamp(0.0, 1.0)
                }))
            }
            psi => Self(psi),
        }
    }

    /// The checked request as the generator takes it.
    pub fn get(self) -> scbg_generator::Courtesy {
        self.0
    }
}

impl From<Courtesy> for scbg_generator::Courtesy {
    fn from(c: Courtesy) -> Self {
        c.0
    }
}

impl TryFrom<scbg_generator::Courtesy> for Courtesy {
    type Error = InvalidRequest;
    fn try_from(c: scbg_generator::Courtesy) -> Result<Self, InvalidRequest> {
        match c {
            scbg_generator::Courtesy::Quantile(q) => Self::quantile(q),
            scbg_generator::Courtesy::Psi(p) => Self::psi(p),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_valid_values_make_a_courtesy() {
        assert_eq!(Courtesy::quantile(0.3).unwrap().as_quantile(), Some(0.3));
        assert!(Courtesy::quantile(1.5).is_err());
        assert!(Courtesy::quantile(f32::NAN).is_err());
        assert!(Courtesy::psi(f32::INFINITY).is_err());
        assert!(Courtesy::psi(1e30).is_err());
        assert!(Courtesy::psi(-50.5).is_err());
        assert!(Courtesy::psi(-50.0).is_ok());
        assert_eq!(Courtesy::psi(-2.0).unwrap().as_quantile(), None);
        assert!(Courtesy::from_request(Some(0.5), Some(1.0)).is_err());
        assert!(Courtesy::from_request(None, None).is_err());
        assert_eq!(
            Courtesy::from_request(None, Some(1.0)).unwrap().get(),
            scbg_generator::Courtesy::Psi(1.0)
        );
    }

    #[test]
    fn deserialising_checks_like_the_constructors() {
        let ok: Courtesy = serde_json::from_str(r#"{"quantile":0.9}"#).unwrap();
        assert_eq!(ok.as_quantile(), Some(0.9));
        assert_eq!(serde_json::to_string(&ok).unwrap(), r#"{"quantile":0.9}"#);
        assert!(serde_json::from_str::<Courtesy>(r#"{"quantile":2.0}"#).is_err());
    }

    #[test]
    fn with_quantile_keeps_a_psi_and_clamps() {
        let q = Courtesy::quantile(0.5).unwrap();
        assert_eq!(q.with_quantile(1.2).as_quantile(), Some(1.0));
        let p = Courtesy::psi(0.7).unwrap();
        assert_eq!(p.with_quantile(0.1), p);
    }
}
