//! The joint fit of the slow effects (drift, hysteresis, non-linear gain): linear in their
//! weights given a few shape constants, so one weighted least-squares solve on the settled
//! samples of all records ([`SlowRegressors`]: the drift lags for each grid time constant, the
//! play operators, the gain terms), with the drift's and the play operators' weights kept
//! non-negative ([`super::nnls`]). The three drift time constants are chosen from a log grid
//! by the same solve, then refined by coordinate descent ([`crate::util::golden_n`] on
//! `log tau`); one round of structural refinement follows where the stage's form is not linear
//! in the parameters (the drift's `K(u)`, `K'(u)` on the play sum).
//!
//! Records weigh equally (each record's normal equations are divided by its settled samples).

use super::catalogue::{self, SlowParams};
use super::constants::{
    DRIFT_REFINE_PASSES, DRIFT_REFINE_TOL_V2, DRIFT_TAU_MAX_RECORDS, SETTLE_S, STRUCTURE_ROUNDS,
};
use super::data::Data;
use super::everett::{self, HYST_COLS, HYST_FIT_COLS, HystFit};
use super::nnls::{nnls_normal, nnls_normal_from, ridge};
use crate::util::golden_n;
use model_core::params;
use nalgebra::{DMatrix, DVector};

/// The slow effects' regressors at the rows the solve uses (they depend on the input only).
pub struct SlowRegressors {
    /// Per record: columns at the rows (drift lags for each grid time constant, the
    /// hysteresis basis, gain terms).
    cols: Vec<Vec<Vec<f64>>>,
    /// Per record: the samples the solve uses, rising: the settled ones, evenly thinned to at
    /// most [`MAX_SLOW_ROWS`].
    rows: Vec<Vec<usize>>,
    /// Per record: the drift lags' input, `K(u) u` (`u` while K = 1), every sample.
    drive: Vec<Vec<f64>>,
    /// Per record: the hysteresis basis at the rows, before the K'(u) scaling (computed once:
    /// it is the costly part).
    hyst: std::sync::Arc<Vec<Vec<Vec<f64>>>>,
    /// The hysteresis table's input range.
    range: (f64, f64),
    /// The hysteresis start memory the basis was computed with.
    start_v: Vec<f64>,
    /// The records' weighted Gram matrix of the columns that depend on the input alone and
    /// the offset's (the sensor gain's row and column zero), computed at the first solve and
    /// kept: every candidate of a step solves on the same regressors with its own target and
    /// sensor-gain column, which cost two products per column and row instead of a column's
    /// worth each.
    gram: std::sync::OnceLock<DMatrix<f64>>,
}

impl SlowRegressors {
    /// The hysteresis table's input range.
    pub fn range(&self) -> (f64, f64) {
        self.range
    }

    /// The hysteresis start memory of the basis.
    pub fn start_v(&self) -> &[f64] {
        &self.start_v
    }
}

/// Rows of one record the slow solve uses at most (our assumption: the slow effects change
/// over milliseconds or more, so 20 000 settled samples, evenly spread, carry what the whole
/// record does; the Gram matrix of the 96 columns then costs the same for any record length,
/// and the regressors' memory stays at 15 MB a record).
pub const MAX_SLOW_ROWS: usize = 20_000;

/// Rows of one record the drift time constants' search evaluates on (every solve of the
/// search; the final solve at the chosen time constants uses all [`MAX_SLOW_ROWS`]). Our
/// assumption: a drift lag of 10 ms or more is sampled evenly by 4000 of a record's settled
/// samples; each search solve then costs a fifth.
const DRIFT_SEARCH_ROWS: usize = 4_000;

/// How the slow regressors are shaped by the slow effects' non-linear parameters (the
/// structural refinement of [`fit_slow`]).
#[derive(Clone, Copy, Debug, Default)]
struct Shape {
    /// K'(u) = 1 + c1 u + c2 u^2 multiplies the play sum (the stage scales the whole fast map).
    kprime: Option<(f64, f64)>,
    /// The drift's K(u): its lags see `K(u) u`.
    kdrift: Option<[f64; 4]>,
    /// The inputs' span: K and K' are held at its edges, as in the stage.
    range: (f64, f64),
}

impl Shape {
    fn kprime(&self, u: f64) -> f64 {
        self.kprime.map_or(1.0, |(c1, c2)| {
            let x = u.clamp(self.range.0, self.range.1);
            1.0 + x * (c1 + x * c2)
        })
    }
    fn drive(&self, u: f64) -> f64 {
        self.kdrift.map_or(u, |k| {
            let x = u.clamp(self.range.0, self.range.1);
            (k[0] + x * (k[1] + x * (k[2] + x * k[3]))) * u
        })
    }
}

