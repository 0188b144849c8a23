//! Arguments of the commands that run a model: `generate`, `sim` and `serve` (and the model
//! and pair groups others share).

use clap::Args;
use scbg::choices::Policy;
use std::path::PathBuf;

/// The model a command runs (shared by `generate`, `sim`, `serve`, `eval sim`, `bench sim`).
#[derive(Debug, Clone, Args)]
pub struct ModelArgs {
    /// Generator folder (`scbg train generator --out`, or a demo's `generator_full`), or an
    /// ensemble folder whose `ensemble.json` lists generator folders (`models/courtesy`).
    #[arg(long)]
    pub model: PathBuf,
    /// Predictor folder, overriding the one recorded in generator.json (every member's).
    #[arg(long)]
    pub predictor: Option<PathBuf>,
    /// How a courtesy becomes B's future: the learned generator, or sample and rank.
    #[arg(long, value_enum, default_value_t = Policy::Generator)]
    pub policy: Policy,
}

impl ModelArgs {
    /// The runtime's load options.
    pub fn load(&self) -> anyhow::Result<scbg::Model> {
        scbg::Model::load(
            &self.model,
            &scbg::LoadOptions {
                predictor: self.predictor.clone(),
                policy: self.policy,
                ..Default::default()
            },
        )
    }
}

/// The pair of one scenario a command works on (shared by `generate` and `sim`).
#[derive(Debug, Clone, Args)]
pub struct PairArgs {
    /// WOMD Scenario or tf.Example TFRecord file.
    #[arg(long)]
    pub scenario: PathBuf,
    /// Which scenario of the file (default: the first with A and B).
    #[arg(long)]
    pub scenario_id: Option<String>,
    /// Track id of A (whose reward the courtesy is about; the ego in `sim`).
    #[arg(long)]
    pub a: i64,
    /// Track id of B (the generated, controlled agent).
    #[arg(long)]
    pub b: i64,
}

#[derive(Debug, Clone, Args)]
pub struct SimArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    #[command(flatten)]
    pub pair: PairArgs,
    /// B's courtesy quantile in [0, 1].
    #[arg(long, default_value_t = 0.5, conflicts_with = "psi")]
    pub quantile: f32,
    /// B's explicit ψ instead of a quantile.
    #[arg(long, allow_negative_numbers = true)]
    pub psi: Option<f32>,
    /// More controlled agents, each `ID=QUANTILE` (courteous toward A too).
    #[arg(long, num_args = 1..)]
    pub also: Vec<String>,
    /// Output folder: rollouts.tfrecord (or the WOSAC shard) and sim.json.
    #[arg(long)]
    pub out: PathBuf,
    /// Settings file whose `[closed_loop]` table sets how A and the others move, the
    /// replanning, the rollouts and the export format (docs/pipeline.toml). The synthetic
    /// world drives the reactive agents when `ground_truth.jsonl` beside the scenario file
    /// describes the scenario.
    #[arg(long)]
    pub config: Option<PathBuf>,
}

#[derive(Debug, Clone, Args)]
pub struct GenerateArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    #[command(flatten)]
    pub pair: PairArgs,
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
    #[command(flatten)]
    pub model: ModelArgs,
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
    /// Connections open at once; one more is answered 503 and closed.
    #[arg(long, default_value_t = 2048)]
    pub max_connections: usize,
    /// Seconds a client may take to send a request's headers (and an idle keep-alive
    /// connection is kept).
    #[arg(long, default_value_t = 10)]
    pub header_timeout_s: u64,
}
