//! Fuzzes TFRecord framing, Scenario/tf.Example decoding, Scene validation, the cache record and
//! WOSAC submissions (`entries.rs`).
#![no_main]

#[path = "../entries.rs"]
mod entries;

libfuzzer_sys::fuzz_target!(|data: &[u8]| entries::decode_records(data));
