//! The one per-sample function: what the firmware's 50 kHz interrupt calls and what the QEMU
//! smoke runs call, so that the code proven in simulation is the code that runs.
//!
//! ```text
//!  ReferenceGenerator ──(r, k samples ahead)──► PreFilter ──► r' ─(+)─► LagCompensator ─┐
//!   or external r                                                 ▲ -                    (+)◄─ hysteresis
//!  AdcCode ─► volts y ─► sensor checks ───────────────────────────┘                      │     feedforward
//!                              └─► faults latch ─► ramp to the safe value ─► OutputLimits ─► DacCode
//! ```
//!
//! # Reference
//! Either external (set by [`ControllerState::set_reference`], no preview: the pre-filter's
//! lag of `preview_samples` shows in the tracking) or the on-board [`ReferenceGenerator`],
//! which hands the pre-filter the reference `preview_samples` ahead so the stage follows the
//! reference itself (trajectory planning, sec. 4.1.2.4).
//!
//! # Hysteresis feedforward
//! With a [`HysteresisTable`], the loop may add `H^-1(r') - r'/k`: the inverse table's
//! departure from the linear inverse (`k` the table's mean slope). The loop then sees a plant
//! that is close to linear, and the compensator and pre-filter, designed for the linear plant,
//! handle the rest. The sum goes through the compensator's anti-windup and the limits.
//!
//! # Modes
//! * `Safe` (boot): the command ramps to, and rests at, the safe value (bottom of the window).
//! * `OpenLoop`: the command is the reference itself (volts at the amplifier input).
//! * `ClosedLoop`: the loop acts on `r' - y`. Entering it is bumpless: the compensator starts
//!   from the command in force, the generator from its start, the pre-filter at rest.
//! * `Hold`: the command stays where it is.
//!
//! # Faults
//! Checked every sample; any fault latches, the command ramps to the safe value at the slew
//! limit, and only [`ControllerState::clear_faults`] (an explicit command) clears them, after
//! which the mode is `Safe`. Detected here: sensor out of range (monitor outside
//! -0.5..10.5 V), sensor stuck (code frozen for 5 ms while the command moved 0.1 V), a
//! non-finite reference or an internal NaN. Raised by the firmware with
//! [`ControllerState::raise`]: interrupt overrun, watchdog.
//!
//! # Guarantees
//! Whatever the mode, the reference or the faults, every command leaves through
//! [`crate::limits::OutputLimits::apply`]: finite, inside the window, within the slew limit of
//! the previous command. The step has no unbounded loops, no allocation, no panics.

use crate::codes::{AdcCode, DacCode};
use crate::hysteresis::{HysteresisMemory, HysteresisTable};
use crate::lag::{LagCompensator, LagConfig, LagState};
use crate::limits::{ConfigError, Flags, Reason, check_finite};
use crate::params;
use crate::plant::LinearPlantConfig;
use crate::prefilter::{PreFilter, PreFilterConfig, PreFilterState};
use crate::reference::{ReferenceConfig, ReferenceGenerator, ReferenceState};

/// Latched fault conditions, as a small bit set.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Faults(pub u8);

impl Faults {
    /// No fault.
    pub const NONE: Self = Self(0);
    /// The sensor reads outside its plausible range (saturated, over-range, disconnected).
    pub const SENSOR_RANGE: Self = Self(1);
    /// The sensor code is frozen while the command moves.
    pub const SENSOR_STUCK: Self = Self(2);
    /// A NaN or infinite value met in the reference or the pipeline.
    pub const NONFINITE: Self = Self(4);
    /// The interrupt did not finish within its period (raised by the firmware).
    pub const OVERRUN: Self = Self(8);
    /// A watchdog condition (raised by the firmware).
    pub const WATCHDOG: Self = Self(16);

    /// True if any bit of `other` is set.
    #[inline]
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 != 0
    }

    /// True if no fault is set.
    #[inline]
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
}

