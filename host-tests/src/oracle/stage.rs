//! `f64` reference of the composed stage (ch. 6), with the linear dynamics written as
//! continuous differential equations and integrated by classical Runge-Kutta at 40 sub-steps
//! per sample (error far below `f32` resolution), instead of model-core's exact discretisation:
//!
//! ```text
//! p' = we (d(t - Td) - p)                       amplifier pole (2 kHz)
//! x'' + 2 zeta wn x' + wn^2 x = wn^2 p           stage mode
//! z'' + 2 z2 w2 z' + w2^2 z = w2^2 x             optional second mode (continuous here)
//! ```
//! `d` is the static map (amplifier limits, `0.79 K'(ue) ue`, drift), held over each sample
//! and delayed by `Td`; the delay must be a multiple of `T/40` (85 us at 50 kHz is 170
//! sub-steps). Converters and noise are left out except the DAC, applied by rounding.

use super::amplifier::AmplifierRef;
use super::drift::DriftRef;
use super::gain::fast_output;
use model_core::params;
use std::collections::VecDeque;
use std::f64::consts::PI;

/// Switches of the reference.
#[derive(Clone, Copy, Debug)]
pub struct RefSwitches {
    /// DAC rounding.
    pub dac: bool,
    /// Drift.
    pub drift: bool,
    /// K'(u).
    pub nonlinear_gain: bool,
    /// Second mode (Hz, damping).
    pub second_mode: Option<(f64, f64)>,
}

/// The reference stage.
pub struct StageRef {
    sw: RefSwitches,
    amp: AmplifierRef,
    drift: DriftRef,
    period_s: f64,
    sub: usize,
    delay_sub: usize,
    /// Held static input per sub-step, oldest first.
    line: VecDeque<f64>,
    /// States p, x, x', z, z'.
    s: [f64; 5],
}

const SUB: usize = 40;

impl StageRef {
    /// At rest with `u0` held, at the thesis' 50 kHz.
    pub fn new(sw: RefSwitches, u0: f64) -> Self {
        let period_s = params::STAGE_PERIOD_S;
        let delay_sub = (params::PLANT_DELAY_S / period_s * SUB as f64).round() as usize;
        let mut r = Self {
            sw,
            amp: AmplifierRef::thesis(period_s),
            drift: DriftRef::thesis(period_s),
            period_s,
            sub: SUB,
            delay_sub,
            line: VecDeque::new(),
            s: [0.0; 5],
        };
        let u0 = r.dac(u0);
        r.amp.out_v = r.amp.target(u0);
        let ue = r.amp.out_v / params::AMP_GAIN;
        let mut d = r.fast(ue);
        if sw.drift {
            r.drift.settle(ue);
            d += r.drift.y.iter().sum::<f64>();
        }
        r.line = std::iter::repeat_n(d, delay_sub + 1).collect();
        r.s = [d, d, 0.0, d, 0.0];
        r
    }

    fn dac(&self, u: f64) -> f64 {
        if !self.sw.dac {
            return u;
        }
        let lsb = 20.0 / 16384.0;
        (u / lsb).round().clamp(-8192.0, 8191.0) * lsb
    }

    fn fast(&self, ue: f64) -> f64 {
        if self.sw.nonlinear_gain {
            fast_output(ue)
        } else {
            params::PLANT_GAIN * ue
        }
    }

    fn deriv(&self, s: &[f64; 5], d: f64) -> [f64; 5] {
        let we = 2.0 * PI * params::AMP_POLE_HZ;
        let wn = 2.0 * PI * params::STAGE_MODE_HZ;
        let z = params::STAGE_DAMPING;
        let mut out = [
            we * (d - s[0]),
            s[2],
            wn * wn * (s[0] - s[1]) - 2.0 * z * wn * s[2],
            0.0,
            0.0,
        ];
        if let Some((f2, z2)) = self.sw.second_mode {
            let w2 = 2.0 * PI * f2;
            out[3] = s[4];
            out[4] = w2 * w2 * (s[1] - s[3]) - 2.0 * z2 * w2 * s[4];
        }
        out
    }

    /// One sample with command `u_v`; returns the position (sensor volts, no noise).
    pub fn step(&mut self, u_v: f64) -> f64 {
        let u = self.dac(u_v);
        let v = self.amp.step(u);
        let ue = v / params::AMP_GAIN;
        let mut d = self.fast(ue);
        if self.sw.drift {
            d += self.drift.step(ue);
        }
        let h = self.period_s / self.sub as f64;
        for _ in 0..self.sub {
            self.line.push_back(d);
            // The input in force now is the one pushed `delay_sub` sub-steps ago.
            let din = self.line[self.line.len() - 1 - self.delay_sub];
            while self.line.len() > self.delay_sub + 1 {
                self.line.pop_front();
            }
            let s = self.s;
            let add = |a: &[f64; 5], k: &[f64; 5], f: f64| -> [f64; 5] {
                std::array::from_fn(|i| a[i] + f * k[i])
            };
            let k1 = self.deriv(&s, din);
            let k2 = self.deriv(&add(&s, &k1, h / 2.0), din);
            let k3 = self.deriv(&add(&s, &k2, h / 2.0), din);
            let k4 = self.deriv(&add(&s, &k3, h), din);
            self.s = std::array::from_fn(|i| {
                s[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            });
        }
        if self.sw.second_mode.is_some() {
            self.s[3]
        } else {
            self.s[1]
        }
    }

    /// The amplifier output, volts.
    pub fn amplifier_v(&self) -> f64 {
        self.amp.out_v
    }
}
