//! Fuzzes the Python module's `Scene.from_arrays` inputs, through its Rust side (`entries.rs`).
#![no_main]

#[path = "../entries.rs"]
mod entries;

libfuzzer_sys::fuzz_target!(|data: &[u8]| entries::scene_arrays(data));
