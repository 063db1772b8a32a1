//! The hysteresis form of the model-gap workflow (issue #12 item 2): a Preisach model fitted
//! as weights on a basis of band-limited play operators, whose result is the model-core
//! Everett table ([`model_core::hysteresis::HysteresisTable`], 3980 bytes) the stage and the
//! firmware's feedforward run. One representation from identification to board.
//!
//! # The basis
//! A Preisach model sums relays `gamma(alpha, beta)` weighted by a density `mu >= 0`. Write a
//! relay by its centre `c = (alpha + beta) / 2` and half-width `r = (alpha - beta) / 2`. All the
//! relays of one half-width `r` with centres spread uniformly make a play operator of radius
//! `r` (Prandtl-Ishlinskii: symmetric, congruent loops everywhere); those with centres in one
//! band `[c_k, c_k+1]` make a **band-limited play operator**, whose output is the play
//! operator's position clamped to the band. A weight per (radius, band) pair is a density that
//! is piecewise constant along the centre and free along the width: narrow and wide
//! operators, loops that differ from one end of the range to the other (asymmetric loops, a
//! loop that is wider at the top), any shape of Everett table at that resolution.
//!
//! Each basis element `(r, k)` has the Everett function
//!
//! ```text
//!     T_rk(a, b) = | [ max(c_k, b + r), min(c_k+1, a - r) ] |      (length of the interval, >= 0)
//! ```
//!
//! with the relays clipped to the table's range (`b + r` read as `-inf` at the bottom node,
//! `a - r` as `+inf` at the top one: a relay whose threshold lies beyond the range switches
//! at its end),
//!
//! and enters the fit as a **loop-only column**: the response of the model-core table with
//! `T_rk` as its grid, minus the reversible part of the same relays (`clamp(u, c_k, c_k+1)`):
//! with no hysteresis the columns vanish, the base model's `static_gain * u` stays the
//! reversible map, and curvature of that map is left to `nonlinear-gain` (so the two effects
//! stay apart). Because the column *is* the table's own response (same grid, bilinear
//! interpolation, turning-point memory, start on the major rising curve as
//! [`model_core::stage::Stage`] starts), the fitted table reproduces the fit exactly: the
//! weights `m_rk >= 0` become the grid
//!
//! ```text
//!     E(a, b) = g (a - b) + sum_rk m_rk ( T_rk(a, b) - |[b, a] ^ [c_k, c_k+1]| ),   offset g lo
//! ```
//!
//! (`g` the plant's static gain), which the stage checks as any table (non-negative, rising in
//! `a`, falling in `b`: the reversible slope must stay positive).
//!
//! The table is the whole static map, as the thesis' is: one more column per band,
//! `clamp(u, c_k, c_k+1) - c_k` with a weight of either sign, lets the reversible slope
//! change along the range (`+ s_k |[b, a] ^ band_k|` in `E`). Without it, the curvature a
//! non-Preisach loop (Bouc-Wen) leaves in the reversible part is named `nonlinear-gain`; with
//! it, `nonlinear-gain` is named beside `hysteresis` only when the records show a curvature the
//! table's four slopes cannot take (a stage's K'(u) and its Everett table are one static map
//! to any record: the workflow says so in GAP.md rather than guess).
//!
//! # Resolution and regulariser
//! Radii: [`HYST_RADII`] at odd multiples of half the table's grid interval ([`radius_v`]:
//! the basis follows the table's own resolution instead of a fixed list of radii);
//! bands: [`HYST_BANDS`] over the records' input span, edges on
//! grid nodes. The table spans the records' inputs ([`hyst_range`]). The weights of one
//! radius in adjacent bands are tied by a smoothness penalty (Tikhonov on their differences,
//! [`HYST_BAND_SMOOTH`] times the mean Gram diagonal of that radius): a record that excites
//! one band only, or cannot tell the bands apart, gets equal weights (a play operator); one
//! whose loops differ along the range pays the penalty for the difference it shows.

