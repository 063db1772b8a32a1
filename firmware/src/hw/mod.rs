//! Everything that touches registers: built for thumbv7em-none-eabihf only.
//!
//! Bring-up order (the output must hold the safe value from the first instant):
//! 1. clocks, caches, DWT cycle counter;
//! 2. DAC: configured and loaded with the safe code (output-enable switch still open);
//! 3. controller built from the default settings, interrupt context installed;
//! 4. ADC armed on the TIM2 trigger, interrupt priorities set (control highest), TIM2 started;
//! 5. output-enable switch closed once the loop runs; tasks spawned; IWDG started.
//!
//! If the IWDG, a panic or a HardFault reset the chip (`safe_state`), the WATCHDOG fault is
//! raised at boot: the controller stays in safe until `clear`; `status` names the reason.

mod adc;
mod board;
mod control;
mod dac;
mod safe_state;
mod shared;
mod tasks;
mod timer;

use core::sync::atomic::Ordering;

use cortex_m::peripheral::DWT;
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, interrupt, pac, peripherals};
use embassy_time::Timer;
use firmware::design_parameters;
use firmware::sample::LoopCore;
use firmware::scaling::TimerSetting;
use firmware::stats::CycleStats;
use model_core::DacCode;
use static_cell::StaticCell;

use firmware::settings::Settings;
use model_core::controller::{ControllerState, Faults};

unsafe extern "C" {
    /// Start of the ITCM code (linker script `memory.x`).
    static __sitcm: u32;
    /// End of the ITCM code.
    static __eitcm: u32;
    /// Where the ITCM code is stored in flash.
    static __siitcm: u32;
    /// Start of the `.dtcm` section (NOLOAD; linker script `memory.x`).
    static __sdtcm: u32;
    /// End of the `.dtcm` section.
    static __edtcm: u32;
}

/// Zeroes the `.dtcm` section (the learning's buffers, `shared::LEARN`), which the start-up
/// code leaves as it found it: the zero bytes are the statics' declared values. Called once at
/// boot, before anything reads them (the interrupt is not enabled yet). Bounded by the
/// section's size.
fn zero_dtcm() {
    let mut dst = (&raw const __sdtcm).cast_mut();
    let end = &raw const __edtcm;
    while dst.cast_const() < end {
        // SAFETY: `__sdtcm..__edtcm` is the `.dtcm` section in DTCM (enabled at reset on the
        // H743, word-aligned by `memory.x`); nothing has read or taken a reference to the
        // statics in it yet (this runs first in `main`, before the interrupt is enabled).
        unsafe {
            dst.write_volatile(0);
            dst = dst.add(1);
        }
    }
    cortex_m::asm::dsb();
}

/// Copies the `.itcm` code (the control interrupt's handler) from flash to ITCM. Called once
/// at boot, before the interrupt is enabled. Bounded by the section's size.
fn load_itcm() {
    let mut dst = (&raw const __sitcm).cast_mut();
    let end = &raw const __eitcm;
    let mut src = &raw const __siitcm;
    while dst.cast_const() < end {
        // SAFETY: `__sitcm..__eitcm` is the `.itcm` section in ITCM (enabled at reset on the
        // H743, word-aligned by `memory.x`) and `__siitcm` its load image in flash of the same
        // length; nothing runs from ITCM yet (the interrupt is not enabled), so nothing reads
        // the words while they are written.
        unsafe {
            dst.write_volatile(src.read_volatile());
            dst = dst.add(1);
            src = src.add(1);
        }
    }
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
}

bind_interrupts!(struct Irqs {
    USART3 => usart::BufferedInterruptHandler<peripherals::USART3>;
});