const N_TAU: usize = catalogue::DRIFT_TAU_GRID_S.len();
const COL_HYST: usize = N_TAU;
const COL_GAIN: usize = N_TAU + HYST_COLS;
/// Columns that depend on the input alone (kept in [`SlowRegressors`]).
const N_INPUT_COLS: usize = N_TAU + HYST_COLS + 2;
/// The offset's column: a constant 1.
const COL_OFFSET: usize = N_INPUT_COLS;
/// The sensor gain's column: the simulated output without slow effects (`y0`): a scale error
/// of the monitor scales the whole output.
const COL_SGAIN: usize = N_INPUT_COLS + 1;
const N_COLS: usize = N_INPUT_COLS + 2;

/// Value of regressor column `c` of record `r` at row `j` (`y0`: the simulated output
/// without slow effects, the sensor gain's column).
#[inline]
fn col(x: &SlowRegressors, y0: &[Vec<f64>], r: usize, c: usize, j: usize) -> f64 {
    match c {
        COL_OFFSET => 1.0,
        COL_SGAIN => y0[r][x.rows[r][j]],
        _ => x.cols[r][c][j],
    }
}

/// The columns of the slow effects in `set` other than the drift's lags.
fn fixed_cols(set: &[&str]) -> Vec<usize> {
    let mut fixed: Vec<usize> = Vec::new();
    if set.contains(&"hysteresis") {
        fixed.extend(COL_HYST..COL_HYST + HYST_FIT_COLS);
    }
    if set.contains(&"nonlinear-gain") {
        fixed.extend([COL_GAIN, COL_GAIN + 1]);
    }
    if set.contains(&"offset") {
        fixed.push(COL_OFFSET);
    }
    if set.contains(&"sensor-gain") {
        fixed.push(COL_SGAIN);
    }
    fixed
}

/// The regressors of `data`, the hysteresis basis starting every record from the memory
/// `start_v` (turning points, [`everett::start_candidates`]).
pub(super) fn slow_regressors(data: &[Data], start_v: &[f64]) -> SlowRegressors {
    let rows: Vec<Vec<usize>> = data.iter().map(solve_rows).collect();
    let (lo, hi) = data
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| {
            let (l, h) = super::data::min_max(&d.u_v);
            (a.min(l), b.max(h))
        });
    let range = everett::hyst_range(lo, hi);
    let hyst = crate::util::par_map(&data.iter().zip(&rows).collect::<Vec<_>>(), |(d, r)| {
        everett::columns(&d.u_v, r, range, start_v)
    });
    let base = SlowRegressors {
        cols: Vec::new(),
        rows,
        drive: Vec::new(),
        hyst: std::sync::Arc::new(hyst),
        range,
        start_v: start_v.to_vec(),
        gram: std::sync::OnceLock::new(),
    };
    slow_regressors_shaped(data, &Shape::default(), &base)
}

/// The rows of record `d` the slow solve uses: the settled samples (no input jump of more
/// than 20 mV within [`SETTLE_S`] before), evenly thinned to at most [`MAX_SLOW_ROWS`].
fn solve_rows(d: &Data) -> Vec<usize> {
    let n = d.len();
    let settle = (SETTLE_S / d.period_s()).ceil() as usize;
    let mut settled = Vec::with_capacity(n);
    let mut last_jump: Option<usize> = None;
    for i in 0..n {
        if d.is_jump(i) {
            last_jump = Some(i);
        }
        if last_jump.is_none_or(|j| i - j > settle) {
            settled.push(i);
        }
    }
    let stride = settled.len().div_ceil(MAX_SLOW_ROWS).max(1);
    settled.into_iter().step_by(stride).collect()
}

