//! The records as the workflow sees them ([`Data`]: `y` required, enough samples, an input
//! that moves), their noise floor (step 2 of the loop in [`super`]), and the noise-free
//! simulation of a model on them (step 1).
//!
//! The noise floor is the median absolute k-th difference of `y`, scaled to the standard
//! deviation of white noise (`1.4826 MAD / sqrt(C(2k, k))`), the smallest of k = 2, 3, 4 (a
//! smooth signal inflates the low orders: no holds are assumed), on the samples at least 10 ms
//! after the last input change when there are enough of them, so ringing after edges does not
//! count. Noise that a sensor's or an anti-alias filter's bandwidth has coloured is partly
//! cancelled by close differences: the same estimate over samples 2, 4, ... apart grows until
//! they decorrelate, and the floor is the estimate where it stops growing
//! ([`strided_floor`]).

use super::constants::{
    FAST_RATE_HZ, GAP_MIN_RATE_HZ, GAP_RATE_TOLERANCE, GLITCH_FLOORS, GLITCH_RUN_MAX,
    GLITCH_RUN_NEIGHBOURS, GLITCH_SPREAD_FLOORS, HOLD_BAND_SIGMAS, JUMP_MIN_V, JUMP_RATIO,
    MIN_SAMPLES, NOISE_DECORRELATE_MAX_S, NOISE_SIGNAL_SHARE, NOISE_STRIDE_GROWTH,
    NOISE_WALK_MIN_DIFFS, RECORD_BITS_MAX, REST_ZERO_INPUT_V, REST_ZERO_MIN_S, REVERSAL_MIN_V,
    STEP_MIN_VALUES, STEP_TEXT_MIN_SPAN_V, STEP_TEXT_SHARE, SWAPPED_NOISE_RATIO,
};
use crate::io::csv::Record;
use crate::io::model_file::ModelFile;
use crate::sim::open_loop::simulate_after_while;
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
    /// Where the record was averaged from a faster one ([`decimated`]): that record's input,
    /// which [`sim`] runs the stage on, so that each sample reads the mean of the stage's
    /// output over its block, as the averaged record does. `None` for a record as measured.
    pub fine: Option<Arc<FineInput>>,
}

/// The input of a record at its own rate, beside the record averaged from it ([`decimated`]).
#[derive(Debug)]
pub struct FineInput {
    /// Sample times, seconds (uniform, the faster rate).
    pub t_s: Vec<f64>,
    /// Amplifier input, volts.
    pub u_v: Vec<f64>,
    /// Samples per block of the averaged record.
    pub factor: usize,
    /// [`input_fingerprint`]'s hash of the times and the input, taken once.
    fingerprint: u64,
}

impl FineInput {
    fn new(t_s: Vec<f64>, u_v: Vec<f64>, factor: usize) -> Self {
        let fingerprint = fingerprint_of(t_s.iter().chain(&u_v), 0xcbf2_9ce4_8422_2325);
        Self {
            t_s,
            u_v,
            factor,
            fingerprint,
        }
    }

    /// The fine input under the first `k` samples of the averaged record.
    pub fn head(&self, k: usize) -> Self {
        let n = (k * self.factor).min(self.t_s.len());
        Self::new(self.t_s[..n].to_vec(), self.u_v[..n].to_vec(), self.factor)
    }
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
    let start = d
        .fine
        .as_ref()
        .map_or(0xcbf2_9ce4_8422_2325, |f| f.fingerprint);
    fingerprint_of(d.t_s.iter().chain(&d.u_v), start)
}

