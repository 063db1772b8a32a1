//! `f64` reference of the E-505 limits (sec. 2.3): input window, gain, output window, slew
//! limit at the output, from the data sheet numbers.

use model_core::params;

/// The amplifier with its output state.
#[derive(Clone, Debug)]
pub struct AmplifierRef {
    /// Output, volts.
    pub out_v: f64,
    /// Largest output change per step (infinite: no limiter).
    pub max_step_v: f64,
    /// Apply the ranges.
    pub saturation: bool,
}

impl AmplifierRef {
    /// The lab's setting at `period_s`: ranges on, 1500 V/ms.
    pub fn thesis(period_s: f64) -> Self {
        Self {
            out_v: 0.0,
            max_step_v: params::AMP_SLEW_OUTPUT_V_PER_S * period_s,
            saturation: true,
        }
    }

    /// The settled output for a held input.
    pub fn target(&self, u_v: f64) -> f64 {
        if self.saturation {
            let u = u_v.clamp(params::AMP_INPUT_MIN_V, params::AMP_INPUT_MAX_V);
            (params::AMP_GAIN * u).clamp(params::AMP_OUTPUT_MIN_V, params::AMP_OUTPUT_MAX_V)
        } else {
            params::AMP_GAIN * u_v
        }
    }

    /// One step.
    pub fn step(&mut self, u_v: f64) -> f64 {
        let want = self.target(u_v);
        let d = want - self.out_v;
        self.out_v += if d > self.max_step_v {
            self.max_step_v
        } else if d < -self.max_step_v {
            -self.max_step_v
        } else {
            d
        };
        self.out_v
    }
}
