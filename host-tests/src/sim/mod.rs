//! Simulations on the host, all built on model-core's blocks:
//!
//! * [`closed_loop`]: the host's way into model-core's one closed-loop harness (the board's
//!   `Controller::step` around a stage, through the converters), put at rest in an operating
//!   point;
//! * [`analysis`]: the loop figures measured on it (margins, bandwidth, step response);
//! * [`tracking`]: how well it follows a periodic reference, with and without pre-filter;
//! * [`open_loop`]: a model's response to a recorded input;
//! * [`synth`]: measured-style records from a model and an input protocol.

pub mod analysis;
pub mod closed_loop;
pub mod open_loop;
pub mod synth;
pub mod tracking;
