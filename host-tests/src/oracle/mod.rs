//! Independent `f64` reference models. None of them calls model-core's maths: they are
//! written from the continuous equations again, in another form, so that an error in one is
//! not repeated in the other. (Called `oracle` so the name does not clash with
//! `model_core::reference`, the set-point generators.)

pub mod amplifier;
pub mod drift;
pub mod gain;
pub mod hysteresis_truth;
pub mod lag;
pub mod prefilter;
pub mod stage;
