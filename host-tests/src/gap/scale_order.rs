//! A sensor scale beside a curvature, against a curvature of one more order (GAP.md step 14).
//!
//! The catalogue's K'(u) is 1 at 0 V: the stage's small-signal gain is the nominal one, and a
//! `sensor-gain` and a `nonlinear-gain` differ only in how they act near 0 V (a scale is
//! linear in the output, the curvature's terms `u^2`, `u^3` vanish there). A true curvature of
//! another shape than the quadratic's (a knee, a plateau) leaves over the records' span a part
//! the quadratic cannot take, and most of it is linear in the input: a scale takes it up.
//! Measured on the families generator's seeds 1100-1299, which no rule was shaped on (session
//! 43) and 1000-1099: of the scales named beside a curvature, nine were false (0.07-1.8 % off
//! 1) and ten true (1.1-4.9 % off 1), and no bar on the scale's size parts them.
//!
//! So the question is put to the records: without the scale (its factor moved into the
//! drift's gains, which it multiplies as well), does a curvature of one more order,
//! `K'(u) = 1 + c1 u + c2 u^2 + c3 u^3`, refitted with the offset where one is named, leave
//! alike in every record (`select`'s test of look-alikes)? Then the records do not tell the
//! scale from the curvature's shape, the model with one name fewer is kept, and the pair is
//! reported. Records that tell them apart show the gain at small inputs (a rest and small steps
//! from 0 V) beside the large ones.
//!
//! Where the scale stays, it may stand in an offset's place (a sine over 2-9 V reads a 20 mV
//! offset as a 0.4 % scale and a bend): like for like, each beside the cubic curvature with as
//! many parameters, an offset that leaves less in every record than the scale refitted there
//! takes its place where it leaves no record worse than the model as it stands (`select`, step
//! 14; reported as a pair where the scale leaves no more than the look-alike bar above it).
//! The model kept then has the cubic term beside the offset: one parameter more than it had,
//! which the like-for-like comparison and the no-record-worse bar stand for.
//!
//! The fit: the simulated output is linear in `c1..c3` and the offset (the sensor adds the
//! offset; K'(u) enters the fast static map, which the linear plant follows), so Gauss-Newton
//! on finite-difference columns of the full simulation, computed once, converges in a step or
//! two (the
//! amplifier's slew limit and saturation, where named, are the only non-linear parts on the
//! way, and they act alike on the columns). A table of hysteresis is left out: K'(u) scales
//! it and the scale its reversible slope, a coupling this check does not model.

use super::catalogue;
use super::data::{Data, simulate_all};
use crate::io::model_file::{ModelFile, OffsetSection};
use crate::util::par_map;
use nalgebra::{DMatrix, DVector};

/// Gauss-Newton iterations at most, on the columns computed once (our assumption: the problem
/// is linear but for the amplifier's limits, so one or two suffice; two more for a limit that
/// bends it).
pub const SCALE_ORDER_ITERATIONS: usize = 4;

/// Tries of a step that does not lower the cost, each half the last (our assumption: a
/// thirty-second of the step is as far as a linear problem's step can be wrong).
pub const SCALE_ORDER_HALVINGS: usize = 6;

/// A step that lowers the summed mean squares by less than this share ends the iterations
/// (our assumption: far below what the look-alike test reads).
pub const SCALE_ORDER_SETTLED: f64 = 1e-6;

/// The steps of the finite differences, per parameter: `c1` per volt, `c2` per volt squared,
/// `c3` per volt cubed, the offset in volts, the scale (our assumption: each moves the output
/// by 8-80 mV at 10 V, far above the `f32` simulation's rounding and small enough for the amplifier's
/// limits to act alike on both points).
pub const SCALE_ORDER_STEPS: [f64; 5] = [1e-3, 1e-4, 1e-5, 1e-2, 1e-3];

/// A model refitted with K'(u) one order higher.
pub struct CubicFit {
    /// The refitted model.
    pub model: ModelFile,
    /// Its simulated outputs, one per record.
    pub sims: Vec<Vec<f64>>,
    /// Its mean squared residual per record.
    pub mse: Vec<f64>,
    /// The scale taken out (the model's `[sensor-gain]`).
    pub scale: f64,
    /// The cubic term fitted, per volt cubed.
    pub c3_per_v3: f64,
}

