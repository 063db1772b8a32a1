//! TEMPORARY stand-in for model_core::controller until the lead's module lands (not committed).
#![allow(missing_docs, dead_code)]
use model_core::lag::LagConfig;
use model_core::limits::{ConfigError, Flags};
use model_core::{AdcCode, DacCode};
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ReferenceConfig {
    Step {
        level_v: f64,
    },
    Sine {
        offset_v: f64,
        amplitude_v: f64,
        freq_hz: f64,
    },
    Triangle {
        offset_v: f64,
        amplitude_v: f64,
        freq_hz: f64,
    },
}
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerConfig {
    pub lag: LagConfig,
    pub reference: ReferenceConfig,
    pub prefilter_tau_s: f64,
    pub hysteresis_ff: bool,
}
#[derive(Clone, Copy)]
pub struct Controller {
    x: f32,
}
impl Controller {
    pub fn new(_c: &ControllerConfig) -> Result<Self, ConfigError> {
        Ok(Self { x: 0.0 })
    }
    pub fn step(&self, state: &mut ControllerState, adc: AdcCode) -> Sample {
        Sample {
            dac: DacCode::from_volts(self.x),
            command_v: 0.0,
            reference_v: 0.0,
            measured_v: adc.volts(),
            faults: state.faults,
            flags: Flags::NONE,
        }
    }
}
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Safe,
    OpenLoop,
    ClosedLoop,
    Hold,
}
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Faults(pub u8);
impl Faults {
    pub const SENSOR_RANGE: Self = Self(1);
    pub const NONFINITE: Self = Self(2);
    pub const OVERRUN: Self = Self(4);
    pub const WATCHDOG: Self = Self(8);
    pub const SENSOR_STUCK: Self = Self(16);
    pub const BAD_CONFIG: Self = Self(32);
    pub fn bits(self) -> u8 {
        self.0
    }
}
pub struct ControllerState {
    mode: Mode,
    faults: Faults,
}
impl ControllerState {
    pub fn new() -> Self {
        Self {
            mode: Mode::Safe,
            faults: Faults(0),
        }
    }
    pub fn set_mode(&mut self, m: Mode) {
        self.mode = m
    }
    pub fn raise(&mut self, f: Faults) {
        self.faults.0 |= f.0
    }
    pub fn clear_faults(&mut self) {
        self.faults = Faults(0)
    }
    pub fn faults(&self) -> Faults {
        self.faults
    }
    pub fn mode(&self) -> Mode {
        self.mode
    }
}
pub struct Sample {
    pub dac: DacCode,
    pub command_v: f32,
    pub reference_v: f32,
    pub measured_v: f32,
    pub faults: Faults,
    pub flags: Flags,
}
