//! Labelling through the library: courtesy toward neighbours, ensembles.

use scbg::choices::{Courtesy, LabelOptions, MarginalEstimate, Reward, Variant};
use scbg::{Quiet, generate};
use scbg_lab::{generator, labels, predictor, synth};

/// Labels, a generator and generation with ψ toward B's neighbours.
pub(crate) fn courtesy_toward_neighbours(
    predictors: &generator::Predictors,
    scene: &scbg_scene::Scene,
    t: &scbg_synth::GroundTruth,
    dir: &std::path::Path,
) {
    use scbg::choices::{Audience, Weighting};
    let p = |s: &str| dir.join(s);
    let mut options = labels::label_options(2, Reward::AverageSpeed, MarginalEstimate::default());
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
        &[
            Courtesy::quantile(0.2).unwrap(),
            Courtesy::quantile(0.8).unwrap(),
        ],
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

/// `scbg label --model P --model Q`: ψ averaged over an ensemble of predictors.
pub(crate) fn ensemble_labels(
    single: &[labels::LabelRow],
    options: LabelOptions,
    dir: &std::path::Path,
) {
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
    let mut config = predictor::TrainConfig::from_toml(crate::TINY_CONFIG).unwrap();
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
