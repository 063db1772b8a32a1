//! `piezo simulate --model MODEL --input FILE.csv --output OUT.csv`: the open-loop response of
//! a model to a recorded input ([`host_tests::sim::open_loop`]).

use anyhow::Context;
use clap::Args;
use host_tests::io::csv::Record;
use host_tests::io::model_file::ModelFile;
use host_tests::sim::open_loop::simulate;
use std::path::PathBuf;

/// Arguments of `piezo simulate`.
#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Model file or built-in name (thesis-linear, thesis-full).
    #[arg(long)]
    pub model: String,
    /// Input record (CSV with columns t and u).
    #[arg(long)]
    pub input: PathBuf,
    /// Output record (CSV t,u,y).
    #[arg(long)]
    pub output: PathBuf,
    /// Switch the sensor noise off.
    #[arg(long)]
    pub no_noise: bool,
}

/// Run `piezo simulate`.
pub fn run(a: &SimulateArgs) -> anyhow::Result<()> {
    let mut model = ModelFile::load(&a.model)?;
    if a.no_noise {
        model.converters.noise_v = 0.0;
    }
    let stage = model.build_stage()?;
    let rec =
        Record::read(&a.input).with_context(|| format!("input record {}", a.input.display()))?;
    let y = simulate(&stage, model.period_s, &rec.t_s, &rec.u_v);
    let out = Record::new(rec.t_s, rec.u_v, Some(y), None)?;
    out.write(&a.output)?;
    eprintln!(
        "simulated {} samples ({:.3} s at {:.0} Hz) with model `{}` -> {}",
        out.len(),
        out.t_s[out.len() - 1] - out.t_s[0],
        out.rate_hz(),
        model.name,
        a.output.display()
    );
    Ok(())
}
