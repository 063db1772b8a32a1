//! `f64` reference of the discrete pre-filter (eq. 4.12), written from the transfer functions,
//! not from model-core's sections: the frequency response is evaluated directly as
//!
//! ```text
//! H'(z) = I(z) F(s_z) [ z^-d (1 - f + f z^-1) + 1/G(s_z) ],   s_z = (2/T)(z - 1)/(z + 1)
//! 1/G(s) = s (s/p + 1) (s/we + 1) (s^2/wn^2 + 2 zeta s/wn + 1) / (Kc K (s + z_c)),  F = 1/(tau s + 1)^4
//! ```
//!
//! with `d + f = Td/T` (or `(Td + T/2)/T` with the hold) the shifted delay (whole samples plus a linearly interpolated
//! fraction) and `I(z) = 1 - delta + delta z^-1` the input's fractional delay that makes the
//! total lag `K = ceil((Td + 4 tau)/T)` whole samples. The time response comes from the
//! frequency response by an inverse FFT (impulse response), so it too is independent of any
//! recursion.
use model_core::params;
use rustfft::FftPlanner;
use rustfft::num_complex::Complex64;
use std::f64::consts::PI;

/// The loop and pre-filter parameters, in continuous form.
#[derive(Clone, Copy, Debug)]
pub struct RefPreFilter {
    /// Compensator gain.
    pub kc: f64,
    /// Lag zero, rad/s.
    pub zero_rad_s: f64,
    /// Lag pole, rad/s.
    pub pole_rad_s: f64,
    /// Plant gain.
    pub gain: f64,
    /// Amplifier pole, rad/s.
    pub we: f64,
    /// Stage mode, rad/s.
    pub wn: f64,
    /// Stage damping.
    pub zeta: f64,
    /// Delay shifted into the preview, seconds (Td, or Td + T/2 with the hold).
    pub shifted_delay_s: f64,
    /// Planning time constant, seconds.
    pub tau_s: f64,
    /// Sample period, seconds.
    pub period_s: f64,
}

impl RefPreFilter {
    /// The thesis loop (eq. 4.4, 4.5) at 50 kHz with planning time constant `tau_s`.
    pub fn thesis(tau_s: f64) -> Self {
        // The thesis numbers from the one parameters module; the maths below is this file's own.
        let t = 1.0 / params::SAMPLE_RATE_HZ;
        Self {
            kc: params::LAG_KC,
            zero_rad_s: params::LAG_ZERO_RAD_S,
            pole_rad_s: params::LAG_POLE_RAD_S,
            gain: params::PLANT_GAIN,
            we: 2.0 * PI * params::AMP_POLE_HZ,
            wn: 2.0 * PI * params::STAGE_MODE_HZ,
            zeta: params::STAGE_DAMPING,
            shifted_delay_s: params::PLANT_DELAY_S,
            tau_s,
            period_s: t,
        }
    }

    /// The same with the DAC hold's half sample added to the shifted delay.
    pub fn with_hold(mut self) -> Self {
        self.shifted_delay_s += 0.5 * self.period_s;
        self
    }

    /// Total lag of the filter in whole samples (the preview it asks for).
    pub fn preview_samples(&self) -> usize {
        ((self.shifted_delay_s + 4.0 * self.tau_s) / self.period_s - 1e-9).ceil() as usize
    }

    /// The delay-free loop inverse `1/G(s)`.
    pub fn inverse_loop(&self, s: Complex64) -> Complex64 {
        let one = Complex64::new(1.0, 0.0);
        s * (s / self.pole_rad_s + one)
            * (s / self.we + one)
            * (s * s / (self.wn * self.wn) + s * 2.0 * self.zeta / self.wn + one)
            / ((s + self.zero_rad_s) * self.kc * self.gain)
    }

    /// `H'(e^{j w})` at `w` rad/sample.
    pub fn response(&self, w: f64) -> Complex64 {
        let t = self.period_s;
        let z = Complex64::from_polar(1.0, w);
        let zi = z.inv();
        let one = Complex64::new(1.0, 0.0);
        let s = (z - one) / (z + one) * (2.0 / t);
        let f = (s * self.tau_s + one).powi(-4);
        let d_total = self.shifted_delay_s / t;
        let d = d_total.floor();
        let frac = d_total - d;
        let direct = zi.powi(d as i32) * (one * (1.0 - frac) + zi * frac);
        let lag = (self.shifted_delay_s + 4.0 * self.tau_s) / t;
        let delta = self.preview_samples() as f64 - lag;
        let input = one * (1.0 - delta) + zi * delta;
        input * f * (direct + self.inverse_loop(s))
    }

    /// Response to a unit step from rest, first `n` samples: the impulse response by an
    /// inverse FFT of [`Self::response`] over 2^20 points, summed.
    pub fn step_response(&self, n: usize) -> Vec<f64> {
        let big = 1 << 20;
        // At z = -1 Tustin's s is infinite: take the limit just below Nyquist.
        let w = |k: usize| (2.0 * PI * k as f64 / big as f64).min(PI - 1e-7);
        let mut buf: Vec<Complex64> = (0..big)
            .map(|k| {
                let h = self.response(w(k));
                if k > big / 2 {
                    self.response(w(big - k)).conj()
                } else {
                    h
                }
            })
            .collect();
        FftPlanner::new().plan_fft_inverse(big).process(&mut buf);
        let mut acc = 0.0;
        buf.iter()
            .take(n)
            .map(|h| {
                acc += h.re / big as f64;
                acc
            })
            .collect()
    }
}
