//! The reference pre-filter of the two-degree-of-freedom loop (sec. 4.1.2.4, eq. 4.8-4.13):
//!
//! ```text
//! T(s)  = L / (1 + L),   L = G_p G_c = exp(-Td s) G(s),   G = G'_p G_c (delay-free)
//! H(s)  = 1 / T(s) = 1 + exp(+Td s) / G(s)                 (four more zeros than poles)
//! H'(s) = H(s) / (tau s + 1)^4                             (bi-proper)
//! ```
//!
//! The loop driven by `H' r` follows `r / (tau s + 1)^4`: the reference "planned" by four
//! fast poles, whose derivatives the inverse needs.
//!
//! # Derived at run time, never typed in
//! [`PreFilter::new`] takes the compensator's and the plant's own configurations
//! ([`LagConfig`], [`LinearPlantConfig`]) and `tau`; changing `Kc`, the plant or the rate
//! re-derives every coefficient. The inverse loop is already factored, because `G` is a
//! product of known factors:
//!
//! ```text
//! 1/G(s) = [ s / (s + z) ] * [ (s/p + 1) / (Kc K) ] * (s/we + 1) * (s^2/wn^2 + 2 zeta s/wn + 1)
//! ```
//!
//! so no polynomial is ever expanded (the expanded polynomials of this loop span 25 decades
//! and are ill-conditioned) and no root finder is needed. Each factor takes one or two of the
//! four planning poles and becomes a bi-proper section:
//!
//! ```text
//! S_hp   = s / (s + z)                                    zero at s = 0, pole at -1 rad/s
//! S_lag  = (s/p + 1) / ((tau s + 1) Kc K)                 zero at -0.398 rad/s
//! S_amp  = (s/we + 1) / (tau s + 1)
//! S_mode = (s^2/wn^2 + 2 zeta s/wn + 1) / (tau s + 1)^2
//! F      = 1 / (tau s + 1)^4                              four first-order sections
//! H'     = F exp(-Td s) (delayed, see below)  +  S_hp S_lag S_amp S_mode
//! ```
//!
//! # Discretisation: Tustin, sections in delta form
//! Each section is mapped by Tustin's substitution `s = (2/T)(z - 1)/(z + 1)` at the loop rate.
//! Tustin is the discretisation the compensator itself uses ([`crate::lag`]), and Tustin is a
//! substitution, so `S_hp S_lag` is the *exact* inverse of the discrete compensator `C(z)`
//! (times the planning poles), not an approximation of it. Its warp is 0.1 % at the 3000
//! rad/s crossover and 4 % on the 5.8 kHz stage mode, whose inverse weighs only
//! `(w/wn)^2 = 3e-4` at 100 Hz: no pre-warping.
//!
//! The integrator of `G_c` becomes a zero at z = 1 and the lag zero (1 rad/s) a pole at
//! `1 - 2e-5`; the lag pole (0.398 rad/s) a zero at `1 - 8e-6`. A direct form in `f32` would
//! lose them (the spacing of `f32` near 1 is 6e-8). Every section is therefore one of the
//! delta-form sections of [`crate::sections`], the family the compensator is built from:
//! [`FirstOrder`] for `(c1 s + c0)/(d1 s + d0)`,
//!
//! ```text
//! y[n] = y[n-1] + bd (x[n] - x[n-1]) + bs (x[n] + x[n-1]) - alpha y[n-1]
//! bd = (2 c1/T) / D,  bs = c0 / D,  alpha = 2 d0 / D,  D = 2 d1/T + d0
//! ```
//!
//! where a zero at z = 1 is `bs = 0` exactly, a zero near 1 is the ratio of `bd` and `bs`,
//! each to full `f32` precision, and `alpha = 1 - a` is computed without cancellation. The
//! section whose pole is near z = 1 (`S_hp`) keeps its output in an [`Accumulator`], the others
//! (poles at `(2 tau - T)/(2 tau + T) = 0.67`) in plain `f32`. The stage-mode section,
//! `S_mode`, is a [`SecondOrder`] section (the same form one order up) on plain `f32`: it has no
//! pole or zero near z = 1 (double pole at `(2 tau - T)/(2 tau + T)`, zeros at `|z| = 0.94`), so
//! the form buys it little (1.6e-7 of its peak against 8e-7 for an `f32` direct form I, for 11
//! instructions more per step), but one form serves every section.
//!
//! # The delay: decided and measured
//! `exp(+Td s)` in the inverse is an advance: not causal. Alternatives ([`DelayHandling`]),
//! measured in the closed-loop simulation (host-tests `tests/prefilter.rs`, `delay_alternatives`:
//! 6 V p-p around 4 V, tau = 50 us, 50 kHz, ADC/DAC quantisation, 1 mV sensor noise):
//!
//! ```text
//! delay handling     sine 100 Hz rms   triangle 100 Hz rms   triangle 300 Hz rms   1 V step overshoot
//! Drop                    21.2 mV             42.0 mV              217.2 mV              21.3 %
//! Preview (Td)             1.6 mV              9.1 mV               46.9 mV               1.9 %
//! PreviewWithHold          4.2 mV             11.3 mV               58.2 mV               0.1 %
//! (feedback alone        425.4 mV            377.4 mV             1105.1 mV               7.9 %)
//! ```
//!
//! * **Drop it** (`1/T ~ 1 + 1/G`): the inverse of a loop without delay. 5x worse than
//!   shifting it, and a 21 % step overshoot: the 85 us are 0.27 rad of phase at 500 Hz.
//! * **Pade**: a Pade approximant of the *advance* `exp(+Td s)` has its poles in the right
//!   half plane (first order: a pole at `+2/Td = +23500 rad/s`), so `H'` would be unstable.
//!   Rejected without a run: there is nothing stable to measure. (A Pade of the delay in `L`
//!   puts the same unstable pole into `1/L`.)
//! * **Shift the delay into the preview**: `H' = exp(+Td s) F (exp(-Td s) + 1/G)`. The factor
//!   `exp(+Td s)` is the reference generator's advance (preview); what remains is causal: the
//!   planned reference `F r` is *delayed* by `Td` on the direct branch, and the inverse branch
//!   `F/G` has no delay. The delay is realised exactly in whole samples (a delay line) plus a
//!   linear interpolation for the fraction (its error on `F r`, band-limited by the four
//!   poles, is below `(wT)^2 frac (1 - frac)/2 = 1.5e-5` at 100 Hz).
//! * **Shift the delay and the hold** (`PreviewWithHold`, **the default**): the sampled loop's
//!   `L(z)` is `L(s)` behind the DAC's zero-order hold, whose average delay is `T/2`, so the
//!   shifted delay is `Td + T/2` (4.75 samples at 50 kHz). With it the loop follows `F r`
//!   exactly up to terms of order `(wT)^2`: the measured 100 Hz sine error, 4.25 mV rms, is the
//!   planning filter's own magnitude droop, `3 V * 2 (w tau)^2 / sqrt 2 = 4.19 mV`, to 0.06 mV.
//!   `Preview` (Td alone) measures lower on sines because the uninverted half sample happens to
//!   cancel part of that droop (both go as `w^2`; the balance depends on `Kc` and tau), but it
//!   pays with 1.9 % of step overshoot, at the 2 % limit; the default keeps it at 0.1 %.
//!
//! **Sampling zeros.** The exact inverse of the sampled loop `T(z)` would have to invert the
//! sampling zeros of the ZOH plant (relative degree 3 plus 0.25 sample of fractional delay:
//! three zeros, one outside the unit circle near z = -3), ZPETC-style with a root finder at
//! design time. This design never places them: it inverts the continuous plant and the hold
//! as `T/2`, so every pole of `H'` is one of the four planning poles or the image of the lag
//! zero, stable by construction at any `Kc`, rate or plant. The price, the uninverted `(wT)^2`
//! terms, is the 0.06 mV above: at 100 Hz an exact sampled inverse could not do better, since
//! what remains is the planning itself.
//!
//! # Preview and lag
//! The pre-filter's output follows `r` late by `Td' + 4 tau` (`Td' = Td + T/2` with the
//! default delay handling): `4 tau` is the low-frequency group delay of `F`.
//! [`PreFilter::preview_samples`] is that lag rounded up to whole samples, `K`; the remaining
//! fraction `K - lag` delays the input by linear interpolation so the total is exactly `K`
//! samples. When the reference is generated on board,
//! [`crate::reference::ReferenceGenerator`] hands the pre-filter the reference `K` samples
//! ahead and the stage follows `r` itself. Without preview (an external reference) the filter
//! works unchanged and the stage follows `r` delayed by `K` samples: 15 samples = 300 us at
//! 50 kHz with tau = 50 us (a phase lag of 10.8 deg at 100 Hz; the shape is tracked as well
//! as with preview, only late).
//!
//! # Choice of tau
//! Criterion: the smallest tau whose pre-filter amplifies white noise on the reference by at
//! most about 2 (`|H'|` at Nyquist and its RMS gain over the band; this matters for an
//! external reference read by an ADC, and it is the high-frequency content the DAC command
//! gets from the reference), while the command of a 6 V p-p 300 Hz triangle stays inside the
//! 0..10 V window and far below the 3 V/sample slew limit. Sensor noise does not constrain tau:
//! the pre-filter acts on the reference, never on the measurement. Measured (`tau_trade_off`):
//!
//! ```text
//! tau us   sine 100 Hz   tri 100 Hz   tri 300 Hz   command tri 300   slew V/ms   |H'(Nyquist)|   noise gain
//!   20       0.78 mV       3.1 mV       15.7 mV     1.27..8.86 V       6.8          59.7           46.9
//!   30       1.59          5.4          27.7        1.40..8.72         5.3          11.8           10.5
//!   50       4.25         11.3          58.2        1.54..8.59         4.6           1.53           1.64
//!   75       9.46         20.5         106.4        1.73..8.40         4.6           0.30           0.48
//!  100      16.7          31.5         163.4        1.92..8.21         4.6           0.10           0.26
//!  200      65.7          88.8         458.8        2.64..7.49         4.4           0.01           0.13
//! ```
//!
//! The sine error goes like `tau^2` (the droop of `F`), the triangle's like `tau` (its
//! corners are rounded over about `8 tau`); the noise gain like `tau^-4`. 50 us is the smallest
//! value in the table with a noise gain below 2 ([`params::PREFILTER_TAU_S`]); it leaves a
//! 100x cut of the sine error and 34x of the triangle's at 100 Hz.
//!
//! # Measured tracking
//! The tracking table (feedback alone, planning only, full pre-filter; sines and triangles at
//! 10, 100 and 300 Hz) is measured by `piezo track` on the one closed-loop harness and kept in
//! one place: `host-tests/README.md`, "Tracking". Test
//! `full_prefilter_cuts_the_error_tenfold_at_100_hz` holds the tenfold cut.
//!
//! # Cost
//! Per sample: 8 first-order sections (one with a compensated sum), one second-order section,
//! one delay-line read with interpolation: about 30 multiplies and 60 additions, a dependent
//! chain through 8 sections.
//! Measured on the host by `benches/prefilter.rs` (criterion) and on the Cortex-M by
//! `piezo qemu bench` (instructions per step): the figures are in `host-tests/README.md` and
//! `firmware/qemu/README.md`.
//!
//! # Example
//! ```
//! use model_core::lag::LagConfig;
//! use model_core::plant::LinearPlantConfig;
//! use model_core::prefilter::{PreFilter, PreFilterConfig};
//! let pf = PreFilter::new(&LagConfig::default(), &LinearPlantConfig::default(),
//!                         &PreFilterConfig::default()).unwrap();
//! assert_eq!(pf.preview_samples(), 15); // (85 us + 10 us + 4 * 50 us) / 20 us, rounded up
//! let mut s = pf.settled_state(4.0);
//! let v = pf.step(&mut s, 4.0);
//! assert!((v - 4.0).abs() < 1e-5); // at rest at DC the filter passes the reference
//! ```

