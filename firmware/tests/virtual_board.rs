//! The virtual board (issue 13): the firmware's register-free code on the host under
//! simulated, deterministic time, with the real constants.
//!
//! What runs is the firmware's own code: the control interrupt's [`LoopCore::step`] /
//! [`LoopCore::finish`] (`src/sample.rs`, calling `Controller::step_with_correction`, taking
//! new configurations from the mailbox in place), the three tasks' bodies
//! (`firmware::tasks::{command_task, heartbeat_task, supervisor_task}`, the async functions
//! `hw/tasks.rs` spawns on the board), polled here as futures once per sample under simulated
//! time, with the command task's [`App`] (`src/app.rs`: line assembly, the command handler,
//! `status`, the capture upload as frames, the learning update), the liveness rule
//! (`src/liveness.rs`) with the supervisor's verdicts, the
//! settings -> controller path, the boot's reset-record handling and the panic handler's
//! safe-state sequence (`reset_reason::{take_last_reset, enter_safe_state}`, the functions
//! `hw/safe_state.rs` calls), the ADC front end model of the README
//! (`scaling::front_end_pin_v`, open input included) and the default calibration. Around it,
//! simulated here: the clock (one tick per sample at the loop rate; `rate` re-times it and
//! the stage; the tasks' `DelayNs` waits on it), the executor (each task's future is polled
//! once after each sample, starting `BOOT_LOOP_TO_TASKS_S` after the loop; a stalled task is
//! one that is no longer polled), the serial line at `UART_BAUD` (10 bits a byte, the board's
//! 2048-byte TX and 256-byte RX buffers behind embedded-io-async's `Read` / `Write`), the
//! LEDs (embedded-hal pins), a fake IWDG (reset when not fed for `IWDG_TIMEOUT_S`), the chip's reset
//! (the output switch opens, RAM is rebuilt except the `.uninit` record, the RCC's IWDG
//! flag is kept, and after [`STARTUP_S`] the board boots again as `hw/mod.rs` does), the
//! output switch (closed by the boot sequence), the external DAC (holds its code through a
//! reset; ideal output stage: the code's volts), the interrupt's cycle count (a constant
//! [`ISR_CYCLES`] plus [`SWAP_CYCLES`] in a sample that takes a configuration: estimates) and
//! the thesis-full stage (`model_core::closed_loop::FullStage`) closing the loop. `piezo
//! record`'s own receiving code (`host_tests::board::record`) fetches a capture over the
//! simulated line.
//!
//! Not here (only a board can show them): embassy's executor and its time driver (`hw/tasks.rs`
//! is one call per task into `firmware::tasks`), the register writes of the panic handler (`hw::safe_state::Registers`: the
//! sequence's order and effects are tested here, the GPIO/SPI writes only on the board) and
//! the interrupt's real cycle counts (a host cannot measure them: the 200 kHz swap test shows
//! the swap is an index swap, asserted by the configuration lying in the mailbox's slot, and
//! charges it an estimate against the real budget).

use std::cell::{Cell, RefCell};
use std::collections::VecDeque;
use std::convert::Infallible;
use std::future::{Future, poll_fn};
use std::pin::Pin;
use std::rc::Rc;
use std::sync::atomic::{AtomicU32, Ordering};
use std::task::{Context, Poll, Waker};
use std::time::Duration;

use firmware::app::{App, Board};
use firmware::capture::CaptureBuffer;
use firmware::design_parameters::{
    BOOT_LOOP_TO_TASKS_S, CAPTURE_RECORDS, CPU_HZ, HEARTBEAT_HALF_PERIOD_S, IWDG_TIMEOUT_S,
    SUPERVISOR_PERIOD_S, TASK_CHECK_IN_S, TIMER_CLOCK_HZ, UART_BAUD, UART_RX_BYTES, UART_TX_BYTES,
};
use firmware::learn::LearnShared;
use firmware::liveness::{Liveness, Verdict};
use firmware::mailbox::Mailbox;
use firmware::reset_reason::{
    ResetReason, ResetRecord, SafeStateOutputs, enter_safe_state, take_last_reset,
};
use firmware::sample::{Links, LoopCore, Requests, Status};
use firmware::scaling::{self, TimerSetting};
use firmware::settings::{LoopConfig, Settings};
use firmware::stats::{CycleStats, SharedStats};
use firmware::tasks::{self, Watchdog};
use host_tests::board::{Link, Options, record};
use model_core::closed_loop::{FullStage, StageModel};
use model_core::controller::{ControllerState, Faults};
use model_core::stage::{Stage, StageConfig};
use model_core::{AdcCode, DacCode, params};

/// Cycles the virtual interrupt reports per sample: 2.5 us at 400 MHz, under the budget at
/// every rate (1200 cycles at 200 kHz: the 5 us period less the 2 us conversion allowance of
/// `app::apply_rate_limits`). Our assumption until the board measures `isr_max_us`.
const ISR_CYCLES: u32 = 1_000;
/// Cycles the interrupt adds in a sample that takes a new configuration: the mailbox's two
/// atomic swaps and an index store (`Reader::update`; no copy, the configuration is used in
/// its slot). Our estimate.
const SWAP_CYCLES: u32 = 16;
/// Cycles per byte of a `memcpy` in the interrupt: the README's "about 3 us" for the 4192-byte
/// configuration the interrupt copied before (1200 cycles at 400 MHz). Only to show what a copy
/// would cost at 200 kHz.
const COPY_CYCLES_PER_BYTE: f64 = 1200.0 / 4192.0;
/// From a reset of the chip to the loop's start (clocks, PLL lock, embassy init), seconds: our
/// assumption; the output switch is open throughout.
const STARTUP_S: f64 = 0.001;
/// Timer ticks from the sampling instant to the DAC write the virtual interrupt reports: the
/// 0.8 us conversion plus 0.3 us of entry and read at 200 MHz (an estimate; the board measures).
const WRITE_TICKS: u32 = 220;

/// What the sensor input sees.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Sensor {
    /// The E-509 monitor of the stage.
    Connected,
    /// The BNC unplugged.
    Open,
    /// The monitor frozen at a code, with +-`noise_lsb` of noise.
    Stuck { code: i16, noise_lsb: i16 },
    /// The monitor saturated at +15 V.
    OverRange,
    /// The loopback cable of `selftest`: the output stage (after the switch) into the front
    /// end.
    Loopback,
}

/// Simulated time, nanoseconds since power-on: set by the board before it polls the tasks.
#[derive(Clone, Default)]
struct Clock(Rc<Cell<u64>>);

impl Clock {
    fn now_ns(&self) -> u64 {
        self.0.get()
    }
}

/// The tasks' delay: ready once simulated time has passed the deadline.
struct SimDelay(Clock);

impl embedded_hal_async::delay::DelayNs for SimDelay {
    async fn delay_ns(&mut self, ns: u32) {
        let end = self.0.now_ns() + u64::from(ns);
        poll_fn(|_| {
            if self.0.now_ns() >= end {
                Poll::Ready(())
            } else {
                Poll::Pending
            }
        })
        .await
    }
}

/// The UART's buffers: the firmware writes into `tx`, the line drains it at the baud rate;
/// the host's bytes land in `rx` (dropped and counted when it is full, as the board's
/// ring buffer overruns).
#[derive(Default)]
struct Line {
    rx: VecDeque<u8>,
    tx: VecDeque<u8>,
    rx_overflow: u32,
}

/// The command task's side of the line, as embassy's `BufferedUart` behaves: `read` waits for
/// at least one byte, `write` for room in the TX buffer, `flush` until the buffer is sent.
#[derive(Clone, Default)]
struct SimUart(Rc<RefCell<Line>>);

impl embedded_io_async::ErrorType for SimUart {
    type Error = Infallible;
}

impl embedded_io_async::Read for SimUart {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        poll_fn(|_| {
            let mut line = self.0.borrow_mut();
            if line.rx.is_empty() && !buf.is_empty() {
                return Poll::Pending;
            }
            let n = buf.len().min(line.rx.len());
            for b in buf.iter_mut().take(n) {
                *b = line.rx.pop_front().unwrap_or(0);
            }
            Poll::Ready(Ok(n))
        })
        .await
    }
}

