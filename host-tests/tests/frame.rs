//! The capture wire format (`model_core::frame`) and the `piezo record` exchange, against
//! damaged byte streams: corrupted, truncated, reordered, duplicated, garbage. Property tests
//! check that no input panics the decoder, that a record is never placed at a wrong index or
//! with wrong contents, and that a capture is only complete when every record arrived.

use std::collections::VecDeque;
use std::time::Duration;

use host_tests::board::{Assembler, Link, Options, Recording, record, write_csv};
use model_core::frame::{self, Decoded, FrameRef, MAX_FRAME, MAX_RECORDS, Record};
use proptest::prelude::*;

fn rec(i: u32) -> Record {
    // Every field depends on the index, so a misplaced record cannot pass for another.
    Record {
        r: (i.wrapping_mul(7) & 0x7FFF) as i16,
        y: (i.wrapping_mul(13) as u16) as i16,
        u: ((i % 16384) as i16) - 8192,
        flags: (i % 251) as u8,
        faults: (i % 3) as u8,
    }
}

/// The frames of one stream, each as its own byte vector: Start, Data..., End.
fn stream(rate_hz: u32, samples: u32, first: u32, count: u32) -> Vec<Vec<u8>> {
    let mut out = vec![];
    let mut buf = [0u8; MAX_FRAME];
    let mut seq = 0u16;
    let n = frame::encode(
        &FrameRef::Start {
            rate_hz,
            samples,
            first,
        },
        seq,
        &mut buf,
    )
    .unwrap();
    out.push(buf[..n].to_vec());
    let mut sent = 0;
    let mut frames = 0;
    while sent < count {
        let k = (count - sent).min(MAX_RECORDS as u32);
        let recs: Vec<Record> = (first + sent..first + sent + k).map(rec).collect();
        seq = seq.wrapping_add(1);
        let n = frame::encode(
            &FrameRef::Data {
                first_index: first + sent,
                records: &recs,
            },
            seq,
            &mut buf,
        )
        .unwrap();
        out.push(buf[..n].to_vec());
        sent += k;
        frames += 1;
    }
    seq = seq.wrapping_add(1);
    let n = frame::encode(
        &FrameRef::End {
            samples_sent: sent,
            data_frames: frames,
        },
        seq,
        &mut buf,
    )
    .unwrap();
    out.push(buf[..n].to_vec());
    out
}

/// Feeds `bytes` to an assembler in chunks of the given sizes (cycled).
fn feed_chunked(asm: &mut Assembler, bytes: &[u8], chunks: &[usize]) {
    let mut at = 0;
    let mut i = 0;
    while at < bytes.len() {
        let k = chunks
            .get(i % chunks.len().max(1))
            .copied()
            .unwrap_or(1)
            .max(1);
        let end = (at + k).min(bytes.len());
        asm.feed(&bytes[at..end]);
        at = end;
        i += 1;
    }
}

/// Every record the assembler placed must be the original one at its index.
fn placed_records_are_right(asm: &Assembler, samples: u32) -> usize {
    if asm.samples() == 0 {
        return 0; // no Start frame: nothing can be placed
    }
    let missing = asm.missing();
    let is_missing = |i: u32| missing.iter().any(|(f, c)| i >= *f && i < f + c);
    let got = asm.complete().unwrap_or_default();
    if !got.is_empty() {
        for (i, r) in got.iter().enumerate() {
            assert_eq!(*r, rec(i as u32), "record {i}");
        }
    }
    (0..samples).filter(|i| !is_missing(*i)).count()
}

