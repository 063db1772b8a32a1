//! The command task's logic without the UART or the timer (issue 13, virtual board): line
//! assembly, the command handler, the `status` text and the capture upload as a frame
//! generator. `src/hw/tasks.rs` runs it on the board with embassy's UART; the virtual board
//! (`tests/virtual_board.rs`) runs the same code on the host under simulated time.
//!
//! The upload is a generator ([`App::next_upload_frame`]) rather than a loop, so the task
//! reads the link between frames: a `mode safe` sent during an upload is applied after at
//! most one frame (issue 13 item 8; before, the whole upload, 4.6 s at 921 600 baud, ran
//! inline and the line was read only after it).

use core::fmt::Write;
use core::sync::atomic::Ordering;

use model_core::controller::{Controller, ControllerConfig, Faults, Mode};
use model_core::frame::{self, FrameRef, Record};
use model_core::learning::{Halt, Learning, LearningConfig, LearningState, Status as LearnStatus};
use model_core::reference::ReferenceGenerator;
use model_core::{AdcCode, DacCode};

use crate::capture::{CaptureBuffer, CaptureState, Consumer};
use crate::command::{self, CaptureRequest, Command, LearnRequest, ModeRequest};
use crate::design_parameters;
use crate::learn::LearnTask;
use crate::liveness;
use crate::mailbox::Mailbox;
use crate::reset_reason::ResetReason;
use crate::sample::{Links, Status};
use crate::scaling::{self, TimerSetting};
use crate::settings::{LoopConfig, Settings};

/// What the command handler needs from the board.
pub trait Board {
    /// CPU clock, Hz (the cycle counter's rate).
    fn cpu_hz(&self) -> u32;
    /// Clock of the control timer, Hz.
    fn timer_clock_hz(&self) -> u32;
    /// Loads a new sampling period into the control timer.
    fn set_rate(&mut self, t: &TimerSetting);
    /// The last reset's reason and detail word.
    fn last_reset(&self) -> (ResetReason, u32);
    /// A monotonic clock, microseconds (times the command handler, e.g. `Controller::new`'s
    /// software f64 maths).
    fn now_us(&self) -> u64;
}

/// Fault bits and their names, for `faults` and `status`.
pub const FAULT_NAMES: [(Faults, &str); 6] = [
    (Faults::SENSOR_RANGE, "sensor_range"),
    (Faults::SENSOR_STUCK, "sensor_stuck"),
    (Faults::NONFINITE, "nonfinite"),
    (Faults::OVERRUN, "overrun"),
    (Faults::WATCHDOG, "watchdog"),
    (Faults::SATURATED, "saturated"),
];

/// Longest reply line, bytes.
pub const MAX_REPLY: usize = 640;

/// One reply line (without its line ending): a fixed buffer, no allocation; text beyond
/// [`MAX_REPLY`] is cut.
#[derive(Clone)]
pub struct Reply {
    buf: [u8; MAX_REPLY],
    len: usize,
}

impl Default for Reply {
    fn default() -> Self {
        Self::new()
    }
}

impl Reply {
    /// Empty.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_REPLY],
            len: 0,
        }
    }
    /// The bytes written.
    pub fn as_bytes(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or(&[])
    }
    /// The text written.
    pub fn as_str(&self) -> &str {
        core::str::from_utf8(self.as_bytes()).unwrap_or("")
    }
}

impl Write for Reply {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let room = MAX_REPLY - self.len;
        let n = s.len().min(room);
        if let (Some(dst), Some(src)) = (
            self.buf.get_mut(self.len..self.len + n),
            s.as_bytes().get(..n),
        ) {
            dst.copy_from_slice(src);
            self.len += n;
        }
        if n < s.len() {
            Err(core::fmt::Error)
        } else {
            Ok(())
        }
    }
}

/// Budget and stall limits that follow the loop rate, published for the interrupt.
pub fn apply_rate_limits(links: &Links<'_>, rate_hz: f64, cpu_hz: u32) {
    let period_cycles = (f64::from(cpu_hz) / rate_hz) as u32;
    // Leave the conversion time (at most about 2 us) out of the budget.
    let conversion_cycles = cpu_hz / 500_000;
    links.budget_cycles.store(
        period_cycles.saturating_sub(conversion_cycles),
        Ordering::Relaxed,
    );
    links
        .stall_samples
        .store(liveness::stall_samples(rate_hz), Ordering::Relaxed);
}

