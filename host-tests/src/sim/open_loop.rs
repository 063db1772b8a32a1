//! The open-loop response of a model to a recorded input (`piezo simulate`, `piezo synth` and
//! the model-gap workflow all simulate through [`simulate`]).
//!
//! The stage runs at its own fixed step (the model's `period_s`) whatever the record's rate:
//! the record's `u` is held from each sample time to the next (as a DAC would hold it), and
//! `y` at each record time is the sensor reading of the last stage step at or before that time.
//! The stage starts at rest with the first input held for ever (drift settled). `piezo simulate`
//! writes the columns `t,u,y` at the input's sample times.
//!
//! A hold is stepped to the fast part's fixed point and taken from there in closed form
//! ([`model_core::held`]): a 1 kHz record holds each input for 50 stage steps, and stepping
//! them one by one was a quarter of the model-gap workflow's time.

use model_core::held::{HELD_MAP_STEPS_MAX, HeldMap};
use model_core::stage::Stage;

/// The stage's readings at the times `t_s` for the input `u_v` held between samples.
/// `period_s` is the stage's fixed step. Both slices must have equal length (the shorter
/// length is used otherwise).
pub fn simulate(stage: &Stage, period_s: f64, t_s: &[f64], u_v: &[f64]) -> Vec<f64> {
    simulate_after(stage, period_s, &[], t_s, u_v)
}

/// As [`simulate`], with the hysteresis memory of a stage that went through the turning points
/// `history_v` before the record ([`Stage::steady_state_after`]; a model file's
/// `[hysteresis] start_turns_v`).
pub fn simulate_after(
    stage: &Stage,
    period_s: f64,
    history_v: &[f32],
    t_s: &[f64],
    u_v: &[f64],
) -> Vec<f64> {
    simulate_after_while(stage, period_s, history_v, t_s, u_v, |_, _| true).unwrap_or_default()
}

/// [`simulate_after`], stopped as soon as `go_on(i, y_i)` (called with each reading in turn)
/// says no: `None` then, the readings otherwise. A search that needs a simulation only if it
/// beats a bound stops this way once the part simulated already shows that it cannot.
pub fn simulate_after_while(
    stage: &Stage,
    period_s: f64,
    history_v: &[f32],
    t_s: &[f64],
    u_v: &[f64],
    mut go_on: impl FnMut(usize, f64) -> bool,
) -> Option<Vec<f64>> {
    let n = t_s.len().min(u_v.len());
    let mut y = Vec::with_capacity(n);
    if n == 0 {
        return Some(y);
    }
    let t0 = t_s[0];
    let mut s = stage.steady_state_after(history_v, u_v[0] as f32);
    let mut last = s.signals().measured_v;
    let mut maps = HeldMaps::default();
    // Steps taken so far; step k ends at t0 + k T.
    let mut k: u64 = 0;
    for i in 0..n {
        // Steps ending at or before t[i] were driven by earlier samples. A time on a step's
        // end computes a hair short of it: `t[i] - t0` carries the rounding of both times'
        // magnitudes (a record whose clock starts at 1234.5 s lost a whole step at some of
        // its 5 kHz samples to a tolerance of 1e-9 steps: 0.5 mV on a 1 Hz sine), so the
        // tolerance is that rounding (an ulp of each), in steps, and a millionth of a step.
        let rounding = 2.0 * f64::EPSILON * (t_s[i].abs() + t0.abs()) / period_s;
        let until = ((t_s[i] - t0) / period_s + 1e-6 + rounding)
            .floor()
            .max(0.0) as u64;
        let held = if i == 0 { u_v[0] } else { u_v[i - 1] } as f32;
        // The steps of one hold at once: whole steps to the fast part's fixed point
        // (`Stage::settle_held`), the rest in closed form (`Stage::finish_held` with the map
        // of that many steps: within half an f32 step of an f64 reference, where stepping in
        // f32 rounds at every step); at most 2^32 - 1 a call, so a longer hold takes several.
        while k < until {
            let steps = (until - k).min(u32::MAX as u64) as u32;
            let mut left = stage.settle_held(&mut s, held, steps);
            // A hold longer than the longest map: maps of that length, then the rest (the
            // fast part stays at its fixed point).
            while left > HELD_MAP_STEPS_MAX {
                stage.finish_held(
                    &mut s,
                    HELD_MAP_STEPS_MAX,
                    maps.get(stage, HELD_MAP_STEPS_MAX),
                );
                left -= HELD_MAP_STEPS_MAX;
            }
            last = stage.finish_held(&mut s, left, maps.get(stage, left));
            k += steps as u64;
        }
        if !go_on(i, last as f64) {
            return None;
        }
        y.push(last as f64);
    }
    Some(y)
}

