//! The filter sections the controller's filters are built from: first- and second-order
//! sections, discretised by Tustin and run in a delta form that stays accurate when a pole or
//! a zero sits near z = 1. The lag compensator ([`crate::lag`]) and the pre-filter
//! ([`crate::prefilter`]) filter with these and nothing else; neither keeps a private copy.
//!
//! # The problem: poles and zeros near z = 1
//! At 50 kHz the lag compensator's pole (0.398 rad/s) maps to z = 1 - 7.96e-6, its zero
//! (1 rad/s) to 1 - 2e-5, and the drift's slowest lag (12 s) to z = 1 - 1.7e-6. In a direct
//! form `y = a y + b x` with `a` rounded to `f32` (spacing 6e-8 near 1), `1 - a` is off by up
//! to 0.75 % for the lag and 3.5 % for the drift: the pole moves, and with it the corner and
//! the DC gain. A zero near 1 written as `b0 x[n] + b1 x[n-1]` with `b1 ~ -b0` loses its
//! distance from 1 the same way. And the state, large compared with its per-step change, loses
//! the low bits of every increment.
//!
//! # The form: Tustin, then sums and differences
//! A section is `N(s)/D(s)` of order one or two, mapped by Tustin's `s = k (z - 1)/(z + 1)`,
//! `k = 2/T`. Multiplied through by `(z + 1)^n`, the difference equation is written in the
//! differences and sums of the input, and the output is advanced by an increment
//! (delta form). First order, `(c1 s + c0)/(d1 s + d0)`, `D = k d1 + d0`:
//!
//! ```text
//! y[n] = y[n-1] + bd (x[n] - x[n-1]) + bs (x[n] + x[n-1]) - alpha y[n-1]
//! bd = k c1 / D,   bs = c0 / D,   alpha = 2 d0 / D                        (alpha = 1 - a)
//! ```
//!
//! Second order, `(c2 s^2 + c1 s + c0)/(d2 s^2 + d1 s + d0)`, `D = k^2 d2 + k d1 + d0`, with
//! `dx = x[n] - x[n-1]`, `dx1 = x[n-1] - x[n-2]`:
//!
//! ```text
//! dy[n] = dy[n-1] + b0 (dx - dx1) + b1 (dx + dx1) + b2 (x[n] + 2 x[n-1] + x[n-2])
//!                 - alpha y[n-1] - beta dy[n-1]
//! y[n]  = y[n-1] + dy[n]
//! b0 = k^2 c2 / D,  b1 = k c1 / D,  b2 = c0 / D,  alpha = 4 d0 / D,  beta = 2 k d1 / D
//! ```
//!
//! `dy` is the last increment: `1 - beta` of it carries over to the next sample, and `alpha`
//! pulls the output towards the input's level (the two states of the delta operator: the
//! output and `T` times its rate). With both poles near 1, `alpha` and `beta` are both small
//! and both exact, where a direct form would round `a1 ~ -2` and `a2 ~ 1`.
//!
//! Every coefficient is a ratio of the continuous coefficients, computed in `f64` and rounded
//! once, so each carries full `f32` relative precision at any sampling rate:
//!
//! * a pole near 1 is `alpha` (and `beta`), its distance from 1, not `a` itself;
//! * a zero at z = 1 (the inverse of an integrator) is `bs = 0` or `b2 = 0` exactly; a zero
//!   near 1 is the ratio of `bd` and `bs`, each exact;
//! * an integrator (`d0 = 0`) is `alpha = 0` exactly: the trapezoid rule;
//! * the DC gain is `2 bs / alpha` (`4 b2 / alpha`), the continuous `c0 / d0` to `f32`
//!   rounding, and a state can be settled at rest exactly.
//!
//! # Storage: compensated where a pole sits near 1
//! The output (for the second order, the output and its increment: near 1 both change by
//! a tiny fraction of themselves per step, and a rounded `beta dy` moves the poles as surely
//! as a rounded `a`) is kept in a [`Store`]: a plain `f32`, or an [`Accumulator`] (Kahan's
//! compensated sum: `hi + lo`, the rounding error of each addition carried to the next), whose
//! error after n steps stays near one `f32` ulp of the state instead of growing like n ulps.
//! The user of a section picks the store per section: compensated where the pole is near 1
//! (the compensator's integrator and lag, the pre-filter's `S_hp`), plain elsewhere. Rust never
//! reassociates floating point, so the compensation is not optimised away.
//!
//! # What it trades
//! * Cost. First order: 3 multiplies and 5 additions, against 3 and 2 for a direct form; the
//!   second order: 5 multiplies and 13 additions, against 5 and 4 for direct form I. A
//!   compensated store adds 3 additions (the second order has two). Measured on the
//!   Cortex-M (`piezo qemu bench`): the pre-filter's step went from 159 to 170 instructions
//!   when its stage-mode section moved from an `f32` direct form I to this form; the
//!   compensator's from 105 to 108 (the integrator's zero-weight terms and second copy of
//!   the last error, less the hold check that went).
//! * Far from z = 1 the form buys little over a direct form (the pre-filter's planning
//!   poles and stage-mode section sit at z = 0.67); it is used there too so that one form,
//!   tested once against an `f64` direct form, serves every filter.
//! * Where a pole sits near 1 and the gain at high frequency is well above the DC gain (a
//!   slow high-pass or lead), the input's difference terms carry the signal and their
//!   rounding is summed through the slow pole. `S_hp` (gain 1 above 1 rad/s) keeps 1.3e-6 of
//!   its peak; a second-order section with both poles near 1 and a direct term keeps 17 %. Such
//!   a section must be run as its direct term plus a strictly proper remainder,
//!   `H = c2/d2 + R(s)` (Tustin maps the sum exactly): 1.8e-6. No section of this crate is of
//!   that kind, so the sections do not carry the split (it would cost every section a
//!   multiply and an add, and cancel at DC where a zero sits near 1, as in `S_lag`).
//! * Tustin warps frequency (`w_d = k tan(w T / 2)`); sections do not pre-warp. Each user
//!   says why the warp is negligible for it. Poles near z = -1 (corners near Nyquist) would
//!   need the mirror-image form; none of this project's filters has them.
//! * The state is the last input(s) and the output (and, second order, its increment): as
//!   many values as a direct form I, one or two more than a direct form II, in exchange for
//!   states that can be settled, reloaded and inspected (the compensator's anti-windup sets
//!   its states directly).
//!
//! # Measured (`sections::tests`, 200 000 steps at 50 kHz, two sines and a step)
//! Worst gap to Tustin's map run as an `f64` direct form, relative to the output's peak:
//!
//! ```text
//! section                                     compensated   plain f32   f32 direct form I
//! integrator Kc z / s                           5.2e-8        1.7e-5
//! lag Kc (p - z)/(s + p)                        7.1e-8        1.2e-5
//! S_hp s/(s + 1)                                1.3e-6        5.6e-6
//! planning 1/(tau s + 1)                        1.0e-7        1.6e-7
//! S_mode (double pole at z = 0.67)              1.0e-7        1.6e-7        8.0e-7
//! 1 kHz resonance, damping 0.1                  1.4e-7        3.3e-7        9.1e-6
//! slow low-pass 0.4/((s + 1)(s + 0.4))          2.0e-7        1.0e-5        0.96
//! (s + 2)(s + 3)/((s + 1)(s + 0.4)), whole      0.17                        0.34
//! the same as 1 + R(s)                          1.8e-6
//! ```
//!
//! # Configuration apart from state
//! [`FirstOrder`] and [`SecondOrder`] hold coefficients only (`Copy`, built at design time
//! from `f64`); [`FirstOrderState`] and [`SecondOrderState`] hold the history. One
//! configuration can drive many states, and a new one is swapped in whole.
//!
//! The drift's [`FirstOrderLag`] is the one section of another discretisation: it models a
//! continuous plant driven by the held DAC command, so it is the exact zero-order-hold
//! discretisation (delta form on an [`Accumulator`] as well).
//!
//! # Example
//! ```
//! use model_core::sections::{Accumulator, FirstOrder, FirstOrderState};
//! // The lag of the compensator, Kc (p - z) / (s + p), at 50 kHz, on a compensated store.
//! let lag = FirstOrder::tustin([0.0, 1e4 * (0.398 - 1.0)], [1.0, 0.398], 20e-6);
//! let mut s: FirstOrderState<Accumulator> = lag.settled(1e-3);
//! let y = lag.step(&mut s, 1e-3);
//! assert!((y - lag.dc_gain() * 1e-3).abs() < 1e-6);
//! ```

