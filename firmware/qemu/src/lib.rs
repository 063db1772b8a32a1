//! Support for the QEMU images: defmt over semihosting, exit codes, the SysTick instruction
//! counter.
//!
//! # Exit codes
//! Every image ends through [`exit`] (semihosting `SYS_EXIT_EXTENDED`, which QEMU turns into
//! its own exit status): 0 pass, 1 a check failed, 101 a panic (defmt-test's failed
//! assertions end here), 102 a HardFault. A hang is killed by the host's timeout.
//!
//! # Counting instructions ([`InstructionCounter`])
//! QEMU does not model the DWT cycle counter. Run with `-icount shift=0`, every instruction
//! advances virtual time by 1 ns, and the mps2 machines clock SysTick (processor clock
//! source) at 25 MHz: one tick is 40 instructions, and the count is repeatable to the
//! instruction. SysTick is a 24-bit down-counter: [`InstructionCounter::elapsed`] takes the
//! difference modulo 2^24, right for spans under 2^24 ticks (671 million instructions).
//!
//! # Stack ([`StackProbe`])
//! The free RAM below the stack pointer is painted with a pattern before the code under test
//! runs; the deepest overwritten word afterwards is the stack it needed.
//!
//! On the host this crate is empty: the images exist for `thumbv7em-none-eabihf` only.
#![no_std]

#[cfg(target_os = "none")]
mod target {
    use cortex_m::peripheral::SYST;
    use cortex_m::peripheral::syst::SystClkSource;
    use cortex_m_rt::{ExceptionFrame, exception};
    use defmt_semihosting as _;

    /// Exit status: every check passed.
    pub const EXIT_PASS: i32 = 0;
    /// Exit status: a check failed.
    pub const EXIT_FAIL: i32 = 1;
    /// Exit status: a panic.
    pub const EXIT_PANIC: i32 = 101;
    /// Exit status: a HardFault.
    pub const EXIT_HARDFAULT: i32 = 102;

    /// End the program; QEMU exits with `code`.
    pub fn exit(code: i32) -> ! {
        semihosting::process::exit(code)
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        defmt::println!("PANIC {}", defmt::Display2Format(info));
        exit(EXIT_PANIC)
    }

    #[exception]
    unsafe fn HardFault(_frame: &ExceptionFrame) -> ! {
        defmt::println!("HARDFAULT");
        exit(EXIT_HARDFAULT)
    }

    /// Instructions per SysTick tick under `qemu-system-arm -icount shift=0` on the mps2
    /// machines (1 ns per instruction, SysTick at 25 MHz).
    pub const INSTRUCTIONS_PER_TICK: u32 = 40;

    /// SysTick free-running over its full 24-bit range on the processor clock.
    pub struct InstructionCounter {
        syst: SYST,
    }

    impl InstructionCounter {
        /// Take SysTick and start it.
        pub fn new(mut syst: SYST) -> Self {
            syst.disable_interrupt();
            syst.set_clock_source(SystClkSource::Core);
            syst.set_reload(0x00FF_FFFF);
            syst.clear_current();
            syst.enable_counter();
            Self { syst }
        }

        /// The counter now (counts down).
        #[inline(always)]
        pub fn now(&self) -> u32 {
            SYST::get_current()
        }

        /// Ticks from `start` (an earlier [`Self::now`]) to `end`, modulo 2^24.
        #[inline(always)]
        pub fn elapsed(start: u32, end: u32) -> u32 {
            start.wrapping_sub(end) & 0x00FF_FFFF
        }

        /// Give SysTick back.
        pub fn free(self) -> SYST {
            self.syst
        }
    }

    /// Fill value of the stack probe.
    const STACK_PAINT: u32 = 0x5AC3_5AC3;
    /// Bytes below the stack pointer left unpainted: none (nothing lives below the stack
    /// pointer on Cortex-M; no red zone).
    const STACK_GUARD: usize = 0;

    unsafe extern "C" {
        /// Start of the free RAM after `.bss` (cortex-m-rt): the stack grows down towards it.
        static mut __sheap: u32;
    }

    /// Stack high-water mark: [`StackProbe::paint`] fills the free RAM below the present
    /// stack pointer with a pattern; [`StackProbe::used_bytes`] finds the deepest word
    /// overwritten since, i.e. how much stack the code run in between needed below the
    /// painting frame.
    pub struct StackProbe {
        sp: usize,
        low: usize,
    }

    impl StackProbe {
        /// Paint the free stack below the caller's stack pointer (inlined, so the pointer is
        /// the caller's own).
        #[inline(always)]
        pub fn paint() -> Self {
            let sp = cortex_m::register::msp::read() as usize;
            let low = core::ptr::addr_of!(__sheap) as usize;
            let top = sp.saturating_sub(STACK_GUARD) & !3;
            let mut a = (low + 3) & !3;
            while a < top {
                // SAFETY: between the end of .bss and below the live stack: memory nobody
                // uses, word aligned.
                unsafe { core::ptr::write_volatile(a as *mut u32, STACK_PAINT) };
                a += 4;
            }
            Self {
                sp,
                low: (low + 3) & !3,
            }
        }

        /// Bytes of stack used below the painting frame since [`Self::paint`].
        #[inline(never)]
        pub fn used_bytes(&self) -> u32 {
            let top = self.sp.saturating_sub(STACK_GUARD) & !3;
            let mut a = self.low;
            // SAFETY: reads of the painted, word-aligned range.
            while a < top && unsafe { core::ptr::read_volatile(a as *const u32) } == STACK_PAINT {
                a += 4;
            }
            (self.sp - a) as u32
        }
    }

    /// The CPUID part number: 0xC24 on a Cortex-M4, 0xC27 on a Cortex-M7.
    pub fn cpu_part() -> u32 {
        let cpuid = cortex_m::peripheral::CPUID::PTR;
        // SAFETY: CPUID's base register is read-only and always readable.
        let base = unsafe { (*cpuid).base.read() };
        (base >> 4) & 0xFFF
    }
}

#[cfg(target_os = "none")]
pub use target::*;
