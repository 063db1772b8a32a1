//! `f64` reference of the drift branch (eq. 5.1-5.3), written from the equations again:
//! the gain polynomial in plain powers, the step response in closed form, and the lags
//! integrated exactly for a held input with `std`'s `exp`.

use model_core::params;

/// K(u) of eq. 5.3 in plain powers, the argument held to 0..6 V (the range our model
/// evaluates it on).
pub fn k_drift(u_v: f64) -> f64 {
    let x = u_v.clamp(
        params::DRIFT_POLY_U_RANGE_V.0,
        params::DRIFT_POLY_U_RANGE_V.1,
    );
    let c = params::DRIFT_POLY;
    c[3] * x.powi(3) + c[2] * x.powi(2) + c[1] * x + c[0]
}

/// The drift `t_s` seconds after a step from rest at 0 V to `h_v`:
/// `K(h) h sum_i g_i (1 - exp(-t / tau_i))`.
pub fn step_response(h_v: f64, t_s: f64) -> f64 {
    let g = params::DRIFT_GAINS;
    let tau = params::DRIFT_TAUS_S;
    let shape: f64 = (0..3).map(|i| g[i] * (1.0 - (-t_s / tau[i]).exp())).sum();
    k_drift(h_v) * h_v * shape
}

/// The three lags of eq. 5.1 driven by `K(u) u`, exact for an input held over each step.
#[derive(Clone, Debug)]
pub struct DriftRef {
    decay: [f64; 3],
    gains: [f64; 3],
    /// Lag outputs.
    pub y: [f64; 3],
}

impl DriftRef {
    /// At rest with 0 V, step `period_s`, gains and time constants given.
    pub fn new(gains: [f64; 3], taus_s: [f64; 3], period_s: f64) -> Self {
        Self {
            decay: taus_s.map(|t| (-period_s / t).exp()),
            gains,
            y: [0.0; 3],
        }
    }

    /// The thesis' lags at `period_s`.
    pub fn thesis(period_s: f64) -> Self {
        Self::new(params::DRIFT_GAINS, params::DRIFT_TAUS_S, period_s)
    }

    /// Settle at the input `u_v` held for ever.
    pub fn settle(&mut self, u_v: f64) {
        let w = k_drift(u_v) * u_v;
        for i in 0..3 {
            self.y[i] = self.gains[i] * w;
        }
    }

    /// One step with `u_v` held; returns the drift.
    pub fn step(&mut self, u_v: f64) -> f64 {
        let w = k_drift(u_v) * u_v;
        for i in 0..3 {
            let target = self.gains[i] * w;
            self.y[i] = target + (self.y[i] - target) * self.decay[i];
        }
        self.y.iter().sum()
    }
}
