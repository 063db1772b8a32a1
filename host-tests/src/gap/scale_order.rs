//! A sensor scale or an offset beside a curvature, against curvatures of higher order (GAP.md
//! step 14).
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
//! drift's gains, which it multiplies as well), does a curvature of higher order, refitted
//! with the offset where one is named, leave alike in every record (`select`'s test of
//! look-alikes)? Then the records do not tell the scale from the curvature's shape, the model
//! with one name fewer is kept, and the pair is reported. Records that tell them apart show
//! the gain at small inputs (a rest and small steps from 0 V) beside the large ones.
//!
//! # Orders (session 49)
//! The orders are tried from the cubic up to the highest model-core's K'(u) holds
//! ([`CURVATURE_ORDERS`], `u^3..u^6`), the lowest that does being kept; above the cubic the
//! curvature must also leave alike against its like-for-like rival, the order below refitted
//! beside the scale ([`refit_order`]: as many parameters). A `tanh` plateau over 1.4-9.3 V
//! (families cases 2577, 2737, 2758, 2721) is no cubic: beside the quadratic a scale took
//! 14-51 % of what was left, and the cubic without it left 1.7-2.9x as much above the floor,
//! while the quartic without it left less than the cubic beside it (2577: 2.39 mV against
//! 4.21 mV, and 4.22 mV with the scale and the quadratic). The same search stands for an
//! offset beside a curvature ([`curvature_in_offsets_place`], step 14 (c); 2628).
//!
//! Where the scale stays, it may stand in an offset's place (a sine over 2-9 V reads a 20 mV
//! offset as a 0.4 % scale and a bend): like for like, each beside the cubic curvature with as
//! many parameters, an offset that leaves less in every record than the scale refitted there
//! takes its place where it leaves no record worse than the model as it stands (`select`, step
//! 14; reported as a pair where the scale leaves no more than the look-alike bar above it).
//! The model kept then has the cubic term beside the offset: one parameter more than it had,
//! which the like-for-like comparison and the no-record-worse bar stand for.
//!
//! The fit: the simulated output is linear in K'(u)'s terms and the offset (the sensor adds
//! the offset; K'(u) enters the fast static map, which the linear plant follows), so
//! Gauss-Newton on finite-difference columns of the full simulation, computed once, converges
//! in a step or two (the amplifier's slew limit and saturation, where named, are the only
//! non-linear parts on the way, and they act alike on the columns). K'(u)'s directions are
//! `u P_k(x)`, Legendre polynomials over the gain's range (`legendre_in_u`): the plain
//! powers up to `u^6` are nearly collinear over 1-9 V, and the columns come from `f32`
//! simulations. A table of hysteresis is left out: K'(u) scales it and the scale its
//! reversible slope, a coupling this check does not model.

use super::catalogue;
use super::data::{Data, simulate_all};
use crate::io::model_file::{ModelFile, OffsetSection, SensorGainSection};
use crate::util::par_map;
use model_core::gain::POLY_TERMS;
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

/// The steps of the finite differences: a curvature direction's largest move of the static
/// output over the gain's range, volts; the offset, volts; the scale (our assumption: each
/// moves the output by 10-40 mV, far above the `f32` simulation's rounding and small enough
/// for the amplifier's limits to act alike on both points).
pub const SCALE_ORDER_STEPS: [f64; 3] = [4e-2, 1e-2, 1e-3];

/// The cubic: one order above the catalogue's quadratic K'(u), the first order step 14 tries
/// and the one the scale's like-for-like rival, an offset in its place, is fitted beside.
pub const CUBIC: usize = 3;

/// The orders of K'(u) step 14 weighs a scale or an offset against, lowest first: from the
/// [`CUBIC`] to the highest model-core holds ([`POLY_TERMS`]` - 1`).
pub const CURVATURE_ORDERS: std::ops::RangeInclusive<usize> = CUBIC..=POLY_TERMS - 1;

