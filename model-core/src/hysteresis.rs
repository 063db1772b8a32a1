//! Rate-independent hysteresis of the piezo stack (sec. 3.2, 5.3) as a compact Everett table
//! with a bounded turning-point memory: the static map from amplifier control-input volts to
//! sensor monitor volts, forward (prediction) and inverse (feedforward compensation).
//!
//! (One file over 900 lines on purpose: the table, its turning-point memory, the forward map
//! and the inverse are one idea; forward and inverse share the reversal step and the memory's
//! invariants, and splitting them would spread those invariants over files.)
//!
//! # Formulation: the Everett function of a Preisach model
//! The Preisach model (sec. 5.3.2, eq. 5.4) writes the output as a weighted sum of relays
//! `gamma_ab` that switch on when the input rises to `a` and off when it falls to `b`
//! (`a >= b`). Its weight function `mu(a, b)` is what the thesis could not obtain: it is the
//! second mixed derivative of measured curves, and differentiating noisy data twice "amplifies
//! the noise to such an extent that the data obtained is virtually useless".
//!
//! We never need `mu`. The *Everett function* is its integral over a triangle,
//! `E(a, b) = integral of mu over { b <= b' <= a' <= a }`, and it is measured directly, without
//! any derivative, by the first-order reversal curves (FORC) the thesis records (sec. 5.3.4):
//! start from the bottom `u_min` of the range, rise along the major rising curve to a turning
//! value `a`, output `y_a`, then fall to `b`, output `y_ab`:
//!
//! ```text
//!     E(a, b) = y_a - y_ab                 (E(a, a) = 0; E >= 0)
//! ```
//!
//! For *any* input history the output follows from the stored turning points alone. With the
//! alternating sequence `s_0 = u_min < s_1 > s_2 < ...` of the turning points still in memory
//! (after wiping out) and the current input `u = s_{n+1}`,
//!
//! ```text
//!     y(u) = y0 + sum_k  sign_k * E(max(s_{k-1}, s_k), min(s_{k-1}, s_k))
//! ```
//!
//! with `sign_k = +1` on rising segments and `-1` on falling ones. Higher-order reversal curves
//! (reversals that start on a reversal curve) are therefore predicted from the *same* FORC data
//! (sums of differences of first-order curves), and every minor loop closes exactly
//! (return-point memory).
//!
//! **What the thesis' polynomial model could not do** (sec. 5.3.4): it fitted one polynomial per
//! first-order reversal curve and interpolated between neighbours by the turning value, so it
//! "can be used to approximate only the behavior of the major rising and the first order
//! reversal curves"; a reversal that starts on a reversal curve (the decaying sine, steps in a
//! point-to-point move) had no curve to follow, and rising curves after a reversal were all
//! replaced by the one major rising curve. Here each segment is an Everett difference from its
//! own turning point, so second, third, ... order curves come out of the same table, and the
//! rising curve after a reversal at `b` is `y_b + E(u, b)`, not the major rising curve.
//!
//! # Storage: a triangle of grid values, bilinear in between
//! `E` is sampled on a uniform grid of [`GRID_NODES`] nodes per axis over the input range,
//! keeping only the strict lower triangle `alpha_i > beta_j` ([`TABLE_LEN`] `f32`; the diagonal
//! is zero by definition). Between nodes it is interpolated bilinearly; in the diagonal cells,
//! where one corner lies outside the triangle, the antisymmetric extension `E(b, a) = -E(a, b)`
//! is used, which reduces to the linear `E = e (fx - fy)` on the triangle's half-cell: a
//! reversal starts with a finite slope, as the stage does. Bilinear interpolation of a grid that
//! is non-decreasing in `alpha` and non-increasing in `beta` (checked by
//! [`HysteresisTable::from_grid`]) keeps both properties everywhere, so every branch is monotone
//! and the inverse is well defined. Table: 990 values, 3980 bytes with the range, offset and
//! step (`size_of::<HysteresisTable>()`, printed by the benchmark).
//!
//! # State: a turning-point stack with wiping-out ([`HysteresisMemory`])
//! The memory holds the turning points `s_k` with the output `y_k` reached at each, so a step
//! costs one table look-up: `y = y_k + E(u, s_k)` on a rising segment from `s_k`,
//! `y = y_k - E(s_k, u)` on a falling one. A reversal pushes the last input; moving past the
//! previous extremum of the same kind closes the innermost loop and pops the two points of it
//! (the *wiping-out property* of sec. 5.3.4 and fig. 5.13). Level parity gives the direction:
//! level 0 (`u_min`) and every even level start a rising segment, odd levels a falling one.
//!
//! Bounded time: one look-up per step plus at most `HYST_MEMORY_DEPTH / 2` pops (the pops are
//! amortised: each pushed point is popped once). The inverse solves the same one-step map
//! exactly: the stored turning-point outputs say on which segment the wanted output lies, a
//! walk of at most [`INVERSE_WALK_CELLS`] grid cells from where the move starts (then a binary
//! search over the rest of the segment) finds the cell, and the bilinear Everett function,
//! linear along the moving coordinate inside a cell, is solved in closed form. In a closed
//! loop the wanted output moves little per sample, so this is one look-up (333 instructions
//! on Cortex-M4 against 1130 for a binary search from scratch). The memory step is built from
//! the same turning-point outputs, and the recorded output is the wanted one (the cell is
//! linear along the move; `forward` recomputes it within a few f32 ulps). It is checked
//! against a plain bisection of `forward` ([`HysteresisTable::inverse_by_bisection`]) and
//! against `forward`'s memory in host-tests.
//!
//! # Edges and a full memory (defined behaviour)
//! * **Input outside the range**: clamped to `[u_min, u_max]`, [`Flags::CLAMPED`] set in
//!   [`HysteresisMemory::flags`]; the output saturates on the major loop. Reaching `u_max`
//!   wipes all memory but the bottom (positive saturation), reaching `u_min` wipes all.
//! * **Non-finite input**: the last input is held, the output does not change,
//!   [`Flags::NONFINITE`] is set.
//! * **Wanted output outside what the history allows** (inverse): the input saturates at the
//!   range edge, [`Flags::CLAMPED`].
//! * **Memory full** ([`params::HYST_MEMORY_DEPTH`] points): before pushing a new turning point
//!   the two innermost points (the smallest loop in memory) are dropped, as if that minor loop
//!   had never been travelled, and the output at the new turning point is recomputed from the
//!   remaining history, so the model stays an exact Preisach model of a slightly different
//!   history. The output steps once, by the Preisach mass of the rectangle
//!   `[c, s_{n-1}] x [s_{n-2}, s_n]` (`c` the new turning point), which is at most the output
//!   change along the dropped loop's outer segment; the memory counts these merges. With
//!   nested loops the innermost is the smallest, so in practice (noise reversals) the step is
//!   of the order of the noise (measured in host-tests).
//! * **Changing the table under a memory**: the stored outputs belong to the table that made
//!   them; call [`HysteresisMemory::reset`] after swapping tables.

