//! The one closed-loop harness: [`Controller::step`], the function the board's interrupt
//! runs, closed around a stage model through the converters. Every closed-loop figure the
//! project publishes comes from here: the QEMU scenarios ([`crate::scenarios`], run on the host
//! and on the Cortex-M), `piezo loop`'s margins and bandwidth, `piezo track`'s tracking tables.
//!
//! # One sample, as on the board
//! ```text
//!            ┌──────────────────────── plant adapter (LoopPlant) ──────────────────────┐
//!  AdcCode ◄─┤ ADC(16 bit) ◄─ (+) noise ◄─ sensor_v ◄─ StageModel ◄─ delay ◄─ (+) ◄─ DAC │◄─ DacCode
//!            └────────────────────────────────────────────────────────────── injection ──┘
//!     │                                                                                     ▲
//!     └──────────────────────────────► Controller::step ──────────────────────────────────┘
//! ```
//! Sample `n`: the adapter reads the stage's sensor at `n` ([`LoopPlant::read`], noise and
//! quantisation included), the controller steps on that code, the adapter holds the DAC code's
//! volts (plus an injected signal, for loop-gain measurements) for one period and the stage
//! advances to `n + 1` ([`LoopPlant::drive`]). The stage's own delay (the 85 us of eq. 4.4) is
//! the loop delay of the thesis' identification; the adapter can add whole samples more
//! ([`Converted::with_extra_delay`]) to model a slower board.
//!
//! # What is generic
//! The stage ([`StageModel`]): the linear plant of eq. 4.4 ([`LinearStage`]) or any ch. 6
//! stage ([`FullStage`], built from [`StageConfig`]; the host builds it from model files). The
//! noise ([`SensorNoise`]): none, the scenarios' seeded uniform noise ([`UniformNoise`]), or a
//! stage's own sensor (a [`FullStage`] whose sensor has noise). Fault injection at the ADC and
//! configuration swaps stay with the caller ([`ClosedLoop::step_reading`], the public
//! `controller` field).
//!
//! `no_std`, no allocation, bounded: the per-sample path is [`Controller::step`] plus a few
//! arithmetic operations; nothing here loops except [`ClosedLoop::prime`] (at most
//! [`PRIME_MAX_STEPS`] controller steps).

use crate::codes::{AdcCode, DacCode};
use crate::controller::{Controller, ControllerState, Mode, Sample};
use crate::limits::ConfigError;
use crate::plant::{LinearPlant, LinearPlantConfig, PlantState};
use crate::stage::{Stage, StageConfig, StageState};

/// What the loop drives: input volts at the amplifier's control input, output sensor monitor
/// volts.
pub trait StageModel {
    /// The true output at the present sample, sensor volts without noise: what the error
    /// figures are measured on.
    fn output_v(&self) -> f32;
    /// What the sensor's monitor gives at the present sample, volts, before the loop's ADC
    /// (with the stage's own sensor noise, if it has a sensor of its own).
    fn sensor_v(&self) -> f32;
    /// Hold `u_v` for one period and advance.
    fn step(&mut self, u_v: f32);
}

/// The linear plant of eq. 4.4 with its state; its sensor is ideal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearStage {
    /// Configuration.
    pub plant: LinearPlant,
    /// State.
    pub state: PlantState,
}

impl LinearStage {
    /// `c` at rest with `u_v` held for ever.
    pub fn new(c: &LinearPlantConfig, u_v: f32) -> Result<Self, ConfigError> {
        let plant = LinearPlant::new(c)?;
        Ok(Self {
            state: plant.steady_state(u_v),
            plant,
        })
    }

    /// The thesis plant at 50 kHz at rest at 0 V.
    pub fn thesis() -> Result<Self, ConfigError> {
        Self::new(&LinearPlantConfig::default(), 0.0)
    }
}

impl StageModel for LinearStage {
    #[inline]
    fn output_v(&self) -> f32 {
        self.plant.output(&self.state)
    }
    #[inline]
    fn sensor_v(&self) -> f32 {
        self.output_v()
    }
    #[inline]
    fn step(&mut self, u_v: f32) {
        self.plant.step(&mut self.state, u_v);
    }
}