impl embedded_io_async::Write for SimUart {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        poll_fn(|_| {
            let mut line = self.0.borrow_mut();
            let free = UART_TX_BYTES - line.tx.len();
            if free == 0 && !buf.is_empty() {
                return Poll::Pending;
            }
            let n = buf.len().min(free);
            line.tx.extend(&buf[..n]);
            Poll::Ready(Ok(n))
        })
        .await
    }
    async fn flush(&mut self) -> Result<(), Infallible> {
        poll_fn(|_| {
            if self.0.borrow().tx.is_empty() {
                Poll::Ready(Ok(()))
            } else {
                Poll::Pending
            }
        })
        .await
    }
}

/// An LED: an embedded-hal output pin whose level the test reads.
#[derive(Clone, Default)]
struct Led(Rc<Cell<bool>>);

impl embedded_hal::digital::ErrorType for Led {
    type Error = Infallible;
}

impl embedded_hal::digital::OutputPin for Led {
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.0.set(false);
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Infallible> {
        self.0.set(true);
        Ok(())
    }
}

impl embedded_hal::digital::StatefulOutputPin for Led {
    fn is_set_high(&mut self) -> Result<bool, Infallible> {
        Ok(self.0.get())
    }
    fn is_set_low(&mut self) -> Result<bool, Infallible> {
        Ok(!self.0.get())
    }
}

/// The IWDG's counter: started by the supervisor, fed by it; the board resets the chip when
/// it has not been fed for `IWDG_TIMEOUT_S`.
#[derive(Clone, Copy, Default)]
struct IwdgState {
    running: bool,
    last_feed_ns: u64,
}

struct FakeIwdg {
    state: Rc<Cell<IwdgState>>,
    clock: Clock,
}

impl Watchdog for FakeIwdg {
    fn start(&mut self) {
        self.state.set(IwdgState {
            running: true,
            last_feed_ns: self.clock.now_ns(),
        });
    }
    fn feed(&mut self) {
        let mut s = self.state.get();
        s.last_feed_ns = self.clock.now_ns();
        self.state.set(s);
    }
}

/// One task's future, polled by the board after each sample.
type Task = Pin<Box<dyn Future<Output = ()>>>;

/// Polls a task once; it runs until it waits on time or the line. The tasks never end.
fn poll_task(task: &mut Task) {
    let mut cx = Context::from_waker(Waker::noop());
    assert!(task.as_mut().poll(&mut cx).is_pending(), "a task returned");
}

struct VirtualBoardHw {
    last_reset: (ResetReason, u32),
    /// The control timer's rate, as last loaded by `set_rate` (or the boot).
    rate_hz: Rc<Cell<f64>>,
    clock: Clock,
}

impl Board for VirtualBoardHw {
    fn cpu_hz(&self) -> u32 {
        CPU_HZ
    }
    fn timer_clock_hz(&self) -> u32 {
        TIMER_CLOCK_HZ
    }
    fn set_rate(&mut self, t: &TimerSetting) {
        self.rate_hz.set(t.rate_hz);
    }
    fn last_reset(&self) -> (ResetReason, u32) {
        self.last_reset
    }
    fn now_us(&self) -> u64 {
        // Simulated time does not advance inside a task run; the board measures this.
        self.clock.now_ns() / 1000
    }
}

/// One sample of the output trajectory.
#[derive(Clone, Copy, Debug)]
struct Trace {
    t_s: f64,
    /// Volts at the amplifier input (0 when the switch is open).
    amp_in_v: f32,
    /// The output switch was closed during the sample.
    switch_closed: bool,
    faults: u8,
}

/// The board's side of the peripherals the tasks use; it outlives a reset of the chip (the
/// test reads it), the firmware gets clones at every boot.
#[derive(Clone, Default)]
struct Peripherals {
    clock: Clock,
    uart: SimUart,
    led: Led,
    fault_led: Led,
    iwdg: Rc<Cell<IwdgState>>,
    /// The control timer's rate as the command task last loaded it.
    rate_hz: Rc<Cell<f64>>,
    /// The supervisor's log: each change of verdict and when.
    verdicts: Rc<RefCell<Vec<(f64, Verdict)>>>,
}

/// The three tasks of `hw/tasks.rs`, as futures.
struct Tasks {
    command: Task,
    heartbeat: Task,
    supervisor: Task,
}

/// The firmware's RAM: rebuilt from scratch at every boot.
struct Firmware {
    links: Links<'static>,
    core: LoopCore<CAPTURE_RECORDS>,
    tasks: Tasks,
    learn: &'static LearnShared,
    rate_hz: f64,
}

/// Steps 1-3 of `hw/mod.rs`'s boot on fresh RAM: the reset record read and cleared
/// (`reset_reason::take_last_reset`, as `hw::safe_state::take_last_reset` calls it), the
/// default settings, the interrupt's context with WATCHDOG latched after any reset that was
/// not a power-on, the command task's `App`; then the tasks spawned as `hw/mod.rs` spawns them
/// (their futures do nothing until polled).
fn load_firmware(uninit: &mut ResetRecord, iwdg_flag: bool, io: &Peripherals) -> Firmware {
    let last_reset = take_last_reset(uninit, iwdg_flag);
    let links = Links {
        config: Box::leak(Box::new(Mailbox::<LoopConfig>::new())),
        requests: Box::leak(Box::new(Requests::new())),
        liveness: Box::leak(Box::new(Liveness::new())),
        stats: Box::leak(Box::new(SharedStats::new())),
        status: Box::leak(Box::new(Status::new())),
        stall_samples: Box::leak(Box::new(AtomicU32::new(u32::MAX))),
        budget_cycles: Box::leak(Box::new(AtomicU32::new(u32::MAX))),
    };
    let capture: &'static CaptureBuffer<CAPTURE_RECORDS> =
        Box::leak(Box::new(CaptureBuffer::new()));
    let learn: &'static LearnShared = Box::leak(Box::new(LearnShared::new()));
    let settings = Settings::default();
    let config = settings.loop_config().expect("the default configuration");
    firmware::app::apply_rate_limits(&links, settings.rate_hz, CPU_HZ);
    let mut state = ControllerState::new(&config.controller);
    if last_reset.0 != ResetReason::PowerOn {
        state.raise(Faults::WATCHDOG);
    }
    let core = LoopCore {
        config: links.config.reader(config).expect("one reader"),
        state,
        stats: CycleStats::new(links.budget_cycles.load(Ordering::Relaxed)),
        capture: capture.producer().expect("one producer"),
        learn: learn.recorder().expect("one recorder"),
    };
    let mut app = App::new(
        links,
        capture,
        capture.consumer().expect("one consumer"),
        learn.task().expect("one learning task"),
        settings,
    );
    io.rate_hz.set(settings.rate_hz);
    let mut hw = VirtualBoardHw {
        last_reset,
        rate_hz: io.rate_hz.clone(),
        clock: io.clock.clone(),
    };
    let (mut uart, mut led, mut fault_led) =
        (io.uart.clone(), io.led.clone(), io.fault_led.clone());
    let (clock, verdicts) = (io.clock.clone(), io.verdicts.clone());
    let mut iwdg = FakeIwdg {
        state: io.iwdg.clone(),
        clock: io.clock.clone(),
    };
    let tasks = Tasks {
        command: Box::pin({
            let mut delay = SimDelay(io.clock.clone());
            async move {
                tasks::command_task(&mut uart, &mut delay, &mut app, &mut hw, links.liveness).await
            }
        }),
        heartbeat: Box::pin({
            let mut delay = SimDelay(io.clock.clone());
            async move {
                tasks::heartbeat_task(
                    &mut delay,
                    &mut led,
                    &mut fault_led,
                    links.status,
                    links.liveness,
                )
                .await
            }
        }),
        supervisor: Box::pin({
            let mut delay = SimDelay(io.clock.clone());
            async move {
                let log = |v: &Verdict| {
                    verdicts
                        .borrow_mut()
                        .push((clock.now_ns() as f64 * 1e-9, *v))
                };
                tasks::supervisor_task(
                    &mut delay,
                    &mut iwdg,
                    links.liveness,
                    links.stall_samples,
                    log,
                )
                .await
            }
        }),
    };
    Firmware {
        links,
        core,
        tasks,
        learn,
        rate_hz: settings.rate_hz,
    }
}

