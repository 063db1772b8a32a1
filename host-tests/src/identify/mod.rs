//! Identification of the stage's non-linear blocks from measured-style records.
//!
//! * [`drift`]: the three drift lags (eq. 5.1) from a step record.

pub mod drift;
