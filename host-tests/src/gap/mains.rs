//! Mains interference on a record: found, fitted and taken out before the workflow judges it.
//!
//! # Why
//! A laboratory record carries the mains' hum (a ground loop between the sensor's monitor and
//! the logger, a rectifier's ripple at twice the grid frequency): a few millivolts at 50 or
//! 60 Hz and their first harmonics. The noise floor, read from close differences of the
//! output, does not see a 50 Hz line (it is smooth at 1-50 kHz), so a clean thesis-stage sine
//! with 3 mV of hum ended at 3.3x its floor with an `unexplained` part, and every effect the
//! workflow judges against the floor is judged against the hum too. The stage makes no such
//! line unless its input drives it; the line is the measurement's, as a glitch is.
//!
//! # How
//! On the record's residual from the base model (before its glitches are looked for; again
//! with them replaced where both are found, `super::select`), in
//! segments of at most [`MAINS_SEGMENT_S`] (a grid's frequency wanders by a few hundredths of
//! a hertz over minutes; within a segment it is one frequency), block-averaged to about
//! [`MAINS_DECIMATED_HZ`], Hann-windowed and zero-padded four times:
//! 1. each mains line (50 and 60 Hz and harmonics up to [`MAINS_HARMONICS`]) is looked for
//!    within [`MAINS_GRID_SHARE`] of its nominal frequency, its peak refined between bins;
//! 2. it is taken as interference only where all of these hold:
//!    * it stands [`MAINS_LINE_RATIO`] times (in power) above the residual's spectrum around
//!      it (a misfit of the stage's dynamics under a broadband input is broadband);
//!    * it stands as far above the residual one and two of the input's own frequency `f0`
//!      away (where the segment holds five of its periods and `f0` is at most half the
//!      line's: an unmodelled loop under a 1 Hz sine has lines at every harmonic of 1 Hz,
//!      50 Hz among them, and its neighbours at 49 and 51 Hz are as strong; hum stands
//!      alone);
//!    * it is none of the input's first [`MAINS_INPUT_HARMONICS`] harmonics (a curvature the
//!      model lacks under a 25 Hz sine puts a line at 50 Hz with no neighbour);
//!    * the model's own output has no line there (the input does not drive it: a sine at
//!      50 Hz is the stage's to answer): where the model's output has more than
//!      [`MAINS_DRIVEN_SHARE`] of the line's power at its frequency, that power must not
//!      stand [`MAINS_LINE_RATIO`] times above the model output's own spectrum around it
//!      (steps through the stage have as much power at 50 Hz as a 2 mV hum, spread over
//!      every frequency, and a misfit of them is as broad);
//!    * it holds in both halves of the segment within [`MAINS_HALVES_RATIO`] in amplitude (a
//!      ringing transient is not a standing line);
//!    * it moves the record by at least [`MAINS_MIN_FLOORS`] noise floors (RMS);
//! 3. each line taken is fitted by weighted least squares (the Hann window's weights, so the
//!    residual's slow content does not leak into it) on the full-rate residual, and subtracted
//!    from the record's output.
//!
//! What it leaves: a hum the input drives (a sine at 50 Hz), hum on a record shorter than
//! [`MAINS_MIN_S`], hum beside an unmodelled loop whose harmonics stand as strong around it
//! (a 1 Hz sine's), and hum whose frequency wanders within a segment by more than a bin
//! (1/10 Hz): the last is reduced, not removed.

use super::constants::{
    MAINS_AROUND_HZ, MAINS_DECIMATED_HZ, MAINS_DRIVEN_SHARE, MAINS_GRID_SHARE, MAINS_HALVES_RATIO,
    MAINS_INPUT_HARMONICS, MAINS_LINE_RATIO, MAINS_MIN_FLOORS, MAINS_MIN_S, MAINS_SEGMENT_S,
};
use super::data::Data;
use super::signatures::refined_peak;
use super::unexplained::{MAINS_HARMONICS, MAINS_HZ};
use rustfft::FftPlanner;
use rustfft::num_complex::Complex;

