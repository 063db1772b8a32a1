//! Least squares on the normal equations with some coefficients kept non-negative: the
//! Lawson-Hanson active-set method ([`nnls_normal`]), and the tiny [`ridge`] that keeps the
//! Cholesky factorisation defined when two regressors coincide. Checked against brute force
//! over every active set in the test below.

use nalgebra::{DMatrix, DVector};

/// A tiny ridge on the normal equations' diagonal (1e-10 of its mean, plus 1e-15): keeps the
/// Cholesky factorisation defined when two regressors coincide (grid time constants, an input
/// that never visits a play operator's range) without moving a well-posed solution.
pub fn ridge(g: &mut DMatrix<f64>) {
    let n = g.nrows();
    let tr = (0..n).map(|i| g[(i, i)]).sum::<f64>() / n.max(1) as f64;
    for i in 0..n {
        g[(i, i)] += 1e-10 * tr + 1e-15;
    }
}

/// Minimise `x' A x / 2 - b' x` (the normal equations of a least-squares problem, `A` positive
/// definite) with `x_j >= 0` where `nonneg[j]`: the Lawson-Hanson active-set method on the
/// normal equations, at most `3 n` changes of the active set. `None` if a sub-system is not
/// positive definite.
pub fn nnls_normal(a: &DMatrix<f64>, b: &DVector<f64>, nonneg: &[bool]) -> Option<DVector<f64>> {
    nnls_normal_from(a, b, nonneg, None)
}