/// A running sum kept as `hi + lo`, with `lo` the rounding error of the last additions
/// (Kahan's compensated summation).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Accumulator {
    hi: f32,
    lo: f32,
}

impl Accumulator {
    /// An accumulator holding `value`.
    #[inline]
    pub const fn new(value: f32) -> Self {
        Self { hi: value, lo: 0.0 }
    }

    /// Add `x`, carrying the rounding error.
    #[inline]
    pub fn add(&mut self, x: f32) {
        let y = x - self.lo;
        let t = self.hi + y;
        self.lo = (t - self.hi) - y;
        self.hi = t;
    }

    /// The sum, rounded to `f32`.
    #[inline]
    pub fn value(&self) -> f32 {
        self.hi
    }

    /// Replace the sum.
    #[inline]
    pub fn set(&mut self, value: f32) {
        *self = Self::new(value);
    }

    /// The sum carried to `f64`: `hi` less the error `lo` it holds too much.
    pub fn exact(&self) -> f64 {
        self.hi as f64 - self.lo as f64
    }

    /// An accumulator holding `value` as nearly as `hi` and `lo` can (`hi` the nearest
    /// `f32`, `lo` what it holds too much).
    pub fn from_exact(value: f64) -> Self {
        let hi = value as f32;
        Self {
            hi,
            lo: (hi as f64 - value) as f32,
        }
    }
}

