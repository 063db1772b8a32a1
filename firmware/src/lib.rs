//! The firmware's logic that touches no register, unit-tested on the host
//! (`cargo test -p firmware --lib`): the command language, the capture buffer protocol,
//! the configuration hand-over to the interrupt, the interrupt's timing statistics, the
//! watchdog liveness rule, the reset-reason record and the converter/timer arithmetic. The board code (`src/hw/`,
//! built for thumbv7em-none-eabihf only) calls these.
#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]

pub mod app;
pub mod capture;
pub mod command;
pub mod design_parameters;
pub mod learn;
pub mod liveness;
pub mod mailbox;
pub mod reset_reason;
pub mod sample;
pub mod scaling;
pub mod settings;
pub mod stats;