/// The regressors for `shape`, at the rows of `base` and with its hysteresis basis.
#[allow(clippy::needless_range_loop)] // several arrays indexed together
fn slow_regressors_shaped(data: &[Data], shape: &Shape, base: &SlowRegressors) -> SlowRegressors {
    let mut cols = Vec::new();
    let mut drives = Vec::new();
    for (r, d) in data.iter().enumerate() {
        let n = d.len();
        let rows = &base.rows[r];
        let t = d.period_s();
        let drive: Vec<f64> = d.u_v.iter().map(|&u| shape.drive(u)).collect();
        let mut c: Vec<Vec<f64>> = Vec::with_capacity(N_COLS);
        for tau in catalogue::DRIFT_TAU_GRID_S {
            // Exact ZOH first-order lag of the held drive, at rest at its first value.
            let a = (-t / tau).exp();
            let mut x = drive[0];
            let mut v = Vec::with_capacity(rows.len());
            let mut next = 0usize;
            for i in 0..n {
                if next < rows.len() && rows[next] == i {
                    v.push(x);
                    next += 1;
                }
                x = a * x + (1.0 - a) * drive[i];
            }
            c.push(v);
        }
        let kp: Vec<f64> = rows.iter().map(|&i| shape.kprime(d.u_v[i])).collect();
        for h in base.hyst[r].iter() {
            c.push(h.iter().zip(&kp).map(|(v, k)| v * k).collect());
        }
        c.push(
            rows.iter()
                .map(|&i| params::PLANT_GAIN * d.u_v[i] * d.u_v[i])
                .collect(),
        );
        c.push(
            rows.iter()
                .map(|&i| params::PLANT_GAIN * d.u_v[i] * d.u_v[i] * d.u_v[i])
                .collect(),
        );
        cols.push(c);
        drives.push(drive);
    }
    SlowRegressors {
        cols,
        rows: base.rows.clone(),
        drive: drives,
        hyst: base.hyst.clone(),
        range: base.range,
        start_v: base.start_v.clone(),
        gram: std::sync::OnceLock::new(),
    }
}

/// The weighted Gram matrix of the input-only columns and the offset's ([`SlowRegressors`]'
/// `gram`).
#[allow(clippy::needless_range_loop)] // a triangle of the matrix
fn input_gram(x: &SlowRegressors) -> DMatrix<f64> {
    let mut g = DMatrix::<f64>::zeros(N_COLS, N_COLS);
    for (cols, rows) in x.cols.iter().zip(&x.rows) {
        let w = 1.0 / rows.len().max(1) as f64;
        // The record's design matrix (its columns, then the offset's ones) times itself: a
        // blocked product (nalgebra's gemm), several times the speed of a row-by-row sum over
        // the two hundred columns of the hysteresis basis.
        let n = rows.len();
        let mut m = DMatrix::<f64>::zeros(n, COL_OFFSET + 1);
        for (k, c) in cols.iter().enumerate() {
            m.column_mut(k).copy_from_slice(c);
        }
        m.column_mut(COL_OFFSET).fill(1.0);
        let gl = m.transpose() * &m;
        let mut v = g.view_mut((0, 0), (COL_OFFSET + 1, COL_OFFSET + 1));
        v += gl * w;
    }
    g
}

/// The slow effects in `set` fitted to the residual of the model without slow effects (`y0`):
/// the linear fit ([`fit_slow_linear`]), then [`STRUCTURE_ROUNDS`] rounds of structural
/// refinement where the stage's form is not linear in the parameters:
/// * with `drift`: its K(u) (`k0 + k1 u + k2 u^2 + k3 u^3`, k0 = 1) from the three lags of
///   `u^2, u^3, u^4` weighted by the fitted gains, then the lags refitted on `K(u) u`;
/// * with `hysteresis` and `nonlinear-gain`: the play columns scaled by the fitted K'(u), as
///   the stage scales the whole fast map (`K'(u) (0.79 u + h(u))`).
///
/// A refinement that fails (K(u) u not increasing, a singular solve) keeps the previous fit.
///
/// `u_range` is the range the model file gets for K(u) and K'(u) ([`catalogue::with_slow`]),
/// so a K accepted here is one the stage accepts.
pub(super) fn fit_slow(
    data: &[Data],
    y0: &[Vec<f64>],
    x: &SlowRegressors,
    set: &[&str],
    u_range: (f64, f64),
) -> Option<SlowParams> {
    let mut p = fit_slow_linear(data, y0, x, set, None)?;
    let couple = set.contains(&"hysteresis") && set.contains(&"nonlinear-gain");
    let has_drift = set.contains(&"drift");
    if !couple && !has_drift {
        return Some(p);
    }
    let mut shape = Shape {
        range: u_range,
        ..Shape::default()
    };
    for _ in 0..STRUCTURE_ROUNDS {
        if couple {
            shape.kprime = p.gain;
        }
        if has_drift && let Some(k) = fit_drift_poly(data, y0, x, &shape, &p) {
            shape.kdrift = Some(k);
        }
        let xs = slow_regressors_shaped(data, &shape, x);
        match fit_slow_linear(data, y0, &xs, set, p.drift.map(|d| d.1)) {
            Some(mut q) => {
                q.drift_poly = shape.kdrift;
                p = q;
            }
            None => break,
        }
    }
    Some(p)
}

