//! State shared between the control interrupt and the tasks: atomics and the lock-free
//! structures of the library (`firmware::{mailbox, capture, stats, liveness}`). Nothing here
//! is held across a sample: the interrupt never waits for a task.

use core::sync::atomic::{AtomicBool, AtomicU8, AtomicU32, Ordering};

use firmware::capture::CaptureBuffer;
use firmware::liveness::Liveness;
use firmware::mailbox::Mailbox;
use firmware::stats::SharedStats;
use model_core::params;

use firmware::settings::LoopConfig;
use model_core::controller::Mode;

/// New loop configurations (controller and reference), built by the command task.
pub static CONFIG: Mailbox<LoopConfig> = Mailbox::new();
/// The interrupt's timing figures.
pub static STATS: SharedStats = SharedStats::new();
/// Watchdog liveness counters.
pub static LIVENESS: Liveness = Liveness::new();
/// The capture buffer (400 kB, in AXI SRAM: all of RAM is AXI SRAM in `memory.x`).
pub static CAPTURE: CaptureBuffer<{ params::FW_CAPTURE_RECORDS }> = CaptureBuffer::new();

/// "No request" in [`MODE_REQUEST`].
pub const NO_MODE: u8 = 0xFF;
/// A mode change for the interrupt ([`mode_to_u8`]), or [`NO_MODE`].
pub static MODE_REQUEST: AtomicU8 = AtomicU8::new(NO_MODE);
/// Clear the latched faults at the next sample.
pub static CLEAR_REQUEST: AtomicBool = AtomicBool::new(false);
/// Fault bits the tasks raise into the controller at the next sample.
pub static RAISE_REQUEST: AtomicU8 = AtomicU8::new(0);
/// Cycle budget of one sample (the period in CPU cycles minus the conversion time).
pub static BUDGET_CYCLES: AtomicU32 = AtomicU32::new(u32::MAX);
/// Samples without a task check-in before the interrupt raises the watchdog fault.
pub static STALL_SAMPLES: AtomicU32 = AtomicU32::new(u32::MAX);

/// Published by the interrupt after each sample.
pub struct Status {
    /// Present mode ([`mode_to_u8`]).
    pub mode: AtomicU8,
    /// Latched fault bits.
    pub faults: AtomicU8,
    /// Last ADC code (i16 in the low half).
    pub y: AtomicU32,
    /// Last DAC code.
    pub u: AtomicU32,
    /// Last reference, as an ADC code.
    pub r: AtomicU32,
    /// Samples whose DAC frame was still in flight at the next sample.
    pub dac_late: AtomicU32,
}

/// The interrupt's published status.
pub static STATUS: Status = Status {
    mode: AtomicU8::new(0),
    faults: AtomicU8::new(0),
    y: AtomicU32::new(0),
    u: AtomicU32::new(0),
    r: AtomicU32::new(0),
    dac_late: AtomicU32::new(0),
};

/// A mode as one byte.
pub fn mode_to_u8(m: Mode) -> u8 {
    match m {
        Mode::Safe => 0,
        Mode::OpenLoop => 1,
        Mode::ClosedLoop => 2,
        Mode::Hold => 3,
    }
}

/// The mode of a byte, if it names one.
pub fn mode_from_u8(b: u8) -> Option<Mode> {
    match b {
        0 => Some(Mode::Safe),
        1 => Some(Mode::OpenLoop),
        2 => Some(Mode::ClosedLoop),
        3 => Some(Mode::Hold),
        _ => None,
    }
}

/// Reads an i16 published in an `AtomicU32`.
pub fn load_i16(a: &AtomicU32) -> i16 {
    a.load(Ordering::Relaxed) as u16 as i16
}