/// One line of interference taken out of a segment of a record: `cos_v cos(w t) + sin_v
/// sin(w t)` with `w = 2 pi hz` and `t` the record's time, on samples `start..end`.
#[derive(Clone, Debug, PartialEq)]
pub struct HumLine {
    /// First sample of the segment.
    pub start: usize,
    /// One past its last sample.
    pub end: usize,
    /// The line's frequency, refined, Hz.
    pub hz: f64,
    /// Its cosine part, volts.
    pub cos_v: f64,
    /// Its sine part, volts.
    pub sin_v: f64,
    /// Its power over the largest of the residual's spectrum around it and at the input's
    /// neighbouring harmonics.
    pub line_ratio: f64,
}

impl HumLine {
    /// Its RMS, volts.
    pub fn rms_v(&self) -> f64 {
        (0.5 * (self.cos_v * self.cos_v + self.sin_v * self.sin_v)).sqrt()
    }
}

/// The record with `lines` subtracted from its output.
pub fn subtract(d: &Data, lines: &[HumLine]) -> Data {
    if lines.is_empty() {
        return d.clone();
    }
    let mut c = d.clone();
    for l in lines {
        let w = 2.0 * std::f64::consts::PI * l.hz;
        for i in l.start..l.end.min(c.y_v.len()) {
            let p = w * d.t_s[i];
            c.y_v[i] -= l.cos_v * p.cos() + l.sin_v * p.sin();
        }
    }
    c
}

/// The mains lines of `d`'s residual from `model_y` that are interference (see the module's
/// notes), segment by segment; `floor_v` is the record's noise floor.
pub fn mains_lines(d: &Data, floor_v: f64, model_y: &[f64]) -> Vec<HumLine> {
    let n = d.len();
    let dt = d.period_s();
    if model_y.len() != n || dt.is_nan() || dt <= 0.0 || (n as f64) * dt < MAINS_MIN_S {
        return Vec::new();
    }
    let segments = ((n as f64 * dt) / MAINS_SEGMENT_S).ceil().max(1.0) as usize;
    let seg_len = n.div_ceil(segments);
    let r: Vec<f64> = d.y_v.iter().zip(model_y).map(|(a, b)| a - b).collect();
    let mut out = Vec::new();
    let mut start = 0;
    while start < n {
        let end = (start + seg_len).min(n);
        if ((end - start) as f64) * dt >= MAINS_MIN_S {
            out.extend(segment_lines(d, &r, model_y, start, end, floor_v));
        }
        start = end;
    }
    out
}

/// Block means of `x[start..end]` over `block` samples.
fn decimate(x: &[f64], start: usize, end: usize, block: usize) -> Vec<f64> {
    x[start..end]
        .chunks_exact(block)
        .map(|c| c.iter().sum::<f64>() / block as f64)
        .collect()
}

/// Power spectrum of `x` (mean removed, Hann window, zero-padded to `len`), bins `0..len/2`.
fn padded_power(x: &[f64], len: usize) -> Vec<f64> {
    let m = x.iter().sum::<f64>() / x.len().max(1) as f64;
    let n = x.len();
    let mut buf: Vec<Complex<f64>> = (0..len)
        .map(|i| {
            if i < n {
                let w = 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos();
                Complex::new((x[i] - m) * w, 0.0)
            } else {
                Complex::new(0.0, 0.0)
            }
        })
        .collect();
    FftPlanner::new().plan_fft_forward(len).process(&mut buf);
    buf[..len / 2].iter().map(|c| c.norm_sqr()).collect()
}

