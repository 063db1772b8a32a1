//! The capture receiver (the library half of `piezo record --port DEV --seconds S --out
//! FILE.csv`): capture a run on the board and write it as a CSV record (`t,u,y,r,flags`) that
//! the model tools read. The serial line itself is [`super::link`].
//!
//! # The exchange
//! 1. `capture Ns` arms the board (`ok capture armed N` or `err ...`);
//! 2. `capture status` is polled until `ok capture done N rate_hz R`;
//! 3. `capture send` streams the frames of `model_core::frame` (Start, Data..., End);
//! 4. every record is placed by its index; missing ranges are asked for again with
//!    `capture send FIRST COUNT` (up to `--retries` times; the board keeps the capture);
//! 5. only a complete capture is written, to a temporary file renamed into place, so `--out`
//!    is never a silently short file. Otherwise the verb fails (exit 2) and names the missing
//!    ranges. The transfer report (frames received, corrupted, lost, duplicated, resent) is
//!    printed either way and the CSV's comment header repeats it.
//!
//! The exchange runs over the [`Link`] trait so the tests drive it with a simulated board.

use std::fs::File;
use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use crate::board::link::Link;
use anyhow::{Context, bail};
use model_core::frame::{self, DecodeError, Decoded, Frame, Record};
use model_core::{AdcCode, DacCode};

/// How the transfer went.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TransferReport {
    /// Data frames decoded with a good CRC.
    pub frames_ok: u64,
    /// Places where bytes were skipped inside a stream: a corrupted or truncated frame each.
    pub frames_corrupted: u64,
    /// Frames that did not arrive intact, from the gaps in the sequence numbers and a missing
    /// Start frame (a corrupted frame is also counted here: it left a gap).
    pub frames_lost: u64,
    /// Data frames whose records had already arrived.
    pub frames_duplicated: u64,
    /// Streams that ended without their End frame (their tail is lost).
    pub streams_truncated: u64,
    /// `capture send FIRST COUNT` requests made for missing ranges.
    pub resend_requests: u64,
    /// Bytes outside any stream (text replies, noise): not an error.
    pub bytes_outside_streams: u64,
}

/// Assembles a capture from the frame streams of one or more `capture send` requests.
#[derive(Debug, Default)]
pub struct Assembler {
    pending: Vec<u8>,
    in_stream: bool,
    stream_data_frames: u32,
    last_seq: Option<u16>,
    ended: bool,
    rate_hz: u32,
    slots: Vec<Option<Record>>,
    /// The transfer figures so far.
    pub report: TransferReport,
    conflicts: u64,
}

impl Assembler {
    /// An empty assembler.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds received bytes.
    pub fn feed(&mut self, bytes: &[u8]) {
        self.pending.extend_from_slice(bytes);
        let mut at = 0;
        loop {
            let rest = &self.pending[at..];
            match frame::decode(rest) {
                Decoded::NeedMore => break,
                Decoded::Skip { error, consumed } => {
                    at += consumed;
                    if self.in_stream {
                        // One skip per damaged frame: after a bad CRC the decoder skips one
                        // byte and then whole runs of non-sync bytes; count the CRC failures.
                        if error != DecodeError::NoSync {
                            self.report.frames_corrupted += 1;
                        }
                    } else {
                        self.report.bytes_outside_streams += consumed as u64;
                    }
                }
                Decoded::Frame {
                    frame,
                    seq,
                    consumed,
                } => {
                    at += consumed;
                    self.on_frame(frame, seq);
                }
            }
        }
        self.pending.drain(..at);
    }

