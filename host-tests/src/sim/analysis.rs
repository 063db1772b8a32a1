//! Loop figures measured on the discrete loop by simulation: gain and phase margins, gain
//! crossover, closed-loop -3 dB bandwidth, step overshoot and settling time.
//!
//! # Method
//! Every figure is measured on the one closed-loop harness ([`model_core::closed_loop`]): the
//! board's [`Controller::step`] (pre-filter off: the figures are the feedback loop's own)
//! around model-core's plant of eq. 4.4 (with its 85 us delay), through the 14-bit DAC and the
//! 16-bit ADC, started at rest in an operating point ([`closed_loop::settled`]). The open-loop
//! response `L(e^{jwT})` is measured by injection at the plant input, in the closed loop, as
//! on a bench: a cosine `d` is added to the DAC's volts, the plant receives `x = u + d`, and the
//! loop answers with the command `u = -L x`; `L = -U/X` from the fundamentals (single-bin DFT
//! over whole periods after the transients). The quantisers and the controller's limits are in
//! the path, so what is measured is the loop the board runs. The margins come from bisection on `|L| = 1` and on `arg(-L) = 0`. The closed-loop
//! bandwidth comes the same way from the closed loop's `Y/R` with a sine reference, scanning up
//! from 10 Hz to the first frequency where `|Y/R|` falls below `1/sqrt 2`.

use crate::sim::closed_loop;
use model_core::closed_loop::{ClosedLoop, Converted, LinearStage, NoNoise};
use model_core::controller::{Controller, ControllerConfig};
use model_core::lag::LagConfig;
use model_core::limits::ConfigError;
use model_core::plant::{LinearPlant, LinearPlantConfig};
use model_core::prefilter::{PreFilterConfig, PreFilterMode};
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

    /// The board's controller for this loop: the thesis defaults with this compensator and
    /// design plant, the pre-filter off (the figures are the feedback loop's own).
    pub fn controller_config(&self) -> ControllerConfig {
        ControllerConfig {
            lag: self.lag,
            plant: self.plant,
            prefilter: PreFilterConfig {
                mode: PreFilterMode::Off,
                ..PreFilterConfig::default()
            },
            ..ControllerConfig::default()
        }
    }

    /// Checks the configuration by building the controller and the plant.
    pub fn validate(&self) -> Result<(), ConfigError> {
        Controller::new(&self.controller_config())?;
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

/// The loop `piezo loop` measures: the board's controller with the pre-filter off (the
/// figures are the feedback loop's own), at rest with the output at `y0_v`.
fn settled_loop(setup: &LoopSetup, y0_v: f64) -> ClosedLoop<Converted<LinearStage, NoNoise>> {
    let run = setup.controller_config();
    let u0 = (y0_v / setup.plant.gain) as f32;
    let stage = LinearStage::new(&setup.plant, u0).expect("validated");
    closed_loop::settled(&run, stage, u0, y0_v as f32).expect("validated")
}

/// Open-loop frequency response `L` at `omega_rad_s`, measured by injection at the plant input
/// in the closed loop: a cosine `d` of `amplitude_v` is added to the DAC's volts, `x = u + d`
/// reaches the plant, and `L = -U/X` (the loop returns `-L x` as the command `u`). The loop
/// runs at the operating point `u0_v` with the quantisers in the path: the loop the board
/// runs, [`Controller::step`] included.
pub fn open_loop_response(
    setup: &LoopSetup,
    omega_rad_s: f64,
    amplitude_v: f64,
    u0_v: f64,
) -> Complex64 {
    let mut lp = settled_loop(setup, u0_v * setup.plant.gain);
    let w = omega_rad_s * setup.lag.period_s;
    let settle = whole_periods(w, 20.0).max(5000);
    let n = whole_periods(w, 40.0).max(4000);
    let mut u_rec = Vec::with_capacity(n);
    let mut x_rec = Vec::with_capacity(n);
    for k in 0..settle + n {
        lp.plant.injection_v = (amplitude_v * (w * k as f64).cos()) as f32;
        let s = lp.step();
        if k >= settle {
            u_rec.push(s.sample.dac.volts() as f64);
            x_rec.push(s.plant_input_v as f64);
        }
    }
    -fundamental(&u_rec, w) / fundamental(&x_rec, w)
}

/// Closed-loop response `Y/R` at `f_hz` with a sine reference of `amplitude_v` around `y0_v`.
pub fn closed_loop_response(
    setup: &LoopSetup,
    f_hz: f64,
    amplitude_v: f64,
    y0_v: f64,
) -> Complex64 {
    let mut lp = settled_loop(setup, y0_v);
    let w = 2.0 * PI * f_hz * setup.lag.period_s;
    let settle = whole_periods(w, 10.0).max(5000);
    let n = whole_periods(w, 20.0).max(5000);
    let mut r_rec = Vec::with_capacity(n);
    let mut y_rec = Vec::with_capacity(n);
    for k in 0..settle + n {
        let r = y0_v + amplitude_v * (w * k as f64).sin();
        lp.state.set_reference(r as f32);
        let s = lp.step();
        if k >= settle {
            r_rec.push(s.sample.reference_v as f64);
            y_rec.push(s.output_v as f64);
        }
    }
    fundamental(&y_rec, w) / fundamental(&r_rec, w)
}

/// The lowest frequency the crossover is searched from, rad/s (lower would take seconds of
/// simulation per point: the response is measured over whole periods).
pub const CROSSOVER_MIN_RAD_S: f64 = 100.0;

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

/// Step response figures for a step of `step_v` from `y0_v`, simulated for `seconds`:
/// overshoot in percent, settling time to 2 % in ms, and the trace (time s, output V).
pub fn step_figures(
    setup: &LoopSetup,
    y0_v: f64,
    step_v: f64,
    seconds: f64,
) -> (f64, f64, Vec<(f64, f64)>) {
    let mut lp = settled_loop(setup, y0_v);
    let t = setup.lag.period_s;
    let n = (seconds / t) as usize;
    let target = y0_v + step_v;
    lp.state.set_reference(target as f32);
    let mut peak = f64::MIN;
    let mut last_out = 0.0;
    let mut trace = Vec::with_capacity(n);
    for k in 0..n {
        let y = lp.step().output_v as f64;
        peak = peak.max((y - y0_v) / step_v);
        if ((y - target) / step_v).abs() > 0.02 {
            last_out = (k + 1) as f64 * t;
        }
        trace.push((k as f64 * t, y));
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
    let crossover = bisect_log(CROSSOVER_MIN_RAD_S, w_max, |w| l(w).norm().ln());
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
