//! Why the board last reset, kept across the reset (issue 13 item 3), without the registers.
//!
//! The panic and HardFault handlers (`src/hw/safe_state.rs`) first make the output safe (open
//! the output switch, write the safe DAC code), then store a [`ResetRecord`] in a RAM section
//! that the start-up code neither zeroes nor initialises (cortex-m-rt's `.uninit`), then
//! reset. At the next boot `hw/` reads the record back with [`ResetRecord::decode`] (a magic
//! word and a check word tell a record from power-on garbage), clears it, and `status`
//! reports it as `last_reset=<name>` with the detail word (the faulting PC for a HardFault,
//! the panic's source line for a panic). A reset that left no record is told apart by the
//! RCC flags: the IWDG's, or power-on / pin.
//!
//! The record is four `u32`s so the handler can store it with plain volatile word writes.
//!
//! The handlers' sequence itself is here too, register-free: [`enter_safe_state`] over a
//! [`SafeStateOutputs`] (registers on the board; the virtual board's switch, DAC and
//! `.uninit` RAM on the host, `tests/virtual_board.rs`), and the boot's read-and-clear
//! [`take_last_reset`]. The board's handler adds only the reset itself.

use model_core::{DacCode, params};

/// What the safe-state sequence drives: the board's registers, or a model of them.
pub trait SafeStateOutputs {
    /// Masks every interrupt: nothing else runs from here on.
    fn mask_interrupts(&mut self);
    /// Opens the output-enable switch (PD15 low): the amplifier input goes to 0 V through
    /// its pull-down, whatever the DAC holds.
    fn open_output_switch(&mut self);
    /// Sends `code` to the DAC, waiting a bounded time for the frame to finish.
    fn send_dac(&mut self, code: DacCode);
    /// Stores `record` in the RAM that survives the reset (`.uninit`).
    fn keep_record(&mut self, record: ResetRecord);
}

/// The safe-state sequence of the panic and HardFault handlers, in this order: interrupts
/// masked, output switch open, the safe code (`params::SAFE_OUTPUT_V`) to the DAC, the
/// reason kept. The caller then resets the chip.
pub fn enter_safe_state(out: &mut impl SafeStateOutputs, reason: ResetReason, detail: u32) {
    out.mask_interrupts();
    out.open_output_switch();
    out.send_dac(DacCode::from_volts(params::SAFE_OUTPUT_V as f32));
    out.keep_record(ResetRecord::encode(reason, detail));
}

/// At boot: what the last reset was (the record if valid, else the IWDG flag, else power-on),
/// and the record cleared, so the next power-on does not read it again.
pub fn take_last_reset(record: &mut ResetRecord, iwdg_flag: bool) -> (ResetReason, u32) {
    let last = record.last_reset(iwdg_flag);
    *record = ResetRecord::default();
    last
}

/// Marks a record written by this firmware ("PZRR").
pub const MAGIC: u32 = 0x505A_5252;

/// Why the last reset happened.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResetReason {
    /// Power-on, the reset pin or a debugger: no record, no watchdog flag.
    PowerOn,
    /// The independent watchdog (RCC flag).
    Watchdog,
    /// A Rust panic; detail: the source line.
    Panic,
    /// A HardFault; detail: the faulting PC.
    HardFault,
}

impl ResetReason {
    /// The name `status` prints.
    pub const fn name(self) -> &'static str {
        match self {
            Self::PowerOn => "power_on",
            Self::Watchdog => "watchdog",
            Self::Panic => "panic",
            Self::HardFault => "hard_fault",
        }
    }

    /// The reason as a number (what the record stores).
    pub const fn code(self) -> u32 {
        match self {
            Self::PowerOn => 0,
            Self::Watchdog => 1,
            Self::Panic => 2,
            Self::HardFault => 3,
        }
    }

    /// The reason of a number, if it names one.
    pub const fn from_code(c: u32) -> Option<Self> {
        match c {
            0 => Some(Self::PowerOn),
            1 => Some(Self::Watchdog),
            2 => Some(Self::Panic),
            3 => Some(Self::HardFault),
            _ => None,
        }
    }
}

/// The words kept in reset-surviving RAM.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[repr(C)]
pub struct ResetRecord {
    /// [`MAGIC`] when valid.
    pub magic: u32,
    /// The reason's code.
    pub reason: u32,
    /// PC or source line.
    pub detail: u32,
    /// `!(magic ^ reason ^ detail)`: power-on garbage almost never matches.
    pub check: u32,
}

impl ResetRecord {
    /// The record for `reason` with `detail`.
    pub const fn encode(reason: ResetReason, detail: u32) -> Self {
        let r = reason.code();
        Self {
            magic: MAGIC,
            reason: r,
            detail,
            check: !(MAGIC ^ r ^ detail),
        }
    }

    /// The reason and detail of a valid record, `None` for garbage or a cleared record.
    pub const fn decode(&self) -> Option<(ResetReason, u32)> {
        if self.magic != MAGIC || self.check != !(self.magic ^ self.reason ^ self.detail) {
            return None;
        }
        match ResetReason::from_code(self.reason) {
            Some(r) => Some((r, self.detail)),
            None => None,
        }
    }

    /// What the last reset was: the record if valid, else the watchdog flag, else power-on.
    pub const fn last_reset(&self, iwdg_flag: bool) -> (ResetReason, u32) {
        match self.decode() {
            Some(r) => r,
            None if iwdg_flag => (ResetReason::Watchdog, 0),
            None => (ResetReason::PowerOn, 0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_and_garbage_is_refused() {
        for (r, d) in [
            (ResetReason::Panic, 123),
            (ResetReason::HardFault, 0x0800_1234),
            (ResetReason::Watchdog, 0),
        ] {
            let rec = ResetRecord::encode(r, d);
            assert_eq!(rec.decode(), Some((r, d)));
            assert_eq!(rec.last_reset(false), (r, d), "a record wins over the flag");
        }
        // Power-on RAM, a cleared record, a flipped bit, an unknown reason.
        let zero = ResetRecord::default();
        assert_eq!(zero.decode(), None);
        assert_eq!(zero.last_reset(false), (ResetReason::PowerOn, 0));
        assert_eq!(zero.last_reset(true), (ResetReason::Watchdog, 0));
        let mut flipped = ResetRecord::encode(ResetReason::Panic, 7);
        flipped.detail ^= 4;
        assert_eq!(flipped.decode(), None);
        let bogus = ResetRecord {
            magic: MAGIC,
            reason: 9,
            detail: 0,
            check: !(MAGIC ^ 9),
        };
        assert_eq!(bogus.decode(), None);
        let garbage = ResetRecord {
            magic: 0xDEAD_BEEF,
            reason: 2,
            detail: 5,
            check: 0,
        };
        assert_eq!(garbage.decode(), None);
        // Taken once: the next boot without a new record is a power-on.
        let mut kept = ResetRecord::encode(ResetReason::Panic, 42);
        assert_eq!(take_last_reset(&mut kept, false), (ResetReason::Panic, 42));
        assert_eq!(take_last_reset(&mut kept, false), (ResetReason::PowerOn, 0));
        println!(
            "panic record: {:x?} -> {}",
            ResetRecord::encode(ResetReason::Panic, 42),
            ResetReason::Panic.name()
        );
    }
}
