//! The catalogue of candidate effects (issue #7): for each, its name, how it sits in the model
//! file, its parameters and bounds, its signature check and its fit.
//!
//! Two kinds of fit, chosen by where the effect shows:
//! * **fast effects** (`time-delay`, `amplifier-pole`, `resonance`, `slew-rate-limit`,
//!   `saturation`) change the response within milliseconds of an edge. Their parameters enter
//!   the dynamics non-linearly, so they are fitted by a bounded search (coarse grid, then a
//!   golden-section refinement) that simulates the fast records (50 kHz, short: cheap) with the
//!   whole current model plus the candidate;
//! * **slow effects** (`drift`, `hysteresis`, `nonlinear-gain`) add a term to the quasi-static
//!   displacement that is linear in their weights given a few shape constants (drift time
//!   constants, play thresholds); the sensor's `sensor-gain` (scale error: the residual is
//!   proportional to the simulated output) and `offset` (a constant) are linear outright. They are fitted together, by one weighted least-squares
//!   solve on the settled samples of all records (time constants chosen from a log grid by the
//!   same solve), so an effect already in the model is refitted with the new one; a base
//!   model's own slow effects are held as it gives them until a step names their refit
//!   (`select`'s candidates, `SlowRegressors::held`).
//!
//! Every candidate is then checked the same way: the whole augmented model is simulated on
//! every record by [`model_core::stage::Stage`] (never by a second simulator) and scored.

use super::constants::{
    CREEP_SHARE_INPUTS_V, CREEP_SHARE_MAX, CREEP_START_UNPINNED_SHARE, SENSOR_GAIN_RANGE,
};
use super::data::Data;
use crate::io::model_file::{
    DelaySection, DriftSection, GainSection, ModelFile, OffsetSection, PoleSection,
    ResonanceSection, SaturationSection, SensorGainSection, SlewSection,
};
use model_core::params;

/// The catalogued effects, in the order the tables list them (the names are a contract).
pub const EFFECTS: [&str; 10] = [
    "time-delay",
    "amplifier-pole",
    "resonance",
    "drift",
    "hysteresis",
    "nonlinear-gain",
    "slew-rate-limit",
    "saturation",
    "sensor-gain",
    "offset",
];

/// The slow effects (fitted together by one least-squares solve).
pub const SLOW: [&str; 5] = [
    "drift",
    "hysteresis",
    "nonlinear-gain",
    "sensor-gain",
    "offset",
];

/// The fast effects (fitted by a bounded search on the fast records).
pub const FAST: [&str; 5] = [
    "time-delay",
    "amplifier-pole",
    "resonance",
    "slew-rate-limit",
    "saturation",
];

/// Drift time constants the fit chooses three from, seconds (log grid, 5 ms..200 s; our
/// assumption: covers the thesis' 0.06, 0.75 and 12 s and the hour-long creep's first minutes).
pub const DRIFT_TAU_GRID_S: [f64; 14] = [
    0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 200.0,
];

/// Why a candidate `m` fitted from `base` names a value no stage or sensor could have, if it
/// does: a `sensor-gain` new in `m` (or changed from `base`'s) outside [`SENSOR_GAIN_RANGE`],
/// or a `drift` new in `m` (or changed) whose settled creep adds more than
/// [`CREEP_SHARE_MAX`] of the stage's linear reading (the plant's static gain through the
/// sensor) at one of [`CREEP_SHARE_INPUTS_V`], counting the lags that settle within the
/// longest of the records `data` (time constants up to [`CREEP_START_UNPINNED_SHARE`] of its
/// length: a longer lag is a ramp there, its settled value the fit's extrapolation, and an
/// offset beside it takes the creep it has not reached back, as step 18's creep from the
/// first input does). Such a candidate is not admitted, whatever it explains.
pub fn implausible(m: &ModelFile, base: &ModelFile, data: &[Data]) -> Option<String> {
    implausible_scale(m, base).or_else(|| implausible_creep(m, base, data))
}

