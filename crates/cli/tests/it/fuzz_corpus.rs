//! The fuzz corpus (`fuzz/corpus/<target>/`, the inputs that add coverage, minimised) and the
//! regressions (`fuzz/regressions/<target>/`, every input that ever crashed, hung or exhausted
//! the memory of a target, kept as found) replayed through the entry points the targets call.

use std::time::{Duration, Instant};

#[path = "../../../../fuzz/entries.rs"]
mod entries;

#[test]
fn every_corpus_input_is_answered_without_a_panic_or_a_hang() {
    let fuzz = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    for (name, entry) in entries::TARGETS {
        let dir = fuzz.join("corpus").join(name);
        let mut inputs: Vec<_> = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .map(|e| e.unwrap().path())
            .collect();
        assert!(
            inputs.len() >= 3,
            "{name}: a corpus of {} inputs",
            inputs.len()
        );
        if let Ok(found) = std::fs::read_dir(fuzz.join("regressions").join(name)) {
            inputs.extend(found.map(|e| e.unwrap().path()));
        }
        inputs.sort();
        for input in inputs {
            let bytes = std::fs::read(&input).unwrap();
            let started = Instant::now();
            entry(&bytes);
            // The fuzzers' bar is 1 s; a test build on a busy machine gets some slack.
            assert!(
                started.elapsed() < Duration::from_secs(5),
                "{}: {:?}",
                input.display(),
                started.elapsed()
            );
        }
    }
}
