//! Does the records' loop need memory? The memoryless twin of a hysteresis candidate
//! (GAP.md algorithm, step 16).
//!
//! Hysteresis is the one catalogued effect whose output depends on the input's history and
//! not on its present value: a Preisach table is rate-independent *memory*. Its Everett table
//! is also the whole static map (the table replaces the stage's `static_gain * u`), and its
//! loop columns, less their reversible part, still carry a memoryless share of their own
//! (a band-limited play operator's centre line bends within its radius of the band's edges;
//! a start memory holds a constant). So a table can take up a static shape that the
//! catalogue's own forms fit less well (a tanh or softplus curvature, which the quadratic
//! K'(u) follows only in part, with an offset) on records whose residual shows a "loop" that
//! is only the stage's dynamics on a static misfit: a curvature before the stage, read
//! against the input on a chirp's faster octaves, lags it and draws a loop of a few noise
//! floors, enough for the signature gate. Families cases 1356 and 1699 (a softplus or tanh
//! curvature and an offset on a chirp) were named `hysteresis` alone at the floor.
//!
//! The test is the loop's own definition: a loop is what a map of the input alone cannot
//! follow. The **memoryless twin** of the candidate is the current model with a table whose
//! Everett function is `F(a) - F(b)` (`F` a map of the input alone, piecewise linear on the
//! table's own grid nodes, so as flexible along the input as the fitted table), `F` fitted by
//! least squares to the current residual on the slow fit's settled rows against the input
//! delayed by the stage's group delay (the slow columns' input,
//! [`super::slow_fit::SlowRegressors::fit_input`]), then simulated like any candidate, the
//! map before the stage's dynamics as a table is. The steps' hysteresis gate (a loop, or held
//! levels apart by the direction they were reached from, of 3 noise floors:
//! [`super::signatures::Signatures::supports`]) is then read on the twin's residual as well:
//! where the best map of the input alone leaves no loop, the records show no memory, and
//! `hysteresis` is not admissible at that step. A stage's loop (5-15 % of the span in the
//! suites, hundreds of millivolts) is left whole by any map; the loop a static misfit draws
//! through the dynamics goes with the misfit. A first version asked instead whether the twin
//! left as little as the table (within the static shapes' look-alike bar): beside a 4.8 %
//! scale error the table of a Bouc-Wen loop explained 74 % of the base residual and the twin
//! 68 %, so a 435 mV loop was refused (families case 1187, 1.4x -> 123x the floor).
//!
//! What it does not see: memory that leaves no loop in the residual of a memoryless map (a
//! table's start memory alone, a loop narrower than the gate); those were never admitted by
//! the gate either.

use super::data::{Data, simulate_all};
use super::everett;
use crate::io::model_file::{HysteresisSection, ModelFile};
use model_core::hysteresis::GRID_NODES;
use nalgebra::{DMatrix, DVector};

/// Weight of the second-difference penalty on the twin's map, as a share of the mean
/// diagonal of its normal matrix (our assumption: small enough to leave every node the
/// records visit to the data, large enough that the nodes they do not visit continue the
/// map in a straight line instead of dropping to zero, which would make the table fall).
pub const TWIN_SMOOTH: f64 = 1e-6;

