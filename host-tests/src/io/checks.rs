//! The checks every verb shares, defined once: numbers where they enter (a flag within its
//! range, a figure that must be finite), the bound on the work a run may take, and outputs
//! written atomically and never over an input.
//!
//! * **Flags:** [`within`] refuses a NaN, an infinity or a value outside `lo..=hi`, and says
//!   the range: `--hold must be within 2e-5..3600 s (got 1e-12)`.
//! * **Work:** a verb that simulates counts the stage steps it will take *before* it starts
//!   ([`stage_steps`]) and refuses above [`max_stage_steps`] (1e8 steps, some seconds of work;
//!   the environment variable `PIEZO_MAX_STEPS` raises or lowers it). The message says the
//!   count, the limit and how to change either. Records themselves are bounded in rate
//!   ([`crate::io::csv::MIN_RATE_HZ`]..[`crate::io::csv::MAX_RATE_HZ`]) and in value
//!   ([`crate::io::csv::MAX_ABS_V`]) by the reader.
//! * **Results:** [`finite`] turns a NaN or infinite figure into an error naming it, so a
//!   verb never exits 0 with a figure it could not compute.
//! * **Outputs:** [`write_atomic`] writes `path.tmp-piezo-PID` beside the target and renames
//!   it into place, so a failed or interrupted run never leaves half a file, and an existing
//!   file is only replaced by a complete one. [`refuse_overwrite`] refuses an output that is
//!   one of the inputs (same path, or the same file through another name).

use anyhow::{Context, bail};
use std::path::{Path, PathBuf};

/// The default bound on the stage steps one run may simulate (each is some tens of ns).
pub const DEFAULT_MAX_STAGE_STEPS: u64 = 100_000_000;

/// The environment variable that changes [`DEFAULT_MAX_STAGE_STEPS`].
pub const MAX_STEPS_ENV: &str = "PIEZO_MAX_STEPS";

/// `flag`'s value if it is finite and within `lo..=hi`; otherwise an error saying the range
/// (with `unit`, e.g. `"s"`, `"Hz"`, `""`).
pub fn within(flag: &str, v: f64, lo: f64, hi: f64, unit: &str) -> anyhow::Result<f64> {
    if v.is_finite() && v >= lo && v <= hi {
        return Ok(v);
    }
    let unit = if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    };
    bail!(
        "{flag} must be within {}..{}{unit} (got {})",
        num(lo),
        num(hi),
        num(v)
    )
}

/// A number as a person writes it: plain between 1e-4 and 1e7, else in exponent form.
pub fn num(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() || (1e-4..1e7).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// `v` if finite, else an error naming the figure: a result that could not be computed.
pub fn finite(figure: &str, v: f64) -> anyhow::Result<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        bail!("{figure} came out as {v}: the result cannot be computed from these inputs")
    }
}

/// The index and value of the first non-finite element of `v`, if any.
pub fn first_non_finite(v: &[f64]) -> Option<(usize, f64)> {
    v.iter().position(|x| !x.is_finite()).map(|i| (i, v[i]))
}

/// The bound on stage steps per run: `PIEZO_MAX_STEPS` if set to a positive integer, else
/// [`DEFAULT_MAX_STAGE_STEPS`].
pub fn max_stage_steps() -> u64 {
    steps_from_env().unwrap_or(DEFAULT_MAX_STAGE_STEPS)
}

/// `PIEZO_MAX_STEPS`, when set to a positive integer.
fn steps_from_env() -> Option<u64> {
    std::env::var(MAX_STEPS_ENV)
        .ok()
        .and_then(|s| s.trim().parse::<u64>().ok())
        .filter(|&n| n > 0)
}

/// Stage steps needed to cover `span_s` seconds at the step `period_s` (saturating; a
/// non-finite ratio counts as `u64::MAX`).
pub fn stage_steps(span_s: f64, period_s: f64) -> u64 {
    let n = (span_s / period_s).ceil();
    if n.is_finite() && n >= 0.0 {
        if n >= u64::MAX as f64 {
            u64::MAX
        } else {
            n as u64
        }
    } else {
        u64::MAX
    }
}

/// Refuses `steps` above `limit`, saying what asked for them, the limit and how to change it.
pub fn bound_steps(what: &str, steps: u64, limit: u64) -> anyhow::Result<()> {
    if steps <= limit {
        return Ok(());
    }
    bail!(
        "{what} needs {steps:.3e} stage steps, more than the limit of {limit:.1e} \
         (set {MAX_STEPS_ENV}=N to change it, or shorten the record / raise the model's period_s)",
        steps = steps as f64,
        limit = limit as f64
    )
}