fn mode_name(m: Option<Mode>) -> &'static str {
    match m {
        Some(Mode::Safe) => "safe",
        Some(Mode::OpenLoop) => "open",
        Some(Mode::ClosedLoop) => "closed",
        Some(Mode::Hold) => "hold",
        None => "?",
    }
}

fn write_faults(out: &mut Reply, bits: u8) {
    let _ = write!(out, "faults=0x{bits:02x}");
    for (f, name) in FAULT_NAMES {
        if bits & f.0 != 0 {
            let _ = write!(out, " {name}");
        }
    }
}

fn status(
    out: &mut Reply,
    settings: &Settings,
    links: &Links<'_>,
    learner: &Learner,
    board: &impl Board,
) {
    let st = links.stats.snapshot();
    let status = links.status;
    let mode = status.mode();
    let y = AdcCode(Status::load_i16(&status.y)).volts();
    let r = AdcCode(Status::load_i16(&status.r)).volts();
    let u = DacCode::new(Status::load_i16(&status.u)).volts();
    let cpu_hz = board.cpu_hz();
    let _ = write!(
        out,
        "ok mode={} y_v={y:.4} r_v={r:.4} u_v={u:.4} rate_hz={:.0} kc={} tau_s={:e} ff={} cal_gain={} cal_offset_v={} isr_max_us={:.2} isr_mean_us={:.2} dac_latency_max_us={:.2} overruns={} dac_late={} samples={} ",
        mode_name(mode),
        settings.rate_hz,
        settings.kc,
        settings.tau_s,
        if settings.feedforward { "on" } else { "off" },
        settings.adc_cal.gain,
        settings.adc_cal.offset_v,
        scaling::cycles_to_us(st.max_cycles, cpu_hz),
        scaling::cycles_to_us(st.mean_cycles, cpu_hz),
        dac_latency_us(
            status.write_ticks_max.load(Ordering::Relaxed),
            board.timer_clock_hz(),
            settings.rate_hz
        ),
        st.overruns,
        status.dac_late.load(Ordering::Relaxed),
        st.samples,
    );
    write_faults(out, status.faults.load(Ordering::Relaxed));
    let (reason, detail) = board.last_reset();
    let _ = write!(out, " last_reset={} detail=0x{detail:x} ", reason.name());
    learner.write_status(out);
}

/// The name of why learning froze or stopped.
fn halt_name(h: Halt) -> &'static str {
    match h {
        Halt::Growing => "growing",
        Halt::Fault(_) => "fault",
        Halt::LoopOpened => "loop_opened",
        Halt::ReferenceChanged => "reference_changed",
        Halt::NonFinite => "nonfinite",
        Halt::ShortBuffer => "short_buffer",
        Halt::Requested => "requested",
    }
}

/// The command task's half of iterative learning control (issue 14 item 3): the design, the
/// state, the last repeat's error; the update itself runs in [`App::poll`]
/// ([`LearnTask::service`]).
struct Learner {
    task: LearnTask,
    /// Learning is on (`learn on` until `learn off`), whatever its status.
    on: bool,
    /// The design for the loop and generator in force, while on.
    design: Option<Learning>,
    state: LearningState,
    /// The generator the interrupt runs (the last configuration posted).
    generator: Option<ReferenceGenerator>,
    /// RMS of `r - y` over the last repeat the interrupt handed over, volts.
    rms_error_v: f32,
}

impl Learner {
    /// `learn=<off|learning|frozen:WHY|stopped:WHY> learn_iter=N learn_rms_v=X`.
    fn write_status(&self, out: &mut Reply) {
        let _ = match (self.on, self.state.status()) {
            (false, _) => write!(out, "learn=off"),
            (true, LearnStatus::Learning) => write!(out, "learn=learning"),
            (true, LearnStatus::Frozen(h)) => write!(out, "learn=frozen:{}", halt_name(h)),
            (true, LearnStatus::Stopped(h)) => write!(out, "learn=stopped:{}", halt_name(h)),
        };
        let _ = write!(
            out,
            " learn_iter={} learn_rms_v={:.6}",
            self.state.iteration(),
            self.rms_error_v
        );
    }

    /// Stops learning for `why`: no correction from the interrupt's next sample.
    fn stop(&mut self, why: Halt) {
        self.state.stop(why);
        self.task.disable();
    }

