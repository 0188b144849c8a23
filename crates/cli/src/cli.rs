//! Command-line arguments.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};
use scbg::choices::{
    Family, MarginalEstimate, Policy, Preset, Reward, Threshold, Variant, Weighting,
};
use scbg::predictor::{ModeSelection, SplitSelection};

/// Socially-controllable behavior generation for interactive traffic simulation.
#[derive(Debug, Parser)]
#[command(name = "scbg", version, about, long_about = None)]
pub struct Cli {
    /// Worker threads for parallel stages (default: all cores).
    #[arg(long, global = true)]
    pub threads: Option<usize>,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the whole pipeline on synthetic data (default) or your WOMD files and write a report.
    Demo(DemoArgs),
    /// Read, inspect, render and prepare WOMD data.
    #[command(subcommand)]
    Data(DataCommand),
    /// Generate synthetic interactive two-vehicle scenarios as WOMD Scenario TFRecords.
    Synth(SynthArgs),
    /// Auto-label the courtesy ψ of interacting pairs with a trained predictor (Parquet).
    Label(LabelArgs),
    /// Train models.
    #[command(subcommand)]
    Train(TrainCommand),
    /// Generate B's future at a chosen courtesy quantile for a pair in a WOMD scenario file.
    Generate(GenerateArgs),
    /// Closed-loop simulation: courtesy-controlled agents re-planned by the generator, A and
    /// the others reactive; rollouts exported as Scenario TFRecords or a WOSAC shard.
    Sim(SimArgs),
    /// Serve a model over HTTP to simulators: generate, courtesy, closed-loop sessions
    /// (OpenAPI at /openapi.json, docs at /docs).
    Serve(ServeArgs),
    /// Evaluate models and predictions.
    #[command(subcommand)]
    Eval(EvalCommand),
    /// Measure throughput of the pipeline stages.
    #[command(subcommand)]
    Bench(BenchCommand),
}

#[derive(Debug, Clone, Args)]
pub struct DemoArgs {
    /// Output folder (data, cache, checkpoints, figures, report.md, report.json).
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Your WOMD files (globs or paths) instead of generated data.
    #[arg(long, num_args = 1..)]
    pub data: Vec<String>,
    /// Synthetic scenarios to generate when --data is not given.
    #[arg(long, default_value_t = 1500)]
    pub scenarios: usize,
    /// Counterfactual siblings per synthetic scenario (B's future re-drawn with courtesy 1/6,
    /// 1/2, 5/6, …, everyone else reacting) added to the predictor's training as conditional
    /// samples of A: interventional data, which the labels need to rank B's futures like the
    /// simulator does (BENCHMARKS.md, issue 11); 0 trains on the logged scenes only, as the
    /// paper does. Ignored with --data.
    #[arg(long, default_value_t = 3)]
    pub counterfactuals: usize,
    /// Tell the generators who A is (A's position, heading and velocity in B's frame after B's
    /// embedding); off by default (BENCHMARKS.md, issue 12).
    #[arg(long)]
    pub condition_on_a: bool,
    /// Train the predictor with B's future also in A's lane frame (arc length along and
    /// offset from A's lane); `--lane-frame false` gives B's future in A's frame only, as the
    /// paper does (BENCHMARKS.md, issue 11).
    #[arg(
        long,
        default_value_t = true,
        action = clap::ArgAction::Set,
        num_args = 0..=1,
        default_missing_value = "true",
        value_name = "BOOL"
    )]
    pub lane_frame: bool,
    /// Train the predictor with B's future acting step by step on A's decoder (A's steps in
    /// each 0.5 s block react only to B's future up to the block's start: interventional
    /// conditioning); `--stepwise false` fuses B's whole future into one vector, as the paper's
    /// conditional model does (BENCHMARKS.md, issue 11).
    #[arg(
        long,
        default_value_t = true,
        action = clap::ArgAction::Set,
        num_args = 0..=1,
        default_missing_value = "true",
        value_name = "BOOL"
    )]
    pub stepwise: bool,
    /// Predictor training epochs.
    #[arg(long, default_value_t = 30)]
    pub epochs: usize,
    /// Predictors to train (seeds --seed, --seed + 1, …) and label with as an ensemble (ψ
    /// averaged; the first one is the generators' J_φ). Each adds a predictor training
    /// (~5 minutes on 2 cores); 1 by default (BENCHMARKS.md, issue 11).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=16))]
    pub predictors: u64,
    /// Training epochs of each generator variant.
    #[arg(long, default_value_t = 6)]
    pub generator_epochs: usize,
    /// Seeds of the generator stage (trained side by side; the report gives seed means).
    #[arg(long, default_value_t = 3)]
    pub generator_seeds: usize,
    /// Weight β of the courtesy loss (in units of the labels' ψ spread) for the full variant.
    #[arg(long, default_value_t = 1.0)]
    pub beta: f32,
    /// How the generators form B's future.
    #[arg(long, value_enum, default_value_t = Head::Modes)]
    pub head: Head,
    /// With `--head modes`: the generator also scores each of B's modes by its own courtesy
    /// (J_φ of the mode toward A) against the requested ψ, so that it can tell which of this
    /// scene's modes helps A, and commits to its likeliest mode outside training instead of
    /// blending them; `--mode-courtesy false` gives the earlier blend of modes chosen from B's
    /// embedding alone (BENCHMARKS.md, issues 11/12).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub mode_courtesy: bool,
    /// Held-out scenes of the closed-loop stage (0 skips it).
    #[arg(long, default_value_t = 60)]
    pub closed_loop_scenes: usize,
    #[command(flatten)]
    pub estimator: EstimatorArgs,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// How courtesy labels estimate E[r(Y_A) | x] and sample B's futures (shared by `label`,
