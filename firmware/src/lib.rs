//! The firmware's logic that touches no register, unit-tested on the host
//! (`cargo test -p firmware --lib`): the command language, the capture buffer protocol,
//! the configuration hand-over to the interrupt, the interrupt's timing statistics, the
//! watchdog liveness rule, the reset-reason record, the converter/timer arithmetic and the
//! tasks' bodies, generic over the serial, pin and delay traits (`tasks`). The board code
//! (`src/hw/`, built for thumbv7em-none-eabihf only) binds them to the peripherals.
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
pub mod tasks;