/// FNV-1a over the bits of `values`, from `h`.
fn fingerprint_of<'a>(values: impl Iterator<Item = &'a f64>, mut h: u64) -> u64 {
    for x in values {
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
        let rate_hz = rec.rate_hz();
        let hz = |r: f64| {
            if r >= 1.0 {
                format!("{r:.1}")
            } else {
                format!("{r:.3e}")
            }
        };
        ensure!(
            rate_hz >= (1.0 - GAP_RATE_TOLERANCE) * GAP_MIN_RATE_HZ,
            "record {name}: sampled at {} Hz (t from {:.4} to {:.4} s over {n} samples); the model-gap \
             workflow reads records sampled at {GAP_MIN_RATE_HZ} Hz or faster{}",
            hz(rate_hz),
            rec.t_s[0],
            rec.t_s[n - 1],
            if rate_hz * 1e3 >= GAP_MIN_RATE_HZ {
                format!(
                    ": is its time column in milliseconds? (in seconds the record would be \
                     sampled at {} Hz)",
                    hz(rate_hz * 1e3)
                )
            } else {
                String::new()
            }
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
            fine: None,
        })
    }

    /// The record with output samples replaced: `(index, value)` pairs, as [`glitches`] gives
    /// them (an index beyond the record is left out).
    pub fn with_samples_replaced(&self, samples: &[(usize, f64)]) -> Self {
        let mut c = self.clone();
        for &(i, v) in samples {
            if let Some(y) = c.y_v.get_mut(i) {
                *y = v;
            }
        }
        c
    }

    /// The record's length, seconds (first to last sample; `None` without samples).
    pub fn length_s(&self) -> Option<f64> {
        Some(self.t_s.last()? - self.t_s.first()?)
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

/// The longest record's length, seconds ([`Data::length_s`]; 0 without records).
pub fn longest_record_s(data: &[Data]) -> f64 {
    data.iter()
        .filter_map(Data::length_s)
        .fold(0.0f64, f64::max)
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
/// differences (the smallest estimate), on quiet samples when there are enough; where the
/// noise is coloured (a sensor's or an anti-alias filter's bandwidth below the record's
/// Nyquist rate), the same estimate over samples far enough apart for the noise to decorrelate
/// ([`strided_floor`]).
///
/// `model_y` is a model's noise-free output on the record (the base model's): what it moves
/// fast is signal, not noise (without it, any growth with the stride counts as the noise's).
pub fn noise_floor(d: &Data, model_y: Option<&[f64]>) -> f64 {
    noise_floor_of(d, model_y).sigma_v
}

/// A record's noise floor and how it was found ([`noise_floor_of`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseFloor {
    /// The floor, volts.
    pub sigma_v: f64,
    /// The estimate from neighbouring samples, volts (the floor where the noise is white).
    pub close_v: f64,
    /// Where the noise is coloured: the samples' spacing, seconds, at which it decorrelated.
    pub decorrelated_s: Option<f64>,
    /// The record's resolution: its output's smallest step, volts ([`output_step_v`]).
    pub step_v: f64,
    /// Whether the output showed that step (else it is the span's `RECORD_BITS_MAX`-bit
    /// share).
    pub step_seen: bool,
    /// Whether the floor is the resolution's (`step_v / sqrt(12)`), above what the
    /// differences give.
    pub by_resolution: bool,
}

impl NoiseFloor {
    /// Words for the table where the noise is coloured or below the record's resolution.
    pub fn note(&self, name: &str) -> Option<String> {
        if self.by_resolution && !self.step_seen {
            return Some(format!(
                "{name}: neighbouring samples barely differ ({:.3} mV of noise) and the output \
                 shows no converter step coarser than {RECORD_BITS_MAX} bits of its span: the \
                 floor is the rounding of {RECORD_BITS_MAX} bits over its span, {:.3} mV",
                1e3 * self.close_v,
                1e3 * self.sigma_v
            ));
        }
        if self.by_resolution {
            return Some(format!(
                "{name}: the output moves in steps of {:.3} mV, and neighbouring samples differ \
                 by less than that ({:.3} mV of noise): the floor is the steps' own rounding, \
                 {:.3} mV (step / sqrt 12)",
                1e3 * self.step_v,
                1e3 * self.close_v,
                1e3 * self.sigma_v
            ));
        }
        self.decorrelated_s.map(|s| {
            format!(
                "{name}: the noise is coloured (a sensor or filter bandwidth below the record's \
                 Nyquist rate): neighbouring samples give {:.2} mV, samples {:.3} ms apart \
                 {:.2} mV, which is the floor",
                1e3 * self.close_v,
                1e3 * s,
                1e3 * self.sigma_v
            )
        })
    }
}

/// [`noise_floor`] with how it was found.
pub fn noise_floor_of(d: &Data, model_y: Option<&[f64]>) -> NoiseFloor {
    let model_y = model_y.filter(|s| s.len() == d.len());
    let max_stride = ((NOISE_DECORRELATE_MAX_S / d.period_s()).floor() as usize).max(1);
    let (step_v, step_seen, _) = output_step_v(&d.y_v);
    let rounding_v = step_v / 12f64.sqrt();
    let (noise_v, stride) = floor_within(d, model_y, max_stride);
    // (the neighbours' estimate is the walk's first: read again only where it walked on)
    let close_v = if stride == 1 {
        noise_v
    } else {
        floor_within(d, model_y, 1).0
    };
    // (noise below the record's steps: the differences see the steps, not the noise, and the
    // strides' growth is the signal crossing them)
    let by_resolution = close_v < rounding_v;
    NoiseFloor {
        sigma_v: if by_resolution { rounding_v } else { noise_v },
        close_v,
        decorrelated_s: (stride > 1 && !by_resolution).then(|| stride as f64 * d.period_s()),
        step_v,
        step_seen,
        by_resolution,
    }
}

/// The noise of a record's input column where it looks like a sensor's reading beside an
/// output that looks like a command (`y_floor` the output's [`noise_floor_of`]): the output
/// shows no noise above its own rounding, and the input's floor, read the same way, is at
/// least [`SWAPPED_NOISE_RATIO`] times the output's, each as a share of its column's span: a
/// sensor's reading in the input's column and a command in the output's. `None` otherwise.
pub fn swapped_columns(d: &Data, y_floor: &NoiseFloor) -> Option<f64> {
    if !y_floor.by_resolution {
        return None;
    }
    let as_output = Data {
        y_v: d.u_v.clone(),
        ..d.clone()
    };
    let u_floor = noise_floor_of(&as_output, None);
    // (each column's noise as a share of its span: the input and the output need not share
    // a scale)
    let span = |v: &[f64]| {
        let (lo, hi) = min_max(v);
        (hi - lo).max(1e-12)
    };
    let (u_share, y_share) = (
        u_floor.sigma_v / span(&d.u_v),
        y_floor.sigma_v / span(&d.y_v),
    );
    (!u_floor.by_resolution && u_share >= SWAPPED_NOISE_RATIO * y_share).then_some(u_floor.sigma_v)
}

/// The least-squares line of `y` on `x` over their common length: its slope and the means it
/// goes through, the correlation of the two, and how far `x` moves (standard deviation). A
/// record's output on the model's simulated output (its slope, sign and the model's
/// movement: the refusals), or a residual on sample index (a glitch run's neighbours).
pub struct LineFit {
    /// Mean of `x`.
    pub mean_x: f64,
    /// Mean of `y`.
    pub mean_y: f64,
    /// Slope of `y` on `x`.
    pub slope: f64,
    /// Correlation of `y` with `x`.
    pub correlation: f64,
    /// Standard deviation of `x`.
    pub sd_x: f64,
}

impl LineFit {
    /// `y` on `x`; `None` under two samples.
    pub fn of(y: &[f64], x: &[f64]) -> Option<Self> {
        let n = y.len().min(x.len());
        if n < 2 {
            return None;
        }
        let my = y[..n].iter().sum::<f64>() / n as f64;
        let mx = x[..n].iter().sum::<f64>() / n as f64;
        let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
        for (a, b) in y[..n].iter().zip(&x[..n]) {
            sxy += (a - my) * (b - mx);
            syy += (a - my) * (a - my);
            sxx += (b - mx) * (b - mx);
        }
        Some(Self {
            mean_x: mx,
            mean_y: my,
            slope: sxy / sxx.max(1e-300),
            correlation: sxy / (sxx * syy).sqrt().max(1e-300),
            sd_x: (sxx / n as f64).sqrt(),
        })
    }

    /// The line's `y` at `x`.
    pub fn at(&self, x: f64) -> f64 {
        self.mean_y + self.slope * (x - self.mean_x)
    }
}

/// The record's resolution, volts: the smallest gap between two of its output's distinct
/// values, and at least its output's span over `2^RECORD_BITS_MAX`. A record rounded by its
/// converter (a scope's 8 or 12 bits, a 16-bit ADC) takes whole steps, and where its noise is
/// below one step, held samples read the same value, the differences' median is zero, and the
/// floor is the rounding's own `step / sqrt(12)` (a model cannot come nearer the record than
/// that on average). An unrounded record's smallest gap is negligible. Gaps below a millionth
/// of the span are the decimal text's, not a converter's. An output of fewer than
/// `STEP_MIN_VALUES` distinct values (held levels that never flip a code) hides the step:
/// there the span's share stands in for it.
///
/// Returns the step, whether the output showed it, and the smallest gap itself (the output's
/// span where it takes one value).
pub fn output_step_v(y: &[f64]) -> (f64, bool, f64) {
    let (lo, hi) = min_max(y);
    let span = (hi - lo).max(0.0);
    let tiny = STEP_TEXT_SHARE * span.max(STEP_TEXT_MIN_SPAN_V);
    let mut v: Vec<f64> = y.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    let gaps: Vec<f64> = v
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|&s| s > tiny)
        .collect();
    let finest = span / 2f64.powi(RECORD_BITS_MAX);
    let gap = gaps.iter().copied().fold(span, f64::min);
    if gaps.len() + 1 < STEP_MIN_VALUES {
        return (finest, false, gap);
    }
    (gap.max(finest), gap >= finest, gap)
}

