//! The Everett table from a first-order reversal curve (FORC) record, as the thesis records
//! them (sec. 5.3.4), and the protocol that makes such a record.
//!
//! # Protocol ([`forc_protocol`])
//! Precondition with a sinusoid over the whole range (1 Hz, sec. 5.3.4; the thesis ran it for
//! 2-3 min to let drift settle, a parameter here), come down to the bottom, then for every
//! turning value `a_k = u_min + k * 0.15 V`: ramp up along the major rising curve to `a_k`,
//! hold, ramp back down to `u_min`, hold, and on to the next (larger) turning value. The last
//! turning value is `u_max`.
//!
//! # Identification ([`identify_hysteresis`])
//! No side information: the record alone.
//! 1. **Reversals**: the turning points of `u` are found with a threshold of
//!    [`REVERSAL_THRESHOLD_V`] (a reversal is declared once the input has come back that far
//!    from its running extremum), so noise on `u` makes no reversals.
//! 2. **First-order curves**: a falling segment is a FORC if it starts from a maximum `a`
//!    reached by rising from the bottom of the range (so it leaves the major rising curve) and
//!    runs down to the bottom. The preconditioning cycles are FORCs with `a = u_max`.
//! 3. **Everett values without derivatives**: `E(a, b) = y_a - y(b)`, with `y_a` the mean
//!    output at the turning point (hold samples included) and `y(b)` at every grid node `b` from
//!    a local straight-line fit to the falling samples within half a grid step (the noise
//!    filter: at 10 V/s and 1 kHz about 20 samples, so 1 mV of noise becomes about 0.3 mV).
//!    Curves with the same turning value (the preconditioning cycles) are averaged.
//! 4. **Onto the grid**: for every node `b_j`, `E(., b_j)` is known at the curves' turning
//!    values and is 0 on the diagonal; it is interpolated linearly in `a` to the grid nodes.
//! 5. **Monotone projection**: running maxima make the grid non-decreasing in `a` and
//!    non-increasing in `b` (what [`HysteresisTable::from_grid`] requires; noise can break it
//!    by a fraction of a millivolt). The offset is the mean output at the bottom after the falls.

use anyhow::{Context, bail, ensure};
use model_core::hysteresis::{GRID_NODES, HysteresisTable, TABLE_LEN, packed_index};
use model_core::params;

/// A reversal of the input is declared once it has come back this far from its running
/// extremum, volts (our assumption: 20x the DAC's LSB, far above command noise, far below the
/// 0.15 V spacing of the turning values).
pub const REVERSAL_THRESHOLD_V: f64 = 0.025;

/// How close to the bottom of the range a FORC must start and end, volts (our assumption).
pub const BOTTOM_TOLERANCE_V: f64 = 0.05;

/// Parameters of the FORC protocol of sec. 5.3.4.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForcProtocol {
    /// Sample rate of the record, Hz.
    pub rate_hz: f64,
    /// Bottom of the range, volts at the amplifier input.
    pub u_min_v: f64,
    /// Top of the range, volts.
    pub u_max_v: f64,
    /// Spacing of the turning values, volts (0.15 V in the thesis).
    pub step_v: f64,
    /// Preconditioning sinusoid, Hz (1 Hz in the thesis).
    pub precondition_hz: f64,
    /// Whole preconditioning cycles (the thesis ran 2-3 min).
    pub precondition_cycles: u32,
    /// Ramp rate of the reversal curves, V/s.
    pub ramp_v_per_s: f64,
    /// Hold at each turning value and at the bottom, seconds.
    pub hold_s: f64,
}