/// `train generator` and `demo`).
#[derive(Debug, Clone, Args)]
pub struct EstimatorArgs {
    /// How E[r(Y_A) | x] is estimated: `conditional-average` (mean of the conditional
    /// expectations over the sampled futures of B; removes the per-scene offset between the two
    /// modes) or `direct` (the marginal mode, as in the paper).
    #[arg(long, value_enum, default_value_t = MarginalEstimate::ConditionalAverage)]
    pub marginal: MarginalEstimate,
    /// Scale of the Gaussian part of B's sampled futures: 1 samples the predicted mixture,
    /// 0 takes mode means drawn by their probabilities (cleaner futures from a weak predictor).
    #[arg(long, default_value_t = 1.0)]
    pub sample_noise: f32,
    /// Whose reward B's courtesy counts: `pair` (A alone, the paper) or `neighbours` (A and
    /// every vehicle within --audience-radius-m of B at the current step, at most 7 besides A).
    #[arg(long, default_value = "pair", value_parser = ["pair", "neighbours"])]
    pub audience: String,
    /// Radius of the `neighbours` audience around B, metres.
    #[arg(long, default_value_t = 30.0)]
    pub audience_radius_m: f32,
    /// Weights of the `neighbours` audience: `sum` (each member 1) or `proximity`
    /// (1 / (1 + distance / radius)).
    #[arg(long, value_enum, default_value_t = Weighting::Sum)]
    pub audience_weighting: Weighting,
}

