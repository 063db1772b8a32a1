//! The records as the workflow sees them ([`Data`]: `y` required, enough samples, an input
//! that moves), their noise floor (step 2 of the loop in [`super`]), and the noise-free
//! simulation of a model on them (step 1).
//!
//! The noise floor is the median absolute k-th difference of `y`, scaled to the standard
//! deviation of white noise (`1.4826 MAD / sqrt(C(2k, k))`), the smallest of k = 2, 3, 4 (a
//! smooth signal inflates the low orders: no holds are assumed), on the samples at least 10 ms
//! after the last input change when there are enough of them, so ringing after edges does not
//! count.

use super::constants::{
    FAST_RATE_HZ, HOLD_BAND_SIGMAS, JUMP_MIN_V, JUMP_RATIO, MIN_SAMPLES, REST_ZERO_INPUT_V,
    REST_ZERO_MIN_S, REVERSAL_MIN_V,
};
use crate::io::csv::Record;
use crate::io::model_file::ModelFile;
use crate::sim::open_loop::simulate_after;
use crate::util::median;
use anyhow::{Context, bail, ensure};
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

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
    /// How far the recorded input may wander and still count as held, volts
    /// ([`hold_band_v`]): 1 nV for an input logged as the exact command, wider when the input
    /// was measured with noise.
    pub hold_band_v: f64,
    /// The simulations of this record already run ([`sim`] looks here first).
    pub memo: SimMemo,
}

/// Simulations already run on one record, by model: the workflow simulates one model on one
/// record more than once (the model without slow effects at each step and in each pruning
/// trial, a candidate the fast search lands on again, a pruned model that is an earlier
/// step's), and a simulation at the 50 kHz step is its costliest part (measured on the gap
/// bench: 195 of the 340 simulations of a diagnosis repeat an earlier one, 4.1 s of its 10.6 s
/// of simulation). Keyed by the model's whole TOML text and a fingerprint of the record's
/// input, so a hit is the same simulation, not a near one; the oldest entries go first
/// beyond [`SIM_MEMO_ENTRIES`]. Clones of a record share it.
#[derive(Clone, Default)]
pub struct SimMemo(Arc<Mutex<VecDeque<MemoEntry>>>);

/// One simulation a [`SimMemo`] keeps: the model's TOML text, the input's fingerprint, the
/// simulated output.
type MemoEntry = (String, u64, Arc<Vec<f64>>);

impl std::fmt::Debug for SimMemo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.0.lock().map_or(0, |q| q.len());
        write!(f, "SimMemo({n} simulations)")
    }
}

/// Simulations a record's [`SimMemo`] keeps (our assumption: a step's candidates, its
/// pruning trials and the start search's simulations fit; 32 simulations of a 10 s record at
/// 50 kHz take 128 MB).
pub const SIM_MEMO_ENTRIES: usize = 32;

impl SimMemo {
    fn get(&self, key: &str, input: u64) -> Option<Arc<Vec<f64>>> {
        let q = self.0.lock().ok()?;
        q.iter()
            .find(|(k, i, _)| *i == input && k == key)
            .map(|(_, _, y)| Arc::clone(y))
    }

    fn put(&self, key: String, input: u64, y: Arc<Vec<f64>>) {
        if let Ok(mut q) = self.0.lock() {
            if q.iter().any(|(k, i, _)| *i == input && *k == key) {
                return;
            }
            if q.len() >= SIM_MEMO_ENTRIES {
                q.pop_front();
            }
            q.push_back((key, input, y));
        }
    }
}

