//! Command-line arguments.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

mod bench;
mod data;
mod eval;
mod run;
mod train;

pub use bench::*;
pub use data::*;
pub use eval::*;
pub use run::*;
pub use train::*;

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
    /// Predictor training epochs (34 since the twenty-fourth session: with two data-parallel
    /// chunks the four extra epochs before the reaction siblings raised control in truth in
    /// four paired data seeds of four; BENCHMARKS.md, issue 11).
    #[arg(long, default_value_t = 34)]
    pub epochs: usize,
    /// Reaction siblings per scene: before the last --reaction-epochs epochs, replay this many
    /// of B's sampled futures (from the predictor's checkpoint there) per scene in the
    /// synthetic world, A reacting, and train those epochs on them too: the labels then rank
    /// B's sampled futures more like the simulator does and its logged futures less so, and
    /// the knob follows the truth far better in open and closed loop (BENCHMARKS.md, issue
    /// 11); 0 skips it. Ignored with --data.
    #[arg(long, default_value_t = 3)]
    pub reaction_siblings: usize,
    /// The last this-many of --epochs train with the reaction siblings.
    #[arg(long, default_value_t = 10)]
    pub reaction_epochs: usize,
    /// Data-parallel chunks of each predictor training step (the batch split into chunks whose
    /// passes run in parallel; the same step up to rounding, ~0.8× the time on 2 cores). Over
    /// four paired data seeds two chunks changed no number beyond the seeds' own spread
    /// (BENCHMARKS.md, issue 11); 1 keeps one graph per step.
    #[arg(long, default_value_t = 2)]
    pub data_parallel_chunks: usize,
    /// Samples per predictor training step.
    #[arg(long, default_value_t = 32, value_parser = clap::value_parser!(u64).range(1..))]
    pub batch_size: u64,
    /// Peak learning rate of the predictor (cosine schedule down to 1 % of it).
    #[arg(long, default_value_t = 1e-3)]
    pub learning_rate: f64,
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
    /// With `--mode-courtesy true`: the scorer also sees the requested ψ relative to this
    /// scene's choices, (ψ − ψ_k) / (their spread + 0.1 label spreads), so that a scene
    /// whose choices J_φ scores close together (a cut-in) is ranked as finely as one whose
    /// choices lie far apart (a crossing); `false` gives the earlier scorer of ψ and ψ_k
    /// alone (BENCHMARKS.md, *Courtesy relative to the scene's choices*, issue 11).
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub relative_mode_courtesy: bool,
    /// With `--head modes`: slowed copies of each of B's modes join the generator's choices
    /// (`scbg train generator --mode-slowdowns`; `none`: the modes alone).
    #[arg(long, default_value_t = Slowdowns::default())]
    pub mode_slowdowns: Slowdowns,
    /// With `--head modes`: each of B's modes that leaves its lane also joins the generators'
    /// choices with the move completed within this many steps (`scbg train generator
    /// --lane-move-steps`; 0: none).
    #[arg(long, default_value_t = scbg::generator::DEFAULT_LANE_MOVE_STEPS)]
    pub lane_move_steps: usize,
    /// With `--head modes`: how the trajectory loss trains the generators' choice among B's
    /// modes (`scbg train generator --selector-loss`).
    #[arg(long, value_enum, default_value_t = scbg::generator::DEFAULT_SELECTOR_LOSS)]
    pub selector_loss: scbg::choices::SelectorLoss,
    /// Held-out scenes of the closed-loop stage (0 skips it).
    #[arg(long, default_value_t = 60)]
    pub closed_loop_scenes: usize,
    #[command(flatten)]
    pub estimator: EstimatorArgs,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// `--mode-slowdowns`: comma-separated factors, each in (0, 2] (above 1: hurried), or `none`.
#[derive(Debug, Clone, PartialEq)]
pub struct Slowdowns(pub Vec<f32>);

impl Default for Slowdowns {
    fn default() -> Self {
        Self(scbg::generator::DEFAULT_MODE_SLOWDOWNS.to_vec())
    }
}

impl std::fmt::Display for Slowdowns {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.0.is_empty() {
            return f.write_str("none");
        }
        let factors: Vec<String> = self.0.iter().map(f32::to_string).collect();
        f.write_str(&factors.join(","))
    }
}

impl std::str::FromStr for Slowdowns {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        if text.trim() == "none" {
            return Ok(Self(Vec::new()));
        }
        let factor = |w: &str| {
            w.trim()
                .parse::<f32>()
                .ok()
                .filter(|w| *w > 0.0 && *w <= scbg::generator::MAX_MODE_SPEEDUP)
                .ok_or_else(|| {
                    format!(
                        "slowdown {w:?}: expected a number in (0, {}], or none",
                        scbg::generator::MAX_MODE_SPEEDUP
                    )
                })
        };
        text.split(',')
            .map(factor)
            .collect::<Result<_, _>>()
            .map(Self)
    }
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

    #[test]
    fn mode_slowdowns_are_factors_in_0_2() {
        let slowdowns = |args: &[&str]| {
            Cli::try_parse_from(["scbg", "demo"].iter().chain(args).copied()).map(|c| {
                match c.command {
                    Command::Demo(d) => d.mode_slowdowns,
                    _ => unreachable!(),
                }
            })
        };
        assert_eq!(slowdowns(&[]).unwrap().0, vec![0.75, 0.5]);
        assert_eq!(
            slowdowns(&["--mode-slowdowns", "0.85,0.7"]).unwrap().0,
            vec![0.85, 0.7]
        );
        assert_eq!(
            slowdowns(&["--mode-slowdowns", "none"]).unwrap().0,
            Vec::<f32>::new()
        );
        assert_eq!(
            slowdowns(&["--mode-slowdowns", "0.5,1.25"]).unwrap().0,
            vec![0.5, 1.25]
        );
        for bad in ["0", "2.5", "-0.5", "slow", "0.5,", ""] {
            assert!(slowdowns(&["--mode-slowdowns", bad]).is_err(), "{bad}");
        }
    }
}
