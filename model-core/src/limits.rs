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
//!
//! The module also holds what every constructor of the crate refuses with, [`ConfigError`]
//! (which parameter, why, and the allowed range), and the design-time checks that build it:
//! [`check_finite`], [`check_range`], [`check_within`], [`check_period`].

use crate::params;
use core::ops::{Bound, RangeBounds};

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

/// Why a configuration was refused: which parameter, and what is wrong with it.
///
/// `Copy`, no allocation: the parameter is named by a `&'static str` (as its configuration
/// spells it: `"kc"`, `"period_s"`, `"taus_s"`; half of a pair as `"input_range_v.0"`; a
/// quantity derived from several, as `"weight(u)"`), and the allowed range is carried as
/// numbers in the parameter's units.
///
/// ```
/// use model_core::lag::{LagCompensator, LagConfig};
/// use model_core::limits::{ConfigError, Reason};
/// use core::ops::Bound::{Excluded, Included};
/// let e = LagCompensator::new(&LagConfig { kc: -1.0, ..LagConfig::default() }).unwrap_err();
/// assert_eq!(e.parameter, "kc");
/// assert_eq!(e.reason, Reason::OutOfRange { min: Excluded(0.0), max: Included(1e6) });
/// assert_eq!(e.to_string(), "kc must lie in (0, 1e6]");
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConfigError {
    /// The parameter refused.
    pub parameter: &'static str,
    /// What is wrong with it.
    pub reason: Reason,
}

/// What is wrong with a parameter ([`ConfigError::reason`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reason {
    /// NaN or infinite.
    NotFinite,
    /// Outside the allowed range, in the parameter's units. [`Bound::Unbounded`] for a side
    /// without a limit.
    OutOfRange {
        /// Lower end.
        min: Bound<f64>,
        /// Upper end.
        max: Bound<f64>,
    },
    /// Must be below the named parameter (the two ends of a range).
    NotBelow(&'static str),
    /// Must equal the named parameter (two blocks that share one sample period).
    Mismatch(&'static str),
    /// A table of the wrong length.
    WrongLength {
        /// Values the table must have.
        expected: usize,
        /// Values it has.
        found: usize,
    },
    /// A table or a map that must rise (or fall) monotonically does not.
    NotMonotone,
}

impl ConfigError {
    /// `parameter` refused for `reason`.
    pub const fn new(parameter: &'static str, reason: Reason) -> Self {
        Self { parameter, reason }
    }

    /// `parameter` is NaN or infinite.
    pub const fn not_finite(parameter: &'static str) -> Self {
        Self::new(parameter, Reason::NotFinite)
    }

    /// `parameter` is outside `(min, max)` with the given ends.
    pub const fn out_of_range(parameter: &'static str, min: Bound<f64>, max: Bound<f64>) -> Self {
        Self::new(parameter, Reason::OutOfRange { min, max })
    }

    /// `parameter` is outside the closed range `[min, max]`.
    pub const fn outside(parameter: &'static str, min: f64, max: f64) -> Self {
        Self::out_of_range(parameter, Bound::Included(min), Bound::Included(max))
    }

    /// `parameter` must be below `other`.
    pub const fn not_below(parameter: &'static str, other: &'static str) -> Self {
        Self::new(parameter, Reason::NotBelow(other))
    }
}

/// A bound's number: plain for ordinary magnitudes, exponent notation for very large or small.
fn write_number(f: &mut core::fmt::Formatter<'_>, v: f64) -> core::fmt::Result {
    let a = v.abs();
    if a != 0.0 && !(1e-2..1e5).contains(&a) {
        write!(f, "{v:e}")
    } else {
        write!(f, "{v}")
    }
}

impl core::fmt::Display for Reason {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::NotFinite => f.write_str("must be finite"),
            Self::OutOfRange { min, max } => {
                f.write_str("must lie in ")?;
                match min {
                    Bound::Included(v) => {
                        f.write_str("[")?;
                        write_number(f, v)?;
                    }
                    Bound::Excluded(v) => {
                        f.write_str("(")?;
                        write_number(f, v)?;
                    }
                    Bound::Unbounded => f.write_str("(-inf")?,
                }
                f.write_str(", ")?;
                match max {
                    Bound::Included(v) => {
                        write_number(f, v)?;
                        f.write_str("]")
                    }
                    Bound::Excluded(v) => {
                        write_number(f, v)?;
                        f.write_str(")")
                    }
                    Bound::Unbounded => f.write_str("inf)"),
                }
            }
            Self::NotBelow(other) => write!(f, "must be below {other}"),
            Self::Mismatch(other) => write!(f, "must equal {other}"),
            Self::WrongLength { expected, found } => {
                write!(f, "must have {expected} values, not {found}")
            }
            Self::NotMonotone => f.write_str("must be monotone"),
        }
    }
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{} {}", self.parameter, self.reason)
    }
}

impl core::error::Error for ConfigError {}

/// `value` if it is finite, else [`Reason::NotFinite`] for `parameter`. Design time.
pub fn check_finite(parameter: &'static str, value: f64) -> Result<f64, ConfigError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(ConfigError::not_finite(parameter))
    }
}