/// K(u) of the drift given the present fit `p` (gains, time constants; `shape`'s K' on the
/// play columns): one weighted solve with the three lags of `u`, the lags of `c(u) u` for
/// `c = u, u^2, u^3` weighted by the present gains (their coefficients are `k1..k3`), and the
/// other slow effects' columns. `None` unless `K(u) u` comes out strictly increasing (the
/// stage refuses it otherwise) and the solve is regular.
#[allow(clippy::needless_range_loop)] // lags, powers and gains indexed together
fn fit_drift_poly(
    data: &[Data],
    y0: &[Vec<f64>],
    x: &SlowRegressors,
    shape: &Shape,
    p: &SlowParams,
) -> Option<[f64; 4]> {
    let (gains, taus) = p.drift?;
    let plain = Shape {
        kdrift: None,
        ..*shape
    };
    let xs = slow_regressors_shaped(data, &plain, x);
    let mut fixed: Vec<usize> = Vec::new();
    if p.hysteresis.is_some() {
        fixed.extend(COL_HYST..COL_HYST + HYST_FIT_COLS);
    }
    if p.gain.is_some() {
        fixed.extend([COL_GAIN, COL_GAIN + 1]);
    }
    if p.offset_v.is_some() {
        fixed.push(COL_OFFSET);
    }
    if p.sensor_gain.is_some() {
        fixed.push(COL_SGAIN);
    }
    let nf = fixed.len();
    let np = 6 + nf;
    let mut g = DMatrix::<f64>::zeros(np, np);
    let mut b = DVector::<f64>::zeros(np);
    let mut row = vec![0.0; np];
    for (r, d) in data.iter().enumerate() {
        let t = d.period_s();
        let a = taus.map(|tau| (-t / tau).exp());
        let x0 = |u: f64, pw: i32| u.clamp(shape.range.0, shape.range.1).powi(pw) * u;
        // Lags of u (3) and of u^(j+1) for j = 1..3 (3 x 3), at rest at the first sample.
        let mut lu = [d.u_v[0]; 3];
        let mut lp = [[0.0f64; 3]; 3];
        for (j, l) in lp.iter_mut().enumerate() {
            *l = [x0(d.u_v[0], j as i32 + 1); 3];
        }
        let rows = &x.rows[r];
        let w = 1.0 / rows.len().max(1) as f64;
        // The rows, row-major (the transposed design matrix), and the target: one blocked
        // product at the end.
        let mut ft: Vec<f64> = Vec::with_capacity(rows.len() * np);
        let mut ev: Vec<f64> = Vec::with_capacity(rows.len());
        let mut next = 0usize;
        for i in 0..d.len() {
            if next < rows.len() && rows[next] == i {
                row[..3].copy_from_slice(&lu);
                for j in 0..3 {
                    row[3 + j] = (0..3).map(|k| gains[k] * lp[j][k]).sum();
                }
                for (c, &col) in fixed.iter().enumerate() {
                    row[6 + c] = self::col(&xs, y0, r, col, next);
                }
                next += 1;
                ft.extend_from_slice(&row);
                ev.push(d.y_v[i] - y0[r][i]);
            }
            let u = d.u_v[i];
            for k in 0..3 {
                lu[k] = a[k] * lu[k] + (1.0 - a[k]) * u;
                for j in 0..3 {
                    lp[j][k] = a[k] * lp[j][k] + (1.0 - a[k]) * x0(u, j as i32 + 1);
                }
            }
        }
        add_weighted_gram(&mut g, &mut b, &DMatrix::from_vec(np, ev.len(), ft), &ev, w);
    }
    band_penalty(&mut g, &fixed, 6);
    ridge(&mut g);
    let nonneg: Vec<bool> = (0..np)
        .map(|k| k < 3 || (k >= 6 && is_nonneg_col(fixed[k - 6])))
        .collect();
    let beta = nnls_normal(&g, &b, &nonneg)?;
    let k = [1.0, beta[3], beta[4], beta[5]];
    let cfg = model_core::drift::DriftConfig {
        gains,
        taus_s: taus,
        poly: k,
        poly_range_v: shape.range,
    };
    (k.iter().all(|v| v.is_finite()) && cfg.validate().is_ok()).then_some(k)
}