/// The memoryless map `F` (sensor volts at the table's grid nodes over `range`, rising) that
/// takes up the residual `data - sims` at the rows `rows` of each record, read against the
/// input `u_fit` (each record weighs equally), on top of the reversible map `table_gain * u`;
/// `None` where no row is given or the solve fails.
fn twin_map(
    data: &[Data],
    sims: &[Vec<f64>],
    rows: &[Vec<usize>],
    u_fit: &[Vec<f64>],
    range: (f64, f64),
    table_gain: f64,
) -> Option<Vec<f64>> {
    let n = GRID_NODES;
    let (lo, hi) = range;
    let step = (hi - lo) / (n - 1) as f64;
    if step.is_nan() || step <= 0.0 {
        return None;
    }
    let mut a = DMatrix::<f64>::zeros(n, n);
    let mut b = DVector::<f64>::zeros(n);
    let mut any = false;
    for (((d, s), rs), u) in data.iter().zip(sims).zip(rows).zip(u_fit) {
        if rs.is_empty() {
            continue;
        }
        let w = 1.0 / rs.len() as f64;
        for &i in rs {
            let r = d.y_v[i] - s[i];
            if !r.is_finite() || !u[i].is_finite() {
                continue;
            }
            let x = ((u[i] - lo) / step).clamp(0.0, (n - 1) as f64);
            let k = (x.floor() as usize).min(n - 2);
            let f = x - k as f64;
            let (p, q) = (1.0 - f, f);
            a[(k, k)] += w * p * p;
            a[(k, k + 1)] += w * p * q;
            a[(k + 1, k)] += w * p * q;
            a[(k + 1, k + 1)] += w * q * q;
            b[k] += w * p * r;
            b[k + 1] += w * q * r;
            any = true;
        }
    }
    if !any {
        return None;
    }
    let lambda = TWIN_SMOOTH * a.trace() / n as f64;
    for j in 1..n - 1 {
        // (f[j-1] - 2 f[j] + f[j+1])^2
        let c = [(j - 1, 1.0), (j, -2.0), (j + 1, 1.0)];
        for &(p, cp) in &c {
            for &(q, cq) in &c {
                a[(p, q)] += lambda * cp * cq;
            }
        }
    }
    let f = a.cholesky()?.solve(&b);
    // The reversible map plus the correction, held non-decreasing (a table's branches rise).
    let mut out = Vec::with_capacity(n);
    let mut last = f64::NEG_INFINITY;
    for j in 0..n {
        let v = (table_gain * everett::node_v(range, j) + f[j]).max(last);
        out.push(v);
        last = v;
    }
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// The hysteresis section of a memoryless table over `range` whose output is `map` (sensor
/// volts at the grid nodes): `E(a, b) = F(a) - F(b)`, the output at the bottom `F(lo)`.
fn memoryless_section(range: (f64, f64), map: &[f64]) -> HysteresisSection {
    // (the grid's nodes are `everett::node_v`'s: the map at a node voltage is its own value)
    let step = (range.1 - range.0) / (GRID_NODES - 1) as f64;
    let at = |v: f64| map[(((v - range.0) / step).round() as usize).min(GRID_NODES - 1)];
    let e = everett::grid(range, |a, b| (at(a) - at(b)).max(0.0));
    HysteresisSection {
        input_range_v: [range.0, range.1],
        offset_v: map[0],
        dc_gain: None,
        loop_width_frac: None,
        everett_v: Some(e),
        start_turns_v: None,
    }
}

/// The twin's name in a step's trace (`tried`: its score and share as a candidate's; its
/// flag says whether its residual still shows the loop, without which the table was not
/// admissible).
pub const TWIN_NAME: &str = "hysteresis: memoryless twin";

/// The memoryless twin of a hysteresis candidate beside `model` (no table yet; `sims` its
/// simulations): the model with a table over `range` whose output is a map of the input
/// alone, see the module doc; its simulations and mean squares per record. `None` where the
/// model already has a table, or the twin cannot be built or simulated (the candidate is then
/// judged as before).
pub fn twin(
    model: &ModelFile,
    data: &[Data],
    sims: &[Vec<f64>],
    (rows, u_fit): (&[Vec<usize>], &[Vec<f64>]),
    range: (f64, f64),
    table_gain: f64,
) -> Option<(Vec<Vec<f64>>, Vec<f64>)> {
    if model.hysteresis.is_some() {
        return None;
    }
    let map = twin_map(data, sims, rows, u_fit, range, table_gain)?;
    let mut m = model.clone();
    m.hysteresis = Some(memoryless_section(range, &map));
    let (s, mse) = simulate_all(&m, data).ok()?;
    mse.iter().all(|v| v.is_finite()).then_some((s, mse))
}

#[cfg(test)]
mod tests {
    use super::super::signatures;
    use super::*;
    use crate::io::csv::Record;

    /// A record of `model` driven by `u` at 2 kHz, 1 mV of noise.
    fn record(model: &ModelFile, u: Vec<f64>) -> Data {
        let t: Vec<f64> = (0..u.len()).map(|i| i as f64 / 2000.0).collect();
        let mut m = model.clone();
        m.converters.noise_v = 1e-3;
        m.converters.seed = 3;
        let stage = m.build_stage().unwrap();
        let y = crate::sim::open_loop::simulate(&stage, m.period_s, &t, &u);
        Data::from_record("r.csv", Record::new(t, u, Some(y), None).unwrap()).unwrap()
    }

    /// A slow sine from 1 to 9 V and back, five cycles.
    fn sine() -> Vec<f64> {
        (0..20_000)
            .map(|i| 5.0 - 4.0 * (2.0 * std::f64::consts::PI * 0.5 * i as f64 / 2000.0).cos())
            .collect()
    }

    /// The twin of a static curvature (the truth's K'(u), no table) takes it up to the
    /// floor; the twin of a real loop (the thesis' Everett table) leaves the loop's width,
    /// tens of times what a table would.
    #[test]
    fn a_memoryless_twin_follows_a_static_map_and_not_a_loop() {
        let base = ModelFile::built_in("thesis-linear").unwrap();
        let mut curved = base.clone();
        curved.nonlinear_gain = Some(crate::io::model_file::GainSection {
            poly: [1.0, 0.02, -0.002, 0.0, 0.0, 0.0, 0.0],
            range_v: [0.0, 10.0],
        });
        let looped = ModelFile::built_in("thesis-full").unwrap();
        let mut looped_only = base.clone();
        looped_only.hysteresis = looped.hysteresis.clone();
        for (truth, memory) in [(&curved, false), (&looped_only, true)] {
            let data = vec![record(truth, sine())];
            let sims: Vec<Vec<f64>> = data
                .iter()
                .map(|d| super::super::data::sim(&base, d).unwrap())
                .collect();
            let rows: Vec<Vec<usize>> = vec![(0..data[0].len()).collect()];
            let u_fit = vec![data[0].u_v.clone()];
            let var = [1e-6];
            let (twin_sims, mse) = twin(
                &base,
                &data,
                &sims,
                (&rows, &u_fit),
                (0.5, 9.5),
                base.plant.static_gain,
            )
            .unwrap();
            let over = (mse[0] / var[0]).sqrt();
            // (the loop signature, as the steps' gate reads it, of what the twin leaves)
            let loop_v = signatures::compute(&data, &twin_sims, &[1e-3]).loop_v;
            if memory {
                assert!(
                    over > 20.0 && loop_v > 0.1,
                    "loop: twin at {over:.1}x the floor, loop {loop_v} V"
                );
            } else {
                assert!(
                    over < 1.22 && loop_v < 3e-3,
                    "curvature: twin at {over:.2}x the floor, loop {loop_v} V"
                );
            }
        }
    }
}
