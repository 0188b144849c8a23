//! Throughput measurements (`scbg bench ingest | synth | train | …`) and the kill sweep
//! (`scbg bench kill`), recorded in BENCHMARKS.md.
//! Each returns its measurements; `to_text` gives the table the command prints.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use rayon::prelude::*;
use scbg_features::{
    FeatureConfig, PairConfig, PreparedScene, SampleBuilder, WindowConfig, marginal_targets,
};
use scbg_womd::WomdFile;

use crate::{ROAD_SUBSAMPLE, inputs};

mod kill;
mod sim;
mod train;
pub use kill::{KillOptions, KillReport, KillRow, KillStage, kill_sweep};
pub use sim::{SimBench, sim};
pub use train::{TrainBench, TrainBenchRow, train};

/// Peak resident memory of this process (Linux `VmHWM`), in MiB.
pub fn peak_rss_mib() -> Option<f64> {
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

/// Decodes and prepares every scene and then either encodes its cache record (what `scbg data
/// prepare` does) or, with `samples_too`, builds features for every valid vehicle of every
/// window (marginal) and both directions of every pair (conditional) — samples need the
/// prepared scene, not its record. Returns (scenes, samples, cache record bytes; 0 with
/// `samples_too`).
fn featurize_file(path: &PathBuf, samples_too: bool) -> anyhow::Result<(usize, usize, u64)> {
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
        if !samples_too {
            // The cache record (`scbg data prepare`); building samples needs only the
            // prepared scene, so decode+features does not pay for it.
            bytes += prepared.encode().len() as u64;
            continue;
        }
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
    let mode = crate::fp::Mode::current();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .start_handler(move |_| mode.apply())
        .build()
        .context("thread pool")?;
    Ok(pool.install(f))
}

/// One row of the ingest benchmark.
#[derive(Debug, Clone, PartialEq)]
pub struct IngestRow {
    /// `decode`, `decode+prepare` (the cache record, as `scbg data prepare`) or
    /// `decode+features` (the prepared scene and every sample built from it, no record).
    pub stage: &'static str,
    /// Rayon threads.
    pub threads: usize,
    /// Scenarios per second.
    pub scenarios_per_s: f64,
    /// Feature samples per second (`decode+features` only).
    pub samples_per_s: Option<f64>,
    /// Raw input megabytes per second.
    pub raw_mb_per_s: f64,
}

/// `scbg bench ingest`'s measurements.
#[derive(Debug, Clone, PartialEq)]
pub struct IngestBench {
    /// Distinct input files.
    pub files: usize,
    /// Their total size.
    pub raw_bytes: u64,
    /// How often the file list was repeated.
    pub repeat: usize,
    /// Rows at 1 thread and at every thread.
    pub rows: Vec<IngestRow>,
    /// Bytes of the prepared records of one pass (measured by the `decode+prepare` stage).
    pub prepared_bytes: Option<u64>,
    /// Peak resident memory, MiB.
    pub peak_rss_mib: Option<f64>,
}

impl IngestBench {
    /// The table `scbg bench ingest` prints.
    pub fn to_text(&self) -> String {
        let all = self.rows.last().map_or(1, |r| r.threads);
        let mut s = format!(
            "bench ingest: {} files ({} raw bytes) x {} repeats; threads: 1 and {all}\n{:<24} {:>8} {:>12} {:>14} {:>14}\n",
            self.files,
            self.raw_bytes,
            self.repeat,
            "stage",
            "threads",
            "scenarios/s",
            "samples/s",
            "MB/s (raw)"
        );
        for r in &self.rows {
            s += &format!(
                "{:<24} {:>8} {:>12.1} {:>14} {:>14.1}\n",
                r.stage,
                r.threads,
                r.scenarios_per_s,
                r.samples_per_s.map_or("-".into(), |v| format!("{v:.0}")),
                r.raw_mb_per_s
            );
        }
        match self.prepared_bytes {
            Some(b) => {
                s += &format!(
                    "prepared cache bytes per raw byte: {:.3} ({b} / {})\n",
                    b as f64 / self.raw_bytes.max(1) as f64,
                    self.raw_bytes
                );
            }
            None => s += "prepared cache bytes per raw byte: (measured by --stage prepare)\n",
        }
        if let Some(rss) = self.peak_rss_mib {
            s += &format!("peak RSS: {rss:.1} MiB\n");
        }
        s
    }
}

/// A stage of [`ingest`]; each is timed on its own (a profile of one stage runs only it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum IngestStage {
    /// Decode every scenario.
    Decode,
    /// Decode and build the prepared cache record (`scbg data prepare`).
    Prepare,
    /// Decode, prepare and build every feature sample.
    Features,
}