impl core::ops::BitOr for Faults {
    type Output = Self;
    fn bitor(self, rhs: Self) -> Self {
        Self(self.0 | rhs.0)
    }
}

/// Operating mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Mode {
    /// Rest at the safe value.
    #[default]
    Safe,
    /// The reference is the command.
    OpenLoop,
    /// The loop is closed.
    ClosedLoop,
    /// Keep the present command.
    Hold,
}

/// Where the reference comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ReferenceSource {
    /// Set by [`ControllerState::set_reference`]; no preview.
    #[default]
    External,
    /// The on-board generator, with preview.
    Generator,
}

/// What the controller is built from. The sample period is the compensator's; the plant
/// model and the generator are re-timed to it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerConfig {
    /// Compensator, sample period and output limits.
    pub lag: LagConfig,
    /// The linear plant the pre-filter inverts.
    pub plant: LinearPlantConfig,
    /// Pre-filter (tau, mode, delay handling).
    pub prefilter: PreFilterConfig,
    /// The on-board reference.
    pub reference: ReferenceConfig,
    /// External reference or the generator.
    pub source: ReferenceSource,
    /// Hysteresis table for feedforward (the thesis default unless identified).
    pub hysteresis: HysteresisTable,
    /// Add the hysteresis feedforward in closed loop.
    pub hysteresis_ff: bool,
    /// The command at rest and after a fault, volts at the amplifier input.
    pub safe_v: f64,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            lag: LagConfig::default(),
            plant: LinearPlantConfig::default(),
            prefilter: PreFilterConfig::default(),
            reference: ReferenceConfig::default(),
            source: ReferenceSource::External,
            hysteresis: HysteresisTable::thesis_default(),
            hysteresis_ff: false,
            safe_v: params::SAFE_OUTPUT_V,
        }
    }
}

/// The controller's configuration, `Copy`: built in a low-priority task and swapped into the
/// interrupt whole.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Controller {
    /// The compensator and its limits.
    pub lag: LagCompensator,
    /// The pre-filter.
    pub prefilter: PreFilter,
    /// The reference generator (its preview matches the pre-filter's).
    pub generator: ReferenceGenerator,
    /// The hysteresis table used for feedforward.
    pub hysteresis: HysteresisTable,
    source: ReferenceSource,
    hysteresis_ff: bool,
    /// Mean slope of the table, sensor volts per amplifier volt (the linear part).
    hysteresis_slope: f32,
    safe_v: f32,
}

/// What one sample produced.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    /// The code for the DAC.
    pub dac: DacCode,
    /// The command in volts (before DAC quantisation).
    pub command_v: f32,
    /// The reference the output should match now, volts.
    pub reference_v: f32,
    /// The measurement, volts.
    pub measured_v: f32,
    /// Latched faults after this sample.
    pub faults: Faults,
    /// What the limits did.
    pub flags: Flags,
}

impl Controller {
    /// Build from a configuration; refuses what any block refuses, and a safe value outside
    /// the window.
    pub fn new(c: &ControllerConfig) -> Result<Self, ConfigError> {
        let lag = LagCompensator::new(&c.lag)?;
        check_finite("safe_v", c.safe_v)?;
        if !lag.limits.contains(c.safe_v as f32) {
            let l = lag.limits;
            return Err(ConfigError::outside(
                "safe_v",
                l.min_v as f64,
                l.max_v as f64,
            ));
        }
        let period_s = c.lag.period_s;
        let plant = LinearPlantConfig {
            period_s,
            ..c.plant
        };
        let prefilter = PreFilter::new(&c.lag, &plant, &c.prefilter)?;
        let reference = ReferenceConfig {
            period_s,
            ..c.reference
        };
        let generator = ReferenceGenerator::new(&reference, prefilter.preview_samples())?;
        let (u0, u1) = c.hysteresis.input_range_v();
        let (y0, y1) = c.hysteresis.output_range_v();
        let slope = (y1 - y0) / (u1 - u0);
        if !(slope.is_finite() && slope > 0.0) {
            // The table's output must rise over its input range.
            return Err(ConfigError::new("hysteresis", Reason::NotMonotone));
        }
        Ok(Self {
            lag,
            prefilter,
            generator,
            hysteresis: c.hysteresis,
            source: c.source,
            hysteresis_ff: c.hysteresis_ff,
            hysteresis_slope: slope,
            safe_v: c.safe_v as f32,
        })
    }