/// The most samples `piezo gap` takes over all its records: its fits hold several
/// simulations of every record at once (measured: 220 MB to 1 GB peak per million samples).
pub const GAP_MAX_SAMPLES: usize = 2_000_000;

/// The environment variable that sets `piezo gap`'s samples bound instead of
/// [`GAP_MAX_SAMPLES`] (a machine with more memory, or a test of the averaging).
pub const MAX_SAMPLES_ENV: &str = "PIEZO_GAP_MAX_SAMPLES";

/// `piezo gap`'s samples bound: `PIEZO_GAP_MAX_SAMPLES` if set to a positive integer, else
/// [`GAP_MAX_SAMPLES`].
pub fn gap_max_samples() -> usize {
    std::env::var(MAX_SAMPLES_ENV)
        .ok()
        .and_then(|s| s.trim().parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or(GAP_MAX_SAMPLES)
}

/// The samples `piezo gap` averages record sets beyond [`gap_max_samples`] down to: half the
/// bound (1 M by default; our assumption: the averaged records then cost what the bench's
/// largest do, not the most the machine can hold; measured in session 41, 1 M samples took
/// 33 s and 1.26 GB on 2 cores).
pub fn gap_averaged_samples() -> usize {
    gap_max_samples() / 2
}

/// `piezo gap` simulates each record some tens of times (about 90 passes over the records
/// for the recommended protocol, measured by the gap benchmark): the passes its bound counts.
pub const GAP_RUNS_PER_RECORD: u64 = 100;

/// `piezo gap`'s default bound on the stage steps' work of one pass over its records: 20
/// million, 400 s of records at the 20 us step stepped one by one (our assumption: the
/// recommended protocol, a 0.2 s fast record and a 150 s slow one, must run without a
/// setting). Since session 43 a slow record's holds cost [`GAP_HELD_SAMPLE_STEPS`] a sample,
/// so its [`GAP_MAX_SAMPLES`] bound it first (2000 s at 1 kHz); fast records, whose samples
/// are one or two steps, are bounded by both alike. The run takes [`GAP_RUNS_PER_RECORD`]
/// passes; `PIEZO_MAX_STEPS`, when set, bounds the whole run instead.
pub const GAP_MAX_STEPS_PER_PASS: u64 = 20_000_000;

/// The bound on `piezo gap`'s stage steps over all its passes: `PIEZO_MAX_STEPS` if set to a
/// positive integer, else [`GAP_MAX_STEPS_PER_PASS`] times [`GAP_RUNS_PER_RECORD`].
pub fn gap_max_stage_steps() -> u64 {
    steps_from_env().unwrap_or(GAP_MAX_STEPS_PER_PASS * GAP_RUNS_PER_RECORD)
}

/// A record's sample as `piezo gap` simulates it, in stage steps' work, where the sample
/// holds more steps: whole steps to the fast part's fixed point (two after a change of
/// input), then the rest of the hold in closed form ([`model_core::held`]: one product, about
/// four steps' work; a product per [`model_core::held::HELD_MAP_STEPS_MAX`] of a longer
/// hold; its simulations are noiseless, and every delay the plant holds has a map). Eight,
/// with a margin (our assumption; measured in session 43: a 600 s
/// identification record at 1 kHz, 30 M stage steps a pass, was diagnosed in 9.8 s on 2
/// cores, where the stage-step count had refused it).
pub const GAP_HELD_SAMPLE_STEPS: u64 = 8;

/// Bounds `piezo gap`'s work before it starts: `records` are (name, samples, span in
/// seconds), `period_s` the model's step; the bound is [`gap_max_stage_steps`].
pub fn bound_gap(records: &[(String, usize, f64)], period_s: f64) -> anyhow::Result<()> {
    bound_gap_within(records, period_s, gap_max_stage_steps())
}

/// [`bound_gap`] with the bound `limit` on the stage steps' work of all passes. A record's
/// pass costs its stage steps, or [`GAP_HELD_SAMPLE_STEPS`] per sample where that is less
/// (its samples hold more steps each).
pub fn bound_gap_within(
    records: &[(String, usize, f64)],
    period_s: f64,
    limit: u64,
) -> anyhow::Result<()> {
    bound_gap_simulated(records, records, period_s, limit)
}

/// [`bound_gap_within`] for records whose simulations run on other samples than the fits
/// hold (the model-gap workflow simulates a record it averaged from a faster one on its
/// input at its own rate): the samples bound on `held`, the work on `simulated` (the same
/// records, in the same order, as their simulations step through them).
pub fn bound_gap_simulated(
    held: &[(String, usize, f64)],
    simulated: &[(String, usize, f64)],
    period_s: f64,
    limit: u64,
) -> anyhow::Result<()> {
    let samples: usize = held.iter().map(|r| r.1).sum();
    let bound = gap_max_samples();
    if samples > bound {
        bail!(
            "the records hold {samples} samples in all, more than the {bound} the model-gap \
             workflow takes (up to 1 GB per million; {MAX_SAMPLES_ENV}=N sets it), after \
             averaging every record down to no less than 1 kHz: cut them shorter"
        );
    }
    let steps = simulated
        .iter()
        .map(|r| {
            // A hold longer than the longest map takes a map per `HELD_MAP_STEPS_MAX` more.
            let steps = stage_steps(r.2, period_s);
            let maps = steps / model_core::held::HELD_MAP_STEPS_MAX as u64;
            steps.min(
                (r.1 as u64)
                    .saturating_add(maps)
                    .saturating_mul(GAP_HELD_SAMPLE_STEPS),
            )
        })
        .fold(0u64, u64::saturating_add);
    let names: Vec<&str> = simulated.iter().map(|r| r.0.as_str()).collect();
    bound_steps(
        &format!(
            "the model-gap workflow on {} ({} stage steps' work per pass at {period_s} s, \
             {GAP_RUNS_PER_RECORD} passes)",
            names.join(", "),
            steps
        ),
        steps.saturating_mul(GAP_RUNS_PER_RECORD),
        limit,
    )
}

/// Refuses a JSON result holding a `null` where a number was due (serde writes NaN and
/// infinities as `null`), naming the key.
pub fn finite_json(v: &serde_json::Value, at: &str) -> anyhow::Result<()> {
    match v {
        serde_json::Value::Null => {
            bail!(
                "{at} came out as NaN or infinite: the result cannot be computed from these inputs"
            )
        }
        serde_json::Value::Array(a) => a
            .iter()
            .enumerate()
            .try_for_each(|(i, x)| finite_json(x, &format!("{at}[{i}]"))),
        serde_json::Value::Object(o) => o
            .iter()
            .try_for_each(|(k, x)| finite_json(x, &format!("{at}.{k}"))),
        _ => Ok(()),
    }
}

/// Refuses an output path that is one of `inputs` (the same path, or the same existing file).
pub fn refuse_overwrite(output: &Path, inputs: &[&Path]) -> anyhow::Result<()> {
    let out_canon = std::fs::canonicalize(output).ok();
    for input in inputs {
        let same_path = output == *input;
        let same_file = out_canon.is_some() && out_canon == std::fs::canonicalize(input).ok();
        if same_path || same_file {
            bail!(
                "the output {} is also an input: write the result to another file",
                output.display()
            );
        }
    }
    Ok(())
}

/// The temporary file [`write_atomic`] writes before renaming: beside `path`, same folder.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    path.with_file_name(format!(".{name}.tmp-piezo-{}", std::process::id()))
}