use crate::lag::{LagCompensator, LagConfig};
use crate::limits::{ConfigError, Reason, check_period, check_within};
use crate::params;
use crate::plant::{LinearPlant, LinearPlantConfig};
use crate::sections::{Accumulator, FirstOrder, FirstOrderState, SecondOrder, SecondOrderState};
use core::f64::consts::PI;
use core::ops::Bound::{Excluded, Included};

/// Length of the direct branch's delay line, samples.
const LINE: usize = 64;

/// What the pre-filter does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PreFilterMode {
    /// Pass the reference through unchanged (feedback alone; no preview).
    Off,
    /// Trajectory planning only: `r / (tau s + 1)^4`, with `4 tau` of preview.
    Planning,
    /// The full pre-filter `H'`.
    Full,
}

/// How the inverse's `exp(+Td s)` is handled (see the module's design note).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DelayHandling {
    /// Ignore the loop delay in the inverse.
    Drop,
    /// Shift `exp(+Td s)` into the preview.
    Preview,
    /// Shift `exp(+(Td + T/2) s)` into the preview: the delay plus the DAC hold's `T/2`.
    PreviewWithHold,
}

/// The pre-filter's own parameters; the loop's come from its [`LagConfig`] and
/// [`LinearPlantConfig`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreFilterConfig {
    /// Time constant of the four planning poles, seconds.
    pub tau_s: f64,
    /// What the filter does.
    pub mode: PreFilterMode,
    /// How the loop delay is inverted.
    pub delay: DelayHandling,
}