use crate::io::model_file::HysteresisSection;
use model_core::hysteresis::{
    GRID_NODES, HysteresisMemory, HysteresisTable, TABLE_LEN, packed_index,
};
use model_core::params;

/// Bands along the Preisach plane's centre axis (our assumption: four resolve a loop that
/// narrows or widens along the range, as the thesis' table and PI stages with
/// input-dependent weights do, at four times the columns of a play sum; 44 grid intervals
/// divide into four bands of 11).
pub const HYST_BANDS: usize = 4;

/// Radii of the basis: one per odd multiple of half a grid interval up to the span's half
/// ([`radius_v`]).
pub const HYST_RADII: usize = INTERVALS / 2;

/// Loop columns of the basis: every (radius, band) pair, radius-major.
pub const HYST_LOOP_COLS: usize = HYST_RADII * HYST_BANDS;

/// Columns of the basis: the loop columns, then one reversible column per band
/// ([`rev_col`]).
pub const HYST_COLS: usize = HYST_LOOP_COLS + HYST_BANDS;

/// Column index of band `k`'s reversible part (`clamp(u, band) - c_k`: a change of the
/// reversible slope within the band; sign free).
pub const fn rev_col(k: usize) -> usize {
    HYST_LOOP_COLS + k
}

/// Are the reversible slopes of the bands fitted with the loop (`false`: their columns stay
/// zero and the table's reversible map is the base model's `static_gain * u`)? A table is the
/// whole static map, so with them a scale error and a curvature of the centre line
/// (`sensor-gain`, `nonlinear-gain`) disappear into the table and are never named; without
/// them the split is the catalogue's: `hysteresis` the loop about the centre line, the other
/// two the centre line's scale and shape. Measured on the randomised families suite: with
/// them 67 % exact, 17 % false names, 29 effects missed (mostly the scale or curvature beside
/// a loop).
pub const HYST_FIT_REVERSIBLE: bool = false;

/// The basis columns the fit solves for: the loop columns, and the reversible ones if
/// [`HYST_FIT_REVERSIBLE`].
pub const HYST_FIT_COLS: usize = if HYST_FIT_REVERSIBLE {
    HYST_COLS
} else {
    HYST_LOOP_COLS
};

/// Weight of the smoothness penalty between adjacent bands of one radius, as a fraction of
/// that radius' mean Gram diagonal (our assumption: a difference between bands is kept when
/// it lowers the weighted residual power by more than a tenth of what the radius' column
/// itself carries; tested on PI truths, where it must leave the bands equal, and on
/// asymmetric Everett truths, where it must not).
pub const HYST_BAND_SMOOTH: f64 = 0.1;

/// Grid intervals of the table.
const INTERVALS: usize = GRID_NODES - 1;
const _: () = assert!(INTERVALS.is_multiple_of(HYST_BANDS));

/// Margin of the table's range beyond the records' inputs, volts (our assumption, measured on
/// the single-sine records of issue #12: without it a 1 Hz sine over 0.5..9.5 V of a PI truth
/// was fitted to 170 mV, with 0.5 V to 16 mV before any start memory). A relay whose lower
/// threshold lies below the records' lowest input never switches off during them (a stage
/// whose earlier motion went lower keeps it on), and one whose upper threshold lies above
/// their highest input never switches on. A table that ends at the records' extremes clips
/// those relays onto its edges, where every visit switches them: the loop gets a drop at its
/// ends that the stage does not have. The margin gives them room; whether they are on at the
/// start is the start memory's part ([`start_candidates`]).
pub const HYST_RANGE_MARGIN_V: f64 = 0.5;

