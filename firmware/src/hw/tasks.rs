//! The tasks below the control interrupt: the command line on USART3, the heartbeat LEDs and
//! the watchdog supervisor. Their bodies are `firmware::tasks` (generic over the serial, pin
//! and delay traits, and run by the virtual board on the host); this file only binds them to
//! embassy's UART, GPIO, delay and the IWDG.

use core::sync::atomic::Ordering;

use embassy_stm32::gpio::Output;
use embassy_stm32::usart::BufferedUart;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_time::Delay;
use firmware::app::{App, Board};
use firmware::design_parameters;
use firmware::liveness::Verdict;
use firmware::reset_reason::ResetReason;
use firmware::scaling::TimerSetting;
use firmware::tasks::{self, Watchdog};

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

/// The IWDG as the supervisor sees it.
struct Iwdg(IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG1>);

impl Watchdog for Iwdg {
    fn start(&mut self) {
        self.0.unleash();
    }
    fn feed(&mut self) {
        self.0.pet();
    }
}

/// The command line (`firmware::tasks::command_task`) on USART3.
#[embassy_executor::task]
pub async fn command_task(
    mut uart: BufferedUart<'static>,
    mut app: App<{ design_parameters::CAPTURE_RECORDS }>,
) {
    tasks::command_task(&mut uart, &mut Delay, &mut app, &mut HwBoard, &LIVENESS).await;
}

/// The heartbeat (`firmware::tasks::heartbeat_task`): green LED, red fault LED.
#[embassy_executor::task]
pub async fn heartbeat_task(mut led: Output<'static>, mut fault_led: Output<'static>) {
    tasks::heartbeat_task(&mut Delay, &mut led, &mut fault_led, &STATUS, &LIVENESS).await;
}

/// The watchdog supervisor (`firmware::tasks::supervisor_task`); logs each change of verdict.
#[embassy_executor::task]
pub async fn supervisor_task(
    iwdg: IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG1>,
) {
    let log = |verdict: &Verdict| match *verdict {
        Verdict::Feed => defmt::info!("liveness restored"),
        Verdict::IsrStalled { advanced } => {
            defmt::warn!("control interrupt stalled ({} samples)", advanced)
        }
        Verdict::TasksStalled { missing } => {
            defmt::warn!("tasks stalled (missing {:x})", missing)
        }
    };
    tasks::supervisor_task(&mut Delay, &mut Iwdg(iwdg), &LIVENESS, &STALL_SAMPLES, log).await;
}
