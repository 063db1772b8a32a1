//! Who feeds the independent watchdog, and when the interrupt gives up on the tasks.
//!
//! Two things must be alive for the IWDG to be fed: the control interrupt (it counts samples)
//! and the tasks (each required task sets its bit with [`Liveness::check_in`]). The supervisor
//! task calls [`Liveness::supervise`] periodically; it answers [`Verdict::Feed`] only if the
//! sample count advanced by at least the expected minimum since its last call *and* every
//! required task checked in recently. Otherwise it does not feed and the IWDG resets the chip.
//!
//! Before that happens, the interrupt itself notices stalled tasks: [`Liveness::isr_tick`]
//! returns true once no complete round of check-ins has been seen for `stall_samples`
//! samples, and the firmware raises the controller's WATCHDOG fault, which ramps the output to
//! the safe value at the slew limit while the interrupt still runs. (If the interrupt stops,
//! nothing in software can move the output: the IWDG reset and the output-enable switch that
//! opens at reset take over; see the README.)

use core::sync::atomic::{AtomicU32, Ordering};

/// Check-in bit of the command task.
pub const TASK_COMMAND: u32 = 1;
/// Check-in bit of the heartbeat task.
pub const TASK_HEARTBEAT: u32 = 2;
/// The tasks that must check in.
pub const REQUIRED_TASKS: u32 = TASK_COMMAND | TASK_HEARTBEAT;

/// What the supervisor should do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Everything alive: feed the watchdog.
    Feed,
    /// The interrupt did not advance enough: do not feed.
    IsrStalled {
        /// Samples seen since the last call.
        advanced: u32,
    },
    /// These required tasks have not checked in for too long: do not feed.
    TasksStalled {
        /// Bits of the tasks missing from the present round.
        missing: u32,
    },
}

/// The shared liveness counters.
#[derive(Debug, Default)]
pub struct Liveness {
    samples: AtomicU32,
    bits: AtomicU32,
    tasks_seen_at: AtomicU32,
}

impl Liveness {
    /// Counters at zero (usable in a `static`).
    pub const fn new() -> Self {
        Self {
            samples: AtomicU32::new(0),
            bits: AtomicU32::new(0),
            tasks_seen_at: AtomicU32::new(0),
        }
    }

    /// Called by the interrupt once per sample. True when the tasks have not completed a round
    /// of check-ins for more than `stall_samples` samples.
    #[inline]
    pub fn isr_tick(&self, stall_samples: u32) -> bool {
        let n = self.samples.load(Ordering::Relaxed).wrapping_add(1);
        self.samples.store(n, Ordering::Relaxed);
        n.wrapping_sub(self.tasks_seen_at.load(Ordering::Relaxed)) > stall_samples
    }

    /// A task says it is alive.
    pub fn check_in(&self, task_bit: u32) {
        self.bits.fetch_or(task_bit, Ordering::Relaxed);
    }

    /// Called by the supervisor every period. `last_samples` is the supervisor's memory of the
    /// sample count at its previous call; `min_advance` the fewest samples a healthy interrupt
    /// produces in one period; `stall_samples` as for [`Liveness::isr_tick`].
    pub fn supervise(
        &self,
        last_samples: &mut u32,
        min_advance: u32,
        stall_samples: u32,
    ) -> Verdict {
        let now = self.samples.load(Ordering::Relaxed);
        let advanced = now.wrapping_sub(*last_samples);
        *last_samples = now;
        let bits = self.bits.load(Ordering::Relaxed);
        if bits & REQUIRED_TASKS == REQUIRED_TASKS {
            self.bits.fetch_and(!REQUIRED_TASKS, Ordering::Relaxed);
            self.tasks_seen_at.store(now, Ordering::Relaxed);
        }
        if advanced < min_advance {
            return Verdict::IsrStalled { advanced };
        }
        let since = now.wrapping_sub(self.tasks_seen_at.load(Ordering::Relaxed));
        if since > stall_samples {
            return Verdict::TasksStalled {
                missing: REQUIRED_TASKS & !bits,
            };
        }
        Verdict::Feed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Simulates `periods` supervisor periods of `per_period` samples; `tasks` says which tasks
    /// check in during each period. Returns the verdicts and the first sample at which the
    /// interrupt saw a stall.
    fn run(
        l: &Liveness,
        periods: u32,
        per_period: u32,
        tasks: impl Fn(u32) -> u32,
    ) -> (Vec<Verdict>, Option<u32>) {
        let mut last = 0;
        let mut verdicts = vec![];
        let mut stall_at = None;
        let mut n = 0;
        for p in 0..periods {
            for _ in 0..per_period {
                n += 1;
                if l.isr_tick(2500) && stall_at.is_none() {
                    stall_at = Some(n);
                }
            }
            let t = tasks(p);
            if t & TASK_COMMAND != 0 {
                l.check_in(TASK_COMMAND);
            }
            if t & TASK_HEARTBEAT != 0 {
                l.check_in(TASK_HEARTBEAT);
            }
            verdicts.push(l.supervise(&mut last, per_period / 2, 2500));
        }
        (verdicts, stall_at)
    }

    #[test]
    fn healthy_system_is_fed() {
        let l = Liveness::new();
        // Command task checks in every 5th period, heartbeat every period: 500 samples each.
        let (v, stall) = run(
            &l,
            100,
            500,
            |p| if p % 5 == 0 { 3 } else { TASK_HEARTBEAT },
        );
        assert!(v.iter().all(|v| *v == Verdict::Feed), "{v:?}");
        assert_eq!(stall, None);
    }

    #[test]
    fn stalled_task_stops_feeding_and_the_isr_notices_first() {
        let l = Liveness::new();
        let (v, stall) = run(&l, 20, 500, |p| if p < 4 { 3 } else { TASK_HEARTBEAT });
        let first_bad = v.iter().position(|v| *v != Verdict::Feed).unwrap();
        println!(
            "task stalled after period 3: isr noticed at sample {stall:?}, supervisor stopped feeding at period {first_bad}"
        );
        assert!(matches!(
            v[first_bad],
            Verdict::TasksStalled {
                missing: TASK_COMMAND
            }
        ));
        let stall = stall.unwrap();
        // Last complete round at sample 2000; stall limit 2500 samples.
        assert_eq!(stall, 4501);
        assert!(v[first_bad..].iter().all(|v| *v != Verdict::Feed));
    }

    #[test]
    fn stalled_interrupt_stops_feeding() {
        let l = Liveness::new();
        let mut last = 0;
        for _ in 0..500 {
            l.isr_tick(2500);
        }
        l.check_in(REQUIRED_TASKS);
        assert_eq!(l.supervise(&mut last, 250, 2500), Verdict::Feed);
        for _ in 0..100 {
            l.isr_tick(2500);
        }
        l.check_in(REQUIRED_TASKS);
        assert_eq!(
            l.supervise(&mut last, 250, 2500),
            Verdict::IsrStalled { advanced: 100 }
        );
        assert_eq!(
            l.supervise(&mut last, 250, 2500),
            Verdict::IsrStalled { advanced: 0 }
        );
    }
}
