//! The non-linear static gain of the fast part, K'(u) (sec. 3.1, 5.1, fig. 3.10).
//!
//! The thesis measured the fast part's gain 5 ms after steps of 1..6 V from 0 V: it "shows an
//! almost linear variation and a proportional increase with respect to the input step height"
//! and "plateaus off at higher input amplitudes" (sec. 5.1). It fits a polynomial but prints no
//! coefficients, so ours are an assumption ([`params::FAST_GAIN_POLY`]):
//!
//! ```text
//! K'(u) = 1 + 0.02 u - 0.001 u^2,   u clamped to 0..10 V
//! ```
//! The polynomial has room for terms up to `u^6` ([`POLY_TERMS`]; zero in the thesis model): a
//! fit may need a curvature of higher order (host `gap`: a sensor scale or an offset against a
//! curvature, weighed order by order; a plateau such as a `tanh` over 1-9 V needs `u^5`-`u^6`).
//! 1 at 0 V (so small signals near 0 V see the linear model's 0.79), +2 %/V at first, flat at
//! 10 V where it reaches 1.10.
//!
//! As for the drift ([`crate::drift`]) the step height is generalised to the present input: the
//! fast static map is `p(u) = K'(u) h(u)` with `h` the hysteresis (or `0.79 u` without it). This
//! keeps the block memoryless, exact for steps from 0 V, and invertible: `K'(u) u` is strictly
//! increasing (slope `1 + 0.04 u - 0.003 u^2 >= 1` on 0..10 V), checked by
//! [`FastGainConfig::validate`].

use crate::limits::{ConfigError, Reason, check_finite, check_within};
use crate::params;

/// Coefficients K'(u) holds, lowest power first: up to the `u^6` term (our assumption: a knee
/// or a plateau over the amplifier's range is fitted to a noise floor of the sensor's by a
/// polynomial of this order, measured on `tanh`, exponential and softplus maps in the host's
/// `gap` families; higher orders add nothing there and cost a multiply-add each per sample).
pub const POLY_TERMS: usize = 7;

/// K'(u) (design time, `f64`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FastGainConfig {
    /// Polynomial coefficients, lowest power first (up to the `u^6` term).
    pub poly: [f64; POLY_TERMS],
    /// Input range over which the polynomial is evaluated, volts; held at the edges outside.
    pub range_v: (f64, f64),
}

impl Default for FastGainConfig {
    /// Our assumption, [`params::FAST_GAIN_POLY`].
    fn default() -> Self {
        Self {
            poly: params::FAST_GAIN_POLY,
            range_v: params::FAST_GAIN_U_RANGE_V,
        }
    }
}

impl FastGainConfig {
    /// K'(u) in `f64`.
    pub fn gain(&self, u_v: f64) -> f64 {
        let x = u_v.clamp(self.range_v.0, self.range_v.1);
        self.poly.iter().rev().fold(0.0, |acc, &c| acc * x + c)
    }

    /// Finite, K' within 0.2..5 over the range, non-empty range inside -20..20 V, and
    /// `K'(u) u` strictly increasing on -20..20 V.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for c in self.poly {
            check_finite("poly", c)?;
        }
        check_finite("range_v.0", self.range_v.0)?;
        check_finite("range_v.1", self.range_v.1)?;
        check_within("range_v.0", self.range_v.0, -20.0, 20.0)?;
        check_within("range_v.1", self.range_v.1, -20.0, 20.0)?;
        if self.range_v.0 >= self.range_v.1 {
            return Err(ConfigError::not_below("range_v.0", "range_v.1"));
        }
        let mut last = f64::NEG_INFINITY;
        for i in 0..=4000 {
            let u = -20.0 + 40.0 * i as f64 / 4000.0;
            let k = self.gain(u);
            if !(0.2..=5.0).contains(&k) {
                return Err(ConfigError::outside("gain(u)", 0.2, 5.0));
            }
            if k * u <= last {
                return Err(ConfigError::new("gain(u) u", Reason::NotMonotone));
            }
            last = k * u;
        }
        Ok(())
    }
}

/// K'(u) in `f32` for the per-sample path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FastGain {
    poly: [f32; POLY_TERMS],
    lo_v: f32,
    hi_v: f32,
}

