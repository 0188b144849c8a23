//! Arguments of `bench`.

use clap::{Args, Subcommand};
use scbg::choices::Preset;
use std::path::PathBuf;

#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Decode and feature-extraction throughput on real files; cache size ratio.
    Ingest(BenchIngestArgs),
    /// Synthetic generator throughput.
    Synth(BenchSynthArgs),
    /// Predictor training step time and inference throughput.
    Train(BenchTrainArgs),
    /// WOSAC realism metric time for one scenario × 32 rollouts (1 thread).
    Wosac(BenchWosacArgs),
    /// Closed-loop rollout time with one generator agent, and WOSAC of 32 rollouts (1 thread).
    Sim(BenchSimArgs),
    /// Loopback load test of `POST /v1/generate` (latency percentiles, errors, peak RSS).
    Serve(BenchServeArgs),
    /// Loopback soak of the server: a long mixed load with ~10 % malformed requests, a burst of
    /// connections, clients that leave or trickle, idle sessions, a graceful shutdown (exit
    /// status 1 when a bar is missed).
    Soak(BenchSoakArgs),
    /// Crash safety: kill -9 each stage at seeded random moments, re-run it, and compare its
    /// outputs with an undisturbed run's (exit status 1 when any kill point fails).
    Kill(BenchKillArgs),
}

#[derive(Debug, Clone, Args)]
pub struct BenchSoakArgs {
    /// Generator or ensemble folder (the release model: models/courtesy).
    #[arg(long)]
    pub model: PathBuf,
    /// Requests per second of the mix.
    #[arg(long, default_value_t = 200.0)]
    pub rate: f64,
    /// Seconds of the mix.
    #[arg(long, default_value_t = 600.0)]
    pub seconds: f64,
    /// Connections opened at once after the mix.
    #[arg(long, default_value_t = 1000)]
    pub connections: usize,
    /// Clients trickling their headers.
    #[arg(long, default_value_t = 100)]
    pub slow_clients: usize,
    /// Inference workers of the server (default: the number of cores).
    #[arg(long)]
    pub workers: Option<usize>,
    /// Seeds the mix.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Clone, Args)]
pub struct BenchKillArgs {
    /// Working folder (the small world, the references and every killed run).
    #[arg(long)]
    pub work: PathBuf,
    /// Kill points per stage.
    #[arg(long, default_value_t = 20)]
    pub kills: usize,
    /// Seeds the kill delays and the small synthetic world.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Stages to kill (default: all): prepare, train_predictor, label, train_generator, sim,
    /// eval_sim.
    #[arg(long, value_delimiter = ',', value_parser = parse_kill_stage)]
    pub stages: Vec<scbg_lab::bench::KillStage>,
    /// Synthetic scenarios of the small world (more make every stage run longer).
    #[arg(long, default_value_t = 400)]
    pub scenarios: usize,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

fn parse_kill_stage(name: &str) -> Result<scbg_lab::bench::KillStage, String> {
    scbg_lab::bench::KillStage::parse(name).ok_or_else(|| {
        let names: Vec<&str> = scbg_lab::bench::KillStage::ALL
            .iter()
            .map(|s| s.name())
            .collect();
        format!("unknown stage {name:?}; one of {}", names.join(", "))
    })
}

#[derive(Debug, Clone, Args)]
pub struct BenchServeArgs {
    /// Generator folder (a demo's out/demo/generator_full).
    #[arg(long)]
    pub model: PathBuf,
    /// Requests per second.
    #[arg(long, default_value_t = 200.0)]
    pub rate: f64,
    /// Seconds of load.
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
    /// Inference workers of the server (default: the number of cores).
    #[arg(long)]
    pub workers: Option<usize>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Clone, Args)]
pub struct BenchSimArgs {
    #[command(flatten)]
    pub model: super::run::ModelArgs,
    /// Synthetic scenes to time.
    #[arg(long, default_value_t = 12)]
    pub scenes: usize,
    /// Steps between plans (default: the policy's own cadence, 20).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=80))]
    pub replan_every: Option<u64>,
}

#[derive(Debug, Clone, Args)]
pub struct BenchWosacArgs {
    /// A WOMD Scenario TFRecord (default: the shared genuine one-scenario file).
    #[arg(long)]
    pub file: Option<PathBuf>,
    /// Timed repetitions per baseline.
    #[arg(long, default_value_t = 10)]
    pub repeats: usize,
}

#[derive(Debug, Clone, Args)]
pub struct BenchTrainArgs {
    /// Model presets to measure.
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "cpu-small,paper"
    )]
    pub presets: Vec<Preset>,
    /// Backend to measure (`flex`; `tch`, `cuda`, `vulkan` when built with them).
    #[arg(long, default_value = "flex")]
    pub backend: String,
    #[arg(long, default_value_t = 32)]
    pub batch: usize,
    /// Timed training steps per preset (each ends with a device sync).
    #[arg(long, default_value_t = 5)]
    pub steps: usize,
    /// Untimed warm-up steps before them (a GPU backend compiles and autotunes its kernels in
    /// these).
    #[arg(long, default_value_t = 1)]
    pub warmup: usize,
    /// Data-parallel chunks: each step splits the batch into this many chunks, runs their
    /// forward and backward passes in parallel (one model fork each) and sums the gradients.
    #[arg(long, default_value_t = 1)]
    pub chunks: usize,
}

#[derive(Debug, Clone, Args)]
pub struct BenchIngestArgs {
    /// Input files (default: every file under the shared real-data folder).
    #[arg(long, num_args = 1..)]
    pub input: Vec<String>,
    /// Repeat the file list this many times, to time more than a blink.
    #[arg(long, default_value_t = 20)]
    pub repeat: usize,
    /// Time only these stages (repeatable; default: all), e.g. to profile one of them.
    #[arg(long, value_enum)]
    pub stage: Vec<scbg_lab::bench::IngestStage>,
}

#[derive(Debug, Clone, Args)]
pub struct BenchSynthArgs {
    #[arg(long, default_value_t = 4000)]
    pub scenarios: usize,
}
