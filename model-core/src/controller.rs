//! The one per-sample function: what the firmware's 50 kHz interrupt calls and what the QEMU
//! smoke runs call, so that the code proven in simulation is the code that runs.
//!
//! ```text
//!  AdcCode ─► volts ─► sensor checks ─┐
//!  reference (setpoint) ──────────────┼─► mode ─► LagCompensator ─► OutputLimits ─► DacCode
//!                                     └─► faults latch ─► ramp to the safe value ──┘
//! ```
//!
//! # Modes
//! * `Safe` (boot): the command ramps to, and rests at, the safe value (bottom of the window).
//! * `OpenLoop`: the command is the reference itself (volts at the amplifier input).
//! * `ClosedLoop`: the lag compensator acts on `r - y`. Entering it is bumpless: the
//!   compensator starts from the command in force.
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
//! [`OutputLimits::apply`]: finite, inside the window, within the slew limit of the previous
//! command. The step has no loops, no allocation, no panics.

use crate::codes::{AdcCode, DacCode};
use crate::lag::{LagCompensator, LagConfig, LagState};
use crate::limits::{ConfigError, Flags};
use crate::params;

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
    /// The lag compensator closes the loop.
    ClosedLoop,
    /// Keep the present command.
    Hold,
}

/// What the controller is built from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerConfig {
    /// Compensator, sample period and output limits.
    pub lag: LagConfig,
    /// The command at rest and after a fault, volts at the amplifier input.
    pub safe_v: f64,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            lag: LagConfig::default(),
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
    safe_v: f32,
}

/// What one sample produced.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    /// The code for the DAC.
    pub dac: DacCode,
    /// The command in volts (before DAC quantisation).
    pub command_v: f32,
    /// The reference in force, volts.
    pub reference_v: f32,
    /// The measurement, volts.
    pub measured_v: f32,
    /// Latched faults after this sample.
    pub faults: Faults,
    /// What the limits did.
    pub flags: Flags,
}

impl Controller {
    /// Build from a configuration; refuses what the compensator or limits refuse, and a safe
    /// value outside the window.
    pub fn new(c: &ControllerConfig) -> Result<Self, ConfigError> {
        let lag = LagCompensator::new(&c.lag)?;
        if !c.safe_v.is_finite() {
            return Err(ConfigError::NotFinite);
        }
        if !lag.limits.contains(c.safe_v as f32) {
            return Err(ConfigError::BadWindow);
        }
        Ok(Self {
            lag,
            safe_v: c.safe_v as f32,
        })
    }

    /// The safe command, volts.
    pub fn safe_v(&self) -> f32 {
        self.safe_v
    }

    /// One sample: the ADC's code in, the DAC's code out.
    #[inline]
    pub fn step(&self, st: &mut ControllerState, adc: AdcCode) -> Sample {
        let measured_v = adc.volts();
        let r = st.reference_v;
        self.check_sensor(st, adc, measured_v);
        if !r.is_finite() {
            st.faults = st.faults | Faults::NONFINITE;
        }
        let last = st.lag.output_v();
        let (command_v, mut flags) = if !st.faults.is_empty() || st.mode == Mode::Safe {
            self.lag.limits.apply(last, self.safe_v)
        } else {
            match st.mode {
                Mode::ClosedLoop => self.lag.update_flags(&mut st.lag, r - measured_v),
                Mode::OpenLoop => self.lag.limits.apply(last, r),
                Mode::Hold | Mode::Safe => (last, Flags::HELD),
            }
        };
        if flags.contains(Flags::NONFINITE) {
            st.faults = st.faults | Faults::NONFINITE;
        }
        if st.mode != Mode::ClosedLoop || !st.faults.is_empty() {
            // Keep the compensator's state on the command actually sent, so entering closed
            // loop later is bumpless.
            st.lag.reset_to(command_v);
        }
        if st.mode == Mode::Hold {
            flags |= Flags::HELD;
        }
        Sample {
            dac: DacCode::from_volts(command_v),
            command_v,
            reference_v: r,
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
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerState {
    lag: LagState,
    mode: Mode,
    faults: Faults,
    reference_v: f32,
    last_adc: AdcCode,
    frozen_samples: u32,
    command_at_freeze: f32,
}

impl ControllerState {
    /// Boot state: safe mode, command at `controller.safe_v()`.
    pub fn new(controller: &Controller) -> Self {
        Self {
            lag: LagState::new(controller.safe_v),
            mode: Mode::Safe,
            faults: Faults::NONE,
            reference_v: controller.safe_v,
            last_adc: AdcCode::MIN,
            frozen_samples: 0,
            command_at_freeze: controller.safe_v,
        }
    }

    /// Change mode. Closed loop starts from the command in force (bumpless).
    pub fn set_mode(&mut self, mode: Mode) {
        if mode == Mode::ClosedLoop && self.mode != Mode::ClosedLoop {
            self.lag.reset_to(self.lag.output_v());
        }
        self.mode = mode;
    }

    /// The mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Set the reference, volts (sensor volts in closed loop, amplifier volts in open loop).
    /// A non-finite value raises [`Faults::NONFINITE`] at the next step.
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
            self.reference_v = self.lag.output_v();
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
        assert!((s.command_v - 4.0).abs() < 1e-3);
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
}