    /// A configuration `cfg` (of `controller`) is about to be posted: a new generator stops
    /// learning first (the table belongs to the old trajectory, and the interrupt must not
    /// add it to the new one); another loop gets a new design.
    fn before_post(&mut self, cfg: &LoopConfig, controller: &ControllerConfig) {
        let new = cfg.controller.generator;
        if self.on && self.generator != Some(new) {
            self.stop(Halt::ReferenceChanged);
            self.task.clear();
        } else if self.on && self.design.is_some() {
            match Learning::new(&LearningConfig::default(), controller) {
                Ok(l) => self.design = Some(l),
                Err(_) => self.stop(Halt::ReferenceChanged),
            }
        }
        self.generator = Some(new);
    }

    /// Once per wake of the command task: stop on a fault or an opened loop, then serve a
    /// repeat the interrupt handed over (the update).
    fn poll(&mut self, links: &Links<'_>) {
        let active = matches!(
            self.state.status(),
            LearnStatus::Learning | LearnStatus::Frozen(_)
        );
        if self.on && active {
            let faults = links.status.faults.load(Ordering::Relaxed);
            if faults != 0 {
                self.stop(Halt::Fault(Faults(faults)));
            } else if links.status.mode() != Some(Mode::ClosedLoop) {
                self.stop(Halt::LoopOpened);
            }
        }
        let Some(generator) = self.generator else {
            return;
        };
        let learning = match (self.on, self.design.as_ref()) {
            (true, Some(l)) => Some((l, &mut self.state)),
            _ => None,
        };
        if let Some(s) = self.task.service(learning, &generator) {
            self.rms_error_v = s.rms_error_v;
        }
        if matches!(self.state.status(), LearnStatus::Stopped(_)) && self.task.enabled() {
            self.task.disable();
        }
    }

    /// `learn on|off|freeze|reset`.
    fn command(
        &mut self,
        req: LearnRequest,
        settings: &Settings,
        links: &Links<'_>,
        out: &mut Reply,
    ) {
        match req {
            LearnRequest::On => {
                if links.status.mode() != Some(Mode::ClosedLoop)
                    || links.status.faults.load(Ordering::Relaxed) != 0
                {
                    let _ = write!(out, "err learn needs closed loop without faults");
                    return;
                }
                if matches!(settings.reference, command::ReferenceRequest::Step { .. }) {
                    let _ = write!(
                        out,
                        "err learn needs a periodic reference (ref sine, ref triangle)"
                    );
                    return;
                }
                let cc = settings.controller_config();
                let design = Learning::new(&LearningConfig::default(), &cc);
                let generator = Controller::new(&cc).map(|c| c.generator);
                match (design, generator) {
                    (Ok(l), Ok(g)) if self.task.enable(l.period_samples()) => {
                        self.design = Some(l);
                        self.generator = Some(g);
                        self.state = LearningState::new();
                        self.on = true;
                        self.rms_error_v = 0.0;
                        let _ = write!(out, "ok learn on period_samples={}", l.period_samples());
                    }
                    (Err(e), _) | (_, Err(e)) => {
                        let _ = write!(out, "err learn: {e}");
                    }
                    _ => {
                        let _ = write!(out, "err learn: the repeat does not fit the table");
                    }
                }
            }
            LearnRequest::Off => {
                self.task.disable();
                self.on = false;
                self.design = None;
                let _ = write!(out, "ok learn off");
            }
            LearnRequest::Freeze => {
                if self.on && self.state.status() == LearnStatus::Learning {
                    self.state.freeze();
                    let _ = write!(out, "ok learn frozen");
                } else {
                    let _ = write!(out, "err learn is not learning");
                }
            }
            LearnRequest::Reset => {
                // The zero table from the next repeat's start; iteration 0.
                self.state.reset(&mut []);
                self.task.clear();
                self.rms_error_v = 0.0;
                let resume = self.on
                    && self.design.is_some()
                    && links.status.mode() == Some(Mode::ClosedLoop)
                    && links.status.faults.load(Ordering::Relaxed) == 0;
                if resume {
                    let n = self.design.map_or(0, |l| l.period_samples());
                    if !self.task.enabled() {
                        self.task.enable(n);
                    }
                    let _ = write!(out, "ok learn reset (learning)");
                } else {
                    self.task.disable();
                    self.on = false;
                    self.design = None;
                    let _ = write!(out, "ok learn reset (off)");
                }
            }
        }
    }
}

