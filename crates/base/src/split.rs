//! The scenario-id marks that decide a scene's split, shared by the synthetic world (which
//! writes them) and training (which reads them).

/// Ends the id of a scene from a *held-out* family (before any `~` sibling mark): the scene is
/// never trained on, only evaluated, whatever the hash split says — how a run measures
/// transfer to a situation and road it has not seen.
pub const HELD_OUT_MARK: &str = "+unseen";

/// A variant of a scene (a counterfactual or reaction sibling) appends `~…` to the scene's id
/// and shares its split: the part of an id before the first `~`.
pub fn base_id(scenario_id: &str) -> &str {
    scenario_id.split('~').next().unwrap_or(scenario_id)
}

/// Whether a scene (or a variant of it) belongs to a held-out family.
pub fn is_held_out(scenario_id: &str) -> bool {
    base_id(scenario_id).ends_with(HELD_OUT_MARK)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn marks() {
        assert!(is_held_out("synth-0-0000007+unseen"));
        assert!(is_held_out("synth-0-0000007+unseen~cf2"));
        assert!(!is_held_out("synth-0-0000007"));
        assert!(!is_held_out("synth-0-0000007~cf2+unseen"));
        assert_eq!(base_id("a~b~c"), "a");
    }
}
