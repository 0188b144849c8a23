//! One module per command group.

mod bench;
mod data;
mod demo;
mod eval;
mod eval_scbg;
mod generator;
mod label;
mod synth;
mod train;

use crate::cli::{BenchCommand, Command, DataCommand, EvalCommand, TrainCommand};

pub fn run(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Demo(a) => demo::demo(&a),
        Command::Label(a) => label::label(&a).map(|_| ()),
        Command::Data(DataCommand::Inspect(a)) => data::inspect(&a),
        Command::Data(DataCommand::Render(a)) => data::render(&a),
        Command::Data(DataCommand::Prepare(a)) => data::prepare(&a).map(|_| ()),
        Command::Synth(a) => synth::synth(&a),
        Command::Bench(BenchCommand::Ingest(a)) => bench::ingest(&a),
        Command::Bench(BenchCommand::Synth(a)) => bench::synth(&a),
        Command::Bench(BenchCommand::Train(a)) => bench::train(&a),
        Command::Train(TrainCommand::Predictor(a)) => train::predictor(&a),
        Command::Train(TrainCommand::Generator(a)) => generator::train(&a).map(|_| ()),
        Command::Generate(a) => generator::generate(&a),
        Command::Eval(EvalCommand::Scbg(a)) => eval_scbg::eval(&a).map(|_| ()),
        Command::Eval(EvalCommand::Predictor(a)) => eval::predictor(&a),
        Command::Eval(EvalCommand::Metrics(a)) => eval::metrics(&a),
    }
}
