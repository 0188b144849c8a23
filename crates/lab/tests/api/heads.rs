//! The generator folder through the library: what it records, and the artefacts it refuses.

use scbg_lab::generator;

/// The generator chooses among B's predicted modes and their slowed copies; a generator.json
/// whose mode count is not the predictor's, or one of another format, is refused clearly.
pub(crate) fn generator_heads(predictors: &generator::Predictors, dir: &std::path::Path) {
    let k = predictors.ckpt.model_config.num_modes;
    let default = generator::load_scbg(&dir.join("gen"), None).unwrap();
    assert_eq!(default.checkpoint.generator.modes, k);
    assert_eq!(
        default.checkpoint.generator.mode_slowdowns,
        scbg_generator::DEFAULT_MODE_SLOWDOWNS
    );
    let out = dir.join("gen_refused");
    std::fs::create_dir_all(&out).unwrap();
    for name in [
        generator::GENERATOR_JSON,
        generator::GENERATOR_WEIGHTS,
        generator::RANGE_WEIGHTS,
    ] {
        std::fs::copy(dir.join("gen").join(name), out.join(name)).unwrap();
    }
    let json = out.join(generator::GENERATOR_JSON);
    let text = std::fs::read_to_string(&json).unwrap();
    // generator.json claiming another mode count than the predictor's.
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["generator"]["modes"] = serde_json::json!(k + 1);
    std::fs::write(&json, v.to_string()).unwrap();
    let err = generator::load_scbg(&out, None).unwrap_err();
    assert!(
        scbg::is_invalid_request(&err) && format!("{err:#}").contains(&format!("{} modes", k + 1)),
        "{err:#}"
    );
    // A folder of an earlier format: retrain, says the error.
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["format_version"] = serde_json::json!(generator::GENERATOR_FORMAT_VERSION - 1);
    std::fs::write(&json, v.to_string()).unwrap();
    let err = generator::load_scbg(&out, None).unwrap_err();
    assert!(format!("{err:#}").contains("retrain"), "{err:#}");
}
