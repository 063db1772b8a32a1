//! `piezo gap --model BASE --data FILE [--data FILE ...] [--out MODEL.toml] [--report DIR]
//! [--json] [--vars t=NAME,u=NAME,y=NAME]`: the model-gap workflow ([`host_tests::gap`]) from
//! the command line.
//!
//! Records are CSV ([`host_tests::io::csv`]) or MATLAB v5 `.mat` files
//! ([`host_tests::io::mat`]); `--vars` names their time, input and output columns or
//! variables (a lab's own header such as `time_s,input_V,sensor_V`), default `t=t,u=u,y=y`. The table
//! goes to stdout (or one JSON object with `--json`: `{"named", "steps": [{"effect",
//! "evidence", "params", "rms_before_v", "rms_after_v", "refit", "removed"}] (a step's
//! `effect` joins with `+` the effects it fitted together: a refit, `X+offset`, or
//! `drift+hysteresis`, a creep and a loop fitted as one step on held levels that show both),
//! "noise_floor_v", "noise_notes" (one sentence per record whose floor was read past white
//! noise, coloured or below the record's resolution, or whose glitches were replaced),
//! "final_rms_v", "unexplained", "cannot_tell", "hysteresis_split": {"chosen",
//! "band_noise_var", "span_noise_var", "rise_noise_var", "by_diagnosis"}}`; `chosen` is
//! `"band"`, `"span"` or `"rise"`; `rise_noise_var` only where the rise split was fitted
//! (the band split left less than the span split); `by_diagnosis` only where both
//! splits' diagnoses ran: `{"split", "named", "final_noise_var"}` of the one not kept), a
//! progress bar to stderr.
//!
//! Records that hold more than [`checks::gap_max_samples`] samples in all (2 M, or
//! `PIEZO_GAP_MAX_SAMPLES`) are averaged in blocks down to half that
//! ([`checks::gap_averaged_samples`], [`decimate_to_fit`]; a 150 s record at the DS1103's
//! 50 kHz is read at 6.25 kHz), each with a `noise_notes` entry that says so; only records
//! that cannot be averaged that far without going below 1 kHz are refused.

use clap::Args;
use host_tests::gap::{Options, decimate_to_fit, diagnose, load_data, report};
use host_tests::io::checks;
use host_tests::io::model_file::ModelFile;
use std::path::{Path, PathBuf};

/// Arguments of `piezo gap`.
#[derive(Args, Debug, Clone)]
pub struct GapArgs {
    /// Base model: a model file or a built-in name (thesis-linear, thesis-full).
    #[arg(long)]
    pub model: String,
    /// Measured record (CSV t,u,y or MATLAB v5 .mat); repeat for several records.
    #[arg(long = "data", required = true)]
    pub data: Vec<PathBuf>,
    /// Write the augmented model file here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write an HTML report with SVG plots into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Names of the time, input and output columns (CSV header) or variables (.mat):
    /// t=NAME,u=NAME,y=NAME [default: t=t,u=u,y=y]; a CSV without a header names them by
    /// their 1-based numbers (t=1,u=2,y=3).
    #[arg(long)]
    pub vars: Option<String>,
}

/// Run `piezo gap`.
pub fn run(a: &GapArgs) -> anyhow::Result<()> {
    if let Some(v) = &a.vars {
        host_tests::io::mat::parse_vars(v)?;
    }
    if let Some(out) = &a.out {
        let mut inputs: Vec<&Path> = a.data.iter().map(PathBuf::as_path).collect();
        inputs.push(Path::new(&a.model));
        checks::refuse_overwrite(out, &inputs)?;
    }
    let base = ModelFile::load(&a.model)?;
    let data = load_data(&a.data, a.vars.as_deref())?;
    // Records too long for the fits are averaged down, and their notes say so.
    let (data, averaged) = decimate_to_fit(
        data,
        checks::gap_max_samples(),
        checks::gap_averaged_samples(),
    );
    let size = |t: &[f64]| t.len().checked_sub(1).map_or(0.0, |last| t[last] - t[0]);
    let held: Vec<(String, usize, f64)> = data
        .iter()
        .map(|d| (d.name.clone(), d.len(), size(&d.t_s)))
        .collect();
    // An averaged record is simulated on its input at its own rate: that is its work.
    let simulated: Vec<(String, usize, f64)> = data
        .iter()
        .map(|d| match &d.fine {
            Some(f) => (d.name.clone(), f.t_s.len(), size(&f.t_s)),
            None => (d.name.clone(), d.len(), size(&d.t_s)),
        })
        .collect();
    checks::bound_gap_simulated(
        &held,
        &simulated,
        base.period_s,
        checks::gap_max_stage_steps(),
    )?;
    let mut d = diagnose(&base, &data, &Options { progress: true })?;
    d.noise_notes.splice(0..0, averaged);
    // A figure that came out NaN or infinite is an error, before anything is written.
    // `unexplained` is null by design when every record ends near its floor; every other
    // figure must be finite.
    let mut figures = d.to_json();
    if let Some(o) = figures.as_object_mut()
        && o.get("unexplained").is_some_and(serde_json::Value::is_null)
    {
        o.remove("unexplained");
    }
    checks::finite_json(&figures, "the result")?;
    if let Some(p) = &a.out {
        let mut m = d.model.clone();
        m.name = format!("{} + gap: {}", base.name, d.named.join(", "));
        m.write(p)?;
    }
    if let Some(dir) = &a.report {
        report::write(dir, &base, &data, &d)?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&d.to_json())?);
    } else {
        print!("{}", d.table());
        if let Some(p) = &a.out {
            println!("augmented model written to {}", p.display());
        }
        if let Some(dir) = &a.report {
            println!("report written to {}", dir.join("index.html").display());
        }
    }
    Ok(())
}