#[test]
fn clean_stream_with_text_around_it_assembles_exactly() {
    let frames = stream(50_000, 1000, 0, 1000);
    let mut bytes = b"piezo firmware ready\r\nok sending 0 1000\r\n".to_vec();
    for f in &frames {
        bytes.extend_from_slice(f);
    }
    bytes.extend_from_slice(b"\r\n");
    let mut asm = Assembler::new();
    feed_chunked(&mut asm, &bytes, &[1, 7, 64, 300]);
    assert!(asm.stream_ended());
    let all = asm.complete().expect("complete");
    assert_eq!(all.len(), 1000);
    for (i, r) in all.iter().enumerate() {
        assert_eq!(*r, rec(i as u32));
    }
    println!("{:?}", asm.report);
    assert_eq!(asm.report.frames_ok, 34);
    assert_eq!(asm.report.frames_corrupted + asm.report.frames_lost, 0);
    // Data frames: 14 bytes (sync, kind, seq, len, index, CRC) per up to 240 bytes of records.
    let data_bytes: usize = frames[1..frames.len() - 1].iter().map(Vec::len).sum();
    let overhead = data_bytes as f64 / (1000.0 * 8.0) - 1.0;
    println!(
        "data-frame overhead for 1000 records: {:.2} % (full frames: {:.2} %)",
        overhead * 100.0,
        14.0 / 240.0 * 100.0
    );
    assert!(overhead <= 34.0 * 14.0 / 8000.0 + 1e-12);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Any record survives the round trip.
    #[test]
    fn records_round_trip(r in any::<i16>(), y in any::<i16>(), u in -8192i16..8192, flags in any::<u8>(), faults in any::<u8>(), first in any::<u32>(), seq in any::<u16>()) {
        let recs = [Record { r, y, u, flags, faults }; 3];
        let mut buf = [0u8; MAX_FRAME];
        let n = frame::encode(&FrameRef::Data { first_index: first, records: &recs }, seq, &mut buf).unwrap();
        match frame::decode(&buf[..n]) {
            Decoded::Frame { frame: frame::Frame::Data { first_index, records }, seq: s, consumed } => {
                prop_assert_eq!((first_index, s, consumed), (first, seq, n));
                prop_assert_eq!(records.as_slice(), &recs[..]);
            }
            other => prop_assert!(false, "{:?}", other),
        }
    }

    /// Random bytes never panic the decoder, every call makes progress or asks for more, and
    /// (with overwhelming probability) no frame is found in them.
    #[test]
    fn garbage_is_skipped(bytes in proptest::collection::vec(any::<u8>(), 0..2000)) {
        let mut at = 0;
        let mut frames = 0;
        while at < bytes.len() {
            match frame::decode(&bytes[at..]) {
                Decoded::NeedMore => break,
                Decoded::Skip { consumed, .. } => { prop_assert!(consumed >= 1 && at + consumed <= bytes.len()); at += consumed; }
                Decoded::Frame { consumed, .. } => { frames += 1; at += consumed; }
            }
        }
        prop_assert!(bytes.len() - at < MAX_FRAME);
        prop_assert_eq!(frames, 0);
    }

    /// Flipped bits: every record placed is the right one, the damaged frames are missing and
    /// reported, the rest arrive.
    #[test]
    fn corrupted_bytes_lose_only_their_frames(flips in proptest::collection::vec((any::<prop::sample::Index>(), 1u8..=255), 1..6), chunk in 1usize..400) {
        let samples = 600;
        let frames = stream(50_000, samples, 0, samples);
        let mut bytes: Vec<u8> = frames.concat();
        let mut damaged_frames = std::collections::BTreeSet::new();
        let bounds: Vec<usize> = frames.iter().scan(0, |s, f| { *s += f.len(); Some(*s) }).collect();
        for (idx, mask) in &flips {
            let i = idx.index(bytes.len());
            bytes[i] ^= mask;
            damaged_frames.insert(bounds.iter().position(|b| i < *b).unwrap());
        }
        let mut asm = Assembler::new();
        feed_chunked(&mut asm, &bytes, &[chunk]);
        asm.close_stream();
        let placed = placed_records_are_right(&asm, samples);
        let damaged_data = damaged_frames.iter().filter(|f| **f != 0 && **f != frames.len() - 1).count();
        // Every record outside a damaged Data frame arrived (unless the Start frame, which
        // sizes the capture, was itself damaged).
        if !damaged_frames.contains(&0) {
            prop_assert_eq!(placed, samples as usize - damaged_data * MAX_RECORDS, "damaged {:?}", damaged_frames);
            if damaged_data > 0 {
                prop_assert!(asm.report.frames_corrupted + asm.report.frames_lost > 0);
            }
        }
    }

    /// A stream cut anywhere: the frames before the cut arrive, nothing after it, no panic.
    #[test]
    fn truncated_stream_keeps_its_head(cut in any::<prop::sample::Index>()) {
        let samples = 300;
        let frames = stream(50_000, samples, 0, samples);
        let bytes: Vec<u8> = frames.concat();
        let cut = cut.index(bytes.len());
        let mut asm = Assembler::new();
        asm.feed(&bytes[..cut]);
        asm.close_stream();
        let whole_frames = frames.iter().scan(0, |s, f| { *s += f.len(); Some(*s) }).take_while(|e| *e <= cut).count();
        let expected = if whole_frames == 0 { 0 } else { ((whole_frames - 1) * MAX_RECORDS).min(samples as usize) };
        let placed = placed_records_are_right(&asm, samples);
        prop_assert_eq!(placed, expected);
        // Complete only if every Data frame arrived (the End frame carries no records).
        prop_assert_eq!(asm.complete().is_ok(), expected == samples as usize);
    }

    /// Frames in any order (and some twice): the capture assembles, duplicates are reported.
    #[test]
    fn reordered_and_duplicated_frames_assemble(perm in Just((0..12usize).collect::<Vec<_>>()).prop_shuffle(), dup in 0usize..12) {
        let samples = 12 * MAX_RECORDS as u32;
        let frames = stream(20_000, samples, 0, samples);
        let (start, rest) = frames.split_first().unwrap();
        let data = &rest[..rest.len() - 1];
        let mut bytes = start.clone();
        for i in &perm { bytes.extend_from_slice(&data[*i]); }
        bytes.extend_from_slice(&data[dup]);
        bytes.extend_from_slice(rest.last().unwrap());
        let mut asm = Assembler::new();
        asm.feed(&bytes);
        let all = asm.complete();
        prop_assert!(all.is_ok(), "missing {:?}", asm.missing());
        prop_assert_eq!(asm.report.frames_duplicated, 1);
        prop_assert_eq!(asm.rate_hz(), 20_000);
        prop_assert_eq!(placed_records_are_right(&asm, samples), samples as usize);
    }
}

