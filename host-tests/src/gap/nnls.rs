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
    let mut factor = FreeFactor::default();
    let mut solve_on = |free: &[bool]| -> Option<DVector<f64>> { factor.solve(a, b, free) };
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

/// The Cholesky factor of the free variables' block of `A`, kept from one solve of the
/// active-set loop to the next: Lawson-Hanson frees or binds a variable or a few at a time,
/// so the factor is updated (a freed variable appended, `O(m^2)`; a bound one removed, the
/// trailing block re-rotated) instead of factored anew (`O(m^3)`). From a cold start the loop
/// frees the positive set one by one: a basis of 150 positive columns cost 150 factorisations,
/// 37 500 of them in one run of `piezo demo`.
#[derive(Default)]
struct FreeFactor {
    /// The free variables in the factor's order.
    order: Vec<usize>,
    chol: Option<nalgebra::Cholesky<f64, nalgebra::Dyn>>,
}

/// More changes than this share of the free set are factored anew (our assumption: a
/// removal costs up to a factorisation's `m^2` of rotations per position it moves, so a
/// quarter of the set changed is near the cost of starting over).
const REFACTOR_SHARE: f64 = 0.25;

impl FreeFactor {
    /// The solution with the variables `free[j]` free and the others at 0 (`None` if their
    /// block is not positive definite).
    fn solve(&mut self, a: &DMatrix<f64>, b: &DVector<f64>, free: &[bool]) -> Option<DVector<f64>> {
        let n = b.len();
        let removed: Vec<usize> = (0..self.order.len())
            .filter(|&p| !free[self.order[p]])
            .collect();
        let mut in_order = vec![false; n];
        for &j in &self.order {
            in_order[j] = true;
        }
        let added: Vec<usize> = (0..n).filter(|&j| free[j] && !in_order[j]).collect();
        let changes = removed.len() + added.len();
        let updated = self.chol.is_some()
            && changes as f64 <= REFACTOR_SHARE * self.order.len() as f64
            && self.update(a, &removed, &added);
        if !updated {
            self.order = (0..n).filter(|&j| free[j]).collect();
            let idx = &self.order;
            let sub = DMatrix::from_fn(idx.len(), idx.len(), |i, j| a[(idx[i], idx[j])]);
            self.chol = Some(sub.cholesky()?);
        }
        let chol = self.chol.as_ref()?;
        let sub_b = DVector::from_fn(self.order.len(), |i, _| b[self.order[i]]);
        let z = chol.solve(&sub_b);
        let mut x = DVector::zeros(n);
        for (i, &j) in self.order.iter().enumerate() {
            x[j] = z[i];
        }
        Some(x)
    }

    /// Remove the factor's positions `removed` (rising) and append the variables `added`;
    /// false (the factor left unusable) if a new pivot is not positive.
    fn update(&mut self, a: &DMatrix<f64>, removed: &[usize], added: &[usize]) -> bool {
        let Some(mut chol) = self.chol.take() else {
            return false;
        };
        for &p in removed.iter().rev() {
            chol = chol.remove_column(p);
            self.order.remove(p);
        }
        for &j in added {
            let m = self.order.len();
            if m == 0 {
                return false;
            }
            let col = DVector::from_fn(m + 1, |i, _| {
                let k = if i < m { self.order[i] } else { j };
                a[(k, j)]
            });
            chol = chol.insert_column(m, col);
            let d = chol.l_dirty()[(m, m)];
            if !(d.is_finite() && d > 0.0) {
                return false;
            }
            self.order.push(j);
        }
        self.chol = Some(chol);
        true
    }
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

    /// On problems too large for brute force (60 variables, 45 constrained, from a cold start
    /// and from random guesses, so that the factor is updated through many frees and binds):
    /// the Karush-Kuhn-Tucker conditions hold. Feasible; the gradient `b - A x` zero (to 1e-9
    /// of `b`'s scale, a few roundings of a solve conditioned near 1e4) on the free variables
    /// and on the unconstrained ones, and not positive on those held at 0.
    #[test]
    fn nnls_meets_the_optimality_conditions_on_larger_problems() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        for case in 0..20 {
            let n = 60;
            let m = DMatrix::<f64>::from_fn(90, n, |_, _| rng.gen_range(-1.0..1.0));
            let a = m.transpose() * &m + DMatrix::identity(n, n) * 1e-2;
            let b = DVector::<f64>::from_fn(n, |_, _| rng.gen_range(-1.0..1.0));
            let nonneg: Vec<bool> = (0..n).map(|j| j % 4 != 0).collect();
            let tol = 1e-9 * b.amax();
            for guess in 0..3u32 {
                let warm: Vec<bool> = (0..n).map(|_| rng.gen_range(0..3) == 0).collect();
                let x = if guess == 0 {
                    nnls_normal(&a, &b, &nonneg)
                } else {
                    nnls_normal_from(&a, &b, &nonneg, Some(&warm))
                }
                .expect("positive definite");
                let w = &b - &a * &x;
                for j in 0..n {
                    if nonneg[j] {
                        assert!(x[j] >= 0.0, "case {case} guess {guess}: x[{j}] = {}", x[j]);
                    }
                    if !nonneg[j] || x[j] > 0.0 {
                        assert!(
                            w[j].abs() <= tol,
                            "case {case} guess {guess}: w[{j}] = {}",
                            w[j]
                        );
                    } else {
                        assert!(
                            w[j] <= tol,
                            "case {case} guess {guess}: bound w[{j}] = {}",
                            w[j]
                        );
                    }
                }
            }
        }
        // Every variable held at 0 (all constrained, every gradient `b - A 0 = b` negative,
        // so 0 meets the optimality conditions): the free set is empty from start to end.
        let n = 8;
        let m = DMatrix::<f64>::from_fn(12, n, |_, _| rng.gen_range(-1.0..1.0));
        let a = m.transpose() * &m + DMatrix::identity(n, n);
        let b = DVector::<f64>::from_fn(n, |_, _| -rng.gen_range(0.1..1.0));
        let nonneg = vec![true; n];
        let x = nnls_normal(&a, &b, &nonneg).expect("positive definite");
        assert!(x.iter().all(|v| *v == 0.0), "{x}");
        let xw = nnls_normal_from(&a, &b, &nonneg, Some(&[true; 8])).expect("warm");
        assert!(xw.iter().all(|v| *v == 0.0), "{xw}");
    }
}