impl Default for ForcProtocol {
    /// The thesis' protocol over the 0..10 V window at 1 kHz, with 3 preconditioning cycles,
    /// 10 V/s ramps and 0.1 s holds (our assumptions where the thesis gives no number).
    fn default() -> Self {
        Self {
            rate_hz: 1000.0,
            u_min_v: params::SAFE_WINDOW_MIN_V,
            u_max_v: params::SAFE_WINDOW_MAX_V,
            step_v: params::HYST_FORC_STEP_V,
            precondition_hz: params::HYST_FORC_PRECONDITION_HZ,
            precondition_cycles: 3,
            ramp_v_per_s: 10.0,
            hold_s: 0.1,
        }
    }
}

/// The input `u(t)` of the FORC protocol, one value per sample at `p.rate_hz`.
///
/// Refuses non-finite or non-positive rates, steps, ramps; a range outside the amplifier's
/// -2..12 V; and records over 50 million samples.
pub fn forc_protocol(p: &ForcProtocol) -> anyhow::Result<Vec<f64>> {
    let all = [
        p.rate_hz,
        p.u_min_v,
        p.u_max_v,
        p.step_v,
        p.precondition_hz,
        p.ramp_v_per_s,
        p.hold_s,
    ];
    ensure!(
        all.iter().all(|x| x.is_finite()),
        "FORC protocol: a parameter is not finite"
    );
    ensure!(
        p.rate_hz > 0.0,
        "FORC protocol: the sample rate must be positive"
    );
    ensure!(
        params::AMP_INPUT_MIN_V <= p.u_min_v
            && p.u_min_v < p.u_max_v
            && p.u_max_v <= params::AMP_INPUT_MAX_V,
        "FORC protocol: the range {}..{} V must be non-empty and inside -2..12 V",
        p.u_min_v,
        p.u_max_v
    );
    ensure!(
        p.step_v >= 0.01 && p.step_v <= p.u_max_v - p.u_min_v,
        "FORC protocol: the turning-value step must be within 0.01 V..range"
    );
    ensure!(
        p.precondition_hz > 0.0 && p.ramp_v_per_s > 0.0 && p.hold_s >= 0.0,
        "FORC protocol: frequency and ramp rate must be positive, the hold not negative"
    );
    let range = p.u_max_v - p.u_min_v;
    let n_curves = (range / p.step_v - 1e-9).ceil() as usize;
    let ramp_s: f64 = (1..=n_curves)
        .map(|k| 2.0 * (k as f64 * p.step_v).min(range) / p.ramp_v_per_s)
        .sum();
    let total_s = p.precondition_cycles as f64 / p.precondition_hz
        + ramp_s
        + (2 * n_curves + 2) as f64 * p.hold_s;
    let total = total_s * p.rate_hz;
    ensure!(
        total < 5e7,
        "FORC protocol: {total:.0} samples is too long a record"
    );

    let dt = 1.0 / p.rate_hz;
    let mut u = Vec::with_capacity(total as usize + 16);
    let hold = |u: &mut Vec<f64>, v: f64| {
        let n = (p.hold_s * p.rate_hz).round() as usize;
        u.extend(std::iter::repeat_n(v, n));
    };
    let ramp = |u: &mut Vec<f64>, from: f64, to: f64| {
        let n = ((to - from).abs() / p.ramp_v_per_s * p.rate_hz)
            .ceil()
            .max(1.0) as usize;
        u.extend(
            (1..=n).map(|k| (from + (to - from) * k as f64 / n as f64).clamp(p.u_min_v, p.u_max_v)),
        );
    };
    hold(&mut u, p.u_min_v);
    let n_pre = (p.precondition_cycles as f64 / p.precondition_hz * p.rate_hz).round() as usize;
    u.extend((0..n_pre).map(|k| {
        let ph = 2.0 * std::f64::consts::PI * p.precondition_hz * k as f64 * dt;
        (p.u_min_v + 0.5 * range * (1.0 - ph.cos())).clamp(p.u_min_v, p.u_max_v)
    }));
    u.push(p.u_min_v);
    hold(&mut u, p.u_min_v);
    for k in 1..=n_curves {
        let a = (p.u_min_v + k as f64 * p.step_v).min(p.u_max_v);
        ramp(&mut u, p.u_min_v, a);
        hold(&mut u, a);
        ramp(&mut u, a, p.u_min_v);
        hold(&mut u, p.u_min_v);
    }
    Ok(u)
}

