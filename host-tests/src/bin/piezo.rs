//! `piezo`: the command line. A thin shell: each verb parses its arguments and calls the
//! library in `host_tests`.
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "piezo",
    version,
    about = "Models and tools for the P-753 / E-505 / E-509 piezo loop"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Closed-loop figures of the thesis loop (margins, bandwidth, step response).
    Loop(host_tests::loop_cmd::LoopArgs),
    /// The control code on Cortex-M4F/M7 under QEMU: scenarios, on-target tests, budget.
    Qemu(host_tests::qemu::QemuArgs),
    /// Tracking error of a periodic reference with and without the pre-filter.
    Track(host_tests::track::TrackArgs),
    /// Open-loop response of a model to a recorded input (writes t,u,y).
    Simulate(host_tests::simulate::SimulateArgs),
    /// Measured-style records from a model, with noise.
    Synth(host_tests::synth::SynthArgs),
    /// Identify drift or hysteresis from a record and write a model file.
    Identify(host_tests::identify_cmd::IdentifyArgs),
    /// Capture a run on the board over its serial port and write it as CSV (t,u,y,r,flags).
    Record(host_tests::record_cmd::RecordArgs),
    /// Name the effects a model lacks from measured records, add them, show the gap shrink.
    Gap(host_tests::gap_cmd::GapArgs),
    /// The model-gap workflow on records synthesised from a virtual stage (no board needed).
    Demo(host_tests::demo::DemoArgs),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Loop(a) => host_tests::loop_cmd::run(&a),
        Command::Qemu(a) => host_tests::qemu::run(&a),
        Command::Track(a) => host_tests::track::run(&a),
        Command::Simulate(a) => host_tests::simulate::run(&a),
        Command::Synth(a) => host_tests::synth::run(&a),
        Command::Identify(a) => host_tests::identify_cmd::run(&a),
        Command::Record(a) => host_tests::record_cmd::run(&a),
        Command::Gap(a) => host_tests::gap_cmd::run(&a),
        Command::Demo(a) => host_tests::demo::run(&a),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::from(2)
        }
    }
}
