//! A fitted hysteresis form for the model-gap workflow (issue #7): a Prandtl-Ishlinskii sum of
//! a few play operators added to the fast static map (sec. 5.3; the operator model of the
//! thesis' future-work list).
//!
//! ```text
//!   z_i[n] = min(max(z_i[n-1], u - r_i), u + r_i)        play operator with threshold r_i
//!   h(u)   = sum_i w_i (z_i - u)                          sensor volts, added to 0.79 u
//! ```
//! Each term `z_i - u` lies in `[-r_i, r_i]`: it is `-r_i` on a rising branch and `+r_i` on a
//! falling one once the input has moved `2 r_i` past its last reversal, so with `w_i >= 0` the
//! loop runs counter-clockwise with the output lagging the input, as the stage's does (sec.
//! 3.2). The map is rate independent and has the wiping-out property (play operators do).
//!
//! **Why this form and not the Everett table** ([`crate::hysteresis`]): the model-gap loop fits
//! the hysteresis from arbitrary records in one linear least-squares solve (the output is
//! linear in the weights), with one weight per operator whose meaning is plain (eight,
//! [`PLAY_OPERATORS`], over the fixed radii [`crate::params::PLAY_RADII_V`]), and the state is
//! eight `f32` (so [`crate::stage::StageState`] stays `Copy`). The table is the model for
//! identification from reversal curves and for inversion; a fitted play sum converts to it
//! exactly (its Everett function is `sum_i w_i max(a - b - 2 r_i, 0)`), which the lead may
//! choose to do when the stage takes a table.
//!
//! Cost: one clamp and one multiply-add per operator (eight) per step; no allocation, no panics.

use crate::limits::{ConfigError, check_within};
use crate::params::PLAY_OPERATORS;

/// Parameters of the play-operator hysteresis (design time, `f64`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlayConfig {
    /// Thresholds `r_i`, volts (0..10, finite).
    pub radii_v: [f64; PLAY_OPERATORS],
    /// Weights `w_i`, sensor volts per volt (each within -100..100, and `|w_i r_i|`, the
    /// operator's half-height on a large loop, within 5 V).
    pub weights: [f64; PLAY_OPERATORS],
}

impl PlayConfig {
    /// Finite, thresholds within 0..10 V, weights within -100..100, each operator's
    /// half-height `|w_i r_i|` within 5 V (our assumptions: half the sensor's 10 V span bounds
    /// any loop; a narrow operator may carry a large weight, as the corner of a loop that
    /// turns sharply at a reversal needs, but not so large that the `f32` rounding of the
    /// input, about 0.5 uV at 10 V, times the weight reaches the ADC's 0.3 mV step).
    pub fn validate(&self) -> Result<(), ConfigError> {
        for r in self.radii_v {
            check_within("radii_v", r, 0.0, 10.0)?;
        }
        for (w, r) in self.weights.iter().zip(&self.radii_v) {
            check_within("weights", *w, -100.0, 100.0)?;
            check_within("weights times radii_v", w * r, -5.0, 5.0)?;
        }
        Ok(())
    }
}

/// The play-operator hysteresis, run-time form (`f32`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Play {
    radii_v: [f32; PLAY_OPERATORS],
    weights: [f32; PLAY_OPERATORS],
}

/// The operators' positions.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlayState {
    z_v: [f32; PLAY_OPERATORS],
}

impl Play {
    /// Checks `cfg` and converts it.
    ///
    /// ```
    /// use model_core::{params::PLAY_OPERATORS, play::{Play, PlayConfig}};
    /// let mut weights = [0.0; PLAY_OPERATORS];
    /// weights[0] = 0.1;
    /// let mut radii_v = [3.0; PLAY_OPERATORS];
    /// radii_v[0] = 0.5;
    /// let p = Play::new(&PlayConfig { radii_v, weights }).unwrap();
    /// let mut s = p.steady_state(0.0);
    /// assert!((p.step(&mut s, 5.0) + 0.05).abs() < 1e-6); // rising: -w r
    /// assert!((p.step(&mut s, 2.0) - 0.05).abs() < 1e-6); // falling: +w r
    /// ```
    pub fn new(cfg: &PlayConfig) -> Result<Self, ConfigError> {
        cfg.validate()?;
        Ok(Self {
            radii_v: cfg.radii_v.map(|v| v as f32),
            weights: cfg.weights.map(|v| v as f32),
        })
    }

    /// At rest with `u_v` held for ever (every operator at the input: no hysteretic offset).
    pub fn steady_state(&self, u_v: f32) -> PlayState {
        PlayState {
            z_v: [u_v; PLAY_OPERATORS],
        }
    }

    /// Advance with input `u_v` and return `h(u)`, sensor volts. A non-finite input leaves the
    /// state unchanged and returns 0.
    #[inline]
    pub fn step(&self, s: &mut PlayState, u_v: f32) -> f32 {
        if !u_v.is_finite() {
            return 0.0;
        }
        let mut h = 0.0;
        for ((z, r), w) in s.z_v.iter_mut().zip(&self.radii_v).zip(&self.weights) {
            *z = z.max(u_v - r).min(u_v + r);
            h += w * (*z - u_v);
        }
        h
    }
}
