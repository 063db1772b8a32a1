//! `piezo simulate --model MODEL --input FILE.csv --output OUT.csv`: the open-loop response of
//! a model to a recorded input.
//!
//! The stage runs at its own fixed step (the model's `period_s`) whatever the record's rate:
//! the record's `u` is held from each sample time to the next (as a DAC would hold it), and
//! `y` at each record time is the sensor reading of the last stage step at or before that time.
//! The stage starts at rest with the first input held for ever (drift settled). The output
//! record has the columns `t,u,y` at the input's sample times.

use crate::model_file::ModelFile;
use crate::record::Record;
use anyhow::Context;
use clap::Args;
use model_core::stage::Stage;
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

/// The stage's readings at the times `t_s` for the input `u_v` held between samples.
/// `period_s` is the stage's fixed step. Both slices must have equal length (the shorter
/// length is used otherwise).
pub fn simulate(stage: &Stage, period_s: f64, t_s: &[f64], u_v: &[f64]) -> Vec<f64> {
    let n = t_s.len().min(u_v.len());
    let mut y = Vec::with_capacity(n);
    if n == 0 {
        return y;
    }
    let t0 = t_s[0];
    let mut s = stage.steady_state(u_v[0] as f32);
    let mut last = s.signals().measured_v;
    // Steps taken so far; step k ends at t0 + k T.
    let mut k: u64 = 0;
    for i in 0..n {
        // Steps ending at or before t[i] were driven by earlier samples.
        let until = ((t_s[i] - t0) / period_s + 1e-9).floor().max(0.0) as u64;
        let held = if i == 0 { u_v[0] } else { u_v[i - 1] } as f32;
        while k < until {
            last = stage.step(&mut s, held);
            k += 1;
        }
        y.push(last as f64);
    }
    y
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
