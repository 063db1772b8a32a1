//! Iterative learning control on the board (issue 14 item 3): the buffers the control
//! interrupt and the command task share, and the hand-over between them, without a lock.
//!
//! The maths is `model_core::learning` (the update `c_{k+1} = Q(c_k + gamma Lf(e_k))`, its
//! window, its growth check and its stops); this module only moves data. Per sample the
//! interrupt does no more than the design note of `model_core::learning` allows:
//! [`Recorder::correction`] reads the table's value at the generator's index (one flag, at a
//! repeat's start one more atomic load, one bounds check, one load) and
//! [`Recorder::record`] stores `r - y` at that index (one compare, one store; at the end of a
//! repeat a few atomic stores). Everything else (the update over the whole repeat, about
//! 0.4 M instructions at 500 samples) runs in the command task ([`LearnTask::service`],
//! called from `App::poll`).
//!
//! # Two tables, two error records, one scratch
//! ```text
//!   task:  copy table in force -> free table; update it from the handed error; post its seq
//!   ISR :  at the repeat's start (index 0) adopt the posted seq; read tables[seq & 1][i]
//!   ISR :  errors[w][i] = r - y; at the repeat's end hand `w` over (ready) if the task
//!          gave the previous one back, and record the next repeat into the other
//!   task:  read errors[ready], give it back (ready = NONE)
//! ```
//! * **Tables** are named by a sequence number: `0` is "no table" (a zero correction, uses no
//!   buffer), `s > 0` lives in `tables[s & 1]`. The task posts `s` (`posted`, Release) after
//!   filling the table; the interrupt adopts it only at a repeat's start, so a whole repeat's
//!   error is recorded under one table (the `e_k` of `c_k`), and publishes the seq it reads
//!   (`in_use`, Release, after its last read of the previous table). The task writes a table
//!   only if neither `in_use` nor `posted` names it. While learning is off the interrupt
//!   reads no table and adopts the posted seq at once.
//! * **Error records**: the interrupt writes `errors[w]`, never the one handed over
//!   (`ready`); when a repeat ends while the task still holds the other one, that repeat is
//!   dropped (counted) and the next one overwrites `w`. Each handed repeat carries the seq it
//!   ran under, the faults at its end and whether the loop was closed throughout; the task
//!   learns only from a repeat recorded under the table it last posted.
//!
//! # Memory
//! Five buffers of [`TABLE_SAMPLES`] `f32` (the longest repeat,
//! `params::MAX_LEARN_PERIOD_SAMPLES` = 4096): [`LearnShared::BYTES`] = 81 920 bytes plus a
//! few words. The AXI SRAM holds the 400 kB capture buffer (81 % of it used), so on the board
//! the buffers live in the 128 KiB DTCM (`.dtcm`, zeroed at boot by `hw::zero_dtcm`; see the
//! README's Sizes).

use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicBool, AtomicU8, AtomicU32, Ordering};

use model_core::controller::{Faults, Sample};
use model_core::learning::{self, Learning, LearningState, Period, Status};
use model_core::params;
use model_core::reference::ReferenceGenerator;

/// Samples of one table or error record: the longest repeat learning accepts
/// (`model_core::params::MAX_LEARN_PERIOD_SAMPLES`, issue #14; our assumption).
pub const TABLE_SAMPLES: usize = params::MAX_LEARN_PERIOD_SAMPLES as usize;

/// "Nothing handed over" in `ready` (record `w` is `w + 1`), so that the all-zero bytes are
/// [`LearnShared::new`].
const NONE: u8 = 0;
/// The recorder waits for the next repeat's start.
const WAIT: u32 = u32::MAX;

type Buffer = UnsafeCell<[f32; TABLE_SAMPLES]>;