impl Default for PreFilterConfig {
    /// The full pre-filter with `tau = 50 us`, the loop delay and the DAC hold's half sample
    /// shifted into the preview (see the design note for why).
    fn default() -> Self {
        Self {
            tau_s: params::PREFILTER_TAU_S,
            mode: PreFilterMode::Full,
            delay: DelayHandling::PreviewWithHold,
        }
    }
}

/// The discrete pre-filter: configuration half (`Copy`, built outside the interrupt).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreFilter {
    mode: PreFilterMode,
    preview: u32,
    /// Fraction of a sample the input is delayed by (`K - lag`), in `[0, 1)`.
    in_frac: f32,
    plan: FirstOrder,
    direct_whole: usize,
    direct_frac: f32,
    hp: FirstOrder,
    lag: FirstOrder,
    amp: FirstOrder,
    stage: SecondOrder,
}

/// The pre-filter's history: the state half.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreFilterState {
    r_prev: f32,
    plan: [FirstOrderState; 4],
    line: [f32; LINE],
    head: usize,
    hp: FirstOrderState<Accumulator>,
    lag: FirstOrderState,
    amp: FirstOrderState,
    stage: SecondOrderState,
    last: f32,
}

impl PreFilter {
    /// Derive the pre-filter of the loop made of `lag` and `plant` (which must share their
    /// sample period). Refuses what [`LagCompensator::new`] or [`LinearPlant::new`] refuse,
    /// different periods (`"plant.period_s"`, [`Reason::Mismatch`]), a non-finite tau, and tau
    /// outside `params::PREFILTER_TAU_MIN_S..=PREFILTER_TAU_MAX_S` or too long for the
    /// preview (`"tau_s"`, [`Reason::OutOfRange`]).
    ///
    /// ```
    /// use model_core::lag::LagConfig;
    /// use model_core::plant::LinearPlantConfig;
    /// use model_core::prefilter::{PreFilter, PreFilterConfig};
    /// let lag = LagConfig { kc: 8000.0, ..LagConfig::default() };
    /// let pf = PreFilter::new(&lag, &LinearPlantConfig::default(), &PreFilterConfig::default());
    /// assert!(pf.is_ok());
    /// let bad = PreFilterConfig { tau_s: f64::NAN, ..PreFilterConfig::default() };
    /// assert!(PreFilter::new(&lag, &LinearPlantConfig::default(), &bad).is_err());
    /// ```
    pub fn new(
        lag: &LagConfig,
        plant: &LinearPlantConfig,
        config: &PreFilterConfig,
    ) -> Result<Self, ConfigError> {
        LagCompensator::new(lag)?;
        LinearPlant::new(plant)?;
        let t = check_period(lag.period_s)?;
        if (plant.period_s - t).abs() > 1e-9 * t {
            return Err(ConfigError::new(
                "plant.period_s",
                Reason::Mismatch("lag.period_s"),
            ));
        }
        let tau = check_within(
            "tau_s",
            config.tau_s,
            params::PREFILTER_TAU_MIN_S,
            params::PREFILTER_TAU_MAX_S,
        )?;
        let delay_s = match (config.mode, config.delay) {
            (PreFilterMode::Full, DelayHandling::Preview) => plant.delay_s,
            (PreFilterMode::Full, DelayHandling::PreviewWithHold) => plant.delay_s + 0.5 * t,
            _ => 0.0,
        };
        let lag_samples = match config.mode {
            PreFilterMode::Off => 0.0,
            _ => (delay_s + 4.0 * tau) / t,
        };
        // Bounded: tau <= 1 ms and the plant's delay < 62 samples keep this far below u32.
        let preview = libm_ceil(lag_samples - 1e-9);
        if preview > params::MAX_PREVIEW_SAMPLES as f64 {
            // The preview would be longer than a generator offers: the longest tau that fits.
            let tau_max = (params::MAX_PREVIEW_SAMPLES as f64 * t - delay_s) / 4.0;
            return Err(ConfigError::outside(
                "tau_s",
                params::PREFILTER_TAU_MIN_S,
                tau_max,
            ));
        }
        let direct = delay_s / t;
        let direct_whole = (direct + 1e-9) as usize;
        if direct_whole + 1 >= LINE {
            // The direct branch's delay line is too short: the longest delay it holds.
            let delay_max = (LINE - 1) as f64 * t - (delay_s - plant.delay_s);
            return Err(ConfigError::out_of_range(
                "plant.delay_s",
                Included(0.0),
                Excluded(delay_max),
            ));
        }
        let we = 2.0 * PI * plant.amp_pole_hz;
        let wn = 2.0 * PI * plant.mode_hz;
        let kck = lag.kc * plant.gain;
        Ok(Self {
            mode: config.mode,
            preview: preview as u32,
            in_frac: (preview - lag_samples).clamp(0.0, 1.0) as f32,
            plan: FirstOrder::tustin([0.0, 1.0], [tau, 1.0], t),
            direct_whole,
            direct_frac: (direct - direct_whole as f64).clamp(0.0, 1.0) as f32,
            hp: FirstOrder::tustin([1.0, 0.0], [1.0, lag.zero_rad_s], t),
            lag: FirstOrder::tustin([1.0 / (lag.pole_rad_s * kck), 1.0 / kck], [tau, 1.0], t),
            amp: FirstOrder::tustin([1.0 / we, 1.0], [tau, 1.0], t),
            stage: SecondOrder::tustin(
                [1.0 / (wn * wn), 2.0 * plant.damping / wn, 1.0],
                [tau * tau, 2.0 * tau, 1.0],
                t,
            ),
        })
    }

