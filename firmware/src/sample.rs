//! What the control interrupt does with one sample, without the registers: host-tested.
//!
//! The interrupt (`src/hw/control.rs`) reads the ADC, calls [`LoopCore::step`], writes the
//! returned code to the DAC, measures its own duration and calls [`LoopCore::finish`]. In
//! between, everything is here:
//!
//! 1. take a new [`LoopConfig`] if the command task posted one (the mailbox's
//!    [`Reader::update`]: an index swap, the configuration is used where it lies);
//! 2. apply the tasks' requests: mode, clear faults, raise faults ([`Requests`]);
//! 3. raise WATCHDOG if the tasks stopped checking in ([`Liveness::isr_tick`]);
//! 4. correct the ADC code, set the reference, read the learned correction at the
//!    generator's index ([`Recorder::correction`]: one load) and run
//!    `Controller::step_with_correction` (the one model-core function: modes, fault latch and
//!    safe ramp, compensator, limits; the correction is 0 unless `learn on`);
//! 5. record the sample's error for the learning ([`Recorder::record`]: one store) and, if a
//!    capture is running, the sample; publish the status ([`Status`]);
//! 6. after the DAC write: account the duration and raise OVERRUN if the sample was late.

use core::sync::atomic::{AtomicBool, AtomicU8, AtomicU32, Ordering};

use model_core::AdcCode;
use model_core::controller::{ControllerState, Faults, Mode, Sample};
use model_core::frame::Record;

use crate::capture::Producer;
use crate::learn::Recorder;
use crate::liveness::Liveness;
use crate::mailbox::{Mailbox, Reader};
use crate::settings::LoopConfig;
use crate::stats::{CycleStats, SharedStats};

/// "No request" in [`Requests::mode`].
pub const NO_MODE: u8 = 0xFF;

/// What the tasks ask of the interrupt; applied at its next sample.
#[derive(Debug)]
pub struct Requests {
    /// A mode ([`mode_to_u8`]) or [`NO_MODE`].
    pub mode: AtomicU8,
    /// Clear the latched faults.
    pub clear: AtomicBool,
    /// Fault bits to raise.
    pub raise: AtomicU8,
}

impl Default for Requests {
    fn default() -> Self {
        Self::new()
    }
}

impl Requests {
    /// No request (usable in a `static`).
    pub const fn new() -> Self {
        Self {
            mode: AtomicU8::new(NO_MODE),
            clear: AtomicBool::new(false),
            raise: AtomicU8::new(0),
        }
    }

    /// Asks for a mode.
    pub fn set_mode(&self, m: Mode) {
        self.mode.store(mode_to_u8(m), Ordering::Relaxed);
    }

    /// Asks to clear the faults.
    pub fn clear_faults(&self) {
        self.clear.store(true, Ordering::Relaxed);
    }

    /// Asks to raise faults.
    pub fn raise(&self, f: Faults) {
        self.raise.fetch_or(f.0, Ordering::Relaxed);
    }
}

/// Published by the interrupt after each sample (any context may read it).
#[derive(Debug, Default)]
pub struct Status {
    /// Present mode ([`mode_to_u8`]).
    pub mode: AtomicU8,
    /// Latched fault bits.
    pub faults: AtomicU8,
    /// Last ADC code (an i16 in the low half).
    pub y: AtomicU32,
    /// Last DAC code.
    pub u: AtomicU32,
    /// Last reference, as an ADC code.
    pub r: AtomicU32,
    /// Samples whose DAC frame was still in flight at the next sample.
    pub dac_late: AtomicU32,
    /// Largest time from the sampling instant (the timer's update) to the DAC write, in
    /// control-timer ticks, since the last `clear` (written by the interrupt, which reads the
    /// timer's counter right after the write).
    pub write_ticks_max: AtomicU32,
}

impl Status {
    /// Zeroed (usable in a `static`).
    pub const fn new() -> Self {
        Self {
            mode: AtomicU8::new(0),
            faults: AtomicU8::new(0),
            y: AtomicU32::new(0),
            u: AtomicU32::new(0),
            r: AtomicU32::new(0),
            dac_late: AtomicU32::new(0),
            write_ticks_max: AtomicU32::new(0),
        }
    }

