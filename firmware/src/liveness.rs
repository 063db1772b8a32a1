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

use crate::design_parameters::{SUPERVISOR_PERIOD_S, TASK_STALL_S};
use model_core::params::MIN_SAMPLE_RATE_HZ;

/// Samples without a complete round of check-ins before the interrupt raises WATCHDOG, at
/// `rate_hz` ([`TASK_STALL_S`] of samples).
pub fn stall_samples(rate_hz: f64) -> u32 {
    (TASK_STALL_S * rate_hz) as u32
}

/// Fewest samples a healthy interrupt produces in one supervisor period, at any allowed rate:
/// half a period's worth at the slowest rate.
pub fn min_advance() -> u32 {
    (SUPERVISOR_PERIOD_S * MIN_SAMPLE_RATE_HZ / 2.0) as u32
}

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

    /// What the simulation of [`boot_and_run`] saw.
    #[derive(Debug)]
    struct Run {
        watchdog_raised_at_s: Option<f64>,
        longest_feed_gap_s: f64,
        feeds: u32,
    }

    /// The firmware's schedule with the real constants, sample by sample from boot: the
    /// interrupt ticks from t = 0; at `BOOT_LOOP_TO_TASKS_S` the tasks start (spawn order:
    /// command, heartbeat, supervisor; the supervisor unleashes the IWDG at its first run);
    /// the command and heartbeat tasks check in every `TASK_CHECK_IN_S` (with their phases),
    /// the supervisor runs every `SUPERVISOR_PERIOD_S`. `stop_heartbeat_s` stops the heartbeat.
    fn boot_and_run(
        rate_hz: f64,
        seconds: f64,
        phase_s: (f64, f64, f64),
        stop_heartbeat_s: f64,
    ) -> Run {
        use crate::design_parameters::{BOOT_LOOP_TO_TASKS_S, TASK_CHECK_IN_S};
        let l = Liveness::new();
        let stall = stall_samples(rate_hz);
        let min = min_advance();
        let dt = 1.0 / rate_hz;
        let n_total = (seconds * rate_hz) as u64;
        let start = BOOT_LOOP_TO_TASKS_S;
        let (mut next_cmd, mut next_hb, mut next_sup) =
            (start + phase_s.0, start + phase_s.1, start + phase_s.2);
        let mut last = 0u32;
        let mut unleashed_at: Option<f64> = None;
        let mut last_feed = 0.0;
        let mut run = Run {
            watchdog_raised_at_s: None,
            longest_feed_gap_s: 0.0,
            feeds: 0,
        };
        for n in 0..n_total {
            let t = n as f64 * dt;
            if l.isr_tick(stall) && run.watchdog_raised_at_s.is_none() {
                run.watchdog_raised_at_s = Some(t);
            }
            while next_cmd <= t {
                l.check_in(TASK_COMMAND);
                next_cmd += TASK_CHECK_IN_S;
            }
            while next_hb <= t && t < stop_heartbeat_s {
                l.check_in(TASK_HEARTBEAT);
                next_hb += TASK_CHECK_IN_S;
            }
            while next_sup <= t {
                if unleashed_at.is_none() {
                    unleashed_at = Some(t);
                    last_feed = t;
                }
                if l.supervise(&mut last, min, stall) == Verdict::Feed {
                    run.longest_feed_gap_s = run.longest_feed_gap_s.max(t - last_feed);
                    last_feed = t;
                    run.feeds += 1;
                }
                next_sup += SUPERVISOR_PERIOD_S;
            }
            if unleashed_at.is_some() {
                run.longest_feed_gap_s = run.longest_feed_gap_s.max(t - last_feed);
            }
        }
        run
    }

    #[test]
    fn real_timings_never_raise_watchdog_and_feed_every_iwdg_window() {
        use crate::design_parameters::IWDG_TIMEOUT_S;
        use model_core::params::{MAX_SAMPLE_RATE_HZ, SAMPLE_RATE_HZ};
        for rate_hz in [MIN_SAMPLE_RATE_HZ, SAMPLE_RATE_HZ, MAX_SAMPLE_RATE_HZ] {
            for phase_s in [
                (0.0, 0.0, 0.0),
                (0.0097, 0.0031, 0.0),
                (0.0, 0.0099, 0.0001),
            ] {
                let r = boot_and_run(rate_hz, 3.0, phase_s, f64::INFINITY);
                println!(
                    "rate {rate_hz} Hz, phases {phase_s:?}: watchdog {:?}, {} feeds, longest gap {:.1} ms (IWDG {} ms)",
                    r.watchdog_raised_at_s,
                    r.feeds,
                    r.longest_feed_gap_s * 1e3,
                    IWDG_TIMEOUT_S * 1e3
                );
                assert_eq!(r.watchdog_raised_at_s, None, "rate {rate_hz} Hz");
                assert!(r.longest_feed_gap_s < IWDG_TIMEOUT_S / 2.0, "{r:?}");
                assert!(r.feeds > 250, "{r:?}");
            }
        }
    }

    #[test]
    fn real_timings_a_stalled_heartbeat_raises_watchdog_before_the_iwdg_bites() {
        use crate::design_parameters::IWDG_TIMEOUT_S;
        use model_core::params::SAMPLE_RATE_HZ;
        let r = boot_and_run(SAMPLE_RATE_HZ, 1.0, (0.0, 0.0, 0.0), 0.5);
        let raised = r.watchdog_raised_at_s.expect("the interrupt notices");
        println!(
            "heartbeat stops at 500 ms: WATCHDOG at {:.1} ms, longest feed gap {:.1} ms",
            raised * 1e3,
            r.longest_feed_gap_s * 1e3
        );
        assert!(raised > 0.5 && raised < 0.5 + TASK_STALL_S + SUPERVISOR_PERIOD_S);
        assert!(
            r.longest_feed_gap_s >= IWDG_TIMEOUT_S,
            "the IWDG bites: {r:?}"
        );
    }
}
