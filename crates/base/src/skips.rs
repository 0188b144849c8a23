//! What a run left out, counted by reason, as every summary shows it.

use std::collections::BTreeMap;

/// Counts `reasons` (one per thing left out) by reason.
pub fn count_by_reason<'a>(reasons: impl IntoIterator<Item = &'a str>) -> BTreeMap<String, usize> {
    let mut counts = BTreeMap::new();
    for reason in reasons {
        *counts.entry(reason.to_owned()).or_insert(0) += 1;
    }
    counts
}

/// `n × reason; …` in reason order, or `nothing` when nothing was left out.
pub fn by_reason_text(counts: &BTreeMap<String, usize>) -> String {
    if counts.is_empty() {
        return "nothing".into();
    }
    counts
        .iter()
        .map(|(reason, n)| format!("{n} × {reason}"))
        .collect::<Vec<_>>()
        .join("; ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reasons_are_counted_and_listed_in_order() {
        let counts = count_by_reason(["too_short", "no_pair", "too_short"]);
        assert_eq!(counts["too_short"], 2);
        assert_eq!(by_reason_text(&counts), "1 × no_pair; 2 × too_short");
        assert_eq!(by_reason_text(&BTreeMap::new()), "nothing");
    }
}
