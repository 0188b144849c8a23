//! Arguments of `label` and `train` (and the estimator options `demo` shares).

use clap::{Args, Subcommand};
use scbg::choices::{MarginalEstimate, Reward, SelectorLoss, Threshold, Variant, Weighting};

use super::Slowdowns;
use std::path::PathBuf;

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
    /// More futures of B sampled for `conditional-average`'s estimate of E[r(Y_A) | x] (kept
    /// and labelled too with --keep-baseline-samples, the default): it averages over the
    /// first --samples sampled futures plus this many
    /// (24: 32 in all with 8 labelled; 0, the default before the twenty-fourth session,
    /// averages over the labelled ones alone). Over four data seeds of the demo's predictor 32
    /// futures ranked held-out logged futures like the oracle at 0.712 against 0.685 with 8
    /// (BENCHMARKS.md).
    #[arg(long, default_value_t = 24)]
    pub baseline_samples: usize,
    /// Above 0: each sampled future of B that drifts off B's lane path (1–5 m) is also
    /// labelled with its lane move completed within this many steps, if it leaves A room
    /// (after the sampled ones, not in E[r(Y_A) | x]; sample and rank chooses among them, the
    /// generator trains without them; with `scbg label --reaction-siblings`, they are replayed
    /// too). 0: none (the default before the thirty-second session). Over four data seeds,
    /// sample and rank's control in truth rose from 0.43 to 0.49 with them (BENCHMARKS.md).
    #[arg(long, default_value_t = scbg::labels::DEFAULT_LABEL_LANE_MOVE_STEPS)]
    pub label_lane_move_steps: usize,
    /// The hardest braking (m/s²) a labelled lane move may ask of A when it enters A's lane,
    /// after --lane-move-room-reaction seconds: 7 (the default since the thirty-fourth
    /// session) is the synthetic world's least courteous cut-in and the closed loop's gap
    /// acceptance; 4 with 1 s is MOBIL's polite limit, the default before. Over four data
    /// seeds, sample and rank's control in truth on cut-ins rose from 0.39 to 0.49 with 7
    /// (BENCHMARKS.md).
    #[arg(long, default_value_t = scbg::labels::DEFAULT_LANE_MOVE_ROOM.braking_mps2, value_name = "MPS2")]
    pub lane_move_room_braking: f32,
    /// A's reaction time (s) before the braking of --lane-move-room-braking.
    #[arg(long, default_value_t = scbg::labels::DEFAULT_LANE_MOVE_ROOM.reaction_s, value_name = "S")]
    pub lane_move_room_reaction: f32,
    /// Also label and keep the --baseline-samples futures (after the --samples ones; lane
    /// moves then come from all of them): sample and rank chooses among every future E[r(Y_A)
    /// | x] scores (their ψ costs no extra forward, their lane moves add some); the generator
    /// and range predictor still train on the first --samples. `false`: the earlier layout.
    /// Over four data seeds, sample and rank's control in truth rose from 0.49 to 0.53 with
    /// them (default since the thirty-third session; BENCHMARKS.md).
    #[arg(
        long,
        default_value_t = true,
        action = clap::ArgAction::Set,
        num_args = 0..=1,
        default_missing_value = "true",
        value_name = "BOOL"
    )]
    pub keep_baseline_samples: bool,
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
    /// With --ground-truth: also write reaction siblings to this folder, the scene replayed
    /// with B following each of its first --reaction-per-role sampled futures and A and the
    /// others reacting by the synthetic world's rule (`reaction-NNNNN.tfrecord`; prepare it
    /// with `scbg data prepare` and give it to `scbg train predictor` as
    /// `counterfactual_cache`).
    #[arg(long, requires = "ground_truth")]
    pub reaction_siblings: Option<PathBuf>,
    /// Sampled futures per ground-truth role written as reaction siblings.
    #[arg(long, default_value_t = 3)]
    pub reaction_per_role: usize,
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
    /// With `--mode-courtesy true`: the scorer also sees the requested ψ relative to this
    /// scene's choices, (ψ − ψ_k) / (their spread + 0.1 label spreads), so that a scene
    /// whose choices J_φ scores close together (a cut-in) is ranked as finely as one whose
    /// choices lie far apart (a crossing); `false` gives the earlier scorer of ψ and ψ_k
    /// alone (BENCHMARKS.md, *Courtesy relative to the scene's choices*, issue 11).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub relative_mode_courtesy: bool,
    /// With `--head modes`: slowed copies of each of B's modes join the generator's choices,
    /// one per factor (comma-separated, each in (0, 2]): the mode's path, travelled at a speed
    /// easing from the mode's own to the factor times it at the horizon (below 1: yielding, in
    /// every family). `none`: the modes alone, the default before 0.75,0.5 (BENCHMARKS.md,
    /// issue 11). A factor above 1 hurries the mode (past its horizon straight on): it widens
    /// what the choices allow in truth, but the trained generator follows the truth less
    /// (BENCHMARKS.md, *Hurried copies*).
    #[arg(long, default_value_t = Slowdowns::default())]
    pub mode_slowdowns: Slowdowns,
    /// With `--head modes`: each of B's modes that drifts off B's lane path also joins the
    /// generator's choices with the move completed: a full lane (3.5 m) over within this many
    /// 0.1 s steps, its progress along the lane kept (moving over for A, or out of its way,
    /// done at once; 30 is 3 s). 0: none, the default: the moves lift what the choices allow
    /// in truth, but the trained generator follows the truth less (BENCHMARKS.md, issue 11).
    #[arg(long, default_value_t = scbg::generator::DEFAULT_LANE_MOVE_STEPS)]
    pub lane_move_steps: usize,
    /// With `--head modes`: how the trajectory loss trains the choice among B's modes:
    /// `classify` (the default) fits the mode nearest each target future plus the
    /// displacement and trains the selector by cross-entropy to pick that mode (MultiPath's
    /// loss); `blend`, the default before, fits the softmax blend of the modes
    /// (BENCHMARKS.md, issue 11).
    #[arg(long, value_enum, default_value_t = scbg::generator::DEFAULT_SELECTOR_LOSS)]
    pub selector_loss: SelectorLoss,
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
