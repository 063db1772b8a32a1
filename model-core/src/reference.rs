//! Reference generators for the firmware, the QEMU runs and the host tools: step, ramp, sine,
//! triangle, square and linear sweep, each with *preview* (sec. 4.1.2.4, "trajectory
//! planning": a reference generated on board has a known future, and the pre-filter wants it
//! [`crate::prefilter::PreFilter::preview_samples`] ahead).
//!
//! # Phase without drift
//! Periodic shapes keep their phase as an integer accumulator, `u64` turns scaled by 2^64,
//! advanced each sample by an integer increment (32.32 fixed point: the frequency resolution
//! is `f_s / 2^64`, 2.7e-15 Hz at 50 kHz). Integer addition wraps exactly, so the phase after
//! hours is exactly `n * increment`: no rounding accumulates, however long the run. A sweep
//! changes the increment by a constant integer each sample (exact too) and starts again at
//! its first frequency after `duration`.
//!
//! # Sine to 0.1 LSB of the 14-bit DAC
//! `micromath`'s `sin` is off by up to 1.1e-3 (measured against `f64`: 8.9 LSB of the 14-bit
//! DAC at 10 V amplitude), far too coarse for a reference. [`sin_turns`] folds the phase
//! exactly in integers onto a quarter-wave `x in [-1, 1]` (`sin(2 pi phase) = sin(pi x / 2)`),
//! then evaluates the Taylor polynomial of `sin(pi x / 2)` to `x^13` in `f32` by Horner's
//! rule. Truncation error `(pi/2)^15 / 15! = 6e-10`; the rest is `f32` rounding. Measured
//! against `f64` over 2^22 phases (host-tests `tests/prefilter.rs`): worst error 2.2e-7,
//! 0.0018 LSB at 10 V amplitude (the requirement is 0.1 LSB). The triangle is the folded `x`
//! itself, exact. Over 200 s at 123.456 Hz the generated sine stays within 1.8e-7 of the
//! `f64` formula: no phase drift.
//!
//! # Preview
//! The state holds two cursors: "now" and "ahead" (started `preview` samples later). Both
//! advance by the same integer recursion, so the advanced value is exactly the value the
//! generator will produce `preview` samples later. [`ReferenceGenerator::next`] returns the
//! advanced value and advances; [`ReferenceGenerator::now`] returns the present value (the
//! one the loop's output should match). Per step: a few integer adds and one polynomial.
//!
//! # Example
//! ```
//! use model_core::reference::{ReferenceConfig, ReferenceGenerator, Shape};
//! let cfg = ReferenceConfig { shape: Shape::Sine, offset_v: 4.0, amplitude_v: 3.0,
//!                             freq_hz: 100.0, ..ReferenceConfig::default() };
//! let g = ReferenceGenerator::new(&cfg, 125).unwrap(); // preview of a quarter period
//! let mut s = g.start();
//! assert!((g.now(&s) - 4.0).abs() < 1e-6);
//! assert!((g.next(&mut s) - 7.0).abs() < 1e-5); // the peak, a quarter period ahead
//! ```

use crate::limits::{ConfigError, check_finite, check_period, check_range, check_within};
use crate::params;
use core::f64::consts::PI;
use core::ops::Bound::{Excluded, Included, Unbounded};

/// The shape of a reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// `offset` before `at_s`, `offset + amplitude` from then on.
    Step {
        /// Time of the step, seconds from the start.
        at_s: f64,
    },
    /// From `offset` towards `offset + amplitude` at `rate_v_per_s`, then held.
    Ramp {
        /// Slope, V/s (positive).
        rate_v_per_s: f64,
    },
    /// `offset + amplitude sin(2 pi f t)`.
    Sine,
    /// Triangle of the same phase as the sine: 0 at t = 0 rising, peak `amplitude` at a
    /// quarter period.
    Triangle,
    /// `offset +- amplitude`, positive during the first half period: periodic steps.
    Square,
    /// Sine whose frequency rises linearly from `freq_hz` to `end_hz` in `duration_s`, then
    /// starts again.
    Sweep {
        /// Frequency at the end, Hz.
        end_hz: f64,
        /// Length of one sweep, seconds.
        duration_s: f64,
    },
}

/// What to generate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceConfig {
    /// The shape.
    pub shape: Shape,
    /// Offset, volts.
    pub offset_v: f64,
    /// Amplitude (peak, or step height), volts.
    pub amplitude_v: f64,
    /// Frequency of periodic shapes (start frequency of a sweep), Hz.
    pub freq_hz: f64,
    /// Sample period, seconds.
    pub period_s: f64,
}