/// A model refitted with K'(u) of a higher order.
pub struct CurvatureFit {
    /// The refitted model.
    pub model: ModelFile,
    /// Its simulated outputs, one per record.
    pub sims: Vec<Vec<f64>>,
    /// Its mean squared residual per record.
    pub mse: Vec<f64>,
    /// The scale taken out (the model's `[sensor-gain]`).
    pub scale: f64,
    /// K'(u)'s order (its highest power).
    pub order: usize,
    /// K'(u)'s term of that power, per volt to the order.
    pub top_term: f64,
}

/// What stands in the scale's place beside the curvature of higher order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InPlace {
    /// Nothing: the scale taken out, the offset refitted where one is named.
    Nothing,
    /// An offset the model does not have (the scale taken out).
    Offset,
    /// The scale itself, refitted (the like-for-like rival of [`InPlace::Offset`]).
    Scale,
}

/// `model` with K'(u) refitted to `order` (its terms `u..u^order`) and, by `place`, its
/// `[sensor-gain]` taken out (its factor moved into the drift's gains, which it multiplies as
/// well) or refitted, and an offset refitted where `named` holds one or `place` adds one;
/// where `named` holds both a `sensor-gain` and a `nonlinear-gain` and no `hysteresis`. `None`
/// otherwise, with [`InPlace::Offset`] where the model has an offset, or where no fit
/// simulates.
pub fn curvature_in_scales_place(
    model: &ModelFile,
    named: &[String],
    data: &[Data],
    place: InPlace,
    order: usize,
) -> Option<CurvatureFit> {
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
    model.nonlinear_gain.as_ref()?;
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
    let free_offset = has_offset || place == InPlace::Offset;
    let (model, sims, mse) =
        fit_curvature(&start, order, free_offset, place == InPlace::Scale, data)?;
    Some(CurvatureFit::new(model, sims, mse, scale, order))
}

impl CurvatureFit {
    fn new(model: ModelFile, sims: Vec<Vec<f64>>, mse: Vec<f64>, scale: f64, order: usize) -> Self {
        let top_term = model.nonlinear_gain.as_ref().map_or(0.0, |g| g.poly[order]);
        Self {
            model,
            sims,
            mse,
            scale,
            order,
            top_term,
        }
    }
}

/// The monomial coefficients (lowest power first) of the Legendre polynomial `P_n(x)`, `x`
/// mapped from `u` in `[lo, hi]` onto `[-1, 1]`: directions of K'(u) that are about orthogonal
/// over the records' span (the plain powers `u^k` on 1-9 V are nearly collinear, and the
/// columns come from `f32` simulations). `n < POLY_TERMS`.
fn legendre_in_u(n: usize, lo: f64, hi: f64) -> [f64; POLY_TERMS] {
    let (a, b) = (2.0 / (hi - lo), -(hi + lo) / (hi - lo));
    let times_x = |p: &[f64; POLY_TERMS]| {
        let mut q = [0.0; POLY_TERMS];
        for k in 0..POLY_TERMS {
            q[k] += b * p[k];
            if k + 1 < POLY_TERMS {
                q[k + 1] += a * p[k];
            }
        }
        q
    };
    let mut prev = [0.0; POLY_TERMS];
    let mut cur = [0.0; POLY_TERMS];
    cur[0] = 1.0;
    for m in 0..n {
        // ((m + 1) P_{m+1} = (2m + 1) x P_m - m P_{m-1})
        let xp = times_x(&cur);
        let mut next = [0.0; POLY_TERMS];
        for k in 0..POLY_TERMS {
            next[k] = ((2 * m + 1) as f64 * xp[k] - m as f64 * prev[k]) / (m + 1) as f64;
        }
        prev = cur;
        cur = next;
    }
    cur
}