    /// The safe command, volts.
    pub fn safe_v(&self) -> f32 {
        self.safe_v
    }

    /// The reference now and the one handed to the pre-filter (ahead by the preview when the
    /// generator is the source). Advances the generator.
    #[inline]
    fn references(&self, st: &mut ControllerState) -> (f32, f32) {
        match self.source {
            ReferenceSource::External => (st.reference_v, st.reference_v),
            ReferenceSource::Generator => {
                let now = self.generator.now(&st.generator);
                (now, self.generator.next(&mut st.generator))
            }
        }
    }

    /// The hysteresis feedforward for the filtered reference `r_v` (zero when off).
    #[inline]
    fn feedforward(&self, st: &mut ControllerState, r_v: f32) -> f32 {
        if self.hysteresis_ff {
            self.hysteresis.inverse(&mut st.hysteresis, r_v) - r_v / self.hysteresis_slope
        } else {
            0.0
        }
    }

    /// Put the loop's states at rest for entering closed loop at the present command.
    fn enter_closed_loop(&self, st: &mut ControllerState) {
        st.generator = self.generator.start();
        let r = match self.source {
            ReferenceSource::External => st.reference_v,
            ReferenceSource::Generator => self.generator.now(&st.generator),
        };
        let r = if r.is_finite() { r } else { 0.0 };
        st.prefilter = self.prefilter.settled_state(r);
        st.hysteresis
            .reset(&self.hysteresis, r / self.hysteresis_slope);
        let ff = self.feedforward(st, r);
        let u = st.lag.output_v();
        st.lag.reset_with_feedforward(u, ff);
    }

    /// One sample: the ADC's code in, the DAC's code out.
    #[inline]
    pub fn step(&self, st: &mut ControllerState, adc: AdcCode) -> Sample {
        self.step_with_correction(st, adc, 0.0)
    }

    /// The present sample's index within the generator's repeat
    /// ([`ReferenceGenerator::index`]): read before the step, it indexes a learned table.
    #[inline]
    pub fn reference_index(&self, st: &ControllerState) -> u32 {
        self.generator.index(&st.generator)
    }

    /// [`Self::step`] with a learned correction ([`crate::learning`]) added, in closed loop
    /// only, to the loop's reference after the pre-filter: it goes through the compensator,
    /// its anti-windup and the output limits like the rest. A non-finite correction is a
    /// [`Faults::NONFINITE`].
    #[inline]
    pub fn step_with_correction(
        &self,
        st: &mut ControllerState,
        adc: AdcCode,
        correction_v: f32,
    ) -> Sample {
        let measured_v = adc.volts();
        self.check_sensor(st, adc, measured_v);
        if st.entering {
            st.entering = false;
            if st.mode == Mode::ClosedLoop {
                self.enter_closed_loop(st);
            }
        }
        let active = st.faults.is_empty() && matches!(st.mode, Mode::ClosedLoop | Mode::OpenLoop);
        let (r_now, r_ahead) = if active {
            self.references(st)
        } else {
            (st.last_reference_v, st.last_reference_v)
        };
        if active && !(r_now.is_finite() && r_ahead.is_finite()) {
            st.faults = st.faults | Faults::NONFINITE;
        }
        let last = st.lag.output_v();
        let (command_v, mut flags) = if !st.faults.is_empty() || st.mode == Mode::Safe {
            self.lag.limits.apply(last, self.safe_v)
        } else {
            match st.mode {
                Mode::ClosedLoop => {
                    let r_loop = self.prefilter.step(&mut st.prefilter, r_ahead);
                    let ff = self.feedforward(st, r_loop);
                    self.lag
                        .update_ff(&mut st.lag, r_loop + correction_v - measured_v, ff)
                }
                Mode::OpenLoop => self.lag.limits.apply(last, r_now),
                Mode::Hold | Mode::Safe => (last, Flags::HELD),
            }
        };
        if flags.contains(Flags::NONFINITE) {
            st.faults = st.faults | Faults::NONFINITE;
        }
        if st.mode != Mode::ClosedLoop || !st.faults.is_empty() {
            // Keep the compensator's state on the command actually sent.
            st.lag.reset_to(command_v);
        }
        if st.mode == Mode::Hold {
            flags |= Flags::HELD;
        }
        if r_now.is_finite() {
            st.last_reference_v = r_now;
        }
        Sample {
            dac: DacCode::from_volts(command_v),
            command_v,
            reference_v: r_now,
            measured_v,
            faults: st.faults,
            flags,
        }
    }