impl FastGain {
    /// Checks and converts `cfg`.
    ///
    /// ```
    /// use model_core::gain::{FastGain, FastGainConfig};
    /// let g = FastGain::new(&FastGainConfig::default()).unwrap();
    /// assert_eq!(g.gain(0.0), 1.0);
    /// assert!((g.gain(10.0) - 1.1).abs() < 1e-6);
    /// assert!((g.gain(20.0) - 1.1).abs() < 1e-6); // held above the range
    /// ```
    pub fn new(cfg: &FastGainConfig) -> Result<Self, ConfigError> {
        cfg.validate()?;
        Ok(Self {
            poly: cfg.poly.map(|c| c as f32),
            lo_v: cfg.range_v.0 as f32,
            hi_v: cfg.range_v.1 as f32,
        })
    }

    /// K'(u). NaN gives NaN.
    #[inline]
    pub fn gain(&self, u_v: f32) -> f32 {
        let x = u_v.max(self.lo_v).min(self.hi_v);
        // (Horner over a fixed-length array: no loop bound depends on the data)
        self.poly.iter().rev().fold(0.0, |acc, &c| acc * x + c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The per-sample `f32` K'(u) with a cubic term is the design-time `f64` one within the
    /// rounding of a few `f32` operations on values near 1 (4 ulp of 1), and held at the edges.
    #[test]
    fn a_cubic_term_is_evaluated_as_in_f64() {
        let cfg = FastGainConfig {
            poly: [1.0, 0.03, -0.004, 2e-4, 0.0, 0.0, 0.0],
            range_v: (0.0, 10.0),
        };
        let g = FastGain::new(&cfg).unwrap();
        for i in 0..=240 {
            let u = -1.0 + 12.0 * i as f64 / 240.0;
            let x = u.clamp(0.0, 10.0);
            let want = 1.0 + 0.03 * x - 0.004 * x * x + 2e-4 * x * x * x;
            assert!((cfg.gain(u) - want).abs() < 1e-12);
            assert!((g.gain(u as f32) as f64 - want).abs() < 4.0 * f32::EPSILON as f64);
        }
    }

    /// With every term up to `u^6` (terms of up to 0.4 at 10 V that cancel to 1.03), the `f32`
    /// K'(u) is the `f64` one within 8 ulp of 1: the rounding of Horner's seven steps on
    /// partial sums below 1.4.
    #[test]
    fn a_sixth_order_gain_is_evaluated_as_in_f64() {
        let poly = [1.0, 0.03, -0.004, 2e-4, -1e-5, 3e-7, -4e-9];
        let cfg = FastGainConfig {
            poly,
            range_v: (0.0, 10.0),
        };
        let g = FastGain::new(&cfg).unwrap();
        for i in 0..=240 {
            let u = -1.0 + 12.0 * i as f64 / 240.0;
            let x = u.clamp(0.0, 10.0);
            let want: f64 = poly
                .iter()
                .enumerate()
                .map(|(k, c)| c * x.powi(k as i32))
                .sum();
            assert!((cfg.gain(u) - want).abs() < 1e-12);
            assert!((g.gain(u as f32) as f64 - want).abs() < 8.0 * f32::EPSILON as f64);
        }
    }

    /// A cubic that folds the map (K'(u) u falling somewhere on the range) is refused.
    #[test]
    fn refuses_a_cubic_that_folds_the_map() {
        let c = FastGainConfig {
            poly: [1.0, 0.0, 0.0, -0.01, 0.0, 0.0, 0.0],
            range_v: (0.0, 10.0),
        };
        // (K'(u) u = u - 0.01 u^4 turns down at 2.9 V, where K' is still 0.76)
        assert_eq!(
            c.validate(),
            Err(ConfigError::new("gain(u) u", Reason::NotMonotone))
        );
    }

    #[test]
    fn refuses_a_gain_that_would_fold_the_map() {
        let c = FastGainConfig {
            poly: [1.0, -0.5, 0.0, 0.0, 0.0, 0.0, 0.0],
            ..FastGainConfig::default()
        };
        assert_eq!(
            FastGain::new(&c),
            Err(ConfigError::new("gain(u) u", Reason::NotMonotone))
        );
        let c = FastGainConfig {
            poly: [f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ..FastGainConfig::default()
        };
        assert_eq!(FastGain::new(&c), Err(ConfigError::not_finite("poly")));
    }
}
