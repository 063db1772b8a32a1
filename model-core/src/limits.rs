//! The last stage before the DAC: window clamp, slew limit, NaN guard.
//!
//! The E-505 takes -2..12 V at its control input and slews at most 1500 V/ms at its output,
//! i.e. 150 V/ms at the input (sec. 2.3, 4.1.1.1). Whatever the controller computes, the
//! command leaving [`OutputLimits::apply`] is
//!
//! 1. finite (a non-finite request holds the last command and raises [`Flags::NONFINITE`]),
//! 2. within `slew_v_per_step` of the previous command ([`Flags::SLEW_LIMITED`]),
//! 3. inside the window `[min_v, max_v]` ([`Flags::CLAMPED`]).
//!
//! The window is applied last so it wins if a reconfiguration leaves the previous command
//! outside a new, narrower window; from a command inside the window both hold at once.
//! Step count: a handful of compares, no branches that depend on history length.

use crate::params;

/// Conditions met by one step, as a small bit set.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Flags(pub u8);

impl Flags {
    /// No condition.
    pub const NONE: Self = Self(0);
    /// The window clamped the command.
    pub const CLAMPED: Self = Self(1);
    /// The slew limit held the command back.
    pub const SLEW_LIMITED: Self = Self(2);
    /// A non-finite value was met; the last safe command was held.
    pub const NONFINITE: Self = Self(4);
    /// The controller is in hold.
    pub const HELD: Self = Self(8);

    /// True if any bit of `other` is set in `self`.
    #[inline]
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 != 0
    }

    /// Union.
    #[inline]
    #[must_use]
    pub const fn union(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }
}

impl core::ops::BitOr for Flags {
    type Output = Self;
    fn bitor(self, rhs: Self) -> Self {
        self.union(rhs)
    }
}

impl core::ops::BitOrAssign for Flags {
    fn bitor_assign(&mut self, rhs: Self) {
        *self = self.union(rhs);
    }
}

/// Why a configuration was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConfigError {
    /// A parameter was NaN or infinite.
    NotFinite,
    /// The window is empty or leaves the amplifier's control input range.
    BadWindow,
    /// The slew rate is not positive or exceeds what the amplifier can do.
    BadSlew,
    /// The sample rate is outside 10..200 kHz.
    BadRate,
    /// A gain, pole or zero is out of its range.
    BadGain,
    /// A time constant is not positive.
    BadTimeConstant,
    /// A table has the wrong size or breaks a required monotonicity.
    BadTable,
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::NotFinite => "a parameter is NaN or infinite",
            Self::BadWindow => {
                "the output window is empty or outside the amplifier input range -2..12 V"
            }
            Self::BadSlew => {
                "the slew rate must be positive and at most the amplifier's 150 V/ms at its input"
            }
            Self::BadRate => "the sample rate must be within 10..200 kHz",
            Self::BadGain => "a gain, pole or zero is out of range",
            Self::BadTimeConstant => "a time constant must be positive",
            Self::BadTable => "a table has the wrong size or is not monotone",
        })
    }
}

/// `x` limited to `[lo, hi]`, for the per-sample path: unlike `f32::clamp` it never panics
/// (`clamp` panics when a bound is NaN or `lo > hi`, and the compiler keeps that panic path in
/// the interrupt unless it can prove the bounds), and it compiles to compares where
/// `f32::max`/`min` call `fmaxf`/`fminf` on thumbv7em. A NaN `x` gives `lo`; `lo > hi` gives
/// `hi`.
#[inline]
pub fn clamp_f32(x: f32, lo: f32, hi: f32) -> f32 {
    let y = if x >= lo { x } else { lo };
    if y > hi { hi } else { y }
}

/// Checks a sample period against the allowed rates and returns it.
pub fn check_period(period_s: f64) -> Result<f64, ConfigError> {
    if !period_s.is_finite() {
        return Err(ConfigError::NotFinite);
    }
    let rate = 1.0 / period_s;
    // A small tolerance so that 1/50e3 round trips.
    if !(params::MIN_SAMPLE_RATE_HZ * (1.0 - 1e-9)..=params::MAX_SAMPLE_RATE_HZ * (1.0 + 1e-9))
        .contains(&rate)
    {
        return Err(ConfigError::BadRate);
    }
    Ok(period_s)
}

/// The window and slew limit, per sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutputLimits {
    /// Lowest command, volts at the amplifier input.
    pub min_v: f32,
    /// Highest command, volts at the amplifier input.
    pub max_v: f32,
    /// Largest change per sample, volts.
    pub slew_v_per_step: f32,
}

