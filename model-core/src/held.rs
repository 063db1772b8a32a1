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
//! every step (`f32`, with the lags' compensated sums). The tests bound it within half an
//! `f32` step of an `f64` reference of the same recursions, and within a twentieth (the plant)
//! to a quarter (the lightly damped two modes, where the stepped form's own rounding builds
//! up) of a 16-bit ADC code of the stepped form. [`crate::stage::Stage::step_held`] keeps the
//! stepped form; the caller chooses (the host keeps a map per stretch length it meets).
//!
//! Bounded: building a map is `n` steps of a `P x (P + d + 5)` product; applying it is one
//! product. Every delay the plant's line holds is covered. A map carries a fingerprint of the
//! coefficients it was built from, and a stage applies only its own.

/// The longest delay line a [`HeldMap`] reads back, in samples: the plant's whole line
/// ([`crate::plant::MAX_DELAY_SAMPLES`]; the thesis' 85 us is 4.25 samples).
pub const HELD_WINDOW_MAX: usize = crate::plant::MAX_DELAY_SAMPLES;

/// The longest stretch a host builds one map for: building costs the map's length in small
/// products, so a longer hold takes several (50 000 steps: 1 s at 50 kHz, a 1 Hz record's
/// sample; our assumption).
pub const HELD_MAP_STEPS_MAX: u32 = 50_000;

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
    /// The fingerprint of the coefficients it was built from ([`fingerprint`]).
    key: u64,
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

    /// The fingerprint of the coefficients it was built from.
    pub(crate) fn key(&self) -> u64 {
        self.key
    }

    /// Build the map of `steps` steps for `section` and the lags' ratios `r_j = 1 - alpha_j`,
    /// carrying `key` (their [`fingerprint`]). `None` for 0 steps, an order above 5 or a
    /// delay beyond the window.
    pub(crate) fn build<const P: usize>(
        section: &Section<'_, P>,
        ratios: [f64; LAGS],
        steps: u32,
        key: u64,
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
            key,
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
        // (Only the columns this section's basis uses: its states, its window, C, the lags.)
        let used = P + self.window + 1 + LAGS;
        for (xi, row) in state.x.iter_mut().zip(&self.rows) {
            *xi = row
                .iter()
                .zip(&b)
                .take(used)
                .map(|(r, v)| r * v)
                .sum::<f64>() as f32;
        }
        let steps = self.steps as usize;
        // (The head's offset taken modulo the line first: no overflow for any `steps`.)
        let end = (head + steps % L) % L;
        for m in 0..(self.window + 1).min(steps) {
            let t = self.tail[m];
            let u = level + (0..LAGS).map(|j| errors[j] * t[j]).sum::<f64>();
            if let Some(slot) = state.line.get_mut((end + L - m % L) % L) {
                *slot = u as f32;
            }
        }
        *state.head = end;
    }
}

/// The fingerprint of a section's coefficients and the lags' ratios (FNV-1a over their bits
/// and the delay): what a [`HeldMap`] is built from.
pub(crate) fn fingerprint<const P: usize>(section: &Section<'_, P>, ratios: [f64; LAGS]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bits: u64| {
        h ^= bits;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    };
    eat(P as u64);
    eat(section.delay_samples as u64);
    for row in section.phi {
        row.iter().for_each(|v| eat(v.to_bits() as u64));
    }
    section
        .gamma_new
        .iter()
        .for_each(|v| eat(v.to_bits() as u64));
    section
        .gamma_old
        .iter()
        .for_each(|v| eat(v.to_bits() as u64));
    ratios.iter().for_each(|v| eat(v.to_bits()));
    h
}
