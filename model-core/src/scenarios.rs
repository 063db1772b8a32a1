//! Closed-loop scenarios that run *identically* on the host and on a Cortex-M (QEMU): the
//! scenario list, a fixed number of samples of the closed-loop harness
//! ([`crate::closed_loop`]) with the scenario's faults injected, and the figures computed from
//! it (issue #6).
//!
//! # Why here
//! The QEMU smoke runs must prove that the control code behaves on `thumbv7em` as it does in
//! the host simulations. Both sides therefore compile *this* module and run the same function,
//! [`run`], and the host compares the [`Figures`] the image prints with the ones it computes
//! itself. Everything is `f32` per sample (as in the interrupt) and `f64` only in the
//! configuration (`Controller::new`, soft-float on the target, IEEE on both sides), with no
//! fused multiply-add (Rust never contracts) and no library maths (no `sqrt`, `sin`, `%` on
//! floats), so the two runs are expected to agree **bit for bit**; the host checks exactly
//! that, including an FNV-1a checksum of every DAC code sent ([`Figures::dac_checksum`]).
//!
//! # One sample, as on the board
//! The harness's sample ([`crate::closed_loop::ClosedLoop::step_reading`]): the ADC reads the
//! stage output plus sensor noise (uniform, +-[`params::SENSOR_NOISE_V`], from a seeded
//! xorshift generator, so runs repeat), a fault may replace the code (sensor saturated: the
//! ADC's top code; sensor stuck: the code of the sample the fault starts), the controller
//! steps on that code and the scenario's reference, the DAC code's volts drive the stage for
//! one period.
//!
//! # The loop
//! [`run_with`] drives the one closed-loop harness ([`crate::closed_loop::ClosedLoop`]) that
//! `piezo loop` and `piezo track` run too: the linear plant of eq. 4.4 behind the converters
//! with the scenarios' uniform noise ([`linear_plant`]), or the ch. 6 overall model with its own
//! sensor ([`full_plant`]) for the hysteresis scenarios.
//!
//! # Scenarios ([`Scenario`])
//! 0.5 s each at 50 kHz ([`SAMPLES`]): a 0 -> 5 V step, a 100 Hz triangle from the on-board
//! reference generator through the pre-filter (and, for comparison, without), the same on the
//! ch. 6 stage with the hysteresis feedforward on and off, and four injected
//! faults on a 5 V set-point (sensor saturates, sensor sticks, NaN reference, absurd gain
//! commands). [`Figures::check`] states what each must show: the command never leaves the
//! window nor exceeds the slew limit, faults latch within their detection time and the
//! command ramps to the safe value, refused configurations leave the loop running.
//!
//! Bounded: one loop of [`SAMPLES`] iterations, no allocation, no indexing, no panics.

use crate::closed_loop::{
    ClosedLoop, Converted, FullStage, LinearStage, LoopPlant, LoopSample, NoNoise, UniformNoise,
};
use crate::codes::AdcCode;
use crate::controller::{Controller, ControllerConfig, Faults, ReferenceSource};
use crate::lag::LagConfig;
use crate::limits::ConfigError;
use crate::params;
use crate::prefilter::{PreFilterConfig, PreFilterMode};
use crate::reference::{ReferenceConfig, Shape};
use crate::sections::Accumulator;