impl Default for ReferenceConfig {
    /// A constant 0 V at 50 kHz (a sine of zero amplitude).
    fn default() -> Self {
        Self {
            shape: Shape::Sine,
            offset_v: 0.0,
            amplitude_v: 0.0,
            freq_hz: 0.0,
            period_s: 1.0 / params::SAMPLE_RATE_HZ,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Step,
    Ramp,
    Sine,
    Triangle,
    Square,
    Sweep,
}

/// The generator: configuration half (`Copy`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceGenerator {
    kind: Kind,
    offset: f32,
    amplitude: f32,
    inc0: u64,
    chirp: i64,
    sweep_len: u64,
    step_at: u64,
    ramp_per_sample: f32,
    ramp_len: u64,
    preview: u32,
    repeat: u32,
}

/// One position of the generator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Cursor {
    n: u64,
    phase: u64,
    inc: u64,
    k: u64,
}

/// The generator's state: the present position and the one `preview` samples ahead.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReferenceState {
    now: Cursor,
    ahead: Cursor,
    index: u32,
}

/// Increment in 2^-64 turns per sample for `f_hz` at period `t`: `f t 2^64`, for
/// `0 <= f t < 1/2`.
fn increment(f_hz: f64, t: f64) -> u64 {
    // 2^64 as f64 is exact; f t < 1/2 keeps the product below 2^63.
    (f_hz * t * 18_446_744_073_709_551_616.0) as u64
}

impl ReferenceGenerator {
    /// A generator handing out the reference `preview` samples ahead. Refuses non-finite
    /// values, a bad period, frequencies outside `[0, Nyquist)`, a ramp rate or sweep length
    /// that is not positive, a step time that is negative, and a preview above
    /// `params::MAX_PREVIEW_SAMPLES`.
    ///
    /// ```
    /// use model_core::reference::{ReferenceConfig, ReferenceGenerator, Shape};
    /// let cfg = ReferenceConfig { shape: Shape::Ramp { rate_v_per_s: 1000.0 },
    ///                             amplitude_v: 2.0, ..ReferenceConfig::default() };
    /// assert!(ReferenceGenerator::new(&cfg, 0).is_ok());
    /// let fast = ReferenceConfig { freq_hz: 30e3, ..ReferenceConfig::default() };
    /// assert!(ReferenceGenerator::new(&fast, 0).is_err()); // above Nyquist
    /// ```
    pub fn new(c: &ReferenceConfig, preview: u32) -> Result<Self, ConfigError> {
        check_finite("offset_v", c.offset_v)?;
        check_finite("amplitude_v", c.amplitude_v)?;
        check_finite("freq_hz", c.freq_hz)?;
        let t = check_period(c.period_s)?;
        let nyquist = 0.5 / t;
        let check_freq = |name, f| check_range(name, f, Included(0.0), Excluded(nyquist));
        check_freq("freq_hz", c.freq_hz)?;
        check_within(
            "preview",
            preview as f64,
            0.0,
            params::MAX_PREVIEW_SAMPLES as f64,
        )?;
        let mut g = Self {
            kind: Kind::Sine,
            offset: c.offset_v as f32,
            amplitude: c.amplitude_v as f32,
            inc0: increment(c.freq_hz, t),
            chirp: 0,
            sweep_len: 0,
            step_at: 0,
            ramp_per_sample: 0.0,
            ramp_len: 0,
            preview,
            repeat: 0,
        };
        match c.shape {
            Shape::Sine => g.repeat = repeat(c.freq_hz, t),
            Shape::Triangle => {
                g.kind = Kind::Triangle;
                g.repeat = repeat(c.freq_hz, t);
            }
            Shape::Square => {
                g.kind = Kind::Square;
                g.repeat = repeat(c.freq_hz, t);
            }
            Shape::Step { at_s } => {
                check_range("at_s", at_s, Included(0.0), Excluded(1e18 * t))?;
                g.kind = Kind::Step;
                g.step_at = (at_s / t + 0.5) as u64;
            }
            Shape::Ramp { rate_v_per_s } => {
                check_finite("rate_v_per_s", rate_v_per_s)?;
                let per_sample = rate_v_per_s * t;
                if !(per_sample > 0.0 && c.amplitude_v.abs() / per_sample < 1e15) {
                    // At most 1e15 samples of ramp.
                    let min = c.amplitude_v.abs() / (1e15 * t);
                    return Err(ConfigError::out_of_range(
                        "rate_v_per_s",
                        Excluded(min),
                        Unbounded,
                    ));
                }
                g.kind = Kind::Ramp;
                g.ramp_per_sample = (per_sample * c.amplitude_v.signum()) as f32;
                g.ramp_len = (c.amplitude_v.abs() / per_sample) as u64;
            }
            Shape::Sweep { end_hz, duration_s } => {
                check_finite("end_hz", end_hz)?;
                check_finite("duration_s", duration_s)?;
                check_freq("end_hz", end_hz)?;
                let len = duration_s / t;
                if !(1.0..1e15).contains(&len) {
                    return Err(ConfigError::out_of_range(
                        "duration_s",
                        Included(t),
                        Excluded(1e15 * t),
                    ));
                }
                g.kind = Kind::Sweep;
                g.sweep_len = len as u64;
                let inc1 = increment(end_hz, t);
                g.chirp = ((inc1 as f64 - g.inc0 as f64) / g.sweep_len as f64) as i64;
            }
        }
        Ok(g)
    }

