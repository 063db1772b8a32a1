//! Where the disagreement is, in time and in frequency: the signature of each effect.
//!
//! * **after edges** (fast records): the share of the residual power within 3 ms after an
//!   input jump: time delay, amplifier pole, slew limiter and resonance live there;
//! * **spectrum** (fast records, rustfft): the residual's strongest line above 500 Hz and how
//!   far it stands above the median level: a second mode rings at its frequency. The line test
//!   uses a Welch average of the first fast record (Hann segments of [`WELCH_SEGMENT`]
//!   samples, half overlap): one periodogram of white noise has bins spread like a Rayleigh
//!   variable, so its largest bin near any frequency stands 2-4x above the median and a weak
//!   true line only 9x; averaged, noise stays within about 1.5x. A ringing after edges is
//!   transient, so averaging lowers its line too (a weak mode went from 9.4x to 5.9x), but
//!   less than the noise's spread;
//! * **tails** (holds of at least 0.2 s): how far the residual moves from shortly after a step
//!   to the end of the hold: drift;
//! * **loop** (slowly moving input): the largest gap between the residual on rising and on
//!   falling input at the same input level: hysteresis; in a record of steps alone (random
//!   levels, no input that moves slowly) the gap between held levels reached from below and
//!   from above, a static quadratic (a quartic on many levels) taken out, which counts where
//!   the holds show no tail (a creep that has not caught up leaves the same pattern) or the
//!   model already has a drift (a creep and a loop together: the tails are the drift's;
//!   session 28);
//! * **static curve** (settled samples): the curvature of the residual against the input:
//!   non-linear gain;
//! * **range**: whether the input comes near the amplifier's limits: saturation;
//! * **level and scale** (all samples): the least-squares line of the residual against the
//!   simulated output: its intercept is an `offset`, its slope a `sensor-gain` error.
//!
//! Each is a number with a unit; [`Signatures::supports`] turns them into the gate the
//! selection uses, [`Signatures::describe`] into words for the table.

use super::constants::{
    HELD_LOOP_MIN_DIR_SHARE, HELD_LOOP_MIN_HOLDS, HELD_LOOP_MIN_S, HELD_LOOP_QUARTIC_LEVELS,
};
use super::{
    DRIFT_TAIL_MIN_NOISE, Data, HYST_LOOP_MIN_NOISE, LINE_RATIO_MIN, MAX_MODE_DAMPING,
    OFFSET_SHOWN_MIN, REST_ZERO_SHOWN_MIN, REST_ZERO_SIGMAS, catalogue,
};
use crate::io::model_file::ModelFile;
use model_core::params;
use nalgebra::{DMatrix, DVector};
use rustfft::{FftPlanner, num_complex::Complex};

/// The measured signatures of a residual.
#[derive(Clone, Debug, Default)]
pub struct Signatures {
    /// Share of the fast records' residual power within 3 ms after edges.
    pub edge_share: f64,
    /// Strongest line of the first fast record's Welch-averaged residual spectrum above
    /// 500 Hz, Hz.
    pub peak_hz: f64,
    /// Largest tail after a step during a hold, volts.
    pub tail_v: f64,
    /// Holds in the records ([`Data::holds`]).
    pub holds: usize,
    /// Largest rising/falling gap of the residual at equal input, volts.
    pub loop_v: f64,
    /// Largest gap between held levels reached from below and from above at equal input, in
    /// records of steps alone (no input that moves slowly), volts: the residual of each
    /// hold's second half fitted to a static quadratic (a quartic on many levels) and the
    /// direction of the step into it.
    pub held_loop_v: f64,
    /// Whether a record of steps alone holds enough levels for that loop, reached each way,
    /// but the direction of the step into each follows from its level (the levels reached
    /// from below all at one end): its held levels give no answer, loop or none.
    pub held_loop_untold: bool,
    /// Whether some record answered the loop's question, whatever the size of its answer: a
    /// slowly moving input's rising/falling gap (`loop_v`) or a held levels' gap
    /// (`held_loop_v`).
    pub loop_answered: bool,
    /// Curvature of the residual against the input (largest deviation from the chord), volts.
    pub curve_v: f64,
    /// Input span (min, max), volts.
    pub u_span_v: (f64, f64),
    /// Intercept of the residual's least-squares line against the simulated output, volts.
    pub level_v: f64,
    /// Slope of that line (a scale error of the monitor), fraction.
    pub scale: f64,
    /// Over the records' first rest at 0 V input ([`Data::zero_rest_len`]): the
    /// residual's mean,
    /// the measured output's mean and the standard error of a mean there, volts; `None` where
    /// no record starts so.
    pub rest_zero_v: Option<(f64, f64, f64)>,
    /// Noise floor, volts.
    pub noise_v: f64,
    /// Residual spectrum of the first fast record: (frequency Hz, magnitude V) for plots.
    pub spectrum: Vec<(f64, f64)>,
    /// Welch-averaged amplitude spectrum of the first fast record's residual (frequency Hz,
    /// root-mean-square amplitude V per bin), for the line test.
    pub welch: Vec<(f64, f64)>,
}

/// How near a fitted mode a line of the residual spectrum must sit, a share of the mode's
/// frequency ([`Signatures::line_ratio_near`]; our assumption: a mode's fit within 15 %).
pub const LINE_NEAR_SHARE: f64 = 0.15;

/// The window beyond a band within which [`Signatures::line_ratio_max`] looks for lines: wider
/// than [`LINE_NEAR_SHARE`], so that it holds every window of a mode in the band.
pub const LINE_BOUND_SHARE: f64 = 0.2;

