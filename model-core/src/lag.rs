//! The lag compensator with its free integrator (sec. 4.1.2, eq. 4.5 / 4.7):
//!
//! ```text
//! G_c(s) = Kc (s + z) / ( s (s/p + 1) ),   Kc = 10000, z = 1 rad/s, p = 0.398 rad/s
//! ```
//!
//! # Discretisation: Tustin, no pre-warping
//! Tustin (`s = 2/T (z-1)/(z+1)`) keeps the direct feed-through of the error, so the loop gets
//! no sample of delay beyond the ADC/DAC hold, and maps the integrator to the trapezoid rule.
//! Pre-warping buys nothing: the lag's corner frequencies (0.4 and 1 rad/s) are 1e-5 of the
//! Nyquist rate, and at the 3000 rad/s crossover Tustin's frequency warp is 0.1 %. ZOH would
//! add a sample of delay (3.5 deg of phase at crossover).
//!
//! # Realisation: parallel form, two delta-form sections, compensated sums
//! Partial fractions split the compensator into an integrator and a first-order lag:
//!
//! ```text
//! G_c(s) = Kc z / s  +  Kc (p - z) / (s + p)
//! ```
//!
//! Each is one [`FirstOrder`] section of [`crate::sections`] (Tustin, delta form), both fed
//! the error, with `e_s = e[n] + e[n-1]`:
//!
//! ```text
//! v[n] = v[n-1] + (Kc z T / 2) e_s                                       (alpha = 0, bd = 0)
//! w[n] = w[n-1] + b e_s - alpha w[n-1],  alpha = p T / (1 + p T/2),  b = Kc (p - z) (T/2) / (1 + p T/2)
//! u[n] = v[n] + w[n]
//! ```
//!
//! `alpha` is `1 - a` computed without cancellation (no `exp` is needed: Tustin is rational),
//! so the lag pole `a = 1 - 7.96e-6` is exact to `f32` relative precision, where a direct form
//! would round `a` itself to the nearest `f32` (spacing 6e-8, a 0.75 % error on `1 - a`) and
//! misplace the lag pole and zero. The sections' outputs `v` and `w` are kept in
//! [`Accumulator`]s so the per-step increments (often 1e-6 of the state) are not lost to
//! rounding. Why not one second-order section: its two poles (z = 1 and 1 - 8e-6) and its zero
//! would all sit near 1, and the anti-windup below needs the integrator's and the lag's
//! shares of the command apart. The parallel form costs one duplicated input history and the
//! integrator's two zero-weight terms (a few instructions). The test in host-tests compares
//! this against an independent `f64` direct-form reference for 1e6 steps: DAC codes agree
//! within 1 LSB.
//!
//! # Limits and anti-windup
//! The command passes through [`OutputLimits::apply`] (NaN guard, slew limit, window). When
//! the command is limited, the step's update of the lag state `w` is undone (conditional
//! integration) and the integrator is set so that `v + w` equals the command actually sent.
//! Both matter: with the integrator alone clamped, the lag state (gain `Kc (p - z)/p = -15000`
//! at DC, time constant 2.5 s) would charge to thousands of volts during a long saturation and
//! hold the output at the clamp for seconds after the error reverses. With both, the states
//! always describe the sent command and the output leaves the limit as soon as the error
//! changes sign.
//!
//! # Reset
//! [`LagState::reset_to`] loads the states so that the next command equals a given value with
//! zero error (bumpless hand-over from open loop, from hold or from the safe value; holding the
//! command is the controller's business, [`crate::controller`]).
//!
//! # Example
//! ```
//! use model_core::lag::{LagCompensator, LagConfig, LagState};
//! let lag = LagCompensator::new(&LagConfig::default()).unwrap();
//! let mut state = LagState::new(2.0);
//! let u = lag.update(&mut state, 1e-3); // 1 mV of error
//! assert!(u > 2.0 && u < 2.001);
//! ```

use crate::limits::{ConfigError, Flags, OutputLimits, check_finite, check_period, check_range};
use crate::params;
use crate::sections::{Accumulator, FirstOrder, FirstOrderState};
use core::ops::Bound::{Excluded, Included};

