//! Each command: arguments → one library call → printing.

use std::io::Write;

use anyhow::Context;
use scbg::Courtesy;
use scbg::Progress;
use scbg_lab::{labels, predictor};

use scbg_lab::config::PipelineConfig;

use crate::cli::{
    BenchCommand, Command, DataCommand, EvalCommand, GenerateArgs, InspectArgs, TrainCommand,
};
use crate::progress::Terminal;

/// Runs one command.
pub fn run(command: Command) -> anyhow::Result<()> {
    let progress = &Terminal;
    match command {
        Command::Demo(a) => {
            // Checked before any work: a bad setting must not cost a predictor training.
            let config = PipelineConfig::load(a.config.as_deref())?;
            let options = scbg_lab::demo::DemoOptions::new(a.out, a.data, a.seed, config)?;
            scbg_lab::demo::run_demo(&options, progress)?;
        }
        Command::Label(a) => {
            let options =
                PipelineConfig::load(a.config.as_deref())?.label_options_with(a.reward)?;
            labels::label_cache(
                &labels::LabelRun {
                    model: a.model[0].clone(),
                    ensemble: a.model[1..].to_vec(),
                    data: a.data,
                    out: a.out,
                    options,
                    seed: a.seed,
                    ground_truth: a.ground_truth,
                    shard_index: a.shard_index,
                    num_shards: a.num_shards,
                    reaction_siblings: a
                        .reaction_siblings
                        .map(|d| (d, labels::REACTION_SIBLINGS_PER_ROLE)),
                },
                progress,
            )?;
        }
        Command::Data(DataCommand::Inspect(a)) => inspect(&a)?,
        Command::Data(DataCommand::Render(a)) => {
            let (id, pair) = scbg::data::render(&a.file, a.index, a.size_px, &a.out)?;
            eprintln!("wrote {} (scenario {id}, pair {pair:?})", a.out.display());
        }
        Command::Data(DataCommand::Prepare(a)) => {
            scbg_lab::prepare::prepare(
                &scbg_lab::prepare::PrepareOptions {
                    inputs: a.input,
                    out: a.out,
                    shard_index: a.shard_index,
                    num_shards: a.num_shards,
                    files_per_shard: a.files_per_shard,
                    stride_steps: a.stride_steps,
                    pair_distance_m: a.pair_distance_m,
                    pair_time_gap_s: a.pair_time_gap_s,
                },
                progress,
            )?;
        }
        Command::Synth(a) => {
            scbg_lab::synth::write_synthetic(
                &scbg_lab::synth::SynthOptions {
                    scenarios: a.scenarios,
                    seed: a.seed,
                    out: a.out,
                    families: a.families,
                    held_out: a.held_out,
                    scenarios_per_file: a.scenarios_per_file,
                    counterfactuals: a.counterfactuals,
                },
                progress,
            )?;
        }
        Command::Bench(BenchCommand::Ingest(a)) => {
            print!(
                "{}",
                scbg_lab::bench::ingest(&a.input, a.repeat, &a.stage)?.to_text()
            );
        }
        Command::Bench(BenchCommand::Synth(a)) => {
            for (threads, per_s, kb) in scbg_lab::bench::synth(a.scenarios)? {
                println!(
                    "synth generate+encode: {threads} thread(s): {per_s:.0} scenarios/s ({kb:.1} KB/scenario)"
                );
            }
        }
        Command::Bench(BenchCommand::Wosac(a)) => {
            print!(
                "{}",
                scbg_lab::bench::wosac(a.file.as_deref(), a.repeats)?.to_text()
            );
        }
        Command::Bench(BenchCommand::Sim(a)) => {
            let model = a.model.load()?;
            print!(
                "{}",
                scbg_lab::bench::sim(model.loaded(), a.scenes, a.replan_every.map(|n| n as usize))?
                    .to_text()
            );
            println!();
        }
        Command::Sim(a) => sim(&a, progress)?,
        Command::Serve(a) => {
            let model = a.model.load()?;
            let defaults = scbg_serve::ServeConfig::default();
            scbg_serve::run(
                model,
                scbg_serve::ServeConfig {
                    addr: a.addr,
                    token: a.token,
                    data_dir: a.data_dir,
                    max_body_bytes: a.max_body_mib << 20,
                    request_timeout: std::time::Duration::from_secs(a.timeout_s),
                    workers: a.workers.unwrap_or(defaults.workers),
                    session_ttl: std::time::Duration::from_secs(a.session_ttl_s),
                    max_connections: a.max_connections,
                    header_timeout: std::time::Duration::from_secs(a.header_timeout_s),
                    ..defaults
                },
            )?;
        }
        Command::Bench(BenchCommand::Serve(a)) => {
            let model = scbg::Model::load(&a.model, &scbg::LoadOptions::default())?;
            let (bytes, truth) = scbg_lab::synth::scenario_bytes(0, 2)?;
            let report = scbg_serve::load::load_test(
                model,
                bytes,
                (truth.a_id, truth.b_id),
                a.rate,
                a.seconds,
                a.workers
                    .unwrap_or_else(|| scbg_serve::ServeConfig::default().workers),
            )?;
            print_report(a.json, &report, report.to_text())?;
        }
        Command::Bench(BenchCommand::Soak(a)) => {
            let model = scbg::Model::load(&a.model, &scbg::LoadOptions::default())?;
            let (bytes, truth) = scbg_lab::synth::scenario_bytes(0, 2)?;
            let report = scbg_serve::soak::soak(
                model,
                bytes,
                (truth.a_id, truth.b_id),
                &scbg_serve::soak::SoakOptions {
                    rate: a.rate,
                    seconds: a.seconds,
                    workers: a
                        .workers
                        .unwrap_or_else(|| scbg_serve::ServeConfig::default().workers),
                    connections: a.connections,
                    slow_clients: a.slow_clients,
                    seed: a.seed,
                },
            )?;
            print_report(a.json, &report, report.to_text())?;
            anyhow::ensure!(report.passed(), "the soak missed a bar (listed above)");
        }
        Command::Bench(BenchCommand::Kill(a)) => {
            let options = scbg_lab::bench::KillOptions {
                work: a.work.clone(),
                kills: a.kills,
                seed: a.seed,
                stages: if a.stages.is_empty() {
                    scbg_lab::bench::KillStage::ALL.to_vec()
                } else {
                    a.stages.clone()
                },
                scenarios: a.scenarios,
            };
            let exe = std::env::current_exe().context("the path of this scbg executable")?;
            let report = scbg_lab::bench::kill_sweep(&exe, &options)?;
            print_report(a.json, &report, report.to_text())?;
            anyhow::ensure!(
                report.all_passed(),
                "some kill points failed (listed above)"
            );
        }
        Command::Eval(EvalCommand::Sim(a)) => {
            let closed_loop = PipelineConfig::load(a.config.as_deref())?.closed_loop;
            let options = scbg_lab::sim_eval::SimEvalOptions {
                policy: a.model.policy,
                scenes: a.scenes,
                wosac_scenes: a.wosac_scenes,
                wosac_quantiles: closed_loop.wosac_quantiles.clone(),
                spread: closed_loop.spread,
                config: closed_loop
                    .loop_options(scbg::sim::OthersMode::Reactive)
                    .config(a.model.policy),
                ..Default::default()
            };
            let eval = scbg_lab::sim_eval::eval_sim_files(
                &a.model.model,
                a.model.predictor.as_deref(),
                &a.data,
                a.ground_truth.as_deref(),
                a.split,
                &options,
                &a.out,
                progress,
            )?;
            if a.json {
                println!("{}", serde_json::to_string_pretty(&eval)?);
            } else {
                print_sim_eval(&eval);
            }
        }
        Command::Bench(BenchCommand::Train(a)) => {
            let bench = scbg_lab::bench::train(
                &a.presets, a.batch, a.steps, a.warmup, a.chunks, &a.backend,
            )?;
            print!("{}", bench.to_text());
        }
        Command::Train(TrainCommand::Predictor(a)) => {
            let config = predictor::load_train_config(a.config.as_deref())?;
            predictor::train_predictor(&a.data, &a.out, &config, a.resume, progress)?;
        }
        Command::Train(TrainCommand::Generator(a)) => {
            let config = PipelineConfig::load(a.config.as_deref())?;
            let settings = config.variant_settings(a.variant, config.label_options()?, a.seed);
            scbg_lab::generator::train_generator(
                &a.predictor,
                &a.data,
                &a.out,
                &settings,
                progress,
            )?;
        }
        Command::Generate(a) => generate(&a, progress)?,
        Command::Eval(EvalCommand::Scbg(a)) => {
            let truth = a
                .ground_truth
                .as_deref()
                .map(scbg_lab::synth::read_ground_truth)
                .transpose()?;
            let result = scbg_lab::scbg_eval::evaluate_scbg(
                &a.model,
                &a.data,
                a.predictor.as_deref(),
                a.split.split(),
                a.seed,
                a.samples.map(|n| n as usize),
                a.figures.as_deref(),
                truth.as_deref(),
                progress,
            )?;
            print_report(a.json, &result, result.to_markdown())?;
        }
        Command::Eval(EvalCommand::Predictor(a)) => {
            let eval = predictor::evaluate_predictor(
                &a.model,
                &a.data,
                a.mode,
                a.split,
                &predictor::thresholds(a.current_thresholds),
            )?;
            if a.json {
                println!("{}", serde_json::to_string(&eval)?);
            } else {
                print!("{}", predictor::table_text(&eval.rows));
                for (mode, v) in &eval.nll_interacting {
                    println!(
                        "NLL of the interacting agents' futures, {mode} mode: {}",
                        v.map_or("-".into(), |v| format!("{v:.2}"))
                    );
                }
            }
        }
        Command::Eval(EvalCommand::Wosac(a)) => {
            let score = scbg::wosac::score_submission(&a.scenarios, &a.submission, progress)?;
            if let Some(dir) = &a.out {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating {}", dir.display()))?;
                scbg::write_json(dir.join("wosac.json"), &score)?;
            }
            print_report(a.json, &score, score.to_text())?;
            anyhow::ensure!(
                score.scored() > 0,
                "no scenario scored ({})",
                score.skipped_line()
            );
        }
        Command::Data(DataCommand::WosacBaseline(a)) => {
            let out =
                scbg::wosac::write_baseline(&a.scenarios, a.baseline, &a.out, &a.name, progress)?;
            for s in &out.skipped {
                eprintln!("left out: {}", s.detail);
            }
            eprintln!(
                "wrote {} scenario(s) into {} shard(s) in {}",
                out.scenarios,
                out.files.len(),
                a.out.display()
            );
            anyhow::ensure!(out.scenarios > 0, "no scenario could be scored");
        }
        Command::Eval(EvalCommand::Metrics(a)) => {
            let table = predictor::evaluate_external(
                &a.scenarios,
                &a.predictions,
                &predictor::thresholds(a.current_thresholds),
            )?;
            if a.json {
                println!("{}", predictor::table_json(&table));
            } else {
                print!("{}", predictor::metrics_text(&table));
            }
        }
    }
    Ok(())
}

