//! The closed loop on the host: model-core's compensator and plant, with the converters
//! (16-bit ADC, 14-bit DAC, both +-10 V) and optional sensor noise in between.
//!
//! Order of one sample `n`, as on the board: the ADC reads `y[n]` (plus noise), the
//! compensator computes `u[n]` from `r[n] - y[n]`, the DAC holds `u[n]` for one period, the
//! plant advances to `y[n+1]`. The plant's 85 us delay is the whole loop delay of the thesis'
//! identification (sec. 4.1.1), so the simulation adds none of its own.

use model_core::lag::{LagCompensator, LagConfig, LagState};
use model_core::limits::{ConfigError, Flags};
use model_core::plant::{LinearPlant, LinearPlantConfig, PlantState};
use model_core::{AdcCode, DacCode};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, Normal};

/// What one sample produced.
#[derive(Clone, Copy, Debug, Default)]
pub struct LoopSample {
    /// The sensor signal the ADC read (with noise and quantisation), volts.
    pub measured_v: f64,
    /// The true plant output at this sample, volts.
    pub output_v: f64,
    /// The DAC command, volts at the amplifier input.
    pub command_v: f64,
    /// The DAC code sent.
    pub dac: DacCode,
    /// What the compensator's output limits did this sample.
    pub flags: Flags,
}

/// A closed loop of model-core blocks.
pub struct LoopSim {
    /// Compensator configuration.
    pub lag: LagCompensator,
    /// Compensator state.
    pub lag_state: LagState,
    /// Plant configuration.
    pub plant: LinearPlant,
    /// Plant state.
    pub plant_state: PlantState,
    /// Quantise through the ADC and DAC codes (on by default).
    pub quantise: bool,
    noise: Option<(Normal<f64>, StdRng)>,
    plant_gain: f64,
}

impl LoopSim {
    /// A loop of the given compensator and plant, at rest at output 0.
    pub fn new(lag: &LagConfig, plant: &LinearPlantConfig) -> Result<Self, ConfigError> {
        let lag_c = LagCompensator::new(lag)?;
        let plant_c = LinearPlant::new(plant)?;
        Ok(Self {
            lag: lag_c,
            lag_state: LagState::new(0.0),
            plant: plant_c,
            plant_state: PlantState::default(),
            quantise: true,
            noise: None,
            plant_gain: plant.gain,
        })
    }

    /// Add white Gaussian sensor noise of `sigma_v` volts (seeded, repeatable).
    pub fn with_noise(mut self, sigma_v: f64, seed: u64) -> Self {
        self.noise = Normal::new(0.0, sigma_v.abs())
            .ok()
            .map(|n| (n, StdRng::seed_from_u64(seed)));
        self
    }

    /// Put the loop at rest with the output at `y_v` (plant and compensator in steady state).
    pub fn settle_at(&mut self, y_v: f64) {
        let u = (y_v / self.plant_gain) as f32;
        self.plant_state = self.plant.steady_state(u);
        self.lag_state = LagState::new(u);
    }

    /// One sample with reference `r_v`.
    pub fn step(&mut self, r_v: f64) -> LoopSample {
        let output = self.plant.output(&self.plant_state) as f64;
        let noise = self.noise.as_mut().map_or(0.0, |(n, rng)| n.sample(rng));
        let measured = if self.quantise {
            AdcCode::from_volts((output + noise) as f32).volts() as f64
        } else {
            output + noise
        };
        let (u, flags) = self
            .lag
            .update_flags(&mut self.lag_state, (r_v - measured) as f32);
        let dac = DacCode::from_volts(u);
        let applied = if self.quantise { dac.volts() } else { u };
        self.plant.step(&mut self.plant_state, applied);
        LoopSample {
            measured_v: measured,
            output_v: output,
            command_v: applied as f64,
            dac,
            flags,
        }
    }
}