/// Write `path` through `fill` (which writes the temporary path it is given), then rename
/// into place; the temporary file is removed on failure. Errors name `path`.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&Path) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let tmp = temp_path(path);
    let r = match path.parent().filter(|d| !d.as_os_str().is_empty()) {
        Some(dir) if !dir.is_dir() => Err(anyhow::anyhow!(
            "the folder {} does not exist",
            dir.display()
        )),
        _ => fill(&tmp).and_then(|()| {
            std::fs::rename(&tmp, path).context("cannot move the finished file into place")
        }),
    };
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    r.with_context(|| format!("cannot write {}", path.display()))
}

/// [`write_atomic`] of bytes.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    write_atomic(path, |tmp| {
        std::fs::write(tmp, bytes).map_err(anyhow::Error::from)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn within_says_the_range() {
        let e = within("--hold", 1e-12, 2e-5, 3600.0, "s").unwrap_err();
        assert_eq!(
            e.to_string(),
            "--hold must be within 2e-5..3600 s (got 1e-12)"
        );
        assert!(within("--rate", f64::NAN, 1.0, 2.0, "Hz").is_err());
        assert_eq!(within("--x", 1.5, 1.0, 2.0, "").unwrap(), 1.5);
    }

    #[test]
    fn steps_saturate() {
        assert_eq!(stage_steps(1.0, 0.5), 2);
        assert_eq!(stage_steps(1e300, 1e-300), u64::MAX);
        assert_eq!(stage_steps(f64::NAN, 1.0), u64::MAX);
        assert!(bound_steps("x", 10, 5).is_err());
    }
}
