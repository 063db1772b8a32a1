//! `piezo simulate --model MODEL --input FILE.csv --output OUT.csv`: the open-loop response of
//! a model to a recorded input ([`host_tests::sim::open_loop`]).

use anyhow::Context;
use clap::Args;
use host_tests::io::checks;
use host_tests::io::csv::Record;
use host_tests::io::model_file::ModelFile;
use host_tests::sim::open_loop::simulate_after;
use std::path::{Path, PathBuf};

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
    checks::refuse_overwrite(&a.output, &[&a.input, Path::new(&a.model)])?;
    let mut model = ModelFile::load(&a.model)?;
    if a.no_noise {
        model.converters.noise_v = 0.0;
    }
    let stage = model.build_stage()?;
    let rec =
        Record::read(&a.input).with_context(|| format!("input record {}", a.input.display()))?;
    if let Some(note) = rec.time_note(&a.input.display().to_string()) {
        eprintln!("{note}");
    }
    let span_s = rec.t_s[rec.len() - 1] - rec.t_s[0];
    checks::bound_steps(
        &format!(
            "simulating {} ({span_s:.6e} s at the model's step of {} s)",
            a.input.display(),
            model.period_s
        ),
        checks::stage_steps(span_s, model.period_s),
        checks::max_stage_steps(),
    )?;
    let y = simulate_after(
        &stage,
        model.period_s,
        &model.start_history_v(),
        &rec.t_s,
        &rec.u_v,
    );
    let out = Record::new(rec.t_s, rec.u_v, Some(y), None)
        .context("the simulated output is out of range (the model's response diverges)")?;
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