/// What the interrupt and the command task share (one `static` on the board, in DTCM).
pub struct LearnShared {
    tables: [Buffer; 2],
    errors: [Buffer; 2],
    scratch: Buffer,
    /// Task -> interrupt: add the correction and record.
    enabled: AtomicBool,
    /// Task -> interrupt: samples in the repeat being learnt.
    period_samples: AtomicU32,
    /// Task -> interrupt: the table to adopt at the next repeat's start.
    posted: AtomicU32,
    /// Interrupt -> task: the table the interrupt reads.
    in_use: AtomicU32,
    /// Interrupt -> task: the error record handed over, or `NONE`.
    ready: AtomicU8,
    ready_seq: AtomicU32,
    ready_faults: AtomicU8,
    ready_closed: AtomicBool,
    /// Repeats the interrupt finished while the task still held the other record.
    dropped: AtomicU32,
    recorder_taken: AtomicBool,
    task_taken: AtomicBool,
}

// SAFETY: the buffers are reached only through the `Recorder` and `LearnTask` tokens, each
// handed out once (an atomic swap). The interrupt (recorder) reads only the table named by
// its `in_use` and writes only the error record that is not `ready`; the task writes only a
// table named by neither `in_use` nor `posted`, reads only the record named by `ready`, and
// owns `scratch`. The Release stores of `posted`, `in_use` and `ready` and the Acquire loads
// on the other side order each buffer's writes before the other party's access (module note).
unsafe impl Sync for LearnShared {}

impl Default for LearnShared {
    fn default() -> Self {
        Self::new()
    }
}

impl LearnShared {
    /// Bytes of the five buffers.
    pub const BYTES: usize = 5 * TABLE_SAMPLES * core::mem::size_of::<f32>();

    /// Learning off, buffers zero (usable in a `static`). Every field is zero bits, so on the
    /// board the `NOLOAD` section it lives in is made this value by zeroing it at boot.
    pub const fn new() -> Self {
        Self {
            tables: [
                UnsafeCell::new([0.0; TABLE_SAMPLES]),
                UnsafeCell::new([0.0; TABLE_SAMPLES]),
            ],
            errors: [
                UnsafeCell::new([0.0; TABLE_SAMPLES]),
                UnsafeCell::new([0.0; TABLE_SAMPLES]),
            ],
            scratch: UnsafeCell::new([0.0; TABLE_SAMPLES]),
            enabled: AtomicBool::new(false),
            period_samples: AtomicU32::new(0),
            posted: AtomicU32::new(0),
            in_use: AtomicU32::new(0),
            ready: AtomicU8::new(NONE),
            ready_seq: AtomicU32::new(0),
            ready_faults: AtomicU8::new(0),
            ready_closed: AtomicBool::new(false),
            dropped: AtomicU32::new(0),
            recorder_taken: AtomicBool::new(false),
            task_taken: AtomicBool::new(false),
        }
    }

    /// The interrupt's token; `None` if already taken.
    pub fn recorder(&'static self) -> Option<Recorder> {
        (!self.recorder_taken.swap(true, Ordering::AcqRel)).then_some(Recorder {
            shared: self,
            in_use: 0,
            write: 0,
            next: WAIT,
            seq: 0,
            closed: false,
        })
    }

    /// The command task's token; `None` if already taken.
    pub fn task(&'static self) -> Option<LearnTask> {
        (!self.task_taken.swap(true, Ordering::AcqRel)).then_some(LearnTask {
            shared: self,
            last_seq: 0,
        })
    }

    /// True while the interrupt adds a correction and records (`learn on`, not stopped).
    pub fn enabled(&self) -> bool {
        self.enabled.load(Ordering::Relaxed)
    }