/// The thesis-full stage re-timed to `rate_hz`, at rest at 0 V.
fn stage_at(rate_hz: f64) -> FullStage {
    let cfg = StageConfig {
        period_s: 1.0 / rate_hz,
        ..StageConfig::thesis_full()
    };
    FullStage::new(Stage::new(&cfg).expect("thesis-full stage"), 0.0)
}

/// What the panic handler's register-free sequence drives on the virtual board.
struct ChipOutputs<'a> {
    switch_closed: &'a mut bool,
    dac_code: &'a mut DacCode,
    uninit: &'a mut ResetRecord,
    /// The sequence's steps in the order they ran.
    log: &'a mut Vec<&'static str>,
}

impl SafeStateOutputs for ChipOutputs<'_> {
    fn mask_interrupts(&mut self) {
        self.log.push("mask");
    }
    fn open_output_switch(&mut self) {
        *self.switch_closed = false;
        self.log.push("switch");
    }
    fn send_dac(&mut self, code: DacCode) {
        *self.dac_code = code;
        self.log.push("dac");
    }
    fn keep_record(&mut self, record: ResetRecord) {
        *self.uninit = record;
        self.log.push("record");
    }
}

struct VirtualBoard {
    n: u64,
    time_s: f64,
    rate_hz: f64,
    links: Links<'static>,
    core: LoopCore<CAPTURE_RECORDS>,
    tasks: Tasks,
    /// The learning's shared buffers (`learn on`).
    learn: &'static LearnShared,
    io: Peripherals,
    stage: FullStage,
    sensor: Sensor,
    noise_state: u32,
    switch_closed: bool,
    /// The code the external DAC holds (it keeps it through a reset of the chip).
    dac_code: DacCode,
    /// The code computed in the previous sample: the interrupt sends it first thing (the DAC
    /// frame at a fixed instant, one sample of computational delay; `hw/control.rs`).
    next_code: DacCode,
    /// The amplifier input (the switch's output) during the last sample.
    amp_in_v: f32,
    /// The chip is in reset (after an IWDG bite or a panic) until `boot_at_s`: the switch is
    /// open (PD15's reset state), nothing runs.
    halted: bool,
    boot_at_s: f64,
    /// When the present boot started (the loop runs, the tasks follow
    /// `BOOT_LOOP_TO_TASKS_S` later).
    boot_t_s: f64,
    /// Reset-surviving RAM (`.uninit`): the panic handler's record.
    uninit: ResetRecord,
    /// The RCC's IWDG reset flag.
    iwdg_flag: bool,
    /// A panic to raise in the next interrupt (its source line).
    panic_line: Option<u32>,
    /// The safe-state sequence's steps, in order, of the last panic.
    safe_state_log: Vec<&'static str>,
    boots: u32,
    isr_alive: bool,
    /// False: the heartbeat task is no longer polled (a stalled task).
    heartbeat_alive: bool,
    tasks_started: bool,
    iwdg_resets: u32,
    tx_credit: f64,
    host_rx: Vec<u8>,
    /// Bytes the host has received in all.
    host_rx_total: usize,
    trace: Vec<Trace>,
    /// Simulated times of the green LED's changes.
    led_toggles: Vec<f64>,
    /// Samples during which the red LED was lit.
    fault_led_samples: u64,
    /// Greeting lines the host has read (one per boot).
    greetings: u32,
}

impl VirtualBoard {
    /// Power-on: the boot sequence of `hw/mod.rs` (DAC safe, switch open, loop running).
    fn boot() -> Self {
        let mut uninit = ResetRecord::default();
        let io = Peripherals::default();
        let fw = load_firmware(&mut uninit, false, &io);
        let safe = DacCode::from_volts(params::SAFE_OUTPUT_V as f32);
        let mut vb = Self {
            n: 0,
            time_s: 0.0,
            rate_hz: fw.rate_hz,
            links: fw.links,
            core: fw.core,
            tasks: fw.tasks,
            learn: fw.learn,
            io,
            stage: stage_at(params::SAMPLE_RATE_HZ),
            sensor: Sensor::Connected,
            noise_state: 0x1234_5678,
            switch_closed: false,
            dac_code: safe,
            next_code: safe,
            amp_in_v: 0.0,
            halted: false,
            boot_at_s: 0.0,
            boot_t_s: 0.0,
            uninit,
            iwdg_flag: false,
            panic_line: None,
            safe_state_log: vec![],
            boots: 0,
            isr_alive: true,
            heartbeat_alive: true,
            tasks_started: false,
            iwdg_resets: 0,
            tx_credit: 0.0,
            host_rx: vec![],
            host_rx_total: 0,
            trace: vec![],
            led_toggles: vec![],
            fault_led_samples: 0,
            greetings: 0,
        };
        vb.start_boot();
        vb
    }

    /// The parts of a boot outside the firmware's RAM: DAC at the safe code (step 2), switch
    /// open until the tasks start, the timer at the default rate, the UART's buffers empty,
    /// the LEDs off, the IWDG stopped.
    fn start_boot(&mut self) {
        let t = self.time_s;
        self.boots += 1;
        self.dac_code = DacCode::from_volts(params::SAFE_OUTPUT_V as f32);
        self.next_code = self.dac_code;
        self.switch_closed = false;
        self.halted = false;
        self.isr_alive = true;
        self.heartbeat_alive = true;
        self.tasks_started = false;
        self.boot_t_s = t;
        {
            let mut line = self.io.uart.0.borrow_mut();
            line.rx.clear();
            line.tx.clear();
        }
        self.io.led.0.set(false);
        self.io.fault_led.0.set(false);
        self.io.iwdg.set(IwdgState::default());
        self.follow_rate();
    }

    /// The chip comes out of reset: fresh RAM apart from `.uninit`, the RCC flag read and
    /// cleared, then the boot.
    fn reboot(&mut self) {
        let fw = load_firmware(&mut self.uninit, self.iwdg_flag, &self.io);
        self.iwdg_flag = false;
        self.links = fw.links;
        self.core = fw.core;
        self.tasks = fw.tasks;
        self.learn = fw.learn;
        self.start_boot();
    }

    /// The chip resets (IWDG or `sys_reset`): the switch opens, nothing runs for
    /// [`STARTUP_S`], then it boots.
    fn enter_reset(&mut self) {
        self.halted = true;
        self.switch_closed = false;
        self.isr_alive = false;
        self.tasks_started = false;
        self.io.iwdg.set(IwdgState::default());
        self.boot_at_s = self.time_s + STARTUP_S;
    }

    /// A new timer rate (`rate`, or the boot's default): the stage model is re-timed (at rest
    /// at 0 V: `rate` is taken only in safe mode, where the output has ramped to 0 V).
    fn follow_rate(&mut self) {
        let rate_hz = self.io.rate_hz.get();
        if rate_hz != self.rate_hz {
            self.rate_hz = rate_hz;
            self.stage = stage_at(self.rate_hz);
        }
    }

    fn t_s(&self) -> f64 {
        self.time_s
    }

    fn noise(&mut self, lsb: i16) -> i16 {
        let mut x = self.noise_state;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.noise_state = x;
        (x % (2 * lsb as u32 + 1)) as i16 - lsb
    }