/// Glitches of a record's output: runs of one to `GLITCH_RUN_MAX` neighbouring samples,
/// each at least `GLITCH_FLOORS` noise floors (or as many of the output's smallest steps, for
/// a rounded record) off the median of the run's six neighbours (three each side) while those
/// neighbours stay within `GLITCH_SPREAD_FLOORS` floors of it, in the record's residual from
/// `model_y` (the base model's simulated output: a one-sample pulse of the input at 1 kHz,
/// which the stage follows within the sample, is in the model's output too, and leaves no
/// residual spike). Away from the input's edges nothing the stage does moves it so: a
/// dynamics the model lacks (a mode) moves many samples and rings, which spreads the
/// neighbours, so this is the recording's (an ADC's or a logger's glitch or burst), and one
/// such sample in 50 000 moves a record's RMS by up to several floors. Samples from four
/// before an input edge to three after it are left: there a delay or a slew limit the model lacks is a short spike of
/// the residual at 1 kHz (families cases 1022 and 1027, whose true delay went with it). Three
/// neighbours a side, not two: a stage ringing at a third of the sampling rate (families case
/// 1032, 12 mV at 6.3 kHz sampled at 19 kHz) repeats each phase every third sample, and with
/// two a side one phase's samples stood alone among the other two's. The shortest run that
/// holds is taken. A longer run needs `GLITCH_RUN_NEIGHBOURS` quiet neighbours a side, and
/// is measured from the straight line through them. Returns each glitch sample's index and
/// the value it is replaced by (the model's output there plus what the neighbours' residual
/// gives: their median, or their line).
pub fn glitches(d: &Data, floor_v: f64, model_y: Option<&[f64]>) -> Vec<(usize, f64)> {
    let n = d.y_v.len();
    let mut out = Vec::new();
    if n < 7 || floor_v <= 0.0 || !floor_v.is_finite() {
        return out;
    }
    let model_y = model_y.filter(|s| s.len() == n);
    let r: Vec<f64> = match model_y {
        Some(s) => d.y_v.iter().zip(s).map(|(a, b)| a - b).collect(),
        None => d.y_v.clone(),
    };
    let (_, _, gap_v) = output_step_v(&d.y_v);
    let bar_v = GLITCH_FLOORS * floor_v.max(gap_v);
    // (samples within four of an input edge are left: a delay or a slew limit the model
    // lacks puts a short spike in the residual at an edge sampled at 1 kHz)
    let mut near_edge = vec![false; n];
    for j in 1..n {
        if d.is_jump(j) {
            for flag in &mut near_edge[j.saturating_sub(4)..(j + 4).min(n)] {
                *flag = true;
            }
        }
    }
    // The run of `len` samples from `i`: what its neighbours say each of its samples should
    // be, if they stay within the spread and every sample of the run is past the bar. One
    // sample: the median of three neighbours a side. A longer run: the straight line through
    // `GLITCH_RUN_NEIGHBOURS` a side (over twenty samples a slow residual's slope, a loop's
    // at 1 Hz, moves a few floors).
    let run = |i: usize, len: usize| -> Option<Vec<f64>> {
        if len == 1 {
            let mut nb = [r[i - 3], r[i - 2], r[i - 1], r[i + 1], r[i + 2], r[i + 3]];
            nb.sort_by(f64::total_cmp);
            let med = 0.5 * (nb[2] + nb[3]);
            let spread = (nb[5] - med).max(med - nb[0]);
            return (spread <= GLITCH_SPREAD_FLOORS * floor_v && (r[i] - med).abs() > bar_v)
                .then(|| vec![med]);
        }
        let side = GLITCH_RUN_NEIGHBOURS;
        if i < side || i + len + side > n {
            return None;
        }
        let at: Vec<usize> = (i - side..i).chain(i + len..i + len + side).collect();
        let xs: Vec<f64> = at.iter().map(|&j| j as f64 - i as f64).collect();
        let ys: Vec<f64> = at.iter().map(|&j| r[j]).collect();
        let line = LineFit::of(&ys, &xs)?;
        let spread = xs
            .iter()
            .zip(&ys)
            .map(|(x, y)| (y - line.at(*x)).abs())
            .fold(0.0, f64::max);
        let want: Vec<f64> = (0..len).map(|j| line.at(j as f64)).collect();
        // (one way: a delay the model lacks under a one-sample input pulse leaves a doublet,
        // one sample each way, which is the stage's)
        let off: Vec<f64> = (0..len).map(|j| r[i + j] - want[j]).collect();
        let one_way = off.iter().all(|&o| o > 0.0) || off.iter().all(|&o| o < 0.0);
        (spread <= GLITCH_SPREAD_FLOORS * floor_v && one_way && off.iter().all(|o| o.abs() > bar_v))
            .then_some(want)
    };
    let mut i = 3;
    while i + 4 <= n {
        // (a run's first sample is past the bar from what its neighbours give, which its
        // left neighbour is within the spread (0.4 of the bar) and one step of their line
        // of: a step of half the bar from that neighbour, or from the line through its two
        // left neighbours where the residual slopes, is needed, and cheap to test first)
        if (r[i] - r[i - 1]).abs() <= 0.5 * bar_v
            && (r[i] - 2.0 * r[i - 1] + r[i - 2]).abs() <= 0.5 * bar_v
        {
            i += 1;
            continue;
        }
        let found = (1..=GLITCH_RUN_MAX)
            .take_while(|&len| i + len + 3 <= n && !near_edge[i..i + len].iter().any(|&e| e))
            .find_map(|len| run(i, len));
        match found {
            Some(want) => {
                let len = want.len();
                out.extend(
                    (i..i + len)
                        .zip(&want)
                        .map(|(j, w)| (j, w + model_y.map_or(0.0, |s| s[j]))),
                );
                i += len;
            }
            None => i += 1,
        }
    }
    out
}

/// The record with its [`glitches`] replaced by what their neighbours give, the glitches, and
/// words for the table when there were any.
pub fn without_glitches(
    d: &Data,
    floor_v: f64,
    model_y: Option<&[f64]>,
) -> (Data, Vec<(usize, f64)>, Option<String>) {
    let found = glitches(d, floor_v, model_y);
    if found.is_empty() {
        return (d.clone(), found, None);
    }
    let c = d.with_samples_replaced(&found);
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for &(i, med) in &found {
        let off = (d.y_v[i] - med).abs();
        lo = lo.min(off);
        hi = hi.max(off);
    }
    // (a glitch is a run of neighbouring samples: its first sample's time names it)
    let mut runs: Vec<(usize, usize)> = Vec::new();
    for &(i, _) in &found {
        match runs.last_mut() {
            Some((start, len)) if *start + *len == i => *len += 1,
            _ => runs.push((i, 1)),
        }
    }
    let longest = runs.iter().map(|r| r.1).max().unwrap_or(1);
    let at: Vec<String> = runs
        .iter()
        .take(5)
        .map(|&(i, _)| format!("{:.4}", d.t_s[i]))
        .collect();
    let what = match (runs.len(), longest) {
        (1, 1) => "1 single sample".to_string(),
        (1, l) => format!("1 run of {l} samples"),
        (k, 1) => format!("{k} single samples"),
        (k, l) => format!("{k} runs of 1-{l} samples"),
    };
    let size = if found.len() == 1 {
        format!("{:.1} mV off its neighbours, which stay", 1e3 * hi)
    } else {
        format!(
            "{:.1}-{:.1} mV off their neighbours, which each time stay",
            1e3 * lo,
            1e3 * hi
        )
    };
    let note = format!(
        "{}: {what} {size} within {GLITCH_SPREAD_FLOORS} noise floors, in the residual from \
         the base model (t = {}{} s): a glitch of the recording, as no stage moves so in a \
         few samples and back; replaced by what the neighbours give",
        d.name,
        at.join(", "),
        if runs.len() > 5 { ", ..." } else { "" }
    );
    (c, found, Some(note))
}

/// [`noise_floor`] with strides of at most `max_stride` samples (1: the stride-1 estimate),
/// and the stride it was read at.
#[allow(clippy::needless_range_loop)] // several arrays indexed together
fn floor_within(d: &Data, model_y: Option<&[f64]>, max_stride: usize) -> (f64, usize) {
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
    // k-th differences of a series at a stride of m samples: white noise of variance s^2
    // gives variance C(2k, k) s^2; a smooth signal (a sine, a ramp, a drift) adds (w m dt)^k
    // of itself, so the smallest of the k = 2, 3, 4 estimates is the one least inflated by the
    // signal (a 20 Hz sine sampled at 1 kHz inflates the second differences' estimate, not the
    // fourth's).
    let diff = |x: &[f64], k: usize, m: usize, quiet: bool| -> Vec<f64> {
        (k * m..n)
            .filter(|&i| {
                // (at a stride the window spans k m samples: no input change inside it either;
                // at stride 1 an edge inside is one large difference the median passes over)
                !quiet || (since[i - k * m] >= settle && (m == 1 || since[i] >= k * m))
            })
            .map(|i| {
                let mut c = 1.0f64;
                let mut acc = 0.0;
                for j in 0..=k {
                    acc += c * x[i - j * m];
                    c = -c * (k - j) as f64 / (j + 1) as f64;
                }
                acc.abs()
            })
            .collect()
    };
    let quiet = diff(&d.y_v, 2, 1, true).len() >= 100;
    let estimate = |x: &[f64], m: usize| -> f64 {
        [(2usize, 6.0f64), (3, 20.0), (4, 70.0)]
            .iter()
            .map(|&(k, var)| {
                let mut v = diff(x, k, m, quiet);
                if v.is_empty() || (m > 1 && v.len() < NOISE_WALK_MIN_DIFFS) {
                    f64::INFINITY
                } else {
                    1.4826 * median(&mut v) / var.sqrt()
                }
            })
            .fold(f64::INFINITY, f64::min)
    };
    // The signal's part at a stride: the same estimate on the model's noise-free output,
    // which holds what the model knows moves fast (the 14-bit DAC's steps through the
    // stage's dynamics: 0.6 to 1.9 mV at strides of 2 to 32 samples at 48 kHz under families
    // case 1014's chirp, whose input alone moves 0.1 mV at 128).
    strided_floor(
        |m| estimate(&d.y_v, m),
        |m| model_y.map_or(0.0, |s| estimate(s, m)),
        max_stride,
    )
}