/// A ch. 6 stage with its state; the sensor (gain, noise, ADC) is the stage's own.
#[derive(Clone, Debug)]
pub struct FullStage {
    /// Configuration.
    pub stage: Stage,
    /// State.
    pub state: StageState,
}

impl FullStage {
    /// `stage` at rest with `u_v` held for ever ([`Stage::steady_state`]).
    pub fn new(stage: Stage, u_v: f32) -> Self {
        Self {
            state: stage.steady_state(u_v),
            stage,
        }
    }

    /// The thesis' overall model (`StageConfig::thesis_full`) at rest at 0 V.
    pub fn thesis() -> Result<Self, ConfigError> {
        Ok(Self::new(Stage::new(&StageConfig::thesis_full())?, 0.0))
    }
}

impl StageModel for FullStage {
    #[inline]
    fn output_v(&self) -> f32 {
        self.state.signals().position_v
    }
    #[inline]
    fn sensor_v(&self) -> f32 {
        self.state.signals().measured_v
    }
    #[inline]
    fn step(&mut self, u_v: f32) {
        self.stage.step(&mut self.state, u_v);
    }
}

/// Noise added to the sensor's monitor before the ADC.
pub trait SensorNoise {
    /// The next sample, volts.
    fn next_v(&mut self) -> f32;
}

/// No noise (a stage whose own sensor is noisy, or a noiseless measurement).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NoNoise;

impl SensorNoise for NoNoise {
    #[inline]
    fn next_v(&mut self) -> f32 {
        0.0
    }
}

/// Uniform noise in `[-amplitude, amplitude)` from a seeded xorshift32: the same sequence on
/// every target, with no library maths (the QEMU scenarios compare bit for bit).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UniformNoise {
    amplitude_v: f32,
    state: u32,
}

impl UniformNoise {
    /// Noise of `amplitude_v` from `seed` (a zero seed is replaced: xorshift would stay at 0).
    pub const fn new(amplitude_v: f32, seed: u32) -> Self {
        Self {
            amplitude_v,
            state: if seed == 0 { 0x9E37_79B9 } else { seed },
        }
    }

    /// The next value in `[-1, 1)`.
    #[inline]
    pub fn next_unit(&mut self) -> f32 {
        let mut x = self.state;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.state = x;
        (x >> 8) as f32 * (2.0 / 16_777_216.0) - 1.0
    }
}

impl SensorNoise for UniformNoise {
    #[inline]
    fn next_v(&mut self) -> f32 {
        self.amplitude_v * self.next_unit()
    }
}

/// The plant as the controller sees it: DAC codes in, ADC codes out.
pub trait LoopPlant {
    /// The true output at the present sample, sensor volts (no noise, no quantisation).
    fn output_v(&self) -> f32;
    /// The ADC's code at the present sample.
    fn read(&mut self) -> AdcCode;
    /// Hold `dac`'s output for one period and advance; returns the volts that reached the
    /// stage's input this period (after injection and delay).
    fn drive(&mut self, dac: DacCode) -> f32;
}

/// Longest extra delay [`Converted`] can add, samples.
pub const MAX_EXTRA_DELAY_SAMPLES: usize = 16;

/// The standard plant adapter: a [`StageModel`] behind the 14-bit DAC and the 16-bit ADC
/// (both over +-10 V, [`crate::codes`]), with sensor noise, an optional extra delay of whole
/// samples and a signal injected at the plant input.
#[derive(Clone, Debug)]
pub struct Converted<S, N> {
    /// The stage.
    pub stage: S,
    /// The noise added before the ADC.
    pub noise: N,
    /// Added to the DAC's volts at the stage's input (before the extra delay): set it before
    /// each [`ClosedLoop::step`] to measure the loop gain by injection.
    pub injection_v: f32,
    delay: [f32; MAX_EXTRA_DELAY_SAMPLES],
    delay_samples: usize,
    delay_head: usize,
}

