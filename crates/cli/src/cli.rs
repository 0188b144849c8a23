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

impl Command {
    /// Whether the command serves HTTP for as long as it runs (`serve`, and the benchmarks that
    /// run a server).
    pub fn is_server(&self) -> bool {
        matches!(
            self,
            Self::Serve(_) | Self::Bench(BenchCommand::Serve(_) | BenchCommand::Soak(_))
        )
    }
}

#[derive(Debug, Clone, Args)]
pub struct DemoArgs {
    /// Output folder (data, cache, checkpoints, figures, report.md, report.json).
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Your WOMD files (globs or paths) instead of generated data.
    #[arg(long, num_args = 1..)]
    pub data: Vec<String>,
    /// Settings file over the defaults of docs/pipeline.toml, or `paper` for the paper's
    /// predictor and labels.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Seed of everything (the data, the predictor, the labels; the generators take seed,
    /// seed + 1, …).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

#[cfg(test)]
mod tests {
    use clap::{CommandFactory, Parser};

    use super::Cli;

    #[test]
    fn the_command_line_is_well_formed() {
        Cli::command().debug_assert();
    }

    #[test]
    fn no_command_has_more_than_twelve_flags() {
        fn walk(cmd: &clap::Command, path: &str, out: &mut Vec<String>) {
            let flags = cmd
                .get_arguments()
                .filter(|a| !a.is_global_set() && a.get_id() != "help" && a.get_id() != "version")
                .count();
            if flags > 12 {
                out.push(format!("{path}: {flags} flags"));
            }
            for sub in cmd.get_subcommands() {
                walk(sub, &format!("{path} {}", sub.get_name()), out);
            }
        }
        let mut over = Vec::new();
        walk(&Cli::command(), "scbg", &mut over);
        assert!(over.is_empty(), "{over:?}");
    }

    /// The command-line reference, `docs/cli.md`, as clap describes the commands: every
    /// command, its flags, their defaults and the first sentence of their help.
    fn cli_reference() -> String {
        fn first_sentence(text: &str) -> String {
            let text = text.split_whitespace().collect::<Vec<_>>().join(" ");
            let end = text.find(". ").map_or(text.len(), |i| i + 1);
            text[..end].replace('|', "\\|")
        }
        fn walk(cmd: &clap::Command, path: &str, out: &mut String) {
            let subs: Vec<&clap::Command> = cmd.get_subcommands().collect();
            if !path.is_empty() && subs.is_empty() {
                out.push_str(&format!("## `{path}`\n\n"));
                if let Some(about) = cmd.get_about() {
                    out.push_str(&format!("{}\n\n", first_sentence(&about.to_string())));
                }
                out.push_str("| flag | default | what |\n|---|---|---|\n");
                for a in cmd.get_arguments() {
                    if a.is_global_set() || ["help", "version"].contains(&a.get_id().as_str()) {
                        continue;
                    }
                    let name = match a.get_long() {
                        Some(l) => format!("`--{l}`"),
                        None => format!("`{}`", a.get_id().as_str().to_uppercase()),
                    };
                    let default: Vec<String> = a
                        .get_default_values()
                        .iter()
                        .map(|v| v.to_string_lossy().into_owned())
                        .collect();
                    let help = a.get_help().map(|h| first_sentence(&h.to_string()));
                    out.push_str(&format!(
                        "| {name} | {} | {} |\n",
                        if default.is_empty() {
                            String::new()
                        } else {
                            format!("`{}`", default.join(" "))
                        },
                        help.unwrap_or_default()
                    ));
                }
                out.push('\n');
            }
            for sub in subs {
                let name = if path.is_empty() {
                    format!("scbg {}", sub.get_name())
                } else {
                    format!("{path} {}", sub.get_name())
                };
                walk(sub, &name, out);
            }
        }
        let mut out = String::from(
            "# Command-line reference\n\n\
             Generated from the argument definitions (`cargo test -p scbg-cli` checks it; set \
             `SCBG_WRITE_DOCS=1` to rewrite it). `scbg <command> --help` says more. Every command \
             also takes `--threads N`, the worker threads of its parallel stages.\n\n",
        );
        walk(&Cli::command(), "", &mut out);
        out
    }

    #[test]
    fn the_cli_reference_is_up_to_date() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/cli.md");
        let want = cli_reference();
        if std::env::var_os("SCBG_WRITE_DOCS").is_some() {
            std::fs::write(&path, &want).unwrap();
        }
        let have = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            have == want,
            "docs/cli.md differs from the commands' definitions: rerun with SCBG_WRITE_DOCS=1"
        );
    }

    #[test]
    fn demo_takes_a_settings_file_or_paper() {
        let cli =
            Cli::try_parse_from(["scbg", "demo", "--config", "paper", "--seed", "2"]).unwrap();
        match cli.command {
            super::Command::Demo(d) => {
                assert_eq!(d.config.as_deref(), Some(std::path::Path::new("paper")));
                assert_eq!(d.seed, 2);
            }
            _ => unreachable!(),
        }
    }

    #[test]
    fn synth_draws_the_default_world_unless_told() {
        let cli = Cli::try_parse_from(["scbg", "synth", "--out", "x"]).unwrap();
        let super::Command::Synth(s) = cli.command else {
            unreachable!()
        };
        assert_eq!(s.families, scbg_synth::Family::DEFAULT);
        let cli =
            Cli::try_parse_from(["scbg", "synth", "--out", "x", "--families", "leftturn"]).unwrap();
        let super::Command::Synth(s) = cli.command else {
            unreachable!()
        };
        assert_eq!(s.families, [scbg_synth::Family::Leftturn]);
    }
}