/// The noise floor from estimates at strides of 1, 2, 4, ... samples (`estimate(m)`, each the
/// white-noise standard deviation its differences give): white noise gives the same at every
/// stride, and the stride-1 estimate is kept. Noise coloured by a filter is correlated over a
/// few of the filter's time constants: its close differences cancel part of it, and the
/// estimate grows with the stride until the samples decorrelate, where it is the noise's whole
/// standard deviation (the thesis' E-509 sensor has a 10 kHz bandwidth: a first-order 10 kHz
/// filter on noise sampled at 50 kHz gives 0.78 of the standard deviation at stride 1, and
/// 1.00 from stride 4). The walk doubles the stride while the estimate grows by more than
/// [`NOISE_STRIDE_GROWTH`] and keeps the estimate where it stops growing, if it stays there
/// one doubling further.
///
/// A signal grows with the stride too, and an oscillating one stops growing where the stride
/// reaches its half period (a chirp to 141 Hz sampled at 48 kHz: families case 1014 read
/// 1.83 mV of its 1.07 mV noise so): `signal(m)` is the signal's own estimate at a stride, and
/// the walk gives up (the stride-1 estimate is kept) at a stride where it is more than
/// [`NOISE_SIGNAL_SHARE`] of the estimate, or where the estimate still grows at `max_stride`
/// samples (a noise correlated for longer, or slow noise without a plateau, is left to the
/// workflow's effects and its unexplained part). Returns the floor and the stride it was read
/// at.
pub fn strided_floor(
    estimate: impl Fn(usize) -> f64,
    signal: impl Fn(usize) -> f64,
    max_stride: usize,
) -> (f64, usize) {
    let first = estimate(1);
    let mut m = 1;
    let mut last = first;
    while m <= max_stride / 2 {
        let next = estimate(2 * m);
        if !next.is_finite() {
            break;
        }
        if next <= NOISE_STRIDE_GROWTH * last {
            if m == 1 {
                return (first, 1);
            }
            // A plateau is the noise's where it holds one doubling further, and the signal
            // there is within its share: a mode the model lacks, ringing at a fixed frequency,
            // stops growing at its half period too, but its estimate swings with the stride.
            if m > max_stride / 4 {
                break;
            }
            let further = estimate(4 * m);
            let flat = further.is_finite()
                && further <= NOISE_STRIDE_GROWTH * next
                && next <= NOISE_STRIDE_GROWTH * further;
            return if flat && signal(4 * m) <= NOISE_SIGNAL_SHARE * further {
                (next, 2 * m)
            } else {
                (first, 1)
            };
        }
        if signal(2 * m) > NOISE_SIGNAL_SHARE * next {
            break;
        }
        m *= 2;
        last = next;
    }
    (first, 1)
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
    Ok(sim_while(model, d, |_, _| true)?.unwrap_or_default())
}

/// [`sim`], stopped (`None`, nothing kept) as soon as `go_on(i, y_i)` says no; a kept
/// simulation is answered whole without asking.
fn sim_while(
    model: &ModelFile,
    d: &Data,
    go_on: impl FnMut(usize, f64) -> bool,
) -> anyhow::Result<Option<Vec<f64>>> {
    let mut m = model.clone();
    m.converters.noise_v = 0.0;
    // Without noise the seed changes nothing: one key for every seed.
    m.converters.seed = 0;
    let key = memo_key(&mut m);
    let input = input_fingerprint(d);
    if let Some(y) = key.as_deref().and_then(|k| d.memo.get(k, input)) {
        return Ok(Some(y.as_ref().clone()));
    }
    let stage = m.build_stage()?;
    let history = m.start_history_v();
    let y = match &d.fine {
        // An averaged record: the stage on the input at its own rate, its output averaged
        // over each block as the record's was (the early stop asked per block mean).
        Some(f) => {
            let mut go_on = go_on;
            let (n, factor) = (d.len(), f.factor);
            let mut y = Vec::with_capacity(n);
            let (mut sum, mut in_block) = (0.0, 0usize);
            let done =
                simulate_after_while(&stage, m.period_s, &history, &f.t_s, &f.u_v, |_, v| {
                    sum += v;
                    in_block += 1;
                    if in_block == factor && y.len() < n {
                        let mean = sum / factor as f64;
                        (sum, in_block) = (0.0, 0);
                        if !go_on(y.len(), mean) {
                            return false;
                        }
                        y.push(mean);
                    }
                    true
                });
            done.map(|_| y)
        }
        None => simulate_after_while(&stage, m.period_s, &history, &d.t_s, &d.u_v, go_on),
    };
    let Some(y) = y else {
        return Ok(None);
    };
    if let Some(k) = key {
        d.memo.put(k, input, Arc::new(y.clone()));
    }
    Ok(Some(y))
}

/// A record's Gaussian log-likelihood term for the searches' costs and the BIC scores:
/// `n ln MSE` over its `n` samples, the mean square held to at least
/// [`super::constants::MSE_MIN_V2`].
pub fn log_mse_term(n: f64, mse: f64) -> f64 {
    n * mse.max(super::constants::MSE_MIN_V2).ln()
}

/// Samples between two checks of [`cost_term_below`]'s bound (our assumption: a logarithm
/// per this many samples is nothing beside the stage's steps).
const COST_CHECK_SAMPLES: usize = 512;