fn implausible_scale(m: &ModelFile, base: &ModelFile) -> Option<String> {
    let g = m.sensor_gain.as_ref()?.gain;
    let changed = base.sensor_gain.as_ref().is_none_or(|b| b.gain != g);
    let (lo, hi) = SENSOR_GAIN_RANGE;
    (changed && !(lo..=hi).contains(&g)).then(|| {
        format!(
            "its fitted scale {g:.3} is outside {lo}-{hi}, what a sensor's calibration and the \
             stage's gain spread could give: a scale standing in for a form the model lacks"
        )
    })
}

fn implausible_creep(m: &ModelFile, base: &ModelFile, data: &[Data]) -> Option<String> {
    let d = m.drift.as_ref()?;
    if base.drift.as_ref() == Some(d) {
        return None;
    }
    let settled = pinned_lags(m, super::data::longest_record_s(data));
    // (the stage's linear reading: a table's `static_output` is a branch of its loop from
    // the table's bottom, not the reversible map, and a wide loop's reads a fraction of it)
    let mut linear = m.clone();
    linear.drift = None;
    linear.hysteresis = None;
    linear.hysteresis_play = None;
    linear.nonlinear_gain = None;
    CREEP_SHARE_INPUTS_V.iter().find_map(|&u| {
        let creep_v = settled.settled_creep_reading_v(u).ok()?;
        let reading_v = linear.static_reading_v(u).ok()?;
        let share = creep_v.abs() / reading_v.abs().max(f64::MIN_POSITIVE);
        (share > CREEP_SHARE_MAX).then(|| {
            format!(
                "its settled creep at {u} V, {:.0} mV, is {:.0} % of the stage's linear reading \
                 there (a creep of a piezo stage adds at most {:.0} %): a lag standing in for a \
                 form the model lacks",
                1e3 * creep_v,
                1e2 * share,
                1e2 * CREEP_SHARE_MAX
            )
        })
    })
}

/// `m` with only the drift lags a record of `seconds` pins (time constants up to
/// [`CREEP_START_UNPINNED_SHARE`] of it; the others' gains set to zero): the creep such a
/// record shows settled, where a longer lag is a ramp.
pub fn pinned_lags(m: &ModelFile, seconds: f64) -> ModelFile {
    let mut pinned = m.clone();
    if let Some(dr) = pinned.drift.as_mut() {
        for (g, tau) in dr.gains.iter_mut().zip(dr.taus_s) {
            if tau > CREEP_START_UNPINNED_SHARE * seconds {
                *g = 0.0;
            }
        }
    }
    pinned
}

/// Is `effect` present in `m`?
pub fn present(m: &ModelFile, effect: &str) -> bool {
    match effect {
        "time-delay" => m.time_delay.is_some(),
        "amplifier-pole" => m.amplifier_pole.is_some(),
        "resonance" => m.resonance.is_some(),
        "drift" => m.drift.is_some(),
        "hysteresis" => m.hysteresis.is_some() || m.hysteresis_play.is_some(),
        "nonlinear-gain" => m.nonlinear_gain.is_some(),
        "slew-rate-limit" => m.slew_rate_limit.is_some(),
        "saturation" => m.saturation.is_some(),
        "sensor-gain" => m.sensor_gain.is_some(),
        "offset" => m.offset.is_some(),
        _ => false,
    }
}

/// Number of fitted parameters of `effect` (for the evidence penalty).
pub fn param_count(effect: &str) -> usize {
    match effect {
        "resonance" => 2,
        // Three gains, three time constants and K(u)'s k1..k3.
        "drift" => 9,
        // The basis has a weight per radius and band, tied along the range by the smoothness
        // penalty: what the
        // records can set freely is about one weight per radius used, which a large loop
        // puts at eight (our assumption, the play form's count before the bands).
        "hysteresis" => params::PLAY_OPERATORS,
        "nonlinear-gain" => 2,
        _ => 1,
    }
}

