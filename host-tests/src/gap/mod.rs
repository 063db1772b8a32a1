//! The model-gap workflow (issue #7): find where simulation and measurement disagree, name the
//! missing effect, add it with fitted parameters, show the gap shrink, repeat.
//!
//! # The loop
//! 1. **Simulate** every record with the current model ([`model_core::stage::Stage`] at the
//!    model's own fixed step, the record's input held between samples:
//!    [`crate::sim::open_loop`]), without sensor noise, and take the residual
//!    `y_measured - y_simulated`.
//! 2. **Noise floor** of each record, from the data alone: the median absolute second
//!    difference of `y` (robust to the few edges; `1.4826 MAD / sqrt(6)` is the standard
//!    deviation of white noise), on the samples at least 10 ms after the last input change
//!    when there are enough of them (so ringing after edges does not count as noise).
//! 3. **Localise** the disagreement: in time (after edges, during holds, during slow cycles)
//!    and in frequency (the residual spectrum of the fast records, rustfft). These are the
//!    signature checks and the evidence printed for each effect ([`signatures`]).
//! 4. **Candidates**: every catalogued effect ([`catalogue`]) not yet in the model is fitted
//!    (bounded), every effect already in it is refitted, never added twice.
//! 5. **Select by evidence**: each candidate model is simulated on every record; its score is
//!    the change of a per-record Gaussian log-likelihood with the BIC penalty,
//!    `sum_r n_r ln(MSE'_r / MSE_r) + k ln N` (the records have their own residual variance, so
//!    a short fast record is not drowned by a long slow one). A candidate is admissible if it
//!    explains at least [`MIN_EXPLAINED`] of the residual power still above the noise floor
//!    and its signature check passes; the admissible candidate with the lowest score is added.
//! 6. **Stop** when every record's residual RMS is within [`STOP_FLOOR_RATIO`] of its noise
//!    floor or no candidate is admissible.
//!
//! # What it trades
//! The slow effects are fitted by a linear solve on settled samples, the fast ones by a
//! bounded one- or two-dimensional search on the fast records; only the few candidates are
//! simulated in full. Greedy selection can in principle miss a pair whose members only help
//! together; refitting every present slow effect with each new one limits that.

pub mod catalogue;
pub mod demo;
pub mod protocol;
pub mod report;
pub mod signatures;

use crate::io::csv::Record;
use crate::io::model_file::ModelFile;
use crate::sim::open_loop::simulate;
use crate::util::{golden, golden_n, median, par_map};
use anyhow::{Context, bail, ensure};
use catalogue::{EFFECTS, FAST, SLOW, SlowParams};
use model_core::params;
use nalgebra::{DMatrix, DVector};

/// Fraction of the residual power above the noise floor a candidate must explain to be added
/// (our assumption, calibrated on the hidden-effect tests).
pub const MIN_EXPLAINED: f64 = 0.1;
/// The final check keeps a named effect only if taking it back out (and refitting the others)
/// raises the residual RMS above the noise floor, in some record, by at least
/// `PRUNE_RATIO + PRUNE_PER_PARAM * k` for an effect of `k` parameters (our assumption,
/// calibrated on the hidden-effect tests): the greedy forward pass may pick an effect that a
/// later one makes redundant, or one whose flexible form only mops up the misfit of another's
/// form (a play-sum hysteresis absorbing what three lags leave of a logarithmic creep), so
/// the bar rises with the effect's freedom.
pub const PRUNE_RATIO: f64 = 1.5;
/// See [`PRUNE_RATIO`].
pub const PRUNE_PER_PARAM: f64 = 0.125;
/// ... but an effect whose removal raises some record's residual power by more than this many
/// noise variances (about 32x the noise RMS in quadrature) always stays (our assumption: the
/// ratio test is for effects near the floor; on a record left far above it, such as the full
/// thesis stage diagnosed from `thesis-linear`, removing the drift doubled a 134 mV residual,
/// about 8600 variances, yet fell under its ratio bar, and the effects were pruned one after
/// another. A time delay mopping up a Bouc-Wen misfit in the hidden-effect tests added about
/// 150, so 100 was too low).
pub const PRUNE_KEEP_EXCESS_VAR: f64 = 1000.0;
/// Stop when every record's residual RMS is within this factor of its noise floor.
pub const STOP_FLOOR_RATIO: f64 = 1.15;
/// A fitted second mode is named only if the Welch-averaged residual spectrum has a line
/// within 15 % of its frequency at least this many times its median level (our assumption,
/// measured on the hidden-effect tests: true second modes stand 5.9-1450x, fits of a
/// resonance to noise or to another effect's misfit 1.2-1.4x).
pub const LINE_RATIO_MIN: f64 = 3.0;
/// ... and only if its damping ratio is at most this (a line, not a lag; our assumption).
pub const MAX_MODE_DAMPING: f64 = 0.25;
/// The drift time constants' refinement stops when a pass of coordinate descent gains less
/// than this much weighted residual power, V^2 (our assumption: 1e-4 of the power of 1 mV of
/// noise; two passes, the earlier fixed count, left the demo at 2.5x its floor, eight reach
/// 1.1x).
pub const DRIFT_REFINE_TOL_V2: f64 = 1e-10;
/// ... or after this many passes.
pub const DRIFT_REFINE_PASSES: usize = 12;
/// Rounds of the slow fit's structural refinement (K(u) of the drift, K'(u) on the play sum;
/// measured: a second round left the demo, the thesis-full records and the hidden-effect
/// tests unchanged and cost 40 % more time).
pub const STRUCTURE_ROUNDS: usize = 1;
/// At most this many steps.
pub const MAX_STEPS: usize = 10;
/// Fewest samples a record must have to show anything.
pub const MIN_SAMPLES: usize = 200;
/// Records at or above this rate are "fast" (edges resolved), volts... Hz.
pub const FAST_RATE_HZ: f64 = 5_000.0;
/// Samples within this time after an input jump are not used by the slow-effect solve.
pub const SETTLE_S: f64 = 5e-3;

/// One measured record ready for the workflow.
#[derive(Clone, Debug)]
pub struct Data {
    /// Name (file name) for tables and the report.
    pub name: String,
    /// Sample times, seconds (uniform).
    pub t_s: Vec<f64>,
    /// Amplifier input, volts.
    pub u_v: Vec<f64>,
    /// Sensor monitor, volts.
    pub y_v: Vec<f64>,
}

impl Data {
    /// From a parsed record: `y` required, at least [`MIN_SAMPLES`] samples, an input that
    /// moves.
    pub fn from_record(name: &str, rec: Record) -> anyhow::Result<Self> {
        let y = rec
            .require_y()
            .with_context(|| format!("record {name}"))?
            .to_vec();
        let n = rec.len();
        ensure!(
            n >= MIN_SAMPLES,
            "record {name}: {n} samples is too short to show anything (at least {MIN_SAMPLES} are needed)"
        );
        let (lo, hi) = min_max(&rec.u_v);
        ensure!(
            hi - lo > 0.05,
            "record {name}: the input u never moves (span {:.3} V): nothing to compare",
            hi - lo
        );
        Ok(Self {
            name: name.to_string(),
            t_s: rec.t_s,
            u_v: rec.u_v,
            y_v: y,
        })
    }

    /// Sampling period, seconds.
    pub fn period_s(&self) -> f64 {
        let n = self.t_s.len();
        (self.t_s[n - 1] - self.t_s[0]) / (n - 1) as f64
    }

