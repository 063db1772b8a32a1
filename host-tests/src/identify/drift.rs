//! Drift identification from a step record (sec. 5.2: the thesis fitted eq. 5.1 on the drift
//! after a 1 V step).
//!
//! # Method
//! 1. **Find the step** in the record itself: the largest jump of `u` between two samples
//!    (at least 0.2 V). The levels before (`u0`) and after (`u1`) are the means of `u` over the
//!    held stretches; the stretch after the step ends where `u` next moves by more than 1 % of
//!    the step (or at the record's end).
//! 2. **Skip the fast part**: the fit starts 10 ms after the step (the thesis saw the fast part
//!    settle in about 5 ms, sec. 3.1), when `y = fast(u1) + drift(t)`.
//! 3. **Model**: `y(t) = c + sum_i a_i (1 - exp(-(t - t_step)/tau_i))`, `i = 1..3`. For fixed
//!    time constants this is linear in `(c, a_1, a_2, a_3)`: solved by SVD least squares. The
//!    time constants are searched on a log grid (10 per lag in 0.01..0.3 s, 0.15..4 s,
//!    2..100 s, never longer than three times the fitted stretch), then refined by a pattern
//!    search in log time (halving steps). The residual is taken over 400 log-spaced time bins
//!    (bin means of `y`), so that each decade of time weighs the same: the 60 ms lag is seen
//!    in a few thousand samples, the 12 s lag in millions.
//! 4. **Gains**: with the Hammerstein drift of [`model_core::drift`], a step from `u0` to `u1`
//!    gives `a_i = g_i (w(u1) - w(u0))`, so `g_i = a_i / (w(u1) - w(u0))`. The gain
//!    polynomial K(u) is kept from the base model (one step height cannot show how the gain
//!    varies with height; the thesis used 1..6 V steps for it).
//!
//! A stretch much shorter than a time constant cannot determine it: a lag whose search range
//! starts above three times the stretch keeps the base model's time constant and only its
//! gain is fitted.

use anyhow::{bail, ensure};
use model_core::drift::DriftConfig;
use nalgebra::{DMatrix, DVector};

/// The result of a drift fit.
#[derive(Clone, Debug, PartialEq)]
pub struct DriftFit {
    /// The identified drift branch.
    pub config: DriftConfig,
    /// Input level before the step, volts.
    pub from_v: f64,
    /// Input level after the step, volts.
    pub to_v: f64,
    /// Time of the step, seconds.
    pub t_step_s: f64,
    /// Length of the fitted stretch, seconds.
    pub fitted_s: f64,
    /// RMS of the fit residual over the binned record, volts.
    pub rms_residual_v: f64,
}

struct Bins {
    t: Vec<f64>,
    y: Vec<f64>,
}

fn bins(t: &[f64], y: &[f64], t0: f64, t1: f64) -> Bins {
    let nb = 400;
    let lo = 1e-4f64.max(t0);
    let ratio = (t1 / lo).ln();
    let mut st = vec![0.0; nb];
    let mut sy = vec![0.0; nb];
    let mut n = vec![0usize; nb];
    for (&ti, &yi) in t.iter().zip(y) {
        if ti < t0 || ti > t1 {
            continue;
        }
        let k = if ti <= lo {
            0
        } else {
            (((ti / lo).ln() / ratio) * nb as f64) as usize
        };
        let k = k.min(nb - 1);
        st[k] += ti;
        sy[k] += yi;
        n[k] += 1;
    }
    let mut b = Bins {
        t: vec![],
        y: vec![],
    };
    for k in 0..nb {
        if n[k] > 0 {
            b.t.push(st[k] / n[k] as f64);
            b.y.push(sy[k] / n[k] as f64);
        }
    }
    b
}

/// Least squares for fixed taus: returns (coefficients c, a1..a3, rms).
fn solve(b: &Bins, taus: &[f64; 3]) -> (Vec<f64>, f64) {
    let m = b.t.len();
    let a = DMatrix::from_fn(m, 4, |i, j| {
        if j == 0 {
            1.0
        } else {
            1.0 - (-b.t[i] / taus[j - 1]).exp()
        }
    });
    let y = DVector::from_column_slice(&b.y);
    let svd = a.clone().svd(true, true);
    let x = match svd.solve(&y, 1e-12) {
        Ok(x) => x,
        Err(_) => return (vec![0.0; 4], f64::INFINITY),
    };
    let r = &a * &x - y;
    let rms = (r.norm_squared() / m as f64).sqrt();
    (
        x.iter().copied().collect(),
        if rms.is_finite() { rms } else { f64::INFINITY },
    )
}

