//! A front end written against the library alone (no binary): synthetic data → cache →
//! predictor → labels → a tiny generator → generation at a quantile and at a ψ, plus the
//! artefact errors a front end has to show.

mod closed_loop;
mod heads;
mod labelling;
mod real_scenes;

use closed_loop::{closed_loop_through_the_library, ranked_policy_in_the_loop};
use heads::generator_heads;
use labelling::{courtesy_toward_neighbours, ensemble_labels};
use real_scenes::closed_loop_on_every_real_file;
use scbg::choices::{Courtesy, Family, MarginalEstimate, Reward, Variant};
use scbg::{Quiet, generate};
use scbg_lab::{generator, labels, predictor, synth};
/// A tiny predictor config, shared with the CLI tests.
pub(crate) const TINY_CONFIG: &str = include_str!("../tiny_train.toml");

#[test]
fn label_train_and_generate_through_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s);
    synth::write_synthetic(
        &synth::SynthOptions {
            scenarios: 16,
            seed: 12,
            out: p("synth"),
            // The families the tiny model's checks below were set on (the let-in family is
            // checked in `scbg-synth` and by the demo).
            families: vec![
                Family::Merge,
                Family::Crossing,
                Family::Cutin,
                Family::Following,
            ],
            held_out: Vec::new(),
            scenarios_per_file: 8,
            counterfactuals: 0,
        },
        &Quiet,
    )
    .unwrap();
    let truth = synth::read_ground_truth(&p("synth").join(synth::GROUND_TRUTH_FILE)).unwrap();
    assert_eq!(truth.len(), 16);
    let manifest = scbg_lab::prepare::prepare(
        &scbg_lab::prepare::PrepareOptions::new(vec![p("synth").display().to_string()], p("cache")),
        &Quiet,
    )
    .unwrap();
    assert_eq!(manifest.total.scenarios, 16);
    let config = predictor::TrainConfig::from_toml(TINY_CONFIG).unwrap();
    predictor::train_predictor(&p("cache"), &p("model"), &config, false, &Quiet).unwrap();

    // Labels: one row per future, the table reads back, the summary checks the ground truth.
    let options = labels::label_options(2, Reward::AverageSpeed, MarginalEstimate::default());
    let (rows, summary) = labels::label_cache(
        &labels::LabelRun {
            model: p("model"),
            ensemble: vec![],
            data: p("cache"),
            out: p("labels"),
            options,
            seed: 0,
            ground_truth: Some(p("synth").join(synth::GROUND_TRUTH_FILE)),
            shard_index: 0,
            num_shards: 1,
            reaction_siblings: Some((p("reaction"), 2)),
        },
        &Quiet,
    )
    .unwrap();
    assert_eq!(rows.len(), 16 * 2 * 3);
    // Reaction siblings: each ground-truth role's two sampled futures replayed in the world;
    // they read back, and a cache prepared from them holds one per scene and future.
    let t = &truth[3];
    let sibling = format!("{}~rx2", t.scenario_id);
    let (_, scene) = generate::find_scene(
        &p("reaction").join("reaction-00000.tfrecord"),
        Some(&sibling),
        t.a_id,
        t.b_id,
    )
    .unwrap();
    assert_eq!(scene.scenario_id, sibling);
    let siblings = scbg_lab::prepare::prepare(
        &scbg_lab::prepare::PrepareOptions::new(
            vec![p("reaction").display().to_string()],
            p("rx_cache"),
        ),
        &Quiet,
    )
    .unwrap();
    assert_eq!(siblings.total.scenarios, 16 * 2);
    assert!(summary.fidelity.is_some() && summary.fidelity_held_out.is_some());
    assert_eq!(summary.pairs_roles, 32);
    assert_eq!(
        labels::read_label_table(&p("labels").join(labels::shard_table_name(0))).unwrap(),
        rows
    );
    assert!(!summary.spearman_latent.is_empty());
    assert_eq!(summary.predictors, 1);
    ensemble_labels(&rows, options, dir.path());

    // The generator's training labels are the label table's: same path, same stream.
    let predictors = generator::load_predictors(&p("model")).unwrap();
    let examples = generator::examples_for_split(
        &predictors.plain,
        &predictors.ckpt,
        &predictors.plain_device,
        &p("cache"),
        None,
        options,
        0,
        &Quiet,
    )
    .unwrap();
    assert_eq!(examples.len(), 32);
    let first = rows
        .iter()
        .find(|r| r.scenario_id == examples[0].scenario_id && r.sample == 0)
        .unwrap();
    assert_eq!(first.psi, examples[0].psi[0]);
    // Sibling `~rx2` replays the ground-truth role's second sampled future slowed as the
    // generator slows its first copies (factor 0.75): it ends at the slowed future's last
    // point, short of the future's own.
    let e = examples
        .iter()
        .find(|e| e.scenario_id == t.scenario_id && e.b.target_track_id == t.b_id)
        .unwrap();
    let future = scbg_lab::fidelity::world_points(&e.b.world_from_agent, &e.futures_b[2]);
    let origin = e.b.world_from_agent.world_from_agent(0.0, 0.0);
    let slowed = scbg_generator::slowed_future(&future, [origin.0, origin.1], 0.75);
    let b = scene.tracks.iter().find(|k| k.id == t.b_id).unwrap();
    let end = b.states.last().unwrap();
    let off = |p: [f64; 2]| (end.x_m - p[0]).hypot(end.y_m - p[1]);
    let travelled = |p: [f64; 2]| (p[0] - origin.0).hypot(p[1] - origin.1);
    assert!(off(slowed[79]) < 0.5, "{} m", off(slowed[79]));
    assert!(travelled(slowed[79]) < 0.9 * travelled(future[79]));

    let saved = generator::train_variant(
        &predictors,
        &examples,
        &generator::VariantSettings {
            epochs: 1,
            batch_size: 8,
            range_steps: 10,
            ..generator::VariantSettings::new(Variant::Full, options)
        },
        &p("gen"),
        &Quiet,
    )
    .unwrap();
    assert_eq!(saved.format_version, generator::GENERATOR_FORMAT_VERSION);
    // Labelled lane moves after the sampled futures (here stand-ins: each role's first
    // sampled future again, with a ψ far out) are for sample and rank: the generator and
    // range predictor train without them, so its ψ scale (the labels' spread) is unchanged.
    let with_moves: Vec<_> = examples
        .iter()
        .cloned()
        .map(|mut e| {
            e.futures_b.push(e.futures_b[1].clone());
            e.psi.push(e.psi[1] + 50.0);
            e
        })
        .collect();
    let saved_moves = generator::train_variant(
        &predictors,
        &with_moves,
        &generator::VariantSettings {
            epochs: 1,
            batch_size: 8,
            range_steps: 10,
            ..generator::VariantSettings::new(Variant::Full, options)
        },
        &p("gen_moves"),
        &Quiet,
    )
    .unwrap();
    assert_eq!(saved_moves.generator.psi_scale, saved.generator.psi_scale);

    let model = generator::load_scbg(&p("gen"), None).unwrap();
    let file = p("synth").join("synth-00000.tfrecord");
    let t = &truth[0];
    let (_, scene) = generate::find_scene(&file, Some(&t.scenario_id), t.a_id, t.b_id).unwrap();
    let out = generate::generate(
        &model,
        &scene,
        t.a_id,
        t.b_id,
        &[
            Courtesy::quantile(0.1).unwrap(),
            Courtesy::quantile(0.9).unwrap(),
        ],
    )
    .unwrap();
    assert_eq!(out.trajectories.len(), 2);
    assert_eq!(out.trajectories[0].world_xy_m.len(), 80);
    // B's generated future starts near B's current world position.
    let b = scene.track_index(t.b_id).unwrap();
    let now = scene.tracks[b].states[scene.current_step];
    let p0 = out.trajectories[0].world_xy_m[0];
    assert!((p0[0] - now.x_m).hypot(p0[1] - now.y_m) < 10.0, "{p0:?}");
    // An explicit ψ at the predicted 0.9 quantile is the quantile 0.9.
    let high = out.trajectories[1].psi;
    let by_psi = generate::generate(
        &model,
        &scene,
        t.a_id,
        t.b_id,
        &[Courtesy::psi(high).unwrap()],
    )
    .unwrap();
    assert!((by_psi.trajectories[0].quantile - 0.9).abs() < 1e-3);
    assert_eq!(
        by_psi.trajectories[0].world_xy_m,
        out.trajectories[1].world_xy_m
    );

    // Requests that are the caller's fault say so.
    let bad = generate::generate(
        &model,
        &scene,
        t.a_id,
        987_654,
        &[Courtesy::quantile(0.5).unwrap()],
    )
    .unwrap_err();
    assert!(scbg::is_invalid_request(&bad) && format!("{bad:#}").contains("987654"));
    let bad = anyhow::Error::new(Courtesy::quantile(1.5).unwrap_err());
    assert!(scbg::is_invalid_request(&bad) && format!("{bad:#}").contains("1.5"));

    generator_heads(&predictors, dir.path());
    closed_loop_through_the_library(&model, &scene, t, dir.path());
    closed_loop_on_every_real_file(&model);
    ranked_policy_in_the_loop(model, &scene, t);
    courtesy_toward_neighbours(&predictors, &scene, t, dir.path());

    // A predictor folder is not a generator folder; an old generator.json is refused clearly.
    let err = generator::load_scbg(&p("model"), None).unwrap_err();
    assert!(
        format!("{err:#}").contains("predictor checkpoint"),
        "{err:#}"
    );
    let json = p("gen").join(generator::GENERATOR_JSON);
    let mut old: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let obj = old.as_object_mut().unwrap();
    obj.remove("kind");
    obj.remove("format_version");
    std::fs::write(&json, old.to_string()).unwrap();
    let err = generator::load_scbg(&p("gen"), None).unwrap_err();
    assert!(format!("{err:#}").contains("older scbg"), "{err:#}");
}
