//! The play operators' radii, refined (issue #12, item 2, as far as the play form goes): the
//! slow fit picks the operators from the fixed grid [`super::catalogue::PLAY_GRID_V`] and
//! merges neighbours down to the stage's [`model_core::params::PLAY_OPERATORS`], so a truth
//! whose operators sit between grid radii (a Prandtl-Ishlinskii stage with its own radii) is
//! matched only to a few millivolts. Here each radius is moved continuously (golden section on
//! `ln r` between its neighbours, coordinate descent), the weights re-solved with the sign
//! constraint at every trial (variable projection: the weights are linear, the radii not).
//!
//! The target is the residual of the final model without its play sum, on the settled samples
//! (records weigh equally); a column is the operator's `z - u` times the model's `K'(u)` and
//! sensor gain, as the stage applies them. The plant's dynamics are left out (the settled
//! samples of slow motion are quasi-static), so the caller keeps the result only if the full
//! simulation agrees.

use super::constants::SETTLE_S;
use super::data::Data;
use super::nnls::{nnls_normal, ridge};
use crate::io::model_file::{ModelFile, PlaySection};
use crate::util::golden_n;
use model_core::params::PLAY_OPERATORS;
use nalgebra::{DMatrix, DVector};

/// A trial radius: (reduction of the weighted SSR, Gram matrix, right-hand side, its column).
type Trial = (f64, DMatrix<f64>, DVector<f64>, Vec<Vec<f64>>);

/// Golden-section steps per radius and pass (our assumption: 14 steps narrow a bracket of a
/// factor 2 in radius to 0.2 %).
const GOLDEN_STEPS: usize = 14;
/// Passes of coordinate descent over the radii.
const PASSES: usize = 3;

/// `model` with its play radii refined against `residual` (`y` minus the simulation of `model`
/// without its play sum), or `None` if it has no play sum or the solve fails.
pub fn refine_play_radii(
    model: &ModelFile,
    data: &[Data],
    residual: &[Vec<f64>],
) -> Option<ModelFile> {
    let play = model.hysteresis_play.as_ref()?;
    let kp = |u: f64| {
        model.nonlinear_gain.as_ref().map_or(1.0, |g| {
            let x = u.clamp(g.range_v[0], g.range_v[1]);
            g.poly[0] + x * (g.poly[1] + x * g.poly[2])
        })
    };
    let sg = model.sensor_gain.as_ref().map_or(1.0, |g| g.gain) * model.converters.sensor_gain;
    // Settled samples and their weights, per record.
    let recs: Vec<(f64, Vec<usize>)> = data
        .iter()
        .map(|d| {
            let settle = (SETTLE_S / d.period_s()).ceil() as usize;
            let mut last: Option<usize> = None;
            let idx: Vec<usize> = (0..d.len())
                .filter(|&i| {
                    if d.is_jump(i) {
                        last = Some(i);
                    }
                    last.is_none_or(|j| i - j > settle)
                })
                .collect();
            (1.0 / idx.len().max(1) as f64, idx)
        })
        .collect();
    let column = |r: f64| -> Vec<Vec<f64>> {
        data.iter()
            .zip(&recs)
            .map(|(d, (_, idx))| {
                let mut z = d.u_v[0];
                let full: Vec<f64> = d
                    .u_v
                    .iter()
                    .map(|&u| {
                        z = z.max(u - r).min(u + r);
                        (z - u) * kp(u) * sg
                    })
                    .collect();
                idx.iter().map(|&i| full[i]).collect()
            })
            .collect()
    };
    let target: Vec<Vec<f64>> = residual
        .iter()
        .zip(&recs)
        .map(|(e, (_, idx))| idx.iter().map(|&i| e[i]).collect())
        .collect();
    let dot = |a: &[Vec<f64>], b: &[Vec<f64>]| -> f64 {
        a.iter()
            .zip(b)
            .zip(&recs)
            .map(|((x, y), (w, _))| w * x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>())
            .sum()
    };
    let mut radii = play.radii_v;
    let mut cols: Vec<Vec<Vec<f64>>> = radii.iter().map(|&r| column(r)).collect();
    let n = PLAY_OPERATORS;
    let mut g = DMatrix::<f64>::zeros(n, n);
    let mut b = DVector::<f64>::zeros(n);
    for i in 0..n {
        b[i] = dot(&cols[i], &target);
        for j in 0..=i {
            g[(i, j)] = dot(&cols[i], &cols[j]);
            g[(j, i)] = g[(i, j)];
        }
    }
    let solve = |g: &DMatrix<f64>, b: &DVector<f64>| -> Option<(DVector<f64>, f64)> {
        let mut a = g.clone();
        ridge(&mut a);
        let x = nnls_normal(&a, b, &[true; PLAY_OPERATORS])?;
        let red = x.dot(b);
        red.is_finite().then_some((x, red))
    };
    let (_, mut best) = solve(&g, &b)?;
    // The radii in increasing order, so each moves between its neighbours.
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &c| radii[a].total_cmp(&radii[c]));
    for _ in 0..PASSES {
        for (k, &m) in order.iter().enumerate() {
            let lo = if k > 0 {
                radii[order[k - 1]] * 1.02
            } else {
                0.005
            };
            let hi = if k + 1 < n {
                radii[order[k + 1]] / 1.02
            } else {
                8.0
            };
            if lo >= hi {
                continue;
            }
            let trial = |r: f64| -> Option<Trial> {
                let c = column(r);
                let mut g2 = g.clone();
                let mut b2 = b.clone();
                b2[m] = dot(&c, &target);
                for j in 0..n {
                    let v = if j == m {
                        dot(&c, &c)
                    } else {
                        dot(&c, &cols[j])
                    };
                    g2[(m, j)] = v;
                    g2[(j, m)] = v;
                }
                let (_, red) = solve(&g2, &b2)?;
                Some((red, g2, b2, c))
            };
            let (a, c) = (lo.ln(), hi.ln());
            let lr = golden_n(a, c, a, c, GOLDEN_STEPS, |lr| {
                trial(lr.exp()).map_or(f64::INFINITY, |t| -t.0)
            });
            if let Some((red, g2, b2, c)) = trial(lr.exp())
                && red > best
            {
                best = red;
                radii[m] = lr.exp();
                g = g2;
                b = b2;
                cols[m] = c;
            }
        }
    }
    let (w, _) = solve(&g, &b)?;
    let mut out = model.clone();
    let mut weights = [0.0; PLAY_OPERATORS];
    for (i, wi) in weights.iter_mut().enumerate() {
        *wi = w[i];
    }
    out.hysteresis_play = Some(PlaySection {
        radii_v: radii,
        weights,
    });
    out.build_stage().ok().map(|_| out)
}