impl<S: StageModel, N: SensorNoise> Converted<S, N> {
    /// `stage` behind the converters, with `noise`, no extra delay, no injection.
    pub fn new(stage: S, noise: N) -> Self {
        Self {
            stage,
            noise,
            injection_v: 0.0,
            delay: [0.0; MAX_EXTRA_DELAY_SAMPLES],
            delay_samples: 0,
            delay_head: 0,
        }
    }

    /// The same with `samples` more of delay between the DAC and the stage (at most
    /// [`MAX_EXTRA_DELAY_SAMPLES`]), the line filled with `u_v` (the stage at rest there).
    pub fn with_extra_delay(mut self, samples: usize, u_v: f32) -> Result<Self, ConfigError> {
        if samples > MAX_EXTRA_DELAY_SAMPLES {
            return Err(ConfigError::outside(
                "extra_delay_samples",
                0.0,
                MAX_EXTRA_DELAY_SAMPLES as f64,
            ));
        }
        self.delay = [u_v; MAX_EXTRA_DELAY_SAMPLES];
        self.delay_samples = samples;
        self.delay_head = 0;
        Ok(self)
    }
}

impl<S: StageModel, N: SensorNoise> LoopPlant for Converted<S, N> {
    #[inline]
    fn output_v(&self) -> f32 {
        self.stage.output_v()
    }
    #[inline]
    fn read(&mut self) -> AdcCode {
        AdcCode::from_volts(self.stage.sensor_v() + self.noise.next_v())
    }
    #[inline]
    fn drive(&mut self, dac: DacCode) -> f32 {
        let mut u = dac.volts() + self.injection_v;
        if self.delay_samples > 0 {
            // A ring of `delay_samples` slots: read the oldest, write the newest in its place.
            let head = self.delay_head % self.delay_samples;
            if let Some(slot) = self.delay.get_mut(head) {
                core::mem::swap(slot, &mut u);
            }
            self.delay_head = (head + 1) % self.delay_samples;
        }
        self.stage.step(u);
        u
    }
}

/// What one loop sample produced.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LoopSample {
    /// The controller's sample (DAC code, command, reference, measurement, faults, flags).
    pub sample: Sample,
    /// The true stage output when the ADC read, sensor volts.
    pub output_v: f32,
    /// The code the controller read.
    pub adc: AdcCode,
    /// The volts that reached the stage's input this period.
    pub plant_input_v: f32,
}

impl LoopSample {
    /// The reference in force minus the true output, volts (NaN when the reference is).
    #[inline]
    pub fn error_v(&self) -> f32 {
        self.sample.reference_v - self.output_v
    }
}

/// Most controller steps [`ClosedLoop::prime`] takes: enough to slew across the whole
/// amplifier input range at the slowest slew limit the controller accepts per sample.
pub const PRIME_MAX_STEPS: u32 = 4096;

/// The controller closed around a plant.
#[derive(Clone, Debug)]
pub struct ClosedLoop<P> {
    /// The controller's configuration (swap it between steps as the firmware does).
    pub controller: Controller,
    /// The controller's state.
    pub state: ControllerState,
    /// The plant.
    pub plant: P,
}

impl<P: LoopPlant> ClosedLoop<P> {
    /// `controller` booted (safe mode, command at its safe value) in front of `plant`.
    pub fn new(controller: Controller, plant: P) -> Self {
        Self {
            state: ControllerState::new(&controller),
            controller,
            plant,
        }
    }

    /// One sample.
    #[inline]
    pub fn step(&mut self) -> LoopSample {
        self.step_reading(|adc| adc)
    }

    /// One sample, the ADC's code passed through `fault` first (a saturated or stuck sensor).
    #[inline]
    pub fn step_reading(&mut self, fault: impl FnOnce(AdcCode) -> AdcCode) -> LoopSample {
        self.step_full(fault, 0.0)
    }

    /// One sample with a learned correction added to the loop's reference
    /// ([`Controller::step_with_correction`], [`crate::learning`]).
    #[inline]
    pub fn step_with_correction(&mut self, correction_v: f32) -> LoopSample {
        self.step_full(|adc| adc, correction_v)
    }