    /// Repeats dropped because the task still held the previous record.
    pub fn dropped(&self) -> u32 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// The interrupt's side (owned by `sample::LoopCore`).
pub struct Recorder {
    shared: &'static LearnShared,
    /// The table read (0: none).
    in_use: u32,
    /// The error record being written.
    write: u8,
    /// The index expected next, or `WAIT`.
    next: u32,
    /// The table in force since this repeat's start.
    seq: u32,
    /// Closed loop at every sample of this repeat so far.
    closed: bool,
}

impl Recorder {
    /// The correction for the sample at generator index `index`, volts (0 while learning is
    /// off or no table is in force). At a repeat's start adopts the table the task posted.
    #[inline]
    pub fn correction(&mut self, index: u32) -> f32 {
        let sh = self.shared;
        if !sh.enabled.load(Ordering::Relaxed) {
            self.next = WAIT;
            let posted = sh.posted.load(Ordering::Acquire);
            if posted != self.in_use {
                self.in_use = posted;
                sh.in_use.store(posted, Ordering::Release);
            }
            return 0.0;
        }
        if index == 0 {
            let posted = sh.posted.load(Ordering::Acquire);
            if posted != self.in_use {
                self.in_use = posted;
                sh.in_use.store(posted, Ordering::Release);
            }
        }
        if self.in_use == 0 {
            return 0.0;
        }
        let t = sh.tables.get(usize::from(self.in_use & 1 != 0));
        // SAFETY: `in_use` names this table, so the task does not write it (module note); the
        // Acquire load of `posted` that adopted it ordered the task's writes before this read.
        t.map_or(0.0, |t| learning::correction(unsafe { &*t.get() }, index))
    }

    /// Records `r - y` of `sample`, taken at generator index `index`; `closed_loop`: the
    /// controller's mode was closed loop. Hands the record over at the repeat's end.
    #[inline]
    pub fn record(&mut self, index: u32, sample: &Sample, closed_loop: bool) {
        let sh = self.shared;
        if !sh.enabled.load(Ordering::Relaxed) {
            return;
        }
        if index == 0 {
            self.next = 0;
            self.seq = self.in_use;
            self.closed = true;
        }
        if index != self.next {
            // Out of step (learning just started, or the generator restarted): wait for the
            // next repeat's start.
            self.next = WAIT;
            return;
        }
        let n = sh
            .period_samples
            .load(Ordering::Relaxed)
            .min(TABLE_SAMPLES as u32);
        let w = self.write;
        if let Some(buf) = sh.errors.get(usize::from(w & 1)) {
            // SAFETY: `w` is never the record handed over (`ready`), so the task does not
            // touch it; only this (unique) recorder writes it.
            learning::record(unsafe { &mut *buf.get() }, index, sample);
        }
        self.closed &= closed_loop;
        self.next = index.wrapping_add(1);
        if self.next >= n {
            self.next = WAIT;
            if sh.ready.load(Ordering::Acquire) == NONE {
                sh.ready_seq.store(self.seq, Ordering::Relaxed);
                sh.ready_faults.store(sample.faults.0, Ordering::Relaxed);
                sh.ready_closed.store(self.closed, Ordering::Relaxed);
                sh.ready.store(w + 1, Ordering::Release);
                self.write = w ^ 1;
            } else {
                let d = sh.dropped.load(Ordering::Relaxed);
                sh.dropped.store(d.wrapping_add(1), Ordering::Relaxed);
            }
        }
    }
}

/// What a repeat handed over gave the task.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Serviced {
    /// RMS of `r - y` over the repeat, volts.
    pub rms_error_v: f32,
    /// The repeat ran under the table last posted (it could be learnt from).
    pub current: bool,
    /// A new table was posted.
    pub posted: bool,
}

/// The command task's side (owned by `app::App`).
pub struct LearnTask {
    shared: &'static LearnShared,
    /// The last seq posted (never 0 after the first post; wraps past 0).
    last_seq: u32,
}

impl LearnTask {
    /// Starts (or restarts) recording and correcting over repeats of `period_samples` from a
    /// zero table. False (and off) if the repeat does not fit the buffers.
    pub fn enable(&mut self, period_samples: u32) -> bool {
        let sh = self.shared;
        if period_samples < 2 || period_samples as usize > TABLE_SAMPLES {
            self.disable();
            return false;
        }
        sh.posted.store(0, Ordering::Release);
        sh.period_samples.store(period_samples, Ordering::Relaxed);
        sh.enabled.store(true, Ordering::Release);
        true
    }