    fn on_frame(&mut self, frame: Frame, seq: u16) {
        if let Some(last) = self.last_seq {
            let gap = seq.wrapping_sub(last).wrapping_sub(1);
            // A gap larger than half the sequence space is a reordering, not a loss.
            if gap != 0 && gap < 0x8000 {
                self.report.frames_lost += u64::from(gap);
            }
        }
        self.last_seq = Some(seq);
        match frame {
            Frame::Start {
                rate_hz, samples, ..
            } => {
                if self.in_stream && !self.ended {
                    self.report.streams_truncated += 1;
                }
                self.in_stream = true;
                self.ended = false;
                self.stream_data_frames = 0;
                self.last_seq = Some(seq);
                if self.slots.is_empty() {
                    self.rate_hz = rate_hz;
                    self.slots = vec![None; samples as usize];
                } else if self.slots.len() != samples as usize || self.rate_hz != rate_hz {
                    // A different capture: keep the first, count the frames as conflicts.
                    self.conflicts += 1;
                }
            }
            Frame::Data {
                first_index,
                records,
            } => {
                if !self.in_stream {
                    // Data without its Start (the Start frame was lost): still place it if it
                    // fits the capture we know.
                    self.report.frames_lost += 1;
                    self.in_stream = true;
                }
                self.stream_data_frames += 1;
                self.report.frames_ok += 1;
                let recs = records.as_slice();
                let first = first_index as usize;
                let Some(slots) = first
                    .checked_add(recs.len())
                    .and_then(|end| self.slots.get_mut(first..end))
                else {
                    self.conflicts += 1;
                    return;
                };
                let mut duplicate = false;
                for (slot, rec) in slots.iter_mut().zip(recs) {
                    match slot {
                        Some(old) if old == rec => duplicate = true,
                        Some(_) => self.conflicts += 1,
                        None => *slot = Some(*rec),
                    }
                }
                if duplicate {
                    self.report.frames_duplicated += 1;
                }
            }
            Frame::End { .. } => {
                self.in_stream = false;
                self.ended = true;
            }
        }
    }

    /// Marks the end of the bytes of one request (a timeout): a stream without its End
    /// frame was truncated; its partial frame, if any, is corrupted.
    pub fn close_stream(&mut self) {
        if self.in_stream {
            self.report.streams_truncated += 1;
            if !self.pending.is_empty() {
                self.report.frames_corrupted += 1;
            }
        }
        self.pending.clear();
        self.in_stream = false;
        self.last_seq = None;
    }

    /// True once an End frame closed the present stream.
    pub fn stream_ended(&self) -> bool {
        self.ended
    }

    /// Loop rate of the capture (0 before a Start frame).
    pub fn rate_hz(&self) -> u32 {
        self.rate_hz
    }

    /// Records in the capture (0 before a Start frame).
    pub fn samples(&self) -> usize {
        self.slots.len()
    }

    /// Records that disagreed with records already received for the same index, or frames
    /// that did not fit the capture: a sign of two different captures mixed.
    pub fn conflicts(&self) -> u64 {
        self.conflicts
    }

    /// The missing index ranges, as (first, count).
    pub fn missing(&self) -> Vec<(u32, u32)> {
        let mut out: Vec<(u32, u32)> = vec![];
        for (i, s) in self.slots.iter().enumerate() {
            if s.is_none() {
                match out.last_mut() {
                    Some((first, count)) if *first as usize + *count as usize == i => *count += 1,
                    _ => out.push((i as u32, 1)),
                }
            }
        }
        out
    }

    /// The complete capture, or the missing ranges.
    pub fn complete(&self) -> Result<Vec<Record>, Vec<(u32, u32)>> {
        if self.slots.is_empty() {
            return Err(vec![]);
        }
        let missing = self.missing();
        if !missing.is_empty() {
            return Err(missing);
        }
        Ok(self.slots.iter().flatten().copied().collect())
    }
}

/// Reads text lines from a link, keeping bytes that are not yet a line.
struct Lines {
    buf: Vec<u8>,
}

