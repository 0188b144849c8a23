//! A front end written against the library alone (no binary): synthetic data → cache →
//! predictor → labels → a tiny generator → generation at a quantile and at a ψ, plus the
//! artefact errors a front end has to show.

use scbg::choices::{Courtesy, Family, LabelOptions, MarginalEstimate, Reward, Variant};
use scbg::{Quiet, data, generate, generator, labels, predictor, synth};

/// A tiny predictor config, shared with the CLI tests.
const TINY_CONFIG: &str = include_str!("tiny_train.toml");

#[test]
fn label_train_and_generate_through_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s);
    synth::write_synthetic(
        &synth::SynthOptions {
            scenarios: 16,
            seed: 12,
            out: p("synth"),
            families: Family::ALL.to_vec(),
            scenarios_per_file: 8,
            counterfactuals: 0,
        },
        &Quiet,
    )
    .unwrap();
    let truth = synth::read_ground_truth(&p("synth").join(synth::GROUND_TRUTH_FILE)).unwrap();
    assert_eq!(truth.len(), 16);
    let manifest = data::prepare(
        &data::PrepareOptions::new(vec![p("synth").display().to_string()], p("cache")),
        &Quiet,
    )
    .unwrap();
    assert_eq!(manifest.total.scenarios, 16);
    let config = predictor::TrainConfig::from_toml(TINY_CONFIG).unwrap();
    predictor::train_predictor(&p("cache"), &p("model"), &config, false, &Quiet).unwrap();

    // Labels: one row per future, the table reads back, the summary checks the ground truth.
    let options =
        labels::label_options(2, Reward::AverageSpeed, MarginalEstimate::default(), 1.0).unwrap();
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
    let siblings = data::prepare(
        &data::PrepareOptions::new(vec![p("reaction").display().to_string()], p("rx_cache")),
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
        // The opt-in generator told who A is: trained, saved, loaded and driven below.
        true,
        &Quiet,
    )
    .unwrap();
    assert_eq!(examples.len(), 32);
    assert!(
        examples
            .iter()
            .all(|e| e.a_context.len() == scbg_generator::A_CONTEXT_WIDTH)
    );
    let first = rows
        .iter()
        .find(|r| r.scenario_id == examples[0].scenario_id && r.sample == 0)
        .unwrap();
    assert_eq!(first.psi, examples[0].psi[0]);

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

    let model = generator::load_scbg(&p("gen"), None).unwrap();
    assert_eq!(
        model.checkpoint.generator.a_context_width,
        scbg_generator::A_CONTEXT_WIDTH
    );
    let file = p("synth").join("synth-00000.tfrecord");
    let t = &truth[0];
    let (_, scene) = generate::find_scene(&file, Some(&t.scenario_id), t.a_id, t.b_id).unwrap();
    let out = generate::generate(
        &model,
        &scene,
        t.a_id,
        t.b_id,
        &[Courtesy::Quantile(0.1), Courtesy::Quantile(0.9)],
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
    let by_psi =
        generate::generate(&model, &scene, t.a_id, t.b_id, &[Courtesy::Psi(high)]).unwrap();
    assert!((by_psi.trajectories[0].quantile - 0.9).abs() < 1e-3);
    assert_eq!(
        by_psi.trajectories[0].world_xy_m,
        out.trajectories[1].world_xy_m
    );

    // Requests that are the caller's fault say so.
    let bad = generate::generate(&model, &scene, t.a_id, 987_654, &[Courtesy::Quantile(0.5)])
        .unwrap_err();
    assert!(scbg::is_invalid_request(&bad) && format!("{bad:#}").contains("987654"));
    let bad =
        generate::generate(&model, &scene, t.a_id, t.b_id, &[Courtesy::Quantile(1.5)]).unwrap_err();
    assert!(scbg::is_invalid_request(&bad));

    generator_heads(&predictors, &examples, options, &scene, t, dir.path());
    closed_loop_through_the_library(&model, &scene, t, dir.path());
    ranked_policy_in_the_loop(model, &scene, t);
    courtesy_toward_neighbours(&predictors, &scene, t, dir.path());
    oracle_labels(&predictors, &rows, &truth, dir.path());

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

/// Sample and rank through the library: the same entry points as the generator, plans equal
/// generations, and a closed-loop rollout driven by it.
fn ranked_policy_in_the_loop(
    mut model: generator::LoadedScbg,
    scene: &scbg_scene::Scene,
    t: &scbg_synth::GroundTruth,
) {
    use scbg::sim::{self, ControlledAgent, SimConfig};
    model.scbg.policy = scbg::choices::Policy::Ranked;
    let quantiles = [0.0, 1.0].map(Courtesy::Quantile);
    let out = generate::generate(&model, scene, t.a_id, t.b_id, &quantiles).unwrap();
    let [low, high] = [&out.trajectories[0], &out.trajectories[1]];
    // The tiny model's labels draw 2 futures of B: the two ends take one each, J_φ measures
    // each at its label.
    assert!(low.psi < high.psi, "{} vs {}", low.psi, high.psi);
    assert_ne!(low.world_xy_m, high.world_xy_m);
    for g in [low, high] {
        assert!((g.achieved_psi - g.psi).abs() < 1e-4);
    }
    let planned = generate::plan(&model, scene, t.a_id, t.b_id, Courtesy::Quantile(1.0)).unwrap();
    assert_eq!(planned, high.world_xy_m);
    let b = [ControlledAgent {
        id: t.b_id,
        courtesy: Courtesy::Quantile(0.9),
    }];
    let config = SimConfig {
        others: sim::OthersMode::Reactive,
        ..SimConfig::default()
    };
    let rolled = sim::rollout(&model, scene, Some(t.a_id), &b, config, Some(t)).unwrap();
    rolled.validate().unwrap();
    let ib = rolled.track_index(t.b_id).unwrap();
    assert!(rolled.tracks[ib].states[11..].iter().all(|s| s.valid));
}

/// The oracle-label experiment: the ground truth's role of each scene keeps its futures with
/// the label table's ψ_true as ψ, every other role is dropped, and a generator trained on them
/// says so in generator.json.
fn oracle_labels(
    predictors: &generator::Predictors,
    rows: &[labels::LabelRow],
    truth: &[scbg::synth::GroundTruth],
    dir: &std::path::Path,
) {
    let options =
        labels::label_options(2, Reward::AverageSpeed, MarginalEstimate::default(), 1.0).unwrap();
    let labelled = generator::labelled_split(
        &predictors.plain,
        &predictors.ckpt,
        &predictors.plain_device,
        &dir.join("cache"),
        None,
        options,
        0,
        &Quiet,
    )
    .unwrap();
    let (kept, count) = labels::oracle_labelled(labelled.clone(), truth, 0);
    let scored: Vec<&labels::LabelRow> = rows.iter().filter(|r| r.psi_true.is_some()).collect();
    assert_eq!(
        count.roles,
        kept.iter().map(|s| s.roles.len()).sum::<usize>()
    );
    assert_eq!(count.roles + count.dropped_roles, 32);
    assert_eq!(count.futures, scored.len());
    assert!(count.roles >= 14, "{count:?}");
    for scene in &kept {
        let t = truth
            .iter()
            .find(|t| t.scenario_id == scene.scenario_id)
            .unwrap();
        let [role] = &scene.roles[..] else {
            panic!("{} keeps {} roles", scene.scenario_id, scene.roles.len())
        };
        assert_eq!((role.a_id, role.b_id), (t.a_id, t.b_id));
        let expected: Vec<f32> = scored
            .iter()
            .filter(|r| r.scenario_id == scene.scenario_id)
            .map(|r| r.psi_true.unwrap())
            .collect();
        assert_eq!(role.labels.psi, expected);
        assert_eq!(role.labels.futures_in_a.len(), expected.len());
    }
    let saved = generator::train_generator(
        &dir.join("model"),
        &dir.join("cache"),
        &dir.join("gen_oracle"),
        &generator::VariantSettings {
            epochs: 1,
            batch_size: 8,
            range_steps: 10,
            oracle_labels: true,
            world_futures: 0,
            ..generator::VariantSettings::new(Variant::Augmented, options)
        },
        false,
        Some(truth),
        &Quiet,
    )
    .unwrap();
    assert!(saved.oracle_labels && saved.examples <= count.roles);
    let read = generator::GeneratorCheckpoint::read(&dir.join("gen_oracle")).unwrap();
    assert!(read.oracle_labels && read.world_futures == 0);
    // The world's own futures of B in place of the sampled ones: the logged future and its
    // ψ_true stay, the world's futures are scored by the oracle like any other.
    let (world, world_count) = labels::oracle_labelled(labelled, truth, 3);
    assert_eq!(world_count.roles, count.roles);
    assert_eq!(world_count.futures, 4 * count.roles, "{world_count:?}");
    for (w, k) in world.iter().zip(&kept) {
        let (wr, kr) = (&w.roles[0], &k.roles[0]);
        assert_eq!(wr.labels.psi[0], kr.labels.psi[0]);
        assert_eq!(wr.labels.futures_in_a[0], kr.labels.futures_in_a[0]);
        assert_eq!(wr.labels.futures_in_a.len(), 4);
        assert!(wr.labels.e_cond[1..].iter().all(|e| e.is_nan()));
        // The courtesy-0.5 future of 3 is the world's B at c = 0.5, scored by the oracle.
        let t = truth
            .iter()
            .find(|t| t.scenario_id == w.scenario_id)
            .unwrap();
        let scenario = scbg_synth::Scenario::of_truth(t).unwrap();
        let mid = scbg::fidelity::world_future_of_b(&scenario, t.b_id, 0.5).unwrap();
        let in_a = &wr.labels.futures_in_a[2];
        let back = scbg::fidelity::world_points(&wr.a.world_from_agent, in_a);
        assert!(
            back.iter()
                .zip(&mid)
                .all(|(p, q)| (p[0] - q[0]).abs() < 1e-2 && (p[1] - q[1]).abs() < 1e-2)
        );
        let psi = scenario.oracle().psi_true(&back).unwrap();
        assert!((f64::from(wr.labels.psi[2]) - psi).abs() < 1e-4);
    }
    // World futures are scored by the oracle: they need its labels.
    let err = generator::train_generator(
        &dir.join("model"),
        &dir.join("cache"),
        &dir.join("gen_world"),
        &generator::VariantSettings {
            world_futures: 2,
            ..generator::VariantSettings::new(Variant::Augmented, options)
        },
        false,
        None,
        &Quiet,
    )
    .unwrap_err();
    assert!(scbg::is_invalid_request(&err), "{err:#}");
    // Without the ground truth there is nothing to take ψ_true from.
    let err = generator::train_generator(
        &dir.join("model"),
        &dir.join("cache"),
        &dir.join("gen_oracle2"),
        &generator::VariantSettings {
            oracle_labels: true,
            world_futures: 0,
            ..generator::VariantSettings::new(Variant::Augmented, options)
        },
        false,
        None,
        &Quiet,
    )
    .unwrap_err();
    assert!(scbg::is_invalid_request(&err), "{err:#}");
}

/// The closed-loop API on a trained (tiny) model: plans equal generations, a rollout in the
/// synthetic world, its metrics, both exports read back, the evaluation, and bad requests.
fn closed_loop_through_the_library(
    model: &generator::LoadedScbg,
    scene: &scbg_scene::Scene,
    t: &scbg_synth::GroundTruth,
    dir: &std::path::Path,
) {
    use scbg::sim::{self, ControlledAgent, SimConfig};
    // The planner's fast path gives the future `generate` gives.
    let planned = generate::plan(model, scene, t.a_id, t.b_id, Courtesy::Quantile(0.7)).unwrap();
    let generated =
        generate::generate(model, scene, t.a_id, t.b_id, &[Courtesy::Quantile(0.7)]).unwrap();
    assert_eq!(planned, generated.trajectories[0].world_xy_m);

    let b = |q: f32| {
        vec![ControlledAgent {
            id: t.b_id,
            courtesy: Courtesy::Quantile(q),
        }]
    };
    let config = SimConfig {
        others: sim::OthersMode::Reactive,
        ..SimConfig::default()
    };
    let rolled = sim::rollout(model, scene, Some(t.a_id), &b(0.9), config, Some(t)).unwrap();
    rolled.validate().unwrap();
    assert_eq!(rolled.num_steps(), 91);
    let ib = rolled.track_index(t.b_id).unwrap();
    assert_eq!(
        rolled.tracks[ib].states[..=10],
        scene.tracks[ib].states[..=10]
    );
    assert!(rolled.tracks[ib].states[11..].iter().all(|s| s.valid));
    // Deterministic: the same request gives the same rollout.
    assert_eq!(
        sim::rollout(model, scene, Some(t.a_id), &b(0.9), config, Some(t)).unwrap(),
        rolled
    );
    let report = sim::report(&rolled, t.a_id, &[t.b_id]).unwrap();
    assert_eq!(report.controlled.len(), 1);
    assert!(report.ego.avg_speed_mps > 0.0 && report.ego.valid_steps == 80);

    // Scenario export reads back through the project's reader.
    let file = dir.join("rollouts.tfrecord");
    assert_eq!(
        sim::write_scenarios(&file, std::slice::from_ref(&rolled)).unwrap(),
        1
    );
    let back: Vec<_> = scbg_womd::WomdFile::open(&file)
        .unwrap()
        .scenes()
        .map(Result::unwrap)
        .collect();
    assert_eq!(back.len(), 1);
    for (p, q) in back[0].tracks[ib]
        .states
        .iter()
        .zip(&rolled.tracks[ib].states)
    {
        assert!((p.x_m - q.x_m).abs() < 1e-3 && (p.y_m - q.y_m).abs() < 1e-3);
    }
    // WOSAC shards: 32 rollouts, every sim agent, decoded back.
    let scenes: Vec<_> = sim::rollout_quantiles(0.5, 32, 0.2)
        .into_iter()
        .map(|q| sim::rollout(model, scene, Some(t.a_id), &b(q), config, Some(t)).unwrap())
        .collect();
    let rollouts = sim::wosac_rollouts(scene, &scenes);
    assert_eq!(rollouts.trajectories.len(), 32);
    let paths = sim::write_wosac(
        &dir.join("wosac"),
        "scbg-test",
        &scbg_womd::wosac::SubmissionHeader::default(),
        &[(scene.clone(), rollouts.clone())],
        1,
    )
    .unwrap();
    assert!(paths[0].ends_with("scbg-test.binproto-00000-of-00001"));
    let (_, decoded) =
        scbg_womd::wosac::decode_submission(&std::fs::read(&paths[0]).unwrap()).unwrap();
    assert_eq!(decoded[0].joint_scenes.len(), 32);
    assert_eq!(decoded[0].joint_scenes[0].len(), rollouts.object_ids.len());
    let metrics = scbg_metrics::wosac::scenario_metrics(
        scene,
        &rollouts,
        scbg_metrics::wosac::WosacConfig::V2025,
    )
    .unwrap();
    assert!((0.0..=1.0).contains(&metrics.metametric));

    // The evaluation runs end to end on a couple of scenes.
    let sim_scene = scbg::sim_eval::SimScene::of(scene.clone(), Some(t.clone())).unwrap();
    let eval = scbg::sim_eval::evaluate_sim(
        model,
        &[sim_scene],
        &scbg::sim_eval::SimEvalOptions {
            quantiles: vec![0.1, 0.9],
            wosac_quantiles: vec![0.5],
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(eval.curve.per_quantile.len(), 3, "0.5 is added");
    assert_eq!(eval.curve.per_quantile[1].realised_courtesy_mps, 0.0);
    assert!(eval.baselines["log_replay"].wosac.is_some());
    assert!(eval.wosac_scbg.is_some());
    // The knob drawn from its prior is scored too, and both scbg runs are compared with
    // IDM-only scene by scene (one scene: the difference of the two meta-metrics, no spread).
    let idm = eval.baselines["idm_only"]
        .wosac
        .as_ref()
        .unwrap()
        .metametric;
    for (summary, diff) in [
        (&eval.wosac_scbg, &eval.wosac_scbg_minus_idm),
        (&eval.wosac_scbg_prior, &eval.wosac_prior_minus_idm),
    ] {
        let (summary, diff) = (summary.as_ref().unwrap(), diff.as_ref().unwrap());
        assert_eq!((diff.scenes, diff.std_error), (1, 0.0));
        assert!((diff.mean - f64::from(summary.metametric - idm)).abs() < 1e-6);
    }
    assert!(eval.realism_line().contains("knob drawn from its prior"));
    // Every collision of B is listed, with its quantile: as many as the rates say.
    let listed = |curve: &scbg::sim_eval::KnobCurve| {
        for row in &curve.per_quantile {
            let n = curve
                .b_collisions
                .iter()
                .filter(|c| c.quantile == row.quantile && c.contact.step >= 1)
                .count();
            assert_eq!(n as f64, row.b_collision_rate * curve.scenes as f64);
        }
    };
    listed(&eval.curve);
    listed(eval.world_knob.as_ref().unwrap());
    // The world's own knob on the same scene: B at courtesy c = q by the world's rule, A's
    // realised speed what the oracle says for that future of B.
    let world = eval
        .world_knob
        .as_ref()
        .expect("a synthetic scene has the world's knob");
    assert_eq!((world.scenes, world.per_quantile.len()), (1, 3));
    assert_eq!(world.per_quantile[1].realised_courtesy_mps, 0.0);
    let scenario = scbg_synth::Scenario::of_truth(t).unwrap();
    let b_future: Vec<[f64; 2]> = scenario.tracks_with_courtesy(0.9)[1].states[11..]
        .iter()
        .map(|s| [s.x_m, s.y_m])
        .collect();
    let oracle_speed = scenario.oracle().a_avg_speed_mps(&b_future).unwrap();
    assert!(
        (world.per_quantile[2].a_avg_speed_mps - oracle_speed).abs() < 0.25,
        "{} vs the oracle's {oracle_speed}",
        world.per_quantile[2].a_avg_speed_mps
    );
    scbg::sim_eval::write_figures(&eval, &dir.join("sim_figures")).unwrap();
    assert!(dir.join("sim_figures/sim_courtesy.png").is_file());

    // A genuine WOMD scene: IDM world on a real map, every sim agent in the WOSAC rollouts.
    if let Some(real) = scbg_womd::fixtures::real_data_dir() {
        let file = real.join("womd/motion_data_one_scenario.tfrecord");
        let womd = scbg_womd::WomdFile::open(&file).unwrap();
        let scene = womd.scenes().next().unwrap().unwrap();
        let a = scene.tracks[scene.sdc_track_index.unwrap()].id;
        let b_id = scene.tracks[scene.tracks_to_predict[0].track_index].id;
        let controlled = [ControlledAgent {
            id: b_id,
            courtesy: Courtesy::Quantile(0.5),
        }];
        let rolled = sim::rollout(model, &scene, Some(a), &controlled, config, None).unwrap();
        rolled.validate().unwrap();
        let rollouts = sim::wosac_rollouts(&scene, &vec![rolled; 32]);
        assert_eq!(
            rollouts.object_ids,
            scbg_metrics::wosac::sim_agent_ids(&scene)
        );
        let m = scbg_metrics::wosac::scenario_metrics(
            &scene,
            &rollouts,
            scbg_metrics::wosac::WosacConfig::V2025,
        )
        .unwrap();
        assert!(m.metametric > 0.3, "{}", m.metametric);
    }

    // Bad requests name what is wrong and are the caller's fault.
    let bad = |r: anyhow::Result<scbg_scene::Scene>, needle: &str| {
        let e = r.unwrap_err();
        assert!(scbg::is_invalid_request(&e), "{e:#}");
        assert!(format!("{e:#}").contains(needle), "{e:#} lacks {needle}");
    };
    bad(
        sim::rollout(model, scene, Some(t.a_id), &b(1.5), config, Some(t)),
        "quantile 1.5",
    );
    let unknown = vec![ControlledAgent {
        id: 4242,
        courtesy: Courtesy::Quantile(0.5),
    }];
    bad(
        sim::rollout(model, scene, Some(t.a_id), &unknown, config, Some(t)),
        "no agent with id 4242",
    );
    let mut invalid = scene.clone();
    invalid.tracks[ib].states[10].valid = false;
    bad(
        sim::rollout(model, &invalid, Some(t.a_id), &b(0.5), config, None),
        "not valid at the current step",
    );
    let mut short = scene.clone();
    for tr in &mut short.tracks {
        tr.states.truncate(8);
    }
    short.timestamps_secs.truncate(8);
    short.current_step = 7;
    bad(
        sim::rollout(model, &short, Some(t.a_id), &b(0.5), config, None),
        "fewer than 11 history steps",
    );
}

/// Issue 12, item 2: labels, a generator and generation with ψ toward B's neighbours.
fn courtesy_toward_neighbours(
    predictors: &generator::Predictors,
    scene: &scbg_scene::Scene,
    t: &scbg_synth::GroundTruth,
    dir: &std::path::Path,
) {
    use scbg::choices::{Audience, Weighting};
    let p = |s: &str| dir.join(s);
    let mut options =
        labels::label_options(2, Reward::AverageSpeed, MarginalEstimate::default(), 1.0).unwrap();
    options.audience = Audience::parse("neighbours", 40.0, Weighting::Proximity).unwrap();
    let (rows, summary) = labels::label_cache(
        &labels::LabelRun {
            model: p("model"),
            ensemble: vec![],
            data: p("cache"),
            out: p("labels_neighbours"),
            options,
            seed: 0,
            ground_truth: Some(p("synth").join(synth::GROUND_TRUTH_FILE)),
            shard_index: 0,
            num_shards: 1,
            reaction_siblings: None,
        },
        &Quiet,
    )
    .unwrap();
    // The same roles and futures; the oracle (ψ toward A alone) does not score them.
    assert_eq!(rows.len(), 16 * 2 * 3);
    assert!(
        rows.iter()
            .all(|r| r.psi_true.is_none() && r.audience_size >= 1)
    );
    assert!(
        rows.iter().any(|r| r.audience_size > 1),
        "no role has a neighbour"
    );
    assert!(summary.fidelity.is_none() && summary.audience_size_mean > 1.0);
    assert_eq!(summary.audience, options.audience);
    assert_eq!(
        labels::read_label_table(&p("labels_neighbours").join(labels::shard_table_name(0)))
            .unwrap(),
        rows
    );
    let examples = generator::examples_for_split(
        &predictors.plain,
        &predictors.ckpt,
        &predictors.plain_device,
        &p("cache"),
        None,
        options,
        0,
        false,
        &Quiet,
    )
    .unwrap();
    // Labels and training examples come from one path.
    for e in examples.iter().take(4) {
        let r = rows
            .iter()
            .find(|r| {
                r.scenario_id == e.scenario_id
                    && r.sample == 0
                    && r.b_id == e.b.target_track_id
                    && r.a_id == e.a.target_track_id
            })
            .unwrap();
        assert_eq!((r.psi, r.audience_size as usize), (e.psi[0], e.terms.len()));
    }
    generator::train_variant(
        predictors,
        &examples,
        &generator::VariantSettings {
            epochs: 1,
            batch_size: 8,
            range_steps: 10,
            ..generator::VariantSettings::new(Variant::Full, options)
        },
        &p("gen_neighbours"),
        &Quiet,
    )
    .unwrap();
    let model = generator::load_scbg(&p("gen_neighbours"), None).unwrap();
    assert_eq!(model.scbg.labels.audience, options.audience);
    let out = generate::generate(
        &model,
        scene,
        t.a_id,
        t.b_id,
        &[Courtesy::Quantile(0.2), Courtesy::Quantile(0.8)],
    )
    .unwrap();
    assert_eq!(out.trajectories.len(), 2);
    // ψ of a given future toward the audience is the generation's achieved ψ.
    for g in &out.trajectories {
        let c = generate::courtesy(&model, scene, t.a_id, t.b_id, &g.world_xy_m).unwrap();
        assert!(
            (c.psi - g.achieved_psi).abs() <= 1e-4 * (1e-3 + g.achieved_psi.abs()),
            "{} vs {}",
            c.psi,
            g.achieved_psi
        );
    }
}

/// The generator heads: the default one chooses among B's predicted modes (the model above);
/// the regression head is trained, saved, loaded and driven the same way; a generator.json
/// whose mode count is not the predictor's is refused.
fn generator_heads(
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
        &[Courtesy::Quantile(0.1), Courtesy::Quantile(0.9)],
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

/// `scbg label --model P --model Q`: ψ averaged over an ensemble of predictors.
fn ensemble_labels(single: &[labels::LabelRow], options: LabelOptions, dir: &std::path::Path) {
    let p = |s: &str| dir.join(s);
    let run = |ensemble: Vec<std::path::PathBuf>, out: &str| {
        labels::label_cache(
            &labels::LabelRun {
                model: p("model"),
                ensemble,
                data: p("cache"),
                out: p(out),
                options,
                seed: 0,
                ground_truth: Some(p("synth").join(synth::GROUND_TRUTH_FILE)),
                shard_index: 0,
                num_shards: 1,
                reaction_siblings: None,
            },
            &Quiet,
        )
    };
    // A predictor twice is that predictor.
    let (twice, summary) = run(vec![p("model")], "labels_twice").unwrap();
    assert_eq!(summary.predictors, 2);
    assert_eq!(twice, single);

    // A second predictor (another seed, and the step-wise interventional conditioning, so
    // that it trains and labels through the library too): the same futures, each logged
    // future's E[r | x, y_B] the mean of the two predictors' (the estimate of E[r | x]
    // averages the sampled futures, which differ when the second predictor labels alone).
    let mut config = predictor::TrainConfig::from_toml(TINY_CONFIG).unwrap();
    config.seed += 1;
    config.epochs = 1;
    config.stepwise_condition = true;
    predictor::train_predictor(&p("cache"), &p("model2"), &config, false, &Quiet).unwrap();
    let (both, _) = run(vec![p("model2")], "labels_both").unwrap();
    let (second, _) = labels::label_cache(
        &labels::LabelRun {
            model: p("model2"),
            ensemble: vec![],
            data: p("cache"),
            out: p("labels_second"),
            options,
            seed: 0,
            ground_truth: None,
            shard_index: 0,
            num_shards: 1,
            reaction_siblings: None,
        },
        &Quiet,
    )
    .unwrap();
    assert_eq!(both.len(), single.len());
    let mut differs = false;
    for ((e, a), b) in both.iter().zip(single).zip(&second) {
        assert_eq!(
            (&e.scenario_id, e.a_id, e.b_id, e.sample),
            (&a.scenario_id, a.a_id, a.b_id, a.sample)
        );
        assert_eq!(
            e.psi_true, a.psi_true,
            "the same futures, scored by the oracle"
        );
        if e.sample == 0 {
            let want = 0.5 * (a.e_cond + b.e_cond);
            assert!((e.e_cond - want).abs() < 1e-4 * (1.0 + want.abs()), "{e:?}");
            differs |= (a.e_cond - b.e_cond).abs() > 1e-3;
        }
    }
    assert!(differs, "the two predictors agree everywhere");

    // Members must read the same features; the lane path may differ (built for any member).
    let ckpt = generator::load_predictors(&p("model")).unwrap().ckpt;
    let mut other = ckpt.clone();
    other.train_config.max_other_agents += 1;
    let err = labels::ensemble_features(&[&ckpt, &other]).unwrap_err();
    assert!(err.to_string().contains("predictor 2"), "{err}");
    assert!(scbg::is_invalid_request(&err));
    let mut lane = ckpt.clone();
    lane.train_config.lane_frame_condition = !ckpt.train_config.lane_frame_condition;
    let features = labels::ensemble_features(&[&ckpt, &lane]).unwrap();
    assert!(features.lane_path);
}
