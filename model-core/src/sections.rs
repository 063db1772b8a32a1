//! Building blocks that stay accurate in `f32` when poles sit near z = 1.
//!
//! At 50 kHz the lag compensator's pole (0.398 rad/s) maps to z = 1 - 7.96e-6 and the drift's
//! slowest lag (12 s) to z = 1 - 1.7e-6. In a direct form `y = a y + b x` with `a` rounded to
//! `f32` (spacing 6e-8 near 1), `1 - a` is off by up to 0.75 % for the lag and 3.5 % for the
//! drift, and the state, which is large compared with its per-step change, loses the low bits
//! of every increment. Two remedies, used together:
//!
//! * **Delta form**: store `alpha = 1 - a` (computed exactly at design time, full `f32`
//!   relative precision) and update `y += b x - alpha y`.
//! * **Compensated accumulation** ([`Accumulator`]): the state is a pair `hi + lo` updated with
//!   Kahan's compensated sum, so the rounding error of each addition is carried to the next
//!   instead of lost. The error after n steps stays near one `f32` ulp of the state instead of
//!   growing like n ulps. Cost: three extra additions per state.
//!
//! Rust never reassociates floating point, so the compensation is not optimised away.

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
}