/// `m` without the slow effects.
pub fn without_slow(m: &ModelFile) -> ModelFile {
    let mut m = m.clone();
    m.drift = None;
    m.hysteresis = None;
    m.hysteresis_play = None;
    m.nonlinear_gain = None;
    m.sensor_gain = None;
    m.offset = None;
    m
}

/// `m` without the slow effects but those in `keep`, which stay as `m` has them (the base
/// model's own effects a diagnosis holds, `select`'s held set).
pub fn without_slow_but(m: &ModelFile, keep: &[&str]) -> ModelFile {
    keep.iter()
        .fold(without_slow(m), |out, e| revert(&out, m, e))
}

/// Is `effect` in `m` as `base` gives it (the same section, or absent from both)?
pub fn as_in(m: &ModelFile, base: &ModelFile, effect: &str) -> bool {
    match effect {
        "time-delay" => m.time_delay == base.time_delay,
        "amplifier-pole" => m.amplifier_pole == base.amplifier_pole,
        "resonance" => m.resonance == base.resonance,
        "drift" => m.drift == base.drift,
        "hysteresis" => {
            m.hysteresis == base.hysteresis && m.hysteresis_play == base.hysteresis_play
        }
        "nonlinear-gain" => m.nonlinear_gain == base.nonlinear_gain,
        "slew-rate-limit" => m.slew_rate_limit == base.slew_rate_limit,
        "saturation" => m.saturation == base.saturation,
        "sensor-gain" => m.sensor_gain == base.sensor_gain,
        "offset" => m.offset == base.offset,
        _ => true,
    }
}

/// `m` without `effect`.
pub fn without(m: &ModelFile, effect: &str) -> ModelFile {
    let mut m = m.clone();
    match effect {
        "time-delay" => m.time_delay = None,
        "amplifier-pole" => m.amplifier_pole = None,
        "resonance" => m.resonance = None,
        "drift" => m.drift = None,
        "hysteresis" => {
            m.hysteresis = None;
            m.hysteresis_play = None;
        }
        "nonlinear-gain" => m.nonlinear_gain = None,
        "slew-rate-limit" => m.slew_rate_limit = None,
        "saturation" => m.saturation = None,
        "sensor-gain" => m.sensor_gain = None,
        "offset" => m.offset = None,
        _ => {}
    }
    m
}

/// `m` with `effect` as `base` has it (absent if `base` lacks it): how an effect is taken
/// back out of the model.
pub fn revert(m: &ModelFile, base: &ModelFile, effect: &str) -> ModelFile {
    let mut m = m.clone();
    match effect {
        "time-delay" => m.time_delay = base.time_delay.clone(),
        "amplifier-pole" => m.amplifier_pole = base.amplifier_pole.clone(),
        "resonance" => m.resonance = base.resonance.clone(),
        "drift" => m.drift = base.drift.clone(),
        "hysteresis" => {
            m.hysteresis = base.hysteresis.clone();
            m.hysteresis_play = base.hysteresis_play.clone();
        }
        "nonlinear-gain" => m.nonlinear_gain = base.nonlinear_gain.clone(),
        "slew-rate-limit" => m.slew_rate_limit = base.slew_rate_limit.clone(),
        "saturation" => m.saturation = base.saturation.clone(),
        "sensor-gain" => m.sensor_gain = base.sensor_gain.clone(),
        "offset" => m.offset = base.offset.clone(),
        _ => {}
    }
    m
}

