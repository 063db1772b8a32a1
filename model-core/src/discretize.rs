//! Continuous to discrete, at design time, in `f64`.
//!
//! These run when a configuration is built (at boot, or in a low-priority task when a gain
//! changes), never in the 50 kHz path, so they may be slow; they must be exact. `core` has no
//! `exp` for `f64` and `micromath` works in `f32` with about 1e-4 relative error, which is far
//! too coarse for poles near z = 1 (the lag pole sits at 1 - 8e-6 at 50 kHz). So the exact
//! discretisations here use only `+ - * /`:
//!
//! * [`expm`]: matrix exponential by scaling and squaring with a Taylor series, accurate to
//!   `f64` rounding for the small matrices (order <= 8) of this project.
//! * [`zoh_delayed`]: exact zero-order-hold discretisation of `x' = A x + B u(t - Td)` with a
//!   delay that need not be a whole number of samples (the modified z-transform): the input
//!   in force during a sample interval is the older held sample for the first `frac T` and the
//!   newer one for the rest.
//! * [`exp`]: scalar `e^x` built on the same series, for design-time use.

/// A small dense square matrix, row major.
pub type Mat<const N: usize> = [[f64; N]; N];

fn mat_mul<const N: usize>(a: &Mat<N>, b: &Mat<N>) -> Mat<N> {
    let mut c = [[0.0; N]; N];
    for (i, row) in c.iter_mut().enumerate() {
        for (j, cij) in row.iter_mut().enumerate() {
            *cij = (0..N).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

fn identity<const N: usize>() -> Mat<N> {
    let mut m = [[0.0; N]; N];
    for (i, row) in m.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    m
}

/// `e^M` by scaling and squaring: scale so that the 1-norm is below 1/2, sum 24 Taylor terms
/// (truncation below 1e-30), square back. Non-finite input gives non-finite output.
pub fn expm<const N: usize>(m: &Mat<N>) -> Mat<N> {
    let norm = (0..N)
        .map(|j| (0..N).map(|i| m[i][j].abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let mut squarings = 0u32;
    let mut scale = 1.0;
    // Bounded: at most 1100 halvings reach any finite f64 norm below 1/2.
    while norm * scale > 0.5 && squarings < 1100 {
        scale *= 0.5;
        squarings += 1;
    }
    let mut a = *m;
    for row in a.iter_mut() {
        for v in row.iter_mut() {
            *v *= scale;
        }
    }
    let mut sum = identity::<N>();
    let mut term = identity::<N>();
    for k in 1..=24 {
        term = mat_mul(&term, &a);
        for row in term.iter_mut() {
            for v in row.iter_mut() {
                *v /= k as f64;
            }
        }
        for i in 0..N {
            for j in 0..N {
                sum[i][j] += term[i][j];
            }
        }
    }
    for _ in 0..squarings {
        sum = mat_mul(&sum, &sum);
    }
    sum
}

/// Scalar `e^x` for design-time use (same method as [`expm`]).
pub fn exp(x: f64) -> f64 {
    expm(&[[x]])[0][0]
}

/// `e^x - 1` without cancellation for small `|x|` (series below 1e-3, else [`exp`]).
pub fn expm1(x: f64) -> f64 {
    if x.abs() < 1e-3 {
        // x + x^2/2 + x^3/6 + x^4/24: next term below 1e-17 relative.
        x * (1.0 + x * (0.5 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x / 120.0))))
    } else {
        exp(x) - 1.0
    }
}

/// Exact ZOH discretisation of `x' = A x + B u(t - delay)` with `N` states; `M = N + 1` (the
/// augmented size, passed explicitly because const generic arithmetic is not stable).
///
/// Returns `(phi, gamma_new, gamma_old, whole)`, where with `d = whole` samples of delay
/// `x[n+1] = phi x[n] + gamma_new u[n-d] + gamma_old u[n-d-1]`.
pub fn zoh_delayed<const N: usize, const M: usize>(
    a: &Mat<N>,
    b: &[f64; N],
    period_s: f64,
    delay_s: f64,
) -> (Mat<N>, [f64; N], [f64; N], usize) {
    assert!(M == N + 1, "M must be N + 1");
    let samples = delay_s / period_s;
    // Guard against 4.2499999 from rounding when the delay is a whole number of samples.
    let whole = (samples + 1e-9) as usize;
    let frac = (samples - whole as f64).max(0.0);
    // Augmented exponential of [[A, B], [0, 0]] * tau gives [[Phi(tau), Gamma(tau)], [0, 1]].
    let aug = |tau: f64| -> (Mat<N>, [f64; N]) {
        let mut m = [[0.0; M]; M];
        for i in 0..N {
            for j in 0..N {
                m[i][j] = a[i][j] * tau;
            }
            m[i][N] = b[i] * tau;
        }
        let e = expm(&m);
        let mut phi = [[0.0; N]; N];
        let mut gamma = [0.0; N];
        for i in 0..N {
            for j in 0..N {
                phi[i][j] = e[i][j];
            }
            gamma[i] = e[i][N];
        }
        (phi, gamma)
    };
    let (phi, _) = aug(period_s);
    // Newer sample acts for the last (1 - frac) T of the interval.
    let (_, gamma_new) = aug((1.0 - frac) * period_s);
    // Older sample acts for the first frac T, then is propagated over (1 - frac) T.
    let (_, gamma_first) = aug(frac * period_s);
    let (phi_tail, _) = aug((1.0 - frac) * period_s);
    let mut gamma_old = [0.0; N];
    for i in 0..N {
        gamma_old[i] = (0..N).map(|k| phi_tail[i][k] * gamma_first[k]).sum();
    }
    (phi, gamma_new, gamma_old, whole)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalar_exp_is_exact_to_rounding() {
        for &x in &[-40.0, -3.0, -1e-6, 0.0, 0.7, 5.0] {
            let want = std::primitive::f64::exp(x);
            assert!(((exp(x) - want) / want).abs() < 1e-13, "{x}");
        }
        assert!(((expm1(-7.96e-6) - (-7.96e-6f64).exp_m1()) / 7.96e-6).abs() < 1e-14);
    }

    #[test]
    fn rotation_exponential() {
        let w = 2.0;
        let e = expm(&[[0.0, w], [-w, 0.0]]);
        assert!((e[0][0] - w.cos()).abs() < 1e-14);
        assert!((e[0][1] - w.sin()).abs() < 1e-14);
    }

    #[test]
    fn delayed_zoh_of_an_integrator() {
        // x' = u(t - 2.25 T): x[n+1] = x[n] + 0.75 T u[n-2] + 0.25 T u[n-3].
        let (phi, gn, go, d) = zoh_delayed::<1, 2>(&[[0.0]], &[1.0], 1.0, 2.25);
        assert_eq!(d, 2);
        assert!((phi[0][0] - 1.0).abs() < 1e-15);
        assert!((gn[0] - 0.75).abs() < 1e-15);
        assert!((go[0] - 0.25).abs() < 1e-15);
    }
}
