//! `f64` reference of the fast static map `0.79 K'(u) u` (sec. 3.1, 5.1; coefficients our
//! assumption in params.rs).

use model_core::params;

/// K'(u) in plain powers, held outside 0..10 V.
pub fn k_fast(u_v: f64) -> f64 {
    let x = u_v.clamp(params::FAST_GAIN_U_RANGE_V.0, params::FAST_GAIN_U_RANGE_V.1);
    params::FAST_GAIN_POLY
        .iter()
        .enumerate()
        .map(|(k, c)| c * x.powi(k as i32))
        .sum()
}

/// The fast part's static output, sensor volts.
pub fn fast_output(u_v: f64) -> f64 {
    params::PLANT_GAIN * k_fast(u_v) * u_v
}