/// The continuous parameters, the sample period and the limits. Built into a
/// [`LagCompensator`] by [`LagCompensator::new`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagConfig {
    /// Gain `Kc`.
    pub kc: f64,
    /// Lag zero `z`, rad/s.
    pub zero_rad_s: f64,
    /// Lag pole `p`, rad/s.
    pub pole_rad_s: f64,
    /// Sample period, seconds.
    pub period_s: f64,
    /// Output window, volts at the amplifier input.
    pub min_v: f64,
    /// Output window, volts at the amplifier input.
    pub max_v: f64,
    /// Slew limit at the amplifier input, V/s.
    pub slew_v_per_s: f64,
}

impl Default for LagConfig {
    /// The thesis compensator at 50 kHz with the default window 0..10 V and 150 V/ms.
    fn default() -> Self {
        Self {
            kc: params::LAG_KC,
            zero_rad_s: params::LAG_ZERO_RAD_S,
            pole_rad_s: params::LAG_POLE_RAD_S,
            period_s: 1.0 / params::SAMPLE_RATE_HZ,
            min_v: params::SAFE_WINDOW_MIN_V,
            max_v: params::SAFE_WINDOW_MAX_V,
            slew_v_per_s: params::AMP_SLEW_INPUT_V_PER_S,
        }
    }
}

/// Discrete coefficients and limits: the configuration half. `Copy`, so a new one can be
/// built outside the interrupt and swapped in whole.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagCompensator {
    /// `Kc z / s` after Tustin: `bs = Kc z T / 2`, `bd = alpha = 0`.
    pub integrator: FirstOrder,
    /// `Kc (p - z) / (s + p)` after Tustin: `bs = Kc (p - z) (T/2) / (1 + p T/2)`,
    /// `alpha = 1 - a = p T / (1 + p T/2)`, `bd = 0`.
    pub lag: FirstOrder,
    /// The last stage.
    pub limits: OutputLimits,
}

impl LagCompensator {
    /// Discretise `config`. Refuses non-finite values, rates outside 10..200 kHz, `Kc` outside
    /// `(0, 1e6]`, a zero or pole that is not positive or above 1/100 of the sample rate
    /// (rad/s), and bad limits; the error names the field of [`LagConfig`].
    pub fn new(config: &LagConfig) -> Result<Self, ConfigError> {
        let c = config;
        check_finite("kc", c.kc)?;
        check_finite("zero_rad_s", c.zero_rad_s)?;
        check_finite("pole_rad_s", c.pole_rad_s)?;
        let t = check_period(c.period_s)?;
        let corner = (Excluded(0.0), Included(0.01 / t));
        check_range("kc", c.kc, Excluded(0.0), Included(params::LAG_KC_MAX))?;
        check_range("zero_rad_s", c.zero_rad_s, corner.0, corner.1)?;
        check_range("pole_rad_s", c.pole_rad_s, corner.0, corner.1)?;
        let limits = OutputLimits::new(c.min_v, c.max_v, c.slew_v_per_s, t)?;
        Ok(Self {
            integrator: FirstOrder::tustin([0.0, c.kc * c.zero_rad_s], [1.0, 0.0], t),
            lag: FirstOrder::tustin(
                [0.0, c.kc * (c.pole_rad_s - c.zero_rad_s)],
                [1.0, c.pole_rad_s],
                t,
            ),
            limits,
        })
    }

    /// One sample: error in volts (reference minus measurement) to the command in volts at
    /// the amplifier input. Never returns a value outside the window or further than the slew
    /// limit from the previous command; a non-finite error holds the last command.
    #[inline]
    pub fn update(&self, state: &mut LagState, error_v: f32) -> f32 {
        self.update_flags(state, error_v).0
    }

    /// [`Self::update`], also returning what the limits did.
    #[inline]
    pub fn update_flags(&self, state: &mut LagState, error_v: f32) -> (f32, Flags) {
        self.update_ff(state, error_v, 0.0)
    }