use crate::limits::clamp_f32;
use crate::limits::{ConfigError, Flags, Reason, check_finite, check_range, check_within};
use crate::params;
use core::ops::Bound::{Excluded, Included};

/// Nodes per axis of the Everett grid.
pub const GRID_NODES: usize = params::HYST_GRID_NODES;
/// Values stored: the strict lower triangle of the grid, `alpha` index > `beta` index.
pub const TABLE_LEN: usize = GRID_NODES * (GRID_NODES - 1) / 2;
/// Turning points the memory holds, the bottom of the range included.
pub const MEMORY_DEPTH: usize = params::HYST_MEMORY_DEPTH;
/// Cells the inverse walks before it binary-searches ([`params::HYST_INVERSE_WALK_CELLS`]).
pub const INVERSE_WALK_CELLS: usize = params::HYST_INVERSE_WALK_CELLS;

const _: () = assert!(GRID_NODES >= 3 && MEMORY_DEPTH >= 4);

/// Position of grid value `E(alpha_i, beta_j)`, `i > j`, in the packed triangle (row `i`
/// holds `j = 0..i`): `i (i - 1) / 2 + j`. `None` if `i <= j` or `i >= GRID_NODES`.
#[inline]
pub const fn packed_index(i: usize, j: usize) -> Option<usize> {
    if i > j && i < GRID_NODES {
        Some(i * (i - 1) / 2 + j)
    } else {
        None
    }
}

/// The static hysteretic map of the stage: an Everett function on a grid plus the output at
/// the bottom of the range. Configuration only (`Copy`); the history lives in
/// [`HysteresisMemory`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HysteresisTable {
    u_min_v: f32,
    u_max_v: f32,
    step_v: f32,
    inv_step_per_v: f32,
    offset_v: f32,
    everett_v: [f32; TABLE_LEN],
}

impl HysteresisTable {
    /// A table from grid data: the input range `[u_min_v, u_max_v]` (volts at the amplifier
    /// input), the output `offset_v` (sensor volts) at `u_min_v` after coming down to it, and
    /// the Everett values `E(alpha_i, beta_j)` at nodes `u_min + k (u_max - u_min) /
    /// (GRID_NODES - 1)`, packed row by row as [`packed_index`] says.
    ///
    /// Refuses, naming the argument: non-finite values ([`Reason::NotFinite`]); a range that
    /// leaves the amplifier's -2..12 V ([`Reason::OutOfRange`]) or is empty
    /// ([`Reason::NotBelow`]); a slice that is not [`TABLE_LEN`] long
    /// ([`Reason::WrongLength`]); a negative value, or a grid that decreases with `alpha` or
    /// increases with `beta` ([`Reason::NotMonotone`]), which would make a branch non-monotone.
    ///
    /// ```
    /// use model_core::hysteresis::{HysteresisMemory, HysteresisTable, GRID_NODES, packed_index, TABLE_LEN};
    /// // A linear stage without hysteresis: E(a, b) = 0.8 (a - b).
    /// let step = 10.0 / (GRID_NODES - 1) as f64;
    /// let mut e = [0.0f32; TABLE_LEN];
    /// for i in 1..GRID_NODES {
    ///     for j in 0..i {
    ///         e[packed_index(i, j).unwrap()] = (0.8 * step * (i - j) as f64) as f32;
    ///     }
    /// }
    /// let table = HysteresisTable::from_grid(0.0, 10.0, 0.0, &e).unwrap();
    /// let mut mem = HysteresisMemory::new();
    /// assert!((table.forward(&mut mem, 5.0) - 4.0).abs() < 1e-5);
    /// assert!(HysteresisTable::from_grid(0.0, 10.0, 0.0, &e[1..]).is_err());
    /// ```
    pub fn from_grid(
        u_min_v: f32,
        u_max_v: f32,
        offset_v: f32,
        everett_v: &[f32],
    ) -> Result<Self, ConfigError> {
        check_finite("u_min_v", u_min_v as f64)?;
        check_finite("u_max_v", u_max_v as f64)?;
        check_finite("offset_v", offset_v as f64)?;
        let (lo, hi) = (params::AMP_INPUT_MIN_V, params::AMP_INPUT_MAX_V);
        check_within("u_min_v", u_min_v as f64, lo, hi)?;
        check_within("u_max_v", u_max_v as f64, lo, hi)?;
        if u_min_v >= u_max_v {
            return Err(ConfigError::not_below("u_min_v", "u_max_v"));
        }
        if everett_v.len() != TABLE_LEN {
            return Err(ConfigError::new(
                "everett_v",
                Reason::WrongLength {
                    expected: TABLE_LEN,
                    found: everett_v.len(),
                },
            ));
        }
        let mut grid = [0.0; TABLE_LEN];
        for (dst, src) in grid.iter_mut().zip(everett_v) {
            if !src.is_finite() {
                return Err(ConfigError::not_finite("everett_v"));
            }
            *dst = *src;
        }
        let table = Self::from_checked_grid(u_min_v, u_max_v, offset_v, grid);
        // Monotone: E(i, j) >= E(i - 1, j) (rising in alpha; E(j, j) = 0) and
        // E(i, j) >= E(i, j + 1) (falling in beta; E(i, i) = 0).
        for i in 1..GRID_NODES {
            for j in 0..i {
                let e = table.node(i, j);
                if e < table.node(i - 1, j) || e < table.node(i, j + 1) {
                    return Err(ConfigError::new("everett_v", Reason::NotMonotone));
                }
            }
        }
        Ok(table)
    }