/// The parameters of `effect` in `m`, as (name, value) pairs for tables and JSON.
pub fn params_of(m: &ModelFile, effect: &str) -> Vec<(String, f64)> {
    let one = |k: &str, v: f64| vec![(k.to_string(), v)];
    match effect {
        "time-delay" => m
            .time_delay
            .as_ref()
            .map_or(vec![], |d| one("delay_s", d.delay_s)),
        "amplifier-pole" => m
            .amplifier_pole
            .as_ref()
            .map_or(vec![], |p| one("pole_hz", p.pole_hz)),
        "resonance" => m.resonance.as_ref().map_or(vec![], |r| {
            vec![("mode_hz".into(), r.mode_hz), ("damping".into(), r.damping)]
        }),
        "drift" => m.drift.as_ref().map_or(vec![], |d| {
            let mut v = Vec::new();
            for i in 0..3 {
                v.push((format!("gain{}", i + 1), d.gains[i]));
                v.push((format!("tau{}_s", i + 1), d.taus_s[i]));
            }
            // K(u) = k0 + k1 u + k2 u^2 + k3 u^3, shown when it is not 1, with the input
            // above which it is held.
            if d.poly != [1.0, 0.0, 0.0, 0.0] {
                for (i, k) in d.poly.iter().enumerate() {
                    v.push((format!("k{i}"), *k));
                }
                v.push(("k_held_above_v".into(), d.poly_range_v[1]));
            }
            if let Some(c) = d.unsettled_v {
                v.push(("unsettled_v".into(), c));
            }
            v
        }),
        "hysteresis" => match (&m.hysteresis, &m.hysteresis_play) {
            (Some(h), _) => super::everett::summary(h),
            (None, Some(h)) => h
                .radii_v
                .iter()
                .zip(&h.weights)
                .filter(|(_, w)| **w != 0.0)
                .map(|(r, w)| (format!("w_r{r:.3}v"), *w))
                .collect(),
            (None, None) => vec![],
        },
        "nonlinear-gain" => m.nonlinear_gain.as_ref().map_or(vec![], |g| {
            let mut p = vec![
                ("c1_per_v".into(), g.poly[1]),
                ("c2_per_v2".into(), g.poly[2]),
            ];
            // (the higher terms only where a fit gave them: `select`'s scale-or-curvature
            // check, step 14)
            for (k, &c) in g.poly.iter().enumerate().skip(3) {
                if c != 0.0 {
                    p.push((format!("c{k}_per_v{k}"), c));
                }
            }
            p
        }),
        "slew-rate-limit" => m
            .slew_rate_limit
            .as_ref()
            .map_or(vec![], |s| one("output_v_per_s", s.output_v_per_s)),
        "saturation" => m
            .saturation
            .as_ref()
            .map_or(vec![], |s| one("output_max_v", s.output_range_v[1])),
        "sensor-gain" => m
            .sensor_gain
            .as_ref()
            .map_or(vec![], |g| one("gain", g.gain)),
        "offset" => m
            .offset
            .as_ref()
            .map_or(vec![], |o| one("offset_v", o.offset_v)),
        _ => vec![],
    }
}

/// A one- or two-parameter fast effect: its bounds and how a value goes into the model.
pub struct FastSpec {
    /// Effect name.
    pub effect: &'static str,
    /// Bounds of the (first) parameter.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
    /// Search on a log scale.
    pub log: bool,
}

/// The search spaces of the fast effects (bounds: what the stage and the model file accept
/// and what is physically plausible; our assumptions).
pub fn fast_spec(effect: &str) -> Option<FastSpec> {
    let s = |effect, lo, hi, log| {
        Some(FastSpec {
            effect,
            lo,
            hi,
            log,
        })
    };
    match effect {
        "time-delay" => s("time-delay", 0.0, params::MAX_DELAY_S, false),
        "amplifier-pole" => s("amplifier-pole", 200.0, 20_000.0, true),
        "resonance" => s("resonance", 1_000.0, 20_000.0, true),
        "slew-rate-limit" => s("slew-rate-limit", 1.5e4, 1.5e6, true),
        "saturation" => s("saturation", 10.0, params::AMP_OUTPUT_MAX_V, false),
        _ => None,
    }
}