/// The closed-loop settings of `sim` and `eval sim`.
fn sim(a: &crate::cli::SimArgs, progress: &dyn Progress) -> anyhow::Result<()> {
    use scbg::sim::ControlledAgent;
    let closed_loop = PipelineConfig::load(a.config.as_deref())?.closed_loop;
    let mut controlled = vec![ControlledAgent::new(
        a.pair.b,
        match a.psi {
            Some(p) => Courtesy::psi(p)?,
            None => Courtesy::quantile(a.quantile)?,
        },
    )];
    for also in &a.also {
        let (id, q) = also
            .split_once('=')
            .with_context(|| format!("--also {also:?}: expected ID=QUANTILE"))?;
        let q: f32 = q
            .trim()
            .parse()
            .with_context(|| format!("--also {also:?}: {q:?} is not a quantile"))?;
        controlled.push(ControlledAgent::new(
            id.trim()
                .parse()
                .with_context(|| format!("--also {also:?}: {id:?} is not a track id"))?,
            Courtesy::quantile(q).with_context(|| format!("--also {also:?}"))?,
        ));
    }
    let rollouts = closed_loop.rollouts.unwrap_or(match closed_loop.format {
        scbg::sim::ExportFormat::Wosac => 32,
        scbg::sim::ExportFormat::Scenario => 1,
    });
    let out = scbg::sim::run_sim(
        &scbg::sim::SimRun {
            model: a.model.model.clone(),
            predictor: a.model.predictor.clone(),
            policy: a.model.policy,
            scenario: a.pair.scenario.clone(),
            scenario_id: a.pair.scenario_id.clone(),
            ego: a.pair.a,
            controlled,
            options: closed_loop.loop_options(scbg::sim::OthersMode::Log),
            rollouts,
            spread: closed_loop.spread,
            out: a.out.clone(),
            format: closed_loop.format,
            name: closed_loop.name.clone(),
        },
        progress,
    )?;
    let r = &out.reports[0];
    eprintln!(
        "{}: {} rollout(s){}; A's realised average speed {:.2} m/s; B collision {}, off-road {}",
        out.scenario_id,
        out.reports.len(),
        if out.synthetic_world {
            " in the synthetic world"
        } else {
            " (IDM world)"
        },
        r.ego.avg_speed_mps,
        r.controlled[0].collision,
        r.controlled[0]
            .offroad
            .map_or("n/a".into(), |o| o.to_string()),
    );
    if let Some(w) = &out.wosac {
        eprintln!(
            "WOSAC meta-metric of the {} rollouts {:.4} (minADE {:.2} m)",
            out.reports.len(),
            w.metametric,
            w.min_average_displacement_error_m
        );
    }
    for f in &out.files {
        eprintln!("wrote {}", f.display());
    }
    Ok(())
}