#[derive(Debug, Clone, Args)]
pub struct LabelArgs {
    /// Predictor checkpoint folder. Give it several times for an ensemble: ψ is averaged over
    /// the predictors (B's sampled futures come from the first one's marginal, every predictor
    /// scores the same futures).
    #[arg(long, required = true)]
    pub model: Vec<PathBuf>,
    /// Prepared cache folder.
    #[arg(long)]
    pub data: PathBuf,
    /// Output folder: labels-NNNNN.parquet per cache shard, psi_histogram.png, summary.json.
    #[arg(long)]
    pub out: PathBuf,
    /// Trajectories sampled from B's marginal prediction per pair and role (augmentation).
    #[arg(long, default_value_t = 8)]
    pub samples: usize,
    /// Reward r(y_A).
    #[arg(long, value_enum, default_value_t = Reward::AverageSpeed)]
    pub reward: Reward,
    #[command(flatten)]
    pub estimator: EstimatorArgs,

    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Synthetic ground truth (ground_truth.jsonl): the latent-courtesy check and the fidelity
    /// report against the simulator's ψ_true (psi_fidelity.png).
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Label only the cache shards with `shard % num_shards == shard_index` (several workers
    /// sharing --out; no summary). Run again without --num-shards to merge: every table is read
    /// back and the summary written.
    #[arg(long, default_value_t = 0)]
    pub shard_index: usize,
    #[arg(long, default_value_t = 1)]
    pub num_shards: usize,
}

#[derive(Debug, Subcommand)]
pub enum TrainCommand {
    /// Train the Multipath++ predictor (marginal + conditional) on a prepared cache.
    Predictor(TrainPredictorArgs),
    /// Train the SCBG generator g(x, ψ) and the courtesy range predictor.
    Generator(TrainGeneratorArgs),
}

#[derive(Debug, Clone, Args)]
pub struct TrainGeneratorArgs {
    /// Trained predictor checkpoint (its encoder is frozen; it also provides J_φ).
    #[arg(long)]
    pub predictor: PathBuf,
    /// Prepared cache folder (its training split by scenario id, as for the predictor).
    #[arg(long)]
    pub data: PathBuf,
    /// Output folder: generator.bpk, range.bpk, generator.json.
    #[arg(long)]
    pub out: PathBuf,
    /// baseline (①), aug (① + ②) or full (① + ② + ③ courtesy loss).
    #[arg(long, value_enum, default_value_t = Variant::Full)]
    pub variant: Variant,
    #[arg(long, default_value_t = 10)]
    pub epochs: usize,
    /// Futures sampled from B's marginal prediction per pair role.
    #[arg(long, default_value_t = 8)]
    pub samples: usize,
    #[command(flatten)]
    pub estimator: EstimatorArgs,

    #[arg(long, default_value_t = 32)]
    pub batch_size: usize,
    /// Weight α of the sampled futures' trajectory loss.
    #[arg(long, default_value_t = 0.5)]
    pub alpha: f32,
    /// Weight β of the courtesy loss.
    #[arg(long, default_value_t = 1.0)]
    pub beta: f32,
    /// High-courtesy threshold for 50/50 batches: a number (m/s, the paper uses 2) or `qX`
    /// for a quantile of the logged |ψ| (default q0.8, since ψ's scale depends on the data).
    #[arg(long, default_value = "q0.8")]
    pub threshold: Threshold,
    #[arg(long, default_value_t = 1e-3)]
    pub learning_rate: f64,
    /// Range-predictor optimisation steps (full batch).
    #[arg(long, default_value_t = 300)]
    pub range_steps: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Tell the generator and range predictor who A is (A's context after B's embedding).
    #[arg(long)]
    pub condition_on_a: bool,
    /// Synthetic data only, an experiment: train on the simulator's ψ_true instead of the
    /// predictor's labels (the ground-truth sidecar `ground_truth.jsonl` of `scbg synth`). Keeps
    /// the ground truth's pair role of each scene, the one the oracle scores.
    #[arg(long, value_name = "GROUND_TRUTH_JSONL")]
    pub oracle_labels: Option<PathBuf>,
    /// With --oracle-labels: replace B's sampled futures by K futures of the synthetic world's
    /// own B, driving with courtesy (k + 0.5) / K from the current step on (everyone else
    /// reacting), each scored by the oracle.
    #[arg(
        long,
        value_name = "K",
        default_value_t = 0,
        requires = "oracle_labels"
    )]
    pub world_futures: usize,
    #[arg(long, value_enum, default_value_t = Head::Modes)]
    pub head: Head,
    /// With `--head modes`: the generator also scores each of B's modes by its own courtesy
    /// (J_φ of the mode toward A) against the requested ψ, so that it can tell which of this
    /// scene's modes helps A, and commits to its likeliest mode outside training instead of
    /// blending them; `--mode-courtesy false` gives the earlier blend of modes chosen from B's
    /// embedding alone (BENCHMARKS.md, issues 11/12).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub mode_courtesy: bool,
}

