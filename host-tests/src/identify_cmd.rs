//! `piezo identify drift|hysteresis --model BASE --data FILE.csv --out MODEL.toml`: identify a
//! block from a record and write the base model with that block replaced (or added).

use crate::identify::drift::identify_drift;
use crate::identify::hysteresis::identify_hysteresis;
use crate::model_file::{DriftSection, HysteresisSection, ModelFile};
use crate::record::Record;
use anyhow::Context;
use clap::{Args, Subcommand};
use model_core::drift::DriftConfig;
use std::path::PathBuf;

/// Flags shared by every `identify` target.
#[derive(Args, Debug)]
pub struct IdentifyFlags {
    /// Base model file or built-in name (thesis-linear, thesis-full).
    #[arg(long)]
    pub model: String,
    /// The record (CSV with t, u, y).
    #[arg(long)]
    pub data: PathBuf,
    /// The model file to write.
    #[arg(long)]
    pub out: PathBuf,
}

/// What to identify.
#[derive(Subcommand, Debug)]
pub enum IdentifyTarget {
    /// The drift lags (eq. 5.1) from a step record.
    Drift(IdentifyFlags),
    /// The hysteresis table from a first-order-reversal record.
    Hysteresis(IdentifyFlags),
}

/// Arguments of `piezo identify`.
#[derive(Args, Debug)]
pub struct IdentifyArgs {
    /// What to identify.
    #[command(subcommand)]
    pub target: IdentifyTarget,
}

fn load(f: &IdentifyFlags) -> anyhow::Result<(ModelFile, Record)> {
    let model = ModelFile::load(&f.model)?;
    let rec = Record::read(&f.data).with_context(|| format!("record {}", f.data.display()))?;
    rec.require_y()?;
    Ok((model, rec))
}

/// The drift branch's output for `u_v` held over each sample of `period_s`, starting at rest
/// with `u_v[0]` (exact for a held input, `f64`; the drift lags are 60 ms and slower, so the
/// record's rate need not be the stage's).
pub fn drift_response(d: &DriftConfig, period_s: f64, u_v: &[f64]) -> Vec<f64> {
    let decay = d.taus_s.map(|t| (-period_s / t).exp());
    let w0 = u_v.first().map_or(0.0, |u| d.weight(*u));
    let mut y = d.gains.map(|g| g * w0);
    let mut out = Vec::with_capacity(u_v.len());
    let mut prev = u_v.first().copied().unwrap_or(0.0);
    for &u in u_v {
        // y[i] is the drift at sample i, driven by the inputs before it.
        out.push(y.iter().sum());
        let w = d.weight(prev);
        for k in 0..3 {
            let target = d.gains[k] * w;
            y[k] = target + (y[k] - target) * decay[k];
        }
        prev = u;
    }
    out
}

/// Identify the hysteresis table from `rec` into `model` (returns true if `[nonlinear-gain]`
/// was removed). With drift in the base model, its prediction is taken out of the record first,
/// so the table holds the fast static curve only and the drift is not counted twice; the table
/// is the measured static curve with the amplitude-dependent gain in it, so `[nonlinear-gain]`
/// is removed (keeping it would count that gain twice).
pub fn hysteresis_into(model: &mut ModelFile, rec: &Record, source: &str) -> anyhow::Result<bool> {
    let mut y = rec.require_y()?.to_vec();
    if let Some(d) = model.stage_config()?.drift {
        let drift = drift_response(&d, rec.period_s(), &rec.u_v);
        for (yi, di) in y.iter_mut().zip(&drift) {
            *yi -= di;
        }
    }
    let table = identify_hysteresis(&rec.t_s, &rec.u_v, &y)?;
    model.hysteresis = Some(HysteresisSection::from_table(&table));
    let dropped = model.nonlinear_gain.take().is_some();
    model.name = format!("{} + hysteresis identified from {source}", model.name);
    model.build_stage()?;
    Ok(dropped)
}

/// Run `piezo identify`.
pub fn run(a: &IdentifyArgs) -> anyhow::Result<()> {
    match &a.target {
        IdentifyTarget::Drift(f) => {
            let (mut model, rec) = load(f)?;
            let base = model.stage_config()?.drift.unwrap_or_default();
            let fit = identify_drift(&rec.t_s, &rec.u_v, rec.require_y()?, &base)?;
            let d: DriftConfig = fit.config;
            model.drift = Some(DriftSection {
                gains: d.gains,
                taus_s: d.taus_s,
                poly: d.poly,
                poly_range_v: [d.poly_range_v.0, d.poly_range_v.1],
            });
            model.name = format!(
                "{} + drift identified from {}",
                model.name,
                f.data.display()
            );
            model.build_stage()?;
            model.write(&f.out)?;
            println!(
                "drift: step {:.3} -> {:.3} V at {:.4} s, {:.2} s fitted, residual {:.2} mV RMS",
                fit.from_v,
                fit.to_v,
                fit.t_step_s,
                fit.fitted_s,
                1e3 * fit.rms_residual_v
            );
            for i in 0..3 {
                println!(
                    "  lag {}: gain {:.4}  tau {:.4} s",
                    i + 1,
                    d.gains[i],
                    d.taus_s[i]
                );
            }
            println!("wrote {}", f.out.display());
            Ok(())
        }
        IdentifyTarget::Hysteresis(f) => {
            let (mut model, rec) = load(f)?;
            let dropped = hysteresis_into(&mut model, &rec, &f.data.display().to_string())?;
            model.write(&f.out)?;
            let table = model.stage_config()?.hysteresis.context("no table")?;
            let (lo, hi) = table.input_range_v();
            let (ylo, yhi) = table.output_range_v();
            println!(
                "hysteresis: table over {lo:.3}..{hi:.3} V in, {ylo:.3}..{yhi:.3} V out ({} grid values)",
                model_core::hysteresis::TABLE_LEN
            );
            if dropped {
                println!(
                    "  [nonlinear-gain] removed: the identified table already holds the static gain curve"
                );
            }
            println!("wrote {}", f.out.display());
            Ok(())
        }
    }
}