/// The joint weighted least-squares fit of the slow effects in `set` to the residual of the
/// model without slow effects (`y0`), linear in the parameters for the regressors' shape.
/// Records weigh equally. Drift time constants: the best three of the grid, then refined.
fn fit_slow_linear(
    data: &[Data],
    y0: &[Vec<f64>],
    x: &SlowRegressors,
    set: &[&str],
    start: Option<[f64; 3]>,
) -> Option<SlowParams> {
    // Gram matrix of all columns and the target: the input-only part is the regressors' own
    // (computed once), the sensor gain's column (`y0`) and the target are this call's.
    let mut g = x.gram.get_or_init(|| input_gram(x)).clone();
    let mut b = DVector::<f64>::zeros(N_COLS);
    for (r, d) in data.iter().enumerate() {
        let cols = &x.cols[r];
        let rows = &x.rows[r];
        let w = 1.0 / rows.len().max(1) as f64;
        let e: Vec<f64> = rows.iter().map(|&i| d.y_v[i] - y0[r][i]).collect();
        let s: Vec<f64> = rows.iter().map(|&i| y0[r][i]).collect();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        for (k, c) in cols.iter().enumerate() {
            b[k] += w * dot(c, &e);
            let gs = w * dot(c, &s);
            g[(k, COL_SGAIN)] += gs;
            g[(COL_SGAIN, k)] += gs;
        }
        b[COL_OFFSET] += w * e.iter().sum::<f64>();
        b[COL_SGAIN] += w * dot(&s, &e);
        let gs = w * s.iter().sum::<f64>();
        g[(COL_OFFSET, COL_SGAIN)] += gs;
        g[(COL_SGAIN, COL_OFFSET)] += gs;
        g[(COL_SGAIN, COL_SGAIN)] += w * dot(&s, &s);
    }
    let solve = |idx: &[usize], warm: Option<&[bool]>| -> Option<(Vec<f64>, f64)> {
        let p = idx.len();
        let mut a = DMatrix::<f64>::zeros(p, p);
        let mut v = DVector::<f64>::zeros(p);
        for (i, &ki) in idx.iter().enumerate() {
            v[i] = b[ki];
            for (j, &kj) in idx.iter().enumerate() {
                a[(i, j)] = g[(ki, kj)];
            }
        }
        band_penalty(&mut a, idx, 0);
        ridge(&mut a);
        let nonneg: Vec<bool> = idx.iter().map(|&k| is_nonneg_col(k)).collect();
        let beta = nnls_normal_from(&a, &v, &nonneg, warm)?;
        // Reduction of the weighted SSR (at the constrained optimum too: x' A x = x' b there).
        let red = beta.dot(&v);
        beta.iter()
            .all(|x| x.is_finite())
            .then(|| (beta.iter().copied().collect(), red))
    };
    let fixed = fixed_cols(set);
    let unpack = |idx: &[usize], beta: &[f64], taus: Option<[usize; 3]>| -> SlowParams {
        let get = |k: usize| {
            idx.iter()
                .position(|&c| c == k)
                .and_then(|p| beta.get(p).copied())
                .unwrap_or(0.0)
        };
        SlowParams {
            drift: taus.map(|t| {
                (
                    [get(t[0]), get(t[1]), get(t[2])],
                    [
                        catalogue::DRIFT_TAU_GRID_S[t[0]],
                        catalogue::DRIFT_TAU_GRID_S[t[1]],
                        catalogue::DRIFT_TAU_GRID_S[t[2]],
                    ],
                )
            }),
            hysteresis: set.contains(&"hysteresis").then(|| HystFit {
                start_v: x.start_v.clone(),
                range: x.range,
                weights: (0..HYST_COLS).map(|i| get(COL_HYST + i)).collect(),
            }),
            gain: set
                .contains(&"nonlinear-gain")
                .then(|| (get(COL_GAIN), get(COL_GAIN + 1))),
            drift_poly: None,
            sensor_gain: set.contains(&"sensor-gain").then(|| 1.0 + get(COL_SGAIN)),
            offset_v: set.contains(&"offset").then(|| get(COL_OFFSET)),
        }
    };
    if set.contains(&"drift") {
        // Time constants beyond DRIFT_TAU_MAX_RECORDS record lengths are not drift the records
        // can show: such a lag barely moves within them and acts as a constant (an offset) or
        // a ramp.
        let longest_s = data
            .iter()
            .map(|d| d.t_s[d.len() - 1] - d.t_s[0])
            .fold(0.0f64, f64::max);
        let tau_max = DRIFT_TAU_MAX_RECORDS * longest_s;
        let n_tau = catalogue::DRIFT_TAU_GRID_S
            .iter()
            .filter(|t| **t <= tau_max)
            .count()
            .max(3);
        let mut best: Option<(f64, [usize; 3], Vec<f64>)> = None;
        // Each solve starts from the previous one's positive set ([`warm_set`]): neighbouring
        // triples share most of it.
        let mut warm: Option<Vec<bool>> = None;
        for i in 0..n_tau {
            for j in i + 1..n_tau {
                for k in j + 1..n_tau {
                    let mut idx = vec![i, j, k];
                    idx.extend(&fixed);
                    if let Some((beta, red)) = solve(&idx, warm.as_deref()) {
                        warm = Some(warm_set(&beta));
                        let ok = beta.iter().take(3).all(|g| g.abs() <= 1.0);
                        if ok && best.as_ref().is_none_or(|b| red > b.0) {
                            best = Some((red, [i, j, k], beta));
                        }
                    }
                }
            }
        }
        let (_, ti, beta_grid) = best?;
        // The refinement searches with the hysteresis radii the grid's best solve uses (all
        // four bands of each, so the band penalty stays whole) and every other fixed column;
        // the final solve has them all (the basis' 22 radii x 4 bands would otherwise enter
        // each of the refinement's few hundred solves).
        let radius_of = |c: usize| (c - COL_HYST) / everett::HYST_BANDS;
        let is_hyst = |c: usize| (COL_HYST..COL_HYST + HYST_COLS).contains(&c);
        let used_radii: std::collections::BTreeSet<usize> = fixed
            .iter()
            .enumerate()
            .filter(|&(p, &c)| is_hyst(c) && beta_grid[3 + p] != 0.0)
            .map(|(_, &c)| radius_of(c))
            .collect();
        let fixed_search: Vec<usize> = fixed
            .iter()
            .copied()
            .filter(|&c| !is_hyst(c) || used_radii.contains(&radius_of(c)))
            .collect();
        // Refine the three time constants continuously (golden section on log tau between
        // the neighbouring grid values), each solve with the other columns.
        let grid = catalogue::DRIFT_TAU_GRID_S;
        let mut taus = ti.map(|i| grid[i]);
        // The search evaluates on evenly thinned rows (DRIFT_SEARCH_ROWS a record), the final
        // solve on all of them.
        let problem = DriftProblem::new(data, y0, x, &fixed, &g, &b, usize::MAX);
        let search = DriftProblem::new(data, y0, x, &fixed_search, &g, &b, DRIFT_SEARCH_ROWS);
        let eval = |taus: &[f64; 3]| -> f64 {
            search.solve(taus).map_or(f64::NEG_INFINITY, |(beta, red)| {
                if beta.iter().take(3).all(|g| g.abs() <= 1.0) {
                    red
                } else {
                    f64::NEG_INFINITY
                }
            })
        };
        // Coordinate descent: the valley is narrow (a shorter first lag and a play operator
        // of small threshold trade against each other), so it runs until a pass gains less
        // than DRIFT_REFINE_TOL_V2 of weighted residual power (at most DRIFT_REFINE_PASSES).
        // A warm start (the previous round's time constants) replaces the grid's best when it
        // explains more.
        let mut cur_val = eval(&taus);
        if let Some(t0) = start {
            let v = eval(&t0);
            if v > cur_val {
                (taus, cur_val) = (t0, v);
            }
        }
        let tau_hi = (grid[N_TAU - 1] * 2.0).min(tau_max.max(grid[n_tau - 1]));
        for pass in 0..DRIFT_REFINE_PASSES {
            let last = cur_val;
            // The first pass searches a factor 3 either side, later ones 1.25 with fewer
            // golden steps (the same final resolution, about 0.1 % of tau).
            let (factor, iters) = if pass == 0 { (3.0, 18) } else { (1.25, 12) };
            for m in 0..3 {
                let lo = if m > 0 {
                    taus[m - 1] * 1.05
                } else {
                    grid[0] * 0.5
                };
                let hi = if m < 2 { taus[m + 1] / 1.05 } else { tau_hi };
                // Also skips NaN bounds.
                if lo.partial_cmp(&hi) != Some(std::cmp::Ordering::Less) {
                    continue;
                }
                let a = lo.max(taus[m] / factor).ln();
                let b = hi.min(taus[m] * factor).ln();
                if a.partial_cmp(&b) != Some(std::cmp::Ordering::Less) {
                    continue;
                }
                let cur = taus;
                let lt = golden_n(a, b, a, b, iters, |lt| {
                    let mut t = cur;
                    t[m] = lt.exp();
                    -eval(&t)
                });
                let mut t = cur;
                t[m] = lt.exp();
                let v = eval(&t);
                if v > cur_val {
                    (taus, cur_val) = (t, v);
                }
            }
            if cur_val - last < DRIFT_REFINE_TOL_V2 {
                break;
            }
        }
        let (beta, _) = problem.solve(&taus)?;
        if !beta.iter().take(3).all(|g| g.abs() <= 1.0) {
            return None;
        }
        let mut p = unpack(&fixed, &beta[3..], None);
        p.drift = Some(([beta[0], beta[1], beta[2]], taus));
        Some(descale(p))
    } else {
        if fixed.is_empty() {
            return None;
        }
        let (beta, _) = solve(&fixed, None)?;
        Some(descale(unpack(&fixed, &beta, None)))
    }
}

