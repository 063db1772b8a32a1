//! Never silent (issue #12, item 5): when the workflow stops with some record's residual still
//! above [`UNEXPLAINED_FLOOR_RATIO`] times its noise floor, the part no catalogued effect
//! explained is reported, with where it sits, in the table, the report and the JSON
//! (`"unexplained": {"rms_v", "where"}`). Where the record's input repeats, the bar is set by
//! the larger of the floor and the bar the noise the residual holds between the input's
//! cycles sets ([`cycle_bar_v`](super::cycle_noise::cycle_bar_v): a sensor's low-frequency
//! noise, which the floor does not count).
//!
//! Where, per record above the bar, from the final residual alone (no assumption of holds,
//! edges or a fast/slow pair):
//! * **in time**: the tenth of the record (ten equal windows) that holds the largest share of
//!   the residual power;
//! * **against the input**: the tenth of the record's input span whose samples carry the largest
//!   mean-square residual, and whether the residual differs between rising and falling input
//!   there (a loop the model lacks);
//! * **in frequency**: the strongest line of the residual's amplitude spectrum (one Hann
//!   window over up to 2^16 samples) and the share of the residual power within 10 % of it,
//!   with what drives it where the input has no power there ([`UNDRIVEN_SHARE`]): a harmonic
//!   of the input's own line, or a line the input does not drive, on a mains frequency
//!   (interference in the measurement?) or not;
//! * **along the input's stretches** (since session 42): where the reading runs against its
//!   input, along a stretch where the input only rises or only falls, by
//!   [`BACKWARDS_FLOORS`] floors more than the model's response does: a loop whose branches
//!   run backwards (a Duhem or Bouc-Wen form can), which no Everett table follows.
//!
//! `rms_v` is the residual RMS with the noise floor (or that noise, where it set the bar)
//! taken out in quadrature, the root of the mean over records of `max(MSE_r - floor_r^2, 0)`:
//! the part a model could still explain.

use super::data::{Data, min_max};
use super::signatures::averaged_spectrum;

/// A record is left unexplained when its final residual RMS exceeds this many times its noise
/// floor (the bar: "above 2x the floor").
pub const UNEXPLAINED_FLOOR_RATIO: f64 = 2.0;

/// The residual no catalogued effect explained.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Unexplained {
    /// Residual RMS above the noise (quadrature), volts.
    pub rms_v: f64,
    /// Where it sits, in words (times, input ranges, frequencies), per record.
    #[serde(rename = "where")]
    pub where_: String,
}

/// The unexplained residual of `y - sims`, if some record stays above the bar, and a note for
/// each record whose bar was set by the noise between a periodic input's cycles (`cycle`, per
/// record: [`cycle_bar_v`](super::cycle_noise::cycle_bar_v), read by the caller before its
/// final check) rather than by its floor `noise`, where that is the larger.
pub fn locate(
    data: &[Data],
    sims: &[Vec<f64>],
    noise: &[f64],
    cycle: &[Option<f64>],
) -> (Option<Unexplained>, Vec<String>) {
    let mut parts = Vec::new();
    let mut notes = Vec::new();
    let mut excess = 0.0;
    for (((d, y), &floor), c) in data.iter().zip(sims).zip(noise).zip(cycle) {
        let r: Vec<f64> = d.y_v.iter().zip(y).map(|(a, b)| a - b).collect();
        let ms = r.iter().map(|e| e * e).sum::<f64>() / r.len().max(1) as f64;
        // (said only where the floor alone would leave the record unexplained)
        let f = match *c {
            Some(c) if c > floor && ms.sqrt() > UNEXPLAINED_FLOOR_RATIO * floor => {
                notes.push(format!(
                    "{}: its residual holds noise that does not repeat with the input's \
                     cycles (above their fundamental), {:.2} mV counted ({:.2}x the floor read \
                     from its fast part): noise at low frequencies, or a misfit that changes \
                     from cycle to cycle; the residual ({:.2} mV) is judged against it",
                    d.name,
                    1e3 * c,
                    c / floor.max(1e-12),
                    1e3 * ms.sqrt()
                ));
                c
            }
            _ => floor,
        };
        excess += (ms - f * f).max(0.0);
        if ms.sqrt() > UNEXPLAINED_FLOOR_RATIO * f {
            parts.push(format!(
                "{} ({:.2} mV, {:.1}x its floor): {}",
                d.name,
                1e3 * ms.sqrt(),
                ms.sqrt() / f.max(1e-12),
                describe(d, &r)
            ));
            // (against the noise the record is judged against: a sensor's low-frequency
            // noise, where it set the bar, is not averaged down by the means)
            if let Some(w) = backwards(d, y, f) {
                parts.push(w);
            }
        }
    }
    if parts.is_empty() {
        return (None, notes);
    }
    let u = Unexplained {
        rms_v: (excess / data.len().max(1) as f64).sqrt(),
        where_: parts.join("; "),
    };
    (Some(u), notes)
}

