//! `piezo`: the command line. A thin shell: each verb (one file here) parses its arguments,
//! calls the library in `host_tests` and prints.
use clap::{Parser, Subcommand};

mod demo;
mod gap;
mod identify;
mod loop_cmd;
mod qemu;
mod record;
mod simulate;
mod synth;
mod track;

#[derive(Parser)]
#[command(
    name = "piezo",
    version,
    about = "Models and tools for the P-753 / E-505 / E-509 piezo loop"
)]
struct Cli {
    #[command(subcommand)]
    verb: Verb,
}

#[derive(Subcommand)]
enum Verb {
    /// Closed-loop figures of the thesis loop (margins, bandwidth, step response).
    Loop(loop_cmd::LoopArgs),
    /// The control code on Cortex-M4F/M7 under QEMU: scenarios, on-target tests, budget.
    Qemu(qemu::QemuArgs),
    /// Tracking error of a periodic reference with and without the pre-filter.
    Track(track::TrackArgs),
    /// Open-loop response of a model to a recorded input (writes t,u,y).
    Simulate(simulate::SimulateArgs),
    /// Measured-style records from a model, with noise.
    Synth(synth::SynthArgs),
    /// Identify drift or hysteresis from a record and write a model file.
    Identify(identify::IdentifyArgs),
    /// Capture a run on the board over its serial port and write it as CSV (t,u,y,r,flags).
    Record(record::RecordArgs),
    /// Name the effects a model lacks from measured records, add them, show the gap shrink.
    Gap(gap::GapArgs),
    /// The model-gap workflow on records synthesised from a virtual stage (no board needed).
    Demo(demo::DemoArgs),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.verb {
        Verb::Loop(a) => loop_cmd::run(&a),
        Verb::Qemu(a) => qemu::run(&a),
        Verb::Track(a) => track::run(&a),
        Verb::Simulate(a) => simulate::run(&a),
        Verb::Synth(a) => synth::run(&a),
        Verb::Identify(a) => identify::run(&a),
        Verb::Record(a) => record::run(&a),
        Verb::Gap(a) => gap::run(&a),
        Verb::Demo(a) => demo::run(&a),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::from(2)
        }
    }
}