/// What stands in the scale's place beside the cubic curvature.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InPlace {
    /// Nothing: the scale taken out, the offset refitted where one is named.
    Nothing,
    /// An offset the model does not have (the scale taken out).
    Offset,
    /// The scale itself, refitted (the like-for-like rival of [`InPlace::Offset`]).
    Scale,
}

/// `model` with K'(u) refitted to a cubic and, by `place`, its `[sensor-gain]` taken out
/// (its factor moved into the drift's gains, which it multiplies as well) or refitted, and
/// an offset refitted where `named` holds one or `place` adds one; where `named` holds both a
/// `sensor-gain` and a `nonlinear-gain` and no `hysteresis`. `None` otherwise, with
/// [`InPlace::Offset`] where the model has an offset, or where no fit simulates.
pub fn curvature_in_scales_place(
    model: &ModelFile,
    named: &[String],
    data: &[Data],
    place: InPlace,
) -> Option<CubicFit> {
    let has = |e: &str| named.iter().any(|n| n == e);
    // (a table the base model holds, named or not, is scaled as well)
    if !has("sensor-gain")
        || !has("nonlinear-gain")
        || has("hysteresis")
        || catalogue::present(model, "hysteresis")
    {
        return None;
    }
    let has_offset = has("offset") && model.offset.is_some();
    if place == InPlace::Offset && (has("offset") || model.offset.is_some()) {
        return None;
    }
    let scale = model.sensor_gain.as_ref()?.gain;
    let gain = model.nonlinear_gain.as_ref()?;
    let mut start = model.clone();
    if place != InPlace::Scale {
        start.sensor_gain = None;
        if let Some(d) = start.drift.as_mut() {
            d.gains = d.gains.map(|g| g * scale);
        }
    }
    if place == InPlace::Offset {
        start.offset = Some(OffsetSection { offset_v: 0.0 });
    }
    let p0 = [
        gain.poly[1],
        gain.poly[2],
        gain.poly[3],
        start.offset.as_ref().map_or(0.0, |o| o.offset_v),
        scale,
    ];
    let free_offset = has_offset || place == InPlace::Offset;
    let (model, sims, mse, p) = fit_cubic(&start, p0, free_offset, place == InPlace::Scale, data)?;
    Some(CubicFit {
        model,
        sims,
        mse,
        scale,
        c3_per_v3: p[2],
    })
}

/// `start` with K'(u) refitted to a cubic from `p0` (`c1..c3`, the offset, the scale), with
/// its offset and its scale free where asked (`gauss_newton`); the others held.
#[allow(clippy::type_complexity)]
fn fit_cubic(
    start: &ModelFile,
    p0: [f64; 5],
    offset: bool,
    scale: bool,
    data: &[Data],
) -> Option<(ModelFile, Vec<Vec<f64>>, Vec<f64>, [f64; 5])> {
    // The free parameters, by their index into SCALE_ORDER_STEPS.
    let mut free: Vec<usize> = vec![0, 1, 2];
    if offset {
        free.push(3);
    }
    if scale {
        free.push(4);
    }
    let at = |p: &[f64]| -> ModelFile {
        let mut m = start.clone();
        if let Some(g) = m.nonlinear_gain.as_mut() {
            g.poly = [1.0, p[0], p[1], p[2]];
        }
        if offset && let Some(o) = m.offset.as_mut() {
            o.offset_v = p[3];
        }
        if scale && let Some(g) = m.sensor_gain.as_mut() {
            g.gain = p[4];
        }
        m
    };
    gauss_newton(&at, p0, &free, data)
}