/// Samples per Welch segment of the line test (our assumption: about 20 ms at 50 kHz, so a
/// mode damped by 0.02 at 3 kHz, whose line is 120 Hz wide, spans a few 49 Hz bins).
pub const WELCH_SEGMENT: usize = 1024;

/// What a record's held levels say of a loop ([`held_loop_v`]).
#[derive(Clone, Copy, Debug, PartialEq)]
enum HeldLoop {
    /// The gap between levels reached from below and from above, volts.
    Gap(f64),
    /// Too few holds, too few reached each way or at distinct levels: nothing to ask.
    TooFew,
    /// Enough holds, but the direction of the step into each follows from its level (the
    /// levels reached from below all at one end): no answer, loop or none.
    Untold,
}

/// The loop of a record's held levels ([`HeldLoop::TooFew`] with fewer than
/// [`HELD_LOOP_MIN_HOLDS`] holds of [`HELD_LOOP_MIN_S`] or more after a step
/// ([`Data::holds_of`]), or fewer than two reached each way): the residual's mean over each
/// hold's second half (settled), fitted by
/// least squares to a static quadratic in the input (a quartic from
/// [`HELD_LOOP_QUARTIC_LEVELS`] distinct levels) plus `g` times the direction of the step into
/// the hold (+1 up, -1 down); the loop is `2 |g|`, the gap between levels reached from below
/// and from above at equal input. The polynomial takes a scale, an offset or a curvature of the
/// static map, which do not depend on the direction.
fn held_loop_v(d: &Data, r: &[f64]) -> HeldLoop {
    held_loop_from(d, r, HELD_LOOP_QUARTIC_LEVELS)
}

/// [`held_loop_v`] with the quartic taken from `quartic_levels` distinct levels.
fn held_loop_from(d: &Data, r: &[f64], quartic_levels: usize) -> HeldLoop {
    let mut pts: Vec<(f64, f64, f64)> = Vec::new();
    for h in d.holds_of(HELD_LOOP_MIN_S) {
        let step = d.u_v[h.start] - d.u_v[h.start - 1];
        if h.len() >= 4 && step.abs() > d.hold_band_v {
            let half = h.start + h.len() / 2;
            pts.push((d.u_v[half], mean(&r[half..h.end]), step.signum()));
        }
    }
    let ups = pts.iter().filter(|p| p.2 > 0.0).count();
    if pts.len() < HELD_LOOP_MIN_HOLDS || ups < 2 || pts.len() - ups < 2 {
        return HeldLoop::TooFew;
    }
    // The direction's coefficient by its part the static polynomial does not explain (in the
    // standardised input, so that it is well conditioned): where a few levels are each reached
    // one way only (a square wave, a 0-5-10-0 cycle), the direction is a function of the
    // level, the loop cannot be told from a static shape, and there is no answer.
    let n = pts.len() as f64;
    let mu = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let sd = (pts.iter().map(|p| (p.0 - mu).powi(2)).sum::<f64>() / n).sqrt();
    if sd.is_nan() || sd <= 0.0 {
        return HeldLoop::TooFew;
    }
    let dir = DVector::from_iterator(pts.len(), pts.iter().map(|p| p.2));
    // Three distinct levels at least, or the quadratic is singular.
    let mut zs: Vec<f64> = pts.iter().map(|p| (p.0 - mu) / sd).collect();
    zs.sort_by(f64::total_cmp);
    let distinct = 1 + zs.windows(2).filter(|w| w[1] - w[0] > 0.01).count();
    if distinct < 3 {
        return HeldLoop::TooFew;
    }
    let ncol = if distinct >= quartic_levels { 5 } else { 3 };
    let x = DMatrix::from_fn(pts.len(), ncol, |i, j| {
        let z = (pts[i].0 - mu) / sd;
        z.powi(j as i32)
    });
    let Some(chol) = (x.transpose() * &x).cholesky() else {
        return HeldLoop::TooFew;
    };
    let c = chol.solve(&(x.transpose() * &dir));
    let e = &dir - &x * c;
    let ee = e.dot(&e);
    if ee < HELD_LOOP_MIN_DIR_SHARE * n {
        return HeldLoop::Untold;
    }
    let y = DVector::from_iterator(pts.len(), pts.iter().map(|p| p.1));
    let g = e.dot(&y) / ee;
    if g.is_finite() {
        HeldLoop::Gap(2.0 * g.abs())
    } else {
        HeldLoop::TooFew
    }
}