    /// The preview, samples.
    pub fn preview_samples(&self) -> u32 {
        self.preview
    }

    /// Samples after which the reference repeats exactly (a whole number of its periods), 0
    /// when it does not within [`params::MAX_LEARN_PERIOD_SAMPLES`] (a step, a ramp, a sweep,
    /// a frequency whose period is not a ratio of small whole numbers of samples).
    ///
    /// ```
    /// use model_core::reference::{ReferenceConfig, ReferenceGenerator, Shape};
    /// let c = |f| ReferenceConfig { shape: Shape::Sine, freq_hz: f, ..ReferenceConfig::default() };
    /// assert_eq!(ReferenceGenerator::new(&c(100.0), 0).unwrap().repeat_samples(), 500);
    /// assert_eq!(ReferenceGenerator::new(&c(300.0), 0).unwrap().repeat_samples(), 500); // 3 periods
    /// assert_eq!(ReferenceGenerator::new(&c(101.234567), 0).unwrap().repeat_samples(), 0);
    /// ```
    pub fn repeat_samples(&self) -> u32 {
        self.repeat
    }

    /// The present sample's index within the repeat, `0..repeat_samples()` (0 without a
    /// repeat): read it before [`Self::next`] to index a per-sample table.
    #[inline]
    pub fn index(&self, s: &ReferenceState) -> u32 {
        s.index
    }

    /// A state at the start (sample 0), its "ahead" cursor `preview` samples on.
    pub fn start(&self) -> ReferenceState {
        let now = Cursor {
            inc: self.inc0,
            ..Cursor::default()
        };
        let mut ahead = now;
        // Bounded: preview <= MAX_PREVIEW_SAMPLES (checked in `new`).
        for _ in 0..self.preview {
            self.advance(&mut ahead);
        }
        ReferenceState {
            now,
            ahead,
            index: 0,
        }
    }

    /// One sample on. Only the step and the ramp read the sample count `n`, so only they
    /// pay for its saturating 64-bit add (about 10 instructions per cursor on the M4/M7,
    /// two cursors per sample: issue 13's instruction budget).
    #[inline]
    fn advance(&self, c: &mut Cursor) {
        c.phase = c.phase.wrapping_add(c.inc);
        match self.kind {
            Kind::Sweep => {
                c.k += 1;
                if c.k >= self.sweep_len {
                    c.k = 0;
                    c.inc = self.inc0;
                } else {
                    c.inc = c.inc.wrapping_add_signed(self.chirp);
                }
            }
            Kind::Step | Kind::Ramp => c.n = c.n.saturating_add(1),
            Kind::Sine | Kind::Triangle | Kind::Square => {}
        }
    }

    #[inline]
    fn value(&self, c: &Cursor) -> f32 {
        let p = (c.phase >> 32) as u32;
        let unit = match self.kind {
            Kind::Sine | Kind::Sweep => sin_turns(p),
            Kind::Triangle => fold(p),
            Kind::Square => {
                if (p as i32) >= 0 {
                    1.0
                } else {
                    -1.0
                }
            }
            Kind::Step => {
                if c.n >= self.step_at {
                    1.0
                } else {
                    0.0
                }
            }
            Kind::Ramp => {
                return if c.n >= self.ramp_len {
                    self.offset + self.amplitude
                } else {
                    // n < ramp_len; through u32 (one instruction) rather than u64 -> f32
                    // (software); a ramp longer than 2^32 samples (24 h at 50 kHz) saturates.
                    let n = if c.n > u32::MAX as u64 {
                        u32::MAX
                    } else {
                        c.n as u32
                    };
                    self.offset + self.ramp_per_sample * n as f32
                };
            }
        };
        self.offset + self.amplitude * unit
    }

    /// The reference at the present sample, volts (what the output should be now).
    #[inline]
    pub fn now(&self, s: &ReferenceState) -> f32 {
        self.value(&s.now)
    }