    /// The raw ADC result: the sensor through the README's front end.
    fn adc_raw(&mut self) -> u32 {
        let pin = match self.sensor {
            Sensor::Connected => scaling::front_end_pin_v(Some(f64::from(self.stage.sensor_v()))),
            Sensor::Open => scaling::front_end_pin_v(None),
            Sensor::OverRange => scaling::front_end_pin_v(Some(15.0)),
            Sensor::Loopback => scaling::front_end_pin_v(Some(f64::from(self.amp_in_v))),
            Sensor::Stuck { code, noise_lsb } => {
                let c = code.saturating_add(self.noise(noise_lsb));
                let v = f64::from(AdcCode(c).volts());
                scaling::front_end_pin_v(Some(v))
            }
        };
        scaling::adc_raw_of_pin(pin)
    }

    /// One sample period: the interrupt, the stage, the tasks (each polled once, in the
    /// order command, heartbeat, supervisor), the serial line, the IWDG.
    fn tick(&mut self) {
        let t = self.t_s();
        if self.isr_alive && !self.halted {
            let raw = self.adc_raw();
            // The fixed instant: the previous sample's code goes to the DAC first.
            self.dac_code = self.next_code;
            if let Some(line) = self.panic_line.take() {
                // The step panics: the handler's register-free sequence, then `sys_reset`.
                self.safe_state_log.clear();
                enter_safe_state(
                    &mut ChipOutputs {
                        switch_closed: &mut self.switch_closed,
                        dac_code: &mut self.dac_code,
                        uninit: &mut self.uninit,
                        log: &mut self.safe_state_log,
                    },
                    ResetReason::Panic,
                    line,
                );
                self.enter_reset();
            } else {
                let swap = self.links.config.pending();
                let s = self.core.step(&self.links, raw);
                let cycles = ISR_CYCLES + if swap { SWAP_CYCLES } else { 0 };
                self.core.finish(&self.links, cycles, false);
                self.links.status.record_write_ticks(WRITE_TICKS);
                self.next_code = s.dac;
            }
        }
        let amp_in_v = if self.switch_closed {
            self.dac_code.volts()
        } else {
            0.0
        };
        self.stage.step(amp_in_v);
        self.amp_in_v = amp_in_v;
        self.trace.push(Trace {
            t_s: t,
            amp_in_v,
            switch_closed: self.switch_closed,
            faults: self.links.status.faults.load(Ordering::Relaxed),
        });
        let dt = 1.0 / self.rate_hz;
        self.n += 1;
        self.time_s += dt;
        self.io.clock.0.set((self.time_s * 1e9).round() as u64);
        if self.halted {
            if self.time_s >= self.boot_at_s {
                self.reboot();
            }
            return;
        }
        // Boot step 5: the switch closes and the tasks start once the loop runs.
        if !self.tasks_started && t >= self.boot_t_s + BOOT_LOOP_TO_TASKS_S {
            self.tasks_started = true;
            self.switch_closed = true;
        }
        if self.tasks_started {
            let led = self.io.led.0.get();
            poll_task(&mut self.tasks.command);
            self.follow_rate();
            if self.heartbeat_alive {
                poll_task(&mut self.tasks.heartbeat);
            }
            poll_task(&mut self.tasks.supervisor);
            if self.io.led.0.get() != led {
                self.led_toggles.push(self.time_s);
            }
            if self.io.fault_led.0.get() {
                self.fault_led_samples += 1;
            }
        }
        // The line drains at the baud rate (10 bits a byte).
        self.tx_credit += f64::from(UART_BAUD) / 10.0 * dt;
        {
            let mut line = self.io.uart.0.borrow_mut();
            while self.tx_credit >= 1.0 {
                match line.tx.pop_front() {
                    Some(b) => {
                        self.host_rx.push(b);
                        self.host_rx_total += 1;
                        self.tx_credit -= 1.0;
                    }
                    None => {
                        self.tx_credit = self.tx_credit.min(1.0);
                        break;
                    }
                }
            }
        }
        let iwdg = self.io.iwdg.get();
        if iwdg.running
            && self.io.clock.now_ns().saturating_sub(iwdg.last_feed_ns) as f64 * 1e-9
                > IWDG_TIMEOUT_S
        {
            self.iwdg_reset();
        }
    }

    /// The IWDG bites: the RCC flag is set and the chip resets (the switch opens), then
    /// boots again.
    fn iwdg_reset(&mut self) {
        self.iwdg_resets += 1;
        self.iwdg_flag = true;
        self.enter_reset();
    }

    fn run_s(&mut self, seconds: f64) {
        let end = self.n + (seconds * self.rate_hz).round() as u64;
        while self.n < end {
            self.tick();
        }
    }

    /// Sends a line as the host would and runs until its reply line arrives.
    fn command(&mut self, line: &str) -> String {
        self.host_send(line);
        self.reply(line)
    }

    /// Runs until a reply line arrives (at most 1 s); `line` names the command it answers.
    /// The boot's greeting is not a reply: it is counted and skipped.
    fn reply(&mut self, line: &str) -> String {
        for _ in 0..(self.rate_hz as u64) {
            self.tick();
            while let Some(p) = self.host_rx.windows(2).position(|w| w == b"\r\n") {
                let reply: Vec<u8> = self.host_rx.drain(..p + 2).collect();
                if reply == tasks::GREETING {
                    self.greetings += 1;
                    continue;
                }
                return String::from_utf8_lossy(&reply[..p]).into_owned();
            }
        }
        panic!("no reply to {line:?} within 1 s");
    }

    fn host_send(&mut self, line: &str) {
        let mut l = self.io.uart.0.borrow_mut();
        for &b in line.as_bytes().iter().chain(b"\n") {
            if l.rx.len() < UART_RX_BYTES {
                l.rx.push_back(b);
            } else {
                l.rx_overflow += 1;
            }
        }
    }

    fn rx_overflow(&self) -> u32 {
        self.io.uart.0.borrow().rx_overflow
    }

    /// Bytes waiting in the board's TX buffer (an upload keeps it filled).
    fn tx_pending(&self) -> usize {
        self.io.uart.0.borrow().tx.len()
    }

    fn faults(&self) -> Faults {
        Faults(self.links.status.faults.load(Ordering::Relaxed))
    }
}

/// `piezo record`'s link: lines go into the board's RX, `recv` runs simulated time until
/// bytes come out (or the timeout passes in simulated time).
impl Link for VirtualBoard {
    fn send_line(&mut self, line: &str) -> anyhow::Result<()> {
        self.host_send(line);
        Ok(())
    }
    fn recv(&mut self, timeout: Duration) -> anyhow::Result<Vec<u8>> {
        let samples = (timeout.as_secs_f64() * self.rate_hz) as u64;
        for _ in 0..samples.max(1) {
            self.tick();
            if !self.host_rx.is_empty() && self.tx_pending() == 0 || self.host_rx.len() >= 4096 {
                break;
            }
        }
        Ok(std::mem::take(&mut self.host_rx))
    }
}

/// Boot, then closed loop on 5 V (sensor volts) settled: the common start of the fault tests.
fn closed_loop_at(level: &str) -> VirtualBoard {
    let mut vb = VirtualBoard::boot();
    vb.run_s(0.05);
    assert_eq!(vb.command(&format!("ref step {level}")), "ok ref");
    assert_eq!(vb.command("mode closed"), "ok mode closed");
    vb.run_s(0.3);
    assert!(vb.faults().is_empty(), "{:?}", vb.faults());
    vb
}

/// Time from `from_s` until the amplifier input is at the safe value (0 V) and stays there,
/// and the largest move per sample on the way.
fn time_to_safe(vb: &VirtualBoard, from_s: f64) -> (f64, f32) {
    let after: Vec<&Trace> = vb.trace.iter().filter(|s| s.t_s >= from_s).collect();
    let settled = after
        .iter()
        .rposition(|s| s.amp_in_v != 0.0)
        .map_or(0, |i| i + 1);
    let t = after.get(settled).map_or(f64::INFINITY, |s| s.t_s - from_s);
    let max_step = after
        .windows(2)
        .map(|w| (w[1].amp_in_v - w[0].amp_in_v).abs())
        .fold(0.0f32, f32::max);
    (t, max_step)
}

