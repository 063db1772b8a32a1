//! The control interrupt: ADC end of conversion, highest priority, once per sample.
//!
//! **The DAC frame goes out at a fixed instant** (issue 13 item 6): first thing in the
//! handler, the code computed in the *previous* sample is sent (a one-sample computational
//! delay), so the output instant does not move with the step's length. SYNC is raised (end of
//! the previous frame, finished 20 us ago) before the ADC read and lowered after it, which
//! keeps SYNC high for longer than the DAC8311's 50 ns minimum. Latency from the sampling
//! instant (TIM2 TRGO) to the DAC update: conversion (0.8 us) + interrupt entry and the read
//! (< 0.5 us) + one sample period (20 us at 50 kHz) + the frame (1.3 us): about 22.6 us at
//! 50 kHz, constant. Its cost on the loop is measured on the host
//! (`virtual_board::dac_at_a_fixed_instant_keeps_the_margins`).
//!
//! Per sample: finish the previous DAC frame, read the ADC (clears EOC), send the code
//! computed in the previous sample, run
//! `firmware::sample::LoopCore::step` (new configuration and requests, watchdog, then
//! **one** model-core function, `Controller::step`: modes, fault latch and safe ramp, lag
//! compensator, limits, the same function the QEMU runs call; capture and status), write the
//! DAC, and time the whole with the DWT cycle counter (`LoopCore::finish`: max, mean,
//! overruns). Nothing in here waits, allocates, panics or locks; a new configuration is an
//! index swap (`firmware::mailbox::Reader::update`), used where it lies.

use core::cell::Cell;
use core::sync::atomic::Ordering;

use cortex_m::peripheral::DWT;
use critical_section::Mutex;
use embassy_stm32::interrupt;
use firmware::design_parameters;
use firmware::sample::LoopCore;

use super::adc;
use super::dac::Dac;
use super::shared::{LINKS, STATUS};

/// Everything the interrupt owns.
pub struct LoopContext {
    /// Configuration, controller state, timing, capture.
    pub core: LoopCore<{ design_parameters::CAPTURE_RECORDS }>,
    /// The DAC.
    pub dac: Dac,
    /// The code computed in the previous sample, sent at the start of this one.
    pub next: model_core::DacCode,
}

// A `Cell`, not a `RefCell`: taking the context has no borrow flag and no panic path.
static HANDOVER: Mutex<Cell<Option<LoopContext>>> = Mutex::new(Cell::new(None));

/// Hands the context to the interrupt (before the timer starts).
pub fn install(ctx: LoopContext) {
    critical_section::with(|cs| HANDOVER.borrow(cs).set(Some(ctx)));
}

// In ITCM (zero wait states, no cache misses): `memory.x`, copied by `super::load_itcm`.
// What it calls and does not inline (the hysteresis inverse) stays in flash behind the
// instruction cache.
#[interrupt]
#[unsafe(link_section = ".itcm.adc")]
fn ADC() {
    static mut CTX: Option<LoopContext> = None;
    let t0 = DWT::cycle_count();
    let Some(ctx) = CTX.as_mut() else {
        let _ = adc::read(); // clears EOC
        *CTX = critical_section::with(|cs| HANDOVER.borrow(cs).take());
        return; // Not installed yet: the DAC still holds the safe value written at boot.
    };
    if !ctx.dac.begin() {
        STATUS.dac_late.fetch_add(1, Ordering::Relaxed);
    }
    let reading = adc::read();
    // The fixed instant: the previous sample's code.
    ctx.dac.write(ctx.next);
    // Timer ticks since the sampling instant (TIM2 counts up from its update, the TRGO).
    STATUS.record_write_ticks(embassy_stm32::pac::TIM2.cnt().read());
    let s = ctx.core.step(&LINKS, reading.raw);
    ctx.next = s.dac;
    let cycles = DWT::cycle_count().wrapping_sub(t0);
    let late = reading.overrun || adc::next_pending();
    ctx.core.finish(&LINKS, cycles, late);
}