/// Sampling instant to DAC update, microseconds: the measured ticks to the write (timer
/// clock), plus the one sample the code waits (it is sent at the next sample), plus the
/// 16-bit frame at [`design_parameters::DAC_SPI_HZ`].
pub fn dac_latency_us(write_ticks: u32, timer_clock_hz: u32, rate_hz: f64) -> f64 {
    let frame_s = 16.0 / f64::from(design_parameters::DAC_SPI_HZ);
    (f64::from(write_ticks) / f64::from(timer_clock_hz) + 1.0 / rate_hz + frame_s) * 1e6
}

/// Builds, checks and posts a controller for `candidate`; on success it becomes the settings.
fn commit(
    config: &Mailbox<LoopConfig>,
    settings: &mut Settings,
    candidate: Settings,
    learner: &mut Learner,
    out: &mut Reply,
) -> bool {
    match candidate.transition_from(settings) {
        Ok(cfg) => {
            learner.before_post(&cfg, &candidate.controller_config());
            if !config.post(cfg) {
                let _ = write!(out, "err the configuration mailbox is busy");
                return false;
            }
            *settings = candidate;
            true
        }
        Err(e) => {
            let _ = write!(out, "err {e}");
            false
        }
    }
}

/// Where an upload stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum UploadStage {
    Start,
    Data,
    End,
    LineEnd,
}

/// A capture upload in progress: records `first .. first + count`.
#[derive(Clone, Copy, Debug)]
struct Upload {
    first: u32,
    count: u32,
    total: u32,
    rate_hz: u32,
    sent: u32,
    frames: u32,
    seq: u16,
    stage: UploadStage,
}

/// The command task's state: settings, the capture's consumer side, the line being
/// assembled, the upload in progress.
pub struct App<const N: usize> {
    links: Links<'static>,
    buffer: &'static CaptureBuffer<N>,
    consumer: Consumer<N>,
    settings: Settings,
    line: [u8; command::MAX_LINE],
    len: usize,
    overlong: bool,
    upload: Option<Upload>,
    /// Longest command handling so far (building and checking a controller included), us.
    handle_max_us: u64,
    /// A `selftest` asked for by the last command, to start after it.
    selftest_requested: bool,
    /// The self-test in progress.
    selftest: Option<SelfTest>,
    /// Iterative learning control.
    learner: Learner,
}

/// What the self-test measured at one level.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LevelFigures {
    /// Mean command over the second half of the capture, volts.
    pub u_mean_v: f64,
    /// Mean read-back, volts.
    pub y_mean_v: f64,
    /// RMS noise of the read-back, volts.
    pub y_rms_v: f64,
    /// Samples from the command's first change to the read-back passing half the step.
    pub latency_samples: u32,
}

/// A self-test in progress: the settings to restore and the figures so far.
#[derive(Clone, Copy, Debug)]
struct SelfTest {
    level: usize,
    restore: Settings,
    figures: [LevelFigures; design_parameters::SELFTEST_LEVELS_V.len()],
}

/// Square root by Newton's iteration (no `std`); 0 for non-positive input.
pub(crate) fn sqrt(x: f64) -> f64 {
    if x <= 0.0 || !x.is_finite() {
        return 0.0;
    }
    let mut r = if x > 1.0 { x } else { 1.0 };
    for _ in 0..64 {
        r = 0.5 * (r + x / r);
    }
    r
}

/// The figures of one level from its capture: `sample(i)` gives the command and the
/// read-back of sample `i` in volts, `n` samples in all. Two passes, no buffer.
pub fn level_figures(sample: impl Fn(usize) -> (f64, f64), n: usize) -> LevelFigures {
    let half = n / 2;
    let (u0, y0) = sample(0);
    let (mut su, mut sy, mut syy, mut k) = (0.0, 0.0, 0.0, 0.0);
    let mut u_end = u0;
    for i in 0..n {
        let (u, y) = sample(i);
        if i >= half {
            su += u;
            sy += y;
            syy += y * y;
            k += 1.0;
        }
        u_end = u;
    }
    // The capture starts with the sample that already computes the new level, while the
    // read-back still shows the old one: both crossings are taken against `y0`.
    let mut iu = None;
    let mut iy = None;
    let threshold = 0.5 * (u_end - y0).abs();
    for i in 0..n {
        let (u, y) = sample(i);
        if iu.is_none() && (u - y0).abs() > threshold {
            iu = Some(i);
        }
        if iy.is_none() && iu.is_some() && (y - y0).abs() > threshold {
            iy = Some(i);
            break;
        }
    }
    let latency_samples = match (iu, iy) {
        (Some(a), Some(b)) => (b - a) as u32,
        _ => u32::MAX,
    };
    let k = if k > 0.0 { k } else { 1.0 };
    let y_mean_v = sy / k;
    LevelFigures {
        u_mean_v: su / k,
        y_mean_v,
        y_rms_v: sqrt(syy / k - y_mean_v * y_mean_v),
        latency_samples,
    }
}