/// Identify the drift lags from a step record; `base` supplies K(u) and the time constants of
/// lags the record is too short to show.
pub fn identify_drift(
    t_s: &[f64],
    u_v: &[f64],
    y_v: &[f64],
    base: &DriftConfig,
) -> anyhow::Result<DriftFit> {
    let n = t_s.len();
    ensure!(
        n == u_v.len() && n == y_v.len(),
        "columns have different lengths"
    );
    ensure!(
        n >= 100,
        "record too short to identify drift: {n} samples (need at least 100)"
    );
    ensure!(
        t_s.iter().chain(u_v).chain(y_v).all(|v| v.is_finite()),
        "record holds non-finite samples"
    );
    // 1. The step.
    let (k, jump) = (1..n)
        .map(|i| (i, u_v[i] - u_v[i - 1]))
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .unwrap_or((1, 0.0));
    ensure!(
        jump.abs() >= 0.2,
        "no step found: the largest jump of u is {:.3} V (need >= 0.2 V)",
        jump.abs()
    );
    let tol = 0.01 * jump.abs();
    let u1 = u_v[k];
    let end = (k..n).find(|&i| (u_v[i] - u1).abs() > tol).unwrap_or(n);
    let start = (0..k)
        .rev()
        .find(|&i| (u_v[i] - u_v[k - 1]).abs() > tol)
        .map_or(0, |i| i + 1);
    let from_v = u_v[start..k].iter().sum::<f64>() / (k - start) as f64;
    let to_v = u_v[k..end].iter().sum::<f64>() / (end - k) as f64;
    let t_step = t_s[k];
    let fitted_s = t_s[end - 1] - t_step;
    ensure!(
        fitted_s >= 0.2,
        "the input is held for only {fitted_s:.3} s after the step (need >= 0.2 s)"
    );
    // 2. Bins of the drift stretch, time measured from the step.
    let rel: Vec<f64> = t_s[k..end].iter().map(|t| t - t_step).collect();
    let b = bins(&rel, &y_v[k..end], 0.01, fitted_s);
    ensure!(b.t.len() >= 20, "too few samples after the step to fit");
    // 3. Search the time constants.
    let ranges: [(f64, f64); 3] = [(0.01, 0.3), (0.15, 4.0), (2.0, 100.0)];
    let limit = 3.0 * fitted_s;
    let free: Vec<bool> = ranges.iter().map(|r| r.0 < limit).collect();
    let grid = |i: usize, j: usize| -> f64 {
        if !free[i] {
            return base.taus_s[i];
        }
        let (lo, hi) = (ranges[i].0, ranges[i].1.min(limit));
        lo * (hi / lo).powf(j as f64 / 9.0)
    };
    let mut best = (f64::INFINITY, base.taus_s);
    for i in 0..10 {
        for j in 0..10 {
            for l in 0..10 {
                let taus = [grid(0, i), grid(1, j), grid(2, l)];
                if !(taus[0] < taus[1] && taus[1] < taus[2]) {
                    continue;
                }
                let (_, rms) = solve(&b, &taus);
                if rms < best.0 {
                    best = (rms, taus);
                }
            }
        }
    }
    if !best.0.is_finite() {
        bail!(
            "the drift fit did not converge: no time constants in the search grid give a finite residual"
        );
    }
    // Pattern search in log tau.
    let mut step = 0.3f64;
    for _ in 0..12 {
        let mut improved = true;
        let mut guard = 0;
        while improved && guard < 50 {
            improved = false;
            guard += 1;
            for i in 0..3 {
                if !free[i] {
                    continue;
                }
                for dir in [-1.0, 1.0] {
                    let mut taus = best.1;
                    taus[i] *= (dir * step).exp();
                    if !(taus[0] < taus[1] && taus[1] < taus[2]) || taus[0] < 1e-3 || taus[2] > 1e4
                    {
                        continue;
                    }
                    let (_, rms) = solve(&b, &taus);
                    if rms < best.0 {
                        best = (rms, taus);
                        improved = true;
                    }
                }
            }
        }
        step *= 0.5;
    }
    let (coef, rms) = solve(&b, &best.1);
    // 4. Gains per volt of weighted input.
    let dw = base.weight(to_v) - base.weight(from_v);
    ensure!(
        dw.abs() > 1e-6,
        "the step from {from_v:.3} V to {to_v:.3} V does not change the drift input K(u) (the model's drift poly is flat there)"
    );
    let gains = [coef[1] / dw, coef[2] / dw, coef[3] / dw];
    let config = DriftConfig {
        gains,
        taus_s: best.1,
        ..*base
    };
    config.validate().map_err(|e| {
        anyhow::anyhow!(
            "the identified drift is not a valid model ({e}): gains {gains:?}, taus {:?}",
            best.1
        )
    })?;
    Ok(DriftFit {
        config,
        from_v,
        to_v,
        t_step_s: t_step,
        fitted_s,
        rms_residual_v: rms,
    })
}
