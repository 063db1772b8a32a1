//! Timing of the control interrupt: its duration in CPU cycles (max and mean), and overruns.
//!
//! The interrupt reads the DWT cycle counter at entry and exit and hands the difference to
//! [`CycleStats::record`], which it owns (plain integers, no atomics on the hot path except
//! the publication). An *overrun* is a sample whose handler took longer than the budget (one
//! sample period in cycles) or that the hardware reports as missed (ADC overrun flag): either
//! way the next conversion was not served in time. Every `WINDOW` samples the mean over the
//! window is published; the maximum is kept since the last clear. Tasks read the published
//! figures from [`SharedStats`] (atomics, any context).

use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

/// Samples per published mean (about 20 ms at 50 kHz).
pub const WINDOW: u32 = 1024;

/// The interrupt's own accumulator.
#[derive(Clone, Copy, Debug)]
pub struct CycleStats {
    budget_cycles: u32,
    max_cycles: u32,
    window_sum: u64,
    window_count: u32,
    overruns: u32,
}

/// The figures as the tasks see them.
#[derive(Debug, Default)]
pub struct SharedStats {
    max_cycles: AtomicU32,
    mean_cycles: AtomicU32,
    overruns: AtomicU32,
    samples: AtomicU32,
    clear: AtomicBool,
}

/// A copy of the published figures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StatsSnapshot {
    /// Longest handler since the last clear, cycles.
    pub max_cycles: u32,
    /// Mean handler duration over the last window, cycles.
    pub mean_cycles: u32,
    /// Overruns since the last clear.
    pub overruns: u32,
    /// Samples handled since boot (wraps).
    pub samples: u32,
}

impl CycleStats {
    /// An accumulator with a budget of `budget_cycles` per sample (the period in cycles).
    pub const fn new(budget_cycles: u32) -> Self {
        Self {
            budget_cycles,
            max_cycles: 0,
            window_sum: 0,
            window_count: 0,
            overruns: 0,
        }
    }

    /// Changes the budget (after a rate change).
    pub fn set_budget(&mut self, budget_cycles: u32) {
        self.budget_cycles = budget_cycles;
    }

    /// Records one sample that took `cycles`; `missed` is the hardware's own overrun report.
    /// Returns true if this sample is an overrun. Publishes into `shared`.
    #[inline]
    pub fn record(&mut self, cycles: u32, missed: bool, shared: &SharedStats) -> bool {
        if shared.clear.swap(false, Ordering::Relaxed) {
            self.max_cycles = 0;
            self.overruns = 0;
        }
        let overrun = missed || cycles > self.budget_cycles;
        if overrun {
            self.overruns = self.overruns.saturating_add(1);
            shared.overruns.store(self.overruns, Ordering::Relaxed);
        }
        if cycles > self.max_cycles {
            self.max_cycles = cycles;
        }
        shared.max_cycles.store(self.max_cycles, Ordering::Relaxed);
        self.window_sum += u64::from(cycles);
        self.window_count += 1;
        if self.window_count >= WINDOW {
            let mean = self.window_sum / u64::from(self.window_count);
            shared
                .mean_cycles
                .store(u32::try_from(mean).unwrap_or(u32::MAX), Ordering::Relaxed);
            self.window_sum = 0;
            self.window_count = 0;
        }
        shared.samples.fetch_add(1, Ordering::Relaxed);
        overrun
    }
}

impl SharedStats {
    /// Zeroed figures (usable in a `static`).
    pub const fn new() -> Self {
        Self {
            max_cycles: AtomicU32::new(0),
            mean_cycles: AtomicU32::new(0),
            overruns: AtomicU32::new(0),
            samples: AtomicU32::new(0),
            clear: AtomicBool::new(false),
        }
    }

    /// The published figures.
    pub fn snapshot(&self) -> StatsSnapshot {
        StatsSnapshot {
            max_cycles: self.max_cycles.load(Ordering::Relaxed),
            mean_cycles: self.mean_cycles.load(Ordering::Relaxed),
            overruns: self.overruns.load(Ordering::Relaxed),
            samples: self.samples.load(Ordering::Relaxed),
        }
    }

    /// Asks the interrupt to zero the maximum and the overrun count at its next sample.
    pub fn request_clear(&self) {
        self.clear.store(true, Ordering::Relaxed);
        // The published values are zeroed by the interrupt at its next sample.
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_mean_and_overruns() {
        let shared = SharedStats::new();
        let mut s = CycleStats::new(8000);
        let mut overruns = 0;
        for i in 0..WINDOW {
            let cycles = 1000 + (i % 100); // mean 1049.5
            overruns += u32::from(s.record(cycles, false, &shared));
        }
        let snap = shared.snapshot();
        let want_mean =
            (0..WINDOW).map(|i| 1000 + u64::from(i % 100)).sum::<u64>() / u64::from(WINDOW);
        println!("{snap:?}, expected mean {want_mean}");
        assert_eq!(overruns, 0);
        assert_eq!(snap.max_cycles, 1099);
        assert_eq!(u64::from(snap.mean_cycles), want_mean);
        assert_eq!(snap.samples, WINDOW);
        assert!(s.record(8001, false, &shared), "over budget is an overrun");
        assert!(
            s.record(10, true, &shared),
            "a missed conversion is an overrun"
        );
        assert!(!s.record(8000, false, &shared), "exactly the budget is not");
        assert_eq!(shared.snapshot().overruns, 2);
        assert_eq!(shared.snapshot().max_cycles, 8001);
        shared.request_clear();
        s.record(5, false, &shared);
        assert_eq!(shared.snapshot().max_cycles, 5);
        s.set_budget(4);
        assert!(s.record(5, false, &shared));
        assert_eq!(shared.snapshot().overruns, 1);
    }
}
