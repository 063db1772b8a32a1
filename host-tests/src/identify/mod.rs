//! Identification of the non-linear stage blocks from measured-style records (issue #4
//! item 6). Design-time `f64`; each function returns the model-core configuration it fills.
//!
//! * [`drift`]: the three drift lags (eq. 5.1) from a step record.
//! * [`hysteresis`]: the Everett table from a first-order-reversal-curve record (sec. 5.3.4),
//!   and the generator of that protocol's input.
//! * [`into_model`]: either written into a model file (`piezo identify`).

pub mod drift;
pub mod hysteresis;
pub mod into_model;
