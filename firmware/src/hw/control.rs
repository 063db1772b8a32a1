//! The control interrupt: ADC end of conversion, highest priority, once per sample.
//!
//! Per sample: read the ADC (clears EOC), finish the previous DAC frame, run
//! `firmware::sample::LoopCore::step` (new configuration and requests, watchdog, then
//! **one** model-core function, `Controller::step`: modes, fault latch and safe ramp, lag
//! compensator, limits, the same function the QEMU runs call; capture and status), write the
//! DAC, and time the whole with the DWT cycle counter (`LoopCore::finish`: max, mean,
//! overruns). Nothing in here waits, allocates, panics or locks for longer than the copy of a
//! configuration when one is pending.

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
}

// A `Cell`, not a `RefCell`: taking the context has no borrow flag and no panic path.
static HANDOVER: Mutex<Cell<Option<LoopContext>>> = Mutex::new(Cell::new(None));

/// Hands the context to the interrupt (before the timer starts).
pub fn install(ctx: LoopContext) {
    critical_section::with(|cs| HANDOVER.borrow(cs).set(Some(ctx)));
}

#[interrupt]
fn ADC() {
    static mut CTX: Option<LoopContext> = None;
    let t0 = DWT::cycle_count();
    let reading = adc::read();
    if CTX.is_none() {
        *CTX = critical_section::with(|cs| HANDOVER.borrow(cs).take());
    }
    let Some(ctx) = CTX.as_mut() else {
        return; // Not installed yet: the DAC still holds the safe value written at boot.
    };
    if !ctx.dac.begin() {
        STATUS.dac_late.fetch_add(1, Ordering::Relaxed);
    }
    let s = ctx.core.step(&LINKS, reading.raw);
    ctx.dac.write(s.dac);
    let cycles = DWT::cycle_count().wrapping_sub(t0);
    let late = reading.overrun || adc::next_pending();
    ctx.core.finish(&LINKS, cycles, late);
}