/// Where the residual `r` of record `d` sits, in words.
#[allow(clippy::needless_range_loop)] // input, residual and bins indexed together
fn describe(d: &Data, r: &[f64]) -> String {
    let n = r.len();
    let total: f64 = r.iter().map(|e| e * e).sum::<f64>().max(1e-300);
    // In time: ten equal windows.
    let w = n.div_ceil(10).max(1);
    let (k, p) = (0..n.div_ceil(w))
        .map(|k| {
            let s: f64 = r[k * w..((k + 1) * w).min(n)].iter().map(|e| e * e).sum();
            (k, s)
        })
        .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    let t0 = d.t_s[k * w];
    let t1 = d.t_s[((k + 1) * w).min(n) - 1];
    let time = format!(
        "{:.0} % of its residual power in t = {t0:.3}-{t1:.3} s",
        100.0 * p / total
    );
    // Against the input: ten bins of the span, the one with the largest mean square.
    let (lo, hi) = min_max(&d.u_v);
    let span = (hi - lo).max(1e-9);
    let mut bins = vec![(0.0f64, 0usize, 0.0f64, 0usize, 0.0f64, 0usize); 10];
    for i in 0..n {
        let b = (((d.u_v[i] - lo) / span * 10.0) as usize).min(9);
        bins[b].0 += r[i] * r[i];
        bins[b].1 += 1;
        let du = if i > 0 { d.u_v[i] - d.u_v[i - 1] } else { 0.0 };
        if du > 0.0 {
            bins[b].2 += r[i];
            bins[b].3 += 1;
        } else if du < 0.0 {
            bins[b].4 += r[i];
            bins[b].5 += 1;
        }
    }
    let (b, bin) =
        bins.iter()
            .enumerate()
            .filter(|(_, x)| x.1 > 0)
            .fold((0, bins[0]), |a, (i, x)| {
                if x.0 / x.1 as f64 > a.1.0 / a.1.1.max(1) as f64 {
                    (i, *x)
                } else {
                    a
                }
            });
    let u0 = lo + span * b as f64 / 10.0;
    let mut input = format!(
        "largest at u = {u0:.2}-{:.2} V ({:.2} mV RMS there)",
        u0 + span / 10.0,
        1e3 * (bin.0 / bin.1.max(1) as f64).sqrt()
    );
    if bin.3 >= 10 && bin.5 >= 10 {
        let gap = bin.2 / bin.3 as f64 - bin.4 / bin.5 as f64;
        input.push_str(&format!(
            ", rising minus falling input {:+.2} mV",
            1e3 * gap
        ));
    }
    format!("{time}; {input}; {}", line(r, &d.u_v, d.period_s()))
}

/// Samples in the moving mean through which the unexplained part reads a record's reading and
/// input for a loop whose branches run backwards (`backwards`)
/// (our assumption: the noise of a mean of 32 samples is 0.18 of the floor, and a loop's
/// branch spans hundreds of samples on the slowest record a lab makes at 1 kHz).
pub const BACKWARDS_WINDOW: usize = 32;

/// How far, in noise floors, a record's reading must run against its input beyond what the
/// model's own response does, along one monotone stretch of the input, for `backwards` to
/// say so (our assumption: the difference of two 32-sample means has a noise of 0.25 of the
/// floor, so 5 floors is 20 of its standard deviations).
pub const BACKWARDS_FLOORS: f64 = 5.0;

