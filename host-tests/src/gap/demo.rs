//! The virtual stage of `piezo demo`: the model-gap workflow without a board. The stage has
//! three effects the base model `thesis-linear` lacks (drift and hysteresis, the thesis' two
//! big ones, and a sensor offset, a real lab's first; 1 mV sensor noise); the demo records the
//! [`super::protocol`] records from it and runs the workflow from `thesis-linear`. Its play
//! operators' radii are none of the fit's grid radii ([`super::catalogue::PLAY_GRID_V`]), so
//! the hysteresis is not a form fitted to itself; its drift is the thesis' eq. 5.1, which is the
//! catalogue's three-lag form (the hidden-effect tests use a logarithmic creep instead).

use crate::io::model_file::{DriftSection, ModelFile, OffsetSection, PlaySection};
use model_core::params;

/// Weights of the demo stage's play-sum hysteresis on [`DEMO_PLAY_RADII_V`] (our
/// assumption: a loop of about 0.28 V, 3.5 % of the sensor span, on a full 0-10 V cycle).
pub const DEMO_PLAY_WEIGHTS: [f64; params::PLAY_OPERATORS] =
    [0.01, 0.01, 0.02, 0.02, 0.02, 0.02, 0.015, 0.01];
/// Radii of the demo stage's play operators, volts (our assumption: between the fit's grid
/// radii, none equal to one of them or to [`params::PLAY_RADII_V`]).
pub const DEMO_PLAY_RADII_V: [f64; params::PLAY_OPERATORS] =
    [0.07, 0.15, 0.29, 0.56, 1.1, 1.6, 2.2, 4.4];
/// The demo stage's sensor offset, volts (our assumption: a 12 mV zero error).
pub const DEMO_OFFSET_V: f64 = 0.012;

/// The demo's virtual stage: `thesis-linear` plus the thesis' drift (eq. 5.1), a play-sum
/// hysteresis on radii of its own and a 12 mV sensor offset, 1 mV noise.
pub fn demo_truth(seed: u64) -> ModelFile {
    let mut m = ModelFile::built_in("thesis-linear").unwrap_or_else(|| unreachable!());
    m.name = "demo truth".into();
    m.converters.noise_v = 1e-3;
    m.converters.seed = seed;
    m.drift = Some(DriftSection {
        gains: params::DRIFT_GAINS,
        taus_s: params::DRIFT_TAUS_S,
        poly: [1.0, 0.0, 0.0, 0.0],
        poly_range_v: [0.0, 10.0],
    });
    m.hysteresis_play = Some(PlaySection {
        radii_v: DEMO_PLAY_RADII_V,
        weights: DEMO_PLAY_WEIGHTS,
    });
    m.offset = Some(OffsetSection {
        offset_v: DEMO_OFFSET_V,
    });
    m
}