    /// A table with the Everett function `E(a, b) = k1 d + k2 d^2`, `d = a - b`: congruent
    /// loops (their shape depends on amplitude only, as sec. 3.2 observes), a full major loop
    /// of output span `dc_gain (u_max - u_min)` and largest vertical width
    /// `loop_width_frac` of that span (at mid-range: `k2 R^2 / 2`). Design time, `f64`.
    ///
    /// `dc_gain` in `(0, 10]`, `loop_width_frac` in `[0, 0.5]` (beyond that the reversal
    /// slope `k1` would be negative), otherwise [`Reason::OutOfRange`] naming the argument.
    ///
    /// ```
    /// use model_core::hysteresis::HysteresisTable;
    /// let t = HysteresisTable::quadratic_everett(0.0, 10.0, 0.0, 0.79, 0.15).unwrap();
    /// let (lo, hi) = t.output_range_v();
    /// assert!(lo.abs() < 1e-6 && (hi - 7.9).abs() < 1e-4);
    /// assert!(HysteresisTable::quadratic_everett(0.0, 10.0, 0.0, 0.79, 0.9).is_err());
    /// ```
    pub fn quadratic_everett(
        u_min_v: f64,
        u_max_v: f64,
        offset_v: f64,
        dc_gain: f64,
        loop_width_frac: f64,
    ) -> Result<Self, ConfigError> {
        check_finite("u_min_v", u_min_v)?;
        check_finite("u_max_v", u_max_v)?;
        check_finite("offset_v", offset_v)?;
        check_range("dc_gain", dc_gain, Excluded(0.0), Included(10.0))?;
        check_within("loop_width_frac", loop_width_frac, 0.0, 0.5)?;
        if u_min_v >= u_max_v {
            return Err(ConfigError::not_below("u_min_v", "u_max_v"));
        }
        let e = Self::quadratic_grid(u_min_v, u_max_v, dc_gain, loop_width_frac);
        Self::from_grid(u_min_v as f32, u_max_v as f32, offset_v as f32, &e)
    }

    /// The table without checks: for grids [`Self::from_grid`] has checked or the thesis
    /// default, whose constants a unit test checks.
    fn from_checked_grid(
        u_min_v: f32,
        u_max_v: f32,
        offset_v: f32,
        everett_v: [f32; TABLE_LEN],
    ) -> Self {
        Self {
            u_min_v,
            u_max_v,
            step_v: (u_max_v - u_min_v) / (GRID_NODES - 1) as f32,
            inv_step_per_v: (GRID_NODES - 1) as f32 / (u_max_v - u_min_v),
            offset_v,
            everett_v,
        }
    }

    /// The Everett grid of [`Self::quadratic_everett`] (`u_min_v < u_max_v`).
    fn quadratic_grid(
        u_min_v: f64,
        u_max_v: f64,
        dc_gain: f64,
        loop_width_frac: f64,
    ) -> [f32; TABLE_LEN] {
        let range = u_max_v - u_min_v;
        let span = dc_gain * range;
        let k2 = 2.0 * loop_width_frac * span / (range * range);
        let k1 = (span - k2 * range * range) / range;
        let step = range / (GRID_NODES - 1) as f64;
        let mut e = [0.0f32; TABLE_LEN];
        for i in 1..GRID_NODES {
            for j in 0..i {
                let d = step * (i - j) as f64;
                if let Some(slot) = packed_index(i, j).and_then(|k| e.get_mut(k)) {
                    *slot = (k1 * d + k2 * d * d) as f32;
                }
            }
        }
        e
    }

    /// The default table of the thesis stage, from our documented assumption (`params`,
    /// "Hysteresis table"): 0..10 V in, 0.79 V/V on average over the major loop, loop width
    /// 18.5 % of the output span (about 9 deg of first-harmonic lag, sec. 3.2).
    ///
    /// ```
    /// use model_core::hysteresis::{HysteresisMemory, HysteresisTable};
    /// let t = HysteresisTable::thesis_default();
    /// let mut m = HysteresisMemory::new();
    /// let up = t.forward(&mut m, 5.0);
    /// t.forward(&mut m, 10.0);
    /// let down = t.forward(&mut m, 5.0);
    /// assert!(down - up > 1.0); // the loop is about 1.46 V wide at mid-range
    /// ```
    pub fn thesis_default() -> Self {
        // The constants pass `quadratic_everett`'s checks (unit test
        // `thesis_default_is_the_checked_quadratic_table`), so the grid is built unchecked
        // and this cannot fail.
        let (lo, hi) = (
            params::HYST_DEFAULT_INPUT_MIN_V,
            params::HYST_DEFAULT_INPUT_MAX_V,
        );
        let e = Self::quadratic_grid(
            lo,
            hi,
            params::HYST_DEFAULT_DC_GAIN,
            params::HYST_DEFAULT_LOOP_WIDTH_FRAC,
        );
        Self::from_checked_grid(
            lo as f32,
            hi as f32,
            params::HYST_DEFAULT_OFFSET_V as f32,
            e,
        )
    }