/// The table's input range for records whose inputs span `lo..hi` volts: that span widened by
/// [`HYST_RANGE_MARGIN_V`] each side, kept within the amplifier's input range and at least
/// 1 V wide.
pub fn hyst_range(lo: f64, hi: f64) -> (f64, f64) {
    let lo =
        (lo - HYST_RANGE_MARGIN_V).clamp(params::AMP_INPUT_MIN_V, params::AMP_INPUT_MAX_V - 1.0);
    let hi = (hi + HYST_RANGE_MARGIN_V).clamp(lo + 1.0, params::AMP_INPUT_MAX_V);
    (lo, hi)
}

/// The start memories tried for records whose first input is `u0_v`, on a table over `range`
/// (turning points after coming up from the bottom, as `[hysteresis] start_turns_v`): none
/// (the major rising curve); came down from above (`[p]`, five heights); came down from the
/// top to `v` and up again (`[hi, v]`, three depths); and a decaying oscillation around
/// `u0` (`u0 +- A, u0 -+ 0.6 A, ...` down to 1 % of the span, three amplitudes, first
/// excursion up or down: the state a stage is left in after a scan that died away, close to
/// the Preisach plane's anti-diagonal). Our assumption: a lab record starts from rest after
/// one of these; 15 candidates, each checked in one simulation of the fitted model.
pub fn start_candidates(u0_v: f64, range: (f64, f64)) -> Vec<Vec<f64>> {
    let (lo, hi) = range;
    let u0 = u0_v.clamp(lo, hi);
    let span = hi - lo;
    let mut out: Vec<Vec<f64>> = vec![vec![]];
    for f in [0.125, 0.25, 0.5, 0.75, 1.0] {
        let p = u0 + (hi - u0) * f;
        if p - u0 > 0.01 * span {
            out.push(vec![p]);
        }
    }
    for f in [0.25, 0.5, 0.75] {
        let v = lo + (u0 - lo) * f;
        if u0 - v > 0.01 * span && v - lo > 0.01 * span {
            out.push(vec![hi, v]);
        }
    }
    for a in [0.125, 0.25, 0.5] {
        for sign in [1.0, -1.0] {
            let mut amp = a * span;
            let mut s = sign;
            let mut h = Vec::new();
            while amp > 0.01 * span && h.len() < crate::io::model_file::MAX_START_TURNS {
                h.push((u0 + s * amp).clamp(lo, hi));
                amp *= 0.6;
                s = -s;
            }
            out.push(h);
        }
    }
    out
}

/// Node `i` of the grid over `range`, volts.
fn node_v(range: (f64, f64), i: usize) -> f64 {
    range.0 + (range.1 - range.0) * i as f64 / INTERVALS as f64
}

/// Edges of band `k`, volts.
fn band_v(range: (f64, f64), k: usize) -> (f64, f64) {
    let per = INTERVALS / HYST_BANDS;
    (node_v(range, k * per), node_v(range, (k + 1) * per))
}

/// Column index of (radius `i`, band `k`).
pub const fn col(i: usize, k: usize) -> usize {
    i * HYST_BANDS + k
}

/// Band-limited play operator `(r, band)`'s Everett function at `(a, b)` on a table over
/// `range`: the measure of the centres `c` in the band whose relay, clipped to the range
/// (thresholds `max(c - r, lo)` and `min(c + r, hi)`), lies inside `[b, a]`. Clipped, a relay
/// near an end of the range still switches within it, so the column stays loop-only there
/// (unclipped, the relays that would need an input beyond the range never switch and leave
/// a constant and a ramp in the column that an `offset` then soaks up).
fn t_rk(a: f64, b: f64, r: f64, band: (f64, f64), range: (f64, f64)) -> f64 {
    let from = if b <= range.0 {
        f64::NEG_INFINITY
    } else {
        b + r
    };
    let to = if a >= range.1 { f64::INFINITY } else { a - r };
    (band.1.min(to) - band.0.max(from)).max(0.0)
}

/// The reversible part of the band's relays at `(a, b)`: the length of `[b, a]` inside it.
fn l_k(a: f64, b: f64, band: (f64, f64)) -> f64 {
    (band.1.min(a) - band.0.max(b)).max(0.0)
}