/// Decode and decode + features throughput over `inputs` (default: every file of the shared
/// real-data folder) repeated `repeat` times, at 1 thread and at every thread, for each of
/// `stages` (empty: all three), after one untimed pass over the files (steady state: the
/// allocator's memory and the page cache warm).
pub fn ingest(
    inputs_given: &[String],
    repeat: usize,
    stages: &[IngestStage],
) -> anyhow::Result<IngestBench> {
    let wanted = |s: IngestStage| stages.is_empty() || stages.contains(&s);
    let files = if inputs_given.is_empty() {
        let dir = scbg_womd::fixtures::real_data_dir()
            .context("no --input and no shared real data folder")?;
        inputs::expand(&[
            dir.join("womd").display().to_string(),
            dir.join("womd-reencoded").display().to_string(),
            dir.join("nuscenes-reencoded").display().to_string(),
        ])?
    } else {
        inputs::expand(inputs_given)?
    };
    let repeat = repeat.max(1);
    let raw_bytes: u64 = files
        .iter()
        .map(|f| std::fs::metadata(f).map(|m| m.len()).unwrap_or(0))
        .sum();
    let work: Vec<PathBuf> = (0..repeat).flat_map(|_| files.iter().cloned()).collect();
    let all = rayon::current_num_threads();
    let mut out = IngestBench {
        files: files.len(),
        raw_bytes,
        repeat,
        rows: Vec::new(),
        prepared_bytes: None,
        peak_rss_mib: None,
    };
    let mb_per_s = |secs: f64| (raw_bytes * repeat as u64) as f64 / secs / 1e6;
    // One untimed pass of the heaviest stage asked for, over every file once at every thread:
    // the allocator's arena reaches its peak and the files are in the page cache, so the first
    // timed row does not pay the first touch of that memory (the steady state is what a long
    // `scbg data prepare` or training run sees).
    let heaviest = [IngestStage::Features, IngestStage::Prepare]
        .into_iter()
        .find(|&s| wanted(s));
    run_in_pool(all, || {
        files
            .par_iter()
            .map(|p| match heaviest {
                Some(s) => featurize_file(p, s == IngestStage::Features).map(|_| ()),
                None => decode_file(p).map(|_| ()),
            })
            .collect::<anyhow::Result<Vec<()>>>()
    })??;
    for threads in [1, all] {
        if wanted(IngestStage::Decode) {
            let t = Instant::now();
            let scenes: usize = run_in_pool(threads, || {
                work.par_iter()
                    .map(decode_file)
                    .collect::<anyhow::Result<Vec<_>>>()
            })??
            .iter()
            .sum();
            let secs = t.elapsed().as_secs_f64();
            out.rows.push(IngestRow {
                stage: "decode",
                threads,
                scenarios_per_s: scenes as f64 / secs,
                samples_per_s: None,
                raw_mb_per_s: mb_per_s(secs),
            });
        }
        for (stage, which, samples_too) in [
            ("decode+prepare", IngestStage::Prepare, false),
            ("decode+features", IngestStage::Features, true),
        ] {
            if !wanted(which) {
                continue;
            }
            let t = Instant::now();
            let results = run_in_pool(threads, || {
                work.par_iter()
                    .map(|p| featurize_file(p, samples_too))
                    .collect::<anyhow::Result<Vec<_>>>()
            })??;
            let secs = t.elapsed().as_secs_f64();
            let (scenes, samples): (usize, usize) = results
                .iter()
                .fold((0, 0), |acc, r| (acc.0 + r.0, acc.1 + r.1));
            if !samples_too {
                out.prepared_bytes = Some(results.iter().map(|r| r.2).sum::<u64>() / repeat as u64);
            }
            out.rows.push(IngestRow {
                stage,
                threads,
                scenarios_per_s: scenes as f64 / secs,
                samples_per_s: samples_too.then(|| samples as f64 / secs),
                raw_mb_per_s: mb_per_s(secs),
            });
        }
    }
    out.peak_rss_mib = peak_rss_mib();
    Ok(out)
}

