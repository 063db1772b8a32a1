//! Float comparison helpers (after idsp's `testing`): `isclose` with relative and absolute
//! tolerances; and a seeded noise of a sensor whose bandwidth is below the record's Nyquist
//! rate, for the tests of the model-gap workflow's floor.

/// `|a - b| <= atol + rtol * |b|`.
pub fn isclose(a: f64, b: f64, rtol: f64, atol: f64) -> bool {
    (a - b).abs() <= atol + rtol * b.abs()
}

/// Element-wise [`isclose`] over two slices of equal length.
pub fn allclose(a: &[f64], b: &[f64], rtol: f64, atol: f64) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| isclose(*x, *y, rtol, atol))
}

/// `n` samples of seeded Gaussian noise through `order` first-order low-passes at `corner_hz`
/// (none when `order` is 0), sampled at `rate_hz`, scaled to a standard deviation of 1 over
/// the samples: a sensor's noise coloured by its bandwidth.
pub fn filtered_noise(n: usize, rate_hz: f64, corner_hz: f64, order: usize, seed: u64) -> Vec<f64> {
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut w: Vec<f64> = (0..n).map(|_| StandardNormal.sample(&mut rng)).collect();
    let a = (-2.0 * std::f64::consts::PI * corner_hz / rate_hz).exp();
    for _ in 0..order {
        let mut s = 0.0;
        for x in w.iter_mut() {
            s = a * s + (1.0 - a) * *x;
            *x = s;
        }
    }
    let sd = (w.iter().map(|x| x * x).sum::<f64>() / n.max(1) as f64).sqrt();
    w.iter().map(|x| x / sd).collect()
}
