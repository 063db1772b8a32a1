//! The open-loop response of a model to a recorded input (`piezo simulate`, `piezo synth` and
//! the model-gap workflow all simulate through [`simulate`]).
//!
//! The stage runs at its own fixed step (the model's `period_s`) whatever the record's rate:
//! the record's `u` is held from each sample time to the next (as a DAC would hold it), and
//! `y` at each record time is the sensor reading of the last stage step at or before that time.
//! The stage starts at rest with the first input held for ever (drift settled). `piezo simulate`
//! writes the columns `t,u,y` at the input's sample times.

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
    let n = t_s.len().min(u_v.len());
    let mut y = Vec::with_capacity(n);
    if n == 0 {
        return y;
    }
    let t0 = t_s[0];
    let mut s = stage.steady_state_after(history_v, u_v[0] as f32);
    let mut last = s.signals().measured_v;
    // Steps taken so far; step k ends at t0 + k T.
    let mut k: u64 = 0;
    for i in 0..n {
        // Steps ending at or before t[i] were driven by earlier samples.
        let until = ((t_s[i] - t0) / period_s + 1e-9).floor().max(0.0) as u64;
        let held = if i == 0 { u_v[0] } else { u_v[i - 1] } as f32;
        while k < until {
            last = stage.step(&mut s, held);
            k += 1;
        }
        y.push(last as f64);
    }
    y
}
