//! Arguments of `eval`.

use clap::{Args, Subcommand};
use scbg_lab::predictor::{ModeSelection, SplitSelection};
use std::path::PathBuf;

use super::run::ModelArgs;

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
    /// A and B: the SDC and an object of interest when the log names them, else the pair
    /// `data prepare` mines; every scene left out is listed with why.
    Sim(EvalSimArgs),
    /// WOSAC 2025 realism of anyone's rollouts: a submission (SimAgentsChallengeSubmission
    /// shards, or a .tar.gz of them) scored against the logged scenarios, per scenario and
    /// averaged. Scenarios that cannot be scored are listed with why; exit code 2 when none was
    /// scored.
    Wosac(EvalWosacArgs),
}

#[derive(Debug, Clone, Args)]
pub struct EvalWosacArgs {
    /// WOMD scenario files holding the logged scenarios (globs, folders or paths).
    #[arg(long, required = true, num_args = 1..)]
    pub scenarios: Vec<String>,
    /// Submission shards NAME.binproto-IIIII-of-NNNNN, or .tar.gz archives of them (globs,
    /// folders or paths).
    #[arg(long, required = true, num_args = 1..)]
    pub submission: Vec<String>,
    /// Output folder for wosac.json (every number per scenario, the mean, what was skipped).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print wosac.json's content instead of the table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Clone, Args)]
pub struct EvalSimArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    /// WOMD Scenario files (globs, folders or paths).
    #[arg(long, required = true, num_args = 1..)]
    pub data: Vec<String>,
    /// Synthetic ground truth (ground_truth.jsonl): the synthetic rule drives A and the others.
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Scenes on the validation split (by scenario id, as in training) or all.
    #[arg(long, value_enum, default_value_t = SplitSelection::Validation)]
    pub split: SplitSelection,
    /// Scenes of the courtesy curve: the first ones with an interacting pair, each with every
    /// 91-step window that has one (as `data prepare` cuts scenes longer than 9.1 s).
    #[arg(long, default_value_t = 40)]
    pub scenes: usize,
    /// Windows scored with WOSAC realism (32 rollouts per quantile and baseline): the first
    /// where it applies (91 steps, current step 10, an evaluated object, road edges), each
    /// scene's first window before any scene's second.
    #[arg(long, default_value_t = 8)]
    pub wosac_scenes: usize,
    /// Output folder (eval_sim.json, sim_courtesy.png, sim_realism.png).
    #[arg(long)]
    pub out: PathBuf,
    /// Settings file whose `[closed_loop]` table sets how A and the others move, the
    /// replanning, the spread of the WOSAC rollouts and their quantiles (docs/pipeline.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
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
    /// drew), with the training labels' kept baseline futures and lane moves of them: the
    /// candidates of the `ranked` row and of the selection yardsticks. With the
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