/// Synthetic generate + encode throughput of `scenarios` scenarios at 1 thread and at every
/// thread: `(threads, scenarios/s, KB per scenario)` rows.
pub fn synth(scenarios: usize) -> anyhow::Result<Vec<(usize, f64, f64)>> {
    let families = scbg_synth::Family::DEFAULT;
    let all = rayon::current_num_threads();
    let mut rows = Vec::new();
    for threads in [1, all] {
        let t = Instant::now();
        let bytes: usize = run_in_pool(threads, || {
            (0..scenarios as u64)
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
        rows.push((
            threads,
            scenarios as f64 / secs,
            bytes as f64 / scenarios.max(1) as f64 / 1e3,
        ));
    }
    Ok(rows)
}

/// Time of the WOSAC realism metric for one scenario × 32 rollouts ([`wosac`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct WosacBench {
    /// The scenario scored.
    pub scenario_id: String,
    /// Sim agents (simulated objects) of the scenario.
    pub sim_agents: usize,
    /// Timed repetitions per baseline.
    pub repeats: usize,
    /// `(baseline, meta-metric, best ms, mean ms)` for log replay and constant velocity.
    pub rows: Vec<(String, f32, f64, f64)>,
}

impl WosacBench {
    /// The lines `scbg bench wosac` prints.
    pub fn to_text(&self) -> String {
        let mut s = format!(
            "WOSAC metrics, scenario {} ({} sim agents), 32 rollouts, 1 thread, {} repeats:\n",
            self.scenario_id, self.sim_agents, self.repeats
        );
        for (name, meta, best, mean) in &self.rows {
            s += &format!(
                "{name:<18} meta-metric {meta:.7}  best {best:.1} ms  mean {mean:.1} ms\n"
            );
        }
        s
    }
}

/// Times `scbg_metrics::wosac::scenario_metrics` on the first scenario of `file` (default: the
/// shared genuine one-scenario WOMD file) for log replay and constant velocity, on the calling
/// thread (the metric is single-threaded).
pub fn wosac(file: Option<&std::path::Path>, repeats: usize) -> anyhow::Result<WosacBench> {
    use scbg_metrics::wosac::{
        ROLLOUTS_PER_SCENARIO, WosacConfig, constant_velocity_rollouts, log_replay_rollouts,
        scenario_metrics, sim_agent_ids,
    };
    let path = match file {
        Some(p) => p.to_path_buf(),
        None => scbg_womd::fixtures::real_data_dir()
            .context("no --file and no shared real data folder")?
            .join("womd/motion_data_one_scenario.tfrecord"),
    };
    let womd = scbg_womd::WomdFile::open(&path)?;
    let scene = womd
        .scenes()
        .next()
        .with_context(|| format!("{}: no scenario", path.display()))??;
    let repeats = repeats.max(1);
    let mut rows = Vec::new();
    for (name, rollouts) in [
        (
            "log replay",
            log_replay_rollouts(&scene, ROLLOUTS_PER_SCENARIO)?,
        ),
        (
            "constant velocity",
            constant_velocity_rollouts(&scene, ROLLOUTS_PER_SCENARIO)?,
        ),
    ] {
        let mut times = Vec::with_capacity(repeats);
        let mut meta = f32::NAN;
        for _ in 0..repeats {
            let t = Instant::now();
            let m = scenario_metrics(&scene, &rollouts, WosacConfig::V2025)?;
            times.push(t.elapsed().as_secs_f64() * 1e3);
            meta = m.metametric;
        }
        let best = times.iter().copied().fold(f64::INFINITY, f64::min);
        let mean = times.iter().sum::<f64>() / times.len() as f64;
        rows.push((name.to_string(), meta, best, mean));
    }
    Ok(WosacBench {
        scenario_id: scene.scenario_id.clone(),
        sim_agents: sim_agent_ids(&scene).len(),
        repeats,
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ingest_times_the_stages_asked_for() {
        let Some(real) = scbg_womd::fixtures::real_data_dir() else {
            return;
        };
        let file = real.join("womd/motion_data_one_scenario.tfrecord");
        let input = [file.display().to_string()];
        let only = ingest(&input, 1, &[IngestStage::Features]).unwrap();
        assert!(!only.rows.is_empty());
        for r in &only.rows {
            assert_eq!(r.stage, "decode+features");
            assert!(r.samples_per_s.is_some_and(|v| v > 0.0));
        }
        assert_eq!(
            only.prepared_bytes, None,
            "the cache record is the prepare stage's"
        );
        assert!(only.to_text().contains("--stage prepare"));
        let all = ingest(&input, 1, &[]).unwrap();
        let stages: Vec<_> = all.rows.iter().take(3).map(|r| r.stage).collect();
        assert_eq!(stages, ["decode", "decode+prepare", "decode+features"]);
        assert_eq!(all.rows.len(), 3 * only.rows.len());
        let prepared = ingest(&input, 1, &[IngestStage::Prepare]).unwrap();
        assert!(prepared.prepared_bytes.is_some_and(|b| b > 0));
        assert_eq!(all.prepared_bytes, prepared.prepared_bytes);
        let decode = ingest(&input, 1, &[IngestStage::Decode]).unwrap();
        assert!(decode.rows.iter().all(|r| r.stage == "decode"));
    }
}