    /// Input range `(u_min, u_max)`, volts at the amplifier input.
    #[inline]
    pub fn input_range_v(&self) -> (f32, f32) {
        (self.u_min_v, self.u_max_v)
    }

    /// Output range `(lowest, highest)`, sensor volts: the ends of the major loop. No history
    /// gives an output outside it.
    #[inline]
    pub fn output_range_v(&self) -> (f32, f32) {
        (self.offset_v, self.offset_v + self.node(GRID_NODES - 1, 0))
    }

    /// Output at the bottom of the range after coming down to it, sensor volts.
    #[inline]
    pub fn offset_v(&self) -> f32 {
        self.offset_v
    }

    /// Grid spacing, volts.
    #[inline]
    pub fn step_v(&self) -> f32 {
        self.step_v
    }

    /// Input volts of grid node `k` (`0..GRID_NODES`).
    #[inline]
    pub fn node_v(&self, k: usize) -> f32 {
        if k + 1 >= GRID_NODES {
            self.u_max_v
        } else {
            self.u_min_v + self.step_v * k as f32
        }
    }

    /// The packed Everett grid (layout: [`packed_index`]), sensor volts, for storing the table.
    #[inline]
    pub fn everett_grid_v(&self) -> &[f32; TABLE_LEN] {
        &self.everett_v
    }

    /// Grid value `E(alpha_i, beta_j)`: zero on and above the diagonal, as the table defines.
    #[inline]
    pub fn node(&self, i: usize, j: usize) -> f32 {
        match packed_index(i, j) {
            Some(k) => self.everett_v.get(k).copied().unwrap_or(0.0),
            None => 0.0,
        }
    }

    /// The Everett function at `(alpha_v, beta_v)`, interpolated bilinearly; arguments are
    /// clamped to the range and `beta` to at most `alpha`.
    #[inline]
    pub fn everett_v(&self, alpha_v: f32, beta_v: f32) -> f32 {
        let top = (GRID_NODES - 1) as f32;
        let x = clamp_f32((alpha_v - self.u_min_v) * self.inv_step_per_v, 0.0, top);
        let y = clamp_f32((beta_v - self.u_min_v) * self.inv_step_per_v, 0.0, x);
        // Non-negative and below GRID_NODES - 1: the casts truncate towards zero (floor).
        let i = (x as usize).min(GRID_NODES - 2);
        let j = (y as usize).min(GRID_NODES - 2);
        let fx = x - i as f32;
        let fy = y - j as f32;
        // Row i starts at i (i - 1) / 2 in the packed triangle, row i + 1 at that plus i.
        let row = i * i.saturating_sub(1) / 2;
        let t = &self.everett_v;
        let at = |k: usize| t.get(k).copied().unwrap_or(0.0);
        if i == j {
            // Diagonal cell: linear on the half-cell alpha >= beta; E(i + 1, i).
            return at(row + 2 * i) * (fx - fy);
        }
        // i > j here: (i, j), (i + 1, j), (i + 1, j + 1) lie in the triangle; (i, j + 1) does
        // unless j + 1 == i, where it is the diagonal's zero.
        let e00 = at(row + j);
        let e10 = at(row + i + j);
        let e01 = if j + 1 < i { at(row + j + 1) } else { 0.0 };
        let e11 = at(row + i + j + 1);
        let a = e00 + (e10 - e00) * fx;
        let b = e01 + (e11 - e01) * fx;
        a + (b - a) * fy
    }

    /// Output of the segment that starts at turning point `base` and runs to `u`.
    #[inline]
    fn segment(&self, base: TurningPoint, rising: bool, u: f32) -> f32 {
        if rising {
            base.output_v + self.everett_v(u, base.input_v)
        } else {
            base.output_v - self.everett_v(base.input_v, u)
        }
    }

    /// The stack a move up (`moving_up`) or down from the last input starts from: `real`
    /// points of the memory, then the last input as a new turning point if the move reverses
    /// the top segment, and whether pushing it needs a merge (memory full: the innermost loop,
    /// levels n-2 and n-1, is dropped and the segment into the last input now starts at level
    /// n-3, of the same direction, so the new point's output is recomputed on it). Shared by
    /// [`Self::locate`] and the inverse ([`Self::solve`]); always inlined (as a call it cost
    /// 30 instructions per step on Cortex-M4).
    #[inline(always)]
    fn open_move(
        &self,
        mem: &HysteresisMemory,
        moving_up: bool,
    ) -> (usize, Option<TurningPoint>, bool) {
        let pts = mem.points.as_slice();
        let n = pts.len();
        let c = mem.input_v;
        let top_rising = n <= 1 || (n - 1).is_multiple_of(2);
        if moving_up == top_rising || n == 0 {
            return (n.max(1), None, false);
        }
        if n >= MEMORY_DEPTH {
            let k = n - 3;
            let base = pts.get(k).copied().unwrap_or(self.bottom());
            let y = self.segment(base, k.is_multiple_of(2), c);
            (n - 2, Some(TurningPoint::new(c, y)), true)
        } else {
            (n, Some(TurningPoint::new(c, mem.output_v)), false)
        }
    }

