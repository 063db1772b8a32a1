//! Loop figures measured on the discrete loop by simulation: gain and phase margins, gain
//! crossover, closed-loop -3 dB bandwidth, step overshoot and settling time.
//!
//! # Method
//! The open-loop response `L(e^{jwT})` is measured, not computed from formulas: model-core's
//! compensator is driven by a cosine error of `amplitude_v`, its command goes through the
//! 14-bit DAC, model-core's plant (with its 85 us delay), and the 16-bit ADC; the plant output's
//! fundamental (single-bin DFT over whole periods after the transients) divided by the
//! error's is `L`. The quantisers are in the path, so what is measured is the loop the board
//! runs. The margins come from bisection on `|L| = 1` and on `arg(-L) = 0`. The closed-loop
//! bandwidth comes the same way from the closed loop's `Y/R` with a sine reference, scanning up
//! from 10 Hz to the first frequency where `|Y/R|` falls below `1/sqrt 2`.

use crate::sim::loop_sim::LoopSim;
use model_core::lag::{LagCompensator, LagConfig, LagState};
use model_core::limits::ConfigError;
use model_core::plant::{LinearPlant, LinearPlantConfig};
use model_core::{AdcCode, DacCode};
use rustfft::num_complex::Complex64;
use std::f64::consts::PI;

/// The loop's configuration as the analysis sees it.
#[derive(Clone, Copy, Debug)]
pub struct LoopSetup {
    /// Compensator.
    pub lag: LagConfig,
    /// Plant.
    pub plant: LinearPlantConfig,
}

impl LoopSetup {
    /// The thesis loop at `rate_hz` with gain `kc`.
    pub fn thesis(rate_hz: f64, kc: f64) -> Self {
        let period_s = 1.0 / rate_hz;
        Self {
            lag: LagConfig {
                kc,
                period_s,
                ..LagConfig::default()
            },
            plant: LinearPlantConfig {
                period_s,
                ..LinearPlantConfig::default()
            },
        }
    }

    /// Checks the configuration by building both blocks.
    pub fn validate(&self) -> Result<(), ConfigError> {
        LagCompensator::new(&self.lag)?;
        LinearPlant::new(&self.plant)?;
        Ok(())
    }
}

/// Everything `piezo loop` reports. `None` where a figure does not exist (an unstable loop
/// has no bandwidth; a loop whose phase never reaches -180 deg has an infinite gain margin).
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct LoopFigures {
    /// Gain margin, dB.
    pub gain_margin_db: Option<f64>,
    /// Phase margin, degrees.
    pub phase_margin_deg: Option<f64>,
    /// Gain crossover, rad/s.
    pub crossover_rad_s: Option<f64>,
    /// Closed-loop -3 dB bandwidth, Hz.
    pub bandwidth_hz: Option<f64>,
    /// Overshoot of a 1 V step response, percent.
    pub step_overshoot_pct: Option<f64>,
    /// Time until the step response stays within 2 % of the step, ms.
    pub settling_2pct_ms: Option<f64>,
}

/// Fundamental of `x` at `w` rad/sample (mean removed), as a complex amplitude.
pub fn fundamental(x: &[f64], w: f64) -> Complex64 {
    let mean = x.iter().sum::<f64>() / x.len() as f64;
    let acc: Complex64 = x
        .iter()
        .enumerate()
        .map(|(n, v)| (v - mean) * Complex64::from_polar(1.0, -w * n as f64))
        .sum();
    acc * 2.0 / x.len() as f64
}

/// Samples for `periods` whole periods of `w` rad/sample (rounded).
fn whole_periods(w: f64, periods: f64) -> usize {
    ((2.0 * PI / w) * periods).round().max(1.0) as usize
}

/// Open-loop frequency response `L` at `omega_rad_s`, measured through the quantisers with a
/// cosine error of `amplitude_v` around the operating point `u0_v`.
pub fn open_loop_response(
    setup: &LoopSetup,
    omega_rad_s: f64,
    amplitude_v: f64,
    u0_v: f64,
) -> Complex64 {
    let lag = LagCompensator::new(&setup.lag).expect("validated");
    let plant = LinearPlant::new(&setup.plant).expect("validated");
    let mut ls = LagState::new(u0_v as f32);
    let mut ps = plant.steady_state(u0_v as f32);
    let w = omega_rad_s * setup.lag.period_s;
    let settle = whole_periods(w, 20.0).max(2000);
    let n = whole_periods(w, 40.0).max(4000);
    let mut e_rec = Vec::with_capacity(n);
    let mut y_rec = Vec::with_capacity(n);
    for k in 0..settle + n {
        let e = amplitude_v * (w * k as f64).cos();
        let y = AdcCode::from_volts(plant.output(&ps)).volts() as f64;
        let u = lag.update(&mut ls, e as f32);
        plant.step(&mut ps, DacCode::from_volts(u).volts());
        if k >= settle {
            // Same index on both: in the closed loop e[k] = r[k] - y[k], so the sample of
            // computation delay (y[k] answers e up to k-1) belongs to L.
            e_rec.push(e);
            y_rec.push(y);
        }
    }
    fundamental(&y_rec, w) / fundamental(&e_rec, w)
}