    /// No correction from the interrupt's next sample on, no recording.
    pub fn disable(&mut self) {
        let sh = self.shared;
        sh.enabled.store(false, Ordering::Release);
        sh.posted.store(0, Ordering::Release);
    }

    /// True while the interrupt adds a correction.
    pub fn enabled(&self) -> bool {
        self.shared.enabled.load(Ordering::Relaxed)
    }

    /// The zero table from the next repeat's start (the `learn reset` command).
    pub fn clear(&mut self) {
        self.shared.posted.store(0, Ordering::Release);
    }

    /// The table the task may write: named by neither `in_use` nor `posted`.
    fn free_table(&self) -> Option<usize> {
        let sh = self.shared;
        let busy = |s: u32| (s != 0).then_some(usize::from(s & 1 != 0));
        let a = busy(sh.in_use.load(Ordering::Acquire));
        let b = busy(sh.posted.load(Ordering::Acquire));
        [0usize, 1]
            .into_iter()
            .find(|&t| a != Some(t) && b != Some(t))
    }

    /// If the interrupt handed a repeat over: its RMS error, and, when it ran under the table
    /// last posted and learning is on, `learning.update` on a copy of that table, posted for
    /// the next repeat's start. `generator` is the one in force (the update stops learning
    /// if it is not the one `learning` was designed for). Gives the record back. Bounded:
    /// one update (about `8 N` operations and `N + 256` pre-filter steps).
    pub fn service(
        &mut self,
        learning: Option<(&Learning, &mut LearningState)>,
        generator: &ReferenceGenerator,
    ) -> Option<Serviced> {
        let sh = self.shared;
        let r = sh.ready.load(Ordering::Acquire);
        if r == NONE {
            return None;
        }
        let seq = sh.ready_seq.load(Ordering::Relaxed);
        let faults = Faults(sh.ready_faults.load(Ordering::Relaxed));
        let closed_loop = sh.ready_closed.load(Ordering::Relaxed);
        let n = (sh.period_samples.load(Ordering::Relaxed) as usize).min(TABLE_SAMPLES);
        let posted = sh.posted.load(Ordering::Relaxed);
        let mut out = Serviced {
            rms_error_v: 0.0,
            current: seq == posted,
            posted: false,
        };
        // SAFETY: `r` is the record handed over: the interrupt writes the other one until the
        // store of NONE below, and its Release store of `r` ordered its writes before this
        // Acquire load.
        let error = sh
            .errors
            .get(usize::from(r.wrapping_sub(1) & 1))
            .map(|b| unsafe { &*b.get() });
        if let Some(e) = error.and_then(|e| e.get(..n)) {
            let mut sum2 = 0.0f32;
            for &v in e {
                sum2 += v * v;
            }
            out.rms_error_v = crate::app::sqrt(f64::from(sum2) / n.max(1) as f64) as f32;
            if let (true, Some((l, st)), Some(t)) = (out.current, learning, self.free_table())
                && st.status() == Status::Learning
            {
                out.posted = self.update(l, st, e, t, posted, faults, closed_loop, generator);
            }
        }
        sh.ready.store(NONE, Ordering::Release);
        Some(out)
    }