// ----- The scenarios' numbers: all our assumptions. -----
/// Simulated time per scenario, seconds (25 000 samples at 50 kHz).
pub const DURATION_S: f64 = 0.5;
/// Set-point of the step and of the fault scenarios, sensor volts (6 um).
pub const STEP_V: f64 = 5.0;
/// When the step (and the triangle) starts, seconds.
pub const STEP_AT_S: f64 = 1e-3;
/// Time after the step from which the peak error is taken, seconds: nine times the 2 %
/// settling time of the thesis loop (1.14 ms, `piezo loop`).
pub const SETTLE_S: f64 = 10e-3;
/// Largest error after settling and final error of the set-point scenarios, sensor volts:
/// four times the sensor's +-2.5 mV noise.
pub const TRACKING_TOL_V: f64 = 4.0 * params::SENSOR_NOISE_V;
/// Frequency of the triangle scenario, Hz.
pub const TRIANGLE_HZ: f64 = 100.0;
/// Offset of the triangle, sensor volts (issue #3's tracking measurements: 6 V p-p around
/// 4 V).
pub const TRIANGLE_OFFSET_V: f64 = 4.0;
/// Amplitude (peak) of the triangle, sensor volts.
pub const TRIANGLE_AMPLITUDE_V: f64 = 3.0;
/// Tracking error of the triangle by feedback alone, sensor volts. Over a half period (5 ms,
/// far shorter than the lag's 1/p = 2.5 s) the compensator acts as the integrator
/// `Kc p / s`, so a ramp of slope `4 A f` leaves the error `4 A f / (Kc p K)`
/// (1200 V/s / 3144 /s = 0.38 V).
pub const TRIANGLE_VELOCITY_ERR_V: f64 = 4.0 * TRIANGLE_AMPLITUDE_V * TRIANGLE_HZ
    / (params::LAG_KC * params::LAG_POLE_RAD_S * params::PLANT_GAIN);
/// Bound on the feedback-only triangle's peak error, in units of
/// [`TRIANGLE_VELOCITY_ERR_V`]: room for the corners.
pub const TRIANGLE_PEAK_FACTOR: f64 = 1.5;
/// The pre-filter must cut the triangle's RMS error below the feedback-only velocity error
/// divided by this (issue #3: a tenfold cut at 100 Hz).
pub const PREFILTER_CUT: f64 = 10.0;
/// Bound on the RMS tracking error on the ch. 6 stage, as a fraction of the triangle's span
/// (the lead's criterion in host-tests `controller.rs`: within 2 %, feedforward on or off).
pub const FULL_STAGE_RMS_FRAC: f64 = 0.02;
/// When faults are injected, seconds.
pub const FAULT_AT_S: f64 = 0.2;
/// When the reference moves in the stuck-sensor scenario, seconds (50 ms after the sensor
/// froze, so the stuck detector has long counted its 5 ms of frozen code).
pub const MOVE_AT_S: f64 = 0.25;
/// Where the reference moves in the stuck-sensor scenario, sensor volts.
pub const MOVE_TO_V: f64 = 7.0;
/// The absurd gain offered in the absurd-gain scenario (a thousand times [`params::LAG_KC_MAX`]).
pub const ABSURD_KC: f64 = 1.0e9;
/// Seed of the scenarios' sensor noise generator.
pub const NOISE_SEED: u32 = 0x2545_f491;

/// Samples per scenario: [`DURATION_S`] at [`params::SAMPLE_RATE_HZ`].
pub const SAMPLES: u32 = (DURATION_S * params::SAMPLE_RATE_HZ) as u32;

const fn sample_at(t_s: f64) -> u32 {
    (t_s * params::SAMPLE_RATE_HZ) as u32
}

/// Sample at which the step (and the triangle) starts.
pub const STEP_AT: u32 = sample_at(STEP_AT_S);
/// Sample from which the peak error is taken (the transient of the step is over).
pub const SETTLED_AT: u32 = sample_at(STEP_AT_S + SETTLE_S);
/// Sample at which faults are injected.
pub const FAULT_AT: u32 = sample_at(FAULT_AT_S);
/// Sample at which the reference moves again in the stuck-sensor scenario.
pub const MOVE_AT: u32 = sample_at(MOVE_AT_S);

