//! The E-509 sensor monitor and the converters, as the stage model sees them (sec. 2.3.1, 2.4).
//!
//! ```text
//! position (V) ─► x gain ─► + offset ─► + noise ─► 16-bit ADC (+-10 V) ─► y (V)
//! ```
//! * **Gain**: monitor volts per volt of position (1 by default: the plant's 0.79 already maps
//!   the amplifier input to monitor volts). A scale error of a real monitor is a gain other
//!   than 1 (the model-gap workflow's effect `sensor-gain`).
//! * **Offset**: a constant added to the monitor reading, volts (0 by default,
//!   [`params::SENSOR_OFFSET_V`]): the monitor's or the ADC's zero error (effect `offset`).
//! * **Noise**: the thesis quotes about +-2.5 mV ([`params::SENSOR_NOISE_V`]); we draw it from
//!   a seeded generator so that every record is reproducible. The generator is SplitMix64 (one
//!   64-bit add, three xor-shifts and two multiplies; passes BigCrush), small enough for
//!   `no_std` and for the target. The 64 bits are cut into four 16-bit uniforms whose sum,
//!   scaled to unit variance, is an Irwin-Hall approximation of a Gaussian: exact mean and
//!   variance, bounded at +-3.46 sigma (a real sensor's noise has no infinite tails either), one
//!   generator call per sample and no `ln`/`cos` (which `core` lacks for `f32`).
//! * **ADC**: 16-bit over +-10 V via [`AdcCode`] (rounding to the nearest code and saturating
//!   at the rails), switchable so that the model-gap workflow can compare with clean models.
//!
//! The DAC's 14-bit quantisation of the command is applied by [`crate::stage`] at its input
//! through [`crate::codes::DacCode`].

use crate::codes::AdcCode;
use crate::limits::{ConfigError, check_within};
use crate::params;

/// Sensor parameters (design time).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorConfig {
    /// Monitor volts per volt of position.
    pub gain: f64,
    /// Constant added to the monitor reading, volts (within +-10 V).
    pub offset_v: f64,
    /// Noise standard deviation, volts (0 for none).
    pub noise_v: f64,
    /// Quantise to the 16-bit ADC.
    pub adc: bool,
    /// Seed of the noise generator.
    pub seed: u64,
}

impl Default for SensorConfig {
    /// Gain 1, no offset, the thesis' 2.5 mV noise, ADC on.
    fn default() -> Self {
        Self {
            gain: params::SENSOR_GAIN,
            offset_v: params::SENSOR_OFFSET_V,
            noise_v: params::SENSOR_NOISE_V,
            adc: true,
            seed: params::SENSOR_NOISE_SEED,
        }
    }
}

/// SplitMix64: a 64-bit state, a full-period counter scrambled on output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// A generator from `seed` (any value, 0 included).
    pub const fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// An approximately normal sample with mean 0 and variance 1 (sum of four uniforms),
    /// bounded by +-2 sqrt(3).
    #[inline]
    pub fn standard_normal(&mut self) -> f32 {
        let r = self.next_u64();
        let u =
            |k: u32| ((r >> (16 * k)) & 0xFFFF) as f32 * (1.0 / 65536.0) - (0.5 - 0.5 / 65536.0);
        // Each uniform has variance 1/12 (to 1e-10): the sum of four has 1/3.
        (u(0) + u(1) + u(2) + u(3)) * 1.732_050_8
    }
}

/// The sensor: configuration half.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sensor {
    gain: f32,
    offset_v: f32,
    noise_v: f32,
    adc: bool,
    seed: u64,
}

/// The sensor's history: the noise generator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SensorState {
    rng: SplitMix64,
}

impl Sensor {
    /// Checks `cfg`: gain within 0.1..10, offset within +-10 V, noise within 0..1 V.
    ///
    /// ```
    /// use model_core::sensor::{Sensor, SensorConfig};
    /// let s = Sensor::new(&SensorConfig { noise_v: 0.0, ..SensorConfig::default() }).unwrap();
    /// let mut st = s.initial_state();
    /// let y = s.measure(&mut st, 1.0);
    /// assert!((y - 1.0).abs() <= 0.5 * model_core::AdcCode::VOLT_PER_LSB);
    /// ```
    pub fn new(cfg: &SensorConfig) -> Result<Self, ConfigError> {
        check_within("gain", cfg.gain, 0.1, 10.0)?;
        check_within("offset_v", cfg.offset_v, -10.0, 10.0)?;
        check_within("noise_v", cfg.noise_v, 0.0, 1.0)?;
        Ok(Self {
            gain: cfg.gain as f32,
            offset_v: cfg.offset_v as f32,
            noise_v: cfg.noise_v as f32,
            adc: cfg.adc,
            seed: cfg.seed,
        })
    }

    /// The state the seed defines.
    pub fn initial_state(&self) -> SensorState {
        SensorState {
            rng: SplitMix64::new(self.seed),
        }
    }

    /// The monitor reading for `position_v` without noise: the reading of a stage at rest,
    /// before its first sample ([`crate::stage::Stage::steady_state`]). Through the ADC's
    /// codes where the sensor has one, as [`Self::measure`] reads.
    #[inline]
    pub fn reading_at_rest(&self, position_v: f32) -> f32 {
        self.converted(self.gain * position_v + self.offset_v)
    }

    /// The monitor reading for `position_v`. Draws one noise sample only when noise is on.
    #[inline]
    pub fn measure(&self, s: &mut SensorState, position_v: f32) -> f32 {
        let mut y = self.gain * position_v + self.offset_v;
        if self.noise_v > 0.0 {
            y += self.noise_v * s.rng.standard_normal();
        }
        self.converted(y)
    }

    /// Whether [`Self::measure`] adds noise (and so advances its state): without noise it is a
    /// pure function of the position.
    #[inline]
    pub fn is_noisy(&self) -> bool {
        self.noise_v > 0.0
    }

    /// `y_v` as the monitor gives it: through the ADC's codes where the sensor has one.
    #[inline]
    fn converted(&self, y_v: f32) -> f32 {
        if self.adc {
            AdcCode::from_volts(y_v).volts()
        } else {
            y_v
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_has_unit_variance_and_zero_mean() {
        let mut r = SplitMix64::new(7);
        let n = 200_000;
        let (mut s1, mut s2) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let x = r.standard_normal() as f64;
            assert!(x.abs() <= 3.465);
            s1 += x;
            s2 += x * x;
        }
        let mean = s1 / n as f64;
        let var = s2 / n as f64 - mean * mean;
        assert!(
            mean.abs() < 0.01 && (var - 1.0).abs() < 0.01,
            "mean {mean} var {var}"
        );
    }
}