/// `start` with K'(u) refitted to `order` (all its terms `u..u^order`, K'(0) = 1 held), and its
/// offset and its scale free where asked (`gauss_newton`); the others held. The directions of
/// K'(u) are `u P_k(x)`, `k < order` (about orthogonal over the gain's range, each scaled to
/// move the static output by [`SCALE_ORDER_STEPS`]`[0]` at most).
#[allow(clippy::type_complexity)]
fn fit_curvature(
    start: &ModelFile,
    order: usize,
    offset: bool,
    scale: bool,
    data: &[Data],
) -> Option<(ModelFile, Vec<Vec<f64>>, Vec<f64>)> {
    if !(1..POLY_TERMS).contains(&order) {
        return None;
    }
    let gain = start.nonlinear_gain.as_ref()?;
    let [lo, hi] = gain.range_v;
    if hi <= lo {
        return None;
    }
    let base = gain.poly;
    let top = lo.abs().max(hi.abs()).max(1e-3);
    let dirs: Vec<[f64; POLY_TERMS]> = (0..order)
        .map(|k| {
            let p = legendre_in_u(k, lo, hi);
            let mut d = [0.0; POLY_TERMS];
            d[1..].copy_from_slice(&p[..POLY_TERMS - 1]);
            // (|u P_k(x)| <= |u| on the range: the static map moves by at most u^2 times it)
            d.map(|c| c * SCALE_ORDER_STEPS[0] / (top * top))
        })
        .collect();
    let mut p0 = vec![0.0; order];
    p0.push(start.offset.as_ref().map_or(0.0, |o| o.offset_v));
    p0.push(start.sensor_gain.as_ref().map_or(1.0, |g| g.gain));
    let mut steps = vec![1.0; order];
    steps.extend([SCALE_ORDER_STEPS[1], SCALE_ORDER_STEPS[2]]);
    let mut free: Vec<usize> = (0..order).collect();
    if offset {
        free.push(order);
    }
    if scale {
        free.push(order + 1);
    }
    let at = |p: &[f64]| -> ModelFile {
        let mut m = start.clone();
        if let Some(g) = m.nonlinear_gain.as_mut() {
            let mut poly = base;
            for (d, a) in dirs.iter().zip(p) {
                for (c, dc) in poly.iter_mut().zip(d) {
                    *c += a * dc;
                }
            }
            // (K'(0) = 1, and no term above the order: the directions do not move them)
            poly[0] = 1.0;
            for c in poly.iter_mut().skip(order + 1) {
                *c = 0.0;
            }
            g.poly = poly;
        }
        if offset && let Some(o) = m.offset.as_mut() {
            o.offset_v = p[order];
        }
        if scale && let Some(g) = m.sensor_gain.as_mut() {
            g.gain = p[order + 1];
        }
        m
    };
    let (model, sims, mse) = gauss_newton(&at, p0, &steps, &free, data)?;
    Some((model, sims, mse))
}

/// Gauss-Newton on the parameters `free` of `p0` (the others held), the model at `p` given by
/// `at`, `steps` the finite differences' steps: the columns of the full simulation computed
/// once (the output is linear in K'(u)'s terms and the offset, and the scale, near 1, couples
/// them weakly), each step halved until the summed mean squares fall. The model, its
/// simulations and mean squares.
#[allow(clippy::type_complexity)]
fn gauss_newton(
    at: &(impl Fn(&[f64]) -> ModelFile + Sync),
    p0: Vec<f64>,
    steps: &[f64],
    free: &[usize],
    data: &[Data],
) -> Option<(ModelFile, Vec<Vec<f64>>, Vec<f64>)> {
    let cost = |mse: &[f64]| mse.iter().sum::<f64>();
    let mut p = p0;
    let (mut sims, mut mse) = simulate_all(&at(&p), data).ok()?;
    let cols: Vec<Option<Vec<Vec<f64>>>> = par_map(free, |&k| {
        let mut q = p.clone();
        q[k] += steps[k];
        let (s, _) = simulate_all(&at(&q), data).ok()?;
        Some(
            s.iter()
                .zip(&sims)
                .map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y) / steps[k]).collect())
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
            let mut q = p.clone();
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
    Some((at(&p), sims, mse))
}