/// The scenarios, in the order the QEMU image runs them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scenario {
    /// Closed loop, external reference 0 V then 5 V (sensor volts) from [`STEP_AT`], through
    /// the default (full) pre-filter.
    Step,
    /// Closed loop, a 100 Hz triangle of [`TRIANGLE_AMPLITUDE_V`] around
    /// [`TRIANGLE_OFFSET_V`] from the controller's on-board reference
    /// generator, with preview, through the full pre-filter.
    Triangle,
    /// The same triangle with the pre-filter off: feedback alone.
    TriangleFeedbackOnly,
    /// The triangle (generator, pre-filter) on the ch. 6 stage ([`FullStage`]: hysteresis
    /// table, drift, K'(u), amplifier, converters, noise) with the controller's hysteresis
    /// feedforward on.
    HysteresisFeedforward,
    /// The same on the ch. 6 stage with the feedforward off.
    HysteresisFeedbackOnly,
    /// 5 V set-point; from [`FAULT_AT`] the sensor reads the ADC's top code.
    SensorSaturates,
    /// 5 V set-point; from [`FAULT_AT`] the ADC code freezes; at [`MOVE_AT`] the reference
    /// moves to [`MOVE_TO_V`], so the command moves and the sensor does not.
    SensorSticks,
    /// 5 V set-point; from [`FAULT_AT`] the reference is NaN.
    NanReference,
    /// 5 V set-point; at [`FAULT_AT`] three absurd compensator configurations (gain 1e9, NaN,
    /// negative) are offered and must all be refused, the loop running on unchanged.
    AbsurdGain,
}

impl Scenario {
    /// Every scenario.
    pub const ALL: [Self; 9] = [
        Self::Step,
        Self::Triangle,
        Self::TriangleFeedbackOnly,
        Self::HysteresisFeedforward,
        Self::HysteresisFeedbackOnly,
        Self::SensorSaturates,
        Self::SensorSticks,
        Self::NanReference,
        Self::AbsurdGain,
    ];

    /// The name printed by the QEMU image and accepted on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Step => "step",
            Self::Triangle => "triangle",
            Self::TriangleFeedbackOnly => "triangle-feedback-only",
            Self::HysteresisFeedforward => "hysteresis-feedforward",
            Self::HysteresisFeedbackOnly => "hysteresis-feedback-only",
            Self::SensorSaturates => "sensor-saturates",
            Self::SensorSticks => "sensor-sticks",
            Self::NanReference => "nan-reference",
            Self::AbsurdGain => "absurd-gain",
        }
    }

    /// The scenario of that name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The external reference at sample `n`, sensor volts. The triangles' references come
    /// from the controller's generator; here they are its offset (unused).
    pub fn reference_v(self, n: u32) -> f32 {
        let hold = STEP_V as f32;
        match self {
            Self::Step | Self::AbsurdGain | Self::SensorSaturates => step_reference(n),
            Self::Triangle
            | Self::TriangleFeedbackOnly
            | Self::HysteresisFeedforward
            | Self::HysteresisFeedbackOnly => TRIANGLE_OFFSET_V as f32,
            Self::SensorSticks if n >= MOVE_AT => MOVE_TO_V as f32,
            Self::SensorSticks => step_reference(n),
            Self::NanReference if n >= FAULT_AT => f32::NAN,
            Self::NanReference => hold,
        }
    }

    /// The controller's configuration for this scenario: the thesis defaults (full pre-filter,
    /// external reference), the triangles from the on-board generator.
    pub fn config(self) -> ControllerConfig {
        let base = ControllerConfig::default();
        let triangle = ReferenceConfig {
            shape: Shape::Triangle,
            offset_v: TRIANGLE_OFFSET_V,
            amplitude_v: TRIANGLE_AMPLITUDE_V,
            freq_hz: TRIANGLE_HZ,
            ..base.reference
        };
        match self {
            Self::Triangle | Self::HysteresisFeedbackOnly => ControllerConfig {
                reference: triangle,
                source: ReferenceSource::Generator,
                ..base
            },
            Self::HysteresisFeedforward => ControllerConfig {
                reference: triangle,
                source: ReferenceSource::Generator,
                hysteresis_ff: true,
                ..base
            },
            Self::TriangleFeedbackOnly => ControllerConfig {
                reference: triangle,
                source: ReferenceSource::Generator,
                prefilter: PreFilterConfig {
                    mode: PreFilterMode::Off,
                    ..base.prefilter
                },
                ..base
            },
            _ => base,
        }
    }

    /// True for the scenarios run on the ch. 6 stage ([`FullStage`]) instead of eq. 4.4.
    pub const fn on_full_stage(self) -> bool {
        matches!(
            self,
            Self::HysteresisFeedforward | Self::HysteresisFeedbackOnly
        )
    }

    /// The fault this scenario must latch, if any.
    pub const fn expected_fault(self) -> Option<Faults> {
        match self {
            Self::SensorSaturates => Some(Faults::SENSOR_RANGE),
            Self::SensorSticks => Some(Faults::SENSOR_STUCK),
            Self::NanReference => Some(Faults::NONFINITE),
            Self::Step
            | Self::Triangle
            | Self::TriangleFeedbackOnly
            | Self::HysteresisFeedforward
            | Self::HysteresisFeedbackOnly
            | Self::AbsurdGain => None,
        }
    }
}