fn print_sim_eval(e: &scbg_lab::sim_eval::SimEval) {
    let na = |x: Option<f64>, decimals: usize| {
        x.map_or("n/a".to_string(), |x| format!("{x:.decimals$}"))
    };
    println!(
        "closed loop, {} scenes, re-plan every {} steps ({:.0} ms per rollout, {:.0} s)",
        e.curve.scenes, e.replan_every, e.rollout_ms, e.seconds
    );
    if let Some(s) = &e.sources {
        println!(
            "scenes: {} windows of {} logged scenes ({} cut from longer scenes); pairs {}",
            e.curve.scenes,
            s.scenarios,
            s.windows,
            s.pairs
                .iter()
                .map(|(k, n)| format!("{k} {n}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    println!("{}", e.skipped_line());
    const LISTED: usize = 20;
    for s in e.skipped_scenes.iter().take(LISTED) {
        println!("  {}: {}", s.scenario_id, s.reason);
    }
    if e.skipped_scenes.len() > LISTED {
        println!(
            "  … and {} more (eval_sim.json lists each)",
            e.skipped_scenes.len() - LISTED
        );
    }
    println!("quantile  A speed m/s  realised courtesy  B collision  B off-road  WOSAC meta");
    for r in &e.curve.per_quantile {
        println!(
            "{:8.1}  {:11.2}  {:17.3}  {:11.3}  {:>10}  {}",
            r.quantile,
            r.a_avg_speed_mps,
            r.realised_courtesy_mps,
            r.b_collision_rate,
            na(r.b_offroad_rate, 3),
            r.wosac
                .as_ref()
                .map_or("n/a".into(), |w| format!("{:.4}", w.metametric))
        );
    }
    println!("{}", e.curve.collision_line());
    println!("{}", e.curve.offroad_line());
    for (name, b) in &e.baselines {
        println!(
            "{name:>18}: A speed {} m/s, B collision {}, B off-road {}, WOSAC meta {}",
            na(b.a_avg_speed_mps, 2),
            na(b.b_collision_rate, 3),
            na(b.b_offroad_rate, 3),
            b.wosac
                .as_ref()
                .map_or("n/a".into(), |w| format!("{:.4}", w.metametric))
        );
    }
    let fmt = |m: &scbg_lab::sim_eval::PerFamily| {
        m.iter()
            .map(|(k, v)| format!("{k} {}", v.map_or("-".into(), |v| format!("{v:.3}"))))
            .collect::<Vec<_>>()
            .join(", ")
    };
    println!(
        "Spearman(quantile, A speed): {}",
        fmt(&e.curve.spearman_quantile_a_speed)
    );
    println!(
        "Spearman(quantile, realised courtesy): {}",
        fmt(&e.curve.spearman_quantile_realised_courtesy)
    );
    println!(
        "Spearman(quantile, A speed) within a scene (0 where it does not respond): {}; responsive scenes: {}",
        fmt(&e.curve.spearman_within_scene_a_speed),
        fmt(&e.curve.responsive_fraction)
    );
    println!(
        "Spearman(quantile, A speed) with each scene's speeds ordered to rise with the quantile (a perfect knob's with these outcomes): {}",
        fmt(&e.curve.spearman_quantile_a_speed_ordered)
    );
    if let Some(w) = &e.world_knob {
        println!(
            "the world's own B at c = q: Spearman(quantile, A speed) {}; within a scene {}; ordered {}",
            fmt(&w.spearman_quantile_a_speed),
            fmt(&w.spearman_within_scene_a_speed),
            fmt(&w.spearman_quantile_a_speed_ordered)
        );
    }
    println!("{}", e.realism_line());
}

/// `scbg data inspect`: one line (or JSON object) per scenario; a bad file is reported and
/// the others still inspected.
fn inspect(args: &InspectArgs) -> anyhow::Result<()> {
    let mut failed = 0usize;
    let mut out = std::io::stdout().lock();
    for path in &args.files {
        let summaries = match scbg::data::inspect(path) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("error: {e:#}");
                failed += 1;
                continue;
            }
        };
        for s in summaries {
            if args.json {
                writeln!(out, "{}", serde_json::to_string(&s)?)?;
            } else {
                let t = &s.tracks_by_type;
                writeln!(
                    out,
                    "{}  {}  [{}]  steps {} (now {})  tracks {} (veh {} ped {} cyc {} other {})  map {} (lanes {})  interest {:?}  predict {}",
                    s.file,
                    s.scenario_id,
                    s.format,
                    s.num_steps,
                    s.current_time_index,
                    s.num_tracks,
                    t.vehicle,
                    t.pedestrian,
                    t.cyclist,
                    t.other,
                    s.num_map_features,
                    s.map_features_by_type.lane,
                    s.objects_of_interest,
                    s.tracks_to_predict.len(),
                )?;
            }
        }
    }
    anyhow::ensure!(
        failed == 0,
        "{failed} of {} file(s) could not be read",
        args.files.len()
    );
    Ok(())
}

/// A generator folder with its predictor (the recorded one unless overridden), driven by `policy`.
/// `scbg generate`.
fn generate(args: &GenerateArgs, progress: &dyn Progress) -> anyhow::Result<()> {
    let courtesy: Vec<Courtesy> = if args.psi.is_empty() {
        args.quantile
            .iter()
            .map(|&q| Courtesy::quantile(q))
            .collect::<Result<_, _>>()?
    } else {
        args.psi
            .iter()
            .map(|&p| Courtesy::psi(p))
            .collect::<Result<_, _>>()?
    };
    let model = args.model.load()?;
    let p = &args.pair;
    let (index, scene) =
        scbg::generate::find_scene(&p.scenario, p.scenario_id.as_deref(), p.a, p.b)?;
    let scene = std::sync::Arc::new(scene);
    let generation = model
        .generate(&scene, p.a, p.b, &courtesy)
        .with_context(|| format!("{} (record {index})", p.scenario.display()))?;
    let text = serde_json::to_string_pretty(&generation)?;
    match &args.out {
        Some(path) => scbg::write_atomic(path, &text)?,
        None => println!("{text}"),
    }
    for g in &generation.trajectories {
        progress.note(&format!(
            "quantile {:.2} → ψ {:+.4} (range {:+.4} … {:+.4}); achieved ψ {:+.4}; A's expected speed {:.2} m/s (marginal {:.2})",
            g.quantile,
            g.psi,
            g.psi_low,
            g.psi_high,
            g.achieved_psi,
            g.a_expected_reward_conditional,
            g.a_expected_reward_marginal
        ));
    }
    if let Some(png) = &args.render {
        scbg::generate::render_generation(&scene, &generation, png)?;
        progress.note(&format!("rendered {}", png.display()));
    }
    Ok(())
}

/// Prints `report` as pretty JSON, or `text`.
fn print_report(json: bool, report: &impl serde::Serialize, text: String) -> anyhow::Result<()> {
    if json {
        println!("{}", serde_json::to_string_pretty(report)?);
    } else {
        print!("{text}");
    }
    Ok(())
}
