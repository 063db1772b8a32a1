//! The fit of a fast effect (time delay, amplifier pole, resonance, slew limit, saturation):
//! a bounded search on the fast records, where these effects show. A coarse grid over the
//! catalogue's bounds (log-spaced where [`super::catalogue::FastSpec::log`] says so; for a
//! resonance, plus the residual spectrum's line and three damping ratios), then golden-section
//! refinement ([`crate::util::golden`]). The cost is `sum_r n_r ln MSE_r` over the fast
//! records, each candidate simulated with the whole current model.

use super::catalogue;
use super::data::{Data, mse, sim};
use crate::io::model_file::ModelFile;
use crate::util::golden;

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
    let cost = |m: &ModelFile| -> f64 {
        let mut c = 0.0;
        for &i in idx {
            match sim(m, &data[i]) {
                Ok(s) => c += data[i].len() as f64 * mse(&data[i].y_v, &s).max(1e-14).ln(),
                Err(_) => return f64::INFINITY,
            }
        }
        c
    };
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
            let c = cost(&catalogue::with_fast(model, effect, from(x), zz));
            if c < best.0 {
                best = (c, x);
                z = zz;
            }
        }
    }
    if x0.is_finite() {
        let c = cost(&catalogue::with_fast(model, effect, x0, z0));
        if c < best.0 {
            best = (c, to(x0));
            z = z0;
        }
    }
    let h = (b - a) / grid as f64;
    let x = golden(best.1 - h, best.1 + h, a, b, |x| {
        cost(&catalogue::with_fast(model, effect, from(x), z))
    });
    let mut xbest = from(x);
    if effect == "resonance" {
        let lz = golden(
            (z / 3.0).ln(),
            (z * 3.0).ln(),
            (0.005f64).ln(),
            (0.5f64).ln(),
            |lz| cost(&catalogue::with_fast(model, effect, xbest, lz.exp())),
        );
        z = lz.exp();
        let x2 = golden(to(xbest) - h / 2.0, to(xbest) + h / 2.0, a, b, |x| {
            cost(&catalogue::with_fast(model, effect, from(x), z))
        });
        xbest = from(x2);
    }
    let m = catalogue::with_fast(model, effect, xbest, z);
    let c = cost(&m);
    c.is_finite().then_some((m, c))
}

/// Whether no slew limit the search can set (down to the catalogue's lowest, 15 V/ms at the
/// amplifier's output) would ever act on the records `idx`: the amplifier's output moves by
/// its gain times the DAC's step of the held input at a sample's edge, and no more (its clamps
/// only shorten that), so where the largest such move, the DAC's rounding and a margin for
/// the f32 stage included, is below what the lowest limit allows in one step, every limit
/// leaves the stage's output as it is, bit for bit, and its search's every simulation is the
/// model's own. (Beside another fast effect named its search also refits that one, which can
/// gain: the caller asks this only where none is.)
pub(super) fn slew_out_of_reach(model: &ModelFile, data: &[Data], idx: &[usize]) -> bool {
    let Some(spec) = catalogue::fast_spec("slew-rate-limit") else {
        return false;
    };
    let lsb_v = if model.converters.dac {
        f64::from(model_core::codes::DacCode::VOLT_PER_LSB)
    } else {
        0.0
    };
    let max_step_v = idx
        .iter()
        .filter_map(|&i| data.get(i))
        .flat_map(|d| d.u_v.windows(2).map(|w| (w[1] - w[0]).abs()))
        .fold(0.0f64, f64::max);
    let reach_v = model.amplifier.gain.abs() * (max_step_v + lsb_v) * 1.001 + 1e-6;
    reach_v.is_finite() && reach_v < 0.99 * spec.lo * model.period_s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::csv::Record;

    /// Where the records' input steps never reach the lowest slew limit, the model with that
    /// limit simulates to the same bits as without it; where they do (a 1 V jump), the check
    /// says so. Records at 5 kHz: a 1 Hz sine over 0.5-9.5 V (5.7 mV steps, 57 mV at the
    /// amplifier's output against the 0.3 V a 20 us step allows), the same sine at 4 Hz
    /// (0.23 V, the DAC's step included: still below) and at 50 Hz (2.8 V: reached), and
    /// levels 1 V apart.
    #[test]
    fn a_slew_limit_the_input_never_reaches_changes_nothing() {
        let rate = 5e3;
        let n = 10_000;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / rate).collect();
        let sine = |hz: f64| -> Vec<f64> {
            t.iter()
                .map(|&x| 5.0 - 4.5 * (std::f64::consts::TAU * hz * x).cos())
                .collect()
        };
        let levels: Vec<f64> = (0..n)
            .map(|i| [2.0, 3.0, 5.0, 4.0][(i / 500) % 4])
            .collect();
        let record = |u: &[f64]| {
            Data::from_record(
                "r.csv",
                Record::new(t.clone(), u.to_vec(), Some(u.to_vec()), None).unwrap(),
            )
            .unwrap()
        };
        let model = ModelFile::built_in("thesis-linear").unwrap();
        let lo = catalogue::fast_spec("slew-rate-limit").unwrap().lo;
        let limited = catalogue::with_fast(&model, "slew-rate-limit", lo, 0.0);
        for (u, unreached) in [
            (sine(1.0), true),
            (sine(4.0), true),
            (sine(50.0), false),
            (levels, false),
        ] {
            let d = record(&u);
            assert_eq!(
                slew_out_of_reach(&model, std::slice::from_ref(&d), &[0]),
                unreached
            );
            let (a, b) = (sim(&model, &d).unwrap(), sim(&limited, &d).unwrap());
            if unreached {
                assert_eq!(a, b, "a limit the input never reaches changed the output");
            } else {
                assert_ne!(a, b, "the input's steps are slowed by the lowest limit");
            }
        }
    }
}
