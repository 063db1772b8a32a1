//! Handing a new configuration to the control interrupt without tearing it and without a
//! lock (issue 13 item 7).
//!
//! A triple buffer: three slots, each owned at any instant by exactly one of the writer (the
//! command task), the reader (the interrupt) or the "back" position between them. The writer
//! fills its own slot (no lock: the interrupt keeps running, even while a 4.2 KB controller
//! is copied), then swaps it into the back position with one atomic operation, marked fresh.
//! The interrupt, once per sample, loads the back word (one atomic load when nothing is
//! pending); when it is fresh, swaps its own slot into the back and reads the fresh one.
//! Neither side waits for the other, and neither masks interrupts: until issue 13 the post
//! copied the value inside a critical section, which held the control interrupt off for the
//! copy (about 3 us for a controller: an overrun at 200 kHz). A newer post before the
//! interrupt took the previous one replaces it (the last word wins).
//!
//! Exclusivity of the two roles is enforced, not assumed: a `post` while another `post` is
//! in progress (a second writer) is refused (returns false), and so is a concurrent `take`,
//! so the slot ownership above holds whatever the callers do. The interrupt still copies the
//! value out of its slot (about 3 us for a controller, once per change).

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, AtomicU8, Ordering};

/// Index bits of the back word.
const IDX: u8 = 0b11;
/// The back slot holds a value not yet taken.
const FRESH: u8 = 0b100;

/// A lock-free one-value mailbox for a `Copy` value (a triple buffer).
pub struct Mailbox<T: Copy> {
    slots: [UnsafeCell<MaybeUninit<T>>; 3],
    back: AtomicU8,
    write_idx: AtomicU8,
    read_idx: AtomicU8,
    writing: AtomicBool,
    reading: AtomicBool,
}

// SAFETY: the slots are only accessed by the role (writer or reader) that owns their index
// (see the module note); the roles are exclusive through `writing` / `reading`, and the
// hand-over of a slot goes through the AcqRel swap of `back`, which orders the slot's write
// before its read. `T: Send` because values cross from the writer's context to the reader's.
unsafe impl<T: Copy + Send> Sync for Mailbox<T> {}

impl<T: Copy> Default for Mailbox<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Copy> Mailbox<T> {
    /// An empty mailbox (usable in a `static`).
    pub const fn new() -> Self {
        Self {
            slots: [
                UnsafeCell::new(MaybeUninit::uninit()),
                UnsafeCell::new(MaybeUninit::uninit()),
                UnsafeCell::new(MaybeUninit::uninit()),
            ],
            back: AtomicU8::new(1),
            write_idx: AtomicU8::new(0),
            read_idx: AtomicU8::new(2),
            writing: AtomicBool::new(false),
            reading: AtomicBool::new(false),
        }
    }

    /// Posts `value` (task side). False if another `post` was in progress at that instant (a
    /// second writer): nothing was posted.
    pub fn post(&self, value: T) -> bool {
        if self.writing.swap(true, Ordering::Acquire) {
            return false;
        }
        let w = self.write_idx.load(Ordering::Relaxed) & IDX;
        if let Some(slot) = self.slots.get(usize::from(w)) {
            // SAFETY: slot `w` is the writer's (module note) and `writing` makes this the only
            // writer; the reader never touches a slot it has not been handed through `back`.
            unsafe { (*slot.get()).write(value) };
            let old = self.back.swap(w | FRESH, Ordering::AcqRel);
            self.write_idx.store(old & IDX, Ordering::Relaxed);
        }
        self.writing.store(false, Ordering::Release);
        true
    }

    /// True when a posted value waits to be taken.
    #[inline]
    pub fn pending(&self) -> bool {
        self.back.load(Ordering::Acquire) & FRESH != 0
    }

    /// Takes the posted value if there is one (interrupt side). Bounded: one load when nothing
    /// is pending; otherwise two swaps and the copy.
    #[inline]
    pub fn take(&self) -> Option<T> {
        if !self.pending() {
            return None;
        }
        if self.reading.swap(true, Ordering::Acquire) {
            return None;
        }
        let r = self.read_idx.load(Ordering::Relaxed) & IDX;
        let old = self.back.swap(r, Ordering::AcqRel);
        let fresh = old & IDX;
        self.read_idx.store(fresh, Ordering::Relaxed);
        let value = if old & FRESH != 0 {
            self.slots.get(usize::from(fresh)).map(|slot| {
                // SAFETY: the slot came through `back` marked FRESH, so a `post` wrote it
                // completely before its AcqRel swap, which this AcqRel swap synchronises
                // with; it is now the reader's and `reading` makes this the only reader.
                unsafe { (*slot.get()).assume_init_read() }
            })
        } else {
            None
        };
        self.reading.store(false, Ordering::Release);
        value
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn last_post_wins_and_is_taken_once() {
        let m: Mailbox<[u32; 4]> = Mailbox::new();
        assert_eq!(m.take(), None);
        assert!(m.post([1; 4]));
        assert!(m.post([2; 4]));
        assert_eq!(m.take(), Some([2; 4]));
        assert_eq!(m.take(), None);
    }

    #[test]
    fn a_second_writer_or_reader_is_refused_not_served() {
        let m: Mailbox<u32> = Mailbox::new();
        m.writing.store(true, Ordering::Relaxed); // a post in progress elsewhere
        assert!(!m.post(1), "a concurrent second post is refused");
        m.writing.store(false, Ordering::Relaxed);
        assert!(m.post(2));
        m.reading.store(true, Ordering::Relaxed); // a take in progress elsewhere
        assert_eq!(m.take(), None);
        m.reading.store(false, Ordering::Relaxed);
        assert_eq!(m.take(), Some(2));
        assert!(!m.pending());
    }

    #[test]
    fn never_torn_under_concurrency() {
        // Each posted value is 32 copies of one number: a torn read would mix two numbers.
        static M: Mailbox<[u64; 32]> = Mailbox::new();
        let writer = std::thread::spawn(|| {
            for i in 1..=20_000u64 {
                assert!(M.post([i; 32]));
                // Leave the reader time to take some of the posts between writes.
                for _ in 0..500 {
                    std::hint::spin_loop();
                }
            }
        });
        let mut seen = 0u32;
        let mut last = 0;
        while !writer.is_finished() || M.pending() {
            if let Some(v) = M.take() {
                assert!(v.iter().all(|x| *x == v[0]), "torn value");
                assert!(v[0] > last, "values arrive in order");
                last = v[0];
                seen += 1;
            }
        }
        writer.join().unwrap();
        println!("took {seen} of 20000 posts, none torn, last {last}");
        assert_eq!(last, 20_000);
    }
}