    /// Where input `u` (already clamped and finite) leads from the state in `mem`, without
    /// changing it.
    fn locate(&self, mem: &HysteresisMemory, u: f32) -> Step {
        let bottom = self.bottom();
        let pts = mem.points.as_slice();
        let n = pts.len();
        let c = mem.input_v;
        let moving_up = u > c;
        let moved = u != c;
        let at = |k: usize| pts.get(k).copied().unwrap_or(bottom);
        // The virtual stack: `real` points of `pts`, then optionally `virt`.
        let (mut real, mut virt, merged) = if moved {
            self.open_move(mem, moving_up)
        } else {
            (n.max(1), None, false)
        };
        // Wiping out: while `u` passes the extremum below the base level, close that loop.
        for _ in 0..=MEMORY_DEPTH {
            let len = real + usize::from(virt.is_some());
            let b = len - 1;
            if b == 0 {
                break;
            }
            let prev = at(b - 1).input_v;
            let rising = b.is_multiple_of(2);
            let passes = if rising { u >= prev } else { u <= prev };
            if !passes {
                break;
            }
            if b >= 2 {
                // Pop levels b and b-1 (the virtual point first, if any).
                if virt.take().is_some() {
                    real -= 1;
                } else {
                    real -= 2;
                }
            } else {
                // Falling from level 1 down to the bottom: everything is wiped.
                virt = None;
                real = 1;
                break;
            }
        }
        let len = real + usize::from(virt.is_some());
        let base_level = len - 1;
        let base = match virt {
            Some(p) => p,
            None => at(base_level),
        };
        let rising = base_level.is_multiple_of(2);
        Step {
            keep: real,
            push: virt,
            merged,
            output_v: self.segment(base, rising, u),
        }
    }

    #[inline]
    fn bottom(&self) -> TurningPoint {
        TurningPoint::new(self.u_min_v, self.offset_v)
    }

    /// Clamp to the range; `None` for a non-finite input.
    #[inline]
    fn admit(&self, u: f32, flags: &mut Flags) -> Option<f32> {
        if !u.is_finite() {
            *flags |= Flags::NONFINITE;
            return None;
        }
        if u < self.u_min_v || u > self.u_max_v {
            *flags |= Flags::CLAMPED;
        }
        Some(clamp_f32(u, self.u_min_v, self.u_max_v))
    }

    fn commit(&self, mem: &mut HysteresisMemory, u: f32, step: Step) {
        mem.points.truncate(step.keep);
        if let Some(p) = step.push {
            // Cannot fail: `keep` is at most MEMORY_DEPTH - 2 when a merge was needed and
            // below MEMORY_DEPTH otherwise.
            let _ = mem.points.push(p);
        }
        if step.merged {
            mem.merges = mem.merges.saturating_add(1);
        }
        mem.input_v = u;
        mem.output_v = step.output_v;
    }

    #[inline]
    fn ensure_init(&self, mem: &mut HysteresisMemory) {
        if mem.points.is_empty() {
            mem.reset(self, self.u_min_v);
        }
    }

    /// Apply `input_v` (amplifier control-input volts) and return the static output, sensor
    /// monitor volts; `mem` advances. Out-of-range input is clamped ([`Flags::CLAMPED`]), a
    /// non-finite one holds the last input ([`Flags::NONFINITE`]); see [`HysteresisMemory::flags`].
    #[inline]
    pub fn forward(&self, mem: &mut HysteresisMemory, input_v: f32) -> f32 {
        self.ensure_init(mem);
        let mut flags = Flags::NONE;
        let Some(u) = self.admit(input_v, &mut flags) else {
            mem.flags = flags;
            return mem.output_v;
        };
        let step = self.locate(mem, u);
        self.commit(mem, u, step);
        mem.flags = flags;
        mem.output_v
    }

    /// The output `input_v` would give from the present state, without changing `mem`.
    #[inline]
    pub fn peek(&self, mem: &HysteresisMemory, input_v: f32) -> f32 {
        if mem.points.is_empty() {
            let mut m = HysteresisMemory::new();
            return self.forward(&mut m, input_v);
        }
        let mut flags = Flags::NONE;
        match self.admit(input_v, &mut flags) {
            Some(u) => self.locate(mem, u).output_v,
            None => mem.output_v,
        }
    }

    /// The input that gives `wanted_output_v` (sensor volts) from the present state; `mem`
    /// advances as if that input were applied.
    ///
    /// Exact inversion of the monotone one-step map `u -> peek(u)`: the wanted output picks
    /// the segment (the stored turning-point outputs say which loops the move would close),
    /// then a walk from the start of the move, cell by cell, finds the cell (a binary search
    /// over the nodes after [`INVERSE_WALK_CELLS`] cells), where the bilinear Everett function
    /// is linear in the moving coordinate and is solved directly. Bounded: at most
    /// `MEMORY_DEPTH / 2` segment checks and `INVERSE_WALK_CELLS + log2(GRID_NODES) + 6` table
    /// look-ups (one for a merge, the walk, the binary search with its two ends, the result). A wanted output the history cannot reach saturates the input at the range edge
    /// ([`Flags::CLAMPED`]); a non-finite one holds the last input ([`Flags::NONFINITE`]).
    pub fn inverse(&self, mem: &mut HysteresisMemory, wanted_output_v: f32) -> f32 {
        self.ensure_init(mem);
        let w = wanted_output_v;
        if !w.is_finite() {
            mem.flags = Flags::NONFINITE;
            return mem.input_v;
        }
        let (u, step) = self.solve(mem, w);
        let reached = step.output_v;
        self.commit(mem, u, step);
        let edge = u <= self.u_min_v || u >= self.u_max_v;
        mem.flags = if edge && (reached - w).abs() > 1e-4 * (1.0 + w.abs()) {
            Flags::CLAMPED
        } else {
            Flags::NONE
        };
        u
    }