/// Where a section keeps its output: a plain `f32`, or an [`Accumulator`] where the pole sits
/// near z = 1 (see the module's notes).
pub trait Store: Copy + Default {
    /// A store holding `value`.
    fn holding(value: f32) -> Self;
    /// Add `delta` to the stored value.
    fn accumulate(&mut self, delta: f32);
    /// The stored value, rounded to `f32`.
    fn get(&self) -> f32;
}

impl Store for f32 {
    #[inline]
    fn holding(value: f32) -> Self {
        value
    }

    #[inline]
    fn accumulate(&mut self, delta: f32) {
        *self += delta;
    }

    #[inline]
    fn get(&self) -> f32 {
        *self
    }
}

impl Store for Accumulator {
    #[inline]
    fn holding(value: f32) -> Self {
        Self::new(value)
    }

    #[inline]
    fn accumulate(&mut self, delta: f32) {
        self.add(delta);
    }

    #[inline]
    fn get(&self) -> f32 {
        self.value()
    }
}

/// A first-order section `(c1 s + c0)/(d1 s + d0)` after Tustin, in delta form: the
/// configuration half.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FirstOrder {
    /// `k c1 / D`: the weight of the input's difference `x[n] - x[n-1]`.
    pub bd: f32,
    /// `c0 / D`: the weight of the input's sum `x[n] + x[n-1]`.
    pub bs: f32,
    /// `2 d0 / D = 1 - a`: the pole's distance from z = 1.
    pub alpha: f32,
}

/// The history of a [`FirstOrder`] section: the last input and the output, kept in a
/// [`Store`] (`f32` by default, [`Accumulator`] where the pole sits near z = 1).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FirstOrderState<S = f32> {
    /// The last input `x[n-1]`.
    pub x: f32,
    /// The output `y[n-1]`.
    pub y: S,
}

impl FirstOrder {
    /// Tustin's map of `(c1 s + c0)/(d1 s + d0)` at `period_s`, coefficients highest power
    /// first: `num = [c1, c0]`, `den = [d1, d0]`. Design time, `f64`. The caller keeps the
    /// section stable and proper: `d1, d0 >= 0`, not both zero (the integrator `1/s` is
    /// `[0, 1], [1, 0]`).
    ///
    /// ```
    /// use model_core::sections::{FirstOrder, FirstOrderState};
    /// // 1 / (tau s + 1) with tau = 50 us at 50 kHz: pole at z = (2 tau - T)/(2 tau + T).
    /// let f = FirstOrder::tustin([0.0, 1.0], [50e-6, 1.0], 20e-6);
    /// assert!((f.alpha - 2.0 / 6.0).abs() < 1e-7);
    /// let mut s = FirstOrderState::<f32>::default();
    /// assert!((f.step(&mut s, 1.0) - 1.0 / 6.0).abs() < 1e-7);
    /// ```
    pub fn tustin(num: [f64; 2], den: [f64; 2], period_s: f64) -> Self {
        let [c1, c0] = num;
        let [d1, d0] = den;
        let k = 2.0 / period_s;
        let d = k * d1 + d0;
        Self {
            bd: (k * c1 / d) as f32,
            bs: (c0 / d) as f32,
            alpha: (2.0 * d0 / d) as f32,
        }
    }