/// The slow effects' weights as the stage has them: the monitor's scale error `g` multiplies
/// everything before the sensor, so the solve's coefficients of the drift, play and gain
/// columns are `g` times the stage's parameters.
fn descale(mut p: SlowParams) -> SlowParams {
    let Some(g) = p.sensor_gain.filter(|g| *g > 0.1) else {
        return p;
    };
    if let Some((gains, _)) = p.drift.as_mut() {
        for v in gains.iter_mut() {
            *v /= g;
        }
    }
    if let Some(h) = p.hysteresis.as_mut() {
        for v in h.weights.iter_mut() {
            *v /= g;
        }
    }
    if let Some((c1, c2)) = p.gain.as_mut() {
        *c1 /= g;
        *c2 /= g;
    }
    p
}

/// Is regressor column `k` one whose coefficient is kept >= 0: a drift lag's or a play
/// operator's? A stage creeps in the direction of its step (the thesis' three drift gains are
/// positive); unconstrained, two lags of nearly equal time constants and opposite gains of
/// +-0.45 make a band-pass that mimics hysteresis. With negative play weights the fitted loop
/// could turn clockwise or the output run backwards after a reversal, which no stage does;
/// unconstrained, a lone hysteresis fit soaks up drift and gain errors with weights of +-2.
fn is_nonneg_col(k: usize) -> bool {
    k < N_TAU || (COL_HYST..COL_HYST + everett::HYST_LOOP_COLS).contains(&k)
}

