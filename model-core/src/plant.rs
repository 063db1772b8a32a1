//! The linear plant of eq. 4.4 (sec. 4.1.1) as a fixed-step simulator:
//!
//! ```text
//! G_p(s) = exp(-Td s) * 1/(s/we + 1) * K wn^2 / (s^2 + 2 zeta wn s + wn^2)
//! we = 2 pi 2000 rad/s (amplifier, "electrical"), wn = 2 pi 5792 rad/s, zeta = 0.08 (stage,
//! "inertial"), K = 0.79, Td = 85 us
//! ```
//!
//! Input: volts at the amplifier's control input. Output: sensor monitor volts.
//!
//! # Discretisation: exact for a held input
//! The state-space form (amplifier state `x1`, stage position `x2`, scaled velocity
//! `x3 = x2' / wn`, chosen so the matrix entries are of one size) is discretised by the exact
//! zero-order-hold map, in `f64` at design time ([`crate::discretize::zoh_delayed`]). The delay
//! of 4.25 samples at 50 kHz is exact too: a whole number of samples in a delay line and the
//! fraction in the input matrices (modified z-transform). The simulator therefore matches the
//! continuous plant exactly at the sample instants when driven by a DAC (which holds).
//!
//! The poles at 50 kHz lie at |z| = 0.78 (2 kHz) and 0.94 (stage), far from z = 1, so a plain
//! `f32` state update is accurate here (checked against `f64` in host-tests).

use crate::discretize::{Mat, zoh_delayed};
use crate::limits::{ConfigError, check_finite, check_period, check_range};
use crate::params;
use core::f64::consts::PI;
use core::ops::Bound::{Excluded, Included};

/// The longest delay line, samples (1.28 ms at 50 kHz; 320 us at 200 kHz). Our assumption:
/// three times the thesis' loop delay at the highest rate, with room for the model-gap
/// workflow's extra delay.
pub const MAX_DELAY_SAMPLES: usize = 64;

/// The plant's continuous parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearPlantConfig {
    /// Static gain, sensor volts per amplifier-input volt.
    pub gain: f64,
    /// Amplifier pole, Hz.
    pub amp_pole_hz: f64,
    /// Stage mode, Hz.
    pub mode_hz: f64,
    /// Stage mode damping ratio.
    pub damping: f64,
    /// Pure delay, seconds.
    pub delay_s: f64,
    /// Sample period, seconds.
    pub period_s: f64,
}

impl Default for LinearPlantConfig {
    /// Eq. 4.4 at 50 kHz.
    fn default() -> Self {
        Self {
            gain: params::PLANT_GAIN,
            amp_pole_hz: params::AMP_POLE_HZ,
            mode_hz: params::STAGE_MODE_HZ,
            damping: params::STAGE_DAMPING,
            delay_s: params::PLANT_DELAY_S,
            period_s: 1.0 / params::SAMPLE_RATE_HZ,
        }
    }
}

/// The continuous state-space matrices `(A, B)` of the plant without its delay.
pub fn continuous_state_space(c: &LinearPlantConfig) -> (Mat<3>, [f64; 3]) {
    let we = 2.0 * PI * c.amp_pole_hz;
    let wn = 2.0 * PI * c.mode_hz;
    let a = [
        [-we, 0.0, 0.0],
        [0.0, 0.0, wn],
        [c.gain * wn, -wn, -2.0 * c.damping * wn],
    ];
    (a, [we, 0.0, 0.0])
}

/// The discrete plant: configuration half.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearPlant {
    phi: [[f32; 3]; 3],
    gamma_new: [f32; 3],
    gamma_old: [f32; 3],
    delay_samples: usize,
    gain: f32,
}