    /// Records one sample's timer ticks from the sampling instant to the DAC write (interrupt
    /// side: the only writer apart from [`Status::clear_latency`]; no read-modify-write loop).
    #[inline]
    pub fn record_write_ticks(&self, ticks: u32) {
        if ticks > self.write_ticks_max.load(Ordering::Relaxed) {
            self.write_ticks_max.store(ticks, Ordering::Relaxed);
        }
    }

    /// Forgets the largest latency (task side, on `clear`).
    pub fn clear_latency(&self) {
        self.write_ticks_max.store(0, Ordering::Relaxed);
    }

    /// The published mode.
    pub fn mode(&self) -> Option<Mode> {
        mode_from_u8(self.mode.load(Ordering::Relaxed))
    }

    /// An i16 published in an `AtomicU32`.
    pub fn load_i16(a: &AtomicU32) -> i16 {
        a.load(Ordering::Relaxed) as u16 as i16
    }
}

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

/// The shared objects the interrupt talks to.
#[derive(Clone, Copy)]
pub struct Links<'a> {
    /// New configurations.
    pub config: &'a Mailbox<LoopConfig>,
    /// The tasks' requests.
    pub requests: &'a Requests,
    /// Watchdog liveness.
    pub liveness: &'a Liveness,
    /// Timing figures.
    pub stats: &'a SharedStats,
    /// Published status.
    pub status: &'a Status,
    /// Samples without task check-ins before WATCHDOG.
    pub stall_samples: &'a AtomicU32,
    /// Cycle budget per sample.
    pub budget_cycles: &'a AtomicU32,
}

/// Everything the interrupt owns, apart from the DAC.
pub struct LoopCore<const N: usize> {
    /// The active configuration, in its mailbox slot ([`Reader::get`]).
    pub config: Reader<'static, LoopConfig>,
    /// The controller's state.
    pub state: ControllerState,
    /// Timing accumulator.
    pub stats: CycleStats,
    /// The right to record.
    pub capture: Producer<N>,
    /// The learning's side in the interrupt (`learn on`).
    pub learn: Recorder,
}

impl<const N: usize> LoopCore<N> {
    /// Steps 1-5 of the module note for the raw ADC result `raw`; returns the sample whose
    /// `dac` code goes out.
    #[inline]
    pub fn step(&mut self, links: &Links<'_>, raw: u32) -> Sample {
        if self.config.update()
            && self.config.get().restart
            && self.state.mode() == Mode::ClosedLoop
        {
            // Re-enter closed loop at the next step: generator from its start, pre-filter
            // settled, compensator bumpless (model-core's entering logic).
            self.state.set_mode(Mode::Hold);
            self.state.set_mode(Mode::ClosedLoop);
        }
        let req = links.requests;
        if let Some(mode) = mode_from_u8(req.mode.swap(NO_MODE, Ordering::Relaxed)) {
            self.state.set_mode(mode);
        }
        if req.clear.swap(false, Ordering::Relaxed) {
            self.state.clear_faults();
        }
        let raise = req.raise.swap(0, Ordering::Relaxed);
        if raise != 0 {
            self.state.raise(Faults(raise));
        }
        if links
            .liveness
            .isr_tick(links.stall_samples.load(Ordering::Relaxed))
        {
            self.state.raise(Faults::WATCHDOG);
        }
        let cfg = self.config.get();
        let y = cfg.adc_cal.apply(raw);
        self.state.set_reference(cfg.reference_v);
        let controller = &cfg.controller;
        let index = controller.reference_index(&self.state);
        let correction_v = self.learn.correction(index);
        let s = controller.step_with_correction(&mut self.state, y, correction_v);
        self.learn
            .record(index, &s, self.state.mode() == Mode::ClosedLoop);
        let r = AdcCode::from_volts(s.reference_v).0;
        self.capture.push(Record {
            r,
            y: y.0,
            u: s.dac.value(),
            flags: s.flags.0,
            faults: s.faults.0,
        });
        let st = links.status;
        st.mode
            .store(mode_to_u8(self.state.mode()), Ordering::Relaxed);
        st.faults.store(s.faults.0, Ordering::Relaxed);
        st.y.store(y.0 as u16 as u32, Ordering::Relaxed);
        st.u.store(s.dac.value() as u16 as u32, Ordering::Relaxed);
        st.r.store(r as u16 as u32, Ordering::Relaxed);
        s
    }

