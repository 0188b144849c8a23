//! The generator heads through the library.

use scbg::choices::{Courtesy, Variant};
use scbg::{Quiet, generate};
use scbg_lab::{generator, synth};

/// The generator heads: the default one chooses among B's predicted modes (the model above);
/// the regression head is trained, saved, loaded and driven the same way; a generator.json
/// whose mode count is not the predictor's is refused.
pub(crate) fn generator_heads(
    predictors: &generator::Predictors,
    examples: &[scbg_generator::Example],
    options: scbg_courtesy::label::LabelOptions,
    scene: &scbg_scene::Scene,
    t: &synth::GroundTruth,
    dir: &std::path::Path,
) {
    let k = predictors.ckpt.model_config.num_modes;
    let default = generator::load_scbg(&dir.join("gen"), None).unwrap();
    assert_eq!(default.checkpoint.generator.modes, k);
    assert!(default.scbg.generator.selects_modes());
    let out = dir.join("gen_regression");
    generator::train_variant(
        predictors,
        examples,
        &generator::VariantSettings {
            epochs: 1,
            batch_size: 8,
            range_steps: 10,
            select_modes: false,
            ..generator::VariantSettings::new(Variant::Full, options)
        },
        &out,
        &Quiet,
    )
    .unwrap();
    let model = generator::load_scbg(&out, None).unwrap();
    assert_eq!(model.checkpoint.generator.modes, 0);
    assert!(!model.scbg.generator.selects_modes());
    let got = generate::generate(
        &model,
        scene,
        t.a_id,
        t.b_id,
        &[
            Courtesy::quantile(0.1).unwrap(),
            Courtesy::quantile(0.9).unwrap(),
        ],
    )
    .unwrap();
    // (A regression trained one epoch from its random initialisation can start metres off:
    // the frames are checked on the default model above.)
    for traj in &got.trajectories {
        assert_eq!(traj.world_xy_m.len(), 80);
        assert!(traj.world_xy_m.iter().flatten().all(|v| v.is_finite()));
    }
    // generator.json claiming another mode count than the predictor's: a clear refusal.
    let json = out.join(generator::GENERATOR_JSON);
    let text = std::fs::read_to_string(&json).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["generator"]["modes"] = serde_json::json!(k + 1);
    std::fs::write(&json, v.to_string()).unwrap();
    let err = generator::load_scbg(&out, None).unwrap_err();
    assert!(
        scbg::is_invalid_request(&err) && format!("{err:#}").contains(&format!("{} modes", k + 1)),
        "{err:#}"
    );
}
