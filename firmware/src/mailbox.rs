//! Handing a new configuration to the control interrupt without tearing it, without a lock
//! and without a copy in the interrupt (issue 13 items 1 and 7).
//!
//! A triple buffer: three slots, each owned at any instant by exactly one of the writer (the
//! command task), the reader (the interrupt) or the "back" position between them. The writer
//! fills its own slot (no lock: the interrupt keeps running, even while a 4.2 KB controller
//! is copied), then swaps it into the back position with one atomic operation, marked fresh.
//! The interrupt, once per sample ([`Reader::update`]), loads the back word (one atomic load
//! when nothing is pending); when it is fresh, swaps its own slot into the back and takes the
//! fresh one: two atomic swaps and an index store. **The value is then used where it lies**
//! ([`Reader::get`]): the interrupt never copies it. Until issue 13 the post copied the value
//! inside a critical section (the control interrupt held off for the copy); after item 7 the
//! interrupt still copied it out of its slot (about 3 us for a controller, once per change:
//! an overrun at 200 kHz, whose budget is 3 us). Neither side waits for the other, and
//! neither masks interrupts. A newer post before the interrupt took the previous one replaces
//! it (the last word wins).
//!
//! Exclusivity of the two roles is enforced, not assumed: a `post` while another `post` is
//! in progress (a second writer) is refused (returns false), and the reader is a token that
//! exists once ([`Mailbox::reader`]); the value in force is borrowed from the token, so it
//! cannot be held across the next [`Reader::update`].

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
    writing: AtomicBool,
    reader_taken: AtomicBool,
}

/// The interrupt's side: the value in force, in the slot the reader owns.
pub struct Reader<'a, T: Copy> {
    mailbox: &'a Mailbox<T>,
    /// The slot the reader owns (initialised: by [`Mailbox::reader`] or a post).
    idx: u8,
}

// SAFETY: the slots are only accessed by the role (writer or reader) that owns their index
// (see the module note); the writer role is exclusive through `writing`, the reader is a
// token handed out once, and the hand-over of a slot goes through the AcqRel swap of `back`,
// which orders the slot's write before its read. `T: Send` because values cross from the
// writer's context to the reader's.
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
            writing: AtomicBool::new(false),
            reader_taken: AtomicBool::new(false),
        }
    }

    /// The reader's token with `initial` in force (at boot, before the interrupt runs);
    /// `None` if it was already taken.
    pub fn reader(&self, initial: T) -> Option<Reader<'_, T>> {
        if self.reader_taken.swap(true, Ordering::AcqRel) {
            return None;
        }
        let idx = 2;
        let slot = self.slots.get(usize::from(idx))?;
        // SAFETY: slot 2 is the reader's from `new` on (the writer starts with 0, the back
        // with 1), and this is the only reader, created once, before it reads anything.
        unsafe { (*slot.get()).write(initial) };
        Some(Reader { mailbox: self, idx })
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

    /// True if `value` lies in one of this mailbox's slots (a value in force that was not
    /// copied out of it).
    pub fn holds(&self, value: &T) -> bool {
        self.slots
            .iter()
            .any(|s| core::ptr::eq(s.get().cast::<T>().cast_const(), value))
    }
}

impl<T: Copy> Reader<'_, T> {
    /// Takes the posted value if there is one (interrupt side, once per sample); true when
    /// it did. Bounded and copy-free: one atomic load when nothing is pending, otherwise two
    /// atomic swaps (the back word) and an index store.
    #[inline]
    pub fn update(&mut self) -> bool {
        let mb = self.mailbox;
        if !mb.pending() {
            return false;
        }
        let old = mb.back.swap(self.idx, Ordering::AcqRel);
        if old & FRESH == 0 {
            // Cannot happen with one reader (only it clears FRESH): take the slot back.
            let mine = mb.back.swap(old, Ordering::AcqRel);
            self.idx = mine & IDX;
            return false;
        }
        self.idx = old & IDX;
        true
    }

    /// The value in force, in place.
    #[inline]
    pub fn get(&self) -> &T {
        let slot = self
            .mailbox
            .slots
            .get(usize::from(self.idx & IDX))
            .unwrap_or(&self.mailbox.slots[2]);
        // SAFETY: the reader's slot was initialised by `Mailbox::reader` or by the `post`
        // that handed it over FRESH (its AcqRel swap synchronises with `update`'s), and the
        // writer does not touch it until the reader swaps it back in `update`, which needs
        // `&mut self` and so ends this borrow first. (`idx & IDX` is at most 3; the slots
        // hold 3, so index 3 falls back to the reader's initial slot, which `update` never
        // produces.)
        unsafe { (*slot.get()).assume_init_ref() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn last_post_wins_and_is_taken_once_in_place() {
        let m: Mailbox<[u32; 4]> = Mailbox::new();
        let mut r = m.reader([0; 4]).unwrap();
        assert!(!r.update());
        assert_eq!(*r.get(), [0; 4]);
        assert!(m.post([1; 4]));
        assert!(m.post([2; 4]));
        assert!(r.update());
        assert_eq!(*r.get(), [2; 4]);
        assert!(m.holds(r.get()), "used where it lies, not copied");
        assert!(!r.update());
        assert_eq!(*r.get(), [2; 4], "stays in force");
    }

    #[test]
    fn a_second_writer_or_reader_is_refused_not_served() {
        let m: Mailbox<u32> = Mailbox::new();
        m.writing.store(true, Ordering::Relaxed); // a post in progress elsewhere
        assert!(!m.post(1), "a concurrent second post is refused");
        m.writing.store(false, Ordering::Relaxed);
        assert!(m.post(2));
        let mut r = m.reader(0).unwrap();
        assert!(m.reader(0).is_none(), "one reader");
        assert!(r.update());
        assert_eq!(*r.get(), 2);
        assert!(!m.pending());
    }

    #[test]
    fn never_torn_under_concurrency() {
        // Each posted value is 32 copies of one number: a torn read would mix two numbers.
        static M: Mailbox<[u64; 32]> = Mailbox::new();
        let mut r = M.reader([0; 32]).unwrap();
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
            if r.update() {
                let v = r.get();
                assert!(v.iter().all(|x| *x == v[0]), "torn value");
                assert!(v[0] > last, "values arrive in order");
                last = v[0];
                seen += 1;
            }
            // Read the value in force while the writer fills another slot.
            let v = r.get();
            assert!(v.iter().all(|x| *x == v[0]), "torn value in force");
        }
        writer.join().unwrap();
        println!("took {seen} of 20000 posts, none torn, last {last}");
        assert_eq!(last, 20_000);
    }
}