/// The lines of one segment `start..end` of the residual `r`.
fn segment_lines(
    d: &Data,
    r: &[f64],
    model_y: &[f64],
    start: usize,
    end: usize,
    floor_v: f64,
) -> Vec<HumLine> {
    let dt = d.period_s();
    let fs = 1.0 / dt;
    let block = ((fs / MAINS_DECIMATED_HZ).floor() as usize).max(1);
    let fd = fs / block as f64;
    let x = decimate(r, start, end, block);
    let s = decimate(model_y, start, end, block);
    if x.len() < 64 {
        return Vec::new();
    }
    let seg_s = x.len() as f64 / fd;
    let len = (4 * x.len()).next_power_of_two();
    let df = fd / len as f64;
    let px = padded_power(&x, len);
    let ps = padded_power(&s, len);
    let bin = |f: f64| (f / df).round() as usize;
    // The largest power within `half` Hz of `f`.
    let peak_near = |p: &[f64], f: f64, half: f64| -> f64 {
        let lo = bin((f - half).max(0.0));
        let hi = bin(f + half).min(p.len() - 1);
        p[lo.min(hi)..=hi].iter().copied().fold(0.0, f64::max)
    };
    // The model output's strongest line (the input's period, as the stage passes it), from
    // two of its periods in the segment.
    let f0 = {
        let lo = bin(2.0 / seg_s).max(1);
        (lo..ps.len())
            .max_by(|&a, &b| ps[a].total_cmp(&ps[b]))
            .map_or(0.0, |k| k as f64 * df)
    };
    let mut out = Vec::new();
    for nominal in MAINS_HZ
        .iter()
        .flat_map(|m| (1..=MAINS_HARMONICS).map(move |h| m * h as f64))
    {
        let half = MAINS_GRID_SHARE * nominal;
        if nominal + half + 4.0 / seg_s >= 0.5 * fd {
            continue;
        }
        let (lo, hi) = (bin(nominal - half), bin(nominal + half));
        let Some(k) = (lo..=hi).max_by(|&a, &b| px[a].total_cmp(&px[b])) else {
            continue;
        };
        let hz = refined_peak(&px, k) * df;
        let line = px[k];
        // The spectrum around it, beyond the Hann window's main lobe.
        let inner = 4.0 / seg_s;
        let median_around = |p: &[f64]| -> Option<f64> {
            let mut around: Vec<f64> = p
                .iter()
                .enumerate()
                .filter(|(j, _)| {
                    let off = (*j as f64 * df - hz).abs();
                    off >= inner && off <= inner + MAINS_AROUND_HZ
                })
                .map(|(_, p)| *p)
                .collect();
            around.sort_by(f64::total_cmp);
            around.get(around.len() / 2).copied()
        };
        let Some(mut reference) = median_around(&px) else {
            continue;
        };
        // (a low harmonic of the input's line is an effect's the model lacks: a curvature
        // under a 25 Hz sine puts its second at 50 Hz, alone; `f0` is read to half a bin)
        if f0 >= 2.0 / seg_s
            && (1..=MAINS_INPUT_HARMONICS)
                .any(|k| (hz - k as f64 * f0).abs() <= k as f64 * df + 2.0 / seg_s)
        {
            continue;
        }
        // The input's neighbouring harmonics, where the segment holds enough of its periods.
        if f0 >= 5.0 / seg_s && f0 <= 0.5 * hz {
            for j in [-2.0, -1.0, 1.0, 2.0] {
                reference = reference.max(peak_near(&px, hz + j * f0, 1.0 / seg_s));
            }
        }
        let ratio = line / reference.max(1e-300);
        // (the model's output has a line there of its own, standing as far above its spectrum
        // around it, and not negligible beside the residual's: the input drives it)
        let model_line = peak_near(&ps, hz, 1.0 / seg_s);
        let driven = model_line > MAINS_DRIVEN_SHARE * line
            && model_line > MAINS_LINE_RATIO * median_around(&ps).unwrap_or(0.0);
        if ratio < MAINS_LINE_RATIO || driven {
            continue;
        }
        let Some((c, sn)) = fit_line(r, &d.t_s, start, end, hz) else {
            continue;
        };
        let rms = (0.5 * (c * c + sn * sn)).sqrt();
        if rms < MAINS_MIN_FLOORS * floor_v {
            continue;
        }
        // A standing line: both halves of the segment carry it alike.
        let mid = start + (end - start) / 2;
        let halves = [(start, mid), (mid, end)].map(|(a, b)| {
            fit_line(r, &d.t_s, a, b, hz).map_or(0.0, |(c, s)| (0.5 * (c * c + s * s)).sqrt())
        });
        if halves
            .iter()
            .any(|&h| !(rms / MAINS_HALVES_RATIO..=MAINS_HALVES_RATIO * rms).contains(&h))
        {
            continue;
        }
        out.push(HumLine {
            start,
            end,
            hz,
            cos_v: c,
            sin_v: sn,
            line_ratio: ratio,
        });
    }
    out
}