static UART_TX: StaticCell<[u8; design_parameters::UART_TX_BYTES]> = StaticCell::new();
static UART_RX: StaticCell<[u8; design_parameters::UART_RX_BYTES]> = StaticCell::new();

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    zero_dtcm();
    let p = embassy_stm32::init(board::config());
    // The typed-in clocks (CPU_HZ: cycle counts in `status`; TIMER_CLOCK_HZ: the loop rate)
    // must be the ones embassy set up (issue 13 item 9). If not, stay here: the DAC is not
    // configured yet and the output switch's pull-down keeps the amplifier input at 0 V.
    {
        let clocks = embassy_stm32::rcc::clocks(&p.RCC);
        let sys_hz = clocks.sys.to_hertz().map_or(0, |h| h.0);
        let tim_hz = clocks.pclk1_tim.to_hertz().map_or(0, |h| h.0);
        if sys_hz != board::CPU_HZ || tim_hz != board::TIMER_CLOCK_HZ {
            defmt::error!(
                "clock mismatch: sys {} Hz (expected {}), timers {} Hz (expected {}); loop not started",
                sys_hz,
                board::CPU_HZ,
                tim_hz,
                board::TIMER_CLOCK_HZ
            );
            loop {
                cortex_m::asm::wfi();
            }
        }
    }
    // Was the last reset the watchdog's? (RCC_RSR, cleared by RMVF.)
    let iwdg_reset = pac::RCC.rsr().read().iwdg1rstf();
    pac::RCC.rsr().modify(|w| w.set_rmvf(true));
    // A panic or HardFault left its reason in reset-surviving RAM (`safe_state`).
    let (last_reset, detail) = safe_state::take_last_reset(iwdg_reset);
    if last_reset != firmware::reset_reason::ResetReason::PowerOn {
        defmt::warn!("last reset: {} (detail {:x})", last_reset.name(), detail);
    }

    let mut cp = cortex_m::Peripherals::take().expect("core peripherals are taken once, here");
    cp.SCB.enable_icache();
    // No DMA is used, so the data cache needs no maintenance.
    cp.SCB.enable_dcache(&mut cp.CPUID);
    cp.DCB.enable_trace();
    DWT::unlock();
    cp.DWT.enable_cycle_counter();

    // The embassy time driver's interrupt must stay below the control interrupt.
    interrupt::TIM3.set_priority(board::PRIO_TIME);

    let settings = Settings::default();
    let setting = match TimerSetting::for_rate(board::TIMER_CLOCK_HZ, settings.rate_hz, 32) {
        Ok(t) => t,
        Err(_) => defmt::panic!("the default rate is reachable"),
    };
    let config = match settings.loop_config() {
        Ok(c) => c,
        Err(_) => defmt::panic!("the default configuration is valid"),
    };

    // 2. The DAC holds the safe value before anything else runs.
    let safe = DacCode::from_volts(config.controller.safe_v());
    #[cfg(not(feature = "internal-dac"))]
    let dac = dac::Dac::new(p.SPI1, p.PA5, p.PB5, p.PD14, safe);
    #[cfg(feature = "internal-dac")]
    let dac = dac::Dac::new(p.DAC1, p.PA4, safe);
    let mut output_enable = Output::new(p.PD15, Level::Low, Speed::Low);

    // 3. The interrupt's context.
    let mut state = ControllerState::new(&config.controller);
    if last_reset != firmware::reset_reason::ResetReason::PowerOn {
        // Watchdog, panic or HardFault: stay safe until `clear`.
        state.raise(Faults::WATCHDOG);
    }
    let Some(producer) = shared::CAPTURE.producer() else {
        defmt::panic!("the capture producer is taken once")
    };
    let Some(consumer) = shared::CAPTURE.consumer() else {
        defmt::panic!("the capture consumer is taken once")
    };
    let (Some(recorder), Some(learn_task)) = (shared::LEARN.recorder(), shared::LEARN.task())
    else {
        defmt::panic!("the learning tokens are taken once")
    };
    firmware::app::apply_rate_limits(&shared::LINKS, setting.rate_hz, board::CPU_HZ);
    control::install(control::LoopContext {
        core: LoopCore {
            config: match shared::CONFIG.reader(config) {
                Some(r) => r,
                None => defmt::panic!("the configuration reader is taken once"),
            },
            state,
            stats: CycleStats::new(shared::BUDGET_CYCLES.load(Ordering::Relaxed)),
            capture: producer,
            learn: recorder,
        },
        dac,
        next: safe,
    });

    // 4. The handler's code into ITCM, then the ADC on the timer's trigger; the control
    // interrupt at the highest priority.
    load_itcm();
    // ADC on the timer's trigger; the control interrupt at the highest priority.
    adc::init(p.ADC1, p.PA3);
    timer::init(p.TIM2, &setting);
    interrupt::ADC.set_priority(board::PRIO_CONTROL);
    // SAFETY: the handler's context is installed above and everything it shares with the
    // tasks is atomic or behind the mailbox; enabling it cannot break a critical section.
    unsafe { interrupt::ADC.enable() };
    timer::start();

    // 5. The command link, the LEDs, the watchdog.
    // Before the driver enables the interrupt (its NVIC default would be P0, the highest).
    interrupt::USART3.set_priority(board::PRIO_UART);
    let mut ucfg = usart::Config::default();
    ucfg.baudrate = design_parameters::UART_BAUD;
    let uart = match BufferedUart::new(
        p.USART3,
        p.PD9,
        p.PD8,
        UART_TX.init([0; 2048]),
        UART_RX.init([0; 256]),
        Irqs,
        ucfg,
    ) {
        Ok(u) => u,
        Err(_) => defmt::panic!("USART3 configuration"),
    };

    Timer::after_micros((design_parameters::BOOT_LOOP_TO_TASKS_S * 1e6) as u64).await;
    output_enable.set_high();
    core::mem::forget(output_enable); // stays high; the reset state (input, pulled down) opens it

    let iwdg = IndependentWatchdog::new(p.IWDG1, (design_parameters::IWDG_TIMEOUT_S * 1e6) as u32);
    let led = Output::new(p.PB0, Level::Low, Speed::Low);
    let fault_led = Output::new(p.PB14, Level::Low, Speed::Low);
    defmt::info!("loop running at {} Hz", setting.rate_hz);
    let app = firmware::app::App::new(
        shared::LINKS,
        &shared::CAPTURE,
        consumer,
        learn_task,
        settings,
    );
    spawner.spawn(tasks::command_task(uart, app).expect("spawn command task"));
    spawner.spawn(tasks::heartbeat_task(led, fault_led).expect("spawn heartbeat task"));
    spawner.spawn(tasks::supervisor_task(iwdg).expect("spawn supervisor task"));
}