/// How the generator forms B's future (`--head`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Head {
    /// A ψ-dependent choice among the frozen predictor's marginal modes of B plus a regressed
    /// displacement (the default since it follows the knob better in truth; BENCHMARKS.md,
    /// *A generator that chooses among B's modes*).
    Modes,
    /// One regressed trajectory (generators before the option).
    Regression,
}

#[derive(Debug, Clone, Args)]
pub struct TrainPredictorArgs {
    /// TOML training config (defaults are used for missing keys; no file = all defaults).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Prepared cache folder (`scbg data prepare`).
    #[arg(long)]
    pub data: PathBuf,
    /// Checkpoint folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Continue from the checkpoint in --out.
    #[arg(long)]
    pub resume: bool,
}

#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Evaluate a trained predictor (and baselines) on a prepared cache: the paper's Table I.
    Predictor(EvalPredictorArgs),
    /// Waymo motion metrics of external predictions (JSON) against WOMD scenario files.
    Metrics(EvalMetricsArgs),
    /// Evaluate SCBG generator variants: CourtesyMSE, TrajADE, correlation (paper Table II,
    /// Figs. 4 and 5).
    Scbg(EvalScbgArgs),
    /// The courtesy knob in closed loop: realised courtesy, A's speed, B's collisions and
    /// off-road, WOSAC realism per quantile, beside log replay, constant velocity and IDM.
    Sim(EvalSimArgs),
}

/// Closed-loop settings shared by `sim` and `eval sim`.
#[derive(Debug, Clone, Args)]
pub struct LoopArgs {
    /// Steps between the controlled agents' plans (1..=80; default 20, 2 s, for either
    /// policy: `scbg::sim::default_replan_every`).
    #[arg(long)]
    pub replan_every: Option<usize>,
    /// How A (the ego) moves.
    #[arg(long, value_enum, default_value_t = scbg::sim::EgoMode::Reactive)]
    pub ego: scbg::sim::EgoMode,
    /// How the agents that are neither A nor controlled move.
    #[arg(long, value_enum)]
    pub others: Option<scbg::sim::OthersMode>,
    /// Follow the plans without the safety guard (no cap by IDM toward agents ahead or
    /// crossing conflicts, no steering bound beside another agent).
    #[arg(long)]
    pub no_safety_guard: bool,
    /// Pull every plan point to within this many metres of the nearest car-lane centre line
    /// before it is followed (lane keeping).
    #[arg(long, default_value_t = scbg::sim::DEFAULT_LANE_KEEPING_M)]
    pub lane_keeping_m: f64,
    /// Follow the plans as generated, without lane keeping.
    #[arg(long, conflicts_with = "lane_keeping_m")]
    pub no_lane_keeping: bool,
}