    /// The DC gain `c0/d0` (`2 bs / alpha`); 0 for an integrator.
    pub fn dc_gain(&self) -> f32 {
        if self.alpha == 0.0 {
            0.0
        } else {
            2.0 * self.bs / self.alpha
        }
    }

    /// A state at rest with the input `x` held for ever (an integrator's rests at 0).
    pub fn settled<S: Store>(&self, x: f32) -> FirstOrderState<S> {
        FirstOrderState {
            x,
            y: S::holding(self.dc_gain() * x),
        }
    }

    /// One sample: input `x` in, output out.
    #[inline]
    pub fn step<S: Store>(&self, s: &mut FirstOrderState<S>, x: f32) -> f32 {
        let y = s.y.get();
        s.y.accumulate(self.bd * (x - s.x) + self.bs * (x + s.x) - self.alpha * y);
        s.x = x;
        s.y.get()
    }
}

/// A second-order section `(c2 s^2 + c1 s + c0)/(d2 s^2 + d1 s + d0)` after Tustin, in delta
/// form: the configuration half.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SecondOrder {
    /// `[k^2 c2, k c1, c0] / D`: the weights of the input's second difference, its
    /// difference over two samples and its double sum.
    pub b: [f32; 3],
    /// `4 d0 / D`: the weight of the output itself (0 for a double integrator).
    pub alpha: f32,
    /// `2 k d1 / D`: the decay of the increment.
    pub beta: f32,
}

/// The history of a [`SecondOrder`] section: the last two inputs, the output and its last
/// increment, both kept in a [`Store`] (near z = 1 the increment too changes by a tiny
/// fraction of itself per step).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SecondOrderState<S = f32> {
    /// The last inputs `[x[n-1], x[n-2]]`.
    pub x: [f32; 2],
    /// The output `y[n-1]`.
    pub y: S,
    /// The last increment `y[n-1] - y[n-2]`.
    pub dy: S,
}

impl SecondOrder {
    /// Tustin's map of `(c2 s^2 + c1 s + c0)/(d2 s^2 + d1 s + d0)` at `period_s`, coefficients
    /// highest power first. Design time, `f64`. The caller keeps the section stable and
    /// proper (`d2, d1, d0 >= 0`, `d2` or `d1` non-zero).
    ///
    /// ```
    /// use model_core::sections::{SecondOrder, SecondOrderState};
    /// // A 1 kHz resonance with damping 0.1, at 50 kHz: unit DC gain.
    /// let wn = 2.0 * core::f64::consts::PI * 1e3;
    /// let f = SecondOrder::tustin([0.0, 0.0, 1.0], [1.0 / (wn * wn), 0.2 / wn, 1.0], 20e-6);
    /// let mut s: SecondOrderState = f.settled(2.0);
    /// assert!((f.step(&mut s, 2.0) - 2.0).abs() < 1e-6);
    /// ```
    pub fn tustin(num: [f64; 3], den: [f64; 3], period_s: f64) -> Self {
        let [c2, c1, c0] = num;
        let [d2, d1, d0] = den;
        let k = 2.0 / period_s;
        let d = k * k * d2 + k * d1 + d0;
        Self {
            b: [
                (k * k * c2 / d) as f32,
                (k * c1 / d) as f32,
                (c0 / d) as f32,
            ],
            alpha: (4.0 * d0 / d) as f32,
            beta: (2.0 * k * d1 / d) as f32,
        }
    }

    /// The DC gain `c0/d0` (`4 b2 / alpha`); 0 when `d0 = 0`.
    pub fn dc_gain(&self) -> f32 {
        if self.alpha == 0.0 {
            0.0
        } else {
            4.0 * self.b[2] / self.alpha
        }
    }

    /// A state at rest with the input `x` held for ever.
    pub fn settled<S: Store>(&self, x: f32) -> SecondOrderState<S> {
        SecondOrderState {
            x: [x; 2],
            y: S::holding(self.dc_gain() * x),
            dy: S::default(),
        }
    }