impl Lines {
    /// The next line starting with `ok` or `err` (other lines, like the boot banner, are
    /// skipped), or an error after `timeout` without one.
    fn reply(&mut self, link: &mut dyn Link, timeout: Duration) -> anyhow::Result<String> {
        let deadline = Instant::now() + timeout;
        loop {
            while let Some(nl) = self.buf.iter().position(|b| *b == b'\n') {
                let line: Vec<u8> = self.buf.drain(..=nl).collect();
                let text = String::from_utf8_lossy(&line).trim().to_string();
                if text.starts_with("ok") || text.starts_with("err") {
                    return Ok(text);
                }
            }
            let now = Instant::now();
            if now >= deadline {
                bail!(
                    "no reply from the board within {:.1} s",
                    timeout.as_secs_f64()
                );
            }
            let bytes = link.recv((deadline - now).min(Duration::from_millis(100)))?;
            self.buf.extend_from_slice(&bytes);
        }
    }

    /// Like [`Lines::reply`], but `err ...` becomes an error.
    fn ok(&mut self, link: &mut dyn Link, timeout: Duration) -> anyhow::Result<String> {
        let r = self.reply(link, timeout)?;
        if let Some(e) = r.strip_prefix("err") {
            bail!("the board refused: {}", e.trim());
        }
        Ok(r)
    }
}

/// Options of one recording.
#[derive(Clone, Copy, Debug)]
pub struct Options {
    /// Give up a step after this long without a byte.
    pub timeout: Duration,
    /// Resend rounds for missing ranges.
    pub retries: u32,
    /// Interval between `capture status` polls.
    pub poll: Duration,
}

/// A finished capture.
#[derive(Clone, Debug)]
pub struct Recording {
    /// Loop rate, Hz.
    pub rate_hz: u32,
    /// The records, index 0 first.
    pub records: Vec<Record>,
    /// How the transfer went.
    pub report: TransferReport,
}

/// Receives one stream into `asm` until its End frame, or until `timeout` passes without a
/// byte.
fn receive_stream(
    link: &mut dyn Link,
    asm: &mut Assembler,
    leftover: &[u8],
    timeout: Duration,
) -> anyhow::Result<()> {
    asm.ended = false;
    asm.feed(leftover);
    let mut last_byte = Instant::now();
    while !asm.stream_ended() {
        let bytes = link.recv(Duration::from_millis(100))?;
        if bytes.is_empty() {
            if last_byte.elapsed() >= timeout {
                asm.close_stream();
                return Ok(());
            }
            continue;
        }
        last_byte = Instant::now();
        asm.feed(&bytes);
    }
    asm.close_stream();
    Ok(())
}