#[derive(Debug, Clone, Args)]
pub struct SimArgs {
    /// Generator folder (`scbg train generator --out`, or a demo's `generator_full_s0`).
    #[arg(long)]
    pub model: PathBuf,
    /// Predictor folder, overriding the one recorded in generator.json.
    #[arg(long)]
    pub predictor: Option<PathBuf>,
    /// How a courtesy becomes B's future.
    #[arg(long, value_enum, default_value_t = Policy::Generator)]
    pub policy: Policy,
    /// WOMD Scenario TFRecord file.
    #[arg(long)]
    pub scenario: PathBuf,
    /// Which scenario of the file (default: the first with A and B).
    #[arg(long)]
    pub scenario_id: Option<String>,
    /// Track id of A, the ego.
    #[arg(long)]
    pub a: i64,
    /// Track id of B, the controlled agent.
    #[arg(long)]
    pub b: i64,
    /// B's courtesy quantile in [0, 1].
    #[arg(long, default_value_t = 0.5, conflicts_with = "psi")]
    pub quantile: f32,
    /// B's explicit ψ instead of a quantile.
    #[arg(long, allow_negative_numbers = true)]
    pub psi: Option<f32>,
    /// More controlled agents, each `ID=QUANTILE` (courteous toward A too).
    #[arg(long, num_args = 1..)]
    pub also: Vec<String>,
    #[command(flatten)]
    pub loop_args: LoopArgs,
    /// Synthetic ground truth (default: ground_truth.jsonl beside the file, if it has the
    /// scenario): the synthetic world's rule is the reactive one.
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Reactive agents use IDM even on a synthetic scene.
    #[arg(long)]
    pub no_synthetic_world: bool,
    /// Rollouts (default 1; 32 for --format wosac), spread over a band of quantiles.
    #[arg(long)]
    pub rollouts: Option<usize>,
    /// Width of that band.
    #[arg(long, default_value_t = 0.2)]
    pub spread: f32,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// `scenario` (rollouts.tfrecord) or `wosac` (NAME.binproto-00000-of-00001).
    #[arg(long, value_enum, default_value_t = scbg::sim::ExportFormat::Scenario)]
    pub format: scbg::sim::ExportFormat,
    /// Method name of the WOSAC submission.
    #[arg(long, default_value = "scbg")]
    pub name: String,
}