    fn check_sensor(&self, st: &mut ControllerState, adc: AdcCode, measured_v: f32) {
        if !(params::SENSOR_VALID_MIN_V as f32..=params::SENSOR_VALID_MAX_V as f32)
            .contains(&measured_v)
            || adc.near_rail(16)
        {
            st.faults = st.faults | Faults::SENSOR_RANGE;
        }
        let command = st.lag.output_v();
        if adc == st.last_adc {
            st.frozen_samples = st.frozen_samples.saturating_add(1);
            if st.frozen_samples >= params::SENSOR_STUCK_SAMPLES
                && (command - st.command_at_freeze).abs() > params::SENSOR_STUCK_COMMAND_V as f32
            {
                st.faults = st.faults | Faults::SENSOR_STUCK;
            }
        } else {
            st.frozen_samples = 0;
            st.command_at_freeze = command;
            st.last_adc = adc;
        }
    }
}

/// The controller's history.
#[derive(Clone, Debug, PartialEq)]
pub struct ControllerState {
    lag: LagState,
    prefilter: PreFilterState,
    generator: ReferenceState,
    hysteresis: HysteresisMemory,
    mode: Mode,
    entering: bool,
    faults: Faults,
    reference_v: f32,
    last_reference_v: f32,
    last_adc: AdcCode,
    frozen_samples: u32,
    command_at_freeze: f32,
}

impl ControllerState {
    /// Boot state: safe mode, command at `controller.safe_v()`.
    pub fn new(controller: &Controller) -> Self {
        let safe = controller.safe_v;
        Self {
            lag: LagState::new(safe),
            prefilter: controller.prefilter.settled_state(0.0),
            generator: controller.generator.start(),
            hysteresis: HysteresisMemory::new(),
            mode: Mode::Safe,
            entering: false,
            faults: Faults::NONE,
            reference_v: 0.0,
            last_reference_v: 0.0,
            last_adc: AdcCode::MIN,
            frozen_samples: 0,
            command_at_freeze: safe,
        }
    }

    /// Change mode. Closed loop starts, at the next step, from the command in force
    /// (bumpless), with the generator at its start and the pre-filter at rest.
    pub fn set_mode(&mut self, mode: Mode) {
        if mode != self.mode {
            self.entering = true;
        }
        self.mode = mode;
    }

    /// The mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Set the external reference, volts (sensor volts in closed loop, amplifier volts in
    /// open loop). A non-finite value raises [`Faults::NONFINITE`] at the next active step.
    pub fn set_reference(&mut self, reference_v: f32) {
        self.reference_v = reference_v;
    }

    /// Latch a fault raised outside the controller (overrun, watchdog).
    pub fn raise(&mut self, f: Faults) {
        self.faults = self.faults | f;
    }

    /// The latched faults.
    pub fn faults(&self) -> Faults {
        self.faults
    }