/// The hysteresis basis' smoothness penalty ([`everett::add_band_penalty`]) on a Gram matrix
/// whose rows from `at` on are the regressor columns `cols`.
fn band_penalty(g: &mut DMatrix<f64>, cols: &[usize], at: usize) {
    everett::add_band_penalty(g, |c| {
        cols.iter().position(|&k| k == COL_HYST + c).map(|p| at + p)
    });
}

/// Adds `w` times the Gram matrix of a design matrix given transposed (`ft`, columns x rows)
/// to `g`, and `w` times its products with the target `e` to `b`: blocked products
/// (nalgebra's gemm), several times the speed of row-by-row sums over a hysteresis basis of a
/// hundred columns.
fn add_weighted_gram(
    g: &mut DMatrix<f64>,
    b: &mut DVector<f64>,
    ft: &DMatrix<f64>,
    e: &[f64],
    w: f64,
) {
    *g += (ft * ft.transpose()) * w;
    b.axpy(w, &(ft * DVector::from_column_slice(e)), 1.0);
}

/// The warm start ([`nnls_normal_from`]) a drift solve passes to the next: its three lags
/// (first) free, the other columns where the solve left them positive.
fn warm_set(beta: &[f64]) -> Vec<bool> {
    beta.iter()
        .enumerate()
        .map(|(p, v)| p < 3 || *v > 0.0)
        .collect()
}

/// The drift refinement's fixed part, computed once per [`fit_slow`] call: per record the
/// target and the fixed columns at the settled samples (the transposed design matrix,
/// columns x rows), and the weighted Gram matrix of the fixed columns, so that each evaluation
/// only runs the three lags and their cross products.
struct DriftProblem<'a> {
    data: &'a [Data],
    /// Per record: the lags' input (`K(u) u`).
    drive: &'a [Vec<f64>],
    /// Per record: (weight, settled sample indices, target at them, fixed columns as a
    /// columns x rows matrix).
    recs: Vec<DriftRecord>,
    /// The fixed columns (indices into the regressors).
    fixed: Vec<usize>,
    /// Number of fixed columns.
    nf: usize,
    /// Weighted Gram matrix of the fixed columns, and their weighted products with the target.
    g_ff: DMatrix<f64>,
    b_f: DVector<f64>,
    /// The last solve's positive set, the next one's start ([`nnls_normal_from`]).
    warm: std::cell::RefCell<Option<Vec<bool>>>,
}

/// One record of a [`DriftProblem`]: (weight, settled sample indices, target at them, fixed
/// columns as a columns x rows matrix).
type DriftRecord = (f64, Vec<usize>, Vec<f64>, DMatrix<f64>);