/// Indices of the turning points of `u` (alternating maxima and minima, the first and last
/// samples excluded), found with a reversal threshold of `threshold_v`: an extremum counts once
/// the input has come back `threshold_v` from it. The index is the first sample at the extremum.
pub fn turning_points(u: &[f64], threshold_v: f64) -> Vec<usize> {
    let mut out = Vec::new();
    let Some(&first) = u.first() else {
        return out;
    };
    // Direction: 0 unknown, +1 rising, -1 falling.
    let mut dir = 0i8;
    let (mut ext, mut ext_i) = (first, 0usize);
    let (mut lo, mut lo_i, mut hi, mut hi_i) = (first, 0usize, first, 0usize);
    for (i, &x) in u.iter().enumerate() {
        match dir {
            0 => {
                if x > hi {
                    (hi, hi_i) = (x, i);
                }
                if x < lo {
                    (lo, lo_i) = (x, i);
                }
                if hi - lo >= threshold_v {
                    // The first move decides: rising if the high came last.
                    if hi_i > lo_i {
                        dir = 1;
                        (ext, ext_i) = (hi, hi_i);
                    } else {
                        dir = -1;
                        (ext, ext_i) = (lo, lo_i);
                    }
                }
            }
            1 => {
                if x > ext {
                    (ext, ext_i) = (x, i);
                } else if ext - x >= threshold_v {
                    out.push(ext_i);
                    dir = -1;
                    (ext, ext_i) = (x, i);
                }
            }
            _ => {
                if x < ext {
                    (ext, ext_i) = (x, i);
                } else if x - ext >= threshold_v {
                    out.push(ext_i);
                    dir = 1;
                    (ext, ext_i) = (x, i);
                }
            }
        }
    }
    out
}

/// One first-order reversal curve: turning value, output there, output at the grid nodes
/// below it (`None` above the turning value).
struct Forc {
    alpha_v: f64,
    y_alpha_v: f64,
    y_at_node_v: Vec<Option<f64>>,
}