/// Least-squares gain and offset of read-back against command over the levels.
pub fn fit_gain_offset(f: &[LevelFigures]) -> (f64, f64) {
    let n = f.len() as f64;
    let (mut su, mut sy, mut suu, mut suy) = (0.0, 0.0, 0.0, 0.0);
    for l in f {
        su += l.u_mean_v;
        sy += l.y_mean_v;
        suu += l.u_mean_v * l.u_mean_v;
        suy += l.u_mean_v * l.y_mean_v;
    }
    let d = n * suu - su * su;
    if d == 0.0 {
        return (0.0, 0.0);
    }
    let gain = (n * suy - su * sy) / d;
    (gain, (sy - gain * su) / n)
}

impl<const N: usize> App<N> {
    /// The command task at boot.
    pub fn new(
        links: Links<'static>,
        buffer: &'static CaptureBuffer<N>,
        consumer: Consumer<N>,
        learn: LearnTask,
        settings: Settings,
    ) -> Self {
        let generator = settings.loop_config().ok().map(|c| c.controller.generator);
        Self {
            learner: Learner {
                task: learn,
                on: false,
                design: None,
                state: LearningState::new(),
                generator,
                rms_error_v: 0.0,
            },
            links,
            buffer,
            consumer,
            settings,
            line: [0; command::MAX_LINE],
            len: 0,
            overlong: false,
            upload: None,
            handle_max_us: 0,
            selftest_requested: false,
            selftest: None,
        }
    }

    /// The settings in force.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// True while an upload has frames to send.
    pub fn uploading(&self) -> bool {
        self.upload.is_some()
    }

    /// Feeds one received byte. At the end of a non-empty line the command is handled and its
    /// reply returned (the caller sends it, then `\r\n`). A `capture send` starts an upload
    /// (a new one replaces one in progress).
    pub fn feed(&mut self, b: u8, board: &mut impl Board) -> Option<Reply> {
        if b != b'\n' && b != b'\r' {
            match self.line.get_mut(self.len) {
                Some(slot) => {
                    *slot = b;
                    self.len += 1;
                }
                None => self.overlong = true,
            }
            return None;
        }
        if self.len == 0 && !self.overlong {
            return None; // empty line or the second half of CR LF
        }
        let mut out = Reply::new();
        let parsed = if self.overlong {
            Err(command::ParseError::TooLong)
        } else {
            core::str::from_utf8(self.line.get(..self.len).unwrap_or(&[]))
                .map_err(|_| command::ParseError::TooLong)
                .and_then(command::parse)
        };
        self.len = 0;
        self.overlong = false;
        let t0_us = board.now_us();
        let send = match parsed {
            Ok(cmd) => self.handle(cmd, board, &mut out),
            Err(e) => {
                let _ = write!(out, "err {}", e.message());
                None
            }
        };
        self.handle_max_us = self.handle_max_us.max(board.now_us().saturating_sub(t0_us));
        if core::mem::take(&mut self.selftest_requested) {
            let restore = self.settings;
            self.selftest = Some(SelfTest {
                level: 0,
                restore,
                figures: Default::default(),
            });
            if let Err(e) = self.start_level(0) {
                self.selftest = None;
                out = Reply::new();
                let _ = write!(out, "err selftest: {e}");
            }
        }
        if let Some((first, count)) = send
            && let CaptureState::Done { len } = self.buffer.state()
        {
            self.upload = Some(Upload {
                first,
                count,
                total: len,
                rate_hz: (self.settings.rate_hz + 0.5) as u32,
                sent: 0,
                frames: 0,
                seq: 0,
                stage: UploadStage::Start,
            });
        }
        Some(out)
    }

