//! The capture buffer: the control interrupt records one [`Record`] per sample, a task
//! reads the finished capture and sends it as frames (`model_core::frame`).
//!
//! # Protocol (single producer, single consumer, no lock)
//! The buffer is shared by exactly two parties, each holding a token that exists once:
//! the [`Producer`] (the interrupt) and the [`Consumer`] (the command task). A state word
//! decides who may touch the records:
//!
//! ```text
//!   Idle ──arm (consumer)──► Recording ──last push (producer)──► Done ──arm──► Recording
//!     ▲                                                            │
//!     └──────────────────────────abort (consumer)──────────────────┘
//! ```
//! * In `Recording` only the producer writes records, at indices below `target`, and only the
//!   producer advances `len`. It publishes `Done` with `Release` after its last write.
//! * In `Idle` and `Done` only the consumer reads records (after an `Acquire` load of the
//!   state), and only the consumer changes the state (arm, abort).
//! * The consumer cannot leave `Recording` (`arm` and `abort` refuse with `Busy`): a capture
//!   always runs to its end (at most 5 s at 10 kHz), so the consumer never changes `len` or
//!   the state under a push in flight, even on a multi-core host.
//!
//! Per push: one atomic load, one store of 8 bytes, one atomic store: a few cycles.
//!
//! # Sizing
//! [`crate::design_parameters::CAPTURE_RECORDS`] records of 8 bytes: 1 s at 50 kHz in 400 kB of
//! the AXI SRAM. At other rates the duration scales: 0.25 s at 200 kHz, 5 s at 10 kHz.

use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicBool, AtomicU8, AtomicU32, Ordering};
use model_core::frame::Record;

const IDLE: u8 = 0;
const RECORDING: u8 = 1;
const DONE: u8 = 2;

/// Where the capture stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CaptureState {
    /// Nothing recorded (or aborted).
    Idle,
    /// Recording: `len` of `target` records taken.
    Recording {
        /// Records taken so far.
        len: u32,
        /// Records asked for.
        target: u32,
    },
    /// Finished: `len` records ready to send.
    Done {
        /// Records held.
        len: u32,
    },
}

/// Why a capture request was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CaptureError {
    /// Zero records, or more than the buffer holds.
    BadLength,
    /// A capture is recording: abort it first (or wait).
    Busy,
    /// The requested range is not inside the finished capture.
    BadRange,
}

/// The shared buffer of `N` records.
pub struct CaptureBuffer<const N: usize> {
    records: UnsafeCell<[Record; N]>,
    state: AtomicU8,
    len: AtomicU32,
    target: AtomicU32,
    producer_taken: AtomicBool,
    consumer_taken: AtomicBool,
}

// SAFETY: the records are only accessed through the `Producer` and `Consumer` tokens, each of
// which exists at most once (handed out by an atomic swap), and the state machine described in
// the module note gives the producer exclusive access while `Recording` and the consumer
// exclusive read access otherwise; the atomics carry the happens-before edges.
unsafe impl<const N: usize> Sync for CaptureBuffer<N> {}

/// The right to record (held by the control interrupt).
pub struct Producer<const N: usize> {
    buf: &'static CaptureBuffer<N>,
}

/// The right to arm and read (held by the command task).
pub struct Consumer<const N: usize> {
    buf: &'static CaptureBuffer<N>,
}

impl<const N: usize> Default for CaptureBuffer<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> CaptureBuffer<N> {
    /// An empty buffer (usable in a `static`).
    pub const fn new() -> Self {
        Self {
            records: UnsafeCell::new(
                [Record {
                    r: 0,
                    y: 0,
                    u: 0,
                    flags: 0,
                    faults: 0,
                }; N],
            ),
            state: AtomicU8::new(IDLE),
            len: AtomicU32::new(0),
            target: AtomicU32::new(0),
            producer_taken: AtomicBool::new(false),
            consumer_taken: AtomicBool::new(false),
        }
    }