    /// Samples of preview the filter wants: the reference generator should hand
    /// [`Self::step`] the reference this many samples ahead. Without it the stage follows the
    /// reference this many samples late. 0 when [`PreFilterMode::Off`].
    pub fn preview_samples(&self) -> u32 {
        self.preview
    }

    /// The mode the filter was built with.
    pub fn mode(&self) -> PreFilterMode {
        self.mode
    }

    /// A state at rest with a constant reference `r_v` for ever (output `r_v`).
    pub fn settled_state(&self, r_v: f32) -> PreFilterState {
        let r = if r_v.is_finite() { r_v } else { 0.0 };
        let p = self.plan.settled(r);
        PreFilterState {
            r_prev: r,
            plan: [p; 4],
            line: [r; LINE],
            head: 0,
            hp: self.hp.settled(r),
            lag: self.lag.settled(0.0),
            amp: self.amp.settled(0.0),
            stage: self.stage.settled(0.0),
            last: r,
        }
    }

    /// One sample: the (previewed) reference in, the reference for the loop out, volts.
    /// A non-finite input holds the last output; should the states ever overflow, the filter
    /// restarts at rest at the present input.
    #[inline]
    pub fn step(&self, s: &mut PreFilterState, r_v: f32) -> f32 {
        if !r_v.is_finite() {
            return s.last;
        }
        if self.mode == PreFilterMode::Off {
            s.last = r_v;
            return r_v;
        }
        let x = r_v - self.in_frac * (r_v - s.r_prev);
        s.r_prev = r_v;
        let mut f = x;
        for st in s.plan.iter_mut() {
            f = self.plan.step(st, f);
        }
        let out = if self.mode == PreFilterMode::Planning {
            f
        } else {
            s.head = (s.head + 1) % LINE;
            s.line[s.head] = f;
            // direct_whole + 1 < LINE (checked in `new`), and `%` keeps the indices in range.
            let a = s.line[(s.head + LINE - self.direct_whole) % LINE];
            let b = s.line[(s.head + LINE - self.direct_whole - 1) % LINE];
            let direct = a + self.direct_frac * (b - a);
            let h = self.hp.step(&mut s.hp, x);
            let g = self.lag.step(&mut s.lag, h);
            let e = self.amp.step(&mut s.amp, g);
            direct + self.stage.step(&mut s.stage, e)
        };
        if out.is_finite() {
            s.last = out;
            out
        } else {
            *s = self.settled_state(r_v);
            r_v
        }
    }
}

