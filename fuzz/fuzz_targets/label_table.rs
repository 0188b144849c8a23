//! Fuzzes the label table (Parquet) reader (`entries.rs`). The reader turns a panic inside
//! the Parquet, Arrow or Snappy crates into an error naming the file; any other panic aborts.
#![no_main]

#[path = "../entries.rs"]
mod entries;

libfuzzer_sys::fuzz_target!(
    init: entries::unwind_panics_inside(&["/parquet-", "/arrow-", "/snap-"]),
    |data: &[u8]| entries::label_table(data)
);