/// Runs the whole exchange: arm, wait, send, resend what is missing. Fails with the missing
/// ranges if the capture cannot be completed.
pub fn record(link: &mut dyn Link, seconds: f64, opts: &Options) -> anyhow::Result<Recording> {
    if !(seconds.is_finite() && seconds > 0.0) {
        bail!("--seconds must be a positive number of seconds, got {seconds}");
    }
    let mut lines = Lines { buf: vec![] };
    link.send_line(&format!("capture {seconds}s"))?;
    let armed = lines.ok(link, opts.timeout)?;
    let n: u64 = armed
        .strip_prefix("ok capture armed ")
        .and_then(|s| s.trim().parse().ok())
        .with_context(|| format!("unexpected reply to capture: {armed:?}"))?;
    // Wait for the capture to finish; the board answers `capture status` at once.
    let mut last_len = None;
    let mut last_progress = Instant::now();
    loop {
        std::thread::sleep(opts.poll);
        link.send_line("capture status")?;
        let st = lines.ok(link, opts.timeout)?;
        if st.starts_with("ok capture done") {
            break;
        }
        let len = st.split_whitespace().nth(3).map(str::to_string);
        if len != last_len {
            last_len = len;
            last_progress = Instant::now();
        } else if last_progress.elapsed() > opts.timeout {
            bail!("the capture makes no progress (last status: {st:?})");
        }
    }
    let mut asm = Assembler::new();
    link.send_line("capture send")?;
    let reply = lines.ok(link, opts.timeout)?;
    if !reply.starts_with("ok sending") {
        bail!("unexpected reply to capture send: {reply:?}");
    }
    let leftover = std::mem::take(&mut lines.buf);
    receive_stream(link, &mut asm, &leftover, opts.timeout)?;
    if asm.samples() as u64 != n && asm.samples() != 0 {
        bail!(
            "the board announced {} samples but armed {n}",
            asm.samples()
        );
    }
    let mut round = 0;
    loop {
        let missing = asm.missing();
        if asm.samples() != 0 && missing.is_empty() {
            break;
        }
        if round >= opts.retries {
            let total: u64 = missing.iter().map(|(_, c)| u64::from(*c)).sum();
            let shown: Vec<String> = missing
                .iter()
                .take(10)
                .map(|(f, c)| format!("{f}..{}", f + c))
                .collect();
            bail!(
                "capture incomplete after {} resend rounds: {total} of {n} samples missing (ranges {}{}); {:?}; nothing written",
                opts.retries,
                shown.join(", "),
                if missing.len() > 10 { ", ..." } else { "" },
                asm.report
            );
        }
        round += 1;
        let ranges = if asm.samples() == 0 {
            vec![(0, n as u32)]
        } else {
            missing
        };
        for (first, count) in ranges {
            asm.report.resend_requests += 1;
            if asm.samples() == 0 {
                link.send_line("capture send")?;
            } else {
                link.send_line(&format!("capture send {first} {count}"))?;
            }
            let reply = lines.ok(link, opts.timeout)?;
            if !reply.starts_with("ok sending") {
                bail!("unexpected reply to capture send: {reply:?}");
            }
            let leftover = std::mem::take(&mut lines.buf);
            receive_stream(link, &mut asm, &leftover, opts.timeout)?;
        }
    }
    if asm.conflicts() > 0 {
        bail!(
            "{} frames disagreed with each other (two different captures?); nothing written",
            asm.conflicts()
        );
    }
    let records = asm
        .complete()
        .map_err(|m| anyhow::anyhow!("capture incomplete: {m:?}"))?;
    Ok(Recording {
        rate_hz: asm.rate_hz(),
        records,
        report: asm.report.clone(),
    })
}

/// Writes the CSV (`t,u,y,r,flags`, `t` in seconds, volts for the rest, `flags` the per-step
/// flags in bits 0..7 and the latched faults in bits 8..15) to a temporary file next to
/// `path`, then renames it into place.
pub fn write_csv(rec: &Recording, path: &Path) -> anyhow::Result<()> {
    if rec.rate_hz == 0 {
        bail!("the capture has no sample rate");
    }
    let tmp = path.with_extension("csv.partial");
    {
        let f = File::create(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
        let mut w = std::io::BufWriter::new(f);
        let r = &rec.report;
        writeln!(
            w,
            "# piezo record: {} samples at {} Hz",
            rec.records.len(),
            rec.rate_hz
        )?;
        writeln!(
            w,
            "# transfer: {} frames ok, {} corrupted, {} lost, {} duplicated, {} resend requests (all samples present)",
            r.frames_ok, r.frames_corrupted, r.frames_lost, r.frames_duplicated, r.resend_requests
        )?;
        writeln!(
            w,
            "# u: amplifier input V (DAC code), y: sensor monitor V (ADC code), r: reference V; flags: limit flags | faults << 8"
        )?;
        writeln!(w, "t,u,y,r,flags")?;
        let dt = 1.0 / f64::from(rec.rate_hz);
        for (i, s) in rec.records.iter().enumerate() {
            writeln!(
                w,
                "{:.8},{:.6},{:.6},{:.6},{}",
                i as f64 * dt,
                DacCode::new(s.u).volts(),
                AdcCode(s.y).volts(),
                AdcCode(s.r).volts(),
                u16::from(s.flags) | (u16::from(s.faults) << 8)
            )?;
        }
        w.flush()?;
    }
    std::fs::rename(&tmp, path)
        .with_context(|| format!("renaming {} to {}", tmp.display(), path.display()))?;
    Ok(())
}
