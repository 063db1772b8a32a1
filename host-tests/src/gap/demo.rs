//! The virtual stage of `piezo demo`: the model-gap workflow without a board. The stage has
//! two effects the base model `thesis-linear` lacks (drift and hysteresis, the thesis' two big
//! ones, with 1 mV sensor noise); the demo records the [`super::protocol`] records from it and
//! runs the workflow from `thesis-linear`.

use crate::io::model_file::{DriftSection, ModelFile, PlaySection};
use model_core::params;

/// Weights of the demo stage's play-sum hysteresis on [`params::PLAY_RADII_V`] (our
/// assumption: a loop of about 0.28 V, 3.5 % of the sensor span, on a full 0-10 V cycle).
pub const DEMO_PLAY_WEIGHTS: [f64; params::PLAY_OPERATORS] =
    [0.01, 0.01, 0.02, 0.02, 0.02, 0.02, 0.015, 0.01];

/// The demo's virtual stage: `thesis-linear` plus the thesis' drift (eq. 5.1) and a play-sum
/// hysteresis of about 15 % of the span, 1 mV noise.
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
        radii_v: params::PLAY_RADII_V,
        weights: DEMO_PLAY_WEIGHTS,
    });
    m
}