/// `m` with the fast effect set to `x` (and `x2`, the resonance's damping).
pub fn with_fast(m: &ModelFile, effect: &str, x: f64, x2: f64) -> ModelFile {
    let mut m = m.clone();
    match effect {
        "time-delay" => m.time_delay = Some(DelaySection { delay_s: x }),
        "amplifier-pole" => m.amplifier_pole = Some(PoleSection { pole_hz: x }),
        "resonance" => {
            m.resonance = Some(ResonanceSection {
                mode_hz: x,
                damping: x2,
            })
        }
        "slew-rate-limit" => m.slew_rate_limit = Some(SlewSection { output_v_per_s: x }),
        "saturation" => {
            m.saturation = Some(SaturationSection {
                input_range_v: [params::AMP_INPUT_MIN_V, params::AMP_INPUT_MAX_V],
                output_range_v: [params::AMP_OUTPUT_MIN_V, x],
            })
        }
        _ => {}
    }
    m
}

/// The current value of a fast effect in `m` (the search's starting point), if present.
pub fn fast_value(m: &ModelFile, effect: &str) -> Option<(f64, f64)> {
    match effect {
        "time-delay" => m.time_delay.as_ref().map(|d| (d.delay_s, 0.0)),
        "amplifier-pole" => m.amplifier_pole.as_ref().map(|p| (p.pole_hz, 0.0)),
        "resonance" => m.resonance.as_ref().map(|r| (r.mode_hz, r.damping)),
        "slew-rate-limit" => m.slew_rate_limit.as_ref().map(|s| (s.output_v_per_s, 0.0)),
        "saturation" => m.saturation.as_ref().map(|s| (s.output_range_v[1], 0.0)),
        _ => None,
    }
}

/// Slow-effect parameters from the least-squares solve.
#[derive(Clone, Debug, Default)]
pub struct SlowParams {
    /// Drift: (gains, taus).
    pub drift: Option<([f64; 3], [f64; 3])>,
    /// Hysteresis: the basis weights and the table's range ([`super::everett`]).
    pub hysteresis: Option<super::everett::HystFit>,
    /// K'(u) = 1 + c1 u + c2 u^2.
    pub gain: Option<(f64, f64)>,
    /// The drift's K(u), lowest power first, and the input above which it is held, volts
    /// (`None`: K = 1).
    pub drift_poly: Option<([f64; 4], f64)>,
    /// The sensor's scale error (factor on the nominal sensor gain).
    pub sensor_gain: Option<f64>,
    /// The sensor's offset, volts.
    pub offset_v: Option<f64>,
}

/// `m` (without its slow effects but those in `keep`, which stay as `m` has them and none of
/// which `p` holds) with the slow effects `p`; `u_range` is the inputs' span (the range of
/// K(u) and K'(u)). `None` if the parameters are outside what the stage accepts.
pub fn with_slow_but(
    m: &ModelFile,
    p: &SlowParams,
    u_range: (f64, f64),
    keep: &[&str],
) -> Option<ModelFile> {
    let mut m = without_slow_but(m, keep);
    if let Some((gains, taus)) = p.drift {
        m.drift = Some(DriftSection {
            gains,
            taus_s: taus,
            poly: p.drift_poly.map_or([1.0, 0.0, 0.0, 0.0], |k| k.0),
            poly_range_v: [u_range.0, p.drift_poly.map_or(u_range.1, |k| k.1)],
            unsettled_v: None,
        });
    }
    if let Some(h) = &p.hysteresis {
        m.hysteresis = Some(h.section(m.plant.static_gain));
    }
    if let Some((c1, c2)) = p.gain {
        m.nonlinear_gain = Some(GainSection {
            poly: [1.0, c1, c2, 0.0, 0.0, 0.0, 0.0],
            range_v: [u_range.0, u_range.1],
        });
    }
    if let Some(gain) = p.sensor_gain {
        m.sensor_gain = Some(SensorGainSection { gain });
    }
    if let Some(offset_v) = p.offset_v {
        m.offset = Some(OffsetSection { offset_v });
    }
    m.build_stage().ok().map(|_| m)
}
