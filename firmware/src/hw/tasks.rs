//! The tasks below the control interrupt: the command line on USART3, the heartbeat LED and
//! the watchdog supervisor.

use core::fmt::Write as _;
use core::sync::atomic::Ordering;

use embassy_stm32::gpio::Output;
use embassy_stm32::usart::BufferedUart;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_time::{Duration, Ticker, with_timeout};
use embedded_io_async::{Read, Write};
use firmware::capture::CaptureState;
use firmware::command::{self, CaptureRequest, Command, ModeRequest};
use firmware::design_parameters;
use firmware::liveness::{TASK_COMMAND, TASK_HEARTBEAT, Verdict};
use firmware::scaling::{self, TimerSetting};
use heapless::String;
use model_core::frame::{self, FrameRef, Record};
use model_core::{AdcCode, DacCode};

use super::board::{CPU_HZ, TIMER_CLOCK_HZ};
use super::shared::*;
use super::timer;
use firmware::sample::Status;
use firmware::settings::Settings;
use model_core::controller::{Faults, Mode};

/// Fault bits and their names, for `faults` and `status`.
const FAULT_NAMES: [(Faults, &str); 6] = [
    (Faults::SENSOR_RANGE, "sensor_range"),
    (Faults::SENSOR_STUCK, "sensor_stuck"),
    (Faults::NONFINITE, "nonfinite"),
    (Faults::OVERRUN, "overrun"),
    (Faults::WATCHDOG, "watchdog"),
    (Faults::SATURATED, "saturated"),
];

type Reply = String<512>;