/// The grid of `f(a, b)` at the nodes, packed.
fn grid(range: (f64, f64), f: impl Fn(f64, f64) -> f64) -> Vec<f32> {
    let mut e = vec![0.0f32; TABLE_LEN];
    for i in 1..GRID_NODES {
        for j in 0..i {
            if let Some(p) = packed_index(i, j) {
                e[p] = f(node_v(range, i), node_v(range, j)) as f32;
            }
        }
    }
    e
}

/// The smallest grid above `e` that model-core accepts: non-negative, rising in `alpha`,
/// falling in `beta` (running maxima along both directions; the second keeps the first).
/// The weights are non-negative but the reversible slopes of the bands have either sign,
/// and a band whose loop columns outweigh its slope leaves a grid with a falling branch: a
/// stage the table cannot be. The repair is small where the fit is near-valid and the
/// candidate is scored on its full simulation, so a large repair only costs it the step.
fn monotone(mut e: Vec<f32>) -> Vec<f32> {
    let at = |i: usize, j: usize| packed_index(i, j);
    // Rising in alpha: E(i, j) >= E(i - 1, j), with E(j, j) = 0.
    for j in 0..GRID_NODES - 1 {
        let mut run = 0.0f32;
        for i in j + 1..GRID_NODES {
            if let Some(p) = at(i, j) {
                run = run.max(e[p]);
                e[p] = run;
            }
        }
    }
    // Falling in beta: E(i, j) >= E(i, j + 1), with E(i, i) = 0.
    for i in 1..GRID_NODES {
        let mut run = 0.0f32;
        for j in (0..i).rev() {
            if let Some(p) = at(i, j) {
                run = run.max(e[p]);
                e[p] = run;
            }
        }
    }
    e
}

/// Radius `i` of the basis on a table over `range`, volts: `2 i + 1` half grid intervals.
///
/// On the table's nodes, where its bilinear interpolation reads it, a band-limited play
/// operator's Everett function is piecewise linear in its radius with breaks only at
/// half-interval multiples (where `b + r`, `a - r` or `b + r = a - r` cross a node). An operator
/// whose radius lies between two radii of the basis is, on the nodes, the mix of its two
/// neighbours except at the one break between them (a node error of at most its weight times
/// half an interval, at one node distance), and one narrower than half an interval is exactly
/// the mix of the first radius and of none (a reversible part). So a truth's radii (a PI
/// stage's, a Preisach density's) need not be guessed: measured on the single-sine records
/// of issue #12 (Prandtl-Ishlinskii truths with random radii), the fixed geometric list this
/// replaced (16 radii, 30 mV..5 V, ratio 1.41: gaps of 1 V between the widest) left 14.9 and
/// 16.0 mV after the hysteresis step, this basis 10.8 and 9.1 mV. Every half interval (43
/// radii) instead of every other one gained another 0.8 mV for seven times the solves'
/// cubic cost (the gap bench 15 s -> 27 s).
pub fn radius_v(range: (f64, f64), i: usize) -> f64 {
    (2 * i + 1) as f64 * (range.1 - range.0) / (2 * INTERVALS) as f64
}