    /// Capacity in records.
    pub const fn capacity(&self) -> usize {
        N
    }

    /// The producer token; `None` if it was already taken.
    pub fn producer(&'static self) -> Option<Producer<N>> {
        (!self.producer_taken.swap(true, Ordering::AcqRel)).then_some(Producer { buf: self })
    }

    /// The consumer token; `None` if it was already taken.
    pub fn consumer(&'static self) -> Option<Consumer<N>> {
        (!self.consumer_taken.swap(true, Ordering::AcqRel)).then_some(Consumer { buf: self })
    }

    /// The present state (any context).
    pub fn state(&self) -> CaptureState {
        match self.state.load(Ordering::Acquire) {
            RECORDING => CaptureState::Recording {
                len: self.len.load(Ordering::Relaxed),
                target: self.target.load(Ordering::Relaxed),
            },
            DONE => CaptureState::Done {
                len: self.len.load(Ordering::Relaxed),
            },
            _ => CaptureState::Idle,
        }
    }
}

impl<const N: usize> Producer<N> {
    /// Records one sample if a capture is recording; returns true when this push finished it.
    #[inline]
    pub fn push(&mut self, rec: Record) -> bool {
        let b = self.buf;
        if b.state.load(Ordering::Acquire) != RECORDING {
            return false;
        }
        let i = b.len.load(Ordering::Relaxed);
        let target = b.target.load(Ordering::Relaxed);
        let records = b.records.get();
        // SAFETY: in `Recording` only this (unique) producer touches the records; `i < target <= N`
        // is checked by `get_mut` below, so the write is in bounds.
        let slot = unsafe { (*records).get_mut(i as usize) };
        if let Some(slot) = slot.filter(|_| i < target) {
            *slot = rec;
            let n = i + 1;
            b.len.store(n, Ordering::Relaxed);
            if n >= target {
                b.state.store(DONE, Ordering::Release);
                return true;
            }
        } else {
            // Cannot happen (arm checks target <= N); end the capture rather than loop.
            b.state.store(DONE, Ordering::Release);
        }
        false
    }
}

impl<const N: usize> Consumer<N> {
    /// Starts a capture of `records` records, discarding any finished one.
    pub fn arm(&mut self, records: u32) -> Result<(), CaptureError> {
        let b = self.buf;
        if records == 0 || records as usize > N {
            return Err(CaptureError::BadLength);
        }
        if b.state.load(Ordering::Acquire) == RECORDING {
            return Err(CaptureError::Busy);
        }
        b.len.store(0, Ordering::Relaxed);
        b.target.store(records, Ordering::Relaxed);
        // Release: the producer sees len = 0 and the target once it sees Recording.
        b.state.store(RECORDING, Ordering::Release);
        Ok(())
    }

    /// Forgets a finished capture. Refused while recording.
    pub fn abort(&mut self) -> Result<(), CaptureError> {
        let b = self.buf;
        if b.state.load(Ordering::Acquire) == RECORDING {
            return Err(CaptureError::Busy);
        }
        b.state.store(IDLE, Ordering::Release);
        b.len.store(0, Ordering::Relaxed);
        Ok(())
    }