#[derive(Debug, Clone, Args)]
pub struct EvalSimArgs {
    /// Generator folder.
    #[arg(long)]
    pub model: PathBuf,
    /// Predictor folder, overriding the one recorded in generator.json.
    #[arg(long)]
    pub predictor: Option<PathBuf>,
    /// How a courtesy becomes B's future.
    #[arg(long, value_enum, default_value_t = Policy::Generator)]
    pub policy: Policy,
    /// WOMD Scenario files (globs, folders or paths).
    #[arg(long, required = true, num_args = 1..)]
    pub data: Vec<String>,
    /// Synthetic ground truth (ground_truth.jsonl): the synthetic rule drives A and the others.
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Scenes on the validation split (by scenario id, as in training) or all.
    #[arg(long, value_enum, default_value_t = SplitSelection::Validation)]
    pub split: SplitSelection,
    /// Scenes of the courtesy curve.
    #[arg(long, default_value_t = 40)]
    pub scenes: usize,
    /// Scenes scored with WOSAC realism (32 rollouts per quantile and baseline).
    #[arg(long, default_value_t = 8)]
    pub wosac_scenes: usize,
    /// Quantiles scored with WOSAC realism (32 rollouts each).
    #[arg(long, num_args = 1.., default_values_t = [0.1f32, 0.5, 0.9])]
    pub wosac_quantiles: Vec<f32>,
    /// Width of the band of quantiles a quantile's 32 WOSAC rollouts spread over (1 with
    /// quantile 0.5: the rollouts cover the whole range, the knob drawn from its prior).
    #[arg(long, default_value_t = 0.2)]
    pub spread: f32,
    #[command(flatten)]
    pub loop_args: LoopArgs,
    /// Output folder (eval_sim.json, sim_courtesy.png, sim_realism.png).
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Clone, Args)]
pub struct EvalScbgArgs {
    /// Generator folders (`scbg train generator --out`), one per variant; they must share one
    /// predictor.
    #[arg(long, required = true, num_args = 1..)]
    pub model: Vec<PathBuf>,
    /// Prepared cache folder.
    #[arg(long)]
    pub data: PathBuf,
    /// Predictor folder, overriding the one recorded in generator.json.
    #[arg(long)]
    pub predictor: Option<PathBuf>,
    /// Evaluate on the validation split (by scenario id) or on every pair.
    #[arg(long, value_enum, default_value_t = SplitSelection::Validation)]
    pub split: SplitSelection,
    /// Synthetic ground truth (ground_truth.jsonl): also score the generated futures with the
    /// simulator's oracle (Spearman(quantile, ψ_true)).
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Folder for the figures (fig4_quantile_courtesy.png, fig5a_*.png, fig5b_*.png).
    #[arg(long)]
    pub figures: Option<PathBuf>,
    /// Futures of B sampled per held-out pair role (default: as many as the training labels
    /// drew): the candidates of the `ranked` row and of the selection yardsticks. With the
    /// conditional-average estimator E[r(Y_A) | x] is their mean, so every row's ψ moves a
    /// little with it.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub samples: Option<u64>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Clone, Args)]
pub struct GenerateArgs {
    /// Generator folder (`scbg train generator --out`).
    #[arg(long)]
    pub model: PathBuf,
    /// Predictor folder, overriding the one recorded in generator.json.
    #[arg(long)]
    pub predictor: Option<PathBuf>,
    /// How a courtesy becomes B's future.
    #[arg(long, value_enum, default_value_t = Policy::Generator)]
    pub policy: Policy,
    /// WOMD Scenario or tf.Example TFRecord file.
    #[arg(long)]
    pub scenario: PathBuf,
    /// Which scenario of the file (default: the first with both tracks).
    #[arg(long)]
    pub scenario_id: Option<String>,
    /// Track id of A (whose reward the courtesy is about).
    #[arg(long)]
    pub a: i64,
    /// Track id of B (the generated agent).
    #[arg(long)]
    pub b: i64,
    /// Courtesy quantiles in [0, 1] (0.1 and 0.9 are the predicted range's ends).
    #[arg(long, num_args = 1.., required_unless_present = "psi")]
    pub quantile: Vec<f32>,
    /// Explicit courtesy values ψ (m/s for the default reward) instead of quantiles.
    #[arg(long, num_args = 1.., allow_negative_numbers = true, conflicts_with = "quantile")]
    pub psi: Vec<f32>,
    /// Write the trajectories as JSON here instead of stdout.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Draw the scene with the generated futures of B.
    #[arg(long)]
    pub render: Option<PathBuf>,
}

#[derive(Debug, Clone, Args)]
pub struct EvalPredictorArgs {
    /// Checkpoint folder.
    #[arg(long)]
    pub model: PathBuf,
    /// Prepared cache folder.
    #[arg(long)]
    pub data: PathBuf,
    /// Which mode to report (both by default).
    #[arg(long, value_enum, default_value_t = ModeSelection::Both)]
    pub mode: ModeSelection,
    /// Evaluate on the validation split (by scenario id, as in training) or on everything.
    #[arg(long, value_enum, default_value_t = SplitSelection::Validation)]
    pub split: SplitSelection,
    /// Use the current Waymo trajectory-classifier thresholds instead of the pre-2024 ones.
    #[arg(long)]
    pub current_thresholds: bool,
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Clone, Args)]
pub struct EvalMetricsArgs {
    /// Scenario files (globs or paths).
    #[arg(long, required = true, num_args = 1..)]
    pub scenarios: Vec<String>,
    /// Predictions JSON (schema in README).
    #[arg(long)]
    pub predictions: PathBuf,
    #[arg(long)]
    pub current_thresholds: bool,
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Subcommand)]
pub enum DataCommand {
    /// Summarise WOMD files (Scenario or tf.Example TFRecords, auto-detected).
    Inspect(InspectArgs),
    /// Draw a bird's-eye view of one scenario as PNG.
    Render(RenderArgs),
    /// Build the prepared, memory-mappable cache of windows and pairs.
    Prepare(PrepareArgs),
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
    /// Scene families to draw from (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "merge,crossing,cutin"
    )]
    pub families: Vec<Family>,
    /// Scenarios per output TFRecord file.
    #[arg(long, default_value_t = 250)]
    pub scenarios_per_file: usize,
    /// Counterfactual siblings per scenario (B's future re-drawn from its courtesy prior,
    /// everyone else reacting), written to OUT/counterfactual/ for `scbg train`'s
    /// `counterfactual_cache`.
    #[arg(long, default_value_t = 0)]
    pub counterfactuals: usize,
}

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
}

