//! A held stretch of the stage in closed form: the host's simulations of records sampled
//! slower than the stage (not the 50 kHz path, which steps once per sample).
//!
//! # Design notes
//! [`crate::stage::Stage::step_held`] reaches the fixed point of the fast part after a step
//! or two of a held input; from there on only two linear parts move:
//! * the drift's three lags, each `y[k+1] = y[k] + alpha (g w - y[k])` with the weight `w`
//!   held, so `y[k] = g w + e r^k` with `e = y[0] - g w` and `r = 1 - alpha`;
//! * the delayed linear section (the plant, or the 5-state two modes), driven by
//!   `u[k] = C + sum_j e_j r_j^k` (`C` the fast part plus the lags' targets) through its delay
//!   line.
//!
//! Stepped one sample at a time that is a chain of dependent `f32` operations, 50 of them per
//! sample of a 1 kHz record: about a quarter of the model-gap workflow's time (perf on its
//! benchmark, session 43). Both parts are linear in the state at the stretch's start, so
//! `n` steps are one matrix: the section's state after `n` steps is `rows * b`, with `b` its
//! state, the delay line's last `d + 1` inputs, `C` and the three `e_j`. A [`HeldMap`] holds
//! that matrix for one `n`, built in `f64` by running the section's own `f32` coefficients
//! (promoted) on the basis; the lags need only `r_j^n`.
//!
//! The closed form is not the stepped one to the bit: it rounds once where stepping rounds at
//! every step (`f32`, with the lags' compensated sums). The tests bound the difference below
//! a thousandth of a 16-bit ADC code. [`crate::stage::Stage::step_held`] keeps the stepped
//! form; the caller chooses (the host keeps a map per stretch length it meets).
//!
//! Bounded: building a map is `n` steps of a `(d + 5) x 5` product; applying it is one
//! product. Delays of up to [`HELD_WINDOW_MAX`]` - 1` whole samples are covered (the thesis'
//! 85 us is 4); longer ones get no map and are stepped.

use crate::sections::Accumulator;

/// The longest delay line a [`HeldMap`] reads back, in samples: whole delays of up to 15
/// samples (0.3 ms at 50 kHz; the thesis' 85 us is 4.25 samples). Our assumption: the model
/// files' extra delays stay well below it; a longer one is stepped.
pub const HELD_WINDOW_MAX: usize = 16;

/// The largest section order (the two modes' five states).
const ORDER_MAX: usize = 5;

/// The drift's lags.
const LAGS: usize = 3;

/// Columns of a map: the section's states, the delay line's window, the level `C`, the lags'
/// errors.
const COLUMNS: usize = ORDER_MAX + HELD_WINDOW_MAX + 1 + LAGS;

/// `n` steps of a held input, past the fast part's fixed point, as one linear map (see the
/// module's notes). Built by [`crate::stage::Stage::held_map`] for one stage and one `n`.
#[derive(Clone, Debug, PartialEq)]
pub struct HeldMap {
    steps: u32,
    order: usize,
    window: usize,
    /// The section's states after `steps`: `rows[i] . b`.
    rows: [[f64; COLUMNS]; ORDER_MAX],
    /// `tail[m][j] = r_j^(steps - m)`: the lags' decay at the last inputs written to the
    /// delay line (`m = 0`: at the end).
    tail: [[f64; LAGS]; HELD_WINDOW_MAX + 1],
}

/// A delayed linear section's coefficients, as the stage keeps them (`f32`).
pub(crate) struct Section<'a, const P: usize> {
    pub phi: &'a [[f32; P]; P],
    pub gamma_new: &'a [f32; P],
    pub gamma_old: &'a [f32; P],
    pub delay_samples: usize,
}

/// A delayed linear section's state, as the stage keeps it.
pub(crate) struct SectionState<'a, const P: usize, const L: usize> {
    pub x: &'a mut [f32; P],
    pub line: &'a mut [f32; L],
    pub head: &'a mut usize,
}

impl HeldMap {
    /// The steps this map covers.
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// The lags' decay over the stretch, `r_j^steps`.
    pub(crate) fn decay(&self) -> [f64; LAGS] {
        self.tail[0]
    }

    /// Whether this map was built for a section of this order and delay.
    pub(crate) fn fits<const P: usize>(&self, s: &Section<'_, P>) -> bool {
        self.order == P && self.window == s.delay_samples + 1
    }