/// Gauss-Newton on the parameters `free` of `p0` (the others held), the model at `p` given by
/// `at`: the finite-difference columns of the full simulation computed once (the output is
/// linear in K'(u)'s terms and the offset, and the scale, near 1, couples them weakly), each
/// step halved until the summed mean squares fall. The model, its simulations and mean squares,
/// and the parameters.
#[allow(clippy::type_complexity)]
fn gauss_newton(
    at: &(impl Fn(&[f64]) -> ModelFile + Sync),
    p0: [f64; 5],
    free: &[usize],
    data: &[Data],
) -> Option<(ModelFile, Vec<Vec<f64>>, Vec<f64>, [f64; 5])> {
    let cost = |mse: &[f64]| mse.iter().sum::<f64>();
    let mut p = p0;
    let (mut sims, mut mse) = simulate_all(&at(&p), data).ok()?;
    let cols: Vec<Option<Vec<Vec<f64>>>> = par_map(free, |&k| {
        let mut q = p;
        q[k] += SCALE_ORDER_STEPS[k];
        let (s, _) = simulate_all(&at(&q), data).ok()?;
        Some(
            s.iter()
                .zip(&sims)
                .map(|(a, b)| {
                    a.iter()
                        .zip(b)
                        .map(|(x, y)| (x - y) / SCALE_ORDER_STEPS[k])
                        .collect()
                })
                .collect(),
        )
    });
    let cols: Vec<Vec<Vec<f64>>> = cols.into_iter().collect::<Option<_>>()?;
    let np = free.len();
    // Normal equations, each record weighted by its length (records weigh equally, as the
    // mean squares do).
    let mut a = DMatrix::<f64>::zeros(np, np);
    for (r, d) in data.iter().enumerate() {
        let w = 1.0 / d.len().max(1) as f64;
        for j in 0..np {
            for k in 0..=j {
                let v: f64 = cols[j][r].iter().zip(&cols[k][r]).map(|(x, y)| x * y).sum();
                a[(j, k)] += w * v;
                a[(k, j)] = a[(j, k)];
            }
        }
    }
    let lu = a.lu();
    for _ in 0..SCALE_ORDER_ITERATIONS {
        let mut b = DVector::<f64>::zeros(np);
        for (r, d) in data.iter().enumerate() {
            let w = 1.0 / d.len().max(1) as f64;
            for (j, c) in cols.iter().enumerate() {
                let v: f64 = c[r]
                    .iter()
                    .zip(d.y_v.iter().zip(&sims[r]))
                    .map(|(x, (y, s))| x * (y - s))
                    .sum();
                b[j] += w * v;
            }
        }
        let step = lu.solve(&b)?;
        // Halve the step until the cost falls (a limit or an invalid K'(u) can bend it).
        let mut taken = false;
        let mut f = 1.0;
        for _ in 0..SCALE_ORDER_HALVINGS {
            let mut q = p;
            for (j, &k) in free.iter().enumerate() {
                q[k] += f * step[j];
            }
            if let Ok((s, m)) = simulate_all(&at(&q), data)
                && cost(&m) < cost(&mse)
            {
                let settled = cost(&mse) - cost(&m) < SCALE_ORDER_SETTLED * cost(&mse);
                (p, sims, mse) = (q, s, m);
                taken = !settled;
                break;
            }
            f *= 0.5;
        }
        if !taken {
            break;
        }
    }
    Some((at(&p), sims, mse, p))
}

/// `model` without its `[offset]`, K'(u) refitted to a cubic (and the scale, where one is
/// named): an offset beside a curvature that a curvature of one more order may do without
/// (`select`, step 14 (c)). Where `named` holds `offset` and `nonlinear-gain` and neither a
/// `hysteresis` (a table's constant is step 13's) nor a `drift` (a creep's start is step
/// 12's); `None` otherwise, or where no fit simulates. The cubic fit's `scale` is the scale
/// the model keeps (1 where none is named).
pub fn curvature_in_offsets_place(
    model: &ModelFile,
    named: &[String],
    data: &[Data],
) -> Option<CubicFit> {
    let has = |e: &str| named.iter().any(|n| n == e);
    if !has("offset")
        || !has("nonlinear-gain")
        || has("hysteresis")
        || has("drift")
        || catalogue::present(model, "hysteresis")
        || catalogue::present(model, "drift")
    {
        return None;
    }
    model.offset.as_ref()?;
    let gain = model.nonlinear_gain.as_ref()?;
    let scaled = has("sensor-gain") && model.sensor_gain.is_some();
    let scale = model.sensor_gain.as_ref().map_or(1.0, |g| g.gain);
    let mut start = model.clone();
    start.offset = None;
    let p0 = [gain.poly[1], gain.poly[2], gain.poly[3], 0.0, scale];
    let (model, sims, mse, p) = fit_cubic(&start, p0, false, scaled, data)?;
    Some(CubicFit {
        model,
        sims,
        mse,
        scale: p[4],
        c3_per_v3: p[2],
    })
}