    /// One sample: input `x` in, output out.
    #[inline]
    pub fn step<S: Store>(&self, s: &mut SecondOrderState<S>, x: f32) -> f32 {
        let [x1, x2] = s.x;
        let dx = x - x1;
        let dx1 = x1 - x2;
        let (y, dy) = (s.y.get(), s.dy.get());
        s.dy.accumulate(
            self.b[0] * (dx - dx1) + self.b[1] * (dx + dx1) + self.b[2] * ((x + x1) + (x1 + x2))
                - self.alpha * y
                - self.beta * dy,
        );
        s.y.accumulate(s.dy.get());
        s.x = [x, x1];
        s.y.get()
    }
}

/// Coefficients of a first-order low-pass `y' = (g x - y) / tau`, discretised exactly for a
/// held input (ZOH): `y[n+1] = y[n] + alpha (g x[n] - y[n])`, `alpha = 1 - e^(-T/tau)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FirstOrderLag {
    /// `1 - e^(-T/tau)`, computed without cancellation.
    pub alpha: f32,
    /// DC gain.
    pub gain: f32,
}

impl FirstOrderLag {
    /// Exact ZOH discretisation for time constant `tau_s` and step `period_s` (both > 0).
    pub fn new(gain: f64, tau_s: f64, period_s: f64) -> Self {
        let alpha = -crate::discretize::expm1(-period_s / tau_s);
        Self {
            alpha: alpha as f32,
            gain: gain as f32,
        }
    }

    /// One step of the state `y` with held input `x`.
    #[inline]
    pub fn step(&self, y: &mut Accumulator, x: f32) {
        y.add(self.alpha * (self.gain * x - y.value()));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compensated_sum_beats_plain_f32() {
        // Add 1e-4 a million times onto 5.0: exact 105.0.
        let mut acc = Accumulator::new(5.0);
        let mut plain = 5.0f32;
        for _ in 0..1_000_000 {
            acc.add(1e-4);
            plain += 1e-4;
        }
        let exact = 5.0 + 1e6 * (1e-4f32 as f64);
        let e_acc = (acc.value() as f64 - exact).abs();
        let e_plain = (plain as f64 - exact).abs();
        assert!(e_acc < 1e-5, "compensated error {e_acc}");
        assert!(e_plain > 100.0 * e_acc, "plain error {e_plain}");
    }

    #[test]
    fn slow_lag_keeps_its_time_constant() {
        // tau = 12 s at 50 kHz: after 1 s of a unit step, y = 1 - e^(-1/12).
        let lag = FirstOrderLag::new(1.0, 12.0, 20e-6);
        let mut y = Accumulator::default();
        for _ in 0..50_000 {
            lag.step(&mut y, 1.0);
        }
        let want = 1.0 - (-1.0f64 / 12.0).exp();
        assert!(
            ((y.value() as f64 - want) / want).abs() < 1e-5,
            "{}",
            y.value()
        );
    }

    /// Tustin's map in `f64` direct form, the oracle: `(num, den)` in powers of `z^-1`.
    fn bilinear(c: &[f64], d: &[f64], t: f64) -> (Vec<f64>, Vec<f64>) {
        // Coefficients highest power of s first; order n = len - 1.
        let n = c.len() - 1;
        let k = 2.0 / t;
        // (1 - q)^i (1 + q)^(n - i) as a polynomial in q = z^-1.
        let basis = |i: usize| {
            let mut p = vec![1.0];
            for j in 0..n {
                let sign = if j < i { -1.0 } else { 1.0 };
                let mut next = vec![0.0; p.len() + 1];
                for (m, v) in p.iter().enumerate() {
                    next[m] += v;
                    next[m + 1] += sign * v;
                }
                p = next;
            }
            p
        };
        let map = |poly: &[f64]| {
            let mut out = vec![0.0; n + 1];
            for (pos, coef) in poly.iter().enumerate() {
                let power = n - pos; // s^power
                let b = basis(power);
                for (m, v) in b.iter().enumerate() {
                    out[m] += coef * k.powi(power as i32) * v;
                }
            }
            out
        };
        let (num, den) = (map(c), map(d));
        let a0 = den[0];
        (
            num.iter().map(|v| v / a0).collect(),
            den.iter().map(|v| v / a0).collect(),
        )
    }

    fn direct_form(num: &[f64], den: &[f64], x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; x.len()];
        for n in 0..x.len() {
            let mut acc = 0.0;
            for (i, b) in num.iter().enumerate() {
                if n >= i {
                    acc += b * x[n - i];
                }
            }
            for (i, a) in den.iter().enumerate().skip(1) {
                if n >= i {
                    acc -= a * y[n - i];
                }
            }
            y[n] = acc;
        }
        y
    }