/// The loop-only columns at `rows` of a record with inputs `u_v`: for each (radius, band)
/// the table's response minus the band's reversible part (zero for radii not used).
pub fn columns(u_v: &[f64], rows: &[usize], range: (f64, f64), start_v: &[f64]) -> Vec<Vec<f64>> {
    let start: Vec<f32> = start_v.iter().map(|&v| v as f32).collect();
    let mut out = vec![vec![0.0; rows.len()]; HYST_COLS];
    for i in 0..HYST_RADII {
        let r = radius_v(range, i);
        for k in 0..HYST_BANDS {
            let band = band_v(range, k);
            let e = grid(range, |a, b| t_rk(a, b, r, band, range));
            let Ok(t) = HysteresisTable::from_grid(range.0 as f32, range.1 as f32, 0.0, &e) else {
                continue;
            };
            let mut mem = HysteresisMemory::new();
            mem.reset_after(&t, &start, u_v[0] as f32);
            let c = &mut out[col(i, k)];
            // (the reversible columns are filled below)
            let mut next = 0usize;
            let mut y = mem.output_v();
            for (j, &row) in rows.iter().enumerate() {
                while next <= row {
                    y = t.forward(&mut mem, u_v[next] as f32);
                    next += 1;
                }
                let u = u_v[row].clamp(range.0, range.1);
                c[j] = y as f64 - (u.clamp(band.0, band.1) - band.0);
            }
        }
    }
    for k in 0..HYST_BANDS {
        let band = band_v(range, k);
        out[rev_col(k)] = rows
            .iter()
            .map(|&row| u_v[row].clamp(range.0, range.1).clamp(band.0, band.1) - band.0)
            .collect();
    }
    out
}

/// Adds the smoothness penalty between adjacent bands to the Gram block of the basis, whose
/// column `c` sits at `at(c)` in `g` (`None`: not in the solve).
pub fn add_band_penalty(g: &mut nalgebra::DMatrix<f64>, at: impl Fn(usize) -> Option<usize>) {
    for i in 0..HYST_RADII {
        let idx: Vec<usize> = (0..HYST_BANDS).filter_map(|k| at(col(i, k))).collect();
        if idx.len() != HYST_BANDS {
            continue;
        }
        let mean = idx.iter().map(|&p| g[(p, p)]).sum::<f64>() / HYST_BANDS as f64;
        let lam = HYST_BAND_SMOOTH * mean;
        if lam <= 0.0 || !lam.is_finite() {
            continue;
        }
        for w in idx.windows(2) {
            let (p, q) = (w[0], w[1]);
            g[(p, p)] += lam;
            g[(q, q)] += lam;
            g[(p, q)] -= lam;
            g[(q, p)] -= lam;
        }
    }
}

/// The fitted hysteresis: the table's range and the basis weights.
#[derive(Clone, Debug, PartialEq)]
pub struct HystFit {
    /// Input range of the table, volts.
    pub range: (f64, f64),
    /// Weight of each (radius, band) column, sensor volts per volt.
    pub weights: Vec<f64>,
    /// The start memory the columns were computed with (`[hysteresis] start_turns_v`).
    pub start_v: Vec<f64>,
}

impl HystFit {
    /// The `[hysteresis]` section: the Everett grid of `g u` plus the weighted basis
    /// ([`Self::grid_v`]), repaired into a table the stage accepts where it is not one
    /// (`monotone`; a fit whose bands keep their loop weights within the reversible slope needs
    /// no repair, see `slow_fit`'s validity penalty).
    pub fn section(&self, static_gain: f64) -> HysteresisSection {
        let range = self.range;
        let e = monotone(self.grid_v(static_gain));
        HysteresisSection {
            input_range_v: [range.0, range.1],
            offset_v: static_gain * range.0,
            dc_gain: None,
            loop_width_frac: None,
            everett_v: Some(e),
            start_turns_v: (!self.start_v.is_empty()).then(|| self.start_v.clone()),
        }
    }

    /// The Everett grid of `g u` plus the weighted basis, before any repair:
    /// `E(a, b) = g (a - b) + sum_k s_k |[b, a] ^ band_k| + sum_rk m_rk (T_rk - |[b, a] ^ band_k|)`.
    pub fn grid_v(&self, static_gain: f64) -> Vec<f32> {
        let range = self.range;
        let bands: Vec<(f64, f64)> = (0..HYST_BANDS).map(|k| band_v(range, k)).collect();
        grid(range, |a, b| {
            let mut v = static_gain * (a - b);
            for (k, band) in bands.iter().enumerate() {
                v += self.weights[rev_col(k)] * l_k(a, b, *band);
            }
            for i in 0..HYST_RADII {
                let r = radius_v(range, i);
                for (k, band) in bands.iter().enumerate() {
                    let w = self.weights[col(i, k)];
                    if w != 0.0 {
                        v += w * (t_rk(a, b, r, *band, range) - l_k(a, b, *band));
                    }
                }
            }
            v
        })
    }
}