    /// Step 6: the sample took `cycles`; `late` is the hardware's report of a missed or
    /// overtaken conversion. Returns true on an overrun (OVERRUN is then latched).
    #[inline]
    pub fn finish(&mut self, links: &Links<'_>, cycles: u32, late: bool) -> bool {
        self.stats
            .set_budget(links.budget_cycles.load(Ordering::Relaxed));
        let overrun = self.stats.record(cycles, late, links.stats);
        if overrun {
            self.state.raise(Faults::OVERRUN);
        }
        overrun
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::{CaptureBuffer, CaptureState};
    use crate::command::ReferenceRequest;
    use crate::liveness::REQUIRED_TASKS;
    use crate::settings::Settings;

    /// The raw ADC result of `volts` at the sensor, through the default calibration's inverse.
    fn raw_of(volts: f32, cfg: &LoopConfig) -> u32 {
        let nominal = (volts - cfg.adc_cal.offset_v) / cfg.adc_cal.gain;
        (AdcCode::from_volts(nominal).0 as u16 ^ 0x8000) as u32
    }

    struct World {
        mailbox: &'static Mailbox<LoopConfig>,
        requests: Requests,
        liveness: Liveness,
        stats: SharedStats,
        status: Status,
        stall: AtomicU32,
        budget: AtomicU32,
    }

    impl World {
        fn new(stall: u32) -> Self {
            Self {
                mailbox: Box::leak(Box::new(Mailbox::new())),
                requests: Requests::new(),
                liveness: Liveness::new(),
                stats: SharedStats::new(),
                status: Status::new(),
                stall: AtomicU32::new(stall),
                budget: AtomicU32::new(7200),
            }
        }
        fn links(&self) -> Links<'_> {
            Links {
                config: self.mailbox,
                requests: &self.requests,
                liveness: &self.liveness,
                stats: &self.stats,
                status: &self.status,
                stall_samples: &self.stall,
                budget_cycles: &self.budget,
            }
        }
    }

    fn core(buf: &'static CaptureBuffer<64>, w: &World) -> LoopCore<64> {
        let config = Settings::default().loop_config().unwrap();
        LoopCore {
            config: w.mailbox.reader(config).unwrap(),
            state: ControllerState::new(&config.controller),
            stats: CycleStats::new(7200),
            capture: buf.producer().unwrap(),
            learn: Box::leak(Box::new(crate::learn::LearnShared::new()))
                .recorder()
                .unwrap(),
        }
    }

    #[test]
    fn boots_safe_then_follows_requests_and_new_configs() {
        static BUF: CaptureBuffer<64> = CaptureBuffer::new();
        let w = World::new(u32::MAX);
        let links = w.links();
        let mut c = core(&BUF, &w);
        let raw = raw_of(2.0, c.config.get());
        let s = c.step(&links, raw);
        assert_eq!(s.command_v, 0.0, "boots at the safe value");
        assert_eq!(w.status.mode(), Some(Mode::Safe));
        // A new reference of 4 V arrives through the mailbox, then open loop is asked for.
        let cfg = Settings {
            reference: ReferenceRequest::Step { level_v: 4.0 },
            ..Settings::default()
        }
        .loop_config()
        .unwrap();
        assert!(w.mailbox.post(cfg));
        w.requests.set_mode(Mode::OpenLoop);
        let mut last = 0.0;
        for _ in 0..4 {
            let s = c.step(&links, raw);
            assert!((s.command_v - last).abs() <= 3.0 + 1e-5, "slew-limited");
            last = s.command_v;
        }
        println!(
            "open loop towards 4 V: command {last} V, measured {} V",
            Status::load_i16(&w.status.y) as f32 * AdcCode::VOLT_PER_LSB
        );
        assert!((last - 4.0).abs() < 1e-6);
        assert_eq!(w.status.mode(), Some(Mode::OpenLoop));
        let y = AdcCode(Status::load_i16(&w.status.y)).volts();
        assert!(
            (y - 2.0).abs() < 2.0 * AdcCode::VOLT_PER_LSB,
            "calibrated reading {y}"
        );
    }

