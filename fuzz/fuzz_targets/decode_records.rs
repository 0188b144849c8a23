//! Fuzzes TFRecord framing + Scenario/tf.Example decoding + Scene validation + the cache codec.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // As a whole file (framing, format detection, decoding of every record).
    if let Ok(file) = scbg_womd::WomdFile::from_bytes("fuzz", data.to_vec()) {
        for _ in file.scenes() {}
    }
    // As one record's payload, in both formats.
    let _ = scbg_womd::decode_record(data, scbg_womd::Format::Scenario);
    let _ = scbg_womd::decode_record(data, scbg_womd::Format::TfExample);
    // As a prepared-cache record.
    let _ = scbg_features::PreparedScene::decode(data);
});