#[test]
fn boot_closed_loop_reference_capture_and_upload_for_ten_seconds() {
    let mut vb = VirtualBoard::boot();
    vb.run_s(0.05);
    let st = vb.command("status");
    assert!(st.starts_with("ok mode=safe"), "{st}");
    assert!(st.contains("last_reset=power_on"), "{st}");
    assert_eq!(vb.command("ref step 5v"), "ok ref");
    assert_eq!(vb.command("mode closed"), "ok mode closed");
    vb.run_s(2.0);
    assert_eq!(vb.command("ref step 6um"), "ok ref");
    vb.run_s(2.0);
    assert_eq!(vb.command("ref sine 5v 2v 10hz"), "ok ref");
    vb.run_s(1.0);
    // A capture fetched by `piezo record`'s own code over the simulated line.
    let opts = Options {
        timeout: Duration::from_secs(5),
        retries: 2,
        poll: Duration::ZERO,
    };
    let t_rec = vb.t_s();
    let rec = record(&mut vb, 0.2, &opts).expect("piezo record completes");
    let upload_s = vb.t_s() - t_rec;
    assert_eq!(rec.records.len(), 10_000);
    assert_eq!(rec.rate_hz, 50_000);
    let worst_err_v = rec
        .records
        .iter()
        .map(|r| (AdcCode(r.r).volts() - AdcCode(r.y).volts()).abs())
        .fold(0.0f32, f32::max);
    assert!(rec.records.iter().all(|r| r.faults == 0));
    let remaining = 10.5 - vb.t_s();
    vb.run_s(remaining);
    let st = vb.command("status");
    assert!(st.contains("faults=0x00"), "{st}");
    assert!(st.contains("dac_latency_max_us=22.38"), "{st}");
    assert!(vb.faults().is_empty());
    assert_eq!(vb.iwdg_resets, 0);
    assert_eq!(vb.rx_overflow(), 0);
    // The tasks' own bodies: one greeting, the green LED at its half period (to a sample),
    // the red one dark, the supervisor's verdict never left `Feed`.
    assert_eq!(vb.greetings, 1);
    let half_periods: Vec<f64> = vb.led_toggles.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(half_periods.len() >= 40, "{}", half_periods.len());
    assert!(
        half_periods
            .iter()
            .all(|p| (p - HEARTBEAT_HALF_PERIOD_S).abs() <= 1.5 / vb.rate_hz),
        "{half_periods:?}"
    );
    assert_eq!(vb.fault_led_samples, 0);
    assert!(
        vb.io.verdicts.borrow().is_empty(),
        "{:?}",
        vb.io.verdicts.borrow()
    );
    let samples = vb.n;
    println!(
        "virtual board: {:.2} s simulated ({samples} samples at {} Hz), faults 0x{:02x}, IWDG resets {}, capture 10000 records via piezo record in {upload_s:.2} s of line time, worst |r - y| in the 10 Hz sine capture {:.1} mV, status: {st}",
        vb.t_s(),
        vb.rate_hz,
        vb.faults().0,
        vb.iwdg_resets,
        worst_err_v * 1e3,
    );
    assert!(vb.t_s() >= 10.0);
}

#[test]
fn unplugged_sensor_latches_and_ramps_to_safe() {
    let mut vb = closed_loop_at("5v");
    let t0 = vb.t_s();
    vb.sensor = Sensor::Open;
    vb.run_s(0.05);
    let (t, step) = time_to_safe(&vb, t0);
    let f = vb.faults();
    println!(
        "unplugged sensor: faults {f:?}, safe output after {:.2} ms, largest move {:.1} mV/sample",
        t * 1e3,
        step * 1e3
    );
    assert!(f.contains(Faults::SENSOR_RANGE));
    let ramp_step = (params::SAFE_RAMP_INPUT_V_PER_S / params::SAMPLE_RATE_HZ) as f32;
    // The ramp's step plus one DAC LSB of quantisation.
    assert!(
        step <= ramp_step + model_core::DacCode::VOLT_PER_LSB + 1e-6,
        "{step}"
    );
    // From about 6.3 V at 1 V/ms: 6.3 ms, plus the detection sample.
    assert!(t < 0.008, "{t}");
}

#[test]
fn stuck_sensor_with_three_lsb_of_noise_latches() {
    let mut vb = closed_loop_at("5v");
    let code = AdcCode::from_volts(5.0).0;
    vb.sensor = Sensor::Stuck { code, noise_lsb: 3 };
    vb.run_s(0.02);
    assert!(vb.faults().is_empty(), "at the set-point nothing moves yet");
    let t0 = vb.t_s();
    assert_eq!(vb.command("ref step 7v"), "ok ref");
    vb.run_s(0.05);
    let f = vb.faults();
    let latched = vb
        .trace
        .iter()
        .find(|s| s.t_s >= t0 && s.faults != 0)
        .map(|s| s.t_s - t0);
    let (t, step) = time_to_safe(&vb, t0);
    println!(
        "stuck sensor (+-3 LSB): faults {f:?} after {:.2} ms, safe output {:.2} ms after the move, largest move {:.1} mV/sample",
        latched.unwrap_or(f64::NAN) * 1e3,
        t * 1e3,
        step * 1e3
    );
    assert!(f.contains(Faults::SENSOR_STUCK));
    assert!(latched.unwrap() < 0.012);
}

#[test]
fn over_range_sensor_latches_at_once() {
    let mut vb = closed_loop_at("5v");
    let t0 = vb.t_s();
    vb.sensor = Sensor::OverRange;
    vb.run_s(0.02);
    let (t, _) = time_to_safe(&vb, t0);
    println!("over-range: safe output after {:.2} ms", t * 1e3);
    assert!(vb.faults().contains(Faults::SENSOR_RANGE));
    assert!(t < 0.008);
}

#[test]
fn nan_reference_latches_nonfinite() {
    let mut vb = closed_loop_at("5v");
    let t0 = vb.t_s();
    // The parser refuses "nan"; a corrupted configuration is the only way in: post one.
    let mut cfg = *vb.core.config.get();
    cfg.reference_v = f32::NAN;
    assert!(vb.links.config.post(cfg));
    vb.run_s(0.02);
    let (t, _) = time_to_safe(&vb, t0);
    println!("NaN reference: safe output after {:.2} ms", t * 1e3);
    assert!(vb.faults().contains(Faults::NONFINITE));
    assert!(t < 0.008);
}

#[test]
fn stalled_task_raises_watchdog_ramps_to_safe_then_the_iwdg_resets() {
    let mut vb = closed_loop_at("5v");
    let t0 = vb.t_s();
    vb.heartbeat_alive = false;
    vb.run_s(0.3);
    let raised = vb
        .trace
        .iter()
        .find(|s| s.t_s >= t0 && Faults(s.faults).contains(Faults::WATCHDOG))
        .map(|s| s.t_s - t0)
        .expect("WATCHDOG raised");
    let (t, step) = time_to_safe(&vb, t0);
    println!(
        "stalled heartbeat: WATCHDOG after {:.1} ms, safe output after {:.1} ms (ramp, largest move {:.1} mV), IWDG resets {}",
        raised * 1e3,
        t * 1e3,
        step * 1e3,
        vb.iwdg_resets
    );
    assert!(raised <= 0.05 + SUPERVISOR_PERIOD_S + TASK_CHECK_IN_S);
    let ramp_step = (params::SAFE_RAMP_INPUT_V_PER_S / params::SAMPLE_RATE_HZ) as f32;
    assert!(
        step <= ramp_step + model_core::DacCode::VOLT_PER_LSB + 1e-6,
        "ramped, not stepped: {step}"
    );
    assert_eq!(vb.iwdg_resets, 1, "then the IWDG resets the chip");
    // The supervisor task logged the stall once (the heartbeat's bit missing), and the command
    // task's check-ins alone did not feed the IWDG.
    let stalls: Vec<Verdict> = vb.io.verdicts.borrow().iter().map(|(_, v)| *v).collect();
    assert_eq!(
        stalls,
        [Verdict::TasksStalled {
            missing: firmware::liveness::TASK_HEARTBEAT
        }],
        "{stalls:?}"
    );
    back_in_safe_after_the_watchdog(&mut vb, "stalled heartbeat");
}

