//! Arguments of `data` and `synth`.

use clap::{Args, Subcommand};
use scbg::choices::Family;
use std::path::PathBuf;

#[derive(Debug, Subcommand)]
pub enum DataCommand {
    /// Summarise WOMD files (Scenario or tf.Example TFRecords, auto-detected).
    Inspect(InspectArgs),
    /// Draw a bird's-eye view of one scenario as PNG.
    Render(RenderArgs),
    /// Build the prepared, memory-mappable cache of windows and pairs.
    Prepare(PrepareArgs),
    /// Write the log-replay or constant-velocity baseline of WOMD scenarios as a WOSAC
    /// submission (one shard per scenario file), the reference for `eval wosac`.
    WosacBaseline(WosacBaselineArgs),
}

#[derive(Debug, Clone, Args)]
pub struct WosacBaselineArgs {
    /// WOMD scenario files (globs, folders or paths).
    #[arg(long, required = true, num_args = 1..)]
    pub scenarios: Vec<String>,
    /// Which baseline.
    #[arg(long, value_enum, default_value_t = scbg::wosac::Baseline::LogReplay)]
    pub baseline: scbg::wosac::Baseline,
    /// Output folder for the shards NAME.binproto-IIIII-of-NNNNN.
    #[arg(long)]
    pub out: PathBuf,
    /// Base name of the shards (the submission's method name).
    #[arg(long, default_value = "baseline")]
    pub name: String,
}

#[derive(Debug, Clone, Args)]
pub struct InspectArgs {
    /// Files to inspect.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Print one JSON object per scenario per line.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Clone, Args)]
pub struct RenderArgs {
    /// File holding the scenario.
    pub file: PathBuf,
    /// Output PNG.
    #[arg(long)]
    pub out: PathBuf,
    /// Which scenario of the file (0-based record index).
    #[arg(long, default_value_t = 0)]
    pub index: usize,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 1000)]
    pub size_px: u32,
}

#[derive(Debug, Clone, Args)]
pub struct PrepareArgs {
    /// Input files: glob patterns or paths.
    #[arg(long, required = true, num_args = 1..)]
    pub input: Vec<String>,
    /// Output folder for shards and the manifest.
    #[arg(long)]
    pub out: PathBuf,
    /// Prepare only the shards with `shard % num_shards == shard_index` (for several machines).
    #[arg(long, default_value_t = 0)]
    pub shard_index: usize,
    #[arg(long, default_value_t = 1)]
    pub num_shards: usize,
    /// Input files per shard.
    #[arg(long, default_value_t = 16)]
    pub files_per_shard: usize,
    /// Window stride in steps for scenarios longer than one window.
    #[arg(long, default_value_t = 10)]
    pub stride_steps: usize,
    /// Pair mining: maximum distance between the two future paths, metres.
    #[arg(long, default_value_t = 3.0)]
    pub pair_distance_m: f64,
    /// Pair mining: maximum difference of arrival times at the conflict point, seconds.
    #[arg(long, default_value_t = 4.0)]
    pub pair_time_gap_s: f64,
}

#[derive(Debug, Clone, Args)]
pub struct SynthArgs {
    /// Number of scenarios to generate.
    #[arg(long, default_value_t = 1000)]
    pub scenarios: usize,
    /// Random seed; the same seed gives the same files.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Scene families to draw from (comma-separated; the default world is every family but
    /// leftturn and zipper).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "merge,crossing,cutin,following,letin,roundabout"
    )]
    pub families: Vec<Family>,
    /// Families held out of training (comma-separated): their scenes' ids end with `+unseen`,
    /// which puts them in every stage's held-out split, so they are only evaluated.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub held_out: Vec<Family>,
    /// Scenarios per output TFRecord file.
    #[arg(long, default_value_t = 250)]
    pub scenarios_per_file: usize,
    /// Counterfactual siblings per scenario (B's future re-drawn from its courtesy prior,
    /// everyone else reacting), written to OUT/counterfactual/ for `scbg train`'s
    /// `counterfactual_cache`.
    #[arg(long, default_value_t = 0)]
    pub counterfactuals: usize,
}