    /// Clear every fault (an explicit command); the mode becomes `Safe`.
    pub fn clear_faults(&mut self) {
        self.faults = Faults::NONE;
        self.mode = Mode::Safe;
        self.frozen_samples = 0;
        self.command_at_freeze = self.lag.output_v();
        if !self.reference_v.is_finite() {
            self.reference_v = self.last_reference_v;
        }
    }

    /// The last command, volts.
    pub fn command_v(&self) -> f32 {
        self.lag.output_v()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::{LinearPlant, LinearPlantConfig};
    use crate::reference::Shape;

    #[test]
    fn boots_safe_and_closes_the_loop_bumplessly() {
        let c = Controller::new(&ControllerConfig::default()).unwrap();
        let mut st = ControllerState::new(&c);
        let s = c.step(&mut st, AdcCode::from_volts(0.0));
        assert_eq!(s.command_v, 0.0);
        st.set_mode(Mode::OpenLoop);
        st.set_reference(4.0);
        for _ in 0..3 {
            c.step(&mut st, AdcCode::from_volts(0.01));
        }
        assert_eq!(st.command_v(), 4.0);
        st.set_mode(Mode::ClosedLoop);
        st.set_reference(3.16);
        let s = c.step(&mut st, AdcCode::from_volts(3.16));
        assert!((s.command_v - 4.0).abs() < 1e-3, "{}", s.command_v);
    }

    #[test]
    fn a_fault_latches_and_ramps_to_safe() {
        let c = Controller::new(&ControllerConfig::default()).unwrap();
        let mut st = ControllerState::new(&c);
        st.set_mode(Mode::OpenLoop);
        st.set_reference(9.0);
        for _ in 0..5 {
            c.step(&mut st, AdcCode::from_volts(1.0));
        }
        assert_eq!(st.command_v(), 9.0);
        let s = c.step(&mut st, AdcCode::MAX);
        assert!(s.faults.contains(Faults::SENSOR_RANGE));
        assert_eq!(s.command_v, 6.0, "one slew step (3 V) towards 0");
        for _ in 0..5 {
            c.step(&mut st, AdcCode::from_volts(1.0));
        }
        assert_eq!(st.command_v(), 0.0);
        assert!(st.faults().contains(Faults::SENSOR_RANGE), "latched");
        st.clear_faults();
        assert_eq!(st.mode(), Mode::Safe);
    }

    #[test]
    fn generator_with_preview_tracks_a_sine_on_the_linear_plant() {
        let cfg = ControllerConfig {
            reference: ReferenceConfig {
                shape: Shape::Sine,
                offset_v: 4.0,
                amplitude_v: 3.0,
                freq_hz: 100.0,
                ..ReferenceConfig::default()
            },
            source: ReferenceSource::Generator,
            ..ControllerConfig::default()
        };
        let c = Controller::new(&cfg).unwrap();
        let plant = LinearPlant::new(&LinearPlantConfig::default()).unwrap();
        let mut ps = plant.steady_state(4.0 / params::PLANT_GAIN as f32);
        let mut st = ControllerState::new(&c);
        // Open loop at the operating point first, then close the loop.
        st.set_mode(Mode::OpenLoop);
        st.set_reference(4.0 / params::PLANT_GAIN as f32);
        for _ in 0..3 {
            let s = c.step(&mut st, AdcCode::from_volts(plant.output(&ps)));
            plant.step(&mut ps, s.dac.volts());
        }
        st.set_mode(Mode::ClosedLoop);
        let mut worst: f32 = 0.0;
        for n in 0..10_000 {
            let y = plant.output(&ps);
            let s = c.step(&mut st, AdcCode::from_volts(y));
            plant.step(&mut ps, s.dac.volts());
            if n > 5_000 {
                worst = worst.max((y - s.reference_v).abs());
            }
            assert!(s.faults.is_empty());
        }
        // Feedback alone errs by 0.6 V peak here; the pre-filter with preview by 6.8 mV
        // (host-tests' tracking table, with 1 mV noise); allow twice that.
        println!("peak tracking error {worst} V");
        assert!(worst < 0.014, "{worst}");
    }
}