/// A simulated board on the other end of the link: answers the capture commands and sends
/// frames, damaging the first `damaged_streams` streams by dropping every `drop_every`-th
/// frame and flipping one byte of another.
struct FakeBoard {
    rate_hz: u32,
    armed: u32,
    out: VecDeque<u8>,
    streams: u32,
    damaged_streams: u32,
    drop_every: usize,
    chunk: usize,
}

impl Link for FakeBoard {
    fn send_line(&mut self, line: &str) -> anyhow::Result<()> {
        let words: Vec<&str> = line.split_whitespace().collect();
        let reply = match words.as_slice() {
            ["capture", "status"] => format!(
                "ok capture done {} rate_hz {}.000",
                self.armed, self.rate_hz
            ),
            ["capture", "send"] | ["capture", "send", _, _] => {
                let (first, count) = match words.as_slice() {
                    [_, _, f, c] => (f.parse().unwrap(), c.parse().unwrap()),
                    _ => (0, self.armed),
                };
                let frames = stream(self.rate_hz, self.armed, first, count);
                self.out
                    .extend(format!("ok sending {first} {count}\r\n").bytes());
                let damage = self.streams < self.damaged_streams;
                self.streams += 1;
                for (i, f) in frames.iter().enumerate() {
                    if damage && i % self.drop_every == 1 {
                        continue; // lost
                    }
                    let mut f = f.clone();
                    if damage && i % self.drop_every == 2 {
                        let k = f.len() / 2;
                        f[k] ^= 0x10; // corrupted
                    }
                    self.out.extend(f);
                }
                self.out.extend(b"\r\n");
                return Ok(());
            }
            ["capture", d] => {
                let s: f64 = d.trim_end_matches('s').parse().unwrap();
                self.armed = (s * f64::from(self.rate_hz)).round() as u32;
                format!("ok capture armed {}", self.armed)
            }
            _ => "err unknown command (try help)".to_string(),
        };
        self.out.extend(reply.bytes());
        self.out.extend(b"\r\n");
        Ok(())
    }