/// `value` if it is finite and inside `(min, max)` with the given ends, else the error naming
/// `parameter`. Design time.
///
/// ```
/// use model_core::limits::check_range;
/// use core::ops::Bound::{Excluded, Included};
/// assert_eq!(check_range("gain", 2.0, Excluded(0.0), Included(10.0)), Ok(2.0));
/// let e = check_range("gain", 0.0, Excluded(0.0), Included(10.0)).unwrap_err();
/// assert_eq!(e.to_string(), "gain must lie in (0, 10]");
/// ```
pub fn check_range(
    parameter: &'static str,
    value: f64,
    min: Bound<f64>,
    max: Bound<f64>,
) -> Result<f64, ConfigError> {
    check_finite(parameter, value)?;
    if (min, max).contains(&value) {
        Ok(value)
    } else {
        Err(ConfigError::out_of_range(parameter, min, max))
    }
}

/// [`check_range`] on the closed range `[min, max]`.
pub fn check_within(
    parameter: &'static str,
    value: f64,
    min: f64,
    max: f64,
) -> Result<f64, ConfigError> {
    check_range(parameter, value, Bound::Included(min), Bound::Included(max))
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
/// The error names `"period_s"` and gives the allowed periods, seconds.
pub fn check_period(period_s: f64) -> Result<f64, ConfigError> {
    check_finite("period_s", period_s)?;
    let rate = 1.0 / period_s;
    // A small tolerance so that 1/50e3 round trips.
    if !(params::MIN_SAMPLE_RATE_HZ * (1.0 - 1e-9)..=params::MAX_SAMPLE_RATE_HZ * (1.0 + 1e-9))
        .contains(&rate)
    {
        return Err(ConfigError::outside(
            "period_s",
            1.0 / params::MAX_SAMPLE_RATE_HZ,
            1.0 / params::MIN_SAMPLE_RATE_HZ,
        ));
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
        check_finite("min_v", min_v)?;
        check_finite("max_v", max_v)?;
        check_finite("slew_v_per_s", slew_v_per_s)?;
        let period_s = check_period(period_s)?;
        let (lo, hi) = (params::AMP_INPUT_MIN_V, params::AMP_INPUT_MAX_V);
        check_within("min_v", min_v, lo, hi)?;
        check_within("max_v", max_v, lo, hi)?;
        if min_v >= max_v {
            return Err(ConfigError::not_below("min_v", "max_v"));
        }
        if !(slew_v_per_s > 0.0 && slew_v_per_s <= params::AMP_SLEW_INPUT_V_PER_S * (1.0 + 1e-9)) {
            return Err(ConfigError::out_of_range(
                "slew_v_per_s",
                Bound::Excluded(0.0),
                Bound::Included(params::AMP_SLEW_INPUT_V_PER_S),
            ));
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
    fn errors_name_the_parameter_and_the_range() {
        let e = OutputLimits::new(0.0, 20.0, 1e5, 20e-6).unwrap_err();
        println!("{e}");
        assert_eq!(e.to_string(), "max_v must lie in [-2, 12]");
        let e = check_period(1e-3).unwrap_err();
        println!("{e}");
        assert_eq!(e.to_string(), "period_s must lie in [5e-6, 1e-4]");
        let e = check_range("at_s", -1.0, Bound::Included(0.0), Bound::Unbounded).unwrap_err();
        assert_eq!(e.to_string(), "at_s must lie in [0, inf)");
        assert_eq!(
            ConfigError::not_finite("kc").to_string(),
            "kc must be finite"
        );
        assert_eq!(
            ConfigError::not_below("min_v", "max_v").to_string(),
            "min_v must be below max_v"
        );
        let e = ConfigError::new(
            "everett_v",
            Reason::WrongLength {
                expected: 990,
                found: 5,
            },
        );
        assert_eq!(e.to_string(), "everett_v must have 990 values, not 5");
        let boxed: &dyn core::error::Error = &e;
        assert!(boxed.source().is_none());
    }

    #[test]
    fn refuses_absurd_limits() {
        let t = 20e-6;
        assert_eq!(
            OutputLimits::new(0.0, 20.0, 1e5, t),
            Err(ConfigError::outside("max_v", -2.0, 12.0))
        );
        assert_eq!(
            OutputLimits::new(5.0, 5.0, 1e5, t),
            Err(ConfigError::not_below("min_v", "max_v"))
        );
        assert_eq!(
            OutputLimits::new(0.0, 10.0, 1e7, t),
            Err(ConfigError::out_of_range(
                "slew_v_per_s",
                Bound::Excluded(0.0),
                Bound::Included(1.5e5)
            ))
        );
        assert_eq!(
            OutputLimits::new(0.0, 10.0, f64::NAN, t),
            Err(ConfigError::not_finite("slew_v_per_s"))
        );
        assert_eq!(
            OutputLimits::new(0.0, 10.0, 1e5, 1e-3),
            Err(ConfigError::outside("period_s", 5e-6, 1e-4))
        );
    }
}