/// The signatures of the residuals `y - sims`.
#[allow(clippy::needless_range_loop)] // several arrays indexed together
pub fn compute(data: &[Data], sims: &[Vec<f64>], noise: &[f64]) -> Signatures {
    let mut s = Signatures {
        noise_v: (noise.iter().map(|x| x * x).sum::<f64>() / noise.len().max(1) as f64).sqrt(),
        u_span_v: (f64::INFINITY, f64::NEG_INFINITY),
        ..Default::default()
    };
    let mut edge_p = 0.0;
    let mut all_p = 0.0;
    // Sums of the residual's line against the simulated output (records weigh equally).
    let (mut s1, mut sx, mut sxx, mut sr, mut sxr) = (0.0, 0.0, 0.0, 0.0, 0.0);
    // Sums over the records' first rest at 0 V: residual, samples, noise variance.
    let (mut rest_sum, mut rest_y, mut rest_n, mut rest_var) = (0.0, 0.0, 0usize, 0.0);
    for (k, (d, y)) in data.iter().zip(sims).enumerate() {
        let r: Vec<f64> = d.y_v.iter().zip(y).map(|(a, b)| a - b).collect();
        // Until the input first leaves 0 V (the output cannot move before it), if that is
        // long enough to be a rest.
        if let Some(end) = d.zero_rest_len().map(|e| e.min(r.len())) {
            rest_sum += r[..end].iter().sum::<f64>();
            rest_y += d.y_v[..end].iter().sum::<f64>();
            rest_n += end;
            rest_var += end as f64 * noise.get(k).map_or(0.0, |s| s * s);
        }
        let w = 1.0 / d.len().max(1) as f64;
        for (x, e) in y.iter().zip(&r) {
            s1 += w;
            sx += w * x;
            sxx += w * x * x;
            sr += w * e;
            sxr += w * x * e;
        }
        let (lo, hi) = super::min_max(&d.u_v);
        s.u_span_v = (s.u_span_v.0.min(lo), s.u_span_v.1.max(hi));
        let t = d.period_s();
        let n = d.len();
        if d.is_fast() {
            let win = (3e-3 / t).ceil() as usize;
            let mut since = usize::MAX;
            for i in 0..n {
                if d.is_jump(i) {
                    since = 0;
                } else {
                    since = since.saturating_add(1);
                }
                let p = r[i] * r[i];
                all_p += p;
                if since <= win {
                    edge_p += p;
                }
            }
            if s.spectrum.is_empty() {
                s.spectrum = spectrum(&r, t);
                s.welch = welch(&r, t);
                s.peak_hz = strongest_line_hz(&s.welch);
            }
        }
        // Holds: the tail after each step's transient.
        for h in d.holds() {
            s.holds += 1;
            let len = h.len();
            let skip = ((0.02 / t).ceil() as usize).min(len / 4);
            let w = ((len - skip) / 10).max(1);
            let a = mean(&r[h.start + skip..h.start + skip + w]);
            let b = mean(&r[h.end - w..h.end]);
            s.tail_v = s.tail_v.max((b - a).abs());
        }
        // Loop and curve, on slowly moving input (no jumps).
        let bins = 20;
        let mut up = vec![(0.0, 0usize); bins];
        let mut down = vec![(0.0, 0usize); bins];
        let span = (hi - lo).max(1e-9);
        let mut xs = Vec::new();
        for i in 1..n {
            let du = d.u_v[i] - d.u_v[i - 1];
            if d.is_jump(i) || du == 0.0 {
                continue;
            }
            let b = (((d.u_v[i] - lo) / span * bins as f64) as usize).min(bins - 1);
            let slot = if du > 0.0 { &mut up[b] } else { &mut down[b] };
            slot.0 += r[i];
            slot.1 += 1;
            xs.push((d.u_v[i], r[i]));
        }
        let mut moving_loop = false;
        for b in 0..bins {
            if up[b].1 >= 20 && down[b].1 >= 20 {
                let gap = up[b].0 / up[b].1 as f64 - down[b].0 / down[b].1 as f64;
                s.loop_v = s.loop_v.max(gap.abs());
                moving_loop = true;
            }
        }
        // A record of steps alone (random levels) never moves slowly: its loop shows in the
        // held levels instead, a level reached from below sitting apart from one reached
        // from above.
        if moving_loop {
            s.loop_answered = true;
        } else {
            match held_loop_v(d, &r) {
                HeldLoop::Gap(gap) => {
                    s.held_loop_v = s.held_loop_v.max(gap);
                    s.loop_answered = true;
                }
                HeldLoop::Untold => s.held_loop_untold = true,
                HeldLoop::TooFew => {}
            }
        }
        if xs.len() >= 50 {
            s.curve_v = s.curve_v.max(curvature(&xs, lo, hi));
        }
    }
    s.edge_share = if all_p > 0.0 { edge_p / all_p } else { 0.0 };
    let det = s1 * sxx - sx * sx;
    if det.abs() > 1e-12 * (s1 * sxx).max(1e-300) {
        s.scale = (s1 * sxr - sx * sr) / det;
        s.level_v = (sr - s.scale * sx) / s1;
    }
    if rest_n > 0 {
        let n = rest_n as f64;
        s.rest_zero_v = Some((rest_sum / n, rest_y / n, rest_var.sqrt() / n));
    }
    s
}