    /// The update into table `t`: a copy of the table in force (`posted`), then
    /// `learning.update`; posted if the table changed (or was cleared).
    #[allow(clippy::too_many_arguments)]
    fn update(
        &mut self,
        l: &Learning,
        st: &mut LearningState,
        error_v: &[f32],
        t: usize,
        posted: u32,
        faults: Faults,
        closed_loop: bool,
        generator: &ReferenceGenerator,
    ) -> bool {
        let sh = self.shared;
        let (Some(dst), Some(scratch)) = (sh.tables.get(t), Some(&sh.scratch)) else {
            return false;
        };
        // SAFETY: table `t` is named by neither `in_use` nor `posted` (`free_table`), so the
        // interrupt does not read it; the scratch is the task's alone; this token is unique.
        let dst = unsafe { &mut *dst.get() };
        // SAFETY: as above, the task's own buffer.
        let scratch = unsafe { &mut *scratch.get() };
        let src = (posted != 0)
            .then(|| sh.tables.get(usize::from(posted & 1 != 0)))
            .flatten();
        match src {
            // SAFETY: the table in force is only read, by both sides.
            Some(s) => dst.copy_from_slice(unsafe { &*s.get() }),
            None => dst.fill(0.0),
        }
        let before = st.iteration();
        let period = Period {
            error_v,
            faults,
            closed_loop,
            generator,
        };
        let status = l.update(st, dst, scratch, &period);
        let changed = st.iteration() != before;
        if changed {
            let mut s = self.last_seq.wrapping_add(1);
            if s == 0 {
                s = 1;
            }
            // The table's index is `s & 1`: skip a seq that names the table not written.
            if usize::from(s & 1 != 0) != t {
                s = s.wrapping_add(1).max(1);
            }
            self.last_seq = s;
            sh.posted.store(s, Ordering::Release);
        } else if status == Status::Stopped(learning::Halt::ReferenceChanged) {
            self.clear();
        }
        changed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(r: f32, y: f32) -> Sample {
        Sample {
            reference_v: r,
            measured_v: y,
            ..Sample::default()
        }
    }

    fn leak() -> &'static LearnShared {
        Box::leak(Box::new(LearnShared::new()))
    }

    #[test]
    fn a_repeat_is_handed_over_whole_and_a_posted_table_is_adopted_at_the_next_start() {
        let sh = leak();
        let mut rec = sh.recorder().unwrap();
        let mut task = sh.task().unwrap();
        assert!(
            sh.recorder().is_none() && sh.task().is_none(),
            "tokens exist once"
        );
        let n = 8u32;
        assert!(task.enable(n));
        // Learning starts mid-repeat: indices 5..7 are not recorded.
        for i in 5..n {
            assert_eq!(rec.correction(i), 0.0);
            rec.record(i, &sample(1.0, 0.5), true);
        }
        assert_eq!(sh.ready.load(Ordering::Relaxed), NONE);
        for i in 0..n {
            assert_eq!(rec.correction(i), 0.0);
            rec.record(i, &sample(1.0, 1.0 - 0.1 * i as f32), true);
        }
        assert_eq!(sh.ready.load(Ordering::Relaxed), 1, "record 0 handed over");
        // The task writes a table by hand (as the update would) and posts it.
        let t = task.free_table().unwrap();
        // SAFETY (test): the free table, no one else touches it.
        unsafe { (*sh.tables[t].get())[3] = 0.25 };
        task.last_seq = if t == 1 { 1 } else { 2 };
        sh.posted.store(task.last_seq, Ordering::Release);
        // The rest of a repeat under the old table: no correction until index 0.
        assert_eq!(rec.correction(3), 0.0);
        assert_eq!(rec.correction(0), 0.0);
        assert_eq!(rec.correction(3), 0.25, "adopted at the repeat's start");
        assert_eq!(sh.in_use.load(Ordering::Relaxed), task.last_seq);
        assert_eq!(
            task.free_table(),
            Some(1 - t),
            "the table in use is not free"
        );
        // A repeat finishing while the task holds record 0 is dropped, not handed over.
        for i in 0..n {
            rec.record(i, &sample(0.0, 0.0), true);
        }
        assert_eq!(sh.dropped(), 1);
        let e = unsafe { &*sh.errors[0].get() };
        assert!(
            (e[7] - 0.7).abs() < 1e-6,
            "the handed record stays intact: {}",
            e[7]
        );
        // Off: no correction at once, and the zero table adopted at once.
        task.disable();
        assert_eq!(rec.correction(3), 0.0);
        assert_eq!(sh.in_use.load(Ordering::Relaxed), 0);
        assert_eq!(task.free_table(), Some(0));
    }

