//! `scbg bench ingest | synth`: throughput measurements recorded in BENCHMARKS.md.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use rayon::prelude::*;
use scbg_features::{
    FeatureConfig, PairConfig, PreparedScene, SampleBuilder, WindowConfig, marginal_targets,
};
use scbg_womd::WomdFile;

use super::data::ROAD_SUBSAMPLE;
use crate::cli::{BenchIngestArgs, BenchSynthArgs};
use crate::inputs;

/// Peak resident memory of this process (Linux `VmHWM`), in MiB.
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// Decodes every scene of a file; returns the number of scenes.
fn decode_file(path: &PathBuf) -> anyhow::Result<usize> {
    let file = WomdFile::open(path)?;
    let mut n = 0;
    for scene in file.scenes() {
        std::hint::black_box(scene?);
        n += 1;
    }
    Ok(n)
}

/// Decodes and builds features for every valid vehicle of every window (marginal), and both
/// directions of every pair (conditional). Returns (scenes, samples, prepared bytes).
fn featurize_file(path: &PathBuf) -> anyhow::Result<(usize, usize, u64)> {
    let file = WomdFile::open(path)?;
    let (window, pair, features) = (
        WindowConfig::default(),
        PairConfig::default(),
        FeatureConfig::default(),
    );
    let (mut scenes, mut samples, mut bytes) = (0, 0, 0u64);
    for scene in file.scenes() {
        let scene = scene?;
        scenes += 1;
        let Ok(prepared) = PreparedScene::from_scene(&scene, &window, &pair, ROAD_SUBSAMPLE) else {
            continue;
        };
        bytes += prepared.encode().len() as u64;
        let mut builder = SampleBuilder::new(&prepared, &features);
        for (w, pairs) in prepared.windows.iter().zip(&prepared.pairs) {
            for target in marginal_targets(&prepared, w, window.future_steps, 1) {
                std::hint::black_box(builder.sample(w, target, None)?);
                samples += 1;
            }
            for p in pairs {
                for (a, b) in [(p.first, p.second), (p.second, p.first)] {
                    std::hint::black_box(builder.sample(w, a, Some(b))?);
                    samples += 1;
                }
            }
        }
    }
    Ok((scenes, samples, bytes))
}

fn run_in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> anyhow::Result<T> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("thread pool")?;
    Ok(pool.install(f))
}

pub fn ingest(args: &BenchIngestArgs) -> anyhow::Result<()> {
    let files = if args.input.is_empty() {
        let dir = scbg_womd::fixtures::real_data_dir()
            .context("no --input and no shared real data folder")?;
        inputs::expand(&[
            dir.join("womd").display().to_string(),
            dir.join("womd-reencoded").display().to_string(),
            dir.join("nuscenes-reencoded").display().to_string(),
        ])?
    } else {
        inputs::expand(&args.input)?
    };
    let raw_bytes: u64 = files
        .iter()
        .map(|f| std::fs::metadata(f).map(|m| m.len()).unwrap_or(0))
        .sum();
    let work: Vec<PathBuf> = (0..args.repeat.max(1))
        .flat_map(|_| files.iter().cloned())
        .collect();
    let all = rayon::current_num_threads();
    println!(
        "bench ingest: {} files ({} raw bytes) x {} repeats; threads: 1 and {all}",
        files.len(),
        raw_bytes,
        args.repeat
    );
    println!(
        "{:<24} {:>8} {:>12} {:>14} {:>14}",
        "stage", "threads", "scenarios/s", "samples/s", "MB/s (raw)"
    );
    let mut prepared_bytes = 0u64;
    for threads in [1, all] {
        let t = Instant::now();
        let scenes: usize = run_in_pool(threads, || {
            work.par_iter()
                .map(decode_file)
                .collect::<anyhow::Result<Vec<_>>>()
        })??
        .iter()
        .sum();
        let secs = t.elapsed().as_secs_f64();
        println!(
            "{:<24} {:>8} {:>12.1} {:>14} {:>14.1}",
            "decode",
            threads,
            scenes as f64 / secs,
            "-",
            (raw_bytes * args.repeat as u64) as f64 / secs / 1e6
        );
        let t = Instant::now();
        let results = run_in_pool(threads, || {
            work.par_iter()
                .map(featurize_file)
                .collect::<anyhow::Result<Vec<_>>>()
        })??;
        let secs = t.elapsed().as_secs_f64();
        let (scenes, samples): (usize, usize) = results
            .iter()
            .fold((0, 0), |acc, r| (acc.0 + r.0, acc.1 + r.1));
        prepared_bytes = results.iter().map(|r| r.2).sum::<u64>() / args.repeat.max(1) as u64;
        println!(
            "{:<24} {:>8} {:>12.1} {:>14.0} {:>14.1}",
            "decode+features",
            threads,
            scenes as f64 / secs,
            samples as f64 / secs,
            (raw_bytes * args.repeat as u64) as f64 / secs / 1e6
        );
    }
    println!(
        "prepared cache bytes per raw byte: {:.3} ({prepared_bytes} / {raw_bytes})",
        prepared_bytes as f64 / raw_bytes.max(1) as f64
    );
    if let Some(rss) = peak_rss_mib() {
        println!("peak RSS: {rss:.1} MiB");
    }
    Ok(())
}