    /// Is this a fast record (edges resolved)?
    pub fn is_fast(&self) -> bool {
        1.0 / self.period_s() >= FAST_RATE_HZ
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// Never empty (checked on construction).
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }
}

/// One step of the workflow: the effect added or refitted.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Step {
    /// Effect name (one of [`EFFECTS`]).
    pub effect: String,
    /// Evidence in words.
    pub evidence: String,
    /// Fitted parameters.
    pub params: serde_json::Map<String, serde_json::Value>,
    /// Residual RMS before the step, volts (root of the mean over records of the mean square).
    pub rms_before_v: f64,
    /// Residual RMS after the step, volts.
    pub rms_after_v: f64,
    /// Residual RMS of each record before, volts.
    #[serde(skip)]
    pub record_rms_before_v: Vec<f64>,
    /// Residual RMS of each record after, volts.
    #[serde(skip)]
    pub record_rms_after_v: Vec<f64>,
    /// Simulated outputs after the step, one per record.
    #[serde(skip)]
    pub sims: Vec<Vec<f64>>,
    /// Refit of an effect already in the model.
    #[serde(skip)]
    pub refit: bool,
    /// The final check took this effect back out.
    #[serde(skip)]
    pub removed: bool,
}

/// The outcome of the workflow.
#[derive(Clone, Debug)]
pub struct Diagnosis {
    /// Effects named (added, or refitted with a significant gain), in order.
    pub named: Vec<String>,
    /// The steps.
    pub steps: Vec<Step>,
    /// Noise floor of each record, volts.
    pub record_noise_v: Vec<f64>,
    /// Noise floor, volts (root of the mean of the records' variances).
    pub noise_floor_v: f64,
    /// Residual RMS of the final model, volts.
    pub final_rms_v: f64,
    /// Residual RMS of the final model on each record, volts.
    pub record_final_rms_v: Vec<f64>,
    /// The base model's simulated outputs.
    pub base_sims: Vec<Vec<f64>>,
    /// The augmented model.
    pub model: ModelFile,
    /// Candidates tried at each step: (effect, score, explained fraction, admissible).
    pub tried: Vec<Vec<(String, f64, f64, bool)>>,
    /// Signature checks of the base model's residual.
    pub signatures: signatures::Signatures,
}

impl Diagnosis {
    /// The JSON object of `piezo gap --json`.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "named": self.named,
            "steps": self.steps.iter().map(|s| serde_json::json!({
                "effect": s.effect,
                "evidence": s.evidence,
                "params": s.params,
                "rms_before_v": s.rms_before_v,
                "rms_after_v": s.rms_after_v,
            })).collect::<Vec<_>>(),
            "noise_floor_v": self.noise_floor_v,
            "final_rms_v": self.final_rms_v,
        })
    }

    /// The terminal table.
    pub fn table(&self) -> String {
        let mut s = String::new();
        s.push_str(&format!(
            "{:<4} {:<16} {:>12} {:>12}  {:<40} {}\n",
            "step", "effect", "rms before", "rms after", "fitted parameters", "evidence"
        ));
        for (i, st) in self.steps.iter().enumerate() {
            let p: Vec<String> = st
                .params
                .iter()
                .map(|(k, v)| format!("{k}={}", fmt_num(v.as_f64().unwrap_or(f64::NAN))))
                .collect();
            s.push_str(&format!(
                "{:<4} {:<16} {:>9.2} mV {:>9.2} mV  {:<40} {}\n",
                i + 1,
                format!(
                    "{}{}",
                    st.effect,
                    if st.removed {
                        " (removed)"
                    } else if st.refit {
                        " (refit)"
                    } else {
                        ""
                    }
                ),
                1e3 * st.rms_before_v,
                1e3 * st.rms_after_v,
                p.join(" "),
                st.evidence
            ));
        }
        // The parameters of the final model: the slow effects are refitted together at every
        // step, so a row's parameters are those of its own step.
        for e in &self.named {
            let p: Vec<String> = catalogue::params_of(&self.model, e)
                .iter()
                .map(|(k, v)| format!("{k}={}", fmt_num(*v)))
                .collect();
            s.push_str(&format!("final {e}: {}\n", p.join(" ")));
        }
        s.push_str(&format!(
            "named: [{}]; noise floor {:.2} mV; final residual {:.2} mV ({:.2}x the floor)\n",
            self.named.join(", "),
            1e3 * self.noise_floor_v,
            1e3 * self.final_rms_v,
            self.final_rms_v / self.noise_floor_v.max(1e-12)
        ));
        s
    }
}

fn fmt_num(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-2..1e4).contains(&a) {
        format!("{v:.3e}")
    } else {
        format!("{v:.4}")
    }
}

/// Smallest and largest value.
pub fn min_max(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        })
}

/// Mean square of `a - b`.
pub fn mse(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()).max(1);
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / n as f64
}

/// Noise floor of a record, volts: robust standard deviation of its second differences.
#[allow(clippy::needless_range_loop)] // several arrays indexed together
pub fn noise_floor(d: &Data) -> f64 {
    let n = d.len();
    let settle = (0.01 / d.period_s()).ceil() as usize;
    let mut since = vec![usize::MAX; n];
    let mut last_change: Option<usize> = None;
    for i in 0..n {
        if i > 0 && (d.u_v[i] - d.u_v[i - 1]).abs() > 1e-9 {
            last_change = Some(i);
        }
        since[i] = last_change.map_or(usize::MAX, |c| i - c);
    }
    let second = |quiet: bool| -> Vec<f64> {
        (2..n)
            .filter(|&i| !quiet || since[i - 2] >= settle)
            .map(|i| (d.y_v[i] - 2.0 * d.y_v[i - 1] + d.y_v[i - 2]).abs())
            .collect()
    };
    let mut v = second(true);
    if v.len() < 100 {
        v = second(false);
    }
    1.4826 * median(&mut v) / 6f64.sqrt()
}

/// Simulate `model` (without sensor noise) on a record.
pub fn sim(model: &ModelFile, d: &Data) -> anyhow::Result<Vec<f64>> {
    let mut m = model.clone();
    m.converters.noise_v = 0.0;
    let stage = m.build_stage()?;
    Ok(simulate(&stage, m.period_s, &d.t_s, &d.u_v))
}

/// A pruning trial: effect, model without it, its simulations and mean squares.
type Trial = (String, ModelFile, Vec<Vec<f64>>, Vec<f64>);

/// Options of the workflow.
#[derive(Clone, Debug, Default)]
pub struct Options {
    /// Show a progress bar on stderr.
    pub progress: bool,
}

/// A fitted candidate, scored.
#[derive(Clone, Debug)]
struct Candidate {
    effect: String,
    refit: bool,
    model: ModelFile,
    k: usize,
    sims: Vec<Vec<f64>>,
    mse: Vec<f64>,
}