/// The closed forms of the holds one simulation meets, by their length (a record at a steady
/// rate meets one to three). Bounded: at most [`HeldMaps::MAX_MAPS`] lengths, from
/// [`HeldMaps::MIN_STEPS`] to [`model_core::held::HELD_MAP_STEPS_MAX`] steps; other holds are
/// stepped.
#[derive(Default)]
struct HeldMaps {
    /// (length, its map), in the order met: a linear search over a handful of keys.
    maps: Vec<(u32, Option<HeldMap>)>,
}

impl HeldMaps {
    /// Lengths kept (our assumption: a record's clock jitters over a few lengths at most).
    const MAX_MAPS: usize = 64;
    /// The shortest hold put in closed form: applying a map costs about what four steps do
    /// (measured on the thesis' full stage, session 43: an 8.3 kHz record, four steps left
    /// per hold, simulates 8 % faster with maps; a 28 kHz record, one or two left, 1.6x
    /// slower with a map for every hold).
    const MIN_STEPS: u32 = 4;
    /// The map of `left` steps, built on first use.
    fn get(&mut self, stage: &Stage, left: u32) -> Option<&HeldMap> {
        if !(Self::MIN_STEPS..=HELD_MAP_STEPS_MAX).contains(&left) {
            return None;
        }
        let at = match self.maps.iter().position(|(n, _)| *n == left) {
            Some(at) => at,
            None if self.maps.len() < Self::MAX_MAPS => {
                self.maps.push((left, stage.held_map(left)));
                self.maps.len() - 1
            }
            None => return None,
        };
        self.maps.get(at).and_then(|(_, m)| m.as_ref())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::csv::Record;
    use crate::io::model_file::ModelFile;

    /// A record's clock may start anywhere (a logger's seconds since midnight, or since
    /// 1970): the stage's response at its samples is the same as from zero, to the last bit
    /// of the f32 stage, whether its times are read from a file's text at 5 or 50 kHz.
    #[test]
    fn a_clock_that_starts_late_simulates_as_one_from_zero() {
        let stage = ModelFile::built_in("thesis-linear").unwrap();
        let built = stage.build_stage().unwrap();
        for (rate_hz, start_s) in [(5e3, 1234.5), (50e3, 86_399.0), (5e3, 1.7e9)] {
            let n = (rate_hz * 2.0) as usize;
            let mut from_zero = String::from("t,u\n");
            let mut late = String::from("t,u\n");
            for i in 0..n {
                let t = i as f64 / rate_hz;
                let u = 5.0 - 4.5 * (2.0 * std::f64::consts::PI * t).cos();
                from_zero.push_str(&format!("{t},{u}\n"));
                late.push_str(&format!("{},{u}\n", start_s + t));
            }
            let a = Record::parse(&from_zero).unwrap();
            let b = Record::parse(&late).unwrap();
            let ya = simulate(&built, stage.period_s, &a.t_s, &a.u_v);
            let yb = simulate(&built, stage.period_s, &b.t_s, &b.u_v);
            assert_eq!(ya, yb, "{rate_hz} Hz from {start_s} s");
        }
    }
}