/// Where the reading of record `d` runs against its input, along a stretch where the input
/// only rises (or only falls), by [`BACKWARDS_FLOORS`] noise floors more than the model's
/// simulated output `sim` does there (its drift): a loop whose branches run backwards, which
/// no Everett table follows (its output rises with its input on every branch). Read through
/// moving means of [`BACKWARDS_WINDOW`] samples; stretches shorter than four windows, those
/// where the model's own response runs against the input by as much (a fast stretch its
/// dynamics bend), and the record's first (its start) are not read. `None` where nothing runs
/// so.
fn backwards(d: &Data, sim: &[f64], floor: f64) -> Option<String> {
    let w = BACKWARDS_WINDOW;
    let n = d.len().min(sim.len());
    if n < 4 * w {
        return None;
    }
    let mean = |x: &[f64]| -> Vec<f64> {
        let mut acc = 0.0;
        let mut out = Vec::with_capacity(n + 1 - w);
        for (i, v) in x[..n].iter().enumerate() {
            acc += v;
            if i >= w {
                acc -= x[i - w];
            }
            if i + 1 >= w {
                out.push(acc / w as f64);
            }
        }
        out
    };
    let (u, y, m) = (mean(&d.u_v), mean(&d.y_v), mean(sim));
    // Monotone stretches of the smoothed input: (first, end, rising).
    let mut stretches: Vec<(usize, usize, bool)> = Vec::new();
    let mut start = 0;
    let mut dir: Option<bool> = None;
    for i in 1..u.len() {
        let step = u[i] - u[i - 1];
        if step == 0.0 {
            continue;
        }
        let rising = step > 0.0;
        match dir {
            Some(r) if r != rising => {
                stretches.push((start, i, r));
                start = i - 1;
                dir = Some(rising);
            }
            None => dir = Some(rising),
            _ => {}
        }
    }
    if let Some(r) = dir {
        stretches.push((start, u.len(), r));
    }
    // The largest run against the input along each stretch (a fall after the highest
    // reading so far while the input rises), the model's own taken off.
    let against = |x: &[f64], a: usize, b: usize, rising: bool| -> (f64, usize) {
        let sign = if rising { 1.0 } else { -1.0 };
        let mut best = f64::NEG_INFINITY;
        let (mut most, mut at) = (0.0, a);
        for (i, v) in x[a..b].iter().enumerate() {
            best = best.max(sign * v);
            if best - sign * v > most {
                (most, at) = (best - sign * v, a + i);
            }
        }
        (most, at)
    };
    let worst = stretches
        .iter()
        .filter(|(a, b, _)| b - a >= 4 * w)
        .map(|&(a, b, rising)| {
            let (dy, at) = against(&y, a, b, rising);
            let (dm, _) = against(&m, a, b, rising);
            (dy - dm, dy, a, b, at, rising, dm)
        })
        // (a stretch whose model response itself runs against the input, a fast one its
        // dynamics bend, is not read: there a misfit of the dynamics runs so too; nor the
        // first, which holds the record's start, where a stage may still be settling from
        // before it: families case 1043, a Preisach plane, 72 mV within 17 ms of its start)
        .filter(|x| x.0.is_finite() && x.6 <= BACKWARDS_FLOORS * floor && x.2 > 0)
        .map(|(e, dy, a, b, at, rising, _)| (e, dy, a, b, at, rising))
        .fold(
            None,
            |acc: Option<(f64, f64, usize, usize, usize, bool)>, x| match acc {
                Some(a) if a.0 >= x.0 => Some(a),
                _ => Some(x),
            },
        )?;
    let (excess, dy, a, b, at, rising) = worst;
    if excess <= BACKWARDS_FLOORS * floor {
        return None;
    }
    // (the means lag their samples by half a window)
    let t = |i: usize| d.t_s[(i + w / 2).min(n - 1)];
    Some(format!(
        "{}: while its input {} from {:.2} to {:.2} V (t = {:.3}-{:.3} s), its reading \
         runs {:.2} mV against it by t = {:.3} s, {:.1}x its floor more than the model's \
         response does: a loop whose branches run backwards there, which no Everett table \
         follows (the table's output moves with its input on every branch; a Duhem or \
         Bouc-Wen loop can), or an effect the final model lacks (a creep it does not hold?)",
        d.name,
        if rising { "rises" } else { "falls" },
        u[a],
        u[b - 1],
        t(a),
        t(b - 1),
        1e3 * dy,
        t(at),
        excess / floor.max(1e-12)
    ))
}