/// `ceil` for the design-time `f64` without `std` (inputs here are small and non-negative).
fn libm_ceil(x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let t = x as u64 as f64;
    if t < x { t + 1.0 } else { t }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pf(mode: PreFilterMode) -> PreFilter {
        let c = PreFilterConfig {
            mode,
            ..PreFilterConfig::default()
        };
        PreFilter::new(&LagConfig::default(), &LinearPlantConfig::default(), &c).unwrap()
    }

    #[test]
    fn preview_follows_the_lag() {
        assert_eq!(pf(PreFilterMode::Off).preview_samples(), 0);
        assert_eq!(pf(PreFilterMode::Planning).preview_samples(), 10);
        assert_eq!(pf(PreFilterMode::Full).preview_samples(), 15);
    }

    #[test]
    fn passes_dc_and_holds_on_nan() {
        let p = pf(PreFilterMode::Full);
        let mut s = p.settled_state(3.0);
        let mut v = 0.0;
        for _ in 0..1000 {
            v = p.step(&mut s, 3.0);
        }
        assert!((v - 3.0).abs() < 1e-5, "{v}");
        assert_eq!(p.step(&mut s, f32::NAN), v);
    }

    #[test]
    fn refuses_bad_configurations() {
        let lag = LagConfig::default();
        let plant = LinearPlantConfig::default();
        for tau in [0.0, -1.0, 1e-7, 1.0, f64::INFINITY] {
            let c = PreFilterConfig {
                tau_s: tau,
                ..PreFilterConfig::default()
            };
            assert!(PreFilter::new(&lag, &plant, &c).is_err(), "{tau}");
        }
        let other_rate = LinearPlantConfig {
            period_s: 1e-5,
            ..plant
        };
        let c = PreFilterConfig::default();
        assert_eq!(
            PreFilter::new(&lag, &other_rate, &c),
            Err(ConfigError::new(
                "plant.period_s",
                Reason::Mismatch("lag.period_s")
            ))
        );
    }
}
