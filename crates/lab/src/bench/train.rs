//! `scbg bench train`: the trainer's own step on synthetic samples, and inference.

use std::time::Instant;

use scbg_features::{FeatureConfig, PairConfig, PreparedScene, SampleBuilder, WindowConfig};

use crate::ROAD_SUBSAMPLE;

/// Training step time and inference throughput on synthetic samples of the default feature
/// sizes, at the current rayon/backend thread count. `warmup` untimed steps come first (a GPU
/// backend compiles its kernels in them); every timed step ends with a device sync, so an
/// asynchronous backend is timed to the end of its work. `chunks` > 1 makes each step
/// data-parallel: the batch split into that many chunks, each chunk's forward and backward pass
/// on its own fork of the model (its own autodiff graph) in a rayon task, the gradients summed.
pub fn train(
    presets: &[scbg_model::Preset],
    batch_size: usize,
    steps: usize,
    warmup: usize,
    chunks: usize,
    backend: &str,
) -> anyhow::Result<TrainBench> {
    use burn::module::Module;
    use burn::optim::{AdamConfig, GradientsParams};
    use rand::SeedableRng;
    use scbg_model::{Batch, BatchAugment, Mode, gmm_nll};
    let features = FeatureConfig {
        max_other_agents: 16,
        max_road_segments: 64,
        ..Default::default()
    };
    // Samples from real geometry: synthetic scenes through the feature pipeline.
    let mut samples = Vec::new();
    for i in 0..batch_size as u64 {
        let g = scbg_synth::generate(9, i, &scbg_synth::Family::DEFAULT);
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
    let mut out = TrainBench {
        batch: batch_size,
        other_agents: features.max_other_agents,
        road_segments: features.max_road_segments,
        threads: rayon::current_num_threads(),
        chunks: chunks.max(1),
        backend: backend.to_string(),
        rows: Vec::new(),
    };
    for &preset in presets {
        let config = preset.config();
        let device = scbg_model::device::training_device(backend)?;
        device.seed(0);
        let mut model = config.init(&device);
        let params = model.num_params();
        // As the trainer and the PyTorch reference: Adam with gradient-norm clipping at 0.4.
        let mut optim = AdamConfig::new()
            .with_grad_clipping(Some(burn::grad_clipping::GradientClippingConfig::Norm(0.4)))
            .init();
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
        let augment = BatchAugment {
            condition_dropout: 0.3,
            history_mask_prob: 0.15,
        };
        // The trainer's own step (GMM NLL alone, as the PyTorch reference).
        let step_config = scbg_train::TrainConfig {
            data_parallel_chunks: chunks.max(1),
            classification_weight: 0.0,
            ..Default::default()
        };
        let mut step = |model: scbg_model::Multipath| {
            let (value, grads) = scbg_train::loss_and_grads(
                &model,
                &refs,
                &augment,
                &mut rng,
                &device,
                &step_config,
            );
            let grads = grads.ok_or_else(|| anyhow::anyhow!("non-finite loss {value}"))?;
            anyhow::Ok(optim.step(1e-4, model, grads))
        };
        let sync = |device: &burn::tensor::Device| {
            device
                .sync()
                .map_err(|e| anyhow::anyhow!("{backend}: device sync failed: {e:?}"))
        };
        let t = Instant::now();
        for _ in 0..warmup.max(1) {
            model = step(model)?;
        }
        sync(&device)?;
        let warmup_ms = t.elapsed().as_secs_f64() * 1e3;
        let mut times = Vec::with_capacity(steps);
        for _ in 0..steps.max(1) {
            let t = Instant::now();
            model = step(model)?;
            sync(&device)?;
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let ms = times.iter().sum::<f64>() / times.len() as f64;
        let best_ms = times.iter().copied().fold(f64::INFINITY, f64::min);
        // Where a step's time goes, over a few more steps of the whole batch in one graph,
        // with a sync after each phase (so a GPU's overlap with the host is lost here).
        const PHASE_STEPS: usize = 3;
        let mut phases_ms = [0.0f64; 4];
        for _ in 0..PHASE_STEPS {
            let t0 = Instant::now();
            let batch = Batch::from_samples(&refs, &augment, &mut rng, &device);
            sync(&device)?;
            let t1 = Instant::now();
            let loss = gmm_nll(
                &model.forward(&batch),
                batch.future_xy.clone(),
                batch.future_valid.clone(),
            );
            sync(&device)?;
            let t2 = Instant::now();
            let grads = GradientsParams::from_grads(loss.backward(), &model);
            sync(&device)?;
            let t3 = Instant::now();
            model = optim.step(1e-4, model, grads);
            sync(&device)?;
            let t4 = Instant::now();
            for (p, (a, b)) in phases_ms
                .iter_mut()
                .zip([(t0, t1), (t1, t2), (t2, t3), (t3, t4)])
            {
                *p += (b - a).as_secs_f64() * 1e3 / PHASE_STEPS as f64;
            }
        }
        let infer = scbg_model::device::device(backend)?;
        let valid = model.valid();
        let batch = Batch::for_mode(&refs, Mode::Conditional, &infer);
        let _ = valid.forward(&batch).xy.into_data();
        // One batch, built once (as the PyTorch reference): this times the model alone.
        let t = Instant::now();
        let reps = steps.max(3);
        for _ in 0..reps {
            let _ = valid.forward(&batch).xy.into_data();
        }
        let per_s = (reps * batch_size) as f64 / t.elapsed().as_secs_f64();
        out.rows.push(TrainBenchRow {
            preset,
            params,
            step_ms: ms,
            best_step_ms: best_ms,
            warmup_ms,
            phases_ms,
            inference_samples_per_s: per_s,
        });
    }
    Ok(out)
}

/// One preset's training step and inference throughput.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainBenchRow {
    /// The model preset.
    pub preset: scbg_model::Preset,
    /// Its parameter count.
    pub params: usize,
    /// Mean training step (forward, backward, Adam with clipping), milliseconds.
    pub step_ms: f64,
    /// The fastest timed step, milliseconds.
    pub best_step_ms: f64,
    /// All warm-up steps together (kernel compilation and autotuning on a GPU), milliseconds.
    pub warmup_ms: f64,
    /// One step of the whole batch split into phases, each ended by a device sync: the batch
    /// built and uploaded, forward and loss, backward, optimizer (with clipping), milliseconds.
    pub phases_ms: [f64; 4],
    /// Inference throughput of the model alone.
    pub inference_samples_per_s: f64,
}

/// `scbg bench train`'s measurements.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainBench {
    /// Batch size.
    pub batch: usize,
    /// Other agents per sample.
    pub other_agents: usize,
    /// Road segments per sample.
    pub road_segments: usize,
    /// Rayon threads.
    pub threads: usize,
    /// Data-parallel chunks per training step (1: the whole batch in one graph).
    pub chunks: usize,
    /// The backend measured.
    pub backend: String,
    /// One row per preset.
    pub rows: Vec<TrainBenchRow>,
}

impl TrainBench {
    /// The table `scbg bench train` prints.
    pub fn to_text(&self) -> String {
        let mut s = format!(
            "bench train: batch {}, {} other agents, {} road segments, {} rayon threads, {} chunk(s), backend {}\n",
            self.batch,
            self.other_agents,
            self.road_segments,
            self.threads,
            self.chunks,
            self.backend
        );
        for r in &self.rows {
            s += &format!(
                "{:<10} {:>10} params   train step {:>9.1} ms (best {:.1}, warm-up {:.0})   inference {:>8.1} samples/s\n",
                r.preset.name(),
                r.params,
                r.step_ms,
                r.best_step_ms,
                r.warmup_ms,
                r.inference_samples_per_s
            );
            s += &format!(
                "{:<10} phases (synced): batch {:.1} ms, forward {:.1} ms, backward {:.1} ms, optimizer {:.1} ms\n",
                "", r.phases_ms[0], r.phases_ms[1], r.phases_ms[2], r.phases_ms[3]
            );
        }
        s
    }
}
