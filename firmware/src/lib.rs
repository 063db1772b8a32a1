//! Firmware logic that does not touch registers: testable on the host.
#![no_std]