/// Share of the input's varying power near a residual line below which the input does not
/// drive it (our assumption: a Hann window's leakage from a line a decade or more away is
/// below 1e-6; a harmonic a stage makes from its input is told by its frequency instead).
pub const UNDRIVEN_SHARE: f64 = 1e-6;

/// Highest harmonic of the input's strongest line that a residual line is said to be (our
/// assumption: a static shape or a loop bends a sine into its first few harmonics).
pub const HARMONIC_MAX: f64 = 20.0;

/// Spectrum bins either side of a line that count as the line (a Hann window spreads a line
/// over about two bins either side of its centre).
pub const LINE_BINS: f64 = 2.0;

/// Input cycles a record must hold, at its strongest line, for a residual line to be called a
/// harmonic of it (our assumption: with fewer, the harmonics lie within a few bins of each
/// other and every low line would be one).
pub const HARMONIC_MIN_CYCLES: f64 = 5.0;

/// Mains frequencies, Hz (the 50 and 60 Hz grids).
pub const MAINS_HZ: [f64; 2] = [50.0, 60.0];
/// Harmonics of the mains named as such (our assumption: a rectifier's hum is mostly the
/// first few).
pub const MAINS_HARMONICS: usize = 5;
/// How far from its nominal a mains line may sit, as a share of its frequency (our
/// assumption: a grid holds its frequency within about 1 %, and a line's own spread in a
/// Hann window adds as much); a spectrum coarser than this window names no mains line.
pub const MAINS_TOL_SHARE: f64 = 0.02;

/// The input's strongest line, Hz, refined between its bins
/// ([`super::signatures::refined_peak`]).
fn strongest_line_hz(input: &[(f64, f64)], df: f64) -> f64 {
    let Some(k) = (0..input.len()).max_by(|&a, &b| input[a].1.total_cmp(&input[b].1)) else {
        return 0.0;
    };
    let powers: Vec<f64> = input.iter().map(|b| b.1).collect();
    input[k].0 + (super::signatures::refined_peak(&powers, k) - k as f64) * df
}

/// What drives the residual's line at `f` Hz (spectrum bin width `df`; `input` the input's
/// power spectrum on the same bins), in words, or nothing where the input has power there: a
/// harmonic of the input's own strongest line (where the record holds
/// [`HARMONIC_MIN_CYCLES`] of it; the tolerance grows with the harmonic's number, as the
/// refined line's error does), or a line the input does not drive, at a mains frequency or
/// not. A line the input does not drive is no effect of the stage's that the catalogue could
/// add: interference in the measurement is the first thing to check on a real record.
fn drive(f: f64, df: f64, input: &[(f64, f64)]) -> String {
    let total: f64 = input.iter().map(|b| b.1).sum::<f64>();
    if total <= 0.0 || f <= 0.0 || df <= 0.0 {
        return String::new();
    }
    let at: f64 = input
        .iter()
        .filter(|b| (b.0 - f).abs() <= LINE_BINS * df)
        .map(|b| b.1)
        .sum();
    if at > UNDRIVEN_SHARE * total {
        return String::new();
    }
    let f0 = strongest_line_hz(input, df);
    if f0 >= HARMONIC_MIN_CYCLES * df {
        let k = (f / f0).round();
        let tol = (df * (LINE_BINS + 0.5 * k)).min(0.25 * f0);
        if (1.0..=HARMONIC_MAX).contains(&k) && (f - k * f0).abs() <= tol {
            return format!(" (harmonic {k:.0} of the input's {f0:.3} Hz)");
        }
    }
    let mains = MAINS_HZ
        .iter()
        .flat_map(|m| (1..=MAINS_HARMONICS).map(move |h| m * h as f64))
        .any(|m| {
            let window = MAINS_TOL_SHARE * m;
            LINE_BINS * df <= window && (m - f).abs() <= window
        });
    if mains {
        " (the input does not drive it and it sits on a mains frequency: interference in the \
         measurement rather than the stage?)"
            .into()
    } else {
        " (the input does not drive it)".into()
    }
}