    /// A deterministic input: two sines and a step, 1 V scale.
    fn input(n: usize) -> Vec<f64> {
        (0..n)
            .map(|i| {
                let t = i as f64 * 20e-6;
                0.7 * (2.0 * core::f64::consts::PI * 130.0 * t).sin()
                    + 0.2 * (2.0 * core::f64::consts::PI * 2900.0 * t).sin()
                    + if i > n / 3 { 0.5 } else { 0.0 }
            })
            .collect()
    }

    /// The worst gap between the `f32` section and the `f64` direct form, relative to the
    /// reference's peak.
    fn worst_first<S: Store>(c: [f64; 2], d: [f64; 2], n: usize) -> f64 {
        let t = 20e-6;
        let f = FirstOrder::tustin(c, d, t);
        let (num, den) = bilinear(&c, &d, t);
        let x = input(n);
        let want = direct_form(&num, &den, &x);
        let mut s = FirstOrderState::<S>::default();
        let peak = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        x.iter()
            .zip(&want)
            .map(|(x, w)| (f.step(&mut s, *x as f32) as f64 - w).abs())
            .fold(0.0, f64::max)
            / peak
    }

    /// The worst gaps (relative to the reference's peak) of the `f32` delta-form section and
    /// of an `f32` direct form I with the same (rounded) coefficients. With `split`, the
    /// section runs the strictly proper remainder `H - g`, `g = c2/d2`, and adds `g x`.
    fn worst_second<S: Store>(c: [f64; 3], d: [f64; 3], split: bool, n: usize) -> (f64, f64) {
        let t = 20e-6;
        let g = if split { c[0] / d[0] } else { 0.0 };
        let rest = [c[0] - g * d[0], c[1] - g * d[1], c[2] - g * d[2]];
        let f = SecondOrder::tustin(rest, d, t);
        let (num, den) = bilinear(&c, &d, t);
        let x = input(n);
        let want = direct_form(&num, &den, &x);
        let peak = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut s = SecondOrderState::<S>::default();
        let (b, a) = (
            num.iter().map(|v| *v as f32).collect::<Vec<_>>(),
            den.iter().map(|v| *v as f32).collect::<Vec<_>>(),
        );
        let (mut xs, mut ys) = ([0.0f32; 2], [0.0f32; 2]);
        let (mut e_delta, mut e_df1) = (0.0f64, 0.0f64);
        for (x, w) in x.iter().zip(&want) {
            let x = *x as f32;
            let y = g as f32 * x + f.step(&mut s, x);
            let y1 = b[0] * x + b[1] * xs[0] + b[2] * xs[1] - a[1] * ys[0] - a[2] * ys[1];
            xs = [x, xs[0]];
            ys = [y1, ys[0]];
            e_delta = e_delta.max((y as f64 - w).abs());
            e_df1 = e_df1.max((y1 as f64 - w).abs());
        }
        (e_delta / peak, e_df1 / peak)
    }

    #[test]
    fn first_order_sections_match_the_f64_direct_form() {
        let n = 200_000;
        // The compensator's integrator and lag (Kc = 1e4, z = 1, p = 0.398 rad/s), the
        // pre-filter's S_hp = s/(s + 1) and a planning pole 1/(50 us s + 1).
        let cases: [(&str, [f64; 2], [f64; 2]); 4] = [
            ("integrator Kc z / s", [0.0, 1e4], [1.0, 0.0]),
            (
                "lag Kc (p - z)/(s + p)",
                [0.0, 1e4 * (0.398 - 1.0)],
                [1.0, 0.398],
            ),
            ("S_hp s / (s + z)", [1.0, 0.0], [1.0, 1.0]),
            ("planning 1/(tau s + 1)", [0.0, 1.0], [50e-6, 1.0]),
        ];
        for (name, c, d) in cases {
            let acc = worst_first::<Accumulator>(c, d, n);
            let plain = worst_first::<f32>(c, d, n);
            println!("{name}: worst gap / peak, compensated {acc:.2e}, plain f32 {plain:.2e}");
            // The input difference term's rounding, summed through the pole: S_hp (pole at
            // 1 - 2e-5, gain 1 at high frequency) keeps about 1e-6 of it.
            assert!(acc < 2e-6, "{name}: {acc}");
            assert!(acc <= plain, "{name}: {acc} {plain}");
        }
    }