    /// The input for output `w` from the state in `mem` (initialised), and the memory step
    /// that input makes (what [`Self::locate`] would return for it, found from the outputs
    /// instead of the inputs, so the inverse needs no second walk of the memory), without
    /// changing `mem`.
    fn solve(&self, mem: &HysteresisMemory, w: f32) -> (f32, Step) {
        let bottom = self.bottom();
        let pts = mem.points.as_slice();
        let c = mem.input_v;
        if w == mem.output_v {
            return (c, Step::stay(mem));
        }
        let up = w > mem.output_v;
        let at = |k: usize| pts.get(k).copied().unwrap_or(bottom);
        // The virtual stack of `locate` for a move in this direction.
        let (mut real, mut virt, merged) = self.open_move(mem, up);
        // Where the move starts: the last input, and the output there (known: the move's
        // segment passes through the present point, or through the turning point it wipes).
        // With a full memory the merge moves the present point onto the enclosing loop's
        // segment (`virt`'s output); a wanted output between the present one and that is
        // reached by no move in this direction: stay.
        let mut start = c;
        let mut start_out = match virt {
            Some(p) => p.output_v,
            None => mem.output_v,
        };
        if (up && w <= start_out) || (!up && w >= start_out) {
            return (c, Step::stay(mem));
        }
        for _ in 0..=MEMORY_DEPTH {
            let len = real + usize::from(virt.is_some());
            let b = len - 1;
            if b == 0 {
                break;
            }
            let prev = at(b - 1);
            // `>=` as `locate`'s `u >= prev`: reaching a turning point closes its loop.
            let beyond = if up {
                w >= prev.output_v
            } else {
                w <= prev.output_v
            };
            if !beyond {
                break;
            }
            if b >= 2 {
                start = prev.input_v;
                start_out = prev.output_v;
                if virt.take().is_some() {
                    real -= 1;
                } else {
                    real -= 2;
                }
            } else {
                // Below the bottom of the major loop: everything is wiped.
                let floor = Step {
                    keep: 1,
                    push: None,
                    merged,
                    output_v: bottom.output_v,
                };
                return (self.u_min_v, floor);
            }
        }
        let len = real + usize::from(virt.is_some());
        let b = len - 1;
        let base = match virt {
            Some(p) => p,
            None => at(b),
        };
        let rising = b.is_multiple_of(2);
        // The segment's far end: the extremum that would be wiped next, or the range edge.
        let end = if b == 0 {
            self.u_max_v
        } else {
            at(b - 1).input_v
        };
        let seg = |u: f32| self.segment(base, rising, u);
        let (u, output_v) = self.solve_walk(start, start_out, end, up, w, seg);
        let step = Step {
            keep: real,
            push: virt,
            merged,
            output_v,
        };
        (u, step)
    }

    /// Solve `h(u) = w` walking from `(start, h(start) = start_out)` towards `end` one grid
    /// cell at a time (`h` monotone in the direction of the move and linear between nodes):
    /// in a closed loop the wanted output moves little per sample, so the answer is almost
    /// always in the first cell, one table look-up. After [`INVERSE_WALK_CELLS`] cells the
    /// rest of the segment is binary-searched ([`Self::solve_piecewise`]); saturates at `end`.
    /// Returns the input and the output it gives (`w` itself inside a cell, where `h` is
    /// linear, so no second look-up is needed).
    fn solve_walk(
        &self,
        start: f32,
        start_out: f32,
        end: f32,
        up: bool,
        w: f32,
        h: impl Fn(f32) -> f32,
    ) -> (f32, f32) {
        let (mut xa, mut ya) = (start, start_out);
        // The first grid node beyond `start` in the direction of the move; later nodes by
        // index (a node's volts do not always map back to its own index in f32).
        let g = clamp_f32(
            (start - self.u_min_v) * self.inv_step_per_v,
            0.0,
            (GRID_NODES - 1) as f32,
        );
        // Non-negative: the cast truncates towards zero (floor).
        let i = g as usize;
        let mut next: Option<usize> = if up {
            Some(i + 1)
        } else if (i as f32) < g {
            Some(i)
        } else {
            i.checked_sub(1)
        };
        for _ in 0..INVERSE_WALK_CELLS {
            if (up && xa >= end) || (!up && xa <= end) {
                return (end, ya);
            }
            let xn = match next.filter(|&k| k < GRID_NODES) {
                Some(k) if up => self.node_v(k).min(end),
                Some(k) => self.node_v(k).max(end),
                None => end,
            };
            next = next.and_then(|k| {
                if up {
                    k.checked_add(1)
                } else {
                    k.checked_sub(1)
                }
            });
            let yn = h(xn);
            let inside = if up { w <= yn } else { w >= yn };
            if inside {
                return if yn != ya {
                    let u = xa + (xn - xa) * ((w - ya) / (yn - ya));
                    if up {
                        (clamp_f32(u, xa, xn), w)
                    } else {
                        (clamp_f32(u, xn, xa), w)
                    }
                } else {
                    (xn, yn)
                };
            }
            (xa, ya) = (xn, yn);
        }
        let u = if up {
            self.solve_piecewise(xa, end, w, &h)
        } else {
            self.solve_piecewise(end, xa, w, &h)
        };
        (u, h(u))
    }