    /// Build the map of `steps` steps for `section` and the lags' ratios `r_j = 1 - alpha_j`.
    /// `None` for 0 steps, an order above 5 or a delay beyond the window.
    pub(crate) fn build<const P: usize>(
        section: &Section<'_, P>,
        ratios: [f64; LAGS],
        steps: u32,
    ) -> Option<Self> {
        let window = section.delay_samples + 1;
        if steps == 0 || P > ORDER_MAX || window > HELD_WINDOW_MAX {
            return None;
        }
        let level = P + window;
        let errors = level + 1;
        let d = section.delay_samples as i64;
        // Each state as a row of coefficients over the basis; at the start, itself.
        let mut x = [[0.0f64; COLUMNS]; ORDER_MAX];
        for (i, row) in x.iter_mut().enumerate().take(P) {
            row[i] = 1.0;
        }
        let mut tail = [[0.0f64; LAGS]; HELD_WINDOW_MAX + 1];
        // r_j^k at step k, and at the inputs the section reads (k - d and k - d - 1).
        let mut power = [1.0f64; LAGS];
        let mut read_new = [1.0f64; LAGS];
        let mut read_old;
        let input = |i: i64, pw: &[f64; LAGS], out: &mut [f64; COLUMNS]| {
            *out = [0.0; COLUMNS];
            if i <= 0 {
                // An input written before the stretch: the window's entry of that age.
                if let Some(c) = out.get_mut(P + (-i) as usize) {
                    *c = 1.0;
                }
            } else {
                out[level] = 1.0;
                out[errors..errors + LAGS].copy_from_slice(pw);
            }
        };
        let mut u_new = [0.0f64; COLUMNS];
        let mut u_old = [0.0f64; COLUMNS];
        for k in 1..=steps as i64 {
            for (p, r) in power.iter_mut().zip(ratios) {
                *p *= r;
            }
            read_old = read_new;
            if k - d >= 1 {
                for (p, r) in read_new.iter_mut().zip(ratios) {
                    *p *= r;
                }
            }
            input(k - d, &read_new, &mut u_new);
            input(k - d - 1, &read_old, &mut u_old);
            let before = x;
            for (i, row) in x.iter_mut().enumerate().take(P) {
                for (c, v) in row.iter_mut().enumerate().take(errors + LAGS) {
                    *v = section.gamma_new[i] as f64 * u_new[c]
                        + section.gamma_old[i] as f64 * u_old[c];
                    for (l, b) in before.iter().enumerate().take(P) {
                        *v += section.phi[i][l] as f64 * b[c];
                    }
                }
            }
            let m = steps as i64 - k;
            if let Some(t) = usize::try_from(m).ok().and_then(|m| tail.get_mut(m)) {
                *t = power;
            }
        }
        Some(Self {
            steps,
            order: P,
            window,
            rows: x,
            tail,
        })
    }

    /// Advance `state` over the stretch with the level `level` and the lags' errors `errors`
    /// (their values less their targets at the start): the section's states, the delay line
    /// (its last `d + 2` entries, all that later steps read) and its head.
    pub(crate) fn apply<const P: usize, const L: usize>(
        &self,
        state: SectionState<'_, P, L>,
        level: f64,
        errors: [f64; LAGS],
    ) {
        let mut b = [0.0f64; COLUMNS];
        for (bi, xi) in b.iter_mut().zip(state.x.iter()) {
            *bi = *xi as f64;
        }
        let head = *state.head;
        for m in 0..self.window {
            let at = (head + L - m % L) % L;
            b[P + m] = state.line.get(at).copied().unwrap_or(0.0) as f64;
        }
        b[P + self.window] = level;
        b[P + self.window + 1..P + self.window + 1 + LAGS].copy_from_slice(&errors);
        for (xi, row) in state.x.iter_mut().zip(&self.rows) {
            *xi = row.iter().zip(&b).map(|(r, v)| r * v).sum::<f64>() as f32;
        }
        let steps = self.steps as usize;
        for m in 0..(self.window + 1).min(steps) {
            let t = self.tail[m];
            let u = level + (0..LAGS).map(|j| errors[j] * t[j]).sum::<f64>();
            if let Some(slot) = state.line.get_mut((head + steps - m) % L) {
                *slot = u as f32;
            }
        }
        *state.head = (head + steps) % L;
    }
}

/// The lag's value after a stretch: its target plus its error decayed.
pub(crate) fn lag_after(target: f64, error: f64, decay: f64) -> Accumulator {
    Accumulator::from_exact(target + error * decay)
}