    #[test]
    fn service_learns_only_from_repeats_under_the_table_last_posted() {
        use model_core::controller::{ControllerConfig, ReferenceSource};
        use model_core::learning::LearningConfig;
        use model_core::reference::{ReferenceConfig, Shape};
        let cfg = ControllerConfig {
            reference: ReferenceConfig {
                shape: Shape::Sine,
                offset_v: 4.0,
                amplitude_v: 3.0,
                freq_hz: 100.0,
                ..ReferenceConfig::default()
            },
            source: ReferenceSource::Generator,
            ..ControllerConfig::default()
        };
        let l = Learning::new(&LearningConfig::default(), &cfg).unwrap();
        let generator = model_core::controller::Controller::new(&cfg)
            .unwrap()
            .generator;
        let n = l.period_samples();
        let sh = leak();
        let mut rec = sh.recorder().unwrap();
        let mut task = sh.task().unwrap();
        let mut st = LearningState::new();
        assert!(task.enable(n));
        // Samples `range` of a repeat with a 50 mV sine of error; the sum of |correction|.
        let run = |rec: &mut Recorder, range: core::ops::Range<u32>| {
            let mut c_sum = 0.0f32;
            for i in range {
                c_sum += rec.correction(i).abs();
                let e = 0.05 * (i as f32 * 2.0 * core::f32::consts::PI / n as f32).sin();
                rec.record(i, &sample(4.0 + e, 4.0), true);
            }
            c_sum
        };
        // Repeat A under the zero table, handed over; B starts before the task serves A.
        assert_eq!(run(&mut rec, 0..n), 0.0);
        assert_eq!(run(&mut rec, 0..n / 2), 0.0);
        let s = task.service(Some((&l, &mut st)), &generator).unwrap();
        println!("repeat A: {s:?}, iteration {}", st.iteration());
        assert!(s.current && s.posted);
        assert!((s.rms_error_v - 0.05 / 2f32.sqrt()).abs() < 1e-4, "{s:?}");
        assert_eq!(st.iteration(), 1);
        assert!(task.service(Some((&l, &mut st)), &generator).is_none());
        // B keeps the zero table to its end: it cannot be learnt from.
        assert_eq!(run(&mut rec, n / 2..n), 0.0);
        let s = task.service(Some((&l, &mut st)), &generator).unwrap();
        assert!(
            !s.current && !s.posted,
            "recorded under the old table: {s:?}"
        );
        assert_eq!(st.iteration(), 1);
        // C runs under the learnt table and is learnt from.
        assert!(run(&mut rec, 0..n) > 0.0, "the learnt table is in force");
        let s = task.service(Some((&l, &mut st)), &generator).unwrap();
        println!("repeat C: {s:?}");
        assert!(s.current && s.posted, "{s:?}");
        assert_eq!(st.iteration(), 2);
        // Another generator: learning stops and the zero table is posted.
        let other = ReferenceGenerator::new(
            &ReferenceConfig {
                shape: Shape::Sine,
                offset_v: 4.0,
                amplitude_v: 3.0,
                freq_hz: 50.0,
                ..ReferenceConfig::default()
            },
            0,
        )
        .unwrap();
        run(&mut rec, 0..n);
        let s = task.service(Some((&l, &mut st)), &other).unwrap();
        println!("after a reference change: {s:?}, {:?}", st.status());
        assert_eq!(
            st.status(),
            Status::Stopped(learning::Halt::ReferenceChanged)
        );
        assert_eq!(sh.posted.load(Ordering::Relaxed), 0);
        assert_eq!(
            run(&mut rec, 0..n),
            0.0,
            "the zero table from the next start"
        );
    }
}
