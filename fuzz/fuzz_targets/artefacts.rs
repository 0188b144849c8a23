//! Fuzzes `checkpoint.json` and `generator.json` (`entries.rs`).
#![no_main]

#[path = "../entries.rs"]
mod entries;

libfuzzer_sys::fuzz_target!(|data: &[u8]| entries::artefacts(data));