    fn recv(&mut self, _timeout: Duration) -> anyhow::Result<Vec<u8>> {
        let k = self.chunk.min(self.out.len());
        Ok(self.out.drain(..k).collect())
    }
}

fn opts(retries: u32) -> Options {
    Options {
        timeout: Duration::from_millis(300),
        retries,
        poll: Duration::from_millis(1),
    }
}

#[test]
fn record_recovers_lost_and_corrupted_frames_by_resending() {
    let mut board = FakeBoard {
        rate_hz: 50_000,
        armed: 0,
        out: VecDeque::new(),
        streams: 0,
        damaged_streams: 1,
        drop_every: 7,
        chunk: 333,
    };
    let rec: Recording = record(&mut board, 0.02, &opts(3)).expect("recovered");
    println!("{:?}", rec.report);
    assert_eq!(rec.records.len(), 1000);
    for (i, r) in rec.records.iter().enumerate() {
        assert_eq!(*r, rec_of(i));
    }
    assert!(rec.report.frames_lost > 0 && rec.report.frames_corrupted > 0);
    assert!(rec.report.resend_requests > 0);

    let dir = std::env::temp_dir().join(format!("piezo-record-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("run.csv");
    write_csv(&rec, &path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let rows: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
    assert_eq!(rows[0], "t,u,y,r,flags");
    assert_eq!(rows.len(), 1001);
    let last: Vec<f64> = rows[1000].split(',').map(|x| x.parse().unwrap()).collect();
    println!("last row: {last:?}");
    assert!((last[0] - 999.0 / 50_000.0).abs() < 1e-9, "t in seconds");
    let r999 = rec_of(999);
    assert!((last[1] - f64::from(model_core::DacCode::new(r999.u).volts())).abs() < 1e-6);
    assert!((last[2] - f64::from(model_core::AdcCode(r999.y).volts())).abs() < 1e-6);
    assert_eq!(
        last[4] as u16,
        u16::from(r999.flags) | (u16::from(r999.faults) << 8)
    );
    assert!(!dir.join("run.csv.partial").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

fn rec_of(i: usize) -> Record {
    rec(i as u32)
}

#[test]
fn record_fails_without_writing_when_frames_stay_lost() {
    let mut board = FakeBoard {
        rate_hz: 50_000,
        armed: 0,
        out: VecDeque::new(),
        streams: 0,
        damaged_streams: u32::MAX,
        drop_every: 3,
        chunk: 4096,
    };
    let err = record(&mut board, 0.01, &opts(2)).expect_err("must fail");
    let msg = format!("{err:#}");
    println!("{msg}");
    assert!(msg.contains("capture incomplete") && msg.contains("missing"));
    assert!(msg.contains("nothing written"));
}

#[test]
fn record_refuses_bad_durations_and_board_errors() {
    let mut board = FakeBoard {
        rate_hz: 50_000,
        armed: 0,
        out: VecDeque::new(),
        streams: 0,
        damaged_streams: 0,
        drop_every: 3,
        chunk: 64,
    };
    for s in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(record(&mut board, s, &opts(0)).is_err(), "{s}");
    }
    // A board that never answers: the exchange times out instead of hanging.
    struct Silent;
    impl Link for Silent {
        fn send_line(&mut self, _: &str) -> anyhow::Result<()> {
            Ok(())
        }
        fn recv(&mut self, t: Duration) -> anyhow::Result<Vec<u8>> {
            std::thread::sleep(t.min(Duration::from_millis(5)));
            Ok(vec![])
        }
    }
    let t0 = std::time::Instant::now();
    let err = record(&mut Silent, 0.1, &opts(0)).expect_err("times out");
    println!("silent board: {err:#} after {:?}", t0.elapsed());
    assert!(format!("{err:#}").contains("no reply"));
}
