//! The fit of a fast effect (time delay, amplifier pole, resonance, slew limit, saturation):
//! a bounded search on the fast records, where these effects show. A coarse grid over the
//! catalogue's bounds (log-spaced where [`super::catalogue::FastSpec::log`] says so; for a
//! resonance, plus the residual spectrum's line and three damping ratios), then golden-section
//! refinement ([`crate::util::golden_below`]). The cost is `sum_r n_r ln MSE_r` over the fast
//! records, each candidate simulated with the whole current model, and only as far as it
//! takes to show that it loses to the point it is compared with
//! ([`super::data::cost_term_below`]: the same points and results as simulating every one
//! whole, a fifth of the families suite's CPU less).

use super::catalogue;
use super::data::{Data, cost_term_below};
use crate::io::model_file::ModelFile;
use crate::util::{GOLDEN_ITERATIONS, golden_below};

/// Fit a fast effect on the fast records: returns the model and its cost
/// `sum n_r ln MSE_r` over those records.
pub(super) fn fit_fast(
    model: &ModelFile,
    data: &[Data],
    idx: &[usize],
    effect: &str,
    peak_hz: f64,
) -> Option<(ModelFile, f64)> {
    let spec = catalogue::fast_spec(effect)?;
    // The cost, or infinity once it is known to exceed `bound`: the last record's simulation
    // stops there (`cost_term_below`; the others' terms are needed whole for the sum).
    let cost_below = |m: &ModelFile, bound: f64| -> f64 {
        let mut c = 0.0;
        for (k, &i) in idx.iter().enumerate() {
            let bound = if k + 1 == idx.len() {
                bound
            } else {
                f64::INFINITY
            };
            match cost_term_below(m, &data[i], c, bound) {
                Ok(t) => c += t,
                Err(_) => return f64::INFINITY,
            }
        }
        c
    };
    let cost = |m: &ModelFile| cost_below(m, f64::INFINITY);
    let (x0, z0) = catalogue::fast_value(model, effect).unwrap_or((f64::NAN, 0.05));
    let to = |x: f64| if spec.log { x.ln() } else { x };
    let from = |x: f64| if spec.log { x.exp() } else { x };
    let (a, b) = (to(spec.lo), to(spec.hi));
    let mut z = if effect == "resonance" { z0 } else { 0.0 };
    let grid = if effect == "resonance" { 32 } else { 16 };
    let mut best = (f64::INFINITY, a);
    let zs: Vec<f64> = if effect == "resonance" {
        vec![0.02, 0.06, 0.15]
    } else {
        vec![z]
    };
    // The grid, plus (resonance) the residual's spectral line: localisation in frequency.
    let mut xs: Vec<f64> = (0..=grid)
        .map(|g| a + (b - a) * g as f64 / grid as f64)
        .collect();
    if effect == "resonance" && peak_hz > spec.lo && peak_hz < spec.hi {
        for f in [0.88, 0.94, 1.0, 1.06, 1.12] {
            xs.push(to((f * peak_hz).clamp(spec.lo, spec.hi)));
        }
    }
    for &zz in &zs {
        for &x in &xs {
            let c = cost_below(&catalogue::with_fast(model, effect, from(x), zz), best.0);
            if c < best.0 {
                best = (c, x);
                z = zz;
            }
        }
    }
    if x0.is_finite() {
        let c = cost_below(&catalogue::with_fast(model, effect, x0, z0), best.0);
        if c < best.0 {
            best = (c, to(x0));
            z = z0;
        }
    }
    let h = (b - a) / grid as f64;
    // (the golden searches compare each new point with one other: its cost is the bound)
    let x = golden_below(
        best.1 - h,
        best.1 + h,
        a,
        b,
        GOLDEN_ITERATIONS,
        |x, bound| cost_below(&catalogue::with_fast(model, effect, from(x), z), bound),
    );
    let mut xbest = from(x);
    if effect == "resonance" {
        let lz = golden_below(
            (z / 3.0).ln(),
            (z * 3.0).ln(),
            (0.005f64).ln(),
            (0.5f64).ln(),
            GOLDEN_ITERATIONS,
            |lz, bound| cost_below(&catalogue::with_fast(model, effect, xbest, lz.exp()), bound),
        );
        z = lz.exp();
        let x2 = golden_below(
            to(xbest) - h / 2.0,
            to(xbest) + h / 2.0,
            a,
            b,
            GOLDEN_ITERATIONS,
            |x, bound| cost_below(&catalogue::with_fast(model, effect, from(x), z), bound),
        );
        xbest = from(x2);
    }
    let m = catalogue::with_fast(model, effect, xbest, z);
    let c = cost(&m);
    c.is_finite().then_some((m, c))
}
