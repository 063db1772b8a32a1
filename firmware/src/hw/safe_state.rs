//! The safe state by design (issue 13 item 3): our own panic and HardFault handlers.
//!
//! panic-probe spun with the DAC at its last code and the output switch closed until the IWDG
//! bit (up to 100 ms), then the reset opened the switch: a step of up to 10 V into the stage.
//! Here, on a panic or a HardFault, with interrupts masked:
//! 1. the output switch opens first (PD15 low: the amplifier input goes to 0 V through its
//!    10 kOhm pull-down, whatever the DAC holds);
//! 2. the safe code is written to the DAC (one SPI frame, a bounded wait for it to finish),
//!    so the output stage is at 0 V before the switch closes again after the reboot;
//! 3. the reason goes into a [`ResetRecord`] in `.uninit` RAM (not zeroed at start-up), with
//!    its magic and check words;
//! 4. the chip resets. At boot [`take_last_reset`] reads and clears the record; `status`
//!    prints it (`last_reset=panic detail=<line>`), and the controller boots with WATCHDOG
//!    latched so the loop stays in safe until `clear`.
//!
//! Steps 1-3 are `firmware::reset_reason::enter_safe_state` (register-free, run by the
//! virtual board's panic test) over this file's `Registers`; step 4 is here.
//!
//! No logging here: nothing in the path can wait for a host.

use core::mem::MaybeUninit;
use core::panic::PanicInfo;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m_rt::{ExceptionFrame, exception};
use embassy_stm32::pac;
use firmware::reset_reason::{self, ResetReason, ResetRecord, SafeStateOutputs};
use model_core::DacCode;

/// The record that survives the reset (cortex-m-rt's `.uninit` section: NOLOAD, not zeroed).
#[unsafe(link_section = ".uninit.RESET_RECORD")]
static mut RECORD: MaybeUninit<ResetRecord> = MaybeUninit::uninit();

/// The last reset's reason code ([`ResetReason::code`]), published for `status`.
pub static LAST_RESET_REASON: AtomicU32 = AtomicU32::new(0);
/// The last reset's detail word (PC or source line), published for `status`.
pub static LAST_RESET_DETAIL: AtomicU32 = AtomicU32::new(0);

/// Reads and clears the record; publishes and returns the last reset's reason and detail.
/// Called once at boot, before the interrupts run.
pub fn take_last_reset(iwdg_flag: bool) -> (ResetReason, u32) {
    let p = (&raw mut RECORD).cast::<ResetRecord>();
    // SAFETY: `RECORD` is four aligned words of RAM that only this function (at boot, before
    // any interrupt is enabled) and the fault handlers (which never return) touch; any bit
    // pattern is a valid `ResetRecord` of `u32`s, and the volatile accesses keep the compiler
    // from assuming anything about memory the start-up code did not initialise.
    let mut rec = unsafe { p.read_volatile() };
    let (reason, detail) = reset_reason::take_last_reset(&mut rec, iwdg_flag);
    // SAFETY: as above; the cleared record makes the next power-on read "no record".
    unsafe { p.write_volatile(rec) };
    LAST_RESET_REASON.store(reason.code(), Ordering::Relaxed);
    LAST_RESET_DETAIL.store(detail, Ordering::Relaxed);
    (reason, detail)
}

/// The registers behind `firmware::reset_reason::enter_safe_state`.
struct Registers;

impl SafeStateOutputs for Registers {
    fn mask_interrupts(&mut self) {
        cortex_m::interrupt::disable();
    }

    fn open_output_switch(&mut self) {
        pac::GPIOD.bsrr().write(|w| w.set_br(15, true));
    }

    fn send_dac(&mut self, code: DacCode) {
        #[cfg(not(feature = "internal-dac"))]
        {
            let spi = pac::SPI1;
            pac::GPIOD.bsrr().write(|w| w.set_bs(14, true)); // SYNC high: end any frame
            pac::GPIOD.bsrr().write(|w| w.set_br(14, true)); // SYNC low: a new frame
            spi.txdr16().write_value(code.spi_frame());
            spi.cr1().modify(|w| w.set_cstart(true));
            // 16 bits at 12.5 MHz = 1.3 us; bounded in case SPI1 was never configured.
            let mut spins = 0u32;
            while !spi.sr().read().txc() && spins < 10_000 {
                spins += 1;
            }
            pac::GPIOD.bsrr().write(|w| w.set_bs(14, true)); // SYNC high: latch
        }
        #[cfg(feature = "internal-dac")]
        pac::DAC1
            .dhr12r(0)
            .write(|w| w.set_dhr(firmware::scaling::internal_dac_value(code)));
    }

    fn keep_record(&mut self, record: ResetRecord) {
        let p = (&raw mut RECORD).cast::<ResetRecord>();
        // SAFETY: interrupts are masked (the sequence's first step) and the handler never
        // returns, so nothing else touches the record; the pointer is to four aligned words
        // of RAM.
        unsafe { p.write_volatile(record) };
        cortex_m::asm::dsb();
    }
}

/// Steps 1-3 of the module note (`firmware::reset_reason::enter_safe_state`, host-tested on
/// the virtual board), then step 4, the reset. Never returns.
fn enter_safe_state(reason: ResetReason, detail: u32) -> ! {
    reset_reason::enter_safe_state(&mut Registers, reason, detail);
    cortex_m::peripheral::SCB::sys_reset()
}

#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    let line = info.location().map_or(0, |l| l.line());
    enter_safe_state(ResetReason::Panic, line)
}

#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    enter_safe_state(ResetReason::HardFault, ef.pc())
}