    #[inline]
    fn step_full(
        &mut self,
        fault: impl FnOnce(AdcCode) -> AdcCode,
        correction_v: f32,
    ) -> LoopSample {
        let output_v = self.plant.output_v();
        let adc = fault(self.plant.read());
        let sample = self
            .controller
            .step_with_correction(&mut self.state, adc, correction_v);
        let plant_input_v = self.plant.drive(sample.dac);
        LoopSample {
            sample,
            output_v,
            adc,
            plant_input_v,
        }
    }

    /// Bring the command to `u_v` in open loop without advancing the plant (the plant is
    /// assumed at rest there already, e.g. [`LinearStage::new`]): how a test starts the loop
    /// in its operating point. Returns false if the command did not get there within
    /// [`PRIME_MAX_STEPS`] (a fault, or `u_v` outside the window). The mode is left open loop.
    pub fn prime(&mut self, u_v: f32) -> bool {
        self.state.set_mode(Mode::OpenLoop);
        self.state.set_reference(u_v);
        for _ in 0..PRIME_MAX_STEPS {
            if self.state.command_v() == u_v {
                return self.state.faults().is_empty();
            }
            let adc = self.plant.read();
            self.controller.step(&mut self.state, adc);
        }
        false
    }

    /// Close the loop (bumpless, from the command in force) on the external reference
    /// `reference_v`, or on the on-board generator if the controller uses it.
    pub fn close(&mut self, reference_v: f32) {
        self.state.set_reference(reference_v);
        self.state.set_mode(Mode::ClosedLoop);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::controller::ControllerConfig;

    fn thesis_loop() -> ClosedLoop<Converted<LinearStage, NoNoise>> {
        let c = Controller::new(&ControllerConfig::default()).unwrap();
        ClosedLoop::new(c, Converted::new(LinearStage::thesis().unwrap(), NoNoise))
    }

    #[test]
    fn primed_loop_holds_its_operating_point() {
        let mut l = thesis_loop();
        let u0 = 5.0;
        l.plant.stage = LinearStage::new(&LinearPlantConfig::default(), u0).unwrap();
        assert!(l.prime(u0));
        let y0 = l.plant.output_v();
        l.close(y0);
        let mut worst: f32 = 0.0;
        for _ in 0..5000 {
            let s = l.step();
            worst = worst.max((s.output_v - y0).abs());
            assert!(s.sample.faults.is_empty());
        }
        // Only the converters' quantisation moves it: well under one DAC LSB times the gain.
        println!("largest departure {worst} V");
        assert!(worst < DacCode::VOLT_PER_LSB, "{worst}");
    }

    #[test]
    fn extra_delay_delays_the_plant_input_by_whole_samples() {
        let mut p = Converted::new(LinearStage::thesis().unwrap(), NoNoise)
            .with_extra_delay(3, 0.0)
            .unwrap();
        let code = DacCode::from_volts(2.0);
        let seen: [f32; 5] = core::array::from_fn(|_| p.drive(code));
        assert_eq!(&seen[..3], &[0.0; 3]);
        assert_eq!(seen[3], code.volts());
        assert!(
            Converted::new(LinearStage::thesis().unwrap(), NoNoise)
                .with_extra_delay(MAX_EXTRA_DELAY_SAMPLES + 1, 0.0)
                .is_err()
        );
    }

    #[test]
    fn injection_reaches_the_stage_input() {
        let mut p = Converted::new(LinearStage::thesis().unwrap(), NoNoise);
        p.injection_v = 0.25;
        assert_eq!(
            p.drive(DacCode::from_volts(1.0)),
            DacCode::from_volts(1.0).volts() + 0.25
        );
    }

    #[test]
    fn uniform_noise_stays_in_its_band_and_has_its_variance() {
        let mut n = UniformNoise::new(0.002, 7);
        let (mut s2, count) = (0.0f64, 100_000);
        for _ in 0..count {
            let v = n.next_v();
            assert!((-0.002..0.002).contains(&v));
            s2 += (v as f64) * (v as f64);
        }
        // Variance of U(-a, a) is a^2 / 3; 1e5 samples pin it to about 0.5 %.
        let ratio = s2 / count as f64 / (0.002f64 * 0.002 / 3.0);
        assert!((ratio - 1.0).abs() < 0.02, "{ratio}");
    }
}
