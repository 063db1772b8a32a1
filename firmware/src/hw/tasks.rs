//! The tasks below the control interrupt: the command line on USART3, the heartbeat LED and
//! the watchdog supervisor. The command logic is `firmware::app` (host-tested, and run by the
//! virtual board); this file only binds it to the UART, the timer and the IWDG.

use core::sync::atomic::Ordering;

use embassy_stm32::gpio::Output;
use embassy_stm32::usart::BufferedUart;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_time::{Duration, Ticker, with_timeout};
use embedded_io_async::{Read, Write};
use firmware::app::{App, Board};
use firmware::design_parameters;
use firmware::liveness::{TASK_COMMAND, TASK_HEARTBEAT, Verdict};
use firmware::reset_reason::ResetReason;
use firmware::scaling::TimerSetting;
use model_core::frame;

use super::board::{CPU_HZ, TIMER_CLOCK_HZ};
use super::shared::*;
use super::timer;

/// The board behind the command handler.
struct HwBoard;

impl Board for HwBoard {
    fn cpu_hz(&self) -> u32 {
        CPU_HZ
    }
    fn timer_clock_hz(&self) -> u32 {
        TIMER_CLOCK_HZ
    }
    fn set_rate(&mut self, t: &TimerSetting) {
        timer::set_rate(t);
    }
    fn now_us(&self) -> u64 {
        embassy_time::Instant::now().as_micros()
    }
    fn last_reset(&self) -> (ResetReason, u32) {
        let reason =
            ResetReason::from_code(super::safe_state::LAST_RESET_REASON.load(Ordering::Relaxed))
                .unwrap_or(ResetReason::PowerOn);
        (
            reason,
            super::safe_state::LAST_RESET_DETAIL.load(Ordering::Relaxed),
        )
    }
}

/// The command line: reads lines, answers each with one `ok ...` or `err ...` line. During a
/// capture upload it sends one frame at a time and looks at the line between frames, so a
/// `mode safe` is applied within one frame (issue 13 item 8).
#[embassy_executor::task]
pub async fn command_task(
    mut uart: BufferedUart<'static>,
    mut app: App<{ design_parameters::CAPTURE_RECORDS }>,
) {
    let mut board = HwBoard;
    let mut byte = [0u8; 32];
    let mut frame_bytes = [0u8; frame::MAX_FRAME];
    let check_in = Duration::from_micros((design_parameters::TASK_CHECK_IN_S * 1e6) as u64);
    let between_frames = Duration::from_micros(10);
    let _ = uart
        .write_all(b"piezo firmware ready (help lists the commands)\r\n")
        .await;
    loop {
        LIVENESS.check_in(TASK_COMMAND);
        if let Some(reply) = app.poll(&board) {
            let _ = uart.write_all(reply.as_bytes()).await;
            let _ = uart.write_all(b"\r\n").await;
        }
        let wait = match app.next_upload_frame(&mut frame_bytes) {
            Some(n) => {
                let _ = uart.write_all(frame_bytes.get(..n).unwrap_or(&[])).await;
                if !app.uploading() {
                    let _ = uart.flush().await;
                }
                between_frames
            }
            None => check_in,
        };
        let n = match with_timeout(wait, uart.read(&mut byte)).await {
            Ok(Ok(n)) => n,
            Ok(Err(_)) => continue, // framing/noise error: drop the byte
            Err(_) => continue,     // timeout: just check in again
        };
        for &b in byte.get(..n).unwrap_or(&[]) {
            if let Some(reply) = app.feed(b, &mut board) {
                let _ = uart.write_all(reply.as_bytes()).await;
                let _ = uart.write_all(b"\r\n").await;
            }
        }
    }
}

/// Checks in every `TASK_CHECK_IN_S`; blinks the green LED every `HEARTBEAT_HALF_PERIOD_S`;
/// lights the red one while a fault is latched. (Checking in only at each LED toggle, every
/// 250 ms, was the watchdog reset loop of issue 13 item 1.)
#[embassy_executor::task]
pub async fn heartbeat_task(mut led: Output<'static>, mut fault_led: Output<'static>) {
    let tick = Duration::from_micros((design_parameters::TASK_CHECK_IN_S * 1e6) as u64);
    let mut ticker = Ticker::every(tick);
    let mut ticks = 0u32;
    loop {
        if ticks == 0 {
            led.toggle();
        }
        ticks = (ticks + 1) % design_parameters::HEARTBEAT_TICKS_PER_TOGGLE;
        if STATUS.faults.load(Ordering::Relaxed) != 0 {
            fault_led.set_high();
        } else {
            fault_led.set_low();
        }
        LIVENESS.check_in(TASK_HEARTBEAT);
        ticker.next().await;
    }
}

/// Feeds the IWDG while the interrupt and the tasks are alive (`firmware::liveness`). Logs a
/// verdict only when it changes, so a stall does not log every period.
#[embassy_executor::task]
pub async fn supervisor_task(
    mut iwdg: IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG1>,
) {
    let period = Duration::from_micros((design_parameters::SUPERVISOR_PERIOD_S * 1e6) as u64);
    let mut ticker = Ticker::every(period);
    let mut last = 0u32;
    let mut previous = Verdict::Feed;
    iwdg.unleash();
    loop {
        // The rate may change at run time: the stall limit is the published one.
        let stall = STALL_SAMPLES.load(Ordering::Relaxed);
        let verdict = LIVENESS.supervise(&mut last, firmware::liveness::min_advance(), stall);
        if verdict == Verdict::Feed {
            iwdg.pet();
        }
        if core::mem::discriminant(&verdict) != core::mem::discriminant(&previous) {
            match verdict {
                Verdict::Feed => defmt::info!("liveness restored"),
                Verdict::IsrStalled { advanced } => {
                    defmt::warn!("control interrupt stalled ({} samples)", advanced)
                }
                Verdict::TasksStalled { missing } => {
                    defmt::warn!("tasks stalled (missing {:x})", missing)
                }
            }
        }
        previous = verdict;
        ticker.next().await;
    }
}