/// Does `level` show at least `share` of `of`, on its side of zero? (The offset's tests: a
/// residual's level against a fitted constant, a fitted constant against a reading.)
pub(super) fn shows_share(level: f64, of: f64, share: f64) -> bool {
    level * of > 0.0 && level.abs() >= share * of.abs()
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Largest deviation of a quadratic least-squares fit of `r` against `u` from its chord.
fn curvature(xs: &[(f64, f64)], lo: f64, hi: f64) -> f64 {
    // Normal equations for r = a + b u + c u^2 (u centred and scaled).
    let m = 0.5 * (lo + hi);
    let h = (0.5 * (hi - lo)).max(1e-9);
    let mut g = [[0.0f64; 3]; 3];
    let mut v = [0.0f64; 3];
    for &(u, r) in xs {
        let x = (u - m) / h;
        let row = [1.0, x, x * x];
        for i in 0..3 {
            v[i] += row[i] * r;
            for j in 0..3 {
                g[i][j] += row[i] * row[j];
            }
        }
    }
    let a = nalgebra::Matrix3::from_fn(|i, j| g[i][j]);
    let b = nalgebra::Vector3::from_fn(|i, _| v[i]);
    match a.lu().solve(&b) {
        // The quadratic term's largest deviation from the chord over x in [-1, 1] is |c|.
        Some(c) => c[2].abs(),
        None => 0.0,
    }
}

/// One Hann-windowed amplitude spectrum of `r` (up to 2^16 samples), for plots: the Welch
/// routine with a single segment.
fn spectrum(r: &[f64], t: f64) -> Vec<(f64, f64)> {
    averaged_spectrum(&r[..r.len().min(1 << 16)], t, usize::MAX)
}

/// Welch-averaged amplitude spectrum of `r` for the line test: [`WELCH_SEGMENT`] samples per
/// segment.
fn welch(r: &[f64], t: f64) -> Vec<(f64, f64)> {
    averaged_spectrum(r, t, WELCH_SEGMENT)
}

/// Amplitude spectrum of `r` (sampling period `t` s) averaged over Hann segments of `seg`
/// samples (or the whole record if shorter), half overlap, mean removed per segment, power
/// averaged, square root taken: `4 |X| / n` per bin for one segment.
pub(crate) fn averaged_spectrum(r: &[f64], t: f64, seg: usize) -> Vec<(f64, f64)> {
    let seg = seg.min(r.len());
    if seg < 64 {
        return vec![];
    }
    let fft = FftPlanner::new().plan_fft_forward(seg);
    let win: Vec<f64> = (0..seg)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / seg as f64).cos())
        .collect();
    let mut power = vec![0.0; seg / 2];
    let mut count = 0usize;
    let mut start = 0;
    while start + seg <= r.len() {
        let x = &r[start..start + seg];
        let m = mean(x);
        let mut buf: Vec<Complex<f64>> = x
            .iter()
            .zip(&win)
            .map(|(v, w)| Complex::new((v - m) * w, 0.0))
            .collect();
        fft.process(&mut buf);
        for (p, b) in power.iter_mut().zip(&buf) {
            *p += b.norm_sqr();
        }
        count += 1;
        start += seg / 2;
    }
    let df = 1.0 / (seg as f64 * t);
    (1..seg / 2)
        .map(|k| {
            let a = 4.0 * (power[k] / count.max(1) as f64).sqrt() / seg as f64;
            (k as f64 * df, a)
        })
        .collect()
}

/// The peak bin `k` of the power spectrum `p` refined between bins: the vertex of a parabola
/// through the log powers of `k` and its neighbours (a Hann window's line is close to a
/// Gaussian in log power, so the refined centre is within a small part of a bin), at most half
/// a bin off `k`; `k` itself at the spectrum's ends or where the three do not peak.
pub(crate) fn refined_peak(p: &[f64], k: usize) -> f64 {
    if k == 0 || k + 1 >= p.len() {
        return k as f64;
    }
    let l = |j: usize| p[j].max(1e-300).ln();
    let (a, b, c) = (l(k - 1), l(k), l(k + 1));
    let den = a - 2.0 * b + c;
    if den < 0.0 {
        k as f64 + (0.5 * (a - c) / den).clamp(-0.5, 0.5)
    } else {
        k as f64
    }
}

/// Median level of `spec` above 500 Hz (the reference of the line test).
fn median_above_500(spec: &[(f64, f64)]) -> f64 {
    let mut mags: Vec<f64> = spec
        .iter()
        .filter(|(f, _)| *f >= 500.0)
        .map(|x| x.1)
        .collect();
    crate::util::median(&mut mags).max(1e-15)
}

/// The frequency of the strongest line of `spec` above 500 Hz (0 if none); its height is
/// [`Signatures::line_ratio_near`].
fn strongest_line_hz(spec: &[(f64, f64)]) -> f64 {
    spec.iter()
        .filter(|(f, _)| *f >= 500.0)
        .fold((0.0, 0.0), |acc, x| if x.1 > acc.1 { *x } else { acc })
        .0
}

impl Signatures {
    /// Height of the Welch-averaged residual spectrum near `f_hz` (within [`LINE_NEAR_SHARE`]) over its
    /// median level above 500 Hz: is there a line where a fitted mode sits?
    pub fn line_ratio_near(&self, f_hz: f64) -> f64 {
        self.line_ratio_where(|f| (f / f_hz - 1.0).abs() <= LINE_NEAR_SHARE)
    }

    /// The largest [`Self::line_ratio_near`] that a mode anywhere from `lo_hz` to `hi_hz`
    /// could find: the highest bin within [`LINE_BOUND_SHARE`] of that band (a superset of
    /// every such mode's window, a mode a hair outside the band by rounding included) over
    /// the median.
    pub fn line_ratio_max(&self, lo_hz: f64, hi_hz: f64) -> f64 {
        self.line_ratio_where(|f| {
            f >= (1.0 - LINE_BOUND_SHARE) * lo_hz && f <= (1.0 + LINE_BOUND_SHARE) * hi_hz
        })
    }

    /// The highest bin of the Welch-averaged residual spectrum at the frequencies `keep`
    /// admits over its median level above 500 Hz.
    fn line_ratio_where(&self, keep: impl Fn(f64) -> bool) -> f64 {
        let near = self
            .welch
            .iter()
            .filter(|(f, _)| keep(*f))
            .map(|x| x.1)
            .fold(0.0f64, f64::max);
        near / median_above_500(&self.welch)
    }

