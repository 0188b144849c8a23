//! Fuzzes the HTTP server's request bodies and the scenario upload decoder (`entries.rs`).
#![no_main]

#[path = "../entries.rs"]
mod entries;

libfuzzer_sys::fuzz_target!(|data: &[u8]| entries::serve_requests(data));
