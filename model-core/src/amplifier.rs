//! The E-505.00 amplifier as the stage model sees it (sec. 2.3, 4.1.1.1): gain 10, control
//! input -2..12 V, output -20..120 V, slew-rate limiter at the output settable 15..1500 V/ms
//! (the lab set 1500 V/ms).
//!
//! ```text
//! u (control input) ─► clamp -2..12 V ─► x10 ─► clamp -20..120 V ─► slew limit ─► v (output)
//! ```
//! **The 2 kHz roll-off is not here.** It is the amplifier's output stage driving the stack's
//! 1.8 uF, identified together with the stage mode as the "electrical" pole of eq. 4.4, and it
//! lives in [`crate::plant::LinearPlant`] (`amp_pole_hz`), after the piezo block, exactly where
//! the thesis' overall model puts `G_electrical` (ch. 6). The wiring and the reason are stated
//! once, in [`crate::stage`]. What this block keeps is what eq. 4.4 cannot: the ranges and the
//! slew limiter, which a linear pole never shows.
//!
//! The slew limit applies to the output. A first-order lag (the 2 kHz pole) driven by a
//! slew-limited signal never slews faster than its input, so the limit also holds for the
//! voltage across the stack.
//!
//! Saturation and the slew limiter can be switched off separately (the model-gap workflow
//! fits `saturation` and `slew-rate-limit` as effects). A non-finite control input holds the
//! previous output (documented safe behaviour; a real amplifier sees a DAC that has no NaN).

use crate::limits::clamp_f32;
use crate::limits::{ConfigError, check_finite, check_period, check_within};
use crate::params;

/// Amplifier parameters (design time, `f64`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AmplifierConfig {
    /// Voltage gain (10 +- 0.1).
    pub gain: f64,
    /// Control input range, volts (applied when `saturation` is on).
    pub input_range_v: (f64, f64),
    /// Output range, volts (applied when `saturation` is on).
    pub output_range_v: (f64, f64),
    /// Slew limit at the output, V/s (15e3..1.5e6), or `None` for no limiter.
    pub slew_v_per_s: Option<f64>,
    /// Apply the input and output ranges.
    pub saturation: bool,
}

impl Default for AmplifierConfig {
    /// The lab's E-505: gain 10, ranges on, slew 1500 V/ms.
    fn default() -> Self {
        Self {
            gain: params::AMP_GAIN,
            input_range_v: (params::AMP_INPUT_MIN_V, params::AMP_INPUT_MAX_V),
            output_range_v: (params::AMP_OUTPUT_MIN_V, params::AMP_OUTPUT_MAX_V),
            slew_v_per_s: Some(params::AMP_SLEW_OUTPUT_V_PER_S),
            saturation: true,
        }
    }
}

impl AmplifierConfig {
    /// Gain within 1..100, ranges non-empty and inside the E-505's own (-2..12 V in, -20..120 V
    /// out), slew within the limiter's 15..1500 V/ms.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let (i0, i1) = self.input_range_v;
        let (o0, o1) = self.output_range_v;
        for (name, v) in [
            ("gain", self.gain),
            ("input_range_v.0", i0),
            ("input_range_v.1", i1),
            ("output_range_v.0", o0),
            ("output_range_v.1", o1),
            ("slew_v_per_s", self.slew_v_per_s.unwrap_or(1.0)),
        ] {
            check_finite(name, v)?;
        }
        check_within("gain", self.gain, 1.0, 100.0)?;
        let (in_lo, in_hi) = (params::AMP_INPUT_MIN_V, params::AMP_INPUT_MAX_V);
        check_within("input_range_v.0", i0, in_lo, in_hi)?;
        check_within("input_range_v.1", i1, in_lo, in_hi)?;
        if i0 >= i1 {
            return Err(ConfigError::not_below("input_range_v.0", "input_range_v.1"));
        }
        let (out_lo, out_hi) = (params::AMP_OUTPUT_MIN_V, params::AMP_OUTPUT_MAX_V);
        check_within("output_range_v.0", o0, out_lo, out_hi)?;
        check_within("output_range_v.1", o1, out_lo, out_hi)?;
        if o0 >= o1 {
            return Err(ConfigError::not_below(
                "output_range_v.0",
                "output_range_v.1",
            ));
        }
        if let Some(s) = self.slew_v_per_s {
            let tol = 1.0 + 1e-9;
            if !(s * tol >= params::AMP_SLEW_OUTPUT_MIN_V_PER_S
                && s <= params::AMP_SLEW_OUTPUT_V_PER_S * tol)
            {
                return Err(ConfigError::outside(
                    "slew_v_per_s",
                    params::AMP_SLEW_OUTPUT_MIN_V_PER_S,
                    params::AMP_SLEW_OUTPUT_V_PER_S,
                ));
            }
        }
        Ok(())
    }
}

