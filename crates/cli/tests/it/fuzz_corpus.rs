//! The fuzz corpus (`fuzz/corpus/<target>/`, every input that ever crashed a target or added
//! coverage, minimised) replayed through the same entry points the fuzz targets call.

use std::time::{Duration, Instant};

#[path = "../../../../fuzz/entries.rs"]
mod entries;

#[test]
fn every_corpus_input_is_answered_without_a_panic_or_a_hang() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus");
    for (name, entry) in entries::TARGETS {
        let dir = root.join(name);
        let mut inputs: Vec<_> = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .map(|e| e.unwrap().path())
            .collect();
        inputs.sort();
        assert!(
            inputs.len() >= 3,
            "{name}: a corpus of {} inputs",
            inputs.len()
        );
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