#[derive(Debug, Clone, Args)]
pub struct ServeArgs {
    /// Generator folder (e.g. out/demo/generator_full).
    #[arg(long)]
    pub model: PathBuf,
    /// Predictor folder, overriding the one recorded in generator.json.
    #[arg(long)]
    pub predictor: Option<PathBuf>,
    /// How a courtesy becomes B's future.
    #[arg(long, value_enum, default_value_t = Policy::Generator)]
    pub policy: Policy,
    /// Address to bind; anything but loopback needs --token.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub addr: std::net::SocketAddr,
    /// Bearer token every API request must carry (also from SCBG_TOKEN).
    #[arg(long, env = "SCBG_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Folder whose WOMD files `POST /v1/scenarios/open` may read (nothing outside it).
    #[arg(long)]
    pub data_dir: Option<PathBuf>,
    /// Inference jobs at once (default: the number of cores).
    #[arg(long)]
    pub workers: Option<usize>,
    /// Largest request body, MiB.
    #[arg(long, default_value_t = 16)]
    pub max_body_mib: usize,
    /// Time limit of one request's inference, seconds.
    #[arg(long, default_value_t = 30)]
    pub timeout_s: u64,
    /// Close sessions idle this long, seconds.
    #[arg(long, default_value_t = 600)]
    pub session_ttl_s: u64,
}

#[derive(Debug, Clone, Args)]
pub struct BenchServeArgs {
    /// Generator folder (e.g. out/demo/generator_full).
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
    /// Generator folder (e.g. a demo's `generator_full_s0`).
    #[arg(long)]
    pub model: PathBuf,
    /// Predictor folder, overriding the one recorded in generator.json.
    #[arg(long)]
    pub predictor: Option<PathBuf>,
    /// How a courtesy becomes B's future.
    #[arg(long, value_enum, default_value_t = Policy::Generator)]
    pub policy: Policy,
    /// Synthetic scenes to time.
    #[arg(long, default_value_t = 12)]
    pub scenes: usize,
    /// Steps between plans (default: the policy's own cadence, 20; the speed bar is
    /// set at 10).
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
    /// Timed training steps per preset (after one warm-up step).
    #[arg(long, default_value_t = 5)]
    pub steps: usize,
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
    pub stage: Vec<scbg::bench::IngestStage>,
}

#[derive(Debug, Clone, Args)]
pub struct BenchSynthArgs {
    #[arg(long, default_value_t = 4000)]
    pub scenarios: usize,
}

#[cfg(test)]
mod tests {
    use clap::{CommandFactory, Parser};

    use super::{Cli, Command};

    #[test]
    fn the_command_line_is_well_formed() {
        Cli::command().debug_assert();
    }

    #[test]
    fn the_demo_predictor_switches_default_on_and_turn_off_by_value() {
        let demo =
            |args: &[&str]| match Cli::try_parse_from(["scbg", "demo"].iter().chain(args).copied())
                .unwrap()
                .command
            {
                Command::Demo(d) => (d.stepwise, d.lane_frame, d.counterfactuals),
                _ => unreachable!(),
            };
        assert_eq!(demo(&[]), (true, true, 3));
        assert_eq!(
            demo(&[
                "--stepwise",
                "false",
                "--lane-frame",
                "false",
                "--counterfactuals",
                "0"
            ]),
            (false, false, 0)
        );
        // The bare flags of earlier versions still mean "on".
        assert_eq!(demo(&["--stepwise", "--lane-frame"]), (true, true, 3));
        assert!(Cli::try_parse_from(["scbg", "demo", "--stepwise", "maybe"]).is_err());
    }
}
