//! What each fuzz target feeds its input to. The fuzz targets (`fuzz_targets/`) call these,
//! and `cargo test` replays the committed corpus (`corpus/<target>/`) and every input that
//! ever crashed or hung a target (`regressions/<target>/`) through the same functions, so each
//! is checked on every build.
//!
//! Every entry must return normally for any input: an error is a fine answer, a panic, an
//! abort or a hang is a bug.

#![allow(dead_code)]

use std::path::Path;

/// A fuzz target's entry: takes any bytes, returns normally.
pub type Entry = fn(&[u8]);

/// The targets, by name (the folder names under `corpus/`).
pub const TARGETS: [(&str, Entry); 6] = [
    ("decode_records", decode_records),
    ("serve_requests", serve_requests),
    ("configs", configs),
    ("artefacts", artefacts),
    ("label_table", label_table),
    ("scene_arrays", scene_arrays),
];

/// TFRecord framing, format detection, Scenario and tf.Example decoding, Scene validation, the
/// cache record, and a WOSAC submission.
pub fn decode_records(data: &[u8]) {
    // As a whole file (framing, format detection, decoding of every record).
    if let Ok(file) = scbg_womd::WomdFile::from_bytes("fuzz", data.to_vec()) {
        for _ in file.scenes() {}
    }
    // As one record's payload, in both formats, and as a submission.
    let _ = scbg_womd::decode_record(data, scbg_womd::Format::Scenario);
    let _ = scbg_womd::decode_record(data, scbg_womd::Format::TfExample);
    let _ = scbg_womd::wosac::decode_submission(data);
    // As a prepared-cache record.
    let _ = scbg_features::PreparedScene::decode(data);
}

/// Every JSON body of the server (with the checks the handlers make before any inference) and
/// the scenario upload decoder.
pub fn serve_requests(data: &[u8]) {
    use scbg_serve::api::{
        CourtesyAsk, CourtesyRequest, CreateSession, GenerateRequest, OpenScenario, StepRequest,
    };
    if let Ok(r) = serde_json::from_slice::<GenerateRequest>(data) {
        let _ = CourtesyAsk {
            quantile: r.quantile,
            psi: r.psi,
        }
        .to_courtesy();
    }
    let _ = serde_json::from_slice::<CourtesyRequest>(data);
    if let Ok(s) = serde_json::from_slice::<CreateSession>(data) {
        for c in &s.controlled {
            let _ = CourtesyAsk {
                quantile: c.quantile,
                psi: c.psi,
            }
            .to_courtesy();
        }
    }
    let _ = serde_json::from_slice::<StepRequest>(data);
    if let Ok(o) = serde_json::from_slice::<OpenScenario>(data) {
        let _ = Path::new(&o.file).components().count();
    }
    // The upload path: a TFRecord file or one bare Scenario message.
    let _ = scbg::data::scenes_from_bytes(data.to_vec());
}

/// The training TOML (`scbg train predictor --config`) and the pipeline settings
/// (`--config` of the other stages), with their checks.
pub fn configs(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(config) = scbg_train::TrainConfig::from_toml(text)
        && config.validate().is_ok()
    {
        let _ = config.model_config();
    }
    if let Ok(settings) = scbg_lab::config::PipelineConfig::from_toml(text) {
        let _ = settings.label_options();
    }
}

/// `checkpoint.json` and `generator.json`, as the loaders read them.
pub fn artefacts(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let _ = scbg_train::checkpoint::Checkpoint::from_json(text, Path::new("checkpoint.json"));
    let _ = scbg::model::GeneratorCheckpoint::from_json(text, Path::new("generator.json"));
}

/// Lets panics raised inside the crates named (by a piece of their source path, such as
/// `"/parquet-"`) unwind, and aborts on every other. libFuzzer's own hook aborts on any panic,
/// even one the code under test catches, so a target whose entry catches a dependency's
/// panics by design installs this once to keep fuzzing past them.
pub fn unwind_panics_inside(crates: &'static [&'static str]) {
    let abort = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let inside = info
            .location()
            .is_some_and(|at| crates.iter().any(|c| at.file().contains(c)));
        if !inside {
            abort(info);
        }
    }));
}

/// A label table (Parquet) as `scbg label` reads its finished shards back.
pub fn label_table(data: &[u8]) {
    let _ = scbg_lab::labels::label_table_from_bytes(data.to_vec(), Path::new("labels.parquet"));
}

/// The arrays of the Python module's `Scene.from_arrays` (any shape, NaN, Inf, huge values),
/// through the Rust side it calls, then the features every model input starts from.
pub fn scene_arrays(data: &[u8]) {
    let mut input = Bytes(data);
    let agents = usize::from(input.byte() % 6);
    let steps = usize::from(input.byte() % 96);
    let mut arrays = scbg::SceneArrays {
        scenario_id: "fuzz".into(),
        current_step: usize::from(input.byte()),
        ..Default::default()
    };
    for _ in 0..agents {
        arrays.ids.push(i64::from(input.byte() as i8));
        arrays.states.push(
            (0..steps)
                .map(|_| std::array::from_fn(|_| input.f64()))
                .collect(),
        );
        arrays
            .valid
            .push((0..steps).map(|_| input.byte() % 4 != 0).collect());
    }
    if input.byte() % 2 == 0 {
        let names = ["vehicle", "pedestrian", "cyclist", "other", "unset", "bus"];
        arrays.object_types = Some(
            (0..agents + usize::from(input.byte() % 2))
                .map(|_| names[usize::from(input.byte()) % names.len()].to_string())
                .collect(),
        );
    }
    if input.byte() % 2 == 0 {
        arrays.sdc_id = Some(i64::from(input.byte() as i8));
    }
    arrays.objects_of_interest = (0..input.byte() % 3)
        .map(|_| i64::from(input.byte() as i8))
        .collect();
    for polylines in [
        &mut arrays.lanes,
        &mut arrays.road_edges,
        &mut arrays.road_lines,
    ] {
        for _ in 0..input.byte() % 4 {
            let points = usize::from(input.byte() % 12);
            polylines.push((0..points).map(|_| [input.f64(), input.f64()]).collect());
        }
    }
    if input.byte() % 2 == 0 {
        let names = [
            "freeway",
            "surface_street",
            "bike_lane",
            "undefined",
            "river",
        ];
        arrays.lane_types = Some(
            (0..arrays.lanes.len())
                .map(|_| names[usize::from(input.byte()) % names.len()].to_string())
                .collect(),
        );
    }
    let Ok(scene) = arrays.build() else {
        return;
    };
    let _ = scbg_features::PreparedScene::from_scene(
        &scene,
        &scbg_features::WindowConfig::default(),
        &scbg_features::PairConfig::default(),
        scbg::ROAD_SUBSAMPLE,
    );
}

/// Reads the fuzz input front to back; zeros once it runs out.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn byte(&mut self) -> u8 {
        match self.0.split_first() {
            Some((b, rest)) => {
                self.0 = rest;
                *b
            }
            None => 0,
        }
    }

    /// A coordinate: mostly ordinary metres, sometimes NaN, ±Inf, huge or subnormal.
    fn f64(&mut self) -> f64 {
        match self.byte() {
            0 => f64::NAN,
            1 => f64::INFINITY,
            2 => f64::NEG_INFINITY,
            3 => f64::from_le_bytes(std::array::from_fn(|_| self.byte())),
            4 => 1e300,
            _ => f64::from(i16::from_le_bytes([self.byte(), self.byte()])) / 16.0,
        }
    }
}
