//! The records as the workflow sees them ([`Data`]: `y` required, enough samples, an input
//! that moves), their noise floor (step 2 of the loop in [`super`]), and the noise-free
//! simulation of a model on them (step 1).
//!
//! The noise floor is the median absolute second difference of `y`, scaled to the standard
//! deviation of white noise (`1.4826 MAD / sqrt(6)`), on the samples at least 10 ms after the
//! last input change when there are enough of them, so ringing after edges does not count.

use super::constants::{FAST_RATE_HZ, MIN_SAMPLES};
use crate::io::csv::Record;
use crate::io::model_file::ModelFile;
use crate::sim::open_loop::simulate;
use crate::util::median;
use anyhow::{Context, bail, ensure};

/// One measured record ready for the workflow.
#[derive(Clone, Debug)]
pub struct Data {
    /// Name (file name) for tables and the report.
    pub name: String,
    /// Sample times, seconds (uniform).
    pub t_s: Vec<f64>,
    /// Amplifier input, volts.
    pub u_v: Vec<f64>,
    /// Sensor monitor, volts.
    pub y_v: Vec<f64>,
}

impl Data {
    /// From a parsed record: `y` required, at least [`MIN_SAMPLES`] samples, an input that
    /// moves.
    pub fn from_record(name: &str, rec: Record) -> anyhow::Result<Self> {
        let y = rec
            .require_y()
            .with_context(|| format!("record {name}"))?
            .to_vec();
        let n = rec.len();
        ensure!(
            n >= MIN_SAMPLES,
            "record {name}: {n} samples is too short to show anything (at least {MIN_SAMPLES} are needed)"
        );
        let (lo, hi) = min_max(&rec.u_v);
        ensure!(
            hi - lo > 0.05,
            "record {name}: the input u never moves (span {:.3} V): nothing to compare",
            hi - lo
        );
        Ok(Self {
            name: name.to_string(),
            t_s: rec.t_s,
            u_v: rec.u_v,
            y_v: y,
        })
    }

    /// Sampling period, seconds.
    pub fn period_s(&self) -> f64 {
        let n = self.t_s.len();
        (self.t_s[n - 1] - self.t_s[0]) / (n - 1) as f64
    }

    /// Is this a fast record (edges resolved)?
    pub fn is_fast(&self) -> bool {
        1.0 / self.period_s() >= FAST_RATE_HZ
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// Never empty (checked on construction).
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }
}

/// Smallest and largest value.
pub fn min_max(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        })
}

/// Mean square of `a - b`.
pub fn mse(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()).max(1);
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / n as f64
}

/// Noise floor of a record, volts: robust standard deviation of its second differences.
#[allow(clippy::needless_range_loop)] // several arrays indexed together
pub fn noise_floor(d: &Data) -> f64 {
    let n = d.len();
    let settle = (0.01 / d.period_s()).ceil() as usize;
    let mut since = vec![usize::MAX; n];
    let mut last_change: Option<usize> = None;
    for i in 0..n {
        if i > 0 && (d.u_v[i] - d.u_v[i - 1]).abs() > 1e-9 {
            last_change = Some(i);
        }
        since[i] = last_change.map_or(usize::MAX, |c| i - c);
    }
    let second = |quiet: bool| -> Vec<f64> {
        (2..n)
            .filter(|&i| !quiet || since[i - 2] >= settle)
            .map(|i| (d.y_v[i] - 2.0 * d.y_v[i - 1] + d.y_v[i - 2]).abs())
            .collect()
    };
    let mut v = second(true);
    if v.len() < 100 {
        v = second(false);
    }
    1.4826 * median(&mut v) / 6f64.sqrt()
}

/// Simulate `model` (without sensor noise) on a record.
pub fn sim(model: &ModelFile, d: &Data) -> anyhow::Result<Vec<f64>> {
    let mut m = model.clone();
    m.converters.noise_v = 0.0;
    let stage = m.build_stage()?;
    Ok(simulate(&stage, m.period_s, &d.t_s, &d.u_v))
}

/// Read the records named on the command line: CSV or MATLAB v5 `.mat` (with `vars`).
pub fn load_data(paths: &[std::path::PathBuf], vars: Option<&str>) -> anyhow::Result<Vec<Data>> {
    if paths.is_empty() {
        bail!("no records: give at least one --data FILE");
    }
    let mut out = Vec::new();
    for p in paths {
        let name = p.file_name().map_or_else(
            || p.display().to_string(),
            |s| s.to_string_lossy().into_owned(),
        );
        let is_mat = p.extension().is_some_and(|e| e.eq_ignore_ascii_case("mat"));
        let rec = if is_mat {
            crate::io::mat::read_record(p, vars.unwrap_or("t=t,u=u,y=y"))?
        } else {
            Record::read(p).with_context(|| format!("record {}", p.display()))?
        };
        out.push(Data::from_record(&name, rec)?);
    }
    Ok(out)
}