/// Output at `b` from falling samples `(u, y)` (sorted by `u` ascending): a straight line
/// fitted to the samples within `half_width_v` of `b`, or linear interpolation between the
/// nearest samples if fewer than three fall in the window.
fn local_fit(samples: &[(f64, f64)], b: f64, half_width_v: f64) -> Option<f64> {
    let (mut n, mut su, mut sy, mut suu, mut suy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let start = samples.partition_point(|s| s.0 < b - half_width_v);
    for &(u, y) in samples[start..]
        .iter()
        .take_while(|s| s.0 <= b + half_width_v)
    {
        let d = u - b;
        n += 1.0;
        su += d;
        sy += y;
        suu += d * d;
        suy += d * y;
    }
    if n >= 3.0 {
        let det = n * suu - su * su;
        if det > 1e-12 * n * n {
            return Some((suu * sy - su * suy) / det);
        }
        return Some(sy / n);
    }
    let k = samples.partition_point(|s| s.0 < b);
    match (
        k.checked_sub(1).and_then(|i| samples.get(i)),
        samples.get(k),
    ) {
        (Some(&(u0, y0)), Some(&(u1, y1))) if u1 > u0 => {
            Some(y0 + (y1 - y0) * (b - u0) / (u1 - u0))
        }
        (_, Some(&(_, y1))) => Some(y1),
        (Some(&(_, y0)), None) => Some(y0),
        _ => None,
    }
}

/// The Everett table from a FORC record: sample times (s), input (V at the amplifier input),
/// output (sensor monitor V). See the module note for the method.
///
/// Errors: columns of unequal length or too short, non-finite values, times not increasing,
/// an input range under 0.5 V or outside -2..12 V, fewer than 8 first-order reversal curves.
pub fn identify_hysteresis(
    t_s: &[f64],
    u_v: &[f64],
    y_v: &[f64],
) -> anyhow::Result<HysteresisTable> {
    ensure!(
        t_s.len() == u_v.len() && u_v.len() == y_v.len(),
        "hysteresis identification: columns t, u, y have different lengths ({}, {}, {})",
        t_s.len(),
        u_v.len(),
        y_v.len()
    );
    ensure!(
        u_v.len() >= 100,
        "hysteresis identification: only {} samples",
        u_v.len()
    );
    for (i, ((t, u), y)) in t_s.iter().zip(u_v).zip(y_v).enumerate() {
        ensure!(
            t.is_finite() && u.is_finite() && y.is_finite(),
            "hysteresis identification: sample {i} is not finite"
        );
    }
    ensure!(
        t_s.windows(2).all(|w| w[1] > w[0]),
        "hysteresis identification: times must increase"
    );
    let u_min = u_v.iter().copied().fold(f64::INFINITY, f64::min);
    let u_max = u_v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    ensure!(
        u_max - u_min >= 0.5,
        "hysteresis identification: the input spans only {:.3} V",
        u_max - u_min
    );
    ensure!(
        params::AMP_INPUT_MIN_V <= u_min && u_max <= params::AMP_INPUT_MAX_V,
        "hysteresis identification: input {u_min:.3}..{u_max:.3} V leaves the amplifier's -2..12 V"
    );

    let step = (u_max - u_min) / (GRID_NODES - 1) as f64;
    let nodes: Vec<f64> = (0..GRID_NODES).map(|k| u_min + step * k as f64).collect();
    let tp = turning_points(u_v, REVERSAL_THRESHOLD_V);
    let near_bottom = |x: f64| x - u_min <= BOTTOM_TOLERANCE_V;

    // Extremum indices with kind, plus the record's end if it finishes a fall at the bottom.
    let mut forcs: Vec<Forc> = Vec::new();
    let mut offsets = Vec::new();
    for w in 0..tp.len() {
        let i_max = tp[w];
        // A maximum: the sample before it is lower (turning points alternate).
        let is_max = u_v[i_max] > u_v[tp.get(w + 1).copied().unwrap_or(u_v.len() - 1)];
        if !is_max {
            continue;
        }
        let start_ok = match w.checked_sub(1) {
            Some(p) => near_bottom(u_v[tp[p]]),
            None => near_bottom(u_v[0]),
        };
        let i_end = tp.get(w + 1).copied().unwrap_or(u_v.len() - 1);
        if !start_ok || !near_bottom(u_v[i_end]) {
            continue;
        }
        let alpha = u_v[i_max];
        if alpha - u_min < 2.0 * REVERSAL_THRESHOLD_V {
            continue;
        }
        // Output at the turning point: every sample at the maximum (the hold).
        let mut top = Vec::new();
        let mut k = i_max;
        while k < u_v.len() && u_v[k] >= alpha - 1e-9 {
            top.push(y_v[k]);
            k += 1;
        }
        let y_alpha = top.iter().sum::<f64>() / top.len() as f64;
        // The falling samples, sorted by input, up to the end of the hold at the bottom.
        let mut end = i_end;
        while end + 1 < u_v.len() && u_v[end + 1] <= u_min + 1e-9 {
            end += 1;
        }
        let mut fall: Vec<(f64, f64)> = (i_max..=end).map(|k| (u_v[k], y_v[k])).collect();
        fall.sort_by(|a, b| a.0.total_cmp(&b.0));
        let bottom: Vec<f64> = fall
            .iter()
            .filter(|s| s.0 <= u_min + 1e-9)
            .map(|s| s.1)
            .collect();
        if !bottom.is_empty() {
            offsets.push(bottom.iter().sum::<f64>() / bottom.len() as f64);
        }
        let y_at_node_v = nodes
            .iter()
            .map(|&b| {
                if b < alpha {
                    local_fit(&fall, b, 0.5 * step)
                } else {
                    None
                }
            })
            .collect();
        forcs.push(Forc {
            alpha_v: alpha,
            y_alpha_v: y_alpha,
            y_at_node_v,
        });
    }
    ensure!(
        forcs.len() >= 8,
        "hysteresis identification: found {} first-order reversal curves (rises from the bottom \
         of the range, reversal, fall back to the bottom); need at least 8",
        forcs.len()
    );

    // Average curves with the same turning value.
    forcs.sort_by(|a, b| a.alpha_v.total_cmp(&b.alpha_v));
    let mut merged: Vec<(f64, Vec<Option<f64>>)> = Vec::new(); // (alpha, E at nodes)
    let mut counts: Vec<usize> = Vec::new();
    for f in &forcs {
        let e: Vec<Option<f64>> = f
            .y_at_node_v
            .iter()
            .map(|y| y.map(|y| f.y_alpha_v - y))
            .collect();
        match merged.last_mut() {
            Some((a, acc)) if (f.alpha_v - *a).abs() < 0.5 * REVERSAL_THRESHOLD_V => {
                let c = counts.last_mut().context("counts follow merged")?;
                for (x, y) in acc.iter_mut().zip(&e) {
                    *x = match (*x, y) {
                        (Some(x), Some(y)) => Some((x * *c as f64 + y) / (*c as f64 + 1.0)),
                        (x, y) => x.or(*y),
                    };
                }
                *c += 1;
            }
            _ => {
                merged.push((f.alpha_v, e));
                counts.push(1);
            }
        }
    }

    // Onto the grid: for each beta node, interpolate in alpha.
    let mut grid = vec![vec![0.0f64; GRID_NODES]; GRID_NODES]; // grid[i][j], i > j used
    for j in 0..GRID_NODES - 1 {
        let b = nodes[j];
        let mut pts: Vec<(f64, f64)> = vec![(b, 0.0)];
        pts.extend(
            merged
                .iter()
                .filter(|(a, _)| *a > b)
                .filter_map(|(a, e)| e.get(j).copied().flatten().map(|e| (*a, e))),
        );
        for i in j + 1..GRID_NODES {
            let a = nodes[i];
            let k = pts.partition_point(|p| p.0 < a);
            grid[i][j] = match (k.checked_sub(1).map(|x| pts[x]), pts.get(k)) {
                (Some((a0, e0)), Some(&(a1, e1))) if a1 > a0 => {
                    e0 + (e1 - e0) * (a - a0) / (a1 - a0)
                }
                (_, Some(&(_, e1))) => e1,
                (Some((_, e0)), None) => e0,
                (None, None) => 0.0,
            };
        }
    }
    // Monotone projection: non-decreasing in alpha, then non-increasing in beta.
    for j in 0..GRID_NODES - 1 {
        let mut run = 0.0f64;
        for row in grid.iter_mut().skip(j + 1) {
            run = run.max(row[j]);
            row[j] = run;
        }
    }
    for (i, row) in grid.iter_mut().enumerate().skip(1) {
        let mut run = 0.0f64;
        for j in (0..i).rev() {
            run = run.max(row[j]);
            row[j] = run;
        }
    }
    let mut packed = vec![0.0f32; TABLE_LEN];
    for (i, row) in grid.iter().enumerate() {
        for (j, e) in row.iter().enumerate().take(i) {
            let k = packed_index(i, j).context("packed index inside the triangle")?;
            packed[k] = *e as f32;
        }
    }
    let offset = if offsets.is_empty() {
        bail!("hysteresis identification: no samples at the bottom of the range after a fall")
    } else {
        offsets.iter().sum::<f64>() / offsets.len() as f64
    };
    HysteresisTable::from_grid(u_min as f32, u_max as f32, offset as f32, &packed)
        .map_err(|e| anyhow::anyhow!("hysteresis identification: {e}"))
}