    /// Why no fit of the fast `effect` could pass [`Self::supports`] on this residual, or
    /// `None` where one could. Where none could, its search (over a hundred simulations of the
    /// fast records for a second mode) is left out, and the diagnosis is the same: a second
    /// mode needs a line of the residual spectrum near it within the catalogue's band
    /// ([`Self::line_ratio_max`]); saturation needs an input near the amplifier's limits,
    /// which no fit changes. A ratio that is not a number is no proof: the search runs.
    pub fn search_left_out(&self, effect: &str) -> Option<&'static str> {
        match effect {
            "resonance" => catalogue::fast_spec(effect).and_then(|s| {
                let r = self.line_ratio_max(s.lo, s.hi);
                (r < LINE_RATIO_MIN).then_some(
                    "no line in the residual spectrum where a mode of the catalogue's band could sit",
                )
            }),
            "saturation" => (!self.input_near_limits())
                .then_some("the input stays away from the amplifier's limits"),
            _ => None,
        }
    }

    /// Does some record's input come within 0.5 V of the amplifier's input limits (where a
    /// saturation can show)?
    fn input_near_limits(&self) -> bool {
        near_amp_limits(self.u_span_v)
    }

    /// Does the residual show the signature of `effect` as `model` has it? (The gate of the
    /// selection; the final check asks it of the residual without the effect.) A second mode
    /// must be lightly damped and sit on a line of the residual spectrum (within 15 %,
    /// [`LINE_RATIO_MIN`] x the median); saturation needs an input near the amplifier's
    /// limits.
    pub fn supports(&self, effect: &str, model: &ModelFile) -> bool {
        match effect {
            "saturation" => self.input_near_limits(),
            // The table's reversible slopes can take any scale or curvature too: hysteresis is
            // named only where the residual shows a loop.
            // Held levels that sit apart by the direction of the step into them are a loop
            // only where the holds are flat: a creep that has not caught up after a step
            // leaves the same pattern, with a tail (families 1073, 1087, 1096: creep on
            // random levels took a false `hysteresis` from the held levels' gap alone).
            // Where the model has a drift, the tails are its part (refitted with the table),
            // and the held levels' gap is judged alone: a stage that creeps and has a loop
            // (every piezo stage; the full thesis stage on random levels) shows both, and
            // the loop was never admitted (41-55x the floor, `drift` alone).
            // Where the held levels cannot tell a loop from a static shape (the levels
            // reached from below all at one end) and no record answered otherwise, they are
            // no evidence either way: beside a drift the loop is then left to the fit (the
            // full thesis stage on random levels whose three rises all went above 8 V named
            // an `offset` of 1.37 V alone at 63x the floor, while the table explained 99.9 %
            // of what a drift left).
            "hysteresis" => {
                self.loop_v >= HYST_LOOP_MIN_NOISE * self.noise_v
                    || (self.held_loop_v >= HYST_LOOP_MIN_NOISE * self.noise_v
                        && (self.tail_v < DRIFT_TAIL_MIN_NOISE * self.noise_v
                            || catalogue::present(model, "drift")))
                    || (self.held_loop_untold
                        && !self.loop_answered
                        && catalogue::present(model, "drift"))
            }
            // Holds that show no tail show no creep (without holds the selection's give-way
            // rule asks the static shapes instead).
            "drift" => self.holds == 0 || self.tail_v >= DRIFT_TAIL_MIN_NOISE * self.noise_v,
            "resonance" => catalogue::fast_value(model, "resonance").is_some_and(|(f, z)| {
                z <= MAX_MODE_DAMPING && self.line_ratio_near(f) >= LINE_RATIO_MIN
            }),
            _ => true,
        }
    }

    /// Does this residual, of a model without `model`'s fitted offset, show that offset? Its
    /// least-squares line against the simulated output must sit, at zero output, on the
    /// constant's side of zero and at least [`OFFSET_SHOWN_MIN`] of its value away, or its
    /// mean over the records' rest at 0 V input must show [`REST_ZERO_SHOWN_MIN`] of it
    /// there, [`REST_ZERO_SIGMAS`] standard errors clear of zero (at 0 V no other effect
    /// predicts any output, so the refit of the others cannot take a sensor offset up
    /// there): a constant the residual shows in neither worked through the refit of the
    /// other effects.
    pub fn shows_offset(&self, model: &ModelFile) -> bool {
        let fitted_v = model.offset.as_ref().map_or(0.0, |o| o.offset_v);
        shows_share(self.level_v, fitted_v, OFFSET_SHOWN_MIN) || self.shows_offset_at_rest(model)
    }

    /// Does this residual, of a model without `model`'s fitted offset, show that offset over
    /// the records' rest at 0 V input, and does the sensor read it there? Both the residual's
    /// mean and the measured output's mean there must sit on the constant's side of zero, at
    /// least [`REST_ZERO_SHOWN_MIN`] of its value and [`REST_ZERO_SIGMAS`] standard errors
    /// away (`false` where no record starts at rest at 0 V). The measured mean keeps a
    /// constant that only corrects the model's own prediction at rest (a table whose range
    /// reaches below 0 V holds a constant there) from passing for the sensor's zero.
    pub fn shows_offset_at_rest(&self, model: &ModelFile) -> bool {
        let fitted_v = model.offset.as_ref().map_or(0.0, |o| o.offset_v);
        let shows = |level_v: f64, se_v: f64| {
            shows_share(level_v, fitted_v, REST_ZERO_SHOWN_MIN)
                && level_v.abs() >= REST_ZERO_SIGMAS * se_v
        };
        self.rest_zero_v
            .is_some_and(|(level_v, y_v, se_v)| shows(level_v, se_v) && shows(y_v, se_v))
    }

    /// The evidence for `effect` (as `model` has it) in words.
    pub fn describe(&self, effect: &str, model: &ModelFile) -> String {
        let mv = |v: f64| format!("{:.1} mV", 1e3 * v);
        match effect {
            "time-delay" | "amplifier-pole" | "slew-rate-limit" => format!(
                "{:.0} % of the fast residual power within 3 ms after edges",
                100.0 * self.edge_share
            ),
            "resonance" => {
                // The line at the fitted mode, else the strongest one.
                let f = catalogue::fast_value(model, "resonance").map_or(self.peak_hz, |m| m.0);
                format!(
                    "residual line at {:.0} Hz, {:.1}x the median spectral level",
                    f,
                    self.line_ratio_near(f)
                )
            }
            "drift" if self.holds == 0 => {
                "no hold in the records to show tails: the lags follow a slow residual under the moving input"
                    .to_string()
            }
            "drift" => format!("tails after steps up to {} during holds", mv(self.tail_v)),
            "hysteresis" if self.held_loop_v > self.loop_v => format!(
                "held levels reached from below and from above differ by {} at equal input",
                mv(self.held_loop_v)
            ),
            "hysteresis" => format!(
                "residual differs by up to {} between rising and falling input",
                mv(self.loop_v)
            ),
            "nonlinear-gain" => format!(
                "static residual curves by {} against the input",
                mv(self.curve_v)
            ),
            "saturation" => format!(
                "input spans {:.2}..{:.2} V, near the amplifier's limits",
                self.u_span_v.0, self.u_span_v.1
            ),
            "offset" => format!(
                "the residual's line against the simulated output sits {} off zero",
                mv(self.level_v)
            ),
            "sensor-gain" => format!(
                "the residual grows with the simulated output, {:+.2} % of it",
                100.0 * self.scale
            ),
            _ => String::new(),
        }
    }
}

