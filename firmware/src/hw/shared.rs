//! The statics shared between the control interrupt and the tasks: the lock-free structures
//! of the library (`firmware::{mailbox, capture, stats, liveness, sample}`). Nothing here is
//! held across a sample: the interrupt never waits for a task.

use core::sync::atomic::AtomicU32;

use firmware::capture::CaptureBuffer;
use firmware::design_parameters;
use firmware::learn::LearnShared;
use firmware::liveness::Liveness;
use firmware::mailbox::Mailbox;
use firmware::sample::{Links, Requests, Status};
use firmware::settings::LoopConfig;
use firmware::stats::SharedStats;

/// New loop configurations (controller, reference, ADC correction), built by the command task.
pub static CONFIG: Mailbox<LoopConfig> = Mailbox::new();
/// Mode, clear and raise requests of the tasks.
pub static REQUESTS: Requests = Requests::new();
/// The interrupt's timing figures.
pub static STATS: SharedStats = SharedStats::new();
/// Watchdog liveness counters.
pub static LIVENESS: Liveness = Liveness::new();
/// The interrupt's published status.
pub static STATUS: Status = Status::new();
/// The capture buffer (400 kB, in AXI SRAM: all of RAM is AXI SRAM in `memory.x`).
pub static CAPTURE: CaptureBuffer<{ design_parameters::CAPTURE_RECORDS }> = CaptureBuffer::new();
/// The learning control's tables and error records (80 KiB), in DTCM (`memory.x`: NOLOAD,
/// zeroed by `super::zero_dtcm` before anything touches it; all-zero bytes are
/// `LearnShared::new()`).
#[unsafe(link_section = ".dtcm.learn")]
pub static LEARN: LearnShared = LearnShared::new();
/// Cycle budget of one sample (the period in CPU cycles minus the conversion time).
pub static BUDGET_CYCLES: AtomicU32 = AtomicU32::new(u32::MAX);
/// Samples without a task check-in before the interrupt raises the watchdog fault.
pub static STALL_SAMPLES: AtomicU32 = AtomicU32::new(u32::MAX);

/// The links the interrupt's core uses.
pub const LINKS: Links<'static> = Links {
    config: &CONFIG,
    requests: &REQUESTS,
    liveness: &LIVENESS,
    stats: &STATS,
    status: &STATUS,
    stall_samples: &STALL_SAMPLES,
    budget_cycles: &BUDGET_CYCLES,
};