/// Run the workflow from `base` on `data`.
pub fn diagnose(base: &ModelFile, data: &[Data], opts: &Options) -> anyhow::Result<Diagnosis> {
    ensure!(!data.is_empty(), "no records given");
    base.build_stage().context("base model")?;
    ensure!(
        base.period_s <= 20e-6 + 1e-12,
        "the model's step {} s is longer than 20 us: the workflow simulates at 50 kHz or faster",
        base.period_s
    );
    let bar = if opts.progress {
        let b = indicatif::ProgressBar::new((MAX_STEPS + 1) as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b.set_message("simulating the base model");
        Some(b)
    } else {
        None
    };
    let noise: Vec<f64> = data.iter().map(noise_floor).collect();
    let var: Vec<f64> = noise.iter().map(|s| (s * s).max(1e-14)).collect();
    let noise_floor_v = (var.iter().sum::<f64>() / var.len() as f64).sqrt();
    let (ulo, uhi) = data.iter().fold((0.0f64, 0.0f64), |(a, b), d| {
        let (l, h) = min_max(&d.u_v);
        (a.min(l), b.max(h))
    });
    let u_range = (ulo.max(-20.0), uhi.min(20.0).max(ulo + 1.0));

    let mut model = base.clone();
    let base_sims: Vec<Vec<f64>> = par_map(data, |d| sim(&model, d))
        .into_iter()
        .collect::<anyhow::Result<_>>()?;
    let mut sims = base_sims.clone();
    let mut cur_mse: Vec<f64> = data
        .iter()
        .zip(&sims)
        .map(|(d, s)| mse(&d.y_v, s))
        .collect();
    let base_sigs = signatures::compute(data, &sims, &noise);
    let slow_x = slow_regressors(data);
    let mut steps: Vec<Step> = Vec::new();
    let mut named: Vec<String> = Vec::new();
    let mut tried = Vec::new();

    for _ in 0..MAX_STEPS {
        if let Some(b) = &bar {
            b.inc(1);
        }
        let at_floor = cur_mse
            .iter()
            .zip(&var)
            .all(|(m, v)| *m <= STOP_FLOOR_RATIO * STOP_FLOOR_RATIO * v);
        if at_floor {
            break;
        }
        let sigs = signatures::compute(data, &sims, &noise);
        if let Some(b) = &bar {
            b.set_message(format!(
                "step {}: fitting {} candidates",
                steps.len() + 1,
                EFFECTS.len()
            ));
        }
        let cands = candidates(
            &model,
            data,
            &slow_x,
            &cur_mse,
            u_range,
            sigs.peak_hz,
            &named,
        )?;
        // Fast effects are fitted and scored on the fast records (where they show), slow ones
        // on all records; no candidate may make any record's excess worse by > 20 %.
        let fast_set: Vec<usize> = {
            let f: Vec<usize> = (0..data.len()).filter(|&i| data[i].is_fast()).collect();
            if f.is_empty() {
                (0..data.len()).collect()
            } else {
                f
            }
        };
        let all_set: Vec<usize> = (0..data.len()).collect();
        let mut scored = Vec::new();
        for c in cands {
            let set = if FAST.contains(&c.effect.as_str()) {
                &fast_set
            } else {
                &all_set
            };
            let n_set: usize = set.iter().map(|&i| data[i].len()).sum();
            let score: f64 = set
                .iter()
                .map(|&i| data[i].len() as f64 * (c.mse[i].max(1e-14) / cur_mse[i].max(1e-14)).ln())
                .sum::<f64>()
                + catalogue::param_count(&c.effect) as f64 * (n_set as f64).ln();
            let ex = |m: &[f64]| set.iter().map(|&i| (m[i] - var[i]).max(0.0)).sum::<f64>();
            let ex0 = ex(&cur_mse);
            let explained = if ex0 > 0.0 {
                1.0 - ex(&c.mse) / ex0
            } else {
                0.0
            };
            let harmless = (0..data.len()).all(|i| {
                let before = (cur_mse[i] - var[i]).max(0.0);
                let after = (c.mse[i] - var[i]).max(0.0);
                after <= 3.0 * before + var[i]
            });
            let sig_ok = sigs.supports(&c.effect, &c.model);
            let ok = score < 0.0 && explained >= MIN_EXPLAINED && sig_ok && harmless;
            scored.push((c, score, explained, ok));
        }
        tried.push(
            scored
                .iter()
                .map(|(c, s, e, ok)| (c.effect.clone(), *s, *e, *ok))
                .collect(),
        );
        let Some((best, score, explained, _)) = scored
            .into_iter()
            .filter(|x| x.3)
            .min_by(|a, b| a.1.total_cmp(&b.1))
        else {
            break;
        };
        let rms_before = (cur_mse.iter().sum::<f64>() / cur_mse.len() as f64).sqrt();
        let rms_after = (best.mse.iter().sum::<f64>() / best.mse.len() as f64).sqrt();
        let p = catalogue::params_of(&best.model, &best.effect);
        let mut params = serde_json::Map::new();
        for (k, v) in &p {
            params.insert(k.clone(), serde_json::json!(v));
        }
        let words = sigs.describe(&best.effect, &best.model);
        let evidence = format!(
            "{}; explains {:.0} % of the residual power above the noise floor; score {:.0} (BIC, {} parameter{})",
            words,
            100.0 * explained,
            score,
            best.k,
            if best.k == 1 { "" } else { "s" }
        );
        steps.push(Step {
            effect: best.effect.clone(),
            evidence,
            params,
            rms_before_v: rms_before,
            rms_after_v: rms_after,
            record_rms_before_v: cur_mse.iter().map(|m| m.sqrt()).collect(),
            record_rms_after_v: best.mse.iter().map(|m| m.sqrt()).collect(),
            sims: best.sims.clone(),
            refit: best.refit,
            removed: false,
        });
        if !named.contains(&best.effect) {
            named.push(best.effect.clone());
        }
        model = best.model;
        sims = best.sims;
        cur_mse = best.mse;
    }
    // Final check: take each named effect back out (refitting the slow ones left) and keep it
    // only if the residual above the noise floor grows by PRUNE_RATIO at least.
    while !named.is_empty() {
        if let Some(b) = &bar {
            b.set_message("final check of each named effect");
        }
        let trials = par_map(&named, |e| -> Option<Trial> {
            let m = reverted_refit(&model, base, e, data, &slow_x, u_range)?;
            let s: Vec<Vec<f64>> = data
                .iter()
                .map(|d| sim(&m, d))
                .collect::<anyhow::Result<_>>()
                .ok()?;
            let ms = data.iter().zip(&s).map(|(d, y)| mse(&d.y_v, y)).collect();
            Some((e.clone(), m, s, ms))
        });
        // The largest growth over the records of the residual power above the floor.
        let growth = |ms: &[f64]| {
            (0..ms.len())
                .map(|i| {
                    let f = (cur_mse[i] - var[i]).max(0.02 * var[i]);
                    ((ms[i] - var[i]).max(0.0) / f).sqrt()
                })
                .fold(0.0f64, f64::max)
        };
        // A second mode whose removal brings its own line back into the residual spectrum
        // stays, whatever the growth: a misfit of another effect's form (Bouc-Wen hysteresis
        // under play operators) can dominate the fast record and hide the growth.
        let weakest = trials
            .into_iter()
            .flatten()
            .map(|(e, m, s, ms)| {
                let line_back =
                    e == "resonance" && signatures::compute(data, &s, &noise).supports(&e, &model);
                // An effect whose removal adds more than PRUNE_KEEP_EXCESS_VAR noise variances
                // to some record's residual power explains a component no noise makes: it stays
                // whatever the ratio (far from the floor, ratios are compressed).
                let large =
                    (0..ms.len()).any(|i| ms[i] - cur_mse[i] > PRUNE_KEEP_EXCESS_VAR * var[i]);
                let ratio = if line_back || large {
                    f64::INFINITY
                } else {
                    growth(&ms)
                };
                (e, m, s, ms, ratio)
            })
            // The effect furthest below its own bar.
            .min_by(|a, b| {
                let bar =
                    |e: &str| PRUNE_RATIO + PRUNE_PER_PARAM * catalogue::param_count(e) as f64;
                (a.4 / bar(&a.0)).total_cmp(&(b.4 / bar(&b.0)))
            });
        let Some((e, m, s, ms, ratio)) = weakest else {
            break;
        };
        let bar_e = PRUNE_RATIO + PRUNE_PER_PARAM * catalogue::param_count(&e) as f64;
        if ratio >= bar_e {
            break;
        }
        let rms_before = (cur_mse.iter().sum::<f64>() / cur_mse.len() as f64).sqrt();
        let rms_after = (ms.iter().sum::<f64>() / ms.len() as f64).sqrt();
        steps.push(Step {
            effect: e.clone(),
            evidence: format!(
                "removed in the final check: without it the residual above the noise floor grows only {ratio:.2}x (< {bar_e:.2}x)"
            ),
            params: serde_json::Map::new(),
            rms_before_v: rms_before,
            rms_after_v: rms_after,
            record_rms_before_v: cur_mse.iter().map(|m| m.sqrt()).collect(),
            record_rms_after_v: ms.iter().map(|m| m.sqrt()).collect(),
            sims: s.clone(),
            refit: false,
            removed: true,
        });
        named.retain(|x| *x != e);
        model = m;
        sims = s;
        cur_mse = ms;
    }
    let _ = &sims;
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let final_rms_v = (cur_mse.iter().sum::<f64>() / cur_mse.len() as f64).sqrt();
    Ok(Diagnosis {
        named,
        steps,
        record_noise_v: noise,
        noise_floor_v,
        final_rms_v,
        record_final_rms_v: cur_mse.iter().map(|m| m.sqrt()).collect(),
        base_sims,
        model,
        tried,
        signatures: base_sigs,
    })
}

/// `model` with `effect` taken back to what `base` has, the slow effects left refitted.
fn reverted_refit(
    model: &ModelFile,
    base: &ModelFile,
    effect: &str,
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
) -> Option<ModelFile> {
    let m = catalogue::revert(model, base, effect);
    let set: Vec<&str> = SLOW
        .iter()
        .copied()
        .filter(|e| catalogue::present(&m, e))
        .collect();
    if set.is_empty() {
        return Some(m);
    }
    let b0 = catalogue::without_slow(&m);
    let y0: Vec<Vec<f64>> = data
        .iter()
        .map(|d| sim(&b0, d))
        .collect::<anyhow::Result<_>>()
        .ok()?;
    let p = fit_slow(data, &y0, slow_x, &set, u_range)?;
    catalogue::with_slow(&m, &p, u_range)
}

/// Fit every candidate and simulate it on every record.
fn candidates(
    model: &ModelFile,
    data: &[Data],
    slow_x: &SlowRegressors,
    cur_mse: &[f64],
    u_range: (f64, f64),
    peak_hz: f64,
    named: &[String],
) -> anyhow::Result<Vec<Candidate>> {
    // Slow effects: one joint solve per candidate set.
    let present_slow: Vec<&str> = SLOW
        .iter()
        .copied()
        .filter(|e| catalogue::present(model, e))
        .collect();
    let base0 = catalogue::without_slow(model);
    let y0: Vec<Vec<f64>> = par_map(data, |d| sim(&base0, d))
        .into_iter()
        .collect::<anyhow::Result<_>>()?;
    let mut jobs: Vec<(String, bool, ModelFile)> = Vec::new();
    let mut sets: Vec<(String, bool, Vec<&str>)> = SLOW
        .iter()
        .filter(|e| !present_slow.contains(e))
        .map(|e| {
            let mut s = present_slow.clone();
            s.push(e);
            (e.to_string(), false, s)
        })
        .collect();
    for e in &present_slow {
        sets.push((e.to_string(), true, present_slow.clone()));
    }
    // One joint solve per distinct set (every refit of a present effect shares the set of
    // the present ones), the solves in parallel.
    let mut distinct: Vec<Vec<&str>> = Vec::new();
    for (_, _, set) in &sets {
        if !distinct.contains(set) {
            distinct.push(set.clone());
        }
    }
    let fitted: Vec<Option<ModelFile>> = par_map(&distinct, |set| {
        fit_slow(data, &y0, slow_x, set, u_range)
            .and_then(|p| catalogue::with_slow(model, &p, u_range))
    });
    for (effect, refit, set) in sets {
        let k = distinct.iter().position(|d| *d == set);
        if let Some(m) = k.and_then(|k| fitted[k].clone()) {
            jobs.push((effect, refit, m));
        }
    }
    // Fast effects: bounded search on the fast records.
    let fast_idx: Vec<usize> = {
        let f: Vec<usize> = (0..data.len()).filter(|&i| data[i].is_fast()).collect();
        if f.is_empty() {
            (0..data.len()).collect()
        } else {
            f
        }
    };
    let fast_fits: Vec<Option<(String, bool, ModelFile, f64)>> = par_map(&FAST, |e| {
        let refit = catalogue::present(model, e);
        // Coordinate descent: the candidate, then the fast effects already named, then the
        // candidate again (fast effects compensate each other: a slew limit mimics a delay).
        let (mut m, mut cost) = fit_fast(model, data, &fast_idx, e, peak_hz)?;
        let others: Vec<&String> = named
            .iter()
            .filter(|n| n.as_str() != *e && FAST.contains(&n.as_str()))
            .collect();
        for _pass in 0..4 {
            if others.is_empty() {
                break;
            }
            let start = cost;
            for o in &others {
                if let Some((m2, c2)) = fit_fast(&m, data, &fast_idx, o, peak_hz)
                    && c2 < cost
                {
                    (m, cost) = (m2, c2);
                }
            }
            if let Some((m2, c2)) = fit_fast(&m, data, &fast_idx, e, peak_hz)
                && c2 < cost
            {
                (m, cost) = (m2, c2);
            }
            // Costs are sums of n ln MSE: stop when a pass gains less than 2 % of MSE.
            let n_fast: f64 = fast_idx.iter().map(|&i| data[i].len() as f64).sum();
            if start - cost < n_fast * 0.02 {
                break;
            }
        }
        Some((e.to_string(), refit, m, cost))
    });
    let cur_fast_cost: f64 = fast_idx
        .iter()
        .map(|&i| data[i].len() as f64 * cur_mse[i].max(1e-14).ln())
        .sum();
    for (effect, refit, m, cost) in fast_fits.into_iter().flatten() {
        // Simulate in full only what helps on the fast records (10 % of their MSE at least).
        let n_fast: f64 = fast_idx.iter().map(|&i| data[i].len() as f64).sum();
        if cost < cur_fast_cost + n_fast * (0.9f64).ln() {
            jobs.push((effect, refit, m));
        }
    }
    let results = par_map(&jobs, |(effect, refit, m)| -> anyhow::Result<Candidate> {
        let sims: Vec<Vec<f64>> = data
            .iter()
            .map(|d| sim(m, d))
            .collect::<anyhow::Result<_>>()?;
        let mse_v = data
            .iter()
            .zip(&sims)
            .map(|(d, s)| mse(&d.y_v, s))
            .collect();
        let k = catalogue::param_count(effect);
        Ok(Candidate {
            effect: effect.clone(),
            refit: *refit,
            model: m.clone(),
            k,
            sims,
            mse: mse_v,
        })
    });
    results.into_iter().collect()
}

/// Fit a fast effect on the fast records: returns the model and its cost
/// `sum n_r ln MSE_r` over those records.
fn fit_fast(
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

/// The slow effects' regressors at every record's samples (they depend on the input only).
pub struct SlowRegressors {
    /// Per record: columns (drift lags for each grid time constant, play terms, gain terms).
    cols: Vec<Vec<Vec<f64>>>,
    /// Per record: is the sample settled (used by the solve)?
    mask: Vec<Vec<bool>>,
    /// Per record: the drift lags' input, `K(u) u` (`u` while K = 1).
    drive: Vec<Vec<f64>>,
}

/// How the slow regressors are shaped by the slow effects' non-linear parameters (the
/// structural refinement of [`fit_slow`]).
#[derive(Clone, Copy, Debug, Default)]
struct Shape {
    /// K'(u) = 1 + c1 u + c2 u^2 multiplies the play sum (the stage scales the whole fast map).
    kprime: Option<(f64, f64)>,
    /// The drift's K(u): its lags see `K(u) u`.
    kdrift: Option<[f64; 4]>,
    /// The inputs' span: K and K' are held at its edges, as in the stage.
    range: (f64, f64),
}

impl Shape {
    fn kprime(&self, u: f64) -> f64 {
        self.kprime.map_or(1.0, |(c1, c2)| {
            let x = u.clamp(self.range.0, self.range.1);
            1.0 + x * (c1 + x * c2)
        })
    }
    fn drive(&self, u: f64) -> f64 {
        self.kdrift.map_or(u, |k| {
            let x = u.clamp(self.range.0, self.range.1);
            (k[0] + x * (k[1] + x * (k[2] + x * k[3]))) * u
        })
    }
}

const N_TAU: usize = catalogue::DRIFT_TAU_GRID_S.len();
const N_PLAY: usize = params::PLAY_OPERATORS;
const COL_PLAY: usize = N_TAU;
const COL_GAIN: usize = N_TAU + N_PLAY;
const N_COLS: usize = N_TAU + N_PLAY + 2;

fn slow_regressors(data: &[Data]) -> SlowRegressors {
    slow_regressors_shaped(data, &Shape::default())
}

#[allow(clippy::needless_range_loop)] // several arrays indexed together
fn slow_regressors_shaped(data: &[Data], shape: &Shape) -> SlowRegressors {
    let mut cols = Vec::new();
    let mut mask = Vec::new();
    let mut drives = Vec::new();
    for d in data {
        let n = d.len();
        let t = d.period_s();
        let drive: Vec<f64> = d.u_v.iter().map(|&u| shape.drive(u)).collect();
        let mut c: Vec<Vec<f64>> = Vec::with_capacity(N_COLS);
        for tau in catalogue::DRIFT_TAU_GRID_S {
            // Exact ZOH first-order lag of the held drive, at rest at its first value.
            let a = (-t / tau).exp();
            let mut x = drive[0];
            let mut v = Vec::with_capacity(n);
            for i in 0..n {
                v.push(x);
                x = a * x + (1.0 - a) * drive[i];
            }
            c.push(v);
        }
        for r in params::PLAY_RADII_V {
            let mut z = d.u_v[0];
            c.push(
                d.u_v
                    .iter()
                    .map(|&u| {
                        z = z.max(u - r).min(u + r);
                        (z - u) * shape.kprime(u)
                    })
                    .collect(),
            );
        }
        c.push(d.u_v.iter().map(|u| params::PLANT_GAIN * u * u).collect());
        c.push(
            d.u_v
                .iter()
                .map(|u| params::PLANT_GAIN * u * u * u)
                .collect(),
        );
        // Settled: no input jump (> 20 mV) within SETTLE_S before.
        let settle = (SETTLE_S / t).ceil() as usize;
        let mut m = vec![true; n];
        let mut last_jump: Option<usize> = None;
        for i in 0..n {
            if i > 0 && (d.u_v[i] - d.u_v[i - 1]).abs() > 0.02 {
                last_jump = Some(i);
            }
            if let Some(j) = last_jump
                && i - j <= settle
            {
                m[i] = false;
            }
        }
        cols.push(c);
        mask.push(m);
        drives.push(drive);
    }
    SlowRegressors {
        cols,
        mask,
        drive: drives,
    }
}

/// The slow effects in `set` fitted to the residual of the model without slow effects (`y0`):
/// the linear fit ([`fit_slow_linear`]), then [`STRUCTURE_ROUNDS`] rounds of structural
/// refinement where the stage's form is not linear in the parameters:
/// * with `drift`: its K(u) (`k0 + k1 u + k2 u^2 + k3 u^3`, k0 = 1) from the three lags of
///   `u^2, u^3, u^4` weighted by the fitted gains, then the lags refitted on `K(u) u`;
/// * with `hysteresis` and `nonlinear-gain`: the play columns scaled by the fitted K'(u), as
///   the stage scales the whole fast map (`K'(u) (0.79 u + h(u))`).
///
/// A refinement that fails (K(u) u not increasing, a singular solve) keeps the previous fit.
///
/// `u_range` is the range the model file gets for K(u) and K'(u) ([`catalogue::with_slow`]),
/// so a K accepted here is one the stage accepts.
fn fit_slow(
    data: &[Data],
    y0: &[Vec<f64>],
    x: &SlowRegressors,
    set: &[&str],
    u_range: (f64, f64),
) -> Option<SlowParams> {
    let mut p = fit_slow_linear(data, y0, x, set, None)?;
    let couple = set.contains(&"hysteresis") && set.contains(&"nonlinear-gain");
    let has_drift = set.contains(&"drift");
    if !couple && !has_drift {
        return Some(p);
    }
    let mut shape = Shape {
        range: u_range,
        ..Shape::default()
    };
    for _ in 0..STRUCTURE_ROUNDS {
        if couple {
            shape.kprime = p.gain;
        }
        if has_drift && let Some(k) = fit_drift_poly(data, y0, x, &shape, &p) {
            shape.kdrift = Some(k);
        }
        let xs = slow_regressors_shaped(data, &shape);
        match fit_slow_linear(data, y0, &xs, set, p.drift.map(|d| d.1)) {
            Some(mut q) => {
                q.drift_poly = shape.kdrift;
                p = q;
            }
            None => break,
        }
    }
    Some(p)
}

/// K(u) of the drift given the present fit `p` (gains, time constants; `shape`'s K' on the
/// play columns): one weighted solve with the three lags of `u`, the lags of `c(u) u` for
/// `c = u, u^2, u^3` weighted by the present gains (their coefficients are `k1..k3`), and the
/// other slow effects' columns. `None` unless `K(u) u` comes out strictly increasing (the
/// stage refuses it otherwise) and the solve is regular.
#[allow(clippy::needless_range_loop)] // lags, powers and gains indexed together
fn fit_drift_poly(
    data: &[Data],
    y0: &[Vec<f64>],
    x: &SlowRegressors,
    shape: &Shape,
    p: &SlowParams,
) -> Option<[f64; 4]> {
    let (gains, taus) = p.drift?;
    let plain = Shape {
        kdrift: None,
        ..*shape
    };
    let xs = slow_regressors_shaped(data, &plain);
    let mut fixed: Vec<usize> = Vec::new();
    if p.hysteresis.is_some() {
        fixed.extend(COL_PLAY..COL_PLAY + N_PLAY);
    }
    if p.gain.is_some() {
        fixed.extend([COL_GAIN, COL_GAIN + 1]);
    }
    let nf = fixed.len();
    let np = 6 + nf;
    let mut g = DMatrix::<f64>::zeros(np, np);
    let mut b = DVector::<f64>::zeros(np);
    let mut row = vec![0.0; np];
    for (r, d) in data.iter().enumerate() {
        let t = d.period_s();
        let a = taus.map(|tau| (-t / tau).exp());
        let x0 = |u: f64, pw: i32| u.clamp(shape.range.0, shape.range.1).powi(pw) * u;
        // Lags of u (3) and of u^(j+1) for j = 1..3 (3 x 3), at rest at the first sample.
        let mut lu = [d.u_v[0]; 3];
        let mut lp = [[0.0f64; 3]; 3];
        for (j, l) in lp.iter_mut().enumerate() {
            *l = [x0(d.u_v[0], j as i32 + 1); 3];
        }
        let m = &x.mask[r];
        let w = 1.0 / m.iter().filter(|v| **v).count().max(1) as f64;
        for i in 0..d.len() {
            if m[i] {
                row[..3].copy_from_slice(&lu);
                for j in 0..3 {
                    row[3 + j] = (0..3).map(|k| gains[k] * lp[j][k]).sum();
                }
                for (c, &col) in fixed.iter().enumerate() {
                    row[6 + c] = xs.cols[r][col][i];
                }
                let e = d.y_v[i] - y0[r][i];
                for k in 0..np {
                    b[k] += w * row[k] * e;
                    for l in 0..=k {
                        g[(k, l)] += w * row[k] * row[l];
                    }
                }
            }
            let u = d.u_v[i];
            for k in 0..3 {
                lu[k] = a[k] * lu[k] + (1.0 - a[k]) * u;
                for j in 0..3 {
                    lp[j][k] = a[k] * lp[j][k] + (1.0 - a[k]) * x0(u, j as i32 + 1);
                }
            }
        }
    }
    for k in 0..np {
        for l in 0..k {
            g[(l, k)] = g[(k, l)];
        }
    }
    ridge(&mut g);
    let nonneg: Vec<bool> = (0..np)
        .map(|k| k < 3 || (k >= 6 && is_nonneg_col(fixed[k - 6])))
        .collect();
    let beta = nnls_normal(&g, &b, &nonneg)?;
    let k = [1.0, beta[3], beta[4], beta[5]];
    let cfg = model_core::drift::DriftConfig {
        gains,
        taus_s: taus,
        poly: k,
        poly_range_v: shape.range,
    };
    (k.iter().all(|v| v.is_finite()) && cfg.validate().is_ok()).then_some(k)
}

/// The joint weighted least-squares fit of the slow effects in `set` to the residual of the
/// model without slow effects (`y0`), linear in the parameters for the regressors' shape.
/// Records weigh equally. Drift time constants: the best three of the grid, then refined.
fn fit_slow_linear(
    data: &[Data],
    y0: &[Vec<f64>],
    x: &SlowRegressors,
    set: &[&str],
    start: Option<[f64; 3]>,
) -> Option<SlowParams> {
    // Gram matrix of all columns and the target.
    let mut g = DMatrix::<f64>::zeros(N_COLS, N_COLS);
    let mut b = DVector::<f64>::zeros(N_COLS);
    for (r, d) in data.iter().enumerate() {
        let cols = &x.cols[r];
        let m = &x.mask[r];
        let n_used = m.iter().filter(|v| **v).count().max(1) as f64;
        let w = 1.0 / n_used;
        let mut gl = [[0.0f64; N_COLS]; N_COLS];
        let mut bl = [0.0f64; N_COLS];
        let mut row = [0.0f64; N_COLS];
        for i in 0..d.len() {
            if !m[i] {
                continue;
            }
            let e = d.y_v[i] - y0[r][i];
            for (k, c) in cols.iter().enumerate() {
                row[k] = c[i];
            }
            for k in 0..N_COLS {
                bl[k] += row[k] * e;
                for l in 0..=k {
                    gl[k][l] += row[k] * row[l];
                }
            }
        }
        for k in 0..N_COLS {
            b[k] += w * bl[k];
            for l in 0..=k {
                g[(k, l)] += w * gl[k][l];
                if l != k {
                    g[(l, k)] += w * gl[k][l];
                }
            }
        }
    }
    let solve = |idx: &[usize]| -> Option<(Vec<f64>, f64)> {
        let p = idx.len();
        let mut a = DMatrix::<f64>::zeros(p, p);
        let mut v = DVector::<f64>::zeros(p);
        for (i, &ki) in idx.iter().enumerate() {
            v[i] = b[ki];
            for (j, &kj) in idx.iter().enumerate() {
                a[(i, j)] = g[(ki, kj)];
            }
        }
        ridge(&mut a);
        let nonneg: Vec<bool> = idx.iter().map(|&k| is_nonneg_col(k)).collect();
        let beta = nnls_normal(&a, &v, &nonneg)?;
        // Reduction of the weighted SSR (at the constrained optimum too: x' A x = x' b there).
        let red = beta.dot(&v);
        beta.iter()
            .all(|x| x.is_finite())
            .then(|| (beta.iter().copied().collect(), red))
    };
    let mut fixed: Vec<usize> = Vec::new();
    if set.contains(&"hysteresis") {
        fixed.extend(COL_PLAY..COL_PLAY + N_PLAY);
    }
    if set.contains(&"nonlinear-gain") {
        fixed.extend([COL_GAIN, COL_GAIN + 1]);
    }
    let unpack = |idx: &[usize], beta: &[f64], taus: Option<[usize; 3]>| -> SlowParams {
        let get = |k: usize| {
            idx.iter()
                .position(|&c| c == k)
                .and_then(|p| beta.get(p).copied())
                .unwrap_or(0.0)
        };
        SlowParams {
            drift: taus.map(|t| {
                (
                    [get(t[0]), get(t[1]), get(t[2])],
                    [
                        catalogue::DRIFT_TAU_GRID_S[t[0]],
                        catalogue::DRIFT_TAU_GRID_S[t[1]],
                        catalogue::DRIFT_TAU_GRID_S[t[2]],
                    ],
                )
            }),
            hysteresis: set.contains(&"hysteresis").then(|| {
                let mut w = [0.0; N_PLAY];
                for (i, wi) in w.iter_mut().enumerate() {
                    *wi = get(COL_PLAY + i);
                }
                w
            }),
            gain: set
                .contains(&"nonlinear-gain")
                .then(|| (get(COL_GAIN), get(COL_GAIN + 1))),
            drift_poly: None,
        }
    };
    if set.contains(&"drift") {
        let mut best: Option<(f64, [usize; 3])> = None;
        for i in 0..N_TAU {
            for j in i + 1..N_TAU {
                for k in j + 1..N_TAU {
                    let mut idx = vec![i, j, k];
                    idx.extend(&fixed);
                    if let Some((beta, red)) = solve(&idx) {
                        let ok = beta.iter().take(3).all(|g| g.abs() <= 1.0);
                        if ok && best.as_ref().is_none_or(|b| red > b.0) {
                            best = Some((red, [i, j, k]));
                        }
                    }
                }
            }
        }
        let (_, ti) = best?;
        // Refine the three time constants continuously (golden section on log tau between
        // the neighbouring grid values), each solve with the other columns.
        let grid = catalogue::DRIFT_TAU_GRID_S;
        let mut taus = ti.map(|i| grid[i]);
        let problem = DriftProblem::new(data, y0, x, &fixed, &g, &b);
        let eval = |taus: &[f64; 3]| -> f64 {
            problem
                .solve(taus)
                .map_or(f64::NEG_INFINITY, |(beta, red)| {
                    if beta.iter().take(3).all(|g| g.abs() <= 1.0) {
                        red
                    } else {
                        f64::NEG_INFINITY
                    }
                })
        };
        // Coordinate descent: the valley is narrow (a shorter first lag and a play operator
        // of small threshold trade against each other), so it runs until a pass gains less
        // than DRIFT_REFINE_TOL_V2 of weighted residual power (at most DRIFT_REFINE_PASSES).
        // A warm start (the previous round's time constants) replaces the grid's best when it
        // explains more.
        let mut cur_val = eval(&taus);
        if let Some(t0) = start {
            let v = eval(&t0);
            if v > cur_val {
                (taus, cur_val) = (t0, v);
            }
        }
        for pass in 0..DRIFT_REFINE_PASSES {
            let last = cur_val;
            // The first pass searches a factor 3 either side, later ones 1.25 with fewer
            // golden steps (the same final resolution, about 0.1 % of tau).
            let (factor, iters) = if pass == 0 { (3.0, 18) } else { (1.25, 12) };
            for m in 0..3 {
                let lo = if m > 0 {
                    taus[m - 1] * 1.05
                } else {
                    grid[0] * 0.5
                };
                let hi = if m < 2 {
                    taus[m + 1] / 1.05
                } else {
                    grid[N_TAU - 1] * 2.0
                };
                // Also skips NaN bounds.
                if lo.partial_cmp(&hi) != Some(std::cmp::Ordering::Less) {
                    continue;
                }
                let a = lo.max(taus[m] / factor).ln();
                let b = hi.min(taus[m] * factor).ln();
                if a.partial_cmp(&b) != Some(std::cmp::Ordering::Less) {
                    continue;
                }
                let cur = taus;
                let lt = golden_n(a, b, a, b, iters, |lt| {
                    let mut t = cur;
                    t[m] = lt.exp();
                    -eval(&t)
                });
                let mut t = cur;
                t[m] = lt.exp();
                let v = eval(&t);
                if v > cur_val {
                    (taus, cur_val) = (t, v);
                }
            }
            if cur_val - last < DRIFT_REFINE_TOL_V2 {
                break;
            }
        }
        let (beta, _) = problem.solve(&taus)?;
        if !beta.iter().take(3).all(|g| g.abs() <= 1.0) {
            return None;
        }
        let mut p = unpack(&fixed, &beta[3..], None);
        p.drift = Some(([beta[0], beta[1], beta[2]], taus));
        Some(p)
    } else {
        if fixed.is_empty() {
            return None;
        }
        let (beta, _) = solve(&fixed)?;
        Some(unpack(&fixed, &beta, None))
    }
}

/// A tiny ridge on the normal equations' diagonal (1e-10 of its mean, plus 1e-15): keeps the
/// Cholesky factorisation defined when two regressors coincide (grid time constants, an input
/// that never visits a play operator's range) without moving a well-posed solution.
fn ridge(g: &mut DMatrix<f64>) {
    let n = g.nrows();
    let tr = (0..n).map(|i| g[(i, i)]).sum::<f64>() / n.max(1) as f64;
    for i in 0..n {
        g[(i, i)] += 1e-10 * tr + 1e-15;
    }
}

/// Is regressor column `k` one whose coefficient is kept >= 0: a drift lag's or a play
/// operator's? A stage creeps in the direction of its step (the thesis' three drift gains are
/// positive); unconstrained, two lags of nearly equal time constants and opposite gains of
/// +-0.45 make a band-pass that mimics hysteresis. With negative play weights the fitted loop
/// could turn clockwise or the output run backwards after a reversal, which no stage does;
/// unconstrained, a lone hysteresis fit soaks up drift and gain errors with weights of +-2.
fn is_nonneg_col(k: usize) -> bool {
    k < N_TAU || (COL_PLAY..COL_PLAY + N_PLAY).contains(&k)
}

/// Minimise `x' A x / 2 - b' x` (the normal equations of a least-squares problem, `A` positive
/// definite) with `x_j >= 0` where `nonneg[j]`: the Lawson-Hanson active-set method on the
/// normal equations, at most `3 n` changes of the active set. `None` if a sub-system is not
/// positive definite.
fn nnls_normal(a: &DMatrix<f64>, b: &DVector<f64>, nonneg: &[bool]) -> Option<DVector<f64>> {
    let n = b.len();
    let solve_on = |free: &[bool]| -> Option<DVector<f64>> {
        let idx: Vec<usize> = (0..n).filter(|&j| free[j]).collect();
        let sub_a = DMatrix::from_fn(idx.len(), idx.len(), |i, j| a[(idx[i], idx[j])]);
        let sub_b = DVector::from_fn(idx.len(), |i, _| b[idx[i]]);
        let z = sub_a.cholesky()?.solve(&sub_b);
        let mut x = DVector::zeros(n);
        for (i, &j) in idx.iter().enumerate() {
            x[j] = z[i];
        }
        Some(x)
    };
    // Unconstrained first: most fits never touch a bound.
    let free: Vec<bool> = vec![true; n];
    let x0 = solve_on(&free)?;
    if (0..n).all(|j| !nonneg[j] || x0[j] >= 0.0) {
        return Some(x0);
    }
    let mut free: Vec<bool> = (0..n).map(|j| !nonneg[j]).collect();
    let mut x = solve_on(&free)?;
    let scale = b.amax().max(1e-300);
    for _ in 0..3 * n {
        // The gradient of the objective's negative: which bound variable wants to move up?
        let w = b - a * &x;
        let enter = (0..n)
            .filter(|&j| !free[j])
            .max_by(|&i, &j| w[i].total_cmp(&w[j]));
        let Some(j) = enter.filter(|&j| w[j] > 1e-12 * scale) else {
            return Some(x);
        };
        free[j] = true;
        // Each pass frees no variable and binds at least one (the one that limits the step is
        // set to 0 explicitly), so n passes always end it.
        for _ in 0..n {
            let s = solve_on(&free)?;
            let bad: Vec<usize> = (0..n)
                .filter(|&k| free[k] && nonneg[k] && s[k] <= 0.0)
                .collect();
            if bad.is_empty() {
                x = s;
                break;
            }
            // Step from x towards s until the first constrained variable reaches 0.
            let (limit, alpha) = bad
                .iter()
                .map(|&k| (k, x[k] / (x[k] - s[k]).max(f64::MIN_POSITIVE)))
                .fold((bad[0], 1.0f64), |a, b| if b.1 < a.1 { b } else { a });
            x = &x + (&s - &x) * alpha;
            x[limit] = 0.0;
            for k in 0..n {
                if free[k] && nonneg[k] && x[k] <= 0.0 {
                    free[k] = false;
                    x[k] = 0.0;
                }
            }
        }
    }
    Some(x)
}

/// The drift refinement's fixed part, computed once per [`fit_slow`] call: per record the
/// target and the fixed columns at the settled samples (row-major, for cache locality), and
/// the weighted Gram matrix of the fixed columns, so that each evaluation only runs the three
/// lags and their cross products.
struct DriftProblem<'a> {
    data: &'a [Data],
    /// Per record: the lags' input (`K(u) u`).
    drive: &'a [Vec<f64>],
    /// Per record: (weight, settled sample indices, target at them, fixed columns row-major).
    recs: Vec<DriftRecord>,
    /// The fixed columns (indices into the regressors).
    fixed: Vec<usize>,
    /// Number of fixed columns.
    nf: usize,
    /// Weighted Gram matrix of the fixed columns, and their weighted products with the target.
    g_ff: DMatrix<f64>,
    b_f: DVector<f64>,
}

/// One record of a [`DriftProblem`]: (weight, settled sample indices, target at them, fixed
/// columns row-major).
type DriftRecord = (f64, Vec<usize>, Vec<f64>, Vec<f64>);

impl<'a> DriftProblem<'a> {
    fn new(
        data: &'a [Data],
        y0: &[Vec<f64>],
        x: &'a SlowRegressors,
        fixed: &[usize],
        g: &DMatrix<f64>,
        b: &DVector<f64>,
    ) -> Self {
        let nf = fixed.len();
        let recs = data
            .iter()
            .enumerate()
            .map(|(r, d)| {
                let idx: Vec<usize> = (0..d.len()).filter(|&i| x.mask[r][i]).collect();
                let w = 1.0 / idx.len().max(1) as f64;
                let e = idx.iter().map(|&i| d.y_v[i] - y0[r][i]).collect();
                let mut f = Vec::with_capacity(idx.len() * nf);
                for &i in &idx {
                    f.extend(fixed.iter().map(|&c| x.cols[r][c][i]));
                }
                (w, idx, e, f)
            })
            .collect();
        Self {
            data,
            drive: &x.drive,
            recs,
            fixed: fixed.to_vec(),
            nf,
            g_ff: DMatrix::from_fn(nf, nf, |i, j| g[(fixed[i], fixed[j])]),
            b_f: DVector::from_fn(nf, |i, _| b[fixed[i]]),
        }
    }

    /// The weighted solve with three drift lags of time constants `taus` and the fixed
    /// columns: (coefficients, drift first; reduction of the weighted SSR).
    fn solve(&self, taus: &[f64; 3]) -> Option<(Vec<f64>, f64)> {
        let nf = self.nf;
        let p = 3 + nf;
        let mut g = DMatrix::<f64>::zeros(p, p);
        let mut bv = DVector::<f64>::zeros(p);
        g.view_mut((3, 3), (nf, nf)).copy_from(&self.g_ff);
        bv.rows_mut(3, nf).copy_from(&self.b_f);
        for ((d, drive), (w, idx, e, f)) in self.data.iter().zip(self.drive).zip(&self.recs) {
            let t = d.period_s();
            let a = taus.map(|tau| (-t / tau).exp());
            let mut lag = [drive[0]; 3];
            let mut ll = [[0.0f64; 3]; 3];
            let mut lf = vec![0.0f64; 3 * nf];
            let mut le = [0.0f64; 3];
            let mut next = 0usize;
            for (j, &i) in idx.iter().enumerate() {
                // Advance the lags to sample i (their value there uses inputs before i).
                while next < i {
                    for k in 0..3 {
                        lag[k] = a[k] * lag[k] + (1.0 - a[k]) * drive[next];
                    }
                    next += 1;
                }
                let row = &f[j * nf..(j + 1) * nf];
                for k in 0..3 {
                    le[k] += lag[k] * e[j];
                    for l in 0..=k {
                        ll[k][l] += lag[k] * lag[l];
                    }
                    let out = &mut lf[k * nf..(k + 1) * nf];
                    for (o, v) in out.iter_mut().zip(row) {
                        *o += lag[k] * v;
                    }
                }
            }
            for k in 0..3 {
                bv[k] += w * le[k];
                for l in 0..=k {
                    g[(k, l)] += w * ll[k][l];
                    if l != k {
                        g[(l, k)] += w * ll[k][l];
                    }
                }
                for c in 0..nf {
                    g[(k, 3 + c)] += w * lf[k * nf + c];
                    g[(3 + c, k)] += w * lf[k * nf + c];
                }
            }
        }
        ridge(&mut g);
        let nonneg: Vec<bool> = (0..p)
            .map(|k| k < 3 || is_nonneg_col(self.fixed[k - 3]))
            .collect();
        let beta = nnls_normal(&g, &bv, &nonneg)?;
        let red = beta.dot(&bv);
        beta.iter()
            .all(|v| v.is_finite())
            .then(|| (beta.iter().copied().collect(), red))
    }
}

/// Read the records named on the command line: CSV or MATLAB v5 `.mat` (with `vars`).
pub fn load_data(paths: &[std::path::PathBuf], vars: Option<&str>) -> anyhow::Result<Vec<Data>> {
    if paths.is_empty() {
        bail!("no records: give at least one --data FILE");
    }
    let mut out = Vec::new();
    for p in paths {
        let name = p.file_name().map_or_else(
            || p.display().to_string(),
            |s| s.to_string_lossy().into_owned(),
        );
        let is_mat = p.extension().is_some_and(|e| e.eq_ignore_ascii_case("mat"));
        let rec = if is_mat {
            crate::io::mat::read_record(p, vars.unwrap_or("t=t,u=u,y=y"))?
        } else {
            Record::read(p).with_context(|| format!("record {}", p.display()))?
        };
        out.push(Data::from_record(&name, rec)?);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The active-set solve against brute force: every subset of the constrained variables
    /// held at zero, the rest solved freely; the best feasible one is the constrained optimum
    /// (the problem is strictly convex, so it is unique).
    #[test]
    fn nnls_matches_brute_force() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        for case in 0..300 {
            let n = 6;
            let m = DMatrix::<f64>::from_fn(12, n, |_, _| rng.gen_range(-1.0..1.0));
            let a = m.transpose() * &m + DMatrix::identity(n, n) * 1e-3;
            let b = DVector::<f64>::from_fn(n, |_, _| rng.gen_range(-1.0..1.0));
            let nonneg = [false, true, true, false, true, true];
            let x = nnls_normal(&a, &b, &nonneg).expect("positive definite");
            let obj = |x: &DVector<f64>| 0.5 * x.dot(&(&a * x)) - b.dot(x);
            let mut best = f64::INFINITY;
            for mask in 0..16u32 {
                let cons: Vec<usize> = vec![1, 2, 4, 5];
                let free: Vec<usize> = (0..n)
                    .filter(|j| {
                        cons.iter()
                            .position(|c| c == j)
                            .is_none_or(|p| mask & (1 << p) == 0)
                    })
                    .collect();
                let sa = DMatrix::from_fn(free.len(), free.len(), |i, j| a[(free[i], free[j])]);
                let sb = DVector::from_fn(free.len(), |i, _| b[free[i]]);
                let z = sa.cholesky().unwrap().solve(&sb);
                let mut y = DVector::zeros(n);
                for (i, &j) in free.iter().enumerate() {
                    y[j] = z[i];
                }
                if (0..n).all(|j| !nonneg[j] || y[j] >= -1e-12) {
                    best = best.min(obj(&y));
                }
            }
            assert!(
                (0..n).all(|j| !nonneg[j] || x[j] >= 0.0),
                "case {case}: {x}"
            );
            assert!(
                obj(&x) <= best + 1e-9 * best.abs().max(1.0),
                "case {case}: {} vs brute force {best}",
                obj(&x)
            );
        }
    }
}
