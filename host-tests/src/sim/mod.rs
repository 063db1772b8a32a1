//! Simulations on the host, all built on model-core's blocks:
//!
//! * [`loop_sim`]: the closed loop (compensator, converters, plant, sensor noise);
//! * [`analysis`]: the loop figures measured on it (margins, bandwidth, step response);
//! * [`tracking`]: how well it follows a periodic reference, with and without pre-filter;
//! * [`open_loop`]: a model's response to a recorded input;
//! * [`synth`]: measured-style records from a model and an input protocol.

pub mod analysis;
pub mod loop_sim;
pub mod open_loop;
pub mod synth;
pub mod tracking;