fn step_reference(n: u32) -> f32 {
    if n >= STEP_AT { STEP_V as f32 } else { 0.0 }
}

/// Start value of [`fnv1a`].
pub const FNV_OFFSET: u32 = 0x811c_9dc5;
const FNV_PRIME: u32 = 0x0100_0193;

/// FNV-1a of `hash` extended by the two bytes of `v` (little-endian): how
/// [`Figures::dac_checksum`] hashes the DAC codes (offset binary).
pub fn fnv1a(hash: u32, v: u16) -> u32 {
    let h = (hash ^ (v & 0xff) as u32).wrapping_mul(FNV_PRIME);
    (h ^ (v >> 8) as u32).wrapping_mul(FNV_PRIME)
}

/// Marker for "never happened" in the sample-index figures.
pub const NEVER: u32 = u32::MAX;

/// What a scenario produced. Every field is compared between host and QEMU.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Figures {
    /// Samples run.
    pub samples: u32,
    /// Mean of the squared error `r - y` (true stage output) from [`SETTLED_AT`] on, over the
    /// samples with a finite reference, V^2 (the RMS is its square root, taken by whoever
    /// prints it).
    pub mean_sq_err_v2: f32,
    /// Largest `|r - y|` from [`SETTLED_AT`] on (finite references only), volts.
    pub peak_err_v: f32,
    /// Stage output after the last sample, sensor volts.
    pub final_output_v: f32,
    /// Last command, volts at the amplifier input.
    pub final_command_v: f32,
    /// Largest change of the command between two samples, volts.
    pub max_slew_v: f32,
    /// Samples whose command left the window.
    pub window_violations: u32,
    /// Samples whose command moved by more than the slew limit.
    pub slew_violations: u32,
    /// Faults latched at the end (bits of [`Faults`]).
    pub faults: u8,
    /// First sample with a latched fault, or [`NEVER`].
    pub fault_latched_at: u32,
    /// First sample after the latch at which the command equals the safe value, or [`NEVER`].
    pub safe_reached_at: u32,
    /// Configurations refused during the run.
    pub refused: u32,
    /// FNV-1a hash of every DAC code sent (offset binary, little-endian bytes).
    pub dac_checksum: u32,
}

impl Figures {
    /// The RMS error, volts (computed in `f64` for display: not part of the comparison).
    pub fn rms_err_v(&self) -> f64 {
        let m = self.mean_sq_err_v2 as f64;
        // Newton's iteration: no `std` here.
        if m <= 0.0 || !m.is_finite() {
            return m;
        }
        let mut x = if m > 1.0 { m } else { 1.0 };
        for _ in 0..64 {
            x = 0.5 * (x + m / x);
        }
        x
    }

