//! The tasks below the control interrupt (issue 13, virtual board): the command line, the
//! heartbeat and the watchdog supervisor, as `async` functions generic over the
//! embedded-io-async serial traits, embedded-hal's pins and embedded-hal-async's delay.
//!
//! # Design
//! The board binds them to embassy's `BufferedUart`, `Output` and `Delay` and the IWDG
//! (`src/hw/tasks.rs`, one line each); the virtual board (`tests/virtual_board.rs`) polls the
//! same futures under simulated, deterministic time with a simulated serial line, LEDs and a
//! fake IWDG. So the check-in cadence, the upload's frame-at-a-time writes with the line read
//! between frames, the LED logic and the supervisor's feed decision that run on the host are
//! the ones the board runs, with the constants of [`design_parameters`].
//!
//! - Nothing here waits on the control interrupt, and the interrupt never waits on a task: the
//!   tasks meet it only through the lock-free [`Links`](crate::sample::Links) structures.
//! - Time: a task's period is a delay after its body, not a fixed-rate ticker; the body takes
//!   microseconds, so a 10 ms check-in drifts by well under 1 % (the stall limit,
//!   `TASK_STALL_S`, is five periods).
//! - A read that times out is dropped (embassy's `BufferedUart::read` is cancel-safe: bytes
//!   stay in its ring buffer).

use core::sync::atomic::{AtomicU32, Ordering};

use embassy_futures::select::{Either, select};
use embedded_hal::digital::{OutputPin, StatefulOutputPin};
use embedded_hal_async::delay::DelayNs;
use embedded_io_async::{Read, Write};
use model_core::frame;

use crate::app::{App, Board};
use crate::design_parameters::{HEARTBEAT_TICKS_PER_TOGGLE, SUPERVISOR_PERIOD_S, TASK_CHECK_IN_S};
use crate::liveness::{self, Liveness, TASK_COMMAND, TASK_HEARTBEAT, Verdict};
use crate::sample::Status;

/// The command task's wait for a byte when there is nothing to send, µs: its check-in period.
pub const CHECK_IN_US: u32 = (TASK_CHECK_IN_S * 1e6) as u32;
/// The supervisor's period, µs.
pub const SUPERVISOR_PERIOD_US: u32 = (SUPERVISOR_PERIOD_S * 1e6) as u32;
/// The command task's wait for a byte between two upload frames, µs: short, so the upload
/// runs at the line's speed, but the line is read between frames (issue 13 item 8).
pub const BETWEEN_FRAMES_US: u32 = 10;
/// The first line after boot.
pub const GREETING: &[u8] = b"piezo firmware ready (help lists the commands)\r\n";
/// Bytes read from the line at a time.
const READ_CHUNK: usize = 32;

/// The independent watchdog, as the supervisor needs it.
pub trait Watchdog {
    /// Starts it (it cannot be stopped afterwards).
    fn start(&mut self);
    /// Reloads its counter.
    fn feed(&mut self);
}

/// The command line: reads lines, answers each with one `ok ...` or `err ...` line. During a
/// capture upload it sends one frame at a time and reads the line between frames, so a `mode
/// safe` is applied within one frame. Checks in at least every [`CHECK_IN_US`] (plus the
/// time to write a reply or a frame into the UART's buffer). Write errors are dropped: the
/// host sees a missing line, the loop does not stop.
pub async fn command_task<U, D, B, const N: usize>(
    uart: &mut U,
    delay: &mut D,
    app: &mut App<N>,
    board: &mut B,
    live: &Liveness,
) where
    U: Read + Write,
    D: DelayNs,
    B: Board,
{
    let mut bytes = [0u8; READ_CHUNK];
    let mut frame_bytes = [0u8; frame::MAX_FRAME];
    let _ = uart.write_all(GREETING).await;
    loop {
        live.check_in(TASK_COMMAND);
        if let Some(reply) = app.poll(board) {
            send_line(uart, reply.as_bytes()).await;
        }
        let wait_us = match app.next_upload_frame(&mut frame_bytes) {
            Some(n) => {
                let _ = uart.write_all(frame_bytes.get(..n).unwrap_or(&[])).await;
                if !app.uploading() {
                    let _ = uart.flush().await;
                }
                BETWEEN_FRAMES_US
            }
            None => CHECK_IN_US,
        };
        let n = match select(uart.read(&mut bytes), delay.delay_us(wait_us)).await {
            Either::First(Ok(n)) => n,
            // A framing or noise error drops the bytes; a timeout just checks in again.
            Either::First(Err(_)) | Either::Second(()) => continue,
        };
        for &b in bytes.get(..n).unwrap_or(&[]) {
            if let Some(reply) = app.feed(b, board) {
                send_line(uart, reply.as_bytes()).await;
            }
        }
    }
}

/// One reply line and its line ending.
async fn send_line<U: Write>(uart: &mut U, line: &[u8]) {
    let _ = uart.write_all(line).await;
    let _ = uart.write_all(b"\r\n").await;
}

/// Checks in every `TASK_CHECK_IN_S`; toggles `led` every `HEARTBEAT_HALF_PERIOD_S`; lights
/// `fault_led` while a fault is latched. (Checking in only at each LED toggle, every 250 ms,
/// was the watchdog reset loop of issue 13 item 1.) Pin errors are ignored: an LED is not
/// worth stopping the check-ins for.
pub async fn heartbeat_task<D, L, F>(
    delay: &mut D,
    led: &mut L,
    fault_led: &mut F,
    status: &Status,
    live: &Liveness,
) where
    D: DelayNs,
    L: StatefulOutputPin,
    F: OutputPin,
{
    let mut ticks = 0u32;
    loop {
        if ticks == 0 {
            let _ = led.toggle();
        }
        ticks = (ticks + 1) % HEARTBEAT_TICKS_PER_TOGGLE;
        let _ = if status.faults.load(Ordering::Relaxed) != 0 {
            fault_led.set_high()
        } else {
            fault_led.set_low()
        };
        live.check_in(TASK_HEARTBEAT);
        delay.delay_us(CHECK_IN_US).await;
    }
}

/// Starts the watchdog, then every `SUPERVISOR_PERIOD_S` feeds it while the interrupt and the
/// tasks are alive (`liveness::Liveness::supervise`, with the stall limit the interrupt
/// publishes in `stall_samples`: the rate may change at run time). `log` hears each change of
/// verdict (not every period, so a stall does not flood the log).
pub async fn supervisor_task<D, W>(
    delay: &mut D,
    watchdog: &mut W,
    live: &Liveness,
    stall_samples: &AtomicU32,
    mut log: impl FnMut(&Verdict),
) where
    D: DelayNs,
    W: Watchdog,
{
    let mut last = 0u32;
    let mut previous = Verdict::Feed;
    watchdog.start();
    loop {
        let stall = stall_samples.load(Ordering::Relaxed);
        let verdict = live.supervise(&mut last, liveness::min_advance(), stall);
        if verdict == Verdict::Feed {
            watchdog.feed();
        }
        if core::mem::discriminant(&verdict) != core::mem::discriminant(&previous) {
            log(&verdict);
        }
        previous = verdict;
        delay.delay_us(SUPERVISOR_PERIOD_US).await;
    }
}