/// Closed-loop response `Y/R` at `f_hz` with a sine reference of `amplitude_v` around `y0_v`.
pub fn closed_loop_response(
    setup: &LoopSetup,
    f_hz: f64,
    amplitude_v: f64,
    y0_v: f64,
) -> Complex64 {
    let mut sim = LoopSim::new(&setup.lag, &setup.plant).expect("validated");
    sim.settle_at(y0_v);
    let w = 2.0 * PI * f_hz * setup.lag.period_s;
    let settle = whole_periods(w, 10.0).max(5000);
    let n = whole_periods(w, 20.0).max(5000);
    let mut r_rec = Vec::with_capacity(n);
    let mut y_rec = Vec::with_capacity(n);
    for k in 0..settle + n {
        let r = y0_v + amplitude_v * (w * k as f64).sin();
        let s = sim.step(r);
        if k >= settle {
            r_rec.push(r);
            y_rec.push(s.output_v);
        }
    }
    fundamental(&y_rec, w) / fundamental(&r_rec, w)
}

/// Bisection on `log w` for a sign change of `f` between `lo` and `hi`; 40 halvings.
fn bisect_log(mut lo: f64, mut hi: f64, f: impl Fn(f64) -> f64) -> Option<f64> {
    let mut f_lo = f(lo);
    if f_lo.signum() == f(hi).signum() {
        return None;
    }
    for _ in 0..40 {
        let mid = (lo * hi).sqrt();
        let fm = f(mid);
        if fm.signum() == f_lo.signum() {
            lo = mid;
            f_lo = fm;
        } else {
            hi = mid;
        }
        if hi / lo < 1.0 + 1e-6 {
            break;
        }
    }
    Some((lo * hi).sqrt())
}

/// Step response figures for a step of `step_v` from `y0_v`, simulated for `seconds`.
pub fn step_figures(
    setup: &LoopSetup,
    y0_v: f64,
    step_v: f64,
    seconds: f64,
) -> (f64, f64, Vec<(f64, f64)>) {
    let mut sim = LoopSim::new(&setup.lag, &setup.plant).expect("validated");
    sim.settle_at(y0_v);
    let t = setup.lag.period_s;
    let n = (seconds / t) as usize;
    let target = y0_v + step_v;
    let mut peak = f64::MIN;
    let mut last_out = 0.0;
    let mut trace = Vec::with_capacity(n);
    for k in 0..n {
        let s = sim.step(target);
        peak = peak.max((s.output_v - y0_v) / step_v);
        if ((s.output_v - target) / step_v).abs() > 0.02 {
            last_out = (k + 1) as f64 * t;
        }
        trace.push((k as f64 * t, s.output_v));
    }
    let overshoot_pct = (peak - 1.0).max(0.0) * 100.0;
    (overshoot_pct, last_out * 1e3, trace)
}

/// All the figures of `piezo loop`.
pub fn loop_figures(setup: &LoopSetup) -> Result<LoopFigures, ConfigError> {
    setup.validate()?;
    let amp = 0.2;
    let u0 = 5.0;
    let l = |w: f64| open_loop_response(setup, w, amp, u0);
    // The crossover lies well below the stage mode; search 100 rad/s .. 1/4 of Nyquist.
    let nyq_rad_s = PI / setup.lag.period_s;
    let w_max = (0.25 * nyq_rad_s).min(2.0 * PI * 4000.0);
    let crossover = bisect_log(100.0, w_max, |w| l(w).norm().ln());
    let phase_margin = crossover.map(|w| (-l(w)).arg().to_degrees());
    // Phase crossover: arg(-L) goes from +90 deg (the integrator) through zero.
    let w180 = bisect_log(100.0, w_max, |w| (-l(w)).arg());
    let gain_margin = w180.map(|w| -20.0 * l(w).norm().log10());
    let stable = gain_margin.is_none_or(|g| g > 0.0) && phase_margin.is_some_and(|p| p > 0.0);
    let (bandwidth, overshoot, settling) = if stable {
        let y0 = 4.0;
        let mag = |f: f64| closed_loop_response(setup, f, 0.2, y0).norm();
        // Scan up in 5 % steps to the first drop below -3 dB, then refine.
        let mut f = 10.0;
        let mut bw = None;
        while f < 0.5 / setup.lag.period_s * 0.5 {
            let f_next = f * 1.05;
            if mag(f_next) < std::f64::consts::FRAC_1_SQRT_2 {
                bw = bisect_log(f, f_next, |x| mag(x) - std::f64::consts::FRAC_1_SQRT_2);
                break;
            }
            f = f_next;
        }
        let (os, st, _) = step_figures(setup, 2.0, 1.0, 0.2);
        (bw, Some(os), Some(st))
    } else {
        (None, None, None)
    };
    Ok(LoopFigures {
        gain_margin_db: gain_margin,
        phase_margin_deg: phase_margin,
        crossover_rad_s: crossover,
        bandwidth_hz: bandwidth,
        step_overshoot_pct: overshoot,
        settling_2pct_ms: settling,
    })
}
