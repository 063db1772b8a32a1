//! `piezo identify drift|hysteresis --model BASE --data FILE.csv --out MODEL.toml`: identify a
//! block from a record and write the base model with that block replaced (or added)
//! ([`host_tests::identify::into_model`]).

use anyhow::Context;
use clap::{Args, Subcommand};
use host_tests::identify::into_model::{drift_into, hysteresis_into};
use host_tests::io::checks;
use host_tests::io::csv::Record;
use host_tests::io::model_file::ModelFile;
use std::path::{Path, PathBuf};

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
    checks::refuse_overwrite(&f.out, &[&f.data, Path::new(&f.model)])?;
    let model = ModelFile::load(&f.model)?;
    let rec = Record::read(&f.data).with_context(|| format!("record {}", f.data.display()))?;
    if let Some(note) = rec.time_note(&f.data.display().to_string()) {
        eprintln!("{note}");
    }
    rec.require_y()
        .with_context(|| format!("record {}", f.data.display()))?;
    Ok((model, rec))
}

/// Run `piezo identify`.
pub fn run(a: &IdentifyArgs) -> anyhow::Result<()> {
    match &a.target {
        IdentifyTarget::Drift(f) => {
            let (mut model, rec) = load(f)?;
            let fit = drift_into(&mut model, &rec, &f.data.display().to_string())?;
            let d = fit.config;
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