pub fn synth(args: &BenchSynthArgs) -> anyhow::Result<()> {
    let families = scbg_synth::Family::ALL;
    let all = rayon::current_num_threads();
    for threads in [1, all] {
        let t = Instant::now();
        let bytes: usize = run_in_pool(threads, || {
            (0..args.scenarios as u64)
                .into_par_iter()
                .map(|i| {
                    scbg_womd::encode_scene(&scbg_synth::generate(1, i, &families).scene)
                        .map(|b| b.len())
                })
                .collect::<Result<Vec<_>, _>>()
        })??
        .iter()
        .sum();
        let secs = t.elapsed().as_secs_f64();
        println!(
            "synth generate+encode: {threads} thread(s): {:.0} scenarios/s ({:.1} KB/scenario)",
            args.scenarios as f64 / secs,
            bytes as f64 / args.scenarios as f64 / 1e3
        );
    }
    Ok(())
}

/// Training step time and inference throughput on synthetic samples of the default feature
/// sizes, at the current rayon/backend thread count.
pub fn train(args: &crate::cli::BenchTrainArgs) -> anyhow::Result<()> {
    use burn::optim::{AdamConfig, GradientsParams};
    use rand::SeedableRng;
    use scbg_model::{Batch, BatchAugment, MultipathConfig, gmm_nll};
    let features = FeatureConfig {
        max_other_agents: 16,
        max_road_segments: 64,
        ..Default::default()
    };
    // Samples from real geometry: synthetic scenes through the feature pipeline.
    let mut samples = Vec::new();
    for i in 0..args.batch as u64 {
        let g = scbg_synth::generate(9, i, &scbg_synth::Family::ALL);
        let p = PreparedScene::from_scene(
            &g.scene,
            &WindowConfig::default(),
            &PairConfig::default(),
            ROAD_SUBSAMPLE,
        )?;
        let w = p.windows[0];
        samples.push(SampleBuilder::new(&p, &features).sample(&w, 0, Some(1))?);
    }
    let refs: Vec<&scbg_features::AgentSample> = samples.iter().collect();
    println!(
        "bench train: batch {}, {} other agents, {} road segments, {} rayon threads",
        args.batch,
        features.max_other_agents,
        features.max_road_segments,
        rayon::current_num_threads()
    );
    for preset in &args.presets {
        let config =
            MultipathConfig::preset(preset).with_context(|| format!("unknown preset {preset}"))?;
        let device = burn::tensor::Device::flex().autodiff();
        device.seed(0);
        let mut model = config.init(&device);
        let params = {
            use burn::module::Module;
            model.num_params()
        };
        // As the trainer and the PyTorch reference: Adam with gradient-norm clipping at 0.4.
        let mut optim = AdamConfig::new()
            .with_grad_clipping(Some(burn::grad_clipping::GradientClippingConfig::Norm(0.4)))
            .init();
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
        let mut step = |model: scbg_model::Multipath| {
            let batch = Batch::from_samples(
                &refs,
                &BatchAugment {
                    condition_dropout: 0.3,
                    history_mask_prob: 0.15,
                },
                &mut rng,
                &device,
            );
            let loss = gmm_nll(
                &model.forward(&batch),
                batch.future_xy.clone(),
                batch.future_valid.clone(),
            );
            let grads = GradientsParams::from_grads(loss.backward(), &model);
            optim.step(1e-4, model, grads)
        };
        model = step(model); // warm-up
        let t = Instant::now();
        for _ in 0..args.steps {
            model = step(model);
        }
        let ms = t.elapsed().as_secs_f64() * 1e3 / args.steps as f64;
        let infer = burn::tensor::Device::flex();
        let valid = {
            use burn::module::Module;
            model.valid()
        };
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
        let batch = Batch::from_samples(&refs, &BatchAugment::default(), &mut rng, &infer);
        let _ = valid.forward(&batch).xy.into_data();
        // One batch, built once (as the PyTorch reference): this times the model alone.
        let t = Instant::now();
        let reps = args.steps.max(3);
        for _ in 0..reps {
            let _ = valid.forward(&batch).xy.into_data();
        }
        let per_s = (reps * args.batch) as f64 / t.elapsed().as_secs_f64();
        println!(
            "{preset:<10} {params:>10} params   train step {ms:>9.1} ms   inference {per_s:>8.1} samples/s"
        );
    }
    Ok(())
}