/// Record `d`'s term ([`log_mse_term`]) in a fast search's cost for `model` ([`sim`],
/// [`mse`]; `n` the record's length), or `f64::INFINITY` as soon as the samples simulated show
/// that `before + term` exceeds `bound` (that simulation is neither finished nor kept). The
/// running sum of squares is a prefix of [`mse`]'s own sum, in its order and from its first
/// sample, so it never exceeds the whole: a term is cut short only where it would have
/// exceeded the bound, and a term computed in full is [`mse`]'s to the bit. (This takes the
/// logarithm as monotone; a libm whose last bit is not could err only where the cost ties the
/// bound to that bit.)
pub fn cost_term_below(
    model: &ModelFile,
    d: &Data,
    before: f64,
    bound: f64,
) -> anyhow::Result<f64> {
    let n = d.len() as f64;
    // (`mse`'s divisor: the shorter of the record and the simulation)
    let n_mse = d.y_v.len().min(d.t_s.len().min(d.u_v.len())).max(1) as f64;
    let mut sum = 0.0;
    // (A simulation whose misfit is not finite, a diverging candidate's, costs infinity, cut
    // or whole: `f64::max` would take a NaN mean square for the best fit there is.)
    let go_on = |i: usize, y: f64| {
        if let Some(&m) = d.y_v.get(i) {
            sum += (m - y) * (m - y);
        }
        !((i + 1).is_multiple_of(COST_CHECK_SAMPLES)
            && (!sum.is_finite() || before + log_mse_term(n, sum / n_mse) > bound))
    };
    Ok(match sim_while(model, d, go_on)? {
        Some(y) => {
            let e = mse(&d.y_v, &y);
            if e.is_finite() {
                log_mse_term(n, e)
            } else {
                f64::INFINITY
            }
        }
        None => f64::INFINITY,
    })
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

/// Read the records named on the command line: CSV or MATLAB v5 `.mat`, their time, input
/// and output columns or variables named by `vars` (`t=NAME,u=NAME,y=NAME`, default `t`, `u`,
/// `y`).
pub fn load_data(paths: &[std::path::PathBuf], vars: Option<&str>) -> anyhow::Result<Vec<Data>> {
    if paths.is_empty() {
        bail!("no records: give at least one --data FILE");
    }
    let names = crate::io::mat::parse_vars(vars.unwrap_or("t=t,u=u,y=y"))?;
    let names = [names[0].as_str(), names[1].as_str(), names[2].as_str()];
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
            let rec = Record::read_named(p, names).with_context(|| {
                format!(
                    "record {} (its time, input and output columns are named by --vars \
                     t=NAME,u=NAME,y=NAME; now t={},u={},y={})",
                    p.display(),
                    names[0],
                    names[1],
                    names[2]
                )
            })?;
            ensure!(
                rec.y_v.is_some(),
                "record {}: no `{}` column, the output y (name it with --vars \
                 t=NAME,u=NAME,y=NAME)",
                p.display(),
                names[2]
            );
            rec
        };
        if let Some(note) = rec.time_note(&name) {
            eprintln!("{note}");
        }
        out.push(Data::from_record(&name, rec)?);
    }
    Ok(out)
}

/// The record averaged in blocks of `factor` samples, stamped at each block's last sample:
/// the output's mean over the block that ends at the stamp, the input's middle sample over
/// the block that starts there (the last stamp's over what is left), and the input at its
/// own rate kept ([`Data::fine`]).
///
/// [`sim`] runs the stage on the kept input and averages its output over the same blocks, so
/// a model reads the averaged record exactly as it reads the record (its edges and ringing
/// included, through their block means), at the cost of simulating at the record's rate.
/// The averaged record's input is what the workflow's own reading sees (holds, jumps,
/// reversals, the slow effects' columns). Its block is where [`sim`]'s convention puts it (a
/// sample's output is the stage's after the previous sample's input was held since it, so
/// the next block is what drives the stage until the next stamp), and its value is a sample
/// of the block, the middle one in order: a step inside a block stays a step (to the nearer
/// stamp), where the block's mean would split it into two changes that neither read as a
/// jump (measured on 45 s of `thesis-full` at 50 kHz, random levels, averaged by 3 and
/// diagnosed from `thesis-linear`: with the mean 16.3 mV was left, with the middle sample
/// 6.15 mV, against 6.88 mV on the same protocol sampled at the averaged rate), a held input
/// keeps its level exactly, and a smooth one reads its value at the block's middle. White
/// noise on the output is divided by `sqrt(factor)`. `factor` is held to 1 ..= the record's length over [`MIN_SAMPLES`], so
/// the averaged record is one the workflow takes.
pub fn decimated(d: &Data, factor: usize) -> Data {
    let factor = factor.clamp(1, (d.len() / MIN_SAMPLES).max(1));
    // (summed in order, as `sim` sums an averaged record's blocks)
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let n = d.len();
    let blocks = n / factor;
    let mut t_s = Vec::with_capacity(blocks);
    let mut u_v = Vec::with_capacity(blocks);
    let mut y_v = Vec::with_capacity(blocks);
    for b in 0..blocks {
        let stamp = (b + 1) * factor - 1;
        t_s.push(d.t_s[stamp]);
        y_v.push(mean(&d.y_v[stamp + 1 - factor..=stamp]));
        u_v.push(median_sample(&d.u_v[stamp..(stamp + factor).min(n)]));
    }
    let hold_band_v = hold_band_v(&u_v);
    Data {
        name: d.name.clone(),
        t_s,
        u_v,
        y_v,
        hold_band_v,
        memo: SimMemo::default(),
        fine: Some(Arc::new(FineInput::new(
            d.t_s[..blocks * factor].to_vec(),
            d.u_v[..blocks * factor].to_vec(),
            factor,
        ))),
    }
}

