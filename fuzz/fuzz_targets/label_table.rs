//! Fuzzes the label table (Parquet) reader (`entries.rs`).
#![no_main]

#[path = "../entries.rs"]
mod entries;

libfuzzer_sys::fuzz_target!(|data: &[u8]| entries::label_table(data));
