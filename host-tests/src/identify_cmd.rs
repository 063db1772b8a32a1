//! `piezo identify drift|hysteresis --model BASE --data FILE.csv --out MODEL.toml`: identify a
//! block from a record and write the base model with that block replaced (or added).

use crate::identify::drift::identify_drift;
use crate::model_file::{DriftSection, ModelFile};
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
        IdentifyTarget::Hysteresis(_) => {
            anyhow::bail!(
                "hysteresis identification is not available in this build yet (branch `hysteresis` not merged)"
            )
        }
    }
}