    /// The figures as `(name, bits)` pairs in a fixed order: what the QEMU image prints and
    /// the host parses. `f32` values are sent as their IEEE bits so the comparison is exact.
    pub fn fields(&self) -> [(&'static str, u32); 13] {
        [
            ("samples", self.samples),
            ("mean_sq_err_v2", self.mean_sq_err_v2.to_bits()),
            ("peak_err_v", self.peak_err_v.to_bits()),
            ("final_output_v", self.final_output_v.to_bits()),
            ("final_command_v", self.final_command_v.to_bits()),
            ("max_slew_v", self.max_slew_v.to_bits()),
            ("window_violations", self.window_violations),
            ("slew_violations", self.slew_violations),
            ("faults", self.faults as u32),
            ("fault_latched_at", self.fault_latched_at),
            ("safe_reached_at", self.safe_reached_at),
            ("refused", self.refused),
            ("dac_checksum", self.dac_checksum),
        ]
    }

    /// Whether a field holds an `f32`'s bits (for printing).
    pub fn is_f32_field(name: &str) -> bool {
        name.ends_with("_v") || name.ends_with("_v2")
    }

    /// The scenario's pass criteria; the first one violated.
    pub fn check(&self, scenario: Scenario, controller: &Controller) -> Result<(), &'static str> {
        if self.samples != SAMPLES {
            return Err("the run did not complete");
        }
        if self.window_violations != 0 {
            return Err("the command left the window");
        }
        if self.slew_violations != 0 {
            return Err("the command exceeded the slew limit");
        }
        let safe = controller.safe_v();
        match scenario.expected_fault() {
            None => {
                if self.faults != 0 {
                    return Err("a fault latched in a fault-free scenario");
                }
                let tol = TRACKING_TOL_V as f32;
                let final_err = (self.final_output_v - STEP_V as f32).abs();
                let velocity_err = TRIANGLE_VELOCITY_ERR_V as f32;
                let span = 2.0 * TRIANGLE_AMPLITUDE_V as f32;
                if scenario.on_full_stage() {
                    let bound = FULL_STAGE_RMS_FRAC as f32 * span;
                    if !within(self.mean_sq_err_v2, bound * bound) {
                        return Err("the ch. 6 stage's RMS tracking error exceeded its bound");
                    }
                } else if scenario == Scenario::Triangle {
                    let bound = velocity_err / PREFILTER_CUT as f32;
                    if !within(self.mean_sq_err_v2, bound * bound) {
                        return Err("the pre-filtered triangle's RMS error exceeded its bound");
                    }
                } else if scenario == Scenario::TriangleFeedbackOnly {
                    let bound = TRIANGLE_PEAK_FACTOR as f32 * velocity_err;
                    if !within(self.peak_err_v, bound) {
                        return Err("the triangle's tracking error exceeded its bound");
                    }
                } else {
                    if !within(final_err, tol) {
                        return Err("the output did not settle at the set-point");
                    }
                    if !within(self.peak_err_v, tol) {
                        return Err("the error after settling exceeded the tolerance");
                    }
                }
                if scenario == Scenario::AbsurdGain && self.refused != 3 {
                    return Err("an absurd gain was accepted");
                }
            }
            Some(f) => {
                if self.faults & f.0 == 0 {
                    return Err("the expected fault did not latch");
                }
                let start = if scenario == Scenario::SensorSticks {
                    MOVE_AT
                } else {
                    FAULT_AT
                };
                let allowed = if scenario == Scenario::SensorSticks {
                    // Counted from the command's 0.1 V move, which follows the reference's
                    // through the pre-filter within a millisecond (50 samples).
                    params::SENSOR_STUCK_SAMPLES + 50
                } else {
                    1
                };
                if self.fault_latched_at < FAULT_AT
                    || self.fault_latched_at > start.saturating_add(allowed)
                {
                    return Err("the fault latched too early or too late");
                }
                // From at most the top of the window, the ramp takes window / safe-ramp step
                // samples (1 V/ms by default: 500 samples for 10 V at 50 kHz).
                let l = controller.lag.limits;
                let ramp = ((l.max_v - l.min_v) / controller.safe_ramp_v_per_step()) as u32 + 2;
                if self.safe_reached_at == NEVER
                    || self.safe_reached_at > self.fault_latched_at.saturating_add(ramp)
                {
                    return Err("the command did not ramp to the safe value in time");
                }
                if self.final_command_v != safe {
                    return Err("the command did not stay at the safe value");
                }
            }
        }
        Ok(())
    }
}