/// After an IWDG reset: the board boots again in safe mode with `last_reset=watchdog` and
/// WATCHDOG latched (`hw/mod.rs`), the output at the safe value; over the next second no
/// other fault, no second reset; `clear` leaves it fault-free.
fn back_in_safe_after_the_watchdog(vb: &mut VirtualBoard, what: &str) {
    assert_eq!(vb.boots, 2, "{what}: rebooted once");
    let st = vb.command("status");
    assert_eq!(
        vb.greetings, 2,
        "{what}: the command task greets after the reboot"
    );
    assert!(st.starts_with("ok mode=safe"), "{what}: {st}");
    assert_eq!(field(&st, "last_reset"), "watchdog", "{st}");
    assert_eq!(
        field(&st, "faults"),
        "0x10",
        "WATCHDOG latched at boot: {st}"
    );
    let t0 = vb.t_s();
    vb.run_s(1.0);
    let after: Vec<&Trace> = vb.trace.iter().filter(|s| s.t_s >= t0).collect();
    let other_faults = after
        .iter()
        .map(|s| s.faults & !Faults::WATCHDOG.0)
        .fold(0, |a, b| a | b);
    let max_out = after
        .iter()
        .map(|s| s.amp_in_v.abs())
        .fold(0.0f32, f32::max);
    assert_eq!(
        other_faults, 0,
        "{what}: no other fault in the second after"
    );
    assert_eq!(vb.iwdg_resets, 1, "{what}: no second reset");
    assert!(
        after.last().is_some_and(|s| s.switch_closed),
        "{what}: switch closed again"
    );
    assert_eq!(max_out, 0.0, "{what}: the output stays at the safe value");
    assert_eq!(vb.command("clear"), "ok cleared");
    vb.run_s(0.1);
    let st = vb.command("status");
    assert_eq!(field(&st, "faults"), "0x00", "{st}");
    assert!(
        vb.fault_led_samples > 0,
        "{what}: the red LED showed the latched fault"
    );
    println!(
        "{what}: rebooted in safe mode, last_reset=watchdog, 1 s with no other fault and no second reset, output {max_out} V; after clear: faults 0x00"
    );
}

#[test]
fn stalled_interrupt_is_reset_by_the_iwdg() {
    let mut vb = closed_loop_at("5v");
    let t0 = vb.t_s();
    vb.isr_alive = false;
    vb.run_s(0.3);
    let (t, step) = time_to_safe(&vb, t0);
    println!(
        "stalled interrupt: IWDG reset, output switch open after {:.1} ms (a step of {:.2} V: nothing in software can ramp without the interrupt)",
        t * 1e3,
        step
    );
    assert_eq!(vb.iwdg_resets, 1);
    assert!(t <= IWDG_TIMEOUT_S + SUPERVISOR_PERIOD_S + 1e-3, "{t}");
    back_in_safe_after_the_watchdog(&mut vb, "stalled interrupt");
}

/// Issue 13 item 1, the panic path: the handler's register-free sequence
/// (`reset_reason::enter_safe_state`, the one `hw::safe_state` runs) on a panic in the
/// interrupt: the switch opens within the sample, then the DAC gets the safe code, the reason
/// goes to `.uninit`; after the reset the board boots in safe mode and `status` names the
/// panic and its line. While the switch is closed the output never moves by more than the
/// safe ramp's step.
#[test]
fn a_panic_opens_the_switch_keeps_the_reason_and_the_board_reboots_safe() {
    const LINE: u32 = 4242;
    let mut vb = closed_loop_at("5v");
    let before = vb.trace.last().copied().expect("a trace");
    assert!(before.switch_closed && before.amp_in_v > 4.0, "{before:?}");
    let t0 = vb.t_s();
    vb.panic_line = Some(LINE);
    vb.tick();
    let at = vb.trace.last().copied().expect("a trace");
    println!(
        "panic at {:.4} s: sequence {:?}, output {:.3} V -> {:.3} V in the panic's sample, DAC holds {:.3} V, .uninit {:x?}",
        t0,
        vb.safe_state_log,
        before.amp_in_v,
        at.amp_in_v,
        vb.dac_code.volts(),
        vb.uninit
    );
    assert_eq!(vb.safe_state_log, ["mask", "switch", "dac", "record"]);
    assert!(
        !at.switch_closed && at.amp_in_v == 0.0,
        "switch open within the sample"
    );
    assert_eq!(
        vb.dac_code,
        DacCode::from_volts(params::SAFE_OUTPUT_V as f32)
    );
    assert_eq!(vb.uninit.decode(), Some((ResetReason::Panic, LINE)));
    vb.run_s(0.5);
    assert_eq!(vb.boots, 2, "rebooted");
    let st = vb.command("status");
    println!("after the reboot: {st}");
    assert!(st.starts_with("ok mode=safe"), "{st}");
    assert_eq!(field(&st, "last_reset"), "panic", "{st}");
    assert_eq!(field(&st, "detail"), format!("0x{LINE:x}"), "{st}");
    assert_eq!(field(&st, "faults"), "0x10", "WATCHDOG latched: {st}");
    assert_eq!(vb.uninit, ResetRecord::default(), "the record was taken");
    // The trajectory from the panic on: while the switch is closed (before the panic and
    // after the reboot), no move beyond the safe ramp's step plus one DAC LSB.
    let ramp_step = (params::SAFE_RAMP_INPUT_V_PER_S / params::SAMPLE_RATE_HZ) as f32;
    let after: Vec<&Trace> = vb.trace.iter().filter(|s| s.t_s >= t0).collect();
    let worst = after
        .windows(2)
        .filter(|w| w[0].switch_closed && w[1].switch_closed)
        .map(|w| (w[1].amp_in_v - w[0].amp_in_v).abs())
        .fold(0.0f32, f32::max);
    let closed_again = after
        .iter()
        .find(|s| s.switch_closed)
        .map(|s| s.t_s - t0)
        .expect("the switch closes after the reboot");
    println!(
        "panic: switch closed again {:.1} ms after the panic at {:.3} V, largest move while closed {:.1} mV/sample",
        closed_again * 1e3,
        after
            .iter()
            .find(|s| s.switch_closed)
            .map_or(f32::NAN, |s| s.amp_in_v),
        worst * 1e3
    );
    assert!(worst <= ramp_step + DacCode::VOLT_PER_LSB + 1e-6, "{worst}");
    assert_eq!(vb.command("clear"), "ok cleared");
    let st = vb.command("status");
    assert_eq!(field(&st, "faults"), "0x00", "{st}");
}