    #[test]
    fn stalled_tasks_raise_watchdog_and_ramp_to_safe() {
        static BUF: CaptureBuffer<64> = CaptureBuffer::new();
        let w = World::new(100);
        let links = w.links();
        let mut c = core(&BUF, &w);
        let cfg = Settings {
            reference: ReferenceRequest::Step { level_v: 9.0 },
            ..Settings::default()
        }
        .loop_config()
        .unwrap();
        assert!(w.mailbox.post(cfg));
        w.requests.set_mode(Mode::OpenLoop);
        let raw = raw_of(5.0, c.config.get());
        let mut last = 0.0;
        let mut first_fault = None;
        let ramp = c.config.get().controller.safe_ramp_v_per_step();
        for n in 0..700 {
            // The tasks check in for the first 10 samples only.
            if n < 10 {
                w.liveness.check_in(REQUIRED_TASKS);
                let mut seen = 0;
                w.liveness.supervise(&mut seen, 0, 100);
            }
            let s = c.step(&links, raw);
            // Slew-limited before the fault, the safe ramp (1 V/ms) after it.
            let bound = if first_fault.is_some() { ramp } else { 3.0 };
            assert!(
                (s.command_v - last).abs() <= bound + 1e-5,
                "sample {n}: {last} -> {}",
                s.command_v
            );
            last = s.command_v;
            if s.faults.contains(Faults::WATCHDOG) && first_fault.is_none() {
                first_fault = Some(n);
            }
        }
        println!(
            "tasks silent after sample 9: WATCHDOG at sample {first_fault:?}, command now {last} V"
        );
        // Last complete round seen at sample count 9; the fault fires when the count exceeds
        // 9 + 100, i.e. in the 110th step (index 109).
        assert_eq!(first_fault, Some(109));
        assert_eq!(last, 0.0, "ramped to the safe value");
        // Latched until cleared.
        w.liveness.check_in(REQUIRED_TASKS);
        let mut seen = 0;
        w.liveness.supervise(&mut seen, 0, 100);
        assert!(c.step(&links, raw).faults.contains(Faults::WATCHDOG));
        w.requests.clear_faults();
        let s = c.step(&links, raw);
        assert!(s.faults.is_empty());
        assert_eq!(
            w.status.mode(),
            Some(Mode::Safe),
            "clearing returns to safe"
        );
    }

    #[test]
    fn overrun_latches_and_capture_records_what_was_sent() {
        static BUF: CaptureBuffer<64> = CaptureBuffer::new();
        let w = World::new(u32::MAX);
        let links = w.links();
        let mut c = core(&BUF, &w);
        let mut consumer = BUF.consumer().unwrap();
        consumer.arm(8).unwrap();
        let cfg = Settings {
            reference: ReferenceRequest::Step { level_v: 6.0 },
            ..Settings::default()
        }
        .loop_config()
        .unwrap();
        assert!(w.mailbox.post(cfg));
        w.requests.set_mode(Mode::OpenLoop);
        let raw = raw_of(1.0, c.config.get());
        let mut sent = vec![];
        for n in 0..8 {
            let s = c.step(&links, raw);
            sent.push(s.dac);
            let overrun = c.finish(&links, 1000, n == 5);
            assert_eq!(overrun, n == 5);
        }
        assert_eq!(BUF.state(), CaptureState::Done { len: 8 });
        let mut recs = [Record::default(); 8];
        consumer.read(0, &mut recs).unwrap();
        for (k, (r, d)) in recs.iter().zip(&sent).enumerate() {
            assert_eq!(r.u, d.value(), "record {k} holds the code sent");
            assert_eq!(r.r, AdcCode::from_volts(6.0).0);
            assert_eq!(
                r.faults != 0,
                k >= 6,
                "OVERRUN latched from the sample after the late one"
            );
        }
        assert_eq!(w.stats.snapshot().overruns, 1);
        println!("records: {:?}", &recs[4..8]);
        // Over budget is an overrun too.
        assert!(c.finish(&links, 7201, false));
    }
}