    /// The reference `preview` samples ahead, volts; then advance one sample.
    #[inline]
    pub fn next(&self, s: &mut ReferenceState) -> f32 {
        let v = self.value(&s.ahead);
        self.advance(&mut s.now);
        self.advance(&mut s.ahead);
        s.index += 1;
        if s.index >= self.repeat {
            s.index = 0;
        }
        v
    }
}

/// Most periods [`repeat`] looks through for a whole number of samples (our assumption:
/// covers frequencies whose period is a ratio `p/q` samples with `q <= 64`).
const MAX_REPEAT_PERIODS: u32 = 64;

/// The smallest whole number of samples that holds a whole number of periods of `f_hz` at
/// period `t` (to 1e-9 of a sample per period), at most
/// [`params::MAX_LEARN_PERIOD_SAMPLES`]; 0 if none. Design time.
fn repeat(f_hz: f64, t: f64) -> u32 {
    if f_hz <= 0.0 {
        return 0;
    }
    let per_period = 1.0 / (f_hz * t);
    for m in 1..=MAX_REPEAT_PERIODS {
        let x = per_period * m as f64;
        if x > params::MAX_LEARN_PERIOD_SAMPLES as f64 + 0.5 {
            return 0;
        }
        let whole = (x + 0.5) as u32;
        if (x - whole as f64).abs() <= 1e-9 * m as f64 && whole >= 2 {
            return whole;
        }
    }
    0
}

/// Fold a phase (turns scaled by 2^32) onto `x in [-1, 1]` with `sin(2 pi phase) =
/// sin(pi x / 2)`: exact in integers. Also the unit triangle wave.
#[inline]
pub fn fold(phase: u32) -> f32 {
    const Q: i64 = 1 << 30;
    const H: i64 = 1 << 31;
    let p = phase as i32 as i64;
    let f = if p > Q {
        H - p
    } else if p < -Q {
        -H - p
    } else {
        p
    };
    // |f| <= 2^30 fits i32, whose conversion is one instruction; i64 -> f32 is a software
    // routine on thumbv7em.
    f as i32 as f32 * (1.0 / Q as f32)
}

/// Taylor coefficients of `sin(pi x / 2)`, odd powers 1..=13.
const SIN_COEF: [f32; 7] = {
    let h = PI / 2.0;
    let mut c = [0.0f32; 7];
    let mut term = h; // h^(2k+1) / (2k+1)!
    let mut k = 0;
    while k < 7 {
        c[k] = term as f32;
        let n = (2 * k + 2) as f64;
        term = -term * h * h / (n * (n + 1.0));
        k += 1;
    }
    c
};

/// `sin(2 pi phase / 2^32)` in `f32`, error a few 1e-8 (see the design note).
#[inline]
pub fn sin_turns(phase: u32) -> f32 {
    let x = fold(phase);
    let x2 = x * x;
    let mut acc = SIN_COEF[6];
    acc = acc * x2 + SIN_COEF[5];
    acc = acc * x2 + SIN_COEF[4];
    acc = acc * x2 + SIN_COEF[3];
    acc = acc * x2 + SIN_COEF[2];
    acc = acc * x2 + SIN_COEF[1];
    acc = acc * x2 + SIN_COEF[0];
    acc * x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sine_and_triangle_landmarks() {
        assert_eq!(sin_turns(0), 0.0);
        assert!((sin_turns(1 << 30) - 1.0).abs() < 1e-7);
        assert!((sin_turns(3 << 30) + 1.0).abs() < 1e-7);
        assert_eq!(fold(1 << 30), 1.0);
        assert_eq!(fold(3 << 30), -1.0);
        assert_eq!(fold(1 << 31), 0.0);
    }

    #[test]
    fn step_and_ramp() {
        let t = 20e-6;
        let step = ReferenceConfig {
            shape: Shape::Step { at_s: 10.0 * t },
            offset_v: 1.0,
            amplitude_v: 2.0,
            ..ReferenceConfig::default()
        };
        let g = ReferenceGenerator::new(&step, 3).unwrap();
        let mut s = g.start();
        let ahead: Vec<f32> = (0..20).map(|_| g.next(&mut s)).collect();
        assert_eq!(ahead[6], 1.0);
        assert_eq!(ahead[7], 3.0);
        let ramp = ReferenceConfig {
            shape: Shape::Ramp { rate_v_per_s: 1e4 },
            amplitude_v: -1.0,
            ..ReferenceConfig::default()
        };
        let g = ReferenceGenerator::new(&ramp, 0).unwrap();
        let mut s = g.start();
        let v: Vec<f32> = (0..10).map(|_| g.next(&mut s)).collect();
        assert!((v[1] + 0.2).abs() < 1e-6);
        assert_eq!(v[9], -1.0);
    }
}