    /// Solve `h(u) = w` on `[lo, hi]` for `h` non-decreasing and linear between grid nodes;
    /// saturates at the ends.
    fn solve_piecewise(&self, lo: f32, hi: f32, w: f32, h: impl Fn(f32) -> f32) -> f32 {
        if hi <= lo {
            return lo;
        }
        let (mut xa, mut ya) = (lo, h(lo));
        let (mut xb, mut yb) = (hi, h(hi));
        if w <= ya {
            return lo;
        }
        if w >= yb {
            return hi;
        }
        // Grid nodes strictly inside (lo, hi): indices first..=last.
        let top = (GRID_NODES - 1) as f32;
        let x_lo = clamp_f32((lo - self.u_min_v) * self.inv_step_per_v, 0.0, top);
        let x_hi = clamp_f32((hi - self.u_min_v) * self.inv_step_per_v, 0.0, top);
        let mut first = x_lo as usize + 1;
        let mut last = (x_hi as usize).min(GRID_NODES - 1);
        if self.node_v(last) >= hi {
            last = last.saturating_sub(1);
        }
        // Binary search over the nodes: keep h(xa) < w <= h(xb).
        for _ in 0..GRID_NODES.ilog2() + 2 {
            if first > last {
                break;
            }
            let mid = first + (last - first) / 2;
            let x = self.node_v(mid);
            if x <= xa || x >= xb {
                break;
            }
            let y = h(x);
            if y < w {
                (xa, ya) = (x, y);
                first = mid + 1;
            } else {
                (xb, yb) = (x, y);
                if mid == 0 {
                    break;
                }
                last = mid - 1;
            }
        }
        if yb > ya {
            clamp_f32(xa + (xb - xa) * ((w - ya) / (yb - ya)), xa, xb)
        } else {
            xb
        }
    }

