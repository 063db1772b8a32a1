//! Identified blocks written into a model file (the library half of `piezo identify`): the
//! base model's block replaced (or added) by the one a record shows, the model's name saying
//! so, and the result checked by building its stage.
//!
//! The hysteresis table is identified from the record minus the base model's drift, so the
//! drift is not counted twice ([`drift_response`] is that drift's prediction).

use crate::identify::drift::{DriftFit, identify_drift};
use crate::identify::hysteresis::identify_hysteresis;
use crate::io::csv::Record;
use crate::io::model_file::{DriftSection, HysteresisSection, ModelFile};
use anyhow::{Context, ensure};
use model_core::drift::DriftConfig;

/// The drift branch's output for `u_v` held over each sample of `period_s`, starting at rest
/// with `u_v[0]` (exact for a held input, `f64`; the drift lags are 60 ms and slower, so the
/// record's rate need not be the stage's).
pub fn drift_response(d: &DriftConfig, period_s: f64, u_v: &[f64]) -> Vec<f64> {
    let decay = d.taus_s.map(|t| (-period_s / t).exp());
    let w0 = u_v.first().map_or(0.0, |u| d.weight(*u));
    let mut y = d.gains.map(|g| g * w0);
    let mut out = Vec::with_capacity(u_v.len());
    let mut prev = u_v.first().copied().unwrap_or(0.0);
    for &u in u_v {
        // y[i] is the drift at sample i, driven by the inputs before it.
        out.push(y.iter().sum());
        let w = d.weight(prev);
        for k in 0..3 {
            let target = d.gains[k] * w;
            y[k] = target + (y[k] - target) * decay[k];
        }
        prev = u;
    }
    out
}

/// Identify the drift lags (eq. 5.1) from the step record `rec` into `model`, starting from
/// the model's own drift (or the default), and return the fit. `source` names the record in
/// the model's new name.
pub fn drift_into(model: &mut ModelFile, rec: &Record, source: &str) -> anyhow::Result<DriftFit> {
    let base = model.stage_config()?.drift.unwrap_or_default();
    let fit = identify_drift(&rec.t_s, &rec.u_v, rec.require_y()?, &base)
        .with_context(|| format!("drift identification from {source}"))?;
    let d: DriftConfig = fit.config;
    let finite =
        d.gains.iter().chain(&d.taus_s).all(|v| v.is_finite()) && fit.rms_residual_v.is_finite();
    ensure!(
        finite && d.gains.iter().any(|g| *g != 0.0),
        "drift identification from {source}: the fit gave gains {:?} and time constants {:?} s, \
         not a usable drift (is the record a step of u held long enough, with y responding?)",
        d.gains,
        d.taus_s
    );
    model.drift = Some(DriftSection {
        gains: d.gains,
        taus_s: d.taus_s,
        poly: d.poly,
        poly_range_v: [d.poly_range_v.0, d.poly_range_v.1],
        unsettled_v: None,
    });
    model.name = format!("{} + drift identified from {source}", model.name);
    model.build_stage()?;
    Ok(fit)
}

/// Identify the hysteresis table from `rec` into `model` (returns true if `[nonlinear-gain]`
/// was removed). With drift in the base model, its prediction is taken out of the record first,
/// so the table holds the fast static curve only and the drift is not counted twice; the table
/// is the measured static curve with the amplitude-dependent gain in it, so `[nonlinear-gain]`
/// is removed (keeping it would count that gain twice).
pub fn hysteresis_into(model: &mut ModelFile, rec: &Record, source: &str) -> anyhow::Result<bool> {
    let mut y = rec.require_y()?.to_vec();
    if let Some(d) = model.stage_config()?.drift {
        let drift = drift_response(&d, rec.period_s(), &rec.u_v);
        for (yi, di) in y.iter_mut().zip(&drift) {
            *yi -= di;
        }
    }
    let table = identify_hysteresis(&rec.t_s, &rec.u_v, &y)
        .with_context(|| format!("hysteresis identification from {source}"))?;
    model.hysteresis = Some(HysteresisSection::from_table(&table));
    let dropped = model.nonlinear_gain.take().is_some();
    model.name = format!("{} + hysteresis identified from {source}", model.name);
    model.build_stage()?;
    Ok(dropped)
}