impl Default for OutputLimits {
    /// The thesis set-up at 50 kHz: window 0..10 V, 150 V/ms at the input (3 V per sample).
    fn default() -> Self {
        Self::new(
            params::SAFE_WINDOW_MIN_V,
            params::SAFE_WINDOW_MAX_V,
            params::AMP_SLEW_INPUT_V_PER_S,
            1.0 / params::SAMPLE_RATE_HZ,
        )
        .expect("the thesis limits are valid")
    }
}

impl OutputLimits {
    /// Limits from a window in volts and a slew rate in V/s at the amplifier input.
    /// The window must lie inside the amplifier's -2..12 V input range and the slew rate
    /// must not exceed the amplifier's own 150 V/ms.
    pub fn new(
        min_v: f64,
        max_v: f64,
        slew_v_per_s: f64,
        period_s: f64,
    ) -> Result<Self, ConfigError> {
        if !(min_v.is_finite() && max_v.is_finite() && slew_v_per_s.is_finite()) {
            return Err(ConfigError::NotFinite);
        }
        let period_s = check_period(period_s)?;
        if !(params::AMP_INPUT_MIN_V <= min_v && min_v < max_v && max_v <= params::AMP_INPUT_MAX_V)
        {
            return Err(ConfigError::BadWindow);
        }
        if !(slew_v_per_s > 0.0 && slew_v_per_s <= params::AMP_SLEW_INPUT_V_PER_S * (1.0 + 1e-9)) {
            return Err(ConfigError::BadSlew);
        }
        Ok(Self {
            min_v: min_v as f32,
            max_v: max_v as f32,
            slew_v_per_step: (slew_v_per_s * period_s) as f32,
        })
    }

    /// The next command from the requested `raw` and the previous command `last`.
    #[inline]
    pub fn apply(&self, last: f32, raw: f32) -> (f32, Flags) {
        let mut flags = Flags::NONE;
        let mut out = if raw.is_finite() {
            raw
        } else {
            flags |= Flags::NONFINITE;
            last
        };
        let lo = last - self.slew_v_per_step;
        let hi = last + self.slew_v_per_step;
        if out > hi {
            out = hi;
            flags |= Flags::SLEW_LIMITED;
        } else if out < lo {
            out = lo;
            flags |= Flags::SLEW_LIMITED;
        }
        if out > self.max_v {
            out = self.max_v;
            flags |= Flags::CLAMPED;
        } else if out < self.min_v {
            out = self.min_v;
            flags |= Flags::CLAMPED;
        }
        // `last` itself may be non-finite only if the caller broke the invariant; fall back to
        // the bottom of the window rather than emit NaN.
        if !out.is_finite() {
            out = self.min_v;
            flags |= Flags::NONFINITE;
        }
        (out, flags)
    }

    /// True if `v` is inside the window.
    #[inline]
    pub fn contains(&self, v: f32) -> bool {
        v >= self.min_v && v <= self.max_v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_and_limits() {
        let l = OutputLimits::default();
        assert!((l.slew_v_per_step - 3.0).abs() < 1e-6);
        assert_eq!(l.apply(5.0, f32::NAN), (5.0, Flags::NONFINITE));
        assert_eq!(l.apply(5.0, 9.0).0, 8.0);
        assert_eq!(
            l.apply(9.5, 20.0),
            (10.0, Flags::SLEW_LIMITED | Flags::CLAMPED)
        );
        assert_eq!(l.apply(0.5, -1.0), (0.0, Flags::CLAMPED));
        assert_eq!(l.apply(f32::NAN, f32::NAN).0, 0.0);
    }

    #[test]
    fn clamp_never_panics() {
        assert_eq!(clamp_f32(5.0, 0.0, 1.0), 1.0);
        assert_eq!(clamp_f32(-5.0, 0.0, 1.0), 0.0);
        assert_eq!(clamp_f32(f32::NAN, 0.0, 1.0), 0.0);
        assert_eq!(clamp_f32(0.5, 2.0, 1.0), 1.0);
    }

    #[test]
    fn refuses_absurd_limits() {
        let t = 20e-6;
        assert_eq!(
            OutputLimits::new(0.0, 20.0, 1e5, t),
            Err(ConfigError::BadWindow)
        );
        assert_eq!(
            OutputLimits::new(5.0, 5.0, 1e5, t),
            Err(ConfigError::BadWindow)
        );
        assert_eq!(
            OutputLimits::new(0.0, 10.0, 1e7, t),
            Err(ConfigError::BadSlew)
        );
        assert_eq!(
            OutputLimits::new(0.0, 10.0, f64::NAN, t),
            Err(ConfigError::NotFinite)
        );
        assert_eq!(
            OutputLimits::new(0.0, 10.0, 1e5, 1e-3),
            Err(ConfigError::BadRate)
        );
    }
}