/// Budget and stall limits that follow the loop rate.
pub fn apply_rate_limits(rate_hz: f64) {
    let period_cycles = (f64::from(CPU_HZ) / rate_hz) as u32;
    // Leave the conversion time (at most about 2 us) out of the budget.
    let conversion_cycles = CPU_HZ / 500_000;
    BUDGET_CYCLES.store(
        period_cycles.saturating_sub(conversion_cycles),
        Ordering::Relaxed,
    );
    STALL_SAMPLES.store(
        firmware::liveness::stall_samples(rate_hz),
        Ordering::Relaxed,
    );
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

fn status(out: &mut Reply, settings: &Settings) {
    let st = STATS.snapshot();
    let mode = STATUS.mode();
    let y = AdcCode(Status::load_i16(&STATUS.y)).volts();
    let r = AdcCode(Status::load_i16(&STATUS.r)).volts();
    let u = DacCode::new(Status::load_i16(&STATUS.u)).volts();
    let _ = write!(
        out,
        "ok mode={} y_v={y:.4} r_v={r:.4} u_v={u:.4} rate_hz={:.0} kc={} tau_s={:e} ff={} cal_gain={} cal_offset_v={} isr_max_us={:.2} isr_mean_us={:.2} overruns={} dac_late={} samples={} ",
        mode_name(mode),
        settings.rate_hz,
        settings.kc,
        settings.tau_s,
        if settings.feedforward { "on" } else { "off" },
        settings.adc_cal.gain,
        settings.adc_cal.offset_v,
        scaling::cycles_to_us(st.max_cycles, CPU_HZ),
        scaling::cycles_to_us(st.mean_cycles, CPU_HZ),
        st.overruns,
        STATUS.dac_late.load(Ordering::Relaxed),
        st.samples,
    );
    write_faults(out, STATUS.faults.load(Ordering::Relaxed));
    let reason = firmware::reset_reason::ResetReason::from_code(
        super::safe_state::LAST_RESET_REASON.load(Ordering::Relaxed),
    )
    .map_or("?", |r| r.name());
    let _ = write!(
        out,
        " last_reset={reason} detail=0x{:x}",
        super::safe_state::LAST_RESET_DETAIL.load(Ordering::Relaxed)
    );
}

/// Builds, checks and posts a controller for `candidate`; on success it becomes the settings.
fn commit(settings: &mut Settings, candidate: Settings, out: &mut Reply) -> bool {
    match candidate.transition_from(settings) {
        Ok(cfg) => {
            CONFIG.post(cfg);
            *settings = candidate;
            true
        }
        Err(e) => {
            let _ = write!(out, "err {e}");
            false
        }
    }
}

/// Handles one parsed command; writes the reply line (without line ending) into `out`.
/// Returns the capture range to send, if the command asked for one.
fn handle(
    cmd: Command,
    settings: &mut Settings,
    capture: &mut firmware::capture::Consumer<{ design_parameters::CAPTURE_RECORDS }>,
    out: &mut Reply,
) -> Option<(u32, u32)> {
    match cmd {
        Command::Help => {
            let _ = write!(out, "ok {}", command::HELP);
        }
        Command::Status => status(out, settings),
        Command::Faults => {
            let _ = write!(out, "ok ");
            write_faults(out, STATUS.faults.load(Ordering::Relaxed));
        }
        Command::Clear => {
            REQUESTS.clear_faults();
            STATS.request_clear();
            let _ = write!(out, "ok cleared");
        }
        Command::Mode(m) => {
            let mode = match m {
                ModeRequest::Safe => Mode::Safe,
                ModeRequest::Open => Mode::OpenLoop,
                ModeRequest::Closed => Mode::ClosedLoop,
                ModeRequest::Hold => Mode::Hold,
            };
            REQUESTS.set_mode(mode);
            let _ = write!(out, "ok mode {}", mode_name(Some(mode)));
        }
        Command::Reference(r) => {
            if commit(
                settings,
                Settings {
                    reference: r,
                    ..*settings
                },
                out,
            ) {
                let _ = write!(out, "ok ref");
            }
        }
        Command::Kc(kc) => {
            if commit(settings, Settings { kc, ..*settings }, out) {
                let _ = write!(out, "ok kc {kc}");
            }
        }
        Command::Tau(tau_s) => {
            if commit(settings, Settings { tau_s, ..*settings }, out) {
                let _ = write!(out, "ok tau_s {tau_s:e}");
            }
        }
        Command::Feedforward(on) => {
            if commit(
                settings,
                Settings {
                    feedforward: on,
                    ..*settings
                },
                out,
            ) {
                let _ = write!(out, "ok ff {}", if on { "on" } else { "off" });
            }
        }
        Command::Rate(rate_hz) => {
            if STATUS.mode() != Some(Mode::Safe) {
                let _ = write!(out, "err rate can only change in safe mode");
            } else if !matches!(
                CAPTURE.state(),
                CaptureState::Idle | CaptureState::Done { .. }
            ) {
                let _ = write!(out, "err a capture is recording");
            } else {
                match TimerSetting::for_rate(TIMER_CLOCK_HZ, rate_hz, 32) {
                    Err(_) => {
                        let _ = write!(out, "err rate not reachable with the timer clock");
                    }
                    Ok(t) => {
                        if commit(
                            settings,
                            Settings {
                                rate_hz: t.rate_hz,
                                ..*settings
                            },
                            out,
                        ) {
                            timer::set_rate(&t);
                            apply_rate_limits(t.rate_hz);
                            let _ = write!(out, "ok rate_hz {:.3}", t.rate_hz);
                        }
                    }
                }
            }
        }
        Command::Calibrate { gain, offset_v } => match scaling::AdcCalibration::new(gain, offset_v)
        {
            Ok(adc_cal) => {
                if commit(
                    settings,
                    Settings {
                        adc_cal,
                        ..*settings
                    },
                    out,
                ) {
                    let _ = write!(out, "ok cal gain {gain} offset_v {offset_v}");
                }
            }
            Err(_) => {
                let _ = write!(out, "err calibration out of range");
            }
        },
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
            let _ = match CAPTURE.state() {
                CaptureState::Idle => write!(out, "ok capture idle"),
                CaptureState::Recording { len, target } => {
                    write!(out, "ok capture recording {len} {target}")
                }
                CaptureState::Done { len } => {
                    write!(out, "ok capture done {len} rate_hz {:.3}", settings.rate_hz)
                }
            };
        }
        Command::Capture(CaptureRequest::Send { range }) => match CAPTURE.state() {
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

/// Sends records `first .. first + count` as frames.
async fn send_capture(
    tx: &mut BufferedUart<'static>,
    capture: &firmware::capture::Consumer<{ design_parameters::CAPTURE_RECORDS }>,
    rate_hz: f64,
    first: u32,
    count: u32,
) {
    let mut bytes = [0u8; frame::MAX_FRAME];
    let mut records = [Record::default(); frame::MAX_RECORDS];
    let total = match CAPTURE.state() {
        CaptureState::Done { len } => len,
        _ => return,
    };
    let mut seq: u16 = 0;
    let start = FrameRef::Start {
        rate_hz: (rate_hz + 0.5) as u32,
        samples: total,
        first,
    };
    if let Ok(n) = frame::encode(&start, seq, &mut bytes) {
        let _ = tx.write_all(bytes.get(..n).unwrap_or(&[])).await;
    }
    let mut sent = 0u32;
    let mut frames = 0u32;
    while sent < count {
        let k = (count - sent).min(frame::MAX_RECORDS as u32) as usize;
        let Some(chunk) = records.get_mut(..k) else {
            break;
        };
        if capture.read(first + sent, chunk).is_err() {
            break;
        }
        seq = seq.wrapping_add(1);
        let data = FrameRef::Data {
            first_index: first + sent,
            records: chunk,
        };
        if let Ok(n) = frame::encode(&data, seq, &mut bytes) {
            let _ = tx.write_all(bytes.get(..n).unwrap_or(&[])).await;
        }
        sent += k as u32;
        frames += 1;
        super::shared::LIVENESS.check_in(TASK_COMMAND);
    }
    seq = seq.wrapping_add(1);
    let end = FrameRef::End {
        samples_sent: sent,
        data_frames: frames,
    };
    if let Ok(n) = frame::encode(&end, seq, &mut bytes) {
        let _ = tx.write_all(bytes.get(..n).unwrap_or(&[])).await;
    }
    let _ = tx.write_all(b"\r\n").await;
    let _ = tx.flush().await;
}

/// The command line: reads lines, answers each with one `ok ...` or `err ...` line.
#[embassy_executor::task]
pub async fn command_task(
    mut uart: BufferedUart<'static>,
    mut settings: Settings,
    mut capture: firmware::capture::Consumer<{ design_parameters::CAPTURE_RECORDS }>,
) {
    let mut line = [0u8; command::MAX_LINE];
    let mut len = 0usize;
    let mut overlong = false;
    let mut byte = [0u8; 32];
    let _ = uart
        .write_all(b"piezo firmware ready (help lists the commands)\r\n")
        .await;
    loop {
        LIVENESS.check_in(TASK_COMMAND);
        let check_in = Duration::from_micros((design_parameters::TASK_CHECK_IN_S * 1e6) as u64);
        let n = match with_timeout(check_in, uart.read(&mut byte)).await {
            Ok(Ok(n)) => n,
            Ok(Err(_)) => continue, // framing/noise error: drop the byte
            Err(_) => continue,     // timeout: just check in again
        };
        for &b in byte.get(..n).unwrap_or(&[]) {
            if b != b'\n' && b != b'\r' {
                match line.get_mut(len) {
                    Some(slot) => {
                        *slot = b;
                        len += 1;
                    }
                    None => overlong = true,
                }
                continue;
            }
            if len == 0 && !overlong {
                continue; // empty line or the second half of CR LF
            }
            let mut out = Reply::new();
            let parsed = if overlong {
                Err(command::ParseError::TooLong)
            } else {
                core::str::from_utf8(line.get(..len).unwrap_or(&[]))
                    .map_err(|_| command::ParseError::TooLong)
                    .and_then(command::parse)
            };
            len = 0;
            overlong = false;
            let send = match parsed {
                Ok(cmd) => handle(cmd, &mut settings, &mut capture, &mut out),
                Err(e) => {
                    let _ = write!(out, "err {}", e.message());
                    None
                }
            };
            let _ = uart.write_all(out.as_bytes()).await;
            let _ = uart.write_all(b"\r\n").await;
            if let Some((first, count)) = send {
                send_capture(&mut uart, &capture, settings.rate_hz, first, count).await;
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