/// `x <= bound`, false for NaN.
fn within(x: f32, bound: f32) -> bool {
    x <= bound
}

/// The thesis controller (default configuration).
pub fn thesis_controller() -> Result<Controller, ConfigError> {
    Controller::new(&ControllerConfig::default())
}

/// The controller of `scenario` ([`Scenario::config`]).
pub fn scenario_controller(scenario: Scenario) -> Result<Controller, ConfigError> {
    Controller::new(&scenario.config())
}

/// The scenarios' sensor noise: uniform, +-[`params::SENSOR_NOISE_V`], seeded with
/// [`NOISE_SEED`].
pub fn scenario_noise() -> UniformNoise {
    UniformNoise::new(params::SENSOR_NOISE_V as f32, NOISE_SEED)
}

/// The scenario's plant: `stage` behind the converters, with the scenarios' uniform sensor
/// noise ([`scenario_noise`]) for the linear stage; the ch. 6 stage has its own sensor.
pub fn linear_plant() -> Result<Converted<LinearStage, UniformNoise>, ConfigError> {
    Ok(Converted::new(LinearStage::thesis()?, scenario_noise()))
}

/// The ch. 6 stage ([`FullStage::thesis`]) behind the converters; its sensor is its own.
pub fn full_plant() -> Result<Converted<FullStage, NoNoise>, ConfigError> {
    Ok(Converted::new(FullStage::thesis()?, NoNoise))
}

/// Run `scenario` with its controller ([`Scenario::config`]) on the linear plant of eq. 4.4,
/// or on the ch. 6 stage ([`Scenario::on_full_stage`]).
pub fn run(scenario: Scenario) -> Result<(Controller, Figures), ConfigError> {
    let controller = scenario_controller(scenario)?;
    let figures = if scenario.on_full_stage() {
        run_with(scenario, ClosedLoop::new(controller, full_plant()?), |_| {}).0
    } else {
        run_with(
            scenario,
            ClosedLoop::new(controller, linear_plant()?),
            |_| {},
        )
        .0
    };
    Ok((controller, figures))
}