    /// One sample with a feedforward term added to the compensator's output before the
    /// limits (for example the hysteresis inverse's non-linear part). The anti-windup treats
    /// the sum: when it is limited, the integrator takes up the difference, so the states
    /// describe the command really sent. A non-finite feedforward is treated as zero and
    /// flagged.
    #[inline]
    pub fn update_ff(
        &self,
        state: &mut LagState,
        error_v: f32,
        feedforward_v: f32,
    ) -> (f32, Flags) {
        if !error_v.is_finite() {
            return (state.last_v, Flags::NONFINITE);
        }
        let (ff, ff_flags) = if feedforward_v.is_finite() {
            (feedforward_v, Flags::NONE)
        } else {
            (0.0, Flags::NONFINITE)
        };
        let lag_before = state.lag.y;
        let v = self.integrator.step(&mut state.integ, error_v);
        let w = self.lag.step(&mut state.lag, error_v);
        let raw = v + w + ff;
        let (out, flags) = self.limits.apply(state.last_v, raw);
        if flags.contains(Flags::NONFINITE) {
            // The states overflowed: restart them from the last safe command.
            state.reload(state.last_v - ff);
        } else if out != raw {
            // Anti-windup: the lag state keeps its value from before this step and the
            // integrator takes up the rest, so the states describe the command really sent.
            state.lag.y = lag_before;
            state
                .integ
                .y
                .add(out - (state.integ.y.value() + state.lag.y.value() + ff));
        }
        state.last_v = out;
        (out, flags | ff_flags)
    }
}

/// The compensator's history: the state half. Both sections' outputs are compensated sums;
/// both keep the last error as their input history.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagState {
    integ: FirstOrderState<Accumulator>,
    lag: FirstOrderState<Accumulator>,
    last_v: f32,
}

impl LagState {
    /// A state whose command is `output_v` with no error history.
    pub fn new(output_v: f32) -> Self {
        let mut s = Self {
            integ: FirstOrderState::default(),
            lag: FirstOrderState::default(),
            last_v: 0.0,
        };
        s.reset_to(output_v);
        s
    }

    /// The integrator holds `output_v`, the lag is empty, no error history.
    fn reload(&mut self, output_v: f32) {
        self.integ = FirstOrderState {
            x: 0.0,
            y: Accumulator::new(output_v),
        };
        self.lag = FirstOrderState::default();
    }

    /// Bumpless reset: the next command continues from `output_v` (a non-finite value is
    /// ignored and the present command kept).
    pub fn reset_to(&mut self, output_v: f32) {
        let v = if output_v.is_finite() {
            output_v
        } else {
            self.last_v
        };
        self.reload(v);
        self.last_v = v;
    }

    /// Bumpless reset when a feedforward term `feedforward_v` will be added: the states hold
    /// `output_v - feedforward_v`, the command stays `output_v`.
    pub fn reset_with_feedforward(&mut self, output_v: f32, feedforward_v: f32) {
        self.reset_to(output_v);
        if feedforward_v.is_finite() {
            self.reload(self.last_v - feedforward_v);
        }
    }

    /// The last command, volts.
    pub fn output_v(&self) -> f32 {
        self.last_v
    }

    /// The integrator's part of the command, volts.
    pub fn integrator_v(&self) -> f32 {
        self.integ.y.value()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_absurd_parameters() {
        let ok = LagConfig::default();
        assert!(LagCompensator::new(&ok).is_ok());
        for bad in [
            LagConfig { kc: -1.0, ..ok },
            LagConfig { kc: 1e9, ..ok },
            LagConfig { kc: f64::NAN, ..ok },
            LagConfig {
                pole_rad_s: 0.0,
                ..ok
            },
            LagConfig {
                zero_rad_s: 1e6,
                ..ok
            },
            LagConfig {
                period_s: 1e-3,
                ..ok
            },
            LagConfig {
                min_v: 5.0,
                max_v: 1.0,
                ..ok
            },
        ] {
            assert!(LagCompensator::new(&bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn nan_keeps_the_command() {
        let lag = LagCompensator::new(&LagConfig::default()).unwrap();
        let mut s = LagState::new(3.0);
        let u = lag.update(&mut s, 0.01);
        assert_eq!(lag.update_flags(&mut s, f32::NAN), (u, Flags::NONFINITE));
        assert!(lag.update(&mut s, 0.0) > u);
    }
}