/// Weighted least squares of `r[start..end]` on `cos(w t)` and `sin(w t)` at `hz`, with a
/// Hann window's weights (the residual's slow content, which a rectangular window leaks into
/// a 50 Hz line, is held off): the cosine and sine parts, volts.
fn fit_line(r: &[f64], t: &[f64], start: usize, end: usize, hz: f64) -> Option<(f64, f64)> {
    let n = end.saturating_sub(start);
    if n < 16 {
        return None;
    }
    let w = 2.0 * std::f64::consts::PI * hz;
    let m = r[start..end].iter().sum::<f64>() / n as f64;
    let (mut cc, mut ss, mut cs, mut rc, mut rs) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (j, i) in (start..end).enumerate() {
        let h = 0.5 - 0.5 * (2.0 * std::f64::consts::PI * j as f64 / n as f64).cos();
        let (sp, cp) = (w * t[i]).sin_cos();
        let v = r[i] - m;
        cc += h * cp * cp;
        ss += h * sp * sp;
        cs += h * cp * sp;
        rc += h * v * cp;
        rs += h * v * sp;
    }
    let det = cc * ss - cs * cs;
    if det.abs() < 1e-12 * (cc * ss).max(1e-300) {
        return None;
    }
    Some(((rc * ss - rs * cs) / det, (rs * cc - rc * cs) / det))
}