/// Run `scenario` on `lp` (the controller from boot, the plant wherever it is): the loop
/// closes at the first sample, the faults are injected as the scenario says, and `each` sees
/// every sample. Returns the figures and the loop as it ended.
pub fn run_with<P: LoopPlant>(
    scenario: Scenario,
    mut lp: ClosedLoop<P>,
    mut each: impl FnMut(&LoopSample),
) -> (Figures, ClosedLoop<P>) {
    lp.close(scenario.reference_v(0));
    let limits = lp.controller.lag.limits;
    let slew_tol = limits.slew_v_per_step * (1.0 + 1e-5) + 1e-6;
    let mut f = Figures {
        fault_latched_at: NEVER,
        safe_reached_at: NEVER,
        dac_checksum: FNV_OFFSET,
        ..Figures::default()
    };
    let mut sum_sq = Accumulator::default();
    let mut counted = 0u32;
    let mut stuck_code = AdcCode(0);
    let mut last_command = lp.state.command_v();
    for n in 0..SAMPLES {
        if scenario == Scenario::AbsurdGain && n == FAULT_AT {
            let ok = scenario.config();
            for kc in [ABSURD_KC, f64::NAN, -params::LAG_KC] {
                let offered = ControllerConfig {
                    lag: LagConfig { kc, ..ok.lag },
                    ..ok
                };
                match Controller::new(&offered) {
                    Ok(c) => lp.controller = c,
                    Err(_) => f.refused += 1,
                }
            }
        }
        lp.state.set_reference(scenario.reference_v(n));
        let s = lp.step_reading(|adc| match scenario {
            Scenario::SensorSaturates if n >= FAULT_AT => AdcCode::MAX,
            Scenario::SensorSticks if n == FAULT_AT => {
                stuck_code = adc;
                adc
            }
            Scenario::SensorSticks if n > FAULT_AT => stuck_code,
            _ => adc,
        });
        each(&s);
        // The reference in force (the generator's present value, or the external one).
        let r = s.sample.reference_v;
        let u = s.sample.command_v;
        f.dac_checksum = fnv1a(f.dac_checksum, s.sample.dac.offset_binary());
        if r.is_finite() && n >= SETTLED_AT {
            let e = s.error_v();
            sum_sq.add(e * e);
            counted += 1;
            if e.abs() > f.peak_err_v {
                f.peak_err_v = e.abs();
            }
        }
        let du = (u - last_command).abs();
        if du > f.max_slew_v {
            f.max_slew_v = du;
        }
        if !within(du, slew_tol) {
            f.slew_violations += 1;
        }
        if !limits.contains(u) {
            f.window_violations += 1;
        }
        last_command = u;
        if !s.sample.faults.is_empty() && f.fault_latched_at == NEVER {
            f.fault_latched_at = n;
        }
        if f.fault_latched_at != NEVER && f.safe_reached_at == NEVER && u == lp.controller.safe_v()
        {
            f.safe_reached_at = n;
        }
        f.samples = n + 1;
    }
    f.mean_sq_err_v2 = if counted > 0 {
        sum_sq.value() / counted as f32
    } else {
        0.0
    };
    f.final_output_v = lp.plant.output_v();
    f.final_command_v = last_command;
    f.faults = lp.state.faults().0;
    (f, lp)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for s in Scenario::ALL {
            assert_eq!(Scenario::from_name(s.name()), Some(s));
        }
        assert_eq!(Scenario::from_name("nope"), None);
    }

    #[test]
    fn every_scenario_passes_its_checks_on_the_host() {
        for s in Scenario::ALL {
            let (c, f) = run(s).unwrap();
            println!(
                "{:<17} rms {:.3e} V  peak {:.3e} V  final y {:.4} V  u {:.4} V  max du {:.3} V  faults {} at {} safe at {} refused {}",
                s.name(),
                f.rms_err_v(),
                f.peak_err_v,
                f.final_output_v,
                f.final_command_v,
                f.max_slew_v,
                f.faults,
                f.fault_latched_at,
                f.safe_reached_at,
                f.refused
            );
            assert_eq!(f.check(s, &c), Ok(()), "{s:?}: {f:?}");
        }
    }

    #[test]
    fn the_generated_triangle_spans_its_range() {
        let c = scenario_controller(Scenario::Triangle).unwrap();
        let mut g = c.generator.start();
        let (mut lo, mut hi) = (f32::MAX, f32::MIN);
        for _ in 0..1000 {
            let r = c.generator.now(&g);
            c.generator.next(&mut g);
            lo = lo.min(r);
            hi = hi.max(r);
        }
        let off = TRIANGLE_OFFSET_V as f32;
        let amp = TRIANGLE_AMPLITUDE_V as f32;
        println!("triangle spans {lo} .. {hi} V");
        assert!((lo - (off - amp)).abs() < 1e-5 && (hi - (off + amp)).abs() < 1e-5);
    }
}