/// A fingerprint of a record's times and input (FNV-1a over their bits): the memo's guard
/// against a record whose samples were changed after it was made.
fn input_fingerprint(d: &Data) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for x in d.t_s.iter().chain(&d.u_v) {
        h = (h ^ x.to_bits()).wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// [`HOLD_BAND_SIGMAS`] times a robust estimate of the noise on the recorded input (median
/// absolute second difference; 0 where the input is mostly held or moves smoothly, as a
/// logged DAC command does), at least 1 nV. An input measured through a converter wanders by
/// its noise during a hold; without the band no hold is found, and the drift's evidence, the
/// report's tails and the cannot-tell check ([`Data::holds`]) see none.
pub fn hold_band_v(u_v: &[f64]) -> f64 {
    let mut d2: Vec<f64> = u_v
        .windows(3)
        .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
        .collect();
    // Second differences of white noise of variance s^2 have variance 6 s^2.
    let sigma = if d2.is_empty() {
        0.0
    } else {
        1.4826 * median(&mut d2) / 6f64.sqrt()
    };
    (HOLD_BAND_SIGMAS * sigma).max(1e-9)
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
        let hold_band_v = hold_band_v(&rec.u_v);
        Ok(Self {
            name: name.to_string(),
            t_s: rec.t_s,
            u_v: rec.u_v,
            y_v: y,
            hold_band_v,
            memo: SimMemo::default(),
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

    /// Is the input's change into sample `i` a jump (an edge the dynamics must settle from)?
    /// More than [`JUMP_MIN_V`] and more than [`JUMP_RATIO`] times the changes on either side:
    /// a step is a jump whatever the rate, a sine or a ramp sampled coarsely is not (each of
    /// its changes is like its neighbours).
    pub fn is_jump(&self, i: usize) -> bool {
        if i == 0 || i >= self.u_v.len() {
            return false;
        }
        let du = |k: usize| {
            if k == 0 || k >= self.u_v.len() {
                0.0
            } else {
                (self.u_v[k] - self.u_v[k - 1]).abs()
            }
        };
        let d = du(i);
        d > JUMP_MIN_V && d > JUMP_RATIO * du(i - 1).max(du(i + 1))
    }

    /// Number of reversals of the input: changes of direction after a move of at least
    /// [`REVERSAL_MIN_V`] (a record with reversals shows hysteresis as a loop).
    pub fn reversals(&self) -> usize {
        let mut count = 0;
        let mut dir = 0.0f64;
        let mut extreme = self.u_v[0];
        for &u in &self.u_v {
            let d = u - extreme;
            if dir >= 0.0 && d > 0.0 || dir <= 0.0 && d < 0.0 {
                extreme = u;
                if dir == 0.0 && d.abs() >= REVERSAL_MIN_V {
                    dir = d.signum();
                }
            } else if d.abs() >= REVERSAL_MIN_V {
                count += 1;
                dir = d.signum();
                extreme = u;
            }
        }
        count
    }

    /// The holds of the record: runs of constant input (within 1 nV) of at least
    /// [`super::constants::HOLD_MIN_S`], as `start..end` sample ranges (where a drift shows
    /// as a tail and a hysteresis loop does not).
    pub fn holds(&self) -> Vec<std::ops::Range<usize>> {
        self.holds_of(super::constants::HOLD_MIN_S)
    }

    /// The runs of constant input (within the record's hold band) from the second sample on
    /// that last `min_s` seconds or more, as `start..end` sample ranges; a run after the first
    /// starts at the sample where the input left the last one.
    pub fn holds_of(&self, min_s: f64) -> Vec<std::ops::Range<usize>> {
        let (n, t) = (self.len(), self.period_s());
        let mut out = Vec::new();
        let mut i = 1;
        while i < n {
            let start = i;
            while i < n && (self.u_v[i] - self.u_v[start]).abs() <= self.hold_band_v {
                i += 1;
            }
            // `i` is now the next run's first sample (a run holds at least its first; the
            // guard keeps the scan moving whatever the band).
            i = i.max(start + 1);
            if (i - start) as f64 * t >= min_s {
                out.push(start..i);
            }
        }
        out
    }

    /// Samples of the record's rest at 0 V input from its first sample: until the input first
    /// leaves [`REST_ZERO_INPUT_V`] of 0 V, where that lasts [`REST_ZERO_MIN_S`] at least (the
    /// one reading that is the sensor's zero: nothing but an offset moves the output there).
    pub fn zero_rest_len(&self) -> Option<usize> {
        let end = self
            .u_v
            .iter()
            .position(|u| u.abs() > REST_ZERO_INPUT_V)
            .unwrap_or(self.len());
        (end as f64 * self.period_s() >= REST_ZERO_MIN_S).then_some(end)
    }

    /// Does the record have a hold ([`Self::holds`])?
    pub fn has_hold(&self) -> bool {
        !self.holds().is_empty()
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

/// Noise floor of a record, volts: robust standard deviation of its second, third or fourth
/// differences (the smallest estimate), on quiet samples when there are enough.
#[allow(clippy::needless_range_loop)] // several arrays indexed together
pub fn noise_floor(d: &Data) -> f64 {
    let n = d.len();
    let settle = (0.01 / d.period_s()).ceil() as usize;
    let mut since = vec![usize::MAX; n];
    let mut last_change: Option<usize> = None;
    for i in 0..n {
        if i > 0 && (d.u_v[i] - d.u_v[i - 1]).abs() > d.hold_band_v {
            last_change = Some(i);
        }
        since[i] = last_change.map_or(usize::MAX, |c| i - c);
    }
    // k-th differences of y: white noise of variance s^2 gives variance C(2k, k) s^2; a smooth
    // signal (a sine, a ramp, a drift) adds (w dt)^k of itself, so the smallest of the k = 2,
    // 3, 4 estimates is the one least inflated by the signal (a 20 Hz sine sampled at 1 kHz
    // inflates the second differences' estimate, not the fourth's).
    let diff = |k: usize, quiet: bool| -> Vec<f64> {
        (k..n)
            .filter(|&i| !quiet || since[i - k] >= settle)
            .map(|i| {
                let mut c = 1.0f64;
                let mut acc = 0.0;
                for j in 0..=k {
                    acc += c * d.y_v[i - j];
                    c = -c * (k - j) as f64 / (j + 1) as f64;
                }
                acc.abs()
            })
            .collect()
    };
    let quiet = diff(2, true).len() >= 100;
    [(2usize, 6.0f64), (3, 20.0), (4, 70.0)]
        .iter()
        .map(|&(k, var)| 1.4826 * median(&mut diff(k, quiet)) / var.sqrt())
        .fold(f64::INFINITY, f64::min)
}

/// The [`SimMemo`]'s key of `m`: its TOML text, but for the hysteresis table's values, which
/// follow as the hexadecimal bits of each (exact, and no float formatting: the TOML text of a
/// table of a thousand values was a twentieth of a diagnosis' CPU time, most of it the keys of
/// the fast searches' thousands of short simulations). TOML has no comment of its own, so the
/// table's part cannot be confused with the model's.
fn memo_key(m: &mut ModelFile) -> Option<String> {
    let table = m.hysteresis.as_mut().and_then(|h| h.everett_v.take());
    let text = toml::to_string(m).ok();
    let key = text.map(|mut k| {
        if let Some(t) = &table {
            use std::fmt::Write;
            k.push_str("# everett_v bits:");
            for v in t {
                let _ = write!(k, " {:08x}", v.to_bits());
            }
        }
        k
    });
    if let Some(h) = m.hysteresis.as_mut() {
        h.everett_v = table;
    }
    key
}

/// Simulate `model` (without sensor noise) on a record; a simulation the record's
/// [`SimMemo`] holds is not run again.
pub fn sim(model: &ModelFile, d: &Data) -> anyhow::Result<Vec<f64>> {
    let mut m = model.clone();
    m.converters.noise_v = 0.0;
    // Without noise the seed changes nothing: one key for every seed.
    m.converters.seed = 0;
    let key = memo_key(&mut m);
    let input = input_fingerprint(d);
    if let Some(y) = key.as_deref().and_then(|k| d.memo.get(k, input)) {
        return Ok(y.as_ref().clone());
    }
    let stage = m.build_stage()?;
    let y = simulate_after(&stage, m.period_s, &m.start_history_v(), &d.t_s, &d.u_v);
    if let Some(k) = key {
        d.memo.put(k, input, Arc::new(y.clone()));
    }
    Ok(y)
}

/// [`sim`] of `model` on every record, and each record's mean square residual.
pub fn simulate_all(model: &ModelFile, data: &[Data]) -> anyhow::Result<(Vec<Vec<f64>>, Vec<f64>)> {
    let sims: Vec<Vec<f64>> = data
        .iter()
        .map(|d| sim(model, d))
        .collect::<anyhow::Result<_>>()?;
    let ms = data
        .iter()
        .zip(&sims)
        .map(|(d, y)| mse(&d.y_v, y))
        .collect();
    Ok((sims, ms))
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
        if let Some(note) = rec.time_note(&name) {
            eprintln!("{note}");
        }
        out.push(Data::from_record(&name, rec)?);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sine_record() -> Data {
        let t: Vec<f64> = (0..2000).map(|i| i as f64 * 1e-4).collect();
        let u: Vec<f64> = t.iter().map(|&x| 5.0 + 4.0 * (20.0 * x).sin()).collect();
        let y = vec![0.0; t.len()];
        Data::from_record("sine", Record::new(t, u, Some(y), None).unwrap()).unwrap()
    }

    /// A memo hit is the simulation itself; a changed model or a changed input is simulated
    /// afresh, never served an earlier one's output.
    #[test]
    fn the_memo_returns_only_the_same_simulation() {
        let d = sine_record();
        let m = ModelFile::built_in("thesis-linear").unwrap();
        let first = sim(&m, &d).unwrap();
        let again = sim(&m, &d).unwrap();
        assert_eq!(first, again);
        // Another model: another output (the sensor gain scales it by 1 %).
        let mut m2 = m.clone();
        m2.converters.sensor_gain = 1.01;
        let scaled = sim(&m2, &d).unwrap();
        let peak = first.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        assert!(
            scaled
                .iter()
                .zip(&first)
                .any(|(a, b)| (a - b).abs() > 1e-3 * peak)
        );
        // The same record with its input changed after it was made: simulated afresh.
        let mut d2 = d.clone();
        for u in d2.u_v.iter_mut() {
            *u *= 0.5;
        }
        let halved = sim(&m, &d2).unwrap();
        let fresh = {
            let mut d3 = sine_record();
            d3.u_v.clone_from(&d2.u_v);
            d3.memo = SimMemo::default();
            sim(&m, &d3).unwrap()
        };
        assert_eq!(halved, fresh);
        assert!(
            halved
                .iter()
                .zip(&first)
                .any(|(a, b)| (a - b).abs() > 0.1 * peak)
        );
    }

    /// The memo's key tells apart tables one bit apart in one value, and one model from the
    /// same with its table gone; the model comes back with its table; a table one value
    /// apart gives another simulation, never the first's.
    #[test]
    fn the_memo_key_holds_the_table_exactly() {
        let mut m = ModelFile::built_in("thesis-full").unwrap();
        assert!(
            m.hysteresis
                .as_ref()
                .and_then(|h| h.everett_v.as_ref())
                .is_some()
        );
        let before = m.clone();
        let k1 = memo_key(&mut m).unwrap();
        assert_eq!(m, before, "the key must leave the model as it was");
        let mut m2 = m.clone();
        if let Some(t) = m2.hysteresis.as_mut().and_then(|h| h.everett_v.as_mut()) {
            t[7] = f32::from_bits(t[7].to_bits() + 1);
        }
        let k2 = memo_key(&mut m2).unwrap();
        assert_ne!(k1, k2);
        let mut m3 = m.clone();
        if let Some(h) = m3.hysteresis.as_mut() {
            h.everett_v = None;
        }
        assert_ne!(k1, memo_key(&mut m3).unwrap());
        assert_eq!(k1, memo_key(&mut m.clone()).unwrap());
        // Through `sim`: the changed table is simulated, not served from the memo.
        let d = sine_record();
        let mut big = m.clone();
        if let Some(t) = big.hysteresis.as_mut().and_then(|h| h.everett_v.as_mut()) {
            for v in t.iter_mut() {
                *v *= 1.5;
            }
        }
        let a = sim(&m, &d).unwrap();
        let b = sim(&big, &d).unwrap();
        assert!(a.iter().zip(&b).any(|(x, y)| (x - y).abs() > 1e-3));
    }
}