/// Words for the table and the report on the lines taken out of record `name`, if any.
pub fn note(name: &str, lines: &[HumLine], floor_v: f64) -> Option<String> {
    if lines.is_empty() {
        return None;
    }
    // One entry per line: the strongest segment's.
    let mut by_line: Vec<&HumLine> = Vec::new();
    for l in lines {
        match by_line
            .iter_mut()
            .find(|b| (b.hz - l.hz).abs() <= MAINS_GRID_SHARE * l.hz)
        {
            Some(b) if b.rms_v() < l.rms_v() => *b = l,
            Some(_) => {}
            None => by_line.push(l),
        }
    }
    by_line.sort_by(|a, b| a.hz.total_cmp(&b.hz));
    let words: Vec<String> = by_line
        .iter()
        .map(|l| format!("{:.3} Hz {:.2} mV RMS", l.hz, 1e3 * l.rms_v()))
        .collect();
    // (a residual of exact zeros around a line makes its ratio unbounded: said as a million)
    let least = by_line
        .iter()
        .map(|l| l.line_ratio)
        .fold(f64::INFINITY, f64::min)
        .min(1e6);
    Some(format!(
        "{name}: mains interference taken out of the output ({}; {:.2} noise floors in all): \
         lines the input does not drive, each standing at least {least:.0} times in power above \
         the residual's spectrum around it and at the input's neighbouring harmonics",
        words.join(", "),
        (by_line.iter().map(|l| l.rms_v() * l.rms_v()).sum::<f64>()).sqrt() / floor_v
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::csv::Record;

    const TAU: f64 = 2.0 * std::f64::consts::PI;

    /// `seconds` at `rate_hz` of the input `u(t)`, a model that follows it exactly (its
    /// output is `u`), and a measured output of `u`, `extra(t)` and 1 mV of white noise: the
    /// record, the model's output and the noise.
    fn record(
        rate_hz: f64,
        seconds: f64,
        u: impl Fn(f64) -> f64,
        extra: impl Fn(f64) -> f64,
    ) -> (Data, Vec<f64>, Vec<f64>) {
        let n = (rate_hz * seconds) as usize;
        let noise: Vec<f64> = crate::testing::filtered_noise(n, rate_hz, 0.0, 0, 17)
            .iter()
            .map(|w| 1e-3 * w)
            .collect();
        let t: Vec<f64> = (0..n).map(|i| i as f64 / rate_hz).collect();
        let uv: Vec<f64> = t.iter().map(|&x| u(x)).collect();
        let y: Vec<f64> = (0..n).map(|i| uv[i] + extra(t[i]) + noise[i]).collect();
        let model = uv.clone();
        let d = Data::from_record("hum", Record::new(t, uv, Some(y), None).unwrap()).unwrap();
        (d, model, noise)
    }

    fn sine(t: f64) -> f64 {
        5.0 - 4.5 * (TAU * t).cos()
    }

    /// Hum on a 50 Hz grid (3 mV RMS at 50.013 Hz and 1 mV at its third harmonic) and on a
    /// 60 Hz one (2 mV at 59.97 Hz, 1.5 mV at 120.05 Hz), over one segment and over three
    /// (25 s), at 5 and 50 kHz: each line found in every segment at its frequency (within a
    /// hundredth of a bin of 0.1 Hz... 2 mHz) and its RMS (within 3 %, a Hann-weighted fit's
    /// error under 1 mV of noise), and what is left of the output after it is taken out is the
    /// model's output and the noise within a twentieth of the noise.
    #[test]
    fn hum_is_found_fitted_and_taken_out() {
        // (rate, seconds, and each line's frequency and RMS)
        type Case = (f64, f64, [(f64, f64); 2]);
        let cases: [Case; 3] = [
            (5e3, 10.0, [(50.013, 3e-3), (150.039, 1e-3)]),
            (5e3, 25.0, [(50.013, 3e-3), (150.039, 1e-3)]),
            (50e3, 10.0, [(59.97, 2e-3), (120.05, 1.5e-3)]),
        ];
        for (rate_hz, seconds, lines) in cases {
            let hum = |t: f64| {
                lines
                    .iter()
                    .enumerate()
                    .map(|(k, &(f, rms))| {
                        rms * 2f64.sqrt() * (TAU * f * t + 0.7 * k as f64 + 0.3).sin()
                    })
                    .sum::<f64>()
            };
            let (d, model, noise) = record(rate_hz, seconds, sine, hum);
            let found = mains_lines(&d, 1e-3, &model);
            let segments = (seconds / MAINS_SEGMENT_S).ceil() as usize;
            assert_eq!(found.len(), 2 * segments, "{rate_hz} {seconds}: {found:?}");
            for &(f, rms) in &lines {
                let of: Vec<&HumLine> = found.iter().filter(|l| (l.hz - f).abs() < 0.5).collect();
                assert_eq!(of.len(), segments, "{f} Hz: {found:?}");
                for l in of {
                    assert!((l.hz - f).abs() < 2e-3, "{f} Hz read {}", l.hz);
                    assert!(
                        (l.rms_v() / rms - 1.0).abs() < 0.03,
                        "{f} Hz: {} V",
                        l.rms_v()
                    );
                }
            }
            let c = subtract(&d, &found);
            let left: f64 = (0..d.len())
                .map(|i| (c.y_v[i] - model[i] - noise[i]).powi(2))
                .sum::<f64>()
                / d.len() as f64;
            assert!(
                left.sqrt() < 0.05e-3,
                "{rate_hz} {seconds}: {} mV left",
                1e3 * left.sqrt()
            );
            let words = note("hum", &found, 1e-3).unwrap();
            assert!(words.contains(&format!("{:.3} Hz", lines[0].0)), "{words}");
        }
    }

    /// What the noise, the stage or the model's misfit make is not taken for hum: white
    /// noise alone; an unmodelled loop under a 1 Hz sine (a steep one, whose harmonics at 49,
    /// 50 and 51 Hz are 2.5-8 mV: 50 Hz is one of them, and its neighbours as strong); a
    /// 5 % gain error under a 50 Hz input (a 100 mV line at 50 Hz, which the input drives);
    /// a curvature the model lacks under a 25 Hz sine (its second harmonic, 20 mV at 50 Hz, with
    /// no neighbour); a 20 mV ring at 50 Hz that dies away over a second (as narrow as a line, 0.16 Hz, but
    /// not a standing one: the segment's second half holds a tenth of its amplitude).
    #[test]
    fn what_the_stage_or_its_misfit_makes_is_not_hum() {
        type Signal<'a> = &'a dyn Fn(f64) -> f64;
        let cases: [(&str, Signal, Signal); 5] = [
            ("noise", &sine, &|_| 0.0),
            ("a loop's harmonics", &sine, &|t| {
                0.2 * (20.0 * (TAU * t + 0.3).sin()).tanh()
                    + 0.05 * (10.0 * (2.0 * TAU * t).sin()).tanh()
            }),
            (
                "a driven line",
                &|t| 5.0 + 2.0 * (TAU * 50.0 * t).sin(),
                &|t| 0.05 * 2.0 * (TAU * 50.0 * t).sin(),
            ),
            (
                "a curvature's second harmonic",
                &|t| 5.0 + 4.5 * (TAU * 25.0 * t).sin(),
                &|t| 0.002 * (4.5 * (TAU * 25.0 * t).sin()).powi(2),
            ),
            ("a ring", &sine, &|t| {
                if t > 1.0 {
                    0.02 * (-(t - 1.0) / 1.0).exp() * (TAU * 50.0 * (t - 1.0)).sin()
                } else {
                    0.0
                }
            }),
        ];
        for (name, u, extra) in cases {
            let (d, model, _) = record(5e3, 10.0, u, extra);
            let found = mains_lines(&d, 1e-3, &model);
            assert!(found.is_empty(), "{name}: {found:?}");
        }
    }
}
