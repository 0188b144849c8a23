//! Arguments of `label` and `train`.

use clap::{Args, Subcommand};
use scbg::choices::{Reward, Variant};
use std::path::PathBuf;

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
    /// Reward r(y_A).
    #[arg(long, value_enum, default_value_t = Reward::AverageSpeed)]
    pub reward: Reward,
    /// Settings file whose `[labels]` table sets the sampled futures, the estimator of
    /// E[r(Y_A) | x], the audience and the lane moves (docs/pipeline.toml; `paper`: the
    /// paper's labelling).
    #[arg(long)]
    pub config: Option<PathBuf>,
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
    /// With --ground-truth: also write reaction siblings to this folder, the scene replayed
    /// with B following each of its first 3 sampled futures (the second and third slowed to
    /// 0.75 and 0.5 of their speed by the horizon, as the generator slows B's modes) and A and
    /// the others reacting by the synthetic world's rule (`reaction-NNNNN.tfrecord`; prepare it
    /// with `scbg data prepare` and give it to `scbg train predictor` as `counterfactual_cache`).
    #[arg(long, requires = "ground_truth")]
    pub reaction_siblings: Option<PathBuf>,
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
    /// Settings file whose `[labels]` and `[generator]` tables set the labelling and the
    /// training (epochs, batch, α, β, threshold, learning rate, range steps;
    /// docs/pipeline.toml; `paper`: the paper's labelling).
    #[arg(long)]
    pub config: Option<PathBuf>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
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
    /// Continue from the checkpoint in --out, to the weights an uninterrupted run reaches; with
    /// no checkpoint there yet, start afresh (so the same command finishes an interrupted run).
    #[arg(long)]
    pub resume: bool,
}