/// Does an input spanning `lo..hi` volts come within 0.5 V of the amplifier's input limits
/// (where a saturation of the amplifier can show; our assumption: the E-505's output limits
/// reached within half a volt of input, its gain 10)?
pub fn near_amp_limits((lo, hi): (f64, f64)) -> bool {
    lo <= params::AMP_INPUT_MIN_V + 0.5 || hi >= params::AMP_INPUT_MAX_V - 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::csv::Record;

    /// A record of steps at 1 kHz, each level held 50 ms, and a residual that is a static
    /// quadratic of the input plus `g` times the direction of the step into the level.
    fn steps(levels: &[f64], g: f64) -> (Data, Vec<f64>) {
        steps_beside(levels, g, |u| 0.01 + 0.003 * u - 0.002 * u * u)
    }

    /// [`steps`] with the static residual `stat(u)` in place of the quadratic.
    fn steps_beside(levels: &[f64], g: f64, stat: impl Fn(f64) -> f64) -> (Data, Vec<f64>) {
        let per = 50;
        let n = per * levels.len();
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 1e-3).collect();
        let u: Vec<f64> = (0..n).map(|i| levels[i / per]).collect();
        let r: Vec<f64> = (0..n)
            .map(|i| {
                let k = i / per;
                let dir = if k == 0 {
                    0.0
                } else {
                    (levels[k] - levels[k - 1]).signum()
                };
                stat(u[i]) + g * dir
            })
            .collect();
        let d = Data::from_record(
            "steps.csv",
            Record::new(t, u.clone(), Some(u), None).unwrap(),
        )
        .unwrap();
        (d, r)
    }

    /// The rest at 0 V shows an offset where the sensor reads it there and the model without
    /// it leaves half of it or more there, and not where either sits at zero or below half:
    /// a record that starts at rest at 0 V for 100 samples, then steps to 5 V, measured with
    /// a 20 mV offset (or without) and a model that predicts nothing, 6 mV (0.7 of it left),
    /// 12 mV (0.4 left) or all of it at rest; and a noise level whose standard error puts the
    /// reading within 3 of them. The means are exact (no noise in the records), so the cuts
    /// at 0.5 and at 3 standard errors cannot be missed by rounding.
    #[test]
    fn the_rest_at_zero_volts_shows_a_sensor_offset_only() {
        let n = 400;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 1e-3).collect();
        let u: Vec<f64> = (0..n).map(|i| if i < 100 { 0.0 } else { 5.0 }).collect();
        let record = |offset_v: f64| {
            let y: Vec<f64> = u.iter().map(|x| x + offset_v).collect();
            Data::from_record(
                "rest.csv",
                Record::new(t.clone(), u.clone(), Some(y), None).unwrap(),
            )
            .unwrap()
        };
        let mut model = ModelFile::built_in("thesis-linear").unwrap();
        model.offset = Some(crate::io::model_file::OffsetSection { offset_v: 0.02 });
        // The model without the offset predicts the input alone.
        let plain: Vec<f64> = u.clone();
        // ... or carries the constant at rest itself (a table's own constant below 0 V).
        let at_rest: Vec<f64> = u.iter().map(|x| x + 0.02).collect();
        let sigs =
            |offset_v: f64, sim: &[f64]| compute(&[record(offset_v)], &[sim.to_vec()], &[1e-3]);
        let shown = sigs(0.02, &plain);
        let (level_v, y_v, se_v) = shown.rest_zero_v.unwrap();
        assert!(
            (level_v - 0.02).abs() < 1e-12 && (y_v - 0.02).abs() < 1e-12,
            "{level_v} {y_v}"
        );
        assert!((se_v - 1e-4).abs() < 1e-12, "{se_v}");
        assert!(shown.shows_offset_at_rest(&model));
        // The sensor reads zero at rest: the constant is not the sensor's.
        assert!(!sigs(0.0, &plain).shows_offset_at_rest(&model));
        // The model without the offset already predicts the reading at rest.
        assert!(!sigs(0.02, &at_rest).shows_offset_at_rest(&model));
        // The other sign of zero.
        assert!(!sigs(-0.02, &plain).shows_offset_at_rest(&model));
        // The model predicts part of the reading: 0.7 of it left shows, 0.4 does not.
        let part = |v: f64| -> Vec<f64> {
            u.iter()
                .enumerate()
                .map(|(i, x)| x + if i < 100 { v } else { 0.0 })
                .collect()
        };
        assert!(sigs(0.02, &part(0.006)).shows_offset_at_rest(&model));
        assert!(!sigs(0.02, &part(0.012)).shows_offset_at_rest(&model));
        // A noise of 0.1 V: the mean's standard error is 10 mV, the reading within 3 of it.
        let noisy = compute(&[record(0.02)], std::slice::from_ref(&plain), &[0.1]);
        assert!((noisy.rest_zero_v.unwrap().2 - 0.01).abs() < 1e-12);
        assert!(!noisy.shows_offset_at_rest(&model));
        // A rest shorter than REST_ZERO_MIN_S (1 ms at 1 kHz) is none.
        let brief: Vec<f64> = (0..n).map(|i| if i < 1 { 0.0 } else { 5.0 }).collect();
        let d = Data::from_record(
            "brief.csv",
            Record::new(t.clone(), brief.clone(), Some(brief.clone()), None).unwrap(),
        )
        .unwrap();
        assert!(compute(&[d], &[brief], &[1e-3]).rest_zero_v.is_none());
        // A record that does not start at 0 V has no rest at 0 V.
        let lifted: Vec<f64> = u.iter().map(|x| x + 1.0).collect();
        let d = Data::from_record(
            "lifted.csv",
            Record::new(t.clone(), lifted.clone(), Some(lifted.clone()), None).unwrap(),
        )
        .unwrap();
        assert!(compute(&[d], &[lifted], &[1e-3]).rest_zero_v.is_none());
    }

    /// A fast effect's search is left out only where no fit of it could pass the gate: the
    /// bound of a second mode's line ratio is at least `line_ratio_near` at every frequency
    /// of the catalogue's band (and a hair beyond, where a search's bounds round), so it
    /// falls below LINE_RATIO_MIN only where every mode would fail. A line at 4 kHz lifts
    /// it, and so do lines just outside the band (880 Hz, 22.5 kHz) that a mode at its edge
    /// sees within its 15 % window: a bound over the band alone would miss those (asserted,
    /// so that the margin cannot be cut). Records: 1 s at 50 kHz of a 1 Hz sine over 1-9 V
    /// (away from the amplifier's limits, which the saturation's gate asks of the input
    /// alone, and up to 11.8 V), its residual pseudo-random noise of 1 mV with or without a
    /// 2 mV line.
    #[test]
    fn a_fast_search_is_left_out_only_where_its_gate_cannot_pass() {
        let rate = 50e3;
        let n = 50_000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / rate).collect();
        let sine = |hi: f64| -> Vec<f64> {
            t.iter()
                .map(|&x| 1.0 + 0.5 * (hi - 1.0) * (1.0 - (std::f64::consts::TAU * x).cos()))
                .collect()
        };
        // (a linear congruential generator: the same noise on every run)
        let mut state = 12345u64;
        let noise: Vec<f64> = (0..n)
            .map(|_| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                1e-3 * (((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5) * 12f64.sqrt()
            })
            .collect();
        let sigs_of = |u: &[f64], line_v: f64, line_hz: f64| {
            let y: Vec<f64> = (0..n)
                .map(|i| u[i] + noise[i] + line_v * (std::f64::consts::TAU * line_hz * t[i]).sin())
                .collect();
            let d = Data::from_record(
                "fast.csv",
                Record::new(t.clone(), u.to_vec(), Some(y), None).unwrap(),
            )
            .unwrap();
            assert!(d.is_fast());
            compute(&[d], &[u.to_vec()], &[1e-3])
        };
        let model = ModelFile::built_in("thesis-linear").unwrap();
        let spec = catalogue::fast_spec("resonance").unwrap();
        let u = sine(9.0);
        // (line volts and hertz, the mode fitted on it, whether it is outside the band)
        let cases = [
            (0.0, 4e3, None, false),
            (2e-3, 4e3, Some(4e3), false),
            (2e-3, 880.0, Some(spec.lo), true),
            (2e-3, 22.5e3, Some(spec.hi), true),
        ];
        for (line_v, line_hz, mode_hz, outside) in cases {
            let s = sigs_of(&u, line_v, line_hz);
            let bound = s.line_ratio_max(spec.lo, spec.hi);
            let steps = 2000;
            for k in 0..=steps {
                let f = spec.lo * (spec.hi / spec.lo).powf(k as f64 / steps as f64);
                for f in [f * (1.0 - 1e-9), f, f * (1.0 + 1e-9)] {
                    assert!(s.line_ratio_near(f) <= bound, "{f} Hz: {bound}");
                }
            }
            let searched = mode_hz.is_some();
            assert_eq!(
                s.search_left_out("resonance").is_none(),
                searched,
                "line {line_v} V at {line_hz} Hz: {bound}"
            );
            assert_eq!(bound >= LINE_RATIO_MIN, searched, "{bound}");
            // A mode fitted on that line passes the gate.
            if let Some(f) = mode_hz {
                let m = catalogue::with_fast(&model, "resonance", f, 0.02);
                assert!(s.supports("resonance", &m), "{line_hz} Hz");
            }
            // (the band's bins alone: below the gate's ratio for a line outside it)
            if outside {
                let band = (
                    spec.lo / (1.0 - LINE_BOUND_SHARE),
                    spec.hi / (1.0 + LINE_BOUND_SHARE),
                );
                assert!(s.line_ratio_max(band.0, band.1) < LINE_RATIO_MIN);
            }
        }
        let s = sigs_of(&u, 0.0, 4e3);
        assert!(s.search_left_out("saturation").is_some());
        let m = catalogue::with_fast(&model, "saturation", 95.0, 0.0);
        assert!(!s.supports("saturation", &m));
        let near = sigs_of(&sine(11.8), 0.0, 4e3);
        assert!(near.search_left_out("saturation").is_none());
        assert!(near.supports("saturation", &m));
        for e in ["time-delay", "amplifier-pole", "slew-rate-limit"] {
            assert!(s.search_left_out(e).is_none(), "{e}");
        }
    }

    /// The held levels' loop finds the direction's gap (2 g) beside a static quadratic, finds
    /// none where the levels depend on the input alone, and declines with too few holds,
    /// holds reached one way only, or levels whose direction follows from the level (a
    /// square wave, a repeated 0-5-10-0 cycle). Tolerance: the fit is exact for these
    /// residuals, so 1e-9 V.
    #[test]
    fn held_levels_show_a_loop_of_steps_alone() {
        let levels = [2.0, 5.0, 3.0, 7.0, 4.0, 8.0, 1.0, 6.0];
        let (d, r) = steps(&levels, 0.02);
        let gap = |h: HeldLoop| match h {
            HeldLoop::Gap(g) => g,
            other => panic!("{other:?}"),
        };
        let g = gap(held_loop_v(&d, &r));
        assert!((g - 0.04).abs() < 1e-9, "gap {g}");
        let (d, r) = steps(&levels, 0.0);
        let g = gap(held_loop_v(&d, &r));
        assert!(g < 1e-9, "gap {g}");
        let (d, r) = steps(&levels[..4], 0.02);
        assert_eq!(held_loop_v(&d, &r), HeldLoop::TooFew, "three steps");
        let (d, r) = steps(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0], 0.02);
        assert_eq!(held_loop_v(&d, &r), HeldLoop::TooFew, "rising only");
        // Two levels each reached one way only: too few distinct levels to ask.
        let (d, r) = steps(&[2.3, 7.1, 2.3, 7.1, 2.3, 7.1, 2.3, 7.1], 0.0);
        assert_eq!(held_loop_v(&d, &r), HeldLoop::TooFew, "square wave");
        // Three levels, each reached one way only: the direction follows from the level.
        let (d, r) = steps(&[0.0, 5.0, 10.0, 0.0, 5.0, 10.0, 0.0, 5.0, 10.0], 0.0);
        assert_eq!(held_loop_v(&d, &r), HeldLoop::Untold, "0-5-10-0 cycle");
    }

    /// On 18 random levels, a static misfit of higher order than a quadratic (a tanh step of
    /// +-30 mV, 1.5 V wide at 2.5 V, what the catalogue's K'(u) leaves of a sharper gain
    /// curve) is no loop: the quartic the levels' count allows takes it to under 1 mV, where
    /// the quadratic read a gap of 3 mV or more from it (the hysteresis gate at a 1 mV floor);
    /// a true gap of 6 mV beside it is found within 1 mV. (Levels drawn once; offline, the
    /// quadratic reads 5.5 mV here, the quartic 0.03 mV, and 5.97 mV of the true 6.) Fourteen
    /// levels each reached one way only give no answer on the quartic's path either.
    #[test]
    fn a_static_shape_of_higher_order_on_many_levels_is_no_loop() {
        let levels = [
            5.0, 7.1, 1.6, 9.4, 3.8, 6.7, 4.8, 6.1, 4.0, 3.2, 1.5, 4.7, 2.2, 9.3, 5.9, 6.4, 3.9,
            6.7, 1.7,
        ];
        let tanh = |u: f64| 0.03 * ((u - 2.5) / 1.5).tanh();
        let gap = |h: HeldLoop| match h {
            HeldLoop::Gap(g) => g,
            other => panic!("{other:?}"),
        };
        let (d, r) = steps_beside(&levels, 0.0, tanh);
        let g0 = gap(held_loop_v(&d, &r));
        let quadratic = gap(held_loop_from(&d, &r, usize::MAX));
        println!(
            "tanh alone: gap {:.3} mV (a quadratic's {:.3} mV)",
            1e3 * g0,
            1e3 * quadratic
        );
        assert!(g0 < 1e-3, "gap {g0} V from a static shape");
        assert!(quadratic >= 3e-3, "the quadratic's gap {quadratic} V");
        let (d, r) = steps_beside(&levels, 0.003, tanh);
        let g = gap(held_loop_v(&d, &r));
        assert!((g - 0.006).abs() < 1e-3, "gap {g} V against 6 mV");
        // Fourteen levels, the high ones all reached from below and the low ones from above:
        // the direction follows from the level, on the quartic's path as on the quadratic's.
        let mut one_way = vec![5.0];
        for k in 0..7 {
            one_way.extend([6.0 + 0.5 * k as f64, 0.5 + 0.5 * k as f64]);
        }
        let (d, r) = steps_beside(&one_way, 0.003, tanh);
        assert_eq!(
            held_loop_v(&d, &r),
            HeldLoop::Untold,
            "levels reached one way"
        );
    }
}