    /// The finished capture's records `first .. first + out.len()` copied into `out`.
    pub fn read(&self, first: u32, out: &mut [Record]) -> Result<(), CaptureError> {
        let b = self.buf;
        let CaptureState::Done { len } = b.state() else {
            return Err(CaptureError::Busy);
        };
        let end = (first as usize)
            .checked_add(out.len())
            .ok_or(CaptureError::BadRange)?;
        if end > len as usize {
            return Err(CaptureError::BadRange);
        }
        // SAFETY: the state is `Done` (acquired above): the producer no longer writes, and only
        // this unique consumer could change the state, which it cannot do while borrowed here.
        let records = unsafe { &*b.records.get() };
        let src = records
            .get(first as usize..end)
            .ok_or(CaptureError::BadRange)?;
        out.copy_from_slice(src);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(i: u32) -> Record {
        Record {
            r: i as i16,
            y: (i >> 16) as i16,
            u: (i as i16).wrapping_neg(),
            flags: (i % 7) as u8,
            faults: 0,
        }
    }

    #[test]
    fn tokens_exist_once() {
        static B: CaptureBuffer<4> = CaptureBuffer::new();
        assert!(B.producer().is_some());
        assert!(B.producer().is_none());
        assert!(B.consumer().is_some());
        assert!(B.consumer().is_none());
    }

    #[test]
    fn records_exactly_the_target_then_stops() {
        static B: CaptureBuffer<16> = CaptureBuffer::new();
        let mut p = B.producer().unwrap();
        let mut c = B.consumer().unwrap();
        assert!(!p.push(rec(99)), "idle push records nothing");
        assert_eq!(B.state(), CaptureState::Idle);
        assert_eq!(c.arm(0), Err(CaptureError::BadLength));
        assert_eq!(c.arm(17), Err(CaptureError::BadLength));
        c.arm(10).unwrap();
        assert_eq!(c.arm(5), Err(CaptureError::Busy));
        assert_eq!(c.abort(), Err(CaptureError::Busy));
        let mut out = [Record::default(); 1];
        assert_eq!(c.read(0, &mut out), Err(CaptureError::Busy));
        let finished: Vec<bool> = (0..15).map(|i| p.push(rec(i))).collect();
        assert_eq!(finished.iter().filter(|f| **f).count(), 1);
        assert!(finished[9]);
        assert_eq!(B.state(), CaptureState::Done { len: 10 });
        let mut all = [Record::default(); 10];
        c.read(0, &mut all).unwrap();
        for (i, r) in all.iter().enumerate() {
            assert_eq!(*r, rec(i as u32));
        }
        let mut tail = [Record::default(); 3];
        c.read(7, &mut tail).unwrap();
        assert_eq!(tail[2], rec(9));
        assert_eq!(c.read(8, &mut tail), Err(CaptureError::BadRange));
        assert_eq!(c.read(u32::MAX, &mut tail), Err(CaptureError::BadRange));
        c.abort().unwrap();
        assert_eq!(B.state(), CaptureState::Idle);
        assert_eq!(c.read(0, &mut out), Err(CaptureError::Busy));
    }

    #[test]
    fn concurrent_producer_and_consumer_see_consistent_data() {
        static B: CaptureBuffer<1000> = CaptureBuffer::new();
        let mut c = B.consumer().unwrap();
        let mut p = B.producer().unwrap();
        let stop = std::sync::Arc::new(AtomicBool::new(false));
        let s2 = stop.clone();
        let producer = std::thread::spawn(move || {
            let mut i = 0u32;
            while !s2.load(Ordering::Relaxed) {
                p.push(rec(i));
                i = i.wrapping_add(1);
            }
        });
        let mut checked = 0;
        for round in 0..200u32 {
            let n = 1 + (round * 37) % 1000;
            c.arm(n).unwrap();
            while !matches!(B.state(), CaptureState::Done { .. }) {
                std::hint::spin_loop();
            }
            let mut out = vec![Record::default(); n as usize];
            c.read(0, &mut out).unwrap();
            // The producer numbers its samples: a finished capture is n consecutive ones.
            let first = out[0].r as u16 as u32 | ((out[0].y as u16 as u32) << 16);
            for (k, r) in out.iter().enumerate() {
                assert_eq!(
                    *r,
                    rec(first.wrapping_add(k as u32)),
                    "round {round} record {k}"
                );
            }
            checked += n;
        }
        stop.store(true, Ordering::Relaxed);
        producer.join().unwrap();
        println!("{checked} records checked across 200 concurrent captures");
    }
}