/// Issue 13 item 1, the configuration swap at 200 kHz: with `rate 200khz` and a `kc` change
/// in closed loop, the interrupt takes the new configuration at its next sample as an index
/// swap (the value in force lies in the mailbox's slot: no copy), so with the real budget
/// (`app::apply_rate_limits` at 200 kHz) no OVERRUN is raised. A copy of the configuration in
/// the interrupt, as before, would not fit the budget.
#[test]
fn a_configuration_swap_at_200_khz_is_an_index_swap_without_overrun() {
    let mut vb = VirtualBoard::boot();
    vb.run_s(0.05);
    assert_eq!(vb.command("rate 200khz"), "ok rate_hz 200000.000");
    assert_eq!(vb.rate_hz, 200_000.0);
    assert_eq!(vb.command("ref step 5v"), "ok ref");
    assert_eq!(vb.command("mode closed"), "ok mode closed");
    vb.run_s(0.2);
    assert!(vb.faults().is_empty(), "{:?}", vb.faults());
    let budget = vb.links.budget_cycles.load(Ordering::Relaxed);
    vb.host_send("kc 5000");
    let mut posted_at = None;
    for _ in 0..(0.1 * vb.rate_hz) as u32 {
        vb.tick();
        if vb.links.config.pending() {
            posted_at = Some(vb.n);
            break;
        }
    }
    let posted_at = posted_at.expect("the kc change posted");
    // What the command task builds for `kc 5000` at this rate (a step reference does not enter
    // the controller).
    let want = Settings {
        kc: 5000.0,
        rate_hz: vb.rate_hz,
        ..Settings::default()
    }
    .loop_config()
    .expect("the new settings")
    .controller;
    assert_ne!(
        vb.core.config.get().controller,
        want,
        "not in force before the next sample"
    );
    vb.tick();
    let in_force = vb.core.config.get();
    assert_eq!(in_force.controller, want, "in force at the next sample");
    assert!(
        vb.links.config.holds(in_force),
        "used in its mailbox slot, not copied"
    );
    assert_eq!(vb.n - posted_at, 1);
    assert_eq!(vb.reply("kc 5000"), "ok kc 5000");
    vb.run_s(0.1);
    let st = vb.command("status");
    let copy_cycles = (std::mem::size_of::<LoopConfig>() as f64 * COPY_CYCLES_PER_BYTE) as u32;
    println!(
        "200 kHz swap: taken 1 sample after the post, budget {budget} cycles, the swap's sample {} cycles (a copy of the {} B configuration would be {} cycles); {st}",
        ISR_CYCLES + SWAP_CYCLES,
        std::mem::size_of::<LoopConfig>(),
        ISR_CYCLES + copy_cycles,
    );
    assert_eq!(
        budget, 1_200,
        "5 us at 400 MHz less the 2 us conversion allowance"
    );
    assert_eq!(field(&st, "overruns"), "0", "{st}");
    assert_eq!(field(&st, "faults"), "0x00", "{st}");
    assert!(
        ISR_CYCLES + copy_cycles > budget,
        "a copy in the interrupt would overrun"
    );
}

#[test]
fn mode_safe_during_an_upload_is_applied_within_a_frame() {
    let mut vb = closed_loop_at("5v");
    assert_eq!(vb.command("capture 1s"), "ok capture armed 50000");
    vb.run_s(1.01);
    assert!(vb.command("capture status").starts_with("ok capture done"));
    vb.host_send("capture send");
    vb.run_s(0.5); // 46 kB of the 400 kB upload (4.6 s at 921 600 baud)
    assert!(vb.tx_pending() > 0, "the upload is running");
    let t0 = vb.t_s();
    vb.host_send("mode safe");
    let mut applied = None;
    for _ in 0..50_000 {
        vb.tick();
        if vb.links.status.mode() == Some(model_core::controller::Mode::Safe) {
            applied = Some(vb.t_s() - t0);
            break;
        }
    }
    let applied = applied.expect("mode safe applied during the upload");
    vb.run_s(0.02);
    let (t, step) = time_to_safe(&vb, t0);
    println!(
        "mode safe during an upload: applied after {:.2} ms, safe output after {:.2} ms (largest move {:.1} mV), upload still running: {}",
        applied * 1e3,
        t * 1e3,
        step * 1e3,
        vb.tx_pending() > 0
    );
    assert!(applied < 0.005, "{applied}");
    assert_eq!(vb.rx_overflow(), 0);
}

/// Issue 13 item 6: the DAC frame at a fixed instant costs one sample of delay. Its effect on
/// the thesis loop's margins, measured with the host harness (`piezo loop`'s analysis) on the
/// loop the board runs: the plant's 85 us plus one period.
#[test]
fn dac_at_a_fixed_instant_keeps_the_margins() {
    use host_tests::sim::analysis::{LoopSetup, loop_figures};
    let base = LoopSetup::thesis(params::SAMPLE_RATE_HZ, params::LAG_KC);
    let mut fixed = base;
    fixed.plant.delay_s += 1.0 / params::SAMPLE_RATE_HZ;
    let a = loop_figures(&base).unwrap();
    let b = loop_figures(&fixed).unwrap();
    let (gm0, pm0) = (a.gain_margin_db.unwrap(), a.phase_margin_deg.unwrap());
    let (gm1, pm1) = (b.gain_margin_db.unwrap(), b.phase_margin_deg.unwrap());
    println!(
        "DAC at a fixed instant (+20 us): gain margin {gm0:.2} -> {gm1:.2} dB, phase margin {pm0:.1} -> {pm1:.1} deg, bandwidth {:.0} -> {:.0} Hz, overshoot {:.1} -> {:.1} %",
        a.bandwidth_hz.unwrap_or(f64::NAN),
        b.bandwidth_hz.unwrap_or(f64::NAN),
        a.step_overshoot_pct.unwrap_or(f64::NAN),
        b.step_overshoot_pct.unwrap_or(f64::NAN),
    );
    // Our acceptance (issue 13): at least 6 dB and 45 deg remain.
    assert!(gm1 > 6.0 && pm1 > 45.0, "{gm1} {pm1}");
}

/// The board's sample of computational delay is in its pre-filter's model of the loop
/// (`design_parameters::COMPUTATIONAL_DELAY_SAMPLES`, `Settings::controller_config`): on a
/// stage whose loop has that sample more than eq. 4.4's 85 us, 6 V periodic steps through the
/// board's own `Controller::step` (the tracking harness, pre-filter on) overshoot by no more
/// than the 2 % the thesis' design promises; the thesis' pre-filter, blind to the extra
/// sample, is printed beside it.
#[test]
fn the_pre_filter_covers_the_boards_computational_delay() {
    use host_tests::sim::tracking::{TrackShape, TrackSpec, simulate};
    use model_core::prefilter::PreFilterMode;
    let board = firmware::settings::Settings::default().controller_config();
    let rate_hz = params::SAMPLE_RATE_HZ;
    let extra_s = f64::from(firmware::design_parameters::COMPUTATIONAL_DELAY_SAMPLES) / rate_hz;
    let overshoot = |plant: model_core::plant::LinearPlantConfig| {
        let mut spec = TrackSpec::new(TrackShape::Step, 20.0, 3.0, 4.0, PreFilterMode::Full);
        spec.lag = board.lag;
        spec.plant = plant;
        spec.stage.delay_s += extra_s;
        simulate(&spec, true).unwrap().overshoot_pct(1.0, 7.0)
    };
    let with = overshoot(board.plant);
    let blind = overshoot(model_core::plant::LinearPlantConfig::default());
    println!(
        "6 V steps, one more sample of loop delay: overshoot {with:.2} % with the board's pre-filter, {blind:.2} % with the thesis' (delay {:.0} us against {:.0} us)",
        1e6 * board.plant.delay_s,
        1e6 * model_core::plant::LinearPlantConfig::default().delay_s
    );
    assert!(
        (board.plant.delay_s - model_core::plant::LinearPlantConfig::default().delay_s - extra_s)
            .abs()
            < 1e-12
    );
    assert!(with <= 2.0, "overshoot {with:.2} %");
}

/// Bring-up: `selftest` over the loopback cable (output stage -> front end, amplifier
/// disconnected) measures gain, offset, noise, latency and interrupt time and passes; with
/// the cable unplugged it fails.
#[test]
fn selftest_passes_on_the_loopback_cable_and_fails_without_it() {
    for (sensor, expect) in [(Sensor::Loopback, "pass"), (Sensor::Open, "fail")] {
        let mut vb = VirtualBoard::boot();
        vb.sensor = Sensor::Loopback;
        vb.run_s(0.05);
        vb.sensor = sensor;
        if sensor == Sensor::Open {
            // The open input latches SENSOR_RANGE at once: selftest refuses to start.
            vb.run_s(0.01);
            let r = vb.command("selftest");
            println!("selftest, cable unplugged: {r}");
            assert!(
                r.starts_with("err selftest runs from safe mode without faults"),
                "{r}"
            );
            continue;
        }
        let r = vb.command("selftest");
        assert!(r.starts_with("ok selftest running"), "{r}");
        let mut reply = None;
        for _ in 0..(0.5 * vb.rate_hz) as u32 {
            vb.tick();
            if let Some(p) = vb.host_rx.windows(2).position(|w| w == b"\r\n") {
                let line: Vec<u8> = vb.host_rx.drain(..p + 2).collect();
                reply = Some(String::from_utf8_lossy(&line[..p]).into_owned());
                break;
            }
        }
        let reply = reply.expect("selftest reports within 0.5 s");
        println!("selftest, loopback cable: {reply}");
        assert!(
            reply.starts_with(&format!("ok selftest {expect}")),
            "{reply}"
        );
        let st = vb.command("status");
        assert!(st.contains("mode=safe"), "back to safe: {st}");
    }
}