/// The discrete amplifier: configuration half.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Amplifier {
    gain: f32,
    in_lo: f32,
    in_hi: f32,
    out_lo: f32,
    out_hi: f32,
    /// Largest output change per step, volts (`f32::INFINITY` when the limiter is off).
    slew_v_per_step: f32,
    saturation: bool,
}

/// The amplifier's history: its output voltage.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AmplifierState {
    /// Output voltage at the end of the last step, volts.
    pub output_v: f32,
}

impl Amplifier {
    /// Checks `cfg` and builds the per-step form for steps of `period_s`.
    ///
    /// ```
    /// use model_core::amplifier::{Amplifier, AmplifierConfig, AmplifierState};
    /// let a = Amplifier::new(&AmplifierConfig::default(), 20e-6).unwrap();
    /// let mut s = AmplifierState::default();
    /// assert_eq!(a.step(&mut s, 10.0), 30.0); // 1500 V/ms = 30 V per 20 us
    /// assert_eq!(a.step(&mut s, 50.0), 60.0); // input clamped to 12 V, output heads to 120 V
    /// ```
    pub fn new(cfg: &AmplifierConfig, period_s: f64) -> Result<Self, ConfigError> {
        let t = check_period(period_s)?;
        cfg.validate()?;
        Ok(Self {
            gain: cfg.gain as f32,
            in_lo: cfg.input_range_v.0 as f32,
            in_hi: cfg.input_range_v.1 as f32,
            out_lo: cfg.output_range_v.0 as f32,
            out_hi: cfg.output_range_v.1 as f32,
            slew_v_per_step: cfg.slew_v_per_s.map_or(f32::INFINITY, |s| (s * t) as f32),
            saturation: cfg.saturation,
        })
    }

    /// Voltage gain.
    pub fn gain(&self) -> f32 {
        self.gain
    }

    /// Largest output change per step, volts (infinite with the limiter off).
    pub fn slew_v_per_step(&self) -> f32 {
        self.slew_v_per_step
    }

    /// Output range, volts (infinite when saturation is off).
    pub fn output_range_v(&self) -> (f32, f32) {
        if self.saturation {
            (self.out_lo, self.out_hi)
        } else {
            (f32::NEG_INFINITY, f32::INFINITY)
        }
    }

    /// The output the amplifier settles to for a held control input (no slew).
    #[inline]
    pub fn static_output(&self, u_v: f32) -> f32 {
        if self.saturation {
            clamp_f32(
                clamp_f32(u_v, self.in_lo, self.in_hi) * self.gain,
                self.out_lo,
                self.out_hi,
            )
        } else {
            u_v * self.gain
        }
    }

    /// A state at rest with `u_v` held.
    pub fn steady_state(&self, u_v: f32) -> AmplifierState {
        let v = self.static_output(u_v);
        AmplifierState {
            output_v: if v.is_finite() { v } else { 0.0 },
        }
    }

    /// Apply the control input `u_v` for one step; returns the output voltage.
    #[inline]
    pub fn step(&self, s: &mut AmplifierState, u_v: f32) -> f32 {
        if !u_v.is_finite() {
            return s.output_v;
        }
        let target = self.static_output(u_v);
        let d = clamp_f32(
            target - s.output_v,
            -self.slew_v_per_step,
            self.slew_v_per_step,
        );
        let v = s.output_v + d;
        // Without saturation a huge finite input may overflow to infinity: hold instead.
        if v.is_finite() {
            s.output_v = v;
        }
        s.output_v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_settings_the_e505_does_not_have() {
        let c = AmplifierConfig::default();
        let t = 20e-6;
        let bad = |c: AmplifierConfig| Amplifier::new(&c, t).unwrap_err();
        assert_eq!(
            bad(AmplifierConfig {
                slew_v_per_s: Some(1e3),
                ..c
            }),
            ConfigError::outside("slew_v_per_s", 1.5e4, 1.5e6)
        );
        assert_eq!(
            bad(AmplifierConfig {
                slew_v_per_s: Some(2e6),
                ..c
            }),
            ConfigError::outside("slew_v_per_s", 1.5e4, 1.5e6)
        );
        assert_eq!(
            bad(AmplifierConfig {
                output_range_v: (0.0, 150.0),
                ..c
            }),
            ConfigError::outside("output_range_v.1", -20.0, 120.0)
        );
        assert_eq!(
            bad(AmplifierConfig {
                gain: f64::NAN,
                ..c
            }),
            ConfigError::not_finite("gain")
        );
        let mut s = AmplifierState::default();
        let a = Amplifier::new(&c, t).unwrap();
        a.step(&mut s, 1.0);
        assert_eq!(a.step(&mut s, f32::NAN), 10.0);
    }
}