/// The strongest line of `r`'s spectrum and its share of the power, in words: one Hann
/// segment over the record (at most 2^16 samples), the line test's own spectrum routine;
/// with what drives the line, from the input `u`'s spectrum on the same samples ([`drive`]).
fn line(r: &[f64], u: &[f64], t: f64) -> String {
    let n = r.len().min(u.len()).min(1 << 16);
    if n < 64 {
        return "too short for a spectrum".into();
    }
    let x = &r[..n];
    let m = x.iter().sum::<f64>() / n as f64;
    // Power per bin, up to a common factor (the shares below are ratios).
    let p: Vec<(f64, f64)> = averaged_spectrum(x, t, n)
        .into_iter()
        .map(|(f, a)| (f, a * a))
        .collect();
    let total: f64 = p.iter().map(|b| b.1).sum::<f64>().max(1e-300);
    let k = (0..p.len()).fold(0, |a, k| if p[k].1 > p[a].1 { k } else { a });
    let f = p[k].0;
    let near: f64 = p
        .iter()
        .enumerate()
        .filter(|&(j, b)| (b.0 / f - 1.0).abs() <= 0.1 || j.abs_diff(k) <= 2)
        .map(|(_, b)| b.1)
        .sum();
    let dc_share = 100.0 * m * m * n as f64 / x.iter().map(|e| e * e).sum::<f64>().max(1e-300);
    let input: Vec<(f64, f64)> = averaged_spectrum(&u[..n], t, n)
        .into_iter()
        .map(|(f, a)| (f, a * a))
        .collect();
    // (the spectrum's bin width: one segment of `n` samples)
    let df = 1.0 / (n as f64 * t);
    format!(
        "strongest residual frequency {f:.3} Hz{} ({:.0} % of the varying power within 10 % of it); mean {:.2} mV ({dc_share:.0} % of the power)",
        drive(f, df, &input),
        100.0 * near / total,
        1e3 * m
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::csv::Record;

    /// A loop whose falling branch runs backwards is said, one whose branches follow the
    /// input is not, and neither is a run against the input that the model's own response
    /// makes too (its dynamics on a fast stretch). 10 s at 5 kHz of a 1 Hz sine over
    /// 0.5-9.5 V, a model (`sim`) that follows it as a straight line, 1 mV of noise.
    #[test]
    fn a_loop_whose_branches_run_backwards_is_said() {
        let n = 50_000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 5e3).collect();
        let u: Vec<f64> = t
            .iter()
            .map(|x| 5.0 - 4.5 * (std::f64::consts::TAU * x).cos())
            .collect();
        let noise = crate::testing::filtered_noise(n, 5e3, 0.0, 0, 7);
        let floor = 1e-3;
        let gain = model_core::params::PLANT_GAIN;
        let sim: Vec<f64> = u.iter().map(|x| gain * x).collect();
        let record = |loop_v: &dyn Fn(f64, f64) -> f64| {
            let y: Vec<f64> = (0..n)
                .map(|i| {
                    let du = if i > 0 { u[i] - u[i - 1] } else { 0.0 };
                    sim[i] + loop_v(u[i], du) + floor * noise[i]
                })
                .collect();
            Data::from_record(
                "r.csv",
                Record::new(t.clone(), u.clone(), Some(y), None).unwrap(),
            )
            .unwrap()
        };
        // A loop term of up to +-40 mV that closes at the sine's ends (a Preisach loop's
        // branches meet at its turning points), whose falling branch has a bump of 0.5 V
        // around 5 V, steep enough (1.7 V/V at most) to beat the stage's static gain (0.79 V/V): the reading
        // runs against the falling input there, by about 0.3 V.
        let width = |x: f64| 0.04 * (std::f64::consts::PI * (x - 0.5) / 9.0).sin();
        let bump = |x: f64| 0.5 * (-((x - 5.0) / 0.25).powi(2)).exp();
        let back = record(&|x, du| {
            if du < 0.0 {
                width(x) - bump(x)
            } else {
                -width(x)
            }
        });
        let said = backwards(&back, &sim, floor).expect("a backwards branch");
        assert!(
            said.contains("falls") && said.contains("branches run backwards"),
            "{said}"
        );
        // The same loop with a bump of 0.15 V (0.52 V/V at most): its branches still follow
        // the input.
        let fwd = record(&|x, du| {
            if du < 0.0 {
                width(x) - 0.3 * bump(x)
            } else {
                -width(x)
            }
        });
        assert_eq!(backwards(&fwd, &sim, floor), None);
        // A run against the input in the record that the model makes too is not said.
        let sim_back: Vec<f64> = (0..n)
            .map(|i| {
                let du = if i > 0 { u[i] - u[i - 1] } else { 0.0 };
                sim[i]
                    + if du < 0.0 {
                        width(u[i]) - bump(u[i])
                    } else {
                        -width(u[i])
                    }
            })
            .collect();
        assert_eq!(backwards(&back, &sim_back, floor), None);
    }

    /// 10 s at 5 kHz of a 1 Hz sine input (plus a 0.2 V line at `extra_hz` where given), a
    /// model that follows it exactly, and records with a 3 mV line at `line_hz` added: the
    /// words on the residual's line.
    fn words(line_hz: f64, extra_hz: Option<f64>) -> String {
        words_at(1.0, 10.0, line_hz, extra_hz)
    }

    /// As [`words`], with an input sine of `f0_hz` over `seconds`.
    fn words_at(f0_hz: f64, seconds: f64, line_hz: f64, extra_hz: Option<f64>) -> String {
        let n = (5_000.0 * seconds) as usize;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 5_000.0).collect();
        let w = |f: f64, x: f64| (2.0 * std::f64::consts::PI * f * x).sin();
        let u: Vec<f64> = t
            .iter()
            .map(|&x| 5.0 + 4.0 * w(f0_hz, x) + extra_hz.map_or(0.0, |f| 0.2 * w(f, x)))
            .collect();
        let sim = u.clone();
        let y: Vec<f64> = u
            .iter()
            .zip(&t)
            .map(|(v, &x)| v + 3e-3 * (2.0 * std::f64::consts::PI * line_hz * x + 0.3).sin())
            .collect();
        let d = Data::from_record("r.csv", Record::new(t, u, Some(y), None).unwrap()).unwrap();
        locate(&[d], &[sim], &[1e-4], &[None]).0.unwrap().where_
    }

    /// The residual's strongest line is told as the records show it: on a mains frequency the
    /// input does not drive (interference), a harmonic of the input's sine, a line the input
    /// does not drive elsewhere, and nothing where the input drives that frequency itself.
    #[test]
    fn the_residual_line_says_what_drives_it() {
        let mains = words(50.0, None);
        assert!(
            mains.contains("50.000 Hz (the input does not drive it and it sits on a mains"),
            "{mains}"
        );
        let harmonic = words(3.0, None);
        assert!(
            harmonic.contains("3.000 Hz (harmonic 3 of the input's 1.000 Hz)"),
            "{harmonic}"
        );
        let other = words(37.3, None);
        assert!(
            other.contains("Hz (the input does not drive it) ("),
            "{other}"
        );
        let driven = words(37.3, Some(37.3));
        assert!(
            !driven.contains("drive") && !driven.contains("harmonic"),
            "{driven}"
        );
        // An input between the spectrum's bins (1.03 Hz on 0.1 Hz bins): its 7th harmonic
        // (7.21 Hz, three bins from 7 times the raw peak) is still one, and a line between
        // harmonics (7.7 Hz) is not.
        let off_bin = words_at(1.03, 10.0, 7.21, None);
        assert!(
            off_bin.contains("(harmonic 7 of the input's 1.03"),
            "{off_bin}"
        );
        let between = words_at(1.03, 10.0, 7.7, None);
        assert!(
            between.contains("Hz (the input does not drive it) ("),
            "{between}"
        );
        // Four input cycles (0.2 Hz over 20 s): too few to call a low line a harmonic.
        let few = words_at(0.2, 20.0, 0.9, None);
        assert!(!few.contains("harmonic"), "{few}");
        // A 0.2 s record's 5 Hz bins are coarser than the mains window at 50 Hz (1 Hz).
        let coarse = words_at(10.0, 0.2, 50.0, None);
        assert!(
            coarse.contains("Hz (the input does not drive it) ("),
            "{coarse}"
        );
    }
}