/// The value of `key=` in a `status` line.
fn field<'a>(status: &'a str, key: &str) -> &'a str {
    let pat = format!(" {key}=");
    let start = status
        .find(&pat)
        .unwrap_or_else(|| panic!("no {key} in {status}"))
        + pat.len();
    status[start..].split(' ').next().unwrap_or("")
}

/// Issue 14 item 3 on the virtual board: `learn on` over a 100 Hz sine (6 V p-p around 4 V,
/// the design note's case of `model_core::learning`) on the thesis-full stage cuts the
/// repeat's RMS error (`r - y` as the board measures it) by at least
/// [`LEARN_MIN_IMPROVEMENT`] within [`LEARN_REPEATS`] repeats, without a fault and without
/// tripping the growth flag; `learn reset` clears the table (the error comes back); a fault
/// while learning stops it (no more updates, no correction).
#[test]
fn learning_a_100_hz_sine_cuts_the_error_reset_clears_and_a_fault_stops_it() {
    /// Repeats of the 100 Hz sine (10 ms each) with learning on.
    const LEARN_REPEATS: u32 = 80;
    /// Least ratio of the first learning repeat's RMS error to the last one's (our
    /// acceptance; the host harness reaches about 150 in 30 updates without the board's
    /// extra sample of delay).
    const LEARN_MIN_IMPROVEMENT: f32 = 10.0;
    let period_s = 0.01;
    let mut vb = VirtualBoard::boot();
    vb.run_s(0.05);
    assert_eq!(vb.command("ref sine 4v 3v 100hz"), "ok ref");
    assert_eq!(vb.command("mode closed"), "ok mode closed");
    vb.run_s(0.3);
    let st = vb.command("status");
    assert_eq!(field(&st, "learn"), "off", "{st}");
    assert_eq!(vb.command("learn on"), "ok learn on period_samples=500");
    let mut history = vec![];
    for _ in 0..LEARN_REPEATS {
        vb.run_s(period_s);
        let st = vb.command("status");
        let iter: u32 = field(&st, "learn_iter").parse().unwrap();
        let rms: f32 = field(&st, "learn_rms_v").parse().unwrap();
        assert_eq!(field(&st, "learn"), "learning", "{st}");
        assert_eq!(field(&st, "faults"), "0x00", "{st}");
        history.push((iter, rms));
    }
    let first = history
        .iter()
        .find(|h| h.1 > 0.0)
        .expect("a repeat handed over")
        .1;
    let (iters, last) = *history.last().unwrap();
    println!(
        "learning, 100 Hz sine 6 V p-p on thesis-full: RMS error of the repeat {:.2} mV before the first update, {:.3} mV after {iters} updates ({LEARN_REPEATS} repeats): {:.0}x; dropped repeats {}; trajectory (iteration, mV): {:?}",
        first * 1e3,
        last * 1e3,
        first / last,
        vb.learn.dropped(),
        history
            .iter()
            .step_by(8)
            .map(|h| (h.0, (h.1 * 1e4).round() / 10.0))
            .collect::<Vec<_>>()
    );
    assert!(first / last >= LEARN_MIN_IMPROVEMENT, "{first} -> {last}");
    assert!(
        iters >= LEARN_REPEATS / 3,
        "an update every few repeats: {iters}"
    );
    assert!(vb.faults().is_empty());

    // `learn reset`: iteration 0 and the zero table from the next repeat: the error returns.
    assert_eq!(vb.command("learn reset"), "ok learn reset (learning)");
    let st = vb.command("status");
    assert_eq!(field(&st, "learn_iter"), "0", "{st}");
    vb.run_s(3.0 * period_s);
    let st = vb.command("status");
    let rms_after_reset: f32 = field(&st, "learn_rms_v").parse().unwrap();
    println!(
        "after learn reset: RMS error {:.2} mV ({st})",
        rms_after_reset * 1e3
    );
    assert!(
        rms_after_reset > 0.5 * first,
        "the cleared table leaves the unlearnt error: {rms_after_reset} vs {first}"
    );
    vb.run_s(10.0 * period_s);
    let st = vb.command("status");
    let iter_before_fault: u32 = field(&st, "learn_iter").parse().unwrap();
    assert!(
        iter_before_fault >= 1,
        "learning again after the reset: {st}"
    );

    // A fault while learning: learning stops, no more updates, the output ramps to safe.
    let t0 = vb.t_s();
    vb.sensor = Sensor::OverRange;
    vb.run_s(5.0 * period_s);
    let st = vb.command("status");
    println!("fault while learning: {st}");
    assert_eq!(field(&st, "learn"), "stopped:fault", "{st}");
    assert!(vb.faults().contains(Faults::SENSOR_RANGE));
    assert!(!vb.learn.enabled(), "no correction after the stop");
    let iter_at_stop: u32 = field(&st, "learn_iter").parse().unwrap();
    assert!(
        iter_at_stop <= iter_before_fault + 1,
        "{iter_before_fault} {iter_at_stop}"
    );
    vb.run_s(5.0 * period_s);
    let st = vb.command("status");
    assert_eq!(field(&st, "learn_iter"), iter_at_stop.to_string(), "{st}");
    let (t, _) = time_to_safe(&vb, t0);
    println!("fault while learning: safe output after {:.2} ms", t * 1e3);
    // From at most 7 V at 1 V/ms, plus the detection sample.
    assert!(t < 0.008, "{t}");
    assert_eq!(
        vb.command("learn on"),
        "err learn needs closed loop without faults"
    );
}

/// A new reference while learning stops it before the new configuration is posted (the
/// interrupt never adds the old table to the new trajectory), and `learn on` starts again
/// on the new repeat; `learn freeze` keeps the table in force without updates.
#[test]
fn a_new_reference_stops_learning_and_freeze_keeps_the_table() {
    let mut vb = VirtualBoard::boot();
    vb.run_s(0.05);
    assert_eq!(vb.command("ref triangle 4v 2v 100hz"), "ok ref");
    assert_eq!(vb.command("mode closed"), "ok mode closed");
    vb.run_s(0.3);
    assert_eq!(vb.command("learn on"), "ok learn on period_samples=500");
    vb.run_s(0.1);
    assert_eq!(vb.command("learn freeze"), "ok learn frozen");
    let st = vb.command("status");
    let frozen_iter = field(&st, "learn_iter").to_string();
    let frozen_rms: f32 = field(&st, "learn_rms_v").parse().unwrap();
    vb.run_s(0.05);
    let st = vb.command("status");
    println!("frozen: {st}");
    assert_eq!(field(&st, "learn"), "frozen:requested", "{st}");
    assert_eq!(
        field(&st, "learn_iter"),
        frozen_iter,
        "no update while frozen"
    );
    let rms: f32 = field(&st, "learn_rms_v").parse().unwrap();
    assert!(vb.learn.enabled(), "the table stays in force");
    assert!(rms < 2.0 * frozen_rms.max(2e-3), "{frozen_rms} -> {rms}");
    assert_eq!(vb.command("ref sine 4v 2v 50hz"), "ok ref");
    let st = vb.command("status");
    println!("after a new reference: {st}");
    assert_eq!(field(&st, "learn"), "stopped:reference_changed", "{st}");
    assert!(!vb.learn.enabled(), "no correction on the new reference");
    vb.run_s(0.1);
    assert!(vb.faults().is_empty());
    assert_eq!(vb.command("learn on"), "ok learn on period_samples=1000");
    vb.run_s(0.1);
    let st = vb.command("status");
    assert_eq!(field(&st, "learn"), "learning", "{st}");
    assert_eq!(vb.command("learn off"), "ok learn off");
    assert!(!vb.learn.enabled());
}
