//! The control interrupt: ADC end of conversion, highest priority, once per sample.
//!
//! Per sample, in this order: read the ADC (clears EOC), finish the previous DAC frame, take
//! any new configuration and requests from the tasks, raise the firmware's own faults
//! (overrun, watchdog), run **one** model-core function, `Controller::step` (reference with
//! preview, pre-filter, lag compensator, optional hysteresis feedforward, limits: the same
//! function the QEMU runs call), write the DAC, record the sample, publish the status, and
//! time itself with the DWT cycle counter. Nothing in here waits, allocates or locks for
//! longer than the copy of a configuration that the mailbox does when one is pending.

use core::cell::Cell;
use core::sync::atomic::Ordering;

use cortex_m::peripheral::DWT;
use critical_section::Mutex;
use embassy_stm32::interrupt;
use firmware::capture::Producer;
use firmware::stats::CycleStats;
use model_core::frame::Record;
use model_core::{AdcCode, params};

use super::adc;
use super::dac::Dac;
use super::shared::*;
use firmware::settings::LoopConfig;
use model_core::controller::{ControllerState, Faults};

/// Everything the interrupt owns.
pub struct LoopContext {
    /// The active configuration (controller and reference).
    pub config: LoopConfig,
    /// The controller's state (mode, latched faults, filter states).
    pub state: ControllerState,
    /// The DAC.
    pub dac: Dac,
    /// Timing accumulator.
    pub stats: CycleStats,
    /// The right to record.
    pub capture: Producer<{ params::FW_CAPTURE_RECORDS }>,
}

// A `Cell`, not a `RefCell`: taking the context has no borrow flag and no panic path.
static HANDOVER: Mutex<Cell<Option<LoopContext>>> = Mutex::new(Cell::new(None));

/// Hands the context to the interrupt (before the timer starts).
pub fn install(ctx: LoopContext) {
    critical_section::with(|cs| {
        HANDOVER.borrow(cs).set(Some(ctx));
    });
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
    if let Some(c) = CONFIG.take() {
        ctx.config = c;
    }
    if let Some(mode) = mode_from_u8(MODE_REQUEST.swap(NO_MODE, Ordering::Relaxed)) {
        ctx.state.set_mode(mode);
    }
    if CLEAR_REQUEST.swap(false, Ordering::Relaxed) {
        ctx.state.clear_faults();
    }
    let raise = RAISE_REQUEST.swap(0, Ordering::Relaxed);
    if raise != 0 {
        ctx.state.raise(Faults(raise));
    }
    if LIVENESS.isr_tick(STALL_SAMPLES.load(Ordering::Relaxed)) {
        ctx.state.raise(Faults::WATCHDOG);
    }

    let y = ctx.config.adc_cal.apply(reading.raw);
    ctx.state.set_reference(ctx.config.reference_v);
    let s = ctx.config.controller.step(&mut ctx.state, y);
    ctx.dac.write(s.dac);

    let r = AdcCode::from_volts(s.reference_v).0;
    ctx.capture.push(Record {
        r,
        y: y.0,
        u: s.dac.value(),
        flags: s.flags.0,
        faults: s.faults.0,
    });
    STATUS
        .mode
        .store(mode_to_u8(ctx.state.mode()), Ordering::Relaxed);
    STATUS.faults.store(s.faults.0, Ordering::Relaxed);
    STATUS.y.store(y.0 as u16 as u32, Ordering::Relaxed);
    STATUS
        .u
        .store(s.dac.value() as u16 as u32, Ordering::Relaxed);
    STATUS.r.store(r as u16 as u32, Ordering::Relaxed);

    ctx.stats.set_budget(BUDGET_CYCLES.load(Ordering::Relaxed));
    let cycles = DWT::cycle_count().wrapping_sub(t0);
    let late = reading.overrun || adc::next_pending();
    if ctx.stats.record(cycles, late, &STATS) {
        // Latched by the controller: the output ramps to safe from the next sample on.
        ctx.state.raise(Faults::OVERRUN);
    }
}