/// [`nnls_normal`] started from a guess of the free set (`warm[j]`: constrained variable `j`
/// is expected positive, as in the solution of a neighbouring problem), which it corrects to
/// the same optimum. A search that solves many problems differing in a few columns (the drift
/// time constants' grid and refinement beside a hysteresis basis of a hundred and more
/// columns) then factors the positive set's small system a few times instead of the whole
/// system and then every active set from the bound one up.
pub fn nnls_normal_from(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    nonneg: &[bool],
    warm: Option<&[bool]>,
) -> Option<DVector<f64>> {
    let n = b.len();
    let solve_on = |free: &[bool]| -> Option<DVector<f64>> {
        let idx: Vec<usize> = (0..n).filter(|&j| free[j]).collect();
        let sub_a = DMatrix::from_fn(idx.len(), idx.len(), |i, j| a[(idx[i], idx[j])]);
        let sub_b = DVector::from_fn(idx.len(), |i, _| b[idx[i]]);
        let z = sub_a.cholesky()?.solve(&sub_b);
        let mut x = DVector::zeros(n);
        for (i, &j) in idx.iter().enumerate() {
            x[j] = z[i];
        }
        Some(x)
    };
    let (mut free, mut x) = match warm.filter(|w| w.len() == n) {
        None => {
            // Unconstrained first: most fits never touch a bound.
            let free: Vec<bool> = vec![true; n];
            let x0 = solve_on(&free)?;
            if (0..n).all(|j| !nonneg[j] || x0[j] >= 0.0) {
                return Some(x0);
            }
            let free: Vec<bool> = (0..n).map(|j| !nonneg[j]).collect();
            let x = solve_on(&free)?;
            (free, x)
        }
        Some(w) => {
            // The guessed free set, less the variables its solve drives negative, until the
            // solve is feasible (each round binds one at least, so at most n rounds): a
            // feasible start for the active-set loop below, which restores the optimum.
            let mut free: Vec<bool> = (0..n).map(|j| !nonneg[j] || w[j]).collect();
            let mut x = solve_on(&free)?;
            for _ in 0..n {
                let bad: Vec<usize> = (0..n)
                    .filter(|&k| free[k] && nonneg[k] && x[k] < 0.0)
                    .collect();
                if bad.is_empty() {
                    break;
                }
                for k in bad {
                    free[k] = false;
                }
                x = solve_on(&free)?;
            }
            for k in 0..n {
                if nonneg[k] && x[k] < 0.0 {
                    free[k] = false;
                    x[k] = 0.0;
                }
            }
            (free, x)
        }
    };
    let scale = b.amax().max(1e-300);
    for _ in 0..3 * n {
        // The gradient of the objective's negative: which bound variable wants to move up?
        let w = b - a * &x;
        let enter = (0..n)
            .filter(|&j| !free[j])
            .max_by(|&i, &j| w[i].total_cmp(&w[j]));
        let Some(j) = enter.filter(|&j| w[j] > 1e-12 * scale) else {
            return Some(x);
        };
        free[j] = true;
        // Each pass frees no variable and binds at least one (the one that limits the step is
        // set to 0 explicitly), so n passes always end it.
        for _ in 0..n {
            let s = solve_on(&free)?;
            let bad: Vec<usize> = (0..n)
                .filter(|&k| free[k] && nonneg[k] && s[k] <= 0.0)
                .collect();
            if bad.is_empty() {
                x = s;
                break;
            }
            // Step from x towards s until the first constrained variable reaches 0.
            let (limit, alpha) = bad
                .iter()
                .map(|&k| (k, x[k] / (x[k] - s[k]).max(f64::MIN_POSITIVE)))
                .fold((bad[0], 1.0f64), |a, b| if b.1 < a.1 { b } else { a });
            x = &x + (&s - &x) * alpha;
            x[limit] = 0.0;
            for k in 0..n {
                if free[k] && nonneg[k] && x[k] <= 0.0 {
                    free[k] = false;
                    x[k] = 0.0;
                }
            }
        }
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The active-set solve against brute force: every subset of the constrained variables
    /// held at zero, the rest solved freely; the best feasible one is the constrained optimum
    /// (the problem is strictly convex, so it is unique).
    #[test]
    fn nnls_matches_brute_force() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        for case in 0..300 {
            let n = 6;
            let m = DMatrix::<f64>::from_fn(12, n, |_, _| rng.gen_range(-1.0..1.0));
            let a = m.transpose() * &m + DMatrix::identity(n, n) * 1e-3;
            let b = DVector::<f64>::from_fn(n, |_, _| rng.gen_range(-1.0..1.0));
            let nonneg = [false, true, true, false, true, true];
            let x = nnls_normal(&a, &b, &nonneg).expect("positive definite");
            let obj = |x: &DVector<f64>| 0.5 * x.dot(&(&a * x)) - b.dot(x);
            let mut best = f64::INFINITY;
            for mask in 0..16u32 {
                let cons: Vec<usize> = vec![1, 2, 4, 5];
                let free: Vec<usize> = (0..n)
                    .filter(|j| {
                        cons.iter()
                            .position(|c| c == j)
                            .is_none_or(|p| mask & (1 << p) == 0)
                    })
                    .collect();
                let sa = DMatrix::from_fn(free.len(), free.len(), |i, j| a[(free[i], free[j])]);
                let sb = DVector::from_fn(free.len(), |i, _| b[free[i]]);
                let z = sa.cholesky().unwrap().solve(&sb);
                let mut y = DVector::zeros(n);
                for (i, &j) in free.iter().enumerate() {
                    y[j] = z[i];
                }
                if (0..n).all(|j| !nonneg[j] || y[j] >= -1e-12) {
                    best = best.min(obj(&y));
                }
            }
            // Feasible and as good as the best feasible subset: the constrained optimum.
            let check = |x: &DVector<f64>, label: &str| {
                assert!(
                    (0..n).all(|j| !nonneg[j] || x[j] >= 0.0),
                    "case {case}{label}: {x}"
                );
                assert!(
                    obj(x) <= best + 1e-9 * best.abs().max(1.0),
                    "case {case}{label}: {} vs brute force {best}",
                    obj(x)
                );
            };
            check(&x, "");
            // Any guess of the free set reaches the same optimum.
            for guess in 0..4u32 {
                let warm: Vec<bool> = (0..n)
                    .map(|j| (guess + case + j as u32).is_multiple_of(3))
                    .collect();
                let xw = nnls_normal_from(&a, &b, &nonneg, Some(&warm)).expect("positive definite");
                check(&xw, &format!(" warm {warm:?}"));
            }
        }
    }
}