    /// The inverse by a fixed [`params::HYST_INVERSE_ITERATIONS`]-step bisection of
    /// `u -> peek(u)` over the whole range: slower than [`HysteresisTable::inverse`] (a full
    /// memory walk per step), kept as its independent cross-check. Advances `mem` likewise.
    pub fn inverse_by_bisection(&self, mem: &mut HysteresisMemory, wanted_output_v: f32) -> f32 {
        self.ensure_init(mem);
        if !wanted_output_v.is_finite() {
            mem.flags = Flags::NONFINITE;
            return mem.input_v;
        }
        let c = mem.input_v;
        let (mut lo, mut hi) = if wanted_output_v >= mem.output_v {
            (c, self.u_max_v)
        } else {
            (self.u_min_v, c)
        };
        for _ in 0..params::HYST_INVERSE_ITERATIONS {
            let mid = 0.5 * (lo + hi);
            if self.locate(mem, mid).output_v < wanted_output_v {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let u = if self.locate(mem, hi).output_v <= wanted_output_v {
            hi
        } else if self.locate(mem, lo).output_v >= wanted_output_v {
            lo
        } else {
            0.5 * (lo + hi)
        };
        let step = self.locate(mem, u);
        self.commit(mem, u, step);
        mem.flags = Flags::NONE;
        u
    }
}

/// One stored turning point: input and the output reached there.
#[derive(Clone, Copy, Debug, PartialEq)]
struct TurningPoint {
    input_v: f32,
    output_v: f32,
}

impl TurningPoint {
    const fn new(input_v: f32, output_v: f32) -> Self {
        Self { input_v, output_v }
    }
}

/// What one input does to the memory.
#[derive(Clone, Copy, Debug)]
struct Step {
    keep: usize,
    push: Option<TurningPoint>,
    merged: bool,
    output_v: f32,
}

impl Step {
    /// No change: the input stays where it is.
    fn stay(mem: &HysteresisMemory) -> Self {
        Self {
            keep: mem.points.len(),
            push: None,
            merged: false,
            output_v: mem.output_v,
        }
    }
}

/// The input history that matters: the turning points not yet wiped out, bottom first, plus
/// the last input and output. State only; one table can drive many memories.
#[derive(Clone, Debug, PartialEq)]
pub struct HysteresisMemory {
    points: heapless::Vec<TurningPoint, MEMORY_DEPTH>,
    input_v: f32,
    output_v: f32,
    flags: Flags,
    merges: u32,
}

impl Default for HysteresisMemory {
    fn default() -> Self {
        Self::new()
    }
}

impl HysteresisMemory {
    /// A memory with no history: the first call of `forward`/`inverse` starts it at the bottom
    /// of the table's range (as after coming down to `u_min`: all relays off, on the major
    /// rising curve), the same as [`HysteresisMemory::reset`] to `u_min`.
    ///
    /// ```
    /// use model_core::hysteresis::{HysteresisMemory, HysteresisTable};
    /// let t = HysteresisTable::thesis_default();
    /// let mut m = HysteresisMemory::new();
    /// assert_eq!(t.forward(&mut m, 0.0), t.output_range_v().0);
    /// ```
    pub const fn new() -> Self {
        Self {
            points: heapless::Vec::new(),
            input_v: 0.0,
            output_v: 0.0,
            flags: Flags::NONE,
            merges: 0,
        }
    }

    /// Forget the history: come up from the bottom of `table`'s range to `input_v` (clamped),
    /// i.e. stand on the major rising curve there. Non-finite `input_v` means the bottom.
    pub fn reset(&mut self, table: &HysteresisTable, input_v: f32) {
        let (lo, hi) = table.input_range_v();
        let u = if input_v.is_finite() {
            clamp_f32(input_v, lo, hi)
        } else {
            lo
        };
        self.points.clear();
        let _ = self.points.push(table.bottom());
        self.input_v = u;
        self.output_v = table.offset_v + table.everett_v(u, lo);
        self.flags = Flags::NONE;
        self.merges = 0;
    }

    /// Come up from the bottom of `table`'s range, visit the turning points `history_v` in
    /// order, then go to `input_v`: the memory of a stage at rest after earlier motion (a stage
    /// that came down from 8 V to 3 V is not on its major rising curve at 3 V). An empty
    /// history is [`HysteresisMemory::reset`]. Bounded: one `forward` per point; non-finite
    /// points are skipped (`forward` holds on them).
    pub fn reset_after(&mut self, table: &HysteresisTable, history_v: &[f32], input_v: f32) {
        self.reset(table, table.input_range_v().0);
        for &p in history_v.iter().filter(|p| p.is_finite()) {
            table.forward(self, p);
        }
        table.forward(
            self,
            if input_v.is_finite() {
                input_v
            } else {
                table.input_range_v().0
            },
        );
        self.flags = Flags::NONE;
    }

    /// The last input applied (clamped), volts.
    #[inline]
    pub fn input_v(&self) -> f32 {
        self.input_v
    }

    /// The last output, sensor volts.
    #[inline]
    pub fn output_v(&self) -> f32 {
        self.output_v
    }

    /// Conditions met by the last call: [`Flags::CLAMPED`] (input or wanted output outside
    /// the range), [`Flags::NONFINITE`] (non-finite argument, last input held).
    #[inline]
    pub fn flags(&self) -> Flags {
        self.flags
    }

    /// Turning points held, the bottom of the range included (0 before the first use).
    #[inline]
    pub fn depth(&self) -> usize {
        self.points.len()
    }

    /// How often a full memory merged its innermost loop since the last reset.
    #[inline]
    pub fn merges(&self) -> u32 {
        self.merges
    }

    /// Input volts of the stored turning points, bottom first (for tests and displays).
    pub fn turning_points_v(&self) -> impl Iterator<Item = f32> + '_ {
        self.points.iter().map(|p| p.input_v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stage that came down from 8 V sits on a descending curve at 3 V, above the major
    /// rising curve by what the table says (the Everett value of the loop 3..8 V); no history
    /// is the plain reset; the same input afterwards wipes the history alike.
    #[test]
    fn reset_after_a_history_stands_on_its_reversal_curve() {
        let t = HysteresisTable::thesis_default();
        let mut plain = HysteresisMemory::new();
        plain.reset(&t, 3.0);
        let mut none = HysteresisMemory::new();
        none.reset_after(&t, &[], 3.0);
        assert_eq!(plain, none);
        let mut down = HysteresisMemory::new();
        down.reset_after(&t, &[8.0], 3.0);
        let (lo, _) = t.input_range_v();
        let rising = t.offset_v() + t.everett_v(3.0, lo);
        let falling = t.offset_v() + t.everett_v(8.0, lo) - t.everett_v(8.0, 3.0);
        assert!((plain.output_v() - rising).abs() < 1e-5);
        assert!((down.output_v() - falling).abs() < 1e-5);
        // The default table's loop is 18.5 % of the span: a clear difference, not rounding.
        assert!(down.output_v() - plain.output_v() > 0.1);
        // Going above 8 V wipes the history: both memories agree from there on.
        for u in [9.0f32, 2.0, 6.5] {
            assert!((t.forward(&mut plain, u) - t.forward(&mut down, u)).abs() < 1e-6);
        }
    }

    #[test]
    fn default_constants_are_valid_and_table_fits() {
        assert!(
            HysteresisTable::quadratic_everett(
                params::HYST_DEFAULT_INPUT_MIN_V,
                params::HYST_DEFAULT_INPUT_MAX_V,
                params::HYST_DEFAULT_OFFSET_V,
                params::HYST_DEFAULT_DC_GAIN,
                params::HYST_DEFAULT_LOOP_WIDTH_FRAC,
            )
            .is_ok()
        );
        let bytes = core::mem::size_of::<HysteresisTable>();
        assert!(bytes <= 4096, "{bytes}");
    }

    #[test]
    fn thesis_default_is_the_checked_quadratic_table() {
        let checked = HysteresisTable::quadratic_everett(
            params::HYST_DEFAULT_INPUT_MIN_V,
            params::HYST_DEFAULT_INPUT_MAX_V,
            params::HYST_DEFAULT_OFFSET_V,
            params::HYST_DEFAULT_DC_GAIN,
            params::HYST_DEFAULT_LOOP_WIDTH_FRAC,
        );
        assert_eq!(checked, Ok(HysteresisTable::thesis_default()));
    }

    #[test]
    fn minor_loop_closes_and_wipes() {
        let t = HysteresisTable::thesis_default();
        let mut m = HysteresisMemory::new();
        let y6 = t.forward(&mut m, 6.0);
        t.forward(&mut m, 3.0);
        t.forward(&mut m, 4.5);
        assert_eq!(m.depth(), 3);
        let back = t.forward(&mut m, 6.0);
        assert!((back - y6).abs() < 1e-5, "{back} {y6}");
        assert_eq!(m.depth(), 1);
    }

    #[test]
    fn rejects_bad_grids() {
        let mut e = *HysteresisTable::thesis_default().everett_grid_v();
        assert_eq!(
            HysteresisTable::from_grid(0.0, 10.0, 0.0, &e[..5]),
            Err(ConfigError::new(
                "everett_v",
                Reason::WrongLength {
                    expected: TABLE_LEN,
                    found: 5
                }
            ))
        );
        assert_eq!(
            HysteresisTable::from_grid(5.0, 5.0, 0.0, &e),
            Err(ConfigError::not_below("u_min_v", "u_max_v"))
        );
        assert_eq!(
            HysteresisTable::from_grid(0.0, 20.0, 0.0, &e),
            Err(ConfigError::outside("u_max_v", -2.0, 12.0))
        );
        assert_eq!(
            HysteresisTable::from_grid(0.0, f32::NAN, 0.0, &e),
            Err(ConfigError::not_finite("u_max_v"))
        );
        e[100] = f32::INFINITY;
        assert_eq!(
            HysteresisTable::from_grid(0.0, 10.0, 0.0, &e),
            Err(ConfigError::not_finite("everett_v"))
        );
        e[100] = -1.0;
        assert_eq!(
            HysteresisTable::from_grid(0.0, 10.0, 0.0, &e),
            Err(ConfigError::new("everett_v", Reason::NotMonotone))
        );
    }
}