    #[test]
    fn second_order_section_matches_the_f64_direct_form() {
        let n = 200_000;
        let wn = 2.0 * core::f64::consts::PI * 5792.0;
        let w1 = 2.0 * core::f64::consts::PI * 1e3;
        let tau = 50e-6;
        // (name, numerator, denominator, poles near z = 1). Bounds relative to the peak
        // output: 1e-6 compensated; the same for plain f32 unless the poles sit near 1.
        type Case = (&'static str, [f64; 3], [f64; 3], bool);
        let cases: [Case; 3] = [
            (
                "pre-filter S_mode",
                [1.0 / (wn * wn), 0.16 / wn, 1.0],
                [tau * tau, 2.0 * tau, 1.0],
                false,
            ),
            (
                "1 kHz resonance, damping 0.1",
                [0.0, 0.0, 1.0],
                [1.0 / (w1 * w1), 0.2 / w1, 1.0],
                false,
            ),
            // Poles at 1 and 0.4 rad/s: z = 1 - 2e-5 and 1 - 8e-6.
            (
                "slow low-pass 0.4 / ((s + 1)(s + 0.4))",
                [0.0, 0.0, 0.4],
                [1.0, 1.4, 0.4],
                true,
            ),
        ];
        for (name, c, d, near_one) in cases {
            let (acc, _) = worst_second::<Accumulator>(c, d, false, n);
            let (plain, df1) = worst_second::<f32>(c, d, false, n);
            println!(
                "{name}: worst gap / peak, compensated {acc:.2e}, plain f32 {plain:.2e}, \
                 f32 direct form I {df1:.2e}"
            );
            assert!(acc < 1e-6, "{name}: {acc}");
            assert!(near_one || plain < 1e-6, "{name}: {plain}");
        }
    }

    #[test]
    fn slow_poles_with_a_direct_term_need_it_split_off() {
        // Poles at 1 and 0.4 rad/s, zeros at 2 and 3 rad/s: gain 1 at high frequency, 15 at
        // DC. Run whole, the input's second difference (weight ~1) is summed twice, and its
        // rounding with it, through a DC gain of 1/alpha = 6e9: the documented limit of the
        // form. Split into `1 + R(s)`, the section sees only small input weights.
        let c = [1.0, 5.0, 6.0];
        let d = [1.0, 1.4, 0.4];
        let n = 200_000;
        let (whole, df1) = worst_second::<Accumulator>(c, d, false, n);
        let (split, _) = worst_second::<Accumulator>(c, d, true, n);
        println!(
            "(s + 2)(s + 3) / ((s + 1)(s + 0.4)): worst gap / peak, whole {whole:.2e}, \
             split {split:.2e}, f32 direct form I {df1:.2e}"
        );
        assert!(split < 1e-5, "{split}");
        assert!(whole > 100.0 * split, "{whole}");
    }

    #[test]
    fn settled_states_stay_at_rest() {
        let f = FirstOrder::tustin([1.0, 2.0], [1.0, 0.5], 20e-6);
        let mut s: FirstOrderState = f.settled(1.5);
        for _ in 0..1000 {
            f.step(&mut s, 1.5);
        }
        assert!((s.y - 6.0).abs() < 1e-5, "{}", s.y);
        let g = SecondOrder::tustin([0.0, 1.0, 3.0], [1e-6, 1e-3, 1.5], 20e-6);
        let mut s: SecondOrderState<Accumulator> = g.settled(-2.0);
        for _ in 0..1000 {
            g.step(&mut s, -2.0);
        }
        assert!((s.y.value() + 4.0).abs() < 1e-5, "{}", s.y.value());
        let integ = FirstOrder::tustin([0.0, 1.0], [1.0, 0.0], 20e-6);
        assert_eq!(integ.dc_gain(), 0.0);
    }
}