/// Step 14 (c) and (d)'s case: `named` holds `offset` and `nonlinear-gain` and the model
/// has both, and neither a `hysteresis` (a table's constant is step 13's) nor a `drift` (a
/// creep's start is step 12's) is named or in the model.
fn offset_beside_curvature_alone(model: &ModelFile, named: &[String]) -> bool {
    let has = |e: &str| named.iter().any(|n| n == e);
    has("offset")
        && has("nonlinear-gain")
        && !has("hysteresis")
        && !has("drift")
        && !catalogue::present(model, "hysteresis")
        && !catalogue::present(model, "drift")
        && model.offset.is_some()
        && model.nonlinear_gain.is_some()
}

/// `model` without its `[offset]`, K'(u) refitted to `order` (and the scale, where one is
/// named): an offset beside a curvature that a curvature of higher order may do without
/// (`select`, step 14 (c)). Where `named` holds `offset` and `nonlinear-gain` and neither a
/// `hysteresis` (a table's constant is step 13's) nor a `drift` (a creep's start is step
/// 12's); `None` otherwise, or where no fit simulates. The fit's `scale` is the scale the
/// model keeps (1 where none is named).
pub fn curvature_in_offsets_place(
    model: &ModelFile,
    named: &[String],
    data: &[Data],
    order: usize,
) -> Option<CurvatureFit> {
    if !offset_beside_curvature_alone(model, named) {
        return None;
    }
    let has = |e: &str| named.iter().any(|n| n == e);
    let scaled = has("sensor-gain") && model.sensor_gain.is_some();
    let mut start = model.clone();
    start.offset = None;
    let (model, sims, mse) = fit_curvature(&start, order, false, scaled, data)?;
    let scale = model.sensor_gain.as_ref().map_or(1.0, |g| g.gain);
    Some(CurvatureFit::new(model, sims, mse, scale, order))
}

/// `model` without its `[offset]`, a `[sensor-gain]` fitted in its place and K'(u) refitted
/// to `order`: the mirror of [`InPlace::Offset`] (a scale in an offset's place, like for
/// like beside the same curvature; `select`, step 14 (d)). Where `named` holds `offset` and
/// `nonlinear-gain` and neither a `sensor-gain`, a `hysteresis` (a table's constant is step
/// 13's) nor a `drift` (a creep's start is step 12's); `None` otherwise, or where no fit
/// simulates. The fit's `scale` is the scale fitted.
pub fn scale_in_offsets_place(
    model: &ModelFile,
    named: &[String],
    data: &[Data],
    order: usize,
) -> Option<CurvatureFit> {
    if !offset_beside_curvature_alone(model, named)
        || named.iter().any(|n| n == "sensor-gain")
        || model.sensor_gain.is_some()
    {
        return None;
    }
    let mut start = model.clone();
    start.offset = None;
    start.sensor_gain = Some(SensorGainSection { gain: 1.0 });
    let (model, sims, mse) = fit_curvature(&start, order, false, true, data)?;
    let scale = model.sensor_gain.as_ref().map_or(1.0, |g| g.gain);
    Some(CurvatureFit::new(model, sims, mse, scale, order))
}

/// `model` with K'(u) refitted to `order`, its offset and its scale refitted where `named`
/// holds them: the like-for-like rival, with as many parameters, of a curvature one order
/// higher in a scale's or an offset's place (`select`, step 14). Where `named` holds a
/// `nonlinear-gain` and no `hysteresis`; `None` otherwise, or where no fit simulates.
pub fn refit_order(
    model: &ModelFile,
    named: &[String],
    data: &[Data],
    order: usize,
) -> Option<CurvatureFit> {
    let has = |e: &str| named.iter().any(|n| n == e);
    if !has("nonlinear-gain") || has("hysteresis") || catalogue::present(model, "hysteresis") {
        return None;
    }
    model.nonlinear_gain.as_ref()?;
    let offset = has("offset") && model.offset.is_some();
    let scaled = has("sensor-gain") && model.sensor_gain.is_some();
    let (model, sims, mse) = fit_curvature(model, order, offset, scaled, data)?;
    let scale = model.sensor_gain.as_ref().map_or(1.0, |g| g.gain);
    Some(CurvatureFit::new(model, sims, mse, scale, order))
}