impl LinearPlant {
    /// Discretise. Refuses non-finite or non-positive parameters, damping outside (0, 10],
    /// modes above the Nyquist rate, and delays longer than the delay line.
    pub fn new(c: &LinearPlantConfig) -> Result<Self, ConfigError> {
        for (name, v) in [
            ("gain", c.gain),
            ("amp_pole_hz", c.amp_pole_hz),
            ("mode_hz", c.mode_hz),
            ("damping", c.damping),
            ("delay_s", c.delay_s),
        ] {
            check_finite(name, v)?;
        }
        let t = check_period(c.period_s)?;
        let nyquist = 0.5 / t;
        check_range("gain", c.gain, Excluded(0.0), Excluded(100.0))?;
        check_range(
            "amp_pole_hz",
            c.amp_pole_hz,
            Excluded(0.0),
            Excluded(10.0 * nyquist),
        )?;
        check_range("mode_hz", c.mode_hz, Excluded(0.0), Excluded(nyquist))?;
        check_range("damping", c.damping, Excluded(0.0), Included(10.0))?;
        let delay_max = (MAX_DELAY_SAMPLES - 2) as f64 * t;
        check_range("delay_s", c.delay_s, Included(0.0), Excluded(delay_max))?;
        let (a, b) = continuous_state_space(c);
        let (phi, gn, go, d) = zoh_delayed::<3, 4>(&a, &b, t, c.delay_s);
        let f = |m: [f64; 3]| m.map(|v| v as f32);
        Ok(Self {
            phi: phi.map(f),
            gamma_new: f(gn),
            gamma_old: f(go),
            delay_samples: d,
            gain: c.gain as f32,
        })
    }

    /// Whole samples of delay in the delay line.
    pub fn delay_samples(&self) -> usize {
        self.delay_samples
    }

    /// The coefficients as a held stretch's closed form reads them ([`crate::held`]).
    pub(crate) fn section(&self) -> crate::held::Section<'_, 3> {
        crate::held::Section {
            phi: &self.phi,
            gamma_new: &self.gamma_new,
            gamma_old: &self.gamma_old,
            delay_samples: self.delay_samples,
        }
    }

    /// A state at rest with the input held at `u_v` forever (output `gain * u_v`).
    pub fn steady_state(&self, u_v: f32) -> PlantState {
        PlantState {
            x: [u_v, self.gain * u_v, 0.0],
            line: [u_v; MAX_DELAY_SAMPLES],
            head: 0,
        }
    }

    /// The output (sensor monitor volts) at the present sample.
    #[inline]
    pub fn output(&self, s: &PlantState) -> f32 {
        s.x[1]
    }

    /// Apply `u_v` (held for one sample) and advance one step; returns the new output.
    #[inline]
    pub fn step(&self, s: &mut PlantState, u_v: f32) -> f32 {
        let n = MAX_DELAY_SAMPLES;
        s.head = (s.head + 1) % n;
        s.line[s.head] = u_v;
        let u_new = s.line[(s.head + n - self.delay_samples) % n];
        let u_old = s.line[(s.head + n - self.delay_samples - 1) % n];
        let x = s.x;
        for i in 0..3 {
            s.x[i] = self.phi[i][0] * x[0]
                + self.phi[i][1] * x[1]
                + self.phi[i][2] * x[2]
                + self.gamma_new[i] * u_new
                + self.gamma_old[i] * u_old;
        }
        s.x[1]
    }
}

/// The plant's history: three states and the delay line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlantState {
    pub(crate) x: [f32; 3],
    pub(crate) line: [f32; MAX_DELAY_SAMPLES],
    pub(crate) head: usize,
}

impl PlantState {
    /// The state as a held stretch's closed form advances it ([`crate::held`]).
    pub(crate) fn section(&mut self) -> crate::held::SectionState<'_, 3, MAX_DELAY_SAMPLES> {
        crate::held::SectionState {
            x: &mut self.x,
            line: &mut self.line,
            head: &mut self.head,
        }
    }
}

impl Default for PlantState {
    fn default() -> Self {
        Self {
            x: [0.0; 3],
            line: [0.0; MAX_DELAY_SAMPLES],
            head: 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn static_gain_and_delay() {
        let p = LinearPlant::new(&LinearPlantConfig::default()).unwrap();
        assert_eq!(p.delay_samples(), 4);
        let mut s = PlantState::default();
        // Nothing moves for the 4.25 samples of delay.
        for _ in 0..4 {
            assert_eq!(p.step(&mut s, 1.0), 0.0);
        }
        let mut y = 0.0;
        for _ in 0..5000 {
            y = p.step(&mut s, 1.0);
        }
        assert!((y - params::PLANT_GAIN as f32).abs() < 1e-5, "{y}");
    }

    #[test]
    fn refuses_absurd_parameters() {
        let ok = LinearPlantConfig::default();
        assert!(LinearPlant::new(&LinearPlantConfig { delay_s: 1.0, ..ok }).is_err());
        assert!(
            LinearPlant::new(&LinearPlantConfig {
                mode_hz: 40e3,
                ..ok
            })
            .is_err()
        );
        assert!(
            LinearPlant::new(&LinearPlantConfig {
                damping: f64::NAN,
                ..ok
            })
            .is_err()
        );
    }
}
