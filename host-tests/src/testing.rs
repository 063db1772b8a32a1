//! Float comparison helpers (after idsp's `testing`): `isclose` with relative and absolute
//! tolerances.

/// `|a - b| <= atol + rtol * |b|`.
pub fn isclose(a: f64, b: f64, rtol: f64, atol: f64) -> bool {
    (a - b).abs() <= atol + rtol * b.abs()
}

/// Element-wise [`isclose`] over two slices of equal length.
pub fn allclose(a: &[f64], b: &[f64], rtol: f64, atol: f64) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| isclose(*x, *y, rtol, atol))
}