impl<'a> DriftProblem<'a> {
    /// The problem on the regressors' rows, evenly thinned to at most `max_rows` a record;
    /// `g` and `b` are the weighted Gram matrix and products of all rows (used as they are
    /// when no record is thinned).
    fn new(
        data: &'a [Data],
        y0: &[Vec<f64>],
        x: &'a SlowRegressors,
        fixed: &[usize],
        g: &DMatrix<f64>,
        b: &DVector<f64>,
        max_rows: usize,
    ) -> Self {
        let nf = fixed.len();
        let mut thinned = false;
        let recs: Vec<DriftRecord> = data
            .iter()
            .enumerate()
            .map(|(r, d)| {
                let stride = x.rows[r].len().div_ceil(max_rows.max(1)).max(1);
                thinned |= stride > 1;
                let js: Vec<usize> = (0..x.rows[r].len()).step_by(stride).collect();
                let idx: Vec<usize> = js.iter().map(|&j| x.rows[r][j]).collect();
                let w = 1.0 / idx.len().max(1) as f64;
                let e = idx.iter().map(|&i| d.y_v[i] - y0[r][i]).collect();
                let mut f = Vec::with_capacity(idx.len() * nf);
                for &j in &js {
                    f.extend(fixed.iter().map(|&c| col(x, y0, r, c, j)));
                }
                let f = DMatrix::from_vec(nf, js.len(), f);
                (w, idx, e, f)
            })
            .collect();
        let (g_ff, b_f) = if thinned {
            let mut g_ff = DMatrix::<f64>::zeros(nf, nf);
            let mut b_f = DVector::<f64>::zeros(nf);
            for (w, _, e, f) in &recs {
                add_weighted_gram(&mut g_ff, &mut b_f, f, e, *w);
            }
            (g_ff, b_f)
        } else {
            (
                DMatrix::from_fn(nf, nf, |i, j| g[(fixed[i], fixed[j])]),
                DVector::from_fn(nf, |i, _| b[fixed[i]]),
            )
        };
        Self {
            data,
            drive: &x.drive,
            recs,
            fixed: fixed.to_vec(),
            nf,
            g_ff,
            b_f,
            warm: std::cell::RefCell::new(None),
        }
    }

    /// The weighted solve with three drift lags of time constants `taus` and the fixed
    /// columns: (coefficients, drift first; reduction of the weighted SSR).
    fn solve(&self, taus: &[f64; 3]) -> Option<(Vec<f64>, f64)> {
        let nf = self.nf;
        let p = 3 + nf;
        let mut g = DMatrix::<f64>::zeros(p, p);
        let mut bv = DVector::<f64>::zeros(p);
        g.view_mut((3, 3), (nf, nf)).copy_from(&self.g_ff);
        bv.rows_mut(3, nf).copy_from(&self.b_f);
        for ((d, drive), (w, idx, e, f)) in self.data.iter().zip(self.drive).zip(&self.recs) {
            let t = d.period_s();
            let a = taus.map(|tau| (-t / tau).exp());
            let mut lag = [drive[0]; 3];
            let mut ll = [[0.0f64; 3]; 3];
            let mut le = [0.0f64; 3];
            // The fixed columns' products with the lags, accumulated as the lags advance: one
            // pass over the fixed columns (stored column by column, `nf` values a row), which
            // are megabytes a record and bound the solve by memory, not by arithmetic.
            let mut lf = [vec![0.0f64; nf], vec![0.0f64; nf], vec![0.0f64; nf]];
            let fs = f.as_slice();
            let mut next = 0usize;
            for (j, &i) in idx.iter().enumerate() {
                // Advance the lags to sample i (their value there uses inputs before i).
                while next < i {
                    for k in 0..3 {
                        lag[k] = a[k] * lag[k] + (1.0 - a[k]) * drive[next];
                    }
                    next += 1;
                }
                for k in 0..3 {
                    le[k] += lag[k] * e[j];
                    for l in 0..=k {
                        ll[k][l] += lag[k] * lag[l];
                    }
                }
                let fj = &fs[j * nf..(j + 1) * nf];
                for (acc, l) in lf.iter_mut().zip(lag) {
                    for (a, &x) in acc.iter_mut().zip(fj) {
                        *a += x * l;
                    }
                }
            }
            for k in 0..3 {
                bv[k] += w * le[k];
                for l in 0..=k {
                    g[(k, l)] += w * ll[k][l];
                    if l != k {
                        g[(l, k)] += w * ll[k][l];
                    }
                }
                for (c, acc) in lf[k].iter().enumerate() {
                    g[(k, 3 + c)] += w * acc;
                    g[(3 + c, k)] += w * acc;
                }
            }
        }
        band_penalty(&mut g, &self.fixed, 3);
        ridge(&mut g);
        let nonneg: Vec<bool> = (0..p)
            .map(|k| k < 3 || is_nonneg_col(self.fixed[k - 3]))
            .collect();
        let warm = self.warm.borrow().clone();
        let beta = nnls_normal_from(&g, &bv, &nonneg, warm.as_deref())?;
        *self.warm.borrow_mut() = Some(warm_set(beta.as_slice()));
        let red = beta.dot(&bv);
        beta.iter()
            .all(|v| v.is_finite())
            .then(|| (beta.iter().copied().collect(), red))
    }
}
