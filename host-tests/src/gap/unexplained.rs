//! Never silent (issue #12, item 5): when the workflow stops with some record's residual still
//! above [`UNEXPLAINED_FLOOR_RATIO`] times its noise floor, the part no catalogued effect
//! explained is reported, with where it sits, in the table, the report and the JSON
//! (`"unexplained": {"rms_v", "where"}`).
//!
//! Where, per record above the bar, from the final residual alone (no assumption of holds,
//! edges or a fast/slow pair):
//! * **in time**: the tenth of the record (ten equal windows) that holds the largest share of
//!   the residual power;
//! * **against the input**: the tenth of the record's input span whose samples carry the largest
//!   mean-square residual, and whether the residual differs between rising and falling input
//!   there (a loop the model lacks);
//! * **in frequency**: the strongest line of the residual's amplitude spectrum (one Hann
//!   window over up to 2^16 samples) and the share of the residual power within 10 % of it.
//!
//! `rms_v` is the residual RMS with the noise floor taken out in quadrature, the root of the
//! mean over records of `max(MSE_r - floor_r^2, 0)`: the part a model could still explain.

use super::data::{Data, min_max};
use super::signatures::averaged_spectrum;

/// A record is left unexplained when its final residual RMS exceeds this many times its noise
/// floor (the bar: "above 2x the floor").
pub const UNEXPLAINED_FLOOR_RATIO: f64 = 2.0;

/// The residual no catalogued effect explained.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Unexplained {
    /// Residual RMS above the noise (quadrature), volts.
    pub rms_v: f64,
    /// Where it sits, in words (times, input ranges, frequencies), per record.
    #[serde(rename = "where")]
    pub where_: String,
}

/// The unexplained residual of `y - sims`, if some record stays above the bar.
pub fn locate(data: &[Data], sims: &[Vec<f64>], noise: &[f64]) -> Option<Unexplained> {
    let mut parts = Vec::new();
    let mut excess = 0.0;
    for ((d, y), f) in data.iter().zip(sims).zip(noise) {
        let r: Vec<f64> = d.y_v.iter().zip(y).map(|(a, b)| a - b).collect();
        let ms = r.iter().map(|e| e * e).sum::<f64>() / r.len().max(1) as f64;
        excess += (ms - f * f).max(0.0);
        if ms.sqrt() > UNEXPLAINED_FLOOR_RATIO * f {
            parts.push(format!(
                "{} ({:.2} mV, {:.1}x its floor): {}",
                d.name,
                1e3 * ms.sqrt(),
                ms.sqrt() / f.max(1e-12),
                describe(d, &r)
            ));
        }
    }
    if parts.is_empty() {
        return None;
    }
    Some(Unexplained {
        rms_v: (excess / data.len().max(1) as f64).sqrt(),
        where_: parts.join("; "),
    })
}

/// Where the residual `r` of record `d` sits, in words.
#[allow(clippy::needless_range_loop)] // input, residual and bins indexed together
fn describe(d: &Data, r: &[f64]) -> String {
    let n = r.len();
    let total: f64 = r.iter().map(|e| e * e).sum::<f64>().max(1e-300);
    // In time: ten equal windows.
    let w = n.div_ceil(10).max(1);
    let (k, p) = (0..n.div_ceil(w))
        .map(|k| {
            let s: f64 = r[k * w..((k + 1) * w).min(n)].iter().map(|e| e * e).sum();
            (k, s)
        })
        .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    let t0 = d.t_s[k * w];
    let t1 = d.t_s[((k + 1) * w).min(n) - 1];
    let time = format!(
        "{:.0} % of its residual power in t = {t0:.3}-{t1:.3} s",
        100.0 * p / total
    );
    // Against the input: ten bins of the span, the one with the largest mean square.
    let (lo, hi) = min_max(&d.u_v);
    let span = (hi - lo).max(1e-9);
    let mut bins = vec![(0.0f64, 0usize, 0.0f64, 0usize, 0.0f64, 0usize); 10];
    for i in 0..n {
        let b = (((d.u_v[i] - lo) / span * 10.0) as usize).min(9);
        bins[b].0 += r[i] * r[i];
        bins[b].1 += 1;
        let du = if i > 0 { d.u_v[i] - d.u_v[i - 1] } else { 0.0 };
        if du > 0.0 {
            bins[b].2 += r[i];
            bins[b].3 += 1;
        } else if du < 0.0 {
            bins[b].4 += r[i];
            bins[b].5 += 1;
        }
    }
    let (b, bin) =
        bins.iter()
            .enumerate()
            .filter(|(_, x)| x.1 > 0)
            .fold((0, bins[0]), |a, (i, x)| {
                if x.0 / x.1 as f64 > a.1.0 / a.1.1.max(1) as f64 {
                    (i, *x)
                } else {
                    a
                }
            });
    let u0 = lo + span * b as f64 / 10.0;
    let mut input = format!(
        "largest at u = {u0:.2}-{:.2} V ({:.2} mV RMS there)",
        u0 + span / 10.0,
        1e3 * (bin.0 / bin.1.max(1) as f64).sqrt()
    );
    if bin.3 >= 10 && bin.5 >= 10 {
        let gap = bin.2 / bin.3 as f64 - bin.4 / bin.5 as f64;
        input.push_str(&format!(
            ", rising minus falling input {:+.2} mV",
            1e3 * gap
        ));
    }
    format!("{time}; {input}; {}", line(r, d.period_s()))
}

/// The strongest line of `r`'s spectrum and its share of the power, in words: one Hann
/// segment over the record (at most 2^16 samples), the line test's own spectrum routine.
fn line(r: &[f64], t: f64) -> String {
    let n = r.len().min(1 << 16);
    if n < 64 {
        return "too short for a spectrum".into();
    }
    let x = &r[..n];
    let m = x.iter().sum::<f64>() / n as f64;
    // Power per bin, up to a common factor (the shares below are ratios).
    let p: Vec<(f64, f64)> = averaged_spectrum(x, t, n)
        .into_iter()
        .map(|(f, a)| (f, a * a))
        .collect();
    let total: f64 = p.iter().map(|b| b.1).sum::<f64>().max(1e-300);
    let k = (0..p.len()).fold(0, |a, k| if p[k].1 > p[a].1 { k } else { a });
    let f = p[k].0;
    let near: f64 = p
        .iter()
        .enumerate()
        .filter(|&(j, b)| (b.0 / f - 1.0).abs() <= 0.1 || j.abs_diff(k) <= 2)
        .map(|(_, b)| b.1)
        .sum();
    let dc_share = 100.0 * m * m * n as f64 / x.iter().map(|e| e * e).sum::<f64>().max(1e-300);
    format!(
        "strongest residual frequency {f:.3} Hz ({:.0} % of the varying power within 10 % of it); mean {:.2} mV ({dc_share:.0} % of the power)",
        100.0 * near / total,
        1e3 * m
    )
}