    /// Posts the level `i` of the self-test (open loop) and arms its capture.
    fn start_level(&mut self, i: usize) -> Result<(), &'static str> {
        let level_v = *design_parameters::SELFTEST_LEVELS_V
            .get(i)
            .ok_or("no such level")?;
        let candidate = Settings {
            reference: command::ReferenceRequest::Step { level_v },
            ..self.settings
        };
        let cfg = candidate
            .transition_from(&self.settings)
            .map_err(|_| "the level's configuration was refused")?;
        // The self-test runs from safe mode, so learning is stopped or off: this only keeps
        // the generator in force known.
        self.learner
            .before_post(&cfg, &candidate.controller_config());
        if !self.links.config.post(cfg) {
            return Err("the configuration mailbox is busy");
        }
        self.settings = candidate;
        self.links.requests.set_mode(Mode::OpenLoop);
        self.consumer
            .arm(design_parameters::SELFTEST_SAMPLES)
            .map_err(|_| "the capture could not be armed")
    }

    /// Advances a running self-test; returns its final reply once it is over. Call at every
    /// wake of the command task. Bounded: reads one level's capture (2000 records, in
    /// frames of 30) per call at most.
    pub fn poll(&mut self, board: &impl Board) -> Option<Reply> {
        self.learner.poll(&self.links);
        let mut st = self.selftest?;
        let CaptureState::Done { len } = self.buffer.state() else {
            return None;
        };
        let n = (len as usize).min(design_parameters::SELFTEST_SAMPLES as usize);
        let consumer = &self.consumer;
        let sample = |i: usize| {
            let mut r = [Record::default()];
            let _ = consumer.read(i as u32, &mut r);
            (
                f64::from(DacCode::new(r[0].u).volts()),
                f64::from(AdcCode(r[0].y).volts()),
            )
        };
        let figures = level_figures(sample, n);
        if let Some(f) = st.figures.get_mut(st.level) {
            *f = figures;
        }
        st.level += 1;
        self.selftest = Some(st);
        let faults = self.links.status.faults.load(Ordering::Relaxed);
        if st.level < st.figures.len() && faults == 0 {
            if let Err(e) = self.start_level(st.level) {
                self.selftest = None;
                let mut out = Reply::new();
                let _ = write!(out, "err selftest: {e}");
                return Some(out);
            }
            return None;
        }
        // Over: back to safe and the settings from before.
        self.selftest = None;
        self.links.requests.set_mode(Mode::Safe);
        if let Ok(cfg) = st.restore.transition_from(&self.settings) {
            self.learner
                .before_post(&cfg, &st.restore.controller_config());
            if self.links.config.post(cfg) {
                self.settings = st.restore;
            }
        }
        let (gain, offset_v) = fit_gain_offset(&st.figures);
        let noise_v = st.figures.iter().map(|f| f.y_rms_v).fold(0.0, f64::max);
        let latency = st
            .figures
            .iter()
            .map(|f| f.latency_samples)
            .max()
            .unwrap_or(u32::MAX);
        let isr_max_us = f64::from(scaling::cycles_to_us(
            self.links.stats.snapshot().max_cycles,
            board.cpu_hz(),
        ));
        let period_us = 1e6 / self.settings.rate_hz;
        let pass = faults == 0
            && (gain - 1.0).abs() <= design_parameters::SELFTEST_MAX_GAIN_ERROR
            && offset_v.abs() <= design_parameters::SELFTEST_MAX_OFFSET_V
            && noise_v <= design_parameters::SELFTEST_MAX_NOISE_V
            && latency <= design_parameters::SELFTEST_MAX_LATENCY_SAMPLES
            && isr_max_us <= design_parameters::SELFTEST_MAX_ISR_FRACTION * period_us;
        let mut out = Reply::new();
        let _ = write!(
            out,
            "ok selftest {} gain={gain:.5} offset_v={offset_v:.5} noise_rms_v={noise_v:.6} latency_samples={latency} isr_max_us={isr_max_us:.2} faults=0x{faults:02x} (limits: gain 1+-{}, offset +-{} V, noise {} V, latency {} samples, isr {} of the period)",
            if pass { "pass" } else { "fail" },
            design_parameters::SELFTEST_MAX_GAIN_ERROR,
            design_parameters::SELFTEST_MAX_OFFSET_V,
            design_parameters::SELFTEST_MAX_NOISE_V,
            design_parameters::SELFTEST_MAX_LATENCY_SAMPLES,
            design_parameters::SELFTEST_MAX_ISR_FRACTION,
        );
        Some(out)
    }

    /// The next bytes of the upload in progress (one frame, or the final line end) written
    /// into `bytes`; `None` when no upload is in progress. Bounded: one frame per call.
    pub fn next_upload_frame(&mut self, bytes: &mut [u8; frame::MAX_FRAME]) -> Option<usize> {
        let mut up = self.upload?;
        let n = match up.stage {
            UploadStage::Start => {
                up.stage = UploadStage::Data;
                let start = FrameRef::Start {
                    rate_hz: up.rate_hz,
                    samples: up.total,
                    first: up.first,
                };
                frame::encode(&start, up.seq, bytes).unwrap_or(0)
            }
            UploadStage::Data => {
                let mut records = [Record::default(); frame::MAX_RECORDS];
                let k = (up.count - up.sent).min(frame::MAX_RECORDS as u32) as usize;
                let first = up.first + up.sent;
                let ok = match records.get_mut(..k) {
                    Some(chunk) if k > 0 => self.consumer.read(first, chunk).is_ok(),
                    _ => false,
                };
                if !ok {
                    up.stage = UploadStage::End;
                    0
                } else {
                    up.seq = up.seq.wrapping_add(1);
                    let data = FrameRef::Data {
                        first_index: first,
                        records: records.get(..k).unwrap_or(&[]),
                    };
                    up.sent += k as u32;
                    up.frames += 1;
                    if up.sent >= up.count {
                        up.stage = UploadStage::End;
                    }
                    frame::encode(&data, up.seq, bytes).unwrap_or(0)
                }
            }
            UploadStage::End => {
                up.seq = up.seq.wrapping_add(1);
                up.stage = UploadStage::LineEnd;
                let end = FrameRef::End {
                    samples_sent: up.sent,
                    data_frames: up.frames,
                };
                frame::encode(&end, up.seq, bytes).unwrap_or(0)
            }
            UploadStage::LineEnd => {
                self.upload = None;
                if let Some(b) = bytes.get_mut(..2) {
                    b.copy_from_slice(b"\r\n");
                }
                return Some(2);
            }
        };
        self.upload = Some(up);
        Some(n)
    }

    /// Handles one parsed command; writes the reply line (without line ending) into `out`.
    /// Returns the capture range to send, if the command asked for one.
    fn handle(
        &mut self,
        cmd: Command,
        board: &mut impl Board,
        out: &mut Reply,
    ) -> Option<(u32, u32)> {
        let links = self.links;
        let settings = &mut self.settings;
        let capture = &mut self.consumer;
        let buffer = self.buffer;
        let learner = &mut self.learner;
        match cmd {
            Command::Help => {
                let _ = write!(out, "ok {}", command::HELP);
            }
            Command::Status => {
                status(out, settings, &links, &self.learner, board);
                let _ = write!(out, " cmd_max_us={}", self.handle_max_us);
            }
            Command::Faults => {
                let _ = write!(out, "ok ");
                write_faults(out, links.status.faults.load(Ordering::Relaxed));
            }
            Command::Clear => {
                links.requests.clear_faults();
                links.stats.request_clear();
                links.status.clear_latency();
                let _ = write!(out, "ok cleared");
            }
            Command::Mode(m) => {
                let mode = match m {
                    ModeRequest::Safe => Mode::Safe,
                    ModeRequest::Open => Mode::OpenLoop,
                    ModeRequest::Closed => Mode::ClosedLoop,
                    ModeRequest::Hold => Mode::Hold,
                };
                links.requests.set_mode(mode);
                let _ = write!(out, "ok mode {}", mode_name(Some(mode)));
            }
            Command::Reference(r) => {
                if commit(
                    links.config,
                    settings,
                    Settings {
                        reference: r,
                        ..*settings
                    },
                    learner,
                    out,
                ) {
                    let _ = write!(out, "ok ref");
                }
            }
            Command::Kc(kc) => {
                if commit(
                    links.config,
                    settings,
                    Settings { kc, ..*settings },
                    learner,
                    out,
                ) {
                    let _ = write!(out, "ok kc {kc}");
                }
            }
            Command::Tau(tau_s) => {
                if commit(
                    links.config,
                    settings,
                    Settings { tau_s, ..*settings },
                    learner,
                    out,
                ) {
                    let _ = write!(out, "ok tau_s {tau_s:e}");
                }
            }
            Command::Feedforward(on) => {
                if commit(
                    links.config,
                    settings,
                    Settings {
                        feedforward: on,
                        ..*settings
                    },
                    learner,
                    out,
                ) {
                    let _ = write!(out, "ok ff {}", if on { "on" } else { "off" });
                }
            }
            Command::Rate(rate_hz) => {
                if links.status.mode() != Some(Mode::Safe) {
                    let _ = write!(out, "err rate can only change in safe mode");
                } else if !matches!(
                    buffer.state(),
                    CaptureState::Idle | CaptureState::Done { .. }
                ) {
                    let _ = write!(out, "err a capture is recording");
                } else {
                    match TimerSetting::for_rate(board.timer_clock_hz(), rate_hz, 32) {
                        Err(_) => {
                            let _ = write!(out, "err rate not reachable with the timer clock");
                        }
                        Ok(t) => {
                            if commit(
                                links.config,
                                settings,
                                Settings {
                                    rate_hz: t.rate_hz,
                                    ..*settings
                                },
                                learner,
                                out,
                            ) {
                                board.set_rate(&t);
                                apply_rate_limits(&links, t.rate_hz, board.cpu_hz());
                                let _ = write!(out, "ok rate_hz {:.3}", t.rate_hz);
                            }
                        }
                    }
                }
            }
            Command::Calibrate { gain, offset_v } => {
                match scaling::AdcCalibration::new(gain, offset_v) {
                    Ok(adc_cal) => {
                        if commit(
                            links.config,
                            settings,
                            Settings {
                                adc_cal,
                                ..*settings
                            },
                            learner,
                            out,
                        ) {
                            let _ = write!(out, "ok cal gain {gain} offset_v {offset_v}");
                        }
                    }
                    Err(_) => {
                        let _ = write!(out, "err calibration out of range");
                    }
                }
            }
            Command::Capture(CaptureRequest::Arm { duration_s }) => {
                // Rounded to the nearest sample; `as` saturates, and the parser refused NaN.
                let n = (duration_s * settings.rate_hz + 0.5) as u64;
                if !(1..=design_parameters::CAPTURE_RECORDS as u64).contains(&n) {
                    let _ = write!(
                        out,
                        "err capture holds at most {} samples ({:.3} s at this rate)",
                        design_parameters::CAPTURE_RECORDS,
                        design_parameters::CAPTURE_RECORDS as f64 / settings.rate_hz
                    );
                } else {
                    let n = n as u32;
                    match capture.arm(n) {
                        Ok(()) => {
                            let _ = write!(out, "ok capture armed {n}");
                        }
                        Err(_) => {
                            let _ = write!(out, "err a capture is recording");
                        }
                    }
                }
            }
            Command::Capture(CaptureRequest::Status) => {
                let _ = match buffer.state() {
                    CaptureState::Idle => write!(out, "ok capture idle"),
                    CaptureState::Recording { len, target } => {
                        write!(out, "ok capture recording {len} {target}")
                    }
                    CaptureState::Done { len } => {
                        write!(out, "ok capture done {len} rate_hz {:.3}", settings.rate_hz)
                    }
                };
            }
            Command::Learn(req) => learner.command(req, settings, &links, out),
            Command::SelfTest => {
                if links.status.mode() != Some(Mode::Safe)
                    || links.status.faults.load(Ordering::Relaxed) != 0
                {
                    let _ = write!(
                        out,
                        "err selftest runs from safe mode without faults (loopback cable, amplifier disconnected)"
                    );
                } else if self.selftest.is_some()
                    || !matches!(
                        buffer.state(),
                        CaptureState::Idle | CaptureState::Done { .. }
                    )
                {
                    let _ = write!(out, "err a capture or a selftest is running");
                } else {
                    self.selftest_requested = true;
                    let _ = write!(
                        out,
                        "ok selftest running ({} levels)",
                        design_parameters::SELFTEST_LEVELS_V.len()
                    );
                }
            }
            Command::Capture(CaptureRequest::Send { range }) => match buffer.state() {
                CaptureState::Done { len } => {
                    let (first, count) = range.unwrap_or((0, len));
                    if u64::from(first) + u64::from(count) > u64::from(len) {
                        let _ = write!(out, "err range outside the {len} samples captured");
                    } else {
                        let _ = write!(out, "ok sending {first} {count}");
                        return Some((first, count));
                    }
                }
                _ => {
                    let _ = write!(out, "err no finished capture");
                }
            },
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dac_latency_adds_the_waiting_sample_and_the_frame() {
        // 1.1 us to the write (220 ticks at 200 MHz), 20 us of waiting, 1.28 us of frame.
        let us = dac_latency_us(220, 200_000_000, 50_000.0);
        println!("latency at 50 kHz with the write 1.1 us after the sampling instant: {us:.2} us");
        assert!((us - 22.38).abs() < 1e-9, "{us}");
    }
}