/// The middle sample of `v` in order (the upper one of an even count): a value `v` holds, so
/// that a block across an input's step reads one of its two levels, not a level between.
fn median_sample(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

/// Records that hold more than `bound` samples in all, averaged ([`decimated`]) until they
/// hold at most `target`, with one note per record averaged (for the diagnosis'
/// `noise_notes`); records within the bound are returned as they are, with no note.
///
/// The longest record (in samples, as averaged so far) is averaged one factor further at a
/// time, so that a short fast record beside a long slow one keeps its rate; no record is
/// averaged below [`GAP_MIN_RATE_HZ`] or [`MIN_SAMPLES`]. Where that cannot reach `target`
/// (a long record already near 1 kHz), the records are averaged only until they hold `bound`,
/// and where even that cannot be reached as far as it allows: the caller's bound then
/// refuses them, saying to cut them shorter.
pub fn decimate_to_fit(data: Vec<Data>, bound: usize, target: usize) -> (Vec<Data>, Vec<String>) {
    let total: usize = data.iter().map(Data::len).sum();
    if total <= bound {
        return (data, Vec::new());
    }
    let can_take = |i: usize, f: usize| {
        data[i].len() / f >= MIN_SAMPLES
            && 1.0 / (data[i].period_s() * f as f64) >= (1.0 - GAP_RATE_TOLERANCE) * GAP_MIN_RATE_HZ
    };
    // The fewest samples the records can be averaged to; where that is above `target`, the
    // records are averaged only as far as `bound` asks (a record already at 1 kHz leaves the
    // others no reason to go there too).
    let fewest: usize = (0..data.len())
        .map(|i| {
            let f_max = (1..=data[i].len()).take_while(|&f| can_take(i, f)).last();
            data[i].len() / f_max.unwrap_or(1)
        })
        .sum();
    let goal = if fewest <= target { target } else { bound };
    let mut factors = vec![1usize; data.len()];
    let samples = |i: usize, f: &[usize]| data[i].len() / f[i];
    loop {
        let now: usize = (0..data.len()).map(|i| samples(i, &factors)).sum();
        if now <= goal {
            break;
        }
        // The longest record that can still be averaged one factor further.
        let next = (0..data.len())
            .filter(|&i| can_take(i, factors[i] + 1))
            .max_by_key(|&i| samples(i, &factors));
        let Some(i) = next else { break };
        factors[i] += 1;
    }
    let mut notes = Vec::new();
    let out = data
        .iter()
        .zip(&factors)
        .map(|(d, &f)| {
            if f == 1 {
                return d.clone();
            }
            let a = decimated(d, f);
            let rate = 1.0 / d.period_s();
            let new_rate = 1.0 / a.period_s();
            notes.push(format!(
                "{}: {} samples at {rate:.0} Hz averaged in blocks of {f} to {} at {new_rate:.0} Hz \
                 (the records held {total} samples, more than the {bound} the workflow fits at \
                 once); the model is simulated on the input at its own rate and averaged alike, \
                 so every effect reads as in the record, but what moves within a block (ringing \
                 above {:.0} Hz, a delay under {:.2} ms) shows only through the block's mean",
                d.name,
                d.len(),
                a.len(),
                new_rate / 2.0,
                1e3 * f as f64 / rate
            ));
            a
        })
        .collect();
    (out, notes)
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

    /// A record of `seconds` at `rate_hz` whose output is `u(t)` plus Gaussian noise of
    /// 1 mV standard deviation through `order` first-order low-passes at `corner_hz` (none
    /// when `order` is 0): the record and the noise's own standard deviation.
    fn noisy_record(
        rate_hz: f64,
        seconds: f64,
        corner_hz: f64,
        order: usize,
        u: impl Fn(f64) -> f64,
    ) -> (Data, f64) {
        let n = (rate_hz * seconds) as usize;
        let w = crate::testing::filtered_noise(n, rate_hz, corner_hz, order, 11);
        let t: Vec<f64> = (0..n).map(|i| i as f64 / rate_hz).collect();
        let uv: Vec<f64> = t.iter().map(|&x| u(x)).collect();
        let y: Vec<f64> = uv.iter().zip(&w).map(|(a, b)| a + 1e-3 * b).collect();
        let d = Data::from_record("noisy", Record::new(t, uv, Some(y), None).unwrap()).unwrap();
        (d, 1e-3)
    }

    /// [`noisy_record`]'s input through the stage `truth` (its noise kept): the record, the
    /// noise's standard deviation, and the output of the stage `model` without noise (the
    /// base model's simulation the glitches are read against).
    fn through(
        truth: &ModelFile,
        model: &ModelFile,
        rate_hz: f64,
        seconds: f64,
        u: impl Fn(f64) -> f64,
    ) -> (Data, f64, Vec<f64>) {
        let (mut d, sd) = noisy_record(rate_hz, seconds, 0.0, 0, u);
        let noise: Vec<f64> = d.y_v.iter().zip(&d.u_v).map(|(y, u)| y - u).collect();
        let y = sim(truth, &d).unwrap();
        d.y_v = y.iter().zip(&noise).map(|(a, b)| a + b).collect();
        let base = sim(model, &d).unwrap();
        (d, sd, base)
    }

    /// The floor is the noise's standard deviation whether the noise is white or coloured by
    /// a sensor's bandwidth (first and second order, 300 Hz to 10 kHz, at 5 and 50 kHz),
    /// under a 1 Hz sine over most of the range. The stride-1 estimate alone gives 0.78, 0.38,
    /// 0.46 and 0.13 of it on the four filtered cases; 5 % is the estimate's spread over a few
    /// thousand decorrelated differences and the plateau's last growth.
    #[test]
    fn the_noise_floor_sees_coloured_noise_whole() {
        let sine = |t: f64| 5.0 - 4.5 * (2.0 * std::f64::consts::PI * t).cos();
        for (rate_hz, corner_hz, order) in [
            (50e3, 0.0, 0),
            (5e3, 0.0, 0),
            (50e3, 10e3, 1),
            (50e3, 2e3, 1),
            (5e3, 300.0, 1),
            (50e3, 3e3, 2),
        ] {
            let (d, sd) = noisy_record(rate_hz, 2.0, corner_hz, order, sine);
            let nf = noise_floor_of(&d, Some(&d.u_v));
            let floor = nf.sigma_v;
            // (the white records say nothing of colour; the filtered ones say where)
            assert_eq!(
                nf.decorrelated_s.is_some(),
                order > 0,
                "{rate_hz} Hz, {corner_hz} Hz"
            );
            assert!(
                (floor / sd - 1.0).abs() < 0.05,
                "{rate_hz} Hz, {order} x {corner_hz} Hz: floor {:.3} mV against {:.3} mV",
                1e3 * floor,
                1e3 * sd
            );
        }
    }

    /// A signal that the strided differences see more of as the stride grows, until its half
    /// period (a chirp to 150 Hz sampled at 48 kHz over white noise, as families case 1014) is
    /// not taken for coloured noise: the floor stays the stride-1 estimate. And the walk
    /// itself: a plateau's value is kept; an estimate that grows to the longest stride, or a
    /// plateau where the signal is more than its share, gives the first back.
    #[test]
    fn a_signal_is_not_taken_for_coloured_noise() {
        // (sine phase: the input moves from its first sample, so no quiet stretch)
        let chirp =
            |t: f64| 5.0 + 4.0 * (2.0 * std::f64::consts::PI * (0.5 * t + 25.0 * t * t)).sin();
        let (d, _) = noisy_record(48e3, 3.0, 0.0, 0, chirp);
        assert_eq!(noise_floor(&d, Some(&d.u_v)), floor_within(&d, None, 1).0);
        let quiet = |_: usize| 0.0;
        let growing = |m: usize| 1e-3 * (m as f64).powi(2);
        assert_eq!(strided_floor(growing, quiet, 64), (1e-3, 1));
        let plateau = |m: usize| 1e-3 * (1.0 - 0.8 / m as f64);
        let (p, _) = strided_floor(plateau, quiet, 64);
        assert!((p / 1e-3 - 1.0).abs() < 0.1 && p > plateau(1) * 1.5, "{p}");
        // (the same plateau, reached where the signal is a third of the estimate: not noise's)
        let moving = |m: usize| 1e-3 * m as f64 / 24.0;
        assert_eq!(strided_floor(plateau, moving, 64), (plateau(1), 1));
        let white = |m: usize| 1e-3 * (1.0 + 0.01 * (m as f64).ln());
        assert_eq!(strided_floor(white, quiet, 64), (1e-3, 1));
    }

    /// A slow ramp rounded to 2 mV steps (a 12-bit scope over 8 V) with 0.05 mV of noise: a
    /// code lasts five samples, the differences' median is zero, and the floor is the
    /// rounding's `2 mV / sqrt(12)` = 0.577 mV, said so. A 1 Hz sine rounded so with 0.2 mV of
    /// noise changes code often enough for the differences to see the rounding as noise:
    /// between the rounding's share and the two together. Unrounded, a record's floor is its
    /// noise. Four held levels and nothing else hide their step: the span's 16-bit share
    /// stands in for it.
    #[test]
    fn a_rounded_record_has_its_resolution_as_floor() {
        let round = |d: &Data, noise_share: f64| {
            let mut r = d.clone();
            for (y, u) in r.y_v.iter_mut().zip(&d.u_v) {
                let w = *y - u;
                *y = ((u + noise_share * w) / 2e-3).round() * 2e-3;
            }
            r
        };
        let rounding_v = 2e-3 / 12f64.sqrt();
        let ramp = |t: f64| 1.0 + 0.36 * t;
        let (d, _) = noisy_record(5e3, 20.0, 0.0, 0, ramp);
        let nf = noise_floor_of(&round(&d, 0.05), None);
        assert!(
            nf.by_resolution && nf.step_seen && (nf.step_v - 2e-3).abs() < 1e-9,
            "{nf:?}"
        );
        assert!((nf.sigma_v - rounding_v).abs() < 1e-9, "{nf:?}");
        assert!(
            nf.note("r")
                .is_some_and(|n| n.contains("steps of 2.000 mV"))
        );
        let sine = |t: f64| 5.0 - 4.5 * (2.0 * std::f64::consts::PI * t).cos();
        let (d, _) = noisy_record(5e3, 2.0, 0.0, 0, sine);
        let nf = noise_floor_of(&round(&d, 0.2), None);
        let both_v = (rounding_v.powi(2) + 0.2e-3f64.powi(2)).sqrt();
        assert!(
            nf.sigma_v >= rounding_v && nf.sigma_v <= 1.15 * both_v,
            "{nf:?}"
        );
        let white = noise_floor_of(&d, None);
        let (lo, hi) = min_max(&d.y_v);
        assert!(
            !white.by_resolution && white.step_v <= (hi - lo) / 65536.0 * (1.0 + 1e-9),
            "{white:?}"
        );
        assert!((white.sigma_v / 1e-3 - 1.0).abs() < 0.05, "{white:?}");
        assert!(white.note("w").is_none());
        let levels = |t: f64| [2.0, 6.3, 4.1, 8.7][((t * 2.0) as usize).min(3)];
        let (mut held, _) = noisy_record(5e3, 2.0, 0.0, 0, levels);
        held.y_v.clone_from(&held.u_v);
        let nf = noise_floor_of(&held, None);
        assert!(
            nf.by_resolution && !nf.step_seen && (nf.step_v - 6.7 / 65536.0).abs() < 1e-12,
            "{nf:?}"
        );
        assert!(
            nf.note("h")
                .is_some_and(|n| n.contains("no converter step"))
        );
    }

    /// Three single-sample glitches (0.3 to 1.2 V) in a 1 Hz sine with 1 mV of noise are found
    /// where they are and replaced by their neighbours' median; none is found in the full
    /// thesis stage's own output (its resonance, slew limit and hysteresis) under random steps
    /// every 5 ms at 50 kHz and under a fast sine near its resonance, with the same noise (in
    /// the residual from that output), nor in a mode ringing at a third of the sampling rate;
    /// nor for a one-sample input pulse at 1 kHz, which the stage follows within about a
    /// sample, nor at the edges of steps sampled at 1 kHz through a delay the model lacks.
    #[test]
    fn single_sample_glitches_are_found_and_nothing_else() {
        let sine = |t: f64| 5.0 - 4.5 * (2.0 * std::f64::consts::PI * t).cos();
        let (mut d, sd) = noisy_record(50e3, 1.0, 0.0, 0, sine);
        let spikes = [(10_000usize, 0.3), (25_000, -0.8), (40_000, 1.2)];
        let clean = d.y_v.clone();
        for &(i, v) in &spikes {
            d.y_v[i] += v;
        }
        let found: Vec<usize> = glitches(&d, sd, None).iter().map(|g| g.0).collect();
        assert_eq!(found, [10_000, 25_000, 40_000]);
        let (c, _, note) = without_glitches(&d, sd, None);
        assert!(note.is_some_and(|n| n.contains("3 single samples")));
        for &(i, _) in &spikes {
            assert!((c.y_v[i] - clean[i]).abs() < 5.0 * sd);
        }
        let stage = ModelFile::built_in("thesis-full").unwrap();
        let steps = |t: f64| 5.0 + 4.0 * ((t * 200.0).floor() * 2.3999).sin();
        let fast = |t: f64| 5.0 + 0.5 * (2.0 * std::f64::consts::PI * 3000.0 * t).sin();
        // (a mode ringing at a third of the sampling rate, 8 mV, on a slow ramp)
        let (mut d, sd) = noisy_record(18e3, 0.5, 0.0, 0, |t| 5.0 + t);
        for (i, y) in d.y_v.iter_mut().enumerate() {
            *y += 8e-3 * (2.0 * std::f64::consts::PI * i as f64 / 3.0).cos();
        }
        assert!(glitches(&d, sd, None).is_empty(), "a third");
        for (name, u) in [("steps", &steps as &dyn Fn(f64) -> f64), ("fast", &fast)] {
            let (d, sd, y) = through(&stage, &stage, 50e3, 0.5, u);
            assert!(glitches(&d, sd, Some(&y)).is_empty(), "{name}");
        }
        // A one-sample input pulse at 1 kHz, which the stage follows within about a sample:
        // none in the residual from the model's output.
        let pulse = |t: f64| {
            if (t - 0.25).abs() < 0.5e-3 {
                6.0
            } else {
                5.0 + t
            }
        };
        let (d, sd, y) = through(&stage, &stage, 1e3, 0.5, pulse);
        assert!(
            glitches(&d, sd, Some(&y)).is_empty(),
            "the pulse's residual"
        );
        // Steps sampled at 1 kHz through a 200 us delay the model lacks: one-sample spikes of
        // the residual at the edges, which are the stage's, not glitches.
        let mut delayed = ModelFile::built_in("thesis-linear").unwrap();
        delayed.time_delay = Some(crate::io::model_file::DelaySection { delay_s: 2e-4 });
        let slow_steps = |t: f64| 5.0 + 4.0 * ((t * 10.0).floor() * 2.3999).sin();
        let linear = ModelFile::built_in("thesis-linear").unwrap();
        let (d, sd, base) = through(&delayed, &linear, 1e3, 2.0, slow_steps);
        assert!(
            glitches(&d, sd, Some(&base)).is_empty(),
            "the delay's edges"
        );
    }

    /// Glitches of two and three samples (a logger's burst) are found as runs, each of their
    /// samples replaced, and said as runs; a doublet (one sample each way) is not; a mode the
    /// model lacks, ringing at a fifth of the
    /// sampling rate after each of a few kicks, is not a run of glitches (its half periods
    /// are two or three samples long between quieter turns: families cases 1049 and 1096 were
    /// so with three neighbours a side; the stage here is 1049's mode under steps).
    #[test]
    fn runs_of_a_few_samples_are_glitches_and_a_ring_is_not() {
        let sine = |t: f64| 5.0 - 4.5 * (2.0 * std::f64::consts::PI * t).cos();
        let (mut d, sd) = noisy_record(50e3, 1.0, 0.0, 0, sine);
        let clean = d.y_v.clone();
        let runs: [(usize, &[f64]); 3] = [
            (10_000, &[0.5, 0.4]),
            (25_000, &[-0.8, -0.7, -0.6]),
            (40_000, &[1.2]),
        ];
        let mut want = Vec::new();
        for &(i, vs) in &runs {
            for (k, v) in vs.iter().enumerate() {
                d.y_v[i + k] += v;
                want.push(i + k);
            }
        }
        let found: Vec<usize> = glitches(&d, sd, None).iter().map(|g| g.0).collect();
        assert_eq!(found, want);
        let (c, _, note) = without_glitches(&d, sd, None);
        assert!(
            note.as_ref()
                .is_some_and(|n| n.contains("3 runs of 1-3 samples")
                    && n.contains("t = 0.2000, 0.5000, 0.8000 s")),
            "{note:?}"
        );
        for &i in &want {
            assert!((c.y_v[i] - clean[i]).abs() < 5.0 * sd);
        }
        // (a doublet, one sample each way: a delay the model lacks under a one-sample input
        // pulse leaves one, which is the stage's)
        let (mut d, sd) = noisy_record(50e3, 1.0, 0.0, 0, sine);
        d.y_v[20_000] += 0.5;
        d.y_v[20_001] -= 0.5;
        assert!(glitches(&d, sd, None).is_empty(), "the doublet");
        // (families case 1049's mode, 8.9 kHz, damping 0.05, under steps sampled at 50 kHz,
        // against a model without it)
        let mut truth = ModelFile::built_in("thesis-linear").unwrap();
        truth.resonance = Some(crate::io::model_file::ResonanceSection {
            mode_hz: 8946.0,
            damping: 0.051,
        });
        let steps = |t: f64| 5.0 + 4.0 * ((t * 5.0).floor() * 2.3999).sin();
        let linear = ModelFile::built_in("thesis-linear").unwrap();
        let (d, sd, base) = through(&truth, &linear, 50e3, 2.0, steps);
        assert!(glitches(&d, sd, Some(&base)).is_empty(), "the ring");
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

    /// A bounded cost term is the term itself, bit for bit, wherever the bound is not passed
    /// (any bound at or above `before` plus the term); below, it is the term or infinite, and
    /// infinite once a check (every [`COST_CHECK_SAMPLES`] samples) has seen the bound passed:
    /// here a uniform misfit, whose check at sample `k` sees `n ln(k / n)` less than the whole.
    #[test]
    fn a_bounded_cost_term_is_the_term_or_infinite_above_its_bound() {
        let mut d = sine_record();
        let n = d.len();
        let m = ModelFile::built_in("thesis-linear").unwrap();
        let y = sim(&m, &d).unwrap();
        d.y_v = y.iter().map(|v| v + 0.05).collect();
        d.memo = SimMemo::default();
        let exact = n as f64 * mse(&d.y_v, &sim(&m, &sine_record_like(&d)).unwrap()).ln();
        // What the first and the last checks see below the whole term.
        let seen_at = |k: usize| n as f64 * (k as f64 / n as f64).ln();
        let first_check = seen_at(COST_CHECK_SAMPLES);
        let last_check = seen_at(n / COST_CHECK_SAMPLES * COST_CHECK_SAMPLES);
        for before in [0.0, -123.4, 5e3] {
            let term = |bound: f64| cost_term_below(&m, &sine_record_like(&d), before, bound);
            let term = |bound: f64| term(bound).unwrap();
            assert_eq!(term(f64::INFINITY).to_bits(), exact.to_bits());
            assert_eq!(term(before + exact).to_bits(), exact.to_bits());
            assert_eq!(term(before + exact + 1.0).to_bits(), exact.to_bits());
            let just_below = term(before + exact - 1e-9 * exact.abs());
            assert!(just_below == f64::INFINITY || just_below.to_bits() == exact.to_bits());
            assert_eq!(term(before + exact + 1.2 * first_check), f64::INFINITY);
            assert_eq!(
                term(before + exact + 0.5 * last_check).to_bits(),
                exact.to_bits()
            );
        }
        // A simulation cut short is not kept: asked whole afterwards, it is simulated whole.
        let e = sine_record_like(&d);
        assert_eq!(
            cost_term_below(&m, &e, 0.0, f64::NEG_INFINITY).unwrap(),
            f64::INFINITY
        );
        assert_eq!(sim(&m, &e).unwrap().len(), n);
    }

    /// `d`'s record with an empty memo.
    fn sine_record_like(d: &Data) -> Data {
        let mut e = d.clone();
        e.memo = SimMemo::default();
        e
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

    /// A record at `rate_hz` of `seconds` whose output is the stage `model`'s (noise-free):
    /// a 2 Hz sine over 1-9 V with a 3 V step at a fifth of the record.
    fn stage_record(model: &ModelFile, rate_hz: f64, seconds: f64) -> Data {
        let n = (rate_hz * seconds) as usize;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / rate_hz).collect();
        let u: Vec<f64> = t
            .iter()
            .map(|&x| {
                let step = if x >= seconds / 5.0 { 3.0 } else { 0.0 };
                3.0 + 2.0 * (std::f64::consts::TAU * 2.0 * x).sin() + step
            })
            .collect();
        let zeros = vec![0.0; n];
        let d = Data::from_record("stage", Record::new(t, u, Some(zeros), None).unwrap()).unwrap();
        let y = sim(model, &d).unwrap();
        Data { y_v: y, ..d }
    }

    /// The averaged record is read as the stage reads it: its simulation runs on the input at
    /// its own rate and averages the output over each block, so it gives the averaged
    /// output, the step's blocks too (to rounding: the same simulation, summed alike). Held
    /// at the averaged rate instead (the staircase of block means, 0.16 ms a block), the
    /// thesis' linear stage (its 85 us delay, 2 kHz amplifier pole and 5.8 kHz mode) reads
    /// its 3 V step a block wrong by most of a volt, and the 25 V/s sine by a fraction of a
    /// millivolt: an edge a fast effect would be fitted to.
    #[test]
    fn averaged_records_read_as_the_stage_reads_them() {
        let linear = ModelFile::load("thesis-linear").unwrap();
        let d = stage_record(&linear, 50_000.0, 0.4);
        let a = decimated(&d, 8);
        assert_eq!(a.len(), d.len() / 8);
        assert!((1.0 / a.period_s() - 6250.0).abs() < 1e-6);
        assert_eq!(a.t_s[0], d.t_s[7]);
        let y = sim(&linear, &a).unwrap();
        let worst = y
            .iter()
            .zip(&a.y_v)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-9, "the averaged simulation is {worst} V off");
        // The step (at a sample of the fine record that is not a block's first) is one jump of
        // the averaged input, not two changes.
        let changes: Vec<usize> = (1..a.len())
            .filter(|&i| (a.u_v[i] - a.u_v[i - 1]).abs() > 0.1)
            .collect();
        assert_eq!(changes.len(), 1, "{changes:?}");
        assert!(a.is_jump(changes[0]));
        assert!((a.u_v[changes[0]] - a.u_v[changes[0] - 1] - 3.0).abs() < 0.05);
        let staircase = Data {
            fine: None,
            memo: SimMemo::default(),
            ..a.clone()
        };
        let y_held = sim(&linear, &staircase).unwrap();
        let step_at = a.t_s.iter().position(|&t| t >= 0.08).unwrap();
        let at_step = (step_at..step_at + 4)
            .map(|i| (y_held[i] - a.y_v[i]).abs())
            .fold(0.0, f64::max);
        assert!(
            at_step > 0.3,
            "held at the averaged rate: {at_step} V at the step"
        );
    }

    /// Records within the bound are left as they are; beyond it the longest is averaged until
    /// the target holds, a short fast record beside it keeps its rate, every averaged record
    /// has its note, and none goes below 1 kHz (then the caller's bound refuses them).
    #[test]
    fn only_records_beyond_the_bound_are_averaged() {
        let linear = ModelFile::load("thesis-linear").unwrap();
        let long = stage_record(&linear, 50_000.0, 0.4);
        let fast = stage_record(&linear, 50_000.0, 0.04);
        let (same, notes) = decimate_to_fit(vec![long.clone(), fast.clone()], 22_000, 10_000);
        assert!(notes.is_empty());
        assert_eq!(same[0].len(), 20_000);
        let (fit, notes) = decimate_to_fit(vec![long.clone(), fast.clone()], 15_000, 10_000);
        let total: usize = fit.iter().map(Data::len).sum();
        assert!(total <= 10_000, "{total}");
        assert_eq!(fit[1].len(), fast.len());
        assert_eq!(fit[1].u_v, fast.u_v);
        assert_eq!(notes.len(), 1);
        assert!(
            notes[0].starts_with("stage: 20000 samples at 50000 Hz averaged in blocks of 3"),
            "{}",
            notes[0]
        );
        // 20 000 samples at 50 kHz cannot go below 400 at 1 kHz: under a target of 100 they
        // are averaged only as far as a bound of 1 000 asks (by 20), and under a bound of 300
        // as far as they go, which the caller's bound then refuses.
        let (fit, _) = decimate_to_fit(vec![long.clone()], 1_000, 100);
        assert_eq!(fit[0].len(), 1_000);
        let (floor, notes) = decimate_to_fit(vec![long.clone()], 300, 150);
        assert_eq!(floor[0].len(), 400);
        assert!(1.0 / floor[0].period_s() >= 1000.0 * (1.0 - GAP_RATE_TOLERANCE));
        assert_eq!(notes.len(), 1);
        // A factor beyond what the record holds is held to one the workflow takes.
        assert_eq!(decimated(&fast, 10_000).len(), MIN_SAMPLES);
        // A record at 1 kHz cannot be averaged: where it alone keeps the records above the
        // target, the others go only as far as the bound asks (20 000 at 50 kHz by 2, not
        // down to 1 kHz).
        let slow = stage_record(&linear, 1_000.0, 16.0);
        let (fit, notes) = decimate_to_fit(vec![slow.clone(), long.clone()], 30_000, 15_000);
        assert_eq!(fit[0].len(), slow.len());
        assert_eq!(fit[1].len(), 10_000);
        assert_eq!(notes.len(), 1);
    }
}
