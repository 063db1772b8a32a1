//! The recording protocol `identification` (issue #7, item 6): the two records a lab takes so
//! that every catalogued effect shows.
//!
//! * **fast record**, 50 kHz, 0.2 s: 5 ms at 0 V, then ten steps held 18 ms each between
//!   levels 1, 3, 2.5, 6, 4, 9, 8.5, 2, 0.5, 5 V: small and large edges up and down. Exposes
//!   `time-delay` and `amplifier-pole` (the first 0.3 ms after every edge), `resonance` (the
//!   ringing, resolved up to 25 kHz), `slew-rate-limit` (large edges ramp, small ones do not),
//!   `saturation` (only if the levels are moved to the amplifier's limits);
//! * **slow record**, 1 kHz, 150 s (any length from 20 s): the first half holds four levels
//!   (5, 2, 8, 5 V: the same level reached from below and from above) for an eighth of the
//!   record each: `drift` (tails during holds), `hysteresis` (the two 5 V plateaus differ),
//!   `nonlinear-gain` (the static gain at 2, 5 and 8 V); the second half cycles slowly: two
//!   0-10-0 V triangles over a quarter of the record, then a sine around 5 V at 0.2 Hz whose
//!   amplitude decays from 5 to 0.5 V (nested reversals): `hysteresis` loops and
//!   `nonlinear-gain` over the whole range, drift under a moving input.
//!
//! The stage starts at rest at 0 V in both (hold the input at 0 V for a minute before the slow
//! record).

use crate::io::csv::Record;
use crate::io::model_file::ModelFile;
use crate::sim::open_loop::simulate;
use std::path::{Path, PathBuf};

/// Levels of the fast record's steps, volts at the amplifier input.
pub const FAST_LEVELS_V: [f64; 10] = [1.0, 3.0, 2.5, 6.0, 4.0, 9.0, 8.5, 2.0, 0.5, 5.0];

/// The fast record's input at `rate_hz` for `seconds`.
pub fn fast_input(rate_hz: f64, seconds: f64) -> (Vec<f64>, Vec<f64>) {
    let n = (seconds * rate_hz).round().max(2.0) as usize;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / rate_hz).collect();
    let hold = (seconds - 0.005) / FAST_LEVELS_V.len() as f64;
    let u = t
        .iter()
        .map(|&x| {
            if x < 0.005 {
                0.0
            } else {
                let k = (((x - 0.005) / hold) as usize).min(FAST_LEVELS_V.len() - 1);
                FAST_LEVELS_V[k]
            }
        })
        .collect();
    (t, u)
}

/// The slow record's input at `rate_hz` for `seconds`.
pub fn slow_input(rate_hz: f64, seconds: f64) -> (Vec<f64>, Vec<f64>) {
    let n = (seconds * rate_hz).round().max(2.0) as usize;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / rate_hz).collect();
    let tt = seconds;
    let levels = [5.0, 2.0, 8.0, 5.0];
    let hold = tt / 8.0;
    let tri = tt / 8.0; // each triangle
    let sine_start = tt / 2.0 + 2.0 * tri;
    let sine_len = tt - sine_start;
    let u = t
        .iter()
        .map(|&x| {
            if x < 0.5 {
                0.0
            } else if x < tt / 2.0 {
                levels[(((x - 0.5) / hold) as usize).min(3)]
            } else if x < sine_start {
                // 5 -> 0 -> 10 -> 0 -> 10 -> 5 V, piecewise linear.
                let pts = [
                    (0.0, 5.0),
                    (0.125, 0.0),
                    (0.375, 10.0),
                    (0.625, 0.0),
                    (0.875, 10.0),
                    (1.0, 5.0),
                ];
                let p = (x - tt / 2.0) / (sine_start - tt / 2.0);
                let k = pts
                    .iter()
                    .rposition(|q| q.0 <= p)
                    .unwrap_or(0)
                    .min(pts.len() - 2);
                let (p0, u0) = pts[k];
                let (p1, u1) = pts[k + 1];
                u0 + (u1 - u0) * (p - p0) / (p1 - p0)
            } else {
                let s = x - sine_start;
                let amp = 5.0 * (0.1f64).powf(s / sine_len);
                5.0 - amp * (2.0 * std::f64::consts::PI * 0.2 * s).sin()
            }
        })
        .map(|u: f64| u.clamp(0.0, 10.0))
        .collect();
    (t, u)
}

/// The two records of the protocol from `model`, with its sensor noise and seed: `("fast",
/// 50 kHz, 0.2 s)` and `("slow", 1 kHz, slow_seconds)`, simulated by the same stage in that
/// order.
pub fn records(
    model: &ModelFile,
    slow_seconds: f64,
) -> anyhow::Result<Vec<(&'static str, Record)>> {
    let stage = model.build_stage()?;
    let mut out = Vec::with_capacity(2);
    for (tag, (t, u)) in [
        ("fast", fast_input(model_core::params::SAMPLE_RATE_HZ, 0.2)),
        ("slow", slow_input(1_000.0, slow_seconds)),
    ] {
        let y = simulate(&stage, model.period_s, &t, &u);
        out.push((tag, Record::new(t, u, Some(y), None)?));
    }
    Ok(out)
}

/// `piezo synth --protocol identification --output FILE.csv`: the records for `FILE-fast.csv`
/// (50 kHz, 0.2 s) and `FILE-slow.csv` (1 kHz, `seconds` long, at least 20 s) from the model
/// file or built-in `model`, with its noise (or `noise_v`) and `seed` ([`record_path`] names
/// the files).
pub fn synth_identification(
    model: &str,
    seed: u64,
    noise_v: Option<f64>,
    seconds: f64,
) -> anyhow::Result<Vec<(&'static str, Record)>> {
    anyhow::ensure!(
        seconds.is_finite() && (20.0..=3600.0).contains(&seconds.max(20.0)),
        "--seconds (the slow record's length) must be within 20..3600 s"
    );
    let mut model = ModelFile::load(model)?;
    model.converters.seed = seed;
    if let Some(n) = noise_v {
        anyhow::ensure!(
            n.is_finite() && (0.0..=1.0).contains(&n),
            "--noise-v must be within 0..1 V"
        );
        model.converters.noise_v = n;
    }
    records(&model, seconds.max(20.0))
}

/// Where `piezo synth --protocol identification --output FILE.csv` writes the record `tag`:
/// `FILE-<tag>.csv`.
pub fn record_path(output: &Path, tag: &str) -> PathBuf {
    let stem = output.with_extension("");
    PathBuf::from(format!("{}-{tag}.csv", stem.display()))
}
