//! Arguments of the commands that run a model: `generate`, `sim` and `serve` (and the
//! closed-loop settings `eval sim` shares).

use clap::Args;
use scbg::choices::Policy;
use std::path::PathBuf;

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
    /// Let the guard hold the synthetic world's B back for a reacting A at crossings, as if B
    /// were courteous. By default (since the thirty-fourth session; BENCHMARKS.md) B's plan
    /// takes the right of way while A can still stop braking at most 7 m/s².
    #[arg(long)]
    pub no_right_of_way: bool,
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