/// Figures of a fitted table for tables and JSON: its range, and the width of its full-range
/// major loop (largest falling-minus-rising output at a node, sensor volts) in the lower and
/// upper half of the range.
pub fn summary(h: &HysteresisSection) -> Vec<(String, f64)> {
    let Ok(t) = h.table() else {
        return vec![];
    };
    let (lo, hi) = t.input_range_v();
    let mut mem = HysteresisMemory::new();
    mem.reset(&t, lo);
    let nodes: Vec<f32> = (0..GRID_NODES).map(|k| t.node_v(k)).collect();
    let rising: Vec<f32> = nodes.iter().map(|&u| t.forward(&mut mem, u)).collect();
    let falling: Vec<f32> = nodes
        .iter()
        .rev()
        .map(|&u| t.forward(&mut mem, u))
        .collect();
    let width = |range: std::ops::Range<usize>| {
        range
            .map(|k| (falling[GRID_NODES - 1 - k] - rising[k]) as f64)
            .fold(0.0f64, f64::max)
    };
    let half = GRID_NODES / 2;
    let mut out = vec![
        ("range_lo_v".into(), lo as f64),
        ("range_hi_v".into(), hi as f64),
        ("loop_width_low_v".into(), width(0..half)),
        ("loop_width_high_v".into(), width(half..GRID_NODES)),
    ];
    // The start memory, when it is not the major rising curve: how many turning points and
    // the first (highest reach) of them.
    if let Some(turns) = h.start_turns_v.as_ref().filter(|t| !t.is_empty()) {
        out.push(("start_turns".into(), turns.len() as f64));
        out.push(("start_first_turn_v".into(), turns[0]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The section's table, driven by the same input, gives `g u + sum w column` (the fit's
    /// model) to f32 rounding: the basis and the table are one representation.
    #[test]
    fn the_table_reproduces_the_weighted_columns() {
        let range = (0.5, 7.5);
        let n = 4000;
        let u: Vec<f64> = (0..n)
            .map(|i| {
                let t = i as f64 / n as f64;
                4.0 + 3.0 * (2.0 * std::f64::consts::PI * 3.0 * t).sin() * (1.0 - 0.7 * t)
                    + 0.4 * (2.0 * std::f64::consts::PI * 17.0 * t).sin()
            })
            .collect();
        let rows: Vec<usize> = (0..n).step_by(7).collect();
        let cols = columns(&u, &rows, range, &[]);
        let mut weights = vec![0.0; HYST_COLS];
        // An asymmetric density: wide operators at the top, narrow ones at the bottom.
        weights[col(2, 0)] = 0.3;
        weights[col(6, 1)] = 0.1;
        weights[col(9, 3)] = 0.08;
        weights[col(12, 2)] = 0.02;
        weights[rev_col(2)] = -0.1;
        weights[rev_col(3)] = 0.05;
        let g = params::PLANT_GAIN;
        let fit = HystFit {
            range,
            weights: weights.clone(),
            start_v: vec![],
        };
        let t = fit.section(g).table().expect("a valid table");
        let mut mem = HysteresisMemory::new();
        mem.reset(&t, u[0] as f32);
        let y: Vec<f32> = u.iter().map(|&v| t.forward(&mut mem, v as f32)).collect();
        let mut worst = 0.0f64;
        for (j, &row) in rows.iter().enumerate() {
            let model = g * u[row] + (0..HYST_COLS).map(|c| weights[c] * cols[c][j]).sum::<f64>();
            worst = worst.max((model - y[row] as f64).abs());
        }
        // f32 table values of up to ~6 V: a few ulps (0.5 uV each) summed over the segments.
        assert!(worst < 2e-5, "table vs weighted columns: {worst} V");
        // And the loop is really there: the columns are not all flat.
        let swing = cols[col(9, 3)].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(swing > 0.5 * radius_v(range, 9), "column swing {swing}");
    }

    /// A valid grid is kept as it is; an invalid one is lifted to the smallest valid grid.
    #[test]
    fn the_repaired_grid_is_a_valid_table_and_keeps_a_valid_one() {
        let range = (0.0, 10.0);
        // A valid grid is left as it is.
        let good = grid(range, |a, b| 0.8 * (a - b) + 0.05 * (a - b).powi(2));
        assert_eq!(monotone(good.clone()), good);
        // A grid with a falling branch (a negative slope in the middle band) is lifted to
        // the smallest valid grid above it: accepted, and no node lowered.
        let bad = grid(range, |a, b| {
            let f = |u: f64| u - 1.5 * (u.clamp(4.0, 6.0) - 4.0);
            f(a) - f(b)
        });
        assert!(HysteresisTable::from_grid(0.0, 10.0, 0.0, &bad).is_err());
        let fixed = monotone(bad.clone());
        assert!(HysteresisTable::from_grid(0.0, 10.0, 0.0, &fixed).is_ok());
        assert!(fixed.iter().zip(&bad).all(|(f, b)| f >= b));
    }

    /// The validity rule `slow_fit` keeps: non-negative loop weights whose sum in each band
    /// stays within the reversible slope give a grid the stage accepts with no repair (random
    /// weights, every radius and band); a band whose weights exceed the slope by half gives a
    /// grid that falls near its diagonal.
    #[test]
    fn loop_weights_within_the_reversible_slope_need_no_repair() {
        use rand::{Rng, SeedableRng};
        let g = params::PLANT_GAIN;
        for seed in 0..20u64 {
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let range = (rng.gen_range(-1.0..2.0), rng.gen_range(6.0..10.0));
            let mut weights = vec![0.0; HYST_COLS];
            for k in 0..HYST_BANDS {
                let raw: Vec<f64> = (0..HYST_RADII)
                    .map(|_| {
                        if rng.gen_bool(0.4) {
                            rng.gen_range(0.0..1.0)
                        } else {
                            0.0
                        }
                    })
                    .collect();
                let total: f64 = raw.iter().sum::<f64>().max(1e-9);
                // Band sums from a tenth of the slope up to the whole of it.
                let share = rng.gen_range(0.1..1.0) * g;
                for (i, w) in raw.iter().enumerate() {
                    weights[col(i, k)] = w / total * share;
                }
            }
            let fit = HystFit {
                range,
                weights: weights.clone(),
                start_v: vec![],
            };
            let raw = fit.grid_v(g);
            assert_eq!(
                monotone(raw.clone()),
                raw,
                "seed {seed}: a valid fit was repaired"
            );
            // Band 1 at 1.5 times the slope, on its narrowest radius: a falling branch.
            for i in 0..HYST_RADII {
                weights[col(i, 1)] = 0.0;
            }
            weights[col(0, 1)] = 1.5 * g;
            let over = HystFit {
                range,
                weights,
                start_v: vec![],
            }
            .grid_v(g);
            assert_ne!(
                monotone(over.clone()),
                over,
                "seed {seed}: an invalid fit passed"
            );
        }
    }

    #[test]
    fn zero_weights_give_the_linear_map() {
        let fit = HystFit {
            range: (0.0, 10.0),
            weights: vec![0.0; HYST_COLS],
            start_v: vec![],
        };
        let t = fit.section(0.79).table().unwrap();
        let mut mem = HysteresisMemory::new();
        for u in [0.0f32, 3.0, 7.5, 2.0, 9.0] {
            assert!((t.forward(&mut mem, u) - 0.79 * u).abs() < 1e-5);
        }
    }
}
