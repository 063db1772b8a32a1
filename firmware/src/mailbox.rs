//! Handing a new configuration to the control interrupt without tearing it and without a
//! long lock.
//!
//! The task builds the new configuration (a `Copy` value, e.g. a `Controller`) outside any
//! lock, then [`Mailbox::post`]s it: a critical section held only for the copy into the slot.
//! The interrupt calls [`Mailbox::take`] once per sample: one relaxed atomic load when nothing
//! is pending (the common case); when something is pending, a critical section for the copy
//! out. The interrupt then owns its configuration until the next post, so it never sees a
//! half-written value and never waits for the task. A newer post before the interrupt took
//! the previous one replaces it (the last word wins).

use core::cell::Cell;
use core::sync::atomic::{AtomicBool, Ordering};
use critical_section::Mutex;

/// A one-slot mailbox for a `Copy` value.
pub struct Mailbox<T: Copy> {
    slot: Mutex<Cell<Option<T>>>,
    pending: AtomicBool,
}

impl<T: Copy> Default for Mailbox<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Copy> Mailbox<T> {
    /// An empty mailbox (usable in a `static`).
    pub const fn new() -> Self {
        Self {
            slot: Mutex::new(Cell::new(None)),
            pending: AtomicBool::new(false),
        }
    }

    /// Posts `value` (task side).
    pub fn post(&self, value: T) {
        critical_section::with(|cs| {
            self.slot.borrow(cs).set(Some(value));
            self.pending.store(true, Ordering::Release);
        });
    }

    /// Takes the posted value if there is one (interrupt side).
    #[inline]
    pub fn take(&self) -> Option<T> {
        if !self.pending.load(Ordering::Acquire) {
            return None;
        }
        critical_section::with(|cs| {
            self.pending.store(false, Ordering::Relaxed);
            self.slot.borrow(cs).take()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn last_post_wins_and_is_taken_once() {
        let m: Mailbox<[u32; 4]> = Mailbox::new();
        assert_eq!(m.take(), None);
        m.post([1; 4]);
        m.post([2; 4]);
        assert_eq!(m.take(), Some([2; 4]));
        assert_eq!(m.take(), None);
    }

    #[test]
    fn never_torn_under_concurrency() {
        // Each posted value is 32 copies of one number: a torn read would mix two numbers.
        static M: Mailbox<[u64; 32]> = Mailbox::new();
        let writer = std::thread::spawn(|| {
            for i in 1..=20_000u64 {
                M.post([i; 32]);
                // Leave the reader time to take some of the posts between writes.
                for _ in 0..500 {
                    std::hint::spin_loop();
                }
            }
        });
        let mut seen = 0u32;
        let mut last = 0;
        while !writer.is_finished() || M.pending.load(Ordering::Relaxed) {
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
