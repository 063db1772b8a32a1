//! The greedy driver of the workflow (steps 4-6 of the loop in [`super`]): fit every candidate
//! ([`super::fast_fit`], [`super::slow_fit`]), simulate it on every record, score it (the
//! per-record Gaussian log-likelihood change with the BIC penalty), add the best admissible
//! one, repeat until the residual reaches the noise floor; then the final check takes back out
//! every named effect that does not earn its place ([`super::constants::PRUNE_RATIO`]), the
//! slow effects are refitted once more with every named effect in place, and the swaps try
//! each named slow effect's look-alikes (step 7 of the loop); last, the sensor's reading at
//! rest at 0 V may name an offset (`rest_reading`, GAP.md step 11), and an offset that is the
//! settled creep at the records' first input taken back is read as the drift's start
//! (`creep_start`, GAP.md step 12).

use super::catalogue::{self, EFFECTS, FAST, SLOW};
use super::constants::{
    CANDIDATE_ROUNDS, CANNOT_TELL_RATIO, CLIP_BAND_FLOORS, CLIP_MIN_SAMPLES, CLIP_MIN_SHARE,
    CLIP_SPAN_SHARE, CREEP_START_MIN_FLOORS, CREEP_START_SHARE, DRIFT_TAIL_KEEP_NOISE,
    DRIFT_TAIL_MIN_NOISE, FOLLOW_MIN_CORRELATION, HELD_LOOP_OVER_TAIL, HOLD_MIN_S,
    HYST_LOOP_MIN_NOISE, MAX_STEPS, MIN_EXPLAINED, MSE_MIN_V2, OCCAM_SWAP_RATIO, PAIR_FLOOR_RATIO,
    PRUNE_KEEP_EXCESS_VAR, PRUNE_PER_PARAM, PRUNE_RATIO, REFIT_ALL_SHARE, REST_ZERO_INPUT_V,
    REST_ZERO_SHOWN_MIN, REST_ZERO_SIGMAS, REVERSED_CORRELATION, REVERSED_MIN_FLOORS,
    RISE_CHOICE_RATIO, SAME_READING_FLOORS, SCALE_APART_MAX, SENSOR_GAIN_RANGE, STATIC_TELL_RATIO,
    STOP_FLOOR_RATIO, STRUCTURE_ROUNDS,
};
use super::cycle_noise::cycle_bar_v;
use super::data::{
    Data, LineFit, NoiseFloor, log_mse_term, min_max, mse, noise_floor_of, sim, simulate_all,
    swapped_columns, without_glitches,
};
use super::everett::CentreLine;
use super::fast_fit::fit_fast;
use super::input_noise;
use super::mains::{self, HumLine};
use super::memory;
use super::scale_order::{self, InPlace};
use super::signatures::{self, shows_share};
use super::slow_fit::{SlowRegressors, fit_slow, slow_regressors, solve_rows};
use super::start;
use super::unexplained::{Unexplained, locate};
use crate::io::model_file::ModelFile;
use crate::util::{par_map, par_map_costliest_first};
use anyhow::{Context, bail, ensure};
use model_core::hysteresis::HysteresisMemory;

/// One step of the workflow: the effect added or refitted.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Step {
    /// Effect name (one of [`EFFECTS`]; a refit of several, a static shape fitted with an
    /// offset at one step, `X+offset`, or a creep and a loop fitted as one step,
    /// `drift+hysteresis`: their names joined by `+`).
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
    /// The final check took this effect back out (or step 12 read it as the drift's start).
    #[serde(skip)]
    pub removed: bool,
}

impl Step {
    /// A step named `effect` with its `evidence`, from each record's residual mean square
    /// before and after it and the simulations after it (no parameters, neither a refit nor
    /// removed: set those fields on the result).
    fn new(
        effect: String,
        evidence: String,
        mse_before: &[f64],
        mse_after: &[f64],
        sims: Vec<Vec<f64>>,
    ) -> Self {
        Step {
            effect,
            evidence,
            params: serde_json::Map::new(),
            rms_before_v: rms_of(mse_before),
            rms_after_v: rms_of(mse_after),
            record_rms_before_v: mse_before.iter().map(|m| m.sqrt()).collect(),
            record_rms_after_v: mse_after.iter().map(|m| m.sqrt()).collect(),
            sims,
            refit: false,
            removed: false,
        }
    }
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
    /// For each record whose noise is coloured or below its resolution, how its floor was
    /// found ([`super::data::NoiseFloor::note`]), each record's glitches, replaced before the
    /// fits ([`super::data::without_glitches`]), its mains interference, taken out before
    /// them ([`super::mains::note`]), and a measured input's noise that its floor holds
    /// ([`super::input_noise::InputNoise::note`]).
    pub noise_notes: Vec<String>,
    /// Each record's glitches, replaced before the fits: (sample index, value it was
    /// replaced by) ([`super::data::glitches`]; [`Diagnosis::cleaned`] applies them).
    pub glitches: Vec<Vec<(usize, f64)>>,
    /// Each record's mains interference, taken out of its output before its glitches are
    /// looked for ([`super::mains::mains_lines`]; [`Diagnosis::cleaned`] applies them).
    pub hum: Vec<Vec<HumLine>>,
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
    /// The candidates each step left out, and why: the fast effects it did not search (no fit
    /// of them could pass the step's gate on its residual,
    /// [`signatures::Signatures::search_left_out`]), and those it fitted to a value no stage
    /// or sensor could have ([`catalogue::implausible`]), which it did not admit.
    pub not_searched: Vec<Vec<(String, String)>>,
    /// Signature checks of the base model's residual.
    pub signatures: signatures::Signatures,
    /// Named effects the records cannot tell from another (no holds: a drift and a
    /// hysteresis loop at low frequency), with the other's residual in its place.
    pub cannot_tell: Vec<CannotTell>,
    /// The residual no catalogued effect explained, when some record stays above
    /// [`super::unexplained::UNEXPLAINED_FLOOR_RATIO`] times its floor.
    pub unexplained: Option<Unexplained>,
    /// The split of the hysteresis basis the diagnosis used, and why.
    pub centre_line: CentreChoice,
}

/// The split of the hysteresis basis ([`CentreLine`]) a diagnosis used: hysteresis and drift
/// fitted from the base model with each, what each left, and, where those were too close to
/// choose by and both splits' diagnoses ran, the other's outcome.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CentreChoice {
    /// The split of the diagnosis kept: the one whose hysteresis and drift left less (the
    /// rise split only where it left less than [`RISE_CHOICE_RATIO`] of the band split's),
    /// unless [`Self::by_diagnosis`] says the other split's diagnosis was kept instead (it
    /// alone explained every record, or it named fewer effects).
    pub chosen: CentreLine,
    /// With the `Band` split: the sum over records of the mean squared residual, in noise
    /// variances (`null` in JSON when the fit failed).
    pub band_noise_var: f64,
    /// The same with the `Span` split.
    pub span_noise_var: f64,
    /// The same with the `Rise` split, fitted whenever the band split left no more than the
    /// span split (kept or not: [`RISE_CHOICE_RATIO`]). Where it is kept the span split left
    /// more than twice it, beyond `CANNOT_TELL_RATIO`, so the span split's diagnosis never
    /// runs beside it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rise_noise_var: Option<f64>,
    /// When those two were within [`CANNOT_TELL_RATIO`] (RMS) of each other and both splits'
    /// diagnoses ran (the one explaining every record kept where only one does, else the one
    /// naming fewer effects): the other's outcome (absent from the
    /// JSON when the loop alone chose).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub by_diagnosis: Option<SplitRival>,
}

/// The diagnosis of the split not kept, when both ran ([`CentreChoice::by_diagnosis`]).
#[derive(Clone, Debug, serde::Serialize)]
pub struct SplitRival {
    /// Its split.
    pub split: CentreLine,
    /// The effects it named.
    pub named: Vec<String>,
    /// Its final residual: the sum over records of the mean square, in noise variances.
    pub final_noise_var: f64,
}

impl CentreChoice {
    /// What hysteresis and drift alone left with the chosen split and with the other, in
    /// noise variances.
    pub fn kept_and_other(&self) -> (f64, f64) {
        (self.noise_var(self.chosen), self.noise_var(self.other()))
    }

    /// The split the kept one was weighed against by the loop alone: the band split for the
    /// span split, the span split for the others.
    pub fn other(&self) -> CentreLine {
        match self.chosen {
            CentreLine::Span => CentreLine::Band,
            CentreLine::Band
            | CentreLine::Rise
            | CentreLine::Tent
            | CentreLine::RiseTent
            | CentreLine::Own
            | CentreLine::RiseOwn => CentreLine::Span,
        }
    }

    /// What hysteresis and drift alone left with split `form`, in noise variances (the rise
    /// split's figure where it was fitted, else the band split's).
    fn noise_var(&self, form: CentreLine) -> f64 {
        match form {
            // (the tent splits are never chosen here: step 20 refines the band and rise splits'
            // tables with them)
            CentreLine::Band | CentreLine::Tent | CentreLine::Own => self.band_noise_var,
            CentreLine::Span => self.span_noise_var,
            CentreLine::Rise | CentreLine::RiseTent | CentreLine::RiseOwn => {
                self.rise_noise_var.unwrap_or(self.band_noise_var)
            }
        }
    }
}

impl Diagnosis {
    /// The records as the diagnosis read them: `data` with its mains interference taken out
    /// and its glitches replaced (what its residuals and plots are of).
    pub fn cleaned(&self, data: &[Data]) -> Vec<Data> {
        data.iter()
            .enumerate()
            .map(|(r, d)| {
                mains::subtract(d, self.hum.get(r).map_or(&[], Vec::as_slice))
                    .with_samples_replaced(self.glitches.get(r).map_or(&[], Vec::as_slice))
            })
            .collect()
    }

    /// Each record's final mean squared residual.
    fn final_mse(&self) -> Vec<f64> {
        self.record_final_rms_v.iter().map(|r| r * r).collect()
    }

    /// The final residual as the split choice measures it: the sum over records of the mean
    /// square over the record's noise variance `var`.
    fn final_noise_var(&self, var: &[f64]) -> f64 {
        in_noise_vars(&self.final_mse(), var)
    }

    /// The JSON object of `piezo gap --json`. `unexplained` is always there: `null` when every
    /// record ends within [`super::unexplained::UNEXPLAINED_FLOOR_RATIO`] of its floor, so a
    /// reader never has to tell a missing key from an old version.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "named": self.named,
            "steps": self.steps.iter().map(|s| serde_json::json!({
                "effect": s.effect,
                "evidence": s.evidence,
                "params": s.params,
                "rms_before_v": s.rms_before_v,
                "rms_after_v": s.rms_after_v,
                "refit": s.refit,
                "removed": s.removed,
            })).collect::<Vec<_>>(),
            "noise_floor_v": self.noise_floor_v,
            "noise_notes": self.noise_notes,
            "final_rms_v": self.final_rms_v,
            "unexplained": self.unexplained,
            "cannot_tell": self.cannot_tell,
            "hysteresis_split": self.centre_line,
        })
    }
}

/// Two effects the records cannot tell apart. Either a named effect and another that, fitted
/// in its place, leaves every record's residual within [`CANNOT_TELL_RATIO`] of the named
/// one's; or two static shapes a step could add, each explaining nearly as much as the other
/// ([`STATIC_TELL_RATIO`], pooled and in every record: `explain_alike`), of which neither is
/// named at that step (`neither_named`; dropped from the list where a later step, or a pair
/// with an offset at the same step, names one of them); or an offset beside a table that the
/// final check took out as a level the records do not show ([`TakenOut::Unshown`]), whatever
/// the two leave, with the static shapes that, fitted in its place, explain a step's share of
/// what the model without it leaves ([`TakenOut::InOffsetsPlace`], `neither_named`); or a
/// static shape beside a table on records without holds that the final check took out below
/// its bar, though the residual without it grew by more than [`CANNOT_TELL_RATIO`]
/// ([`TakenOut::BelowBar`]).
#[derive(Clone, Debug, serde::Serialize)]
pub struct CannotTell {
    /// The effect named (with `neither_named`: the one the step would have added).
    pub named: String,
    /// The effect the records cannot tell from it.
    pub alternative: String,
    /// Residual RMS over the records with `named`, volts (final, or the step's candidate's).
    pub rms_v: f64,
    /// Residual RMS with the alternative in the named effect's place, volts.
    pub alternative_rms_v: f64,
    /// Neither effect was named: the records leave the choice between them to chance.
    pub neither_named: bool,
    /// How the final check made the pair, where it did ([`TakenOut`]). Not in the JSON (its
    /// keys stay).
    #[serde(skip)]
    pub taken_out: TakenOut,
    /// Why, and what record would tell them apart.
    pub why: String,
}

/// How the final check made a [`CannotTell`] pair.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TakenOut {
    /// It did not: a step's pair, or a later rule's.
    #[default]
    No,
    /// It took `alternative` (an offset beside a table) out as a level the records do not
    /// show: `alternative_rms_v` is what the model left with it, `rms_v` without it, and the
    /// two need not be alike (the report's unexplained part says so where the second is
    /// clearly larger).
    Unshown,
    /// A static shape (`named`) fitted in the place of such an offset (`alternative`) beside
    /// the effects still named then explains at least a step's share of what the model
    /// without the offset leaves: the offset's work may have been the shape's. Neither is
    /// named.
    InOffsetsPlace,
    /// It took `alternative` (a scale or a curvature beside a table, on records without
    /// holds) out below its bar, though the residual without it grew by more than
    /// [`CANNOT_TELL_RATIO`]: the others' refit, the table's among them, took up most of its
    /// work. `alternative_rms_v` is what the model left with it, `rms_v` without it.
    BelowBar,
    /// It took `alternative` (a static shape beside a table) out as one the records do not
    /// tell from the loop's own centre line and constant (GAP.md step 17): no held levels it
    /// puts clearly nearer from both sides, no rest at 0 V that shows an offset.
    /// `alternative_rms_v` is what the model left with it, `rms_v` without it.
    Untold,
}

impl CannotTell {
    /// Does the alternative leave clearly less than the named side (by [`CANNOT_TELL_RATIO`],
    /// RMS)? Then the two are not alike in residual, and what keeps the alternative out is
    /// another reason ([`TakenOut::Unshown`]: a level the records do not show).
    pub fn alternative_clearly_less(&self) -> bool {
        self.alternative_rms_v * CANNOT_TELL_RATIO < self.rms_v
    }
}

/// The BIC score of the named `set` over all records at residual powers `ms`: each record's
/// Gaussian log-likelihood term plus the set's parameters times the log of all samples
/// (lower is better; the swaps and the reading at rest compare sets by it).
fn set_score(data: &[Data], ms: &[f64], set: &[String]) -> f64 {
    let n_all: f64 = data.iter().map(|d| d.len() as f64).sum();
    data.iter()
        .zip(ms)
        .map(|(d, m)| log_mse_term(d.len() as f64, *m))
        .sum::<f64>()
        + set
            .iter()
            .map(|e| catalogue::param_count(e) as f64)
            .sum::<f64>()
            * n_all.ln()
}

/// The records' mean squares `mse` summed in their noise variances `var`.
fn in_noise_vars(mse: &[f64], var: &[f64]) -> f64 {
    mse.iter().zip(var).map(|(m, v)| m / v).sum()
}

/// No record's residual power grows (beyond 0.1 %, rounding): the score is dominated by the
/// longest record, and a change that trades a short fast record for it is no explanation.
fn no_record_worse(ms: &[f64], cur_mse: &[f64]) -> bool {
    ms.iter().zip(cur_mse).all(|(a, b)| *a <= *b * 1.001)
}

/// Does `ms` leave strictly less than `other` in every record (the like-for-like tests of
/// step 14 (b) and (d))?
fn less_in_every_record(ms: &[f64], other: &[f64]) -> bool {
    ms.iter().zip(other).all(|(a, b)| a < b)
}

/// An offset fitted in the place of the table's constant at rest at 0 V
/// ([`rest_reading`]).
struct RestReading {
    /// The model with the offset, its slow effects refitted.
    with: ModelFile,
    sims: Vec<Vec<f64>>,
    mse: Vec<f64>,
    reading_v: f64,
    predicted_v: f64,
}

/// The sensor's reading over the records' rest at 0 V input, with no offset named: at rest
/// at 0 V no other catalogued effect moves the sensor (a scale, `K'(u) u` and a settled drift
/// all vanish), and the thesis' table ends at 0 V, where its memory is wiped, so the reading
/// there is the sensor's zero. The model may leave it in the residual there (a step's share
/// of the residual power is too small to add an offset for a few hundred samples of a long
/// record) or predict it (the table's relays below the records' inputs, its range reaching
/// below them, or its start memory, hold a constant there). Returned where the reading is at
/// least one noise floor (a level a single sample shows) and [`REST_ZERO_SIGMAS`] standard
/// errors of its mean: the model with an offset refitted beside the others, its simulations
/// and residual powers, and the reading and the model's prediction at rest, volts.
#[allow(clippy::too_many_arguments)] // the selection's state, passed as it stands
fn rest_reading(
    model: &ModelFile,
    named: &[String],
    data: &[Data],
    sims: &[Vec<f64>],
    noise: &[f64],
    noise_floor_v: f64,
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
) -> Option<RestReading> {
    if named.iter().any(|n| n == "offset") || catalogue::present(model, "offset") {
        return None;
    }
    let (level_v, y_v, se_v) = signatures::compute(data, sims, noise).rest_zero_v?;
    if y_v.abs() < noise_floor_v.max(REST_ZERO_SIGMAS * se_v) {
        return None;
    }
    let with = refit_slow(model, &["offset"], data, slow_x, u_range)?;
    let (sims, mse) = simulate_all(&with, data).ok()?;
    Some(RestReading {
        with,
        sims,
        mse,
        reading_v: y_v,
        predicted_v: y_v - level_v,
    })
}

/// A named offset that is the model's settled creep at the records' first input taken back
/// ([`creep_start`]): the offset, the records' first input (the first record's) and the
/// settled creep there, volts.
struct CreepStart {
    offset_v: f64,
    first_input_v: f64,
    creep_v: f64,
    /// The settled creep there of the lags the first record pins (`creep_v` where it pins
    /// all, or where theirs is within the noise).
    pinned_v: f64,
}

/// Step 12 (GAP.md): with `drift` and `offset` named, is the offset the model's settled creep
/// at every record's first input with its sign turned, within [`CREEP_START_SHARE`] of it
/// or of the span below (and that creep at least [`CREEP_START_MIN_FLOORS`] noise floors)? The model's drift starts
/// settled at the first input (a stage at rest there for ever); a stage whose creep counts
/// from the first input (its creep had not settled there, or a creep with no end, such as a
/// logarithmic one, measured from the record's start) reads exactly that much less at every
/// sample, which an offset takes up. Records that start at different inputs have different
/// settled creeps, and one offset cannot take back all of them.
///
/// A lag slower than a third of a record
/// ([`CREEP_START_UNPINNED_SHARE`](super::constants::CREEP_START_UNPINNED_SHARE): the lags
/// `catalogue::pinned_lags` leaves out) barely moves within it: whether it started settled
/// or counting from the first input, the record sees
/// a constant and a slow trend that the offset and the other lags share, so its part of the
/// settled creep may or may not be in the offset. The offset is then compared with the span
/// from the settled creep of the lags the record pins to that of all of them (a power-law
/// creep on a 12 s sine, lags of 0.04, 1.2 and 9 s: the offset took back 0.87 V of a
/// settled creep of 1.08 V, 0.91 V of it the two faster lags'). Spans of records that start
/// at different inputs may overlap, so such records tell a sensor offset from the drift's
/// start only where their lags are pinned.
fn creep_start(
    model: &ModelFile,
    named: &[String],
    data: &[Data],
    noise: &[f64],
) -> Option<CreepStart> {
    if !["drift", "offset"]
        .iter()
        .all(|e| named.iter().any(|n| n == e))
    {
        return None;
    }
    let offset_v = model.offset.as_ref()?.offset_v;
    let mut first_creep_v = None;
    for (d, floor) in data.iter().zip(noise) {
        let u0 = *d.u_v.first()?;
        let creep_v = model.settled_creep_reading_v(u0).ok()?;
        // The settled creep of the lags the record pins (their time constants within
        // CREEP_START_UNPINNED_SHARE of its length).
        let pinned = catalogue::pinned_lags(model, d.length_s()?);
        // (where the pinned lags leave no creep of the same sign clear of the noise, as a
        // record shorter than three of every lag's time constants, the span would reach zero
        // and take any small offset of the right sign: the one value of all the lags, then)
        let pinned_v = pinned.settled_creep_reading_v(u0).ok()?;
        let pinned_v = if pinned_v * creep_v.signum() >= CREEP_START_MIN_FLOORS * floor {
            pinned_v
        } else {
            creep_v
        };
        let (lo, hi) = (pinned_v.min(creep_v), pinned_v.max(creep_v));
        let taken_back = -offset_v >= lo - CREEP_START_SHARE * lo.abs()
            && -offset_v <= hi + CREEP_START_SHARE * hi.abs()
            && creep_v.abs() >= CREEP_START_MIN_FLOORS * floor;
        if !taken_back {
            return None;
        }
        first_creep_v.get_or_insert((creep_v, pinned_v));
    }
    let (creep_v, pinned_v) = first_creep_v?;
    Some(CreepStart {
        offset_v,
        first_input_v: *data.first()?.u_v.first()?,
        creep_v,
        pinned_v,
    })
}

/// Say that an offset the records cannot tell from `holder`'s own constant was moved into it
/// (steps 12 and 13): a step `offset (removed)` from the mean squares `before` to `after`
/// (the same readings) and a `"cannot_tell"` pair, both giving `why`.
fn offset_moved(
    (steps, cannot_tell): (&mut Vec<Step>, &mut Vec<CannotTell>),
    holder: &str,
    why: String,
    (before, after): (&[f64], &[f64]),
    sims: &[Vec<f64>],
) {
    steps.push(Step {
        removed: true,
        ..Step::new("offset".into(), why.clone(), before, after, sims.to_vec())
    });
    cannot_tell.push(CannotTell {
        named: holder.into(),
        alternative: "offset".into(),
        neither_named: false,
        taken_out: TakenOut::No,
        rms_v: rms_of(after),
        alternative_rms_v: rms_of(before),
        why,
    });
}

/// Does no record read the sensor's zero: none starts at rest at 0 V input (the one reading
/// nothing but an offset moves) and none goes down to the table's low end `table_low_v`
/// (where every relay is off)? A sensor offset is then a constant that the table's relays the
/// records never switch, and its start memory, hold too (steps 11 and 13, GAP.md).
fn reads_no_zero(data: &[Data], table_low_v: f64) -> bool {
    data.iter()
        .all(|d| d.zero_rest_len().is_none() && min_max(&d.u_v).0 > table_low_v + REST_ZERO_INPUT_V)
}

/// How far `model`'s reading moves per volt of its hysteresis table's own output level
/// (`[hysteresis] offset_v`): the sensor's scale times K'(u) (the plant's static gain is 1:
/// the 0.79 lives in the table), measured on the stage at the table's mid-range input
/// ([`ModelFile::static_reading_v`]). `None` without a table, or where it does not move it.
fn reading_per_table_v(model: &ModelFile) -> Option<f64> {
    let [lo, hi] = model.hysteresis.as_ref()?.input_range_v;
    let mut up = model.clone();
    up.hysteresis.as_mut()?.offset_v += 1.0;
    let u = 0.5 * (lo + hi);
    let per_v = up.static_reading_v(u).ok()? - model.static_reading_v(u).ok()?;
    (per_v.is_finite() && per_v.abs() >= 1e-6).then_some(per_v)
}

/// `model` with its `[offset]` moved into the hysteresis table's own output level, and the
/// table's shift (volts of the table's output): the reading moves by the sensor's scale
/// times K'(u) per volt of the table's level (the plant's static gain is 1: the 0.79 lives in
/// the table: [`reading_per_table_v`], as [`ModelFile::settled_creep_reading_v`] reads the
/// drift). Exact where no K'(u) scales the table ([`same_readings`] checks it).
fn offset_into_table(model: &ModelFile) -> Option<(ModelFile, f64)> {
    let offset_v = model.offset.as_ref()?.offset_v;
    let shift_v = offset_v / reading_per_table_v(model)?;
    let mut moved = model.clone();
    moved.hysteresis.as_mut()?.offset_v += shift_v;
    moved.offset = None;
    Some((moved, shift_v))
}

/// `model` with its `[sensor-gain]` and `[offset]` moved into its hysteresis table's own map
/// (step 19): the Everett values, the table's level and the drift's gains times the scale
/// (everything before the sensor, the plant of unity static gain between), then the offset
/// into the table's level ([`offset_into_table`]). `None` without a table in grid form, or
/// with a drift's unsettled constant (step 12's: it is read after the sensor's gain, as the
/// offset is, and step 19 does not run beside it). The caller checks the readings are the
/// same.
fn centre_line_into_table(model: &ModelFile) -> Option<ModelFile> {
    if model
        .drift
        .as_ref()
        .is_some_and(|d| d.unsettled_v.is_some())
    {
        return None;
    }
    let scale = model.sensor_gain.as_ref().map_or(1.0, |g| g.gain);
    let mut m = model.clone();
    let h = m.hysteresis.as_mut()?;
    for v in h.everett_v.as_mut()? {
        *v = (f64::from(*v) * scale) as f32;
    }
    h.offset_v *= scale;
    if let Some(d) = m.drift.as_mut() {
        for g in &mut d.gains {
            *g *= scale;
        }
    }
    m.sensor_gain = None;
    if m.offset.is_some() {
        m = offset_into_table(&m)?.0;
    }
    Some(m)
}

/// The scales step 19 searches: those a `sensor-gain` may name (a wrong unit or a wrong model
/// farther off, which the refusals say).
const CENTRE_SCALES: (f64, f64) = SENSOR_GAIN_RANGE;

/// How much wider than the table fitted without it step 19 lets a scale make the table's
/// major loop over its whole range (our assumption, [`CANNOT_TELL_RATIO`]'s 1.25): beside a
/// scale, the relays the records never switch (the table reaches 0.5 V beyond them) trade
/// with it and with the offset, and on issue #12's measured record the residual kept falling
/// as the scale grew past 1.05 (18.8 mV) to 1.25 (16.9 mV) while the major loop over the
/// table's range went from 1.2 V to 4.4 V, the records' loop staying 1.2 V: a table no
/// feedforward could use outside the records.
const CENTRE_WIDTH_RATIO: f64 = CANNOT_TELL_RATIO;

/// The widest loop of `model`'s hysteresis table over its range, sensor volts (the larger of
/// [`super::everett::summary`]'s two widths).
fn loop_width_v(model: &ModelFile) -> Option<f64> {
    super::everett::summary(model.hysteresis.as_ref()?)
        .into_iter()
        .filter(|(k, _)| k.starts_with("loop_width"))
        .map(|(_, v)| v)
        .reduce(f64::max)
}

/// Reductions of step 19's bracket of scales (0.618^14 = 0.12 % of its width, 5e-4 in the
/// scale: below what a centre line's residual tells).
const CENTRE_SCALE_ITERATIONS: usize = 14;

/// Step 19's fit: the table and an offset refitted beside a sensor scale held fixed, the
/// scale chosen by a golden-section search over [`CENTRE_SCALES`] (the residual mean squares
/// in noise variances summed over the records), and the model with that scale and offset
/// with its simulations. A scale fitted free beside the split's loop-only columns trades
/// with their own slopes (each band's relays less `clamp(u, band)`) and with the relays the
/// records never switch: on issue #12's measured record it came to 1.50, with -1.99 V, and a
/// table whose major loop over its whole range was 4.4 V wide where the records' is 1.2 V.
/// Held fixed, the scale is read the records' way: the table is refitted to the output
/// divided by it.
fn centre_line_fit(
    model: &ModelFile,
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
    var: &[f64],
) -> Option<(ModelFile, Vec<Vec<f64>>)> {
    let scaled = |scale: f64| -> Vec<Data> {
        data.iter()
            .map(|d| {
                let mut d = d.clone();
                d.y_v.iter_mut().for_each(|y| *y /= scale);
                d
            })
            .collect()
    };
    // (the model of the scaled records read back in the records' own volts)
    let read_back = |mut m: ModelFile, scale: f64| -> ModelFile {
        m.sensor_gain = Some(crate::io::model_file::SensorGainSection { gain: scale });
        if let Some(o) = m.offset.as_mut() {
            o.offset_v *= scale;
        }
        m
    };
    let width_now = loop_width_v(model)?;
    let at = |scale: f64| -> Option<(ModelFile, Vec<Vec<f64>>, f64)> {
        let x = slow_x.for_other_outputs();
        let m = refit_slow(model, &["offset"], &scaled(scale), &x, u_range)?;
        if scale * loop_width_v(&m)? > CENTRE_WIDTH_RATIO * width_now {
            return None;
        }
        let m = read_back(m, scale);
        let (sims, mse) = simulate_all(&m, data).ok()?;
        let cost = in_noise_vars(&mse, var);
        cost.is_finite().then_some((m, sims, cost))
    };
    let (lo, hi) = CENTRE_SCALES;
    let best = crate::util::golden_n(lo, hi, lo, hi, CENTRE_SCALE_ITERATIONS, |g| {
        at(g).map_or(f64::INFINITY, |r| r.2)
    });
    let (m, sims, _) = at(best)?;
    // The start memory that suits the refitted table (as after every step that fits one),
    // searched on the scaled records.
    let scaled_data = scaled(best);
    let x = slow_x.for_other_outputs();
    let mut inner = m.clone();
    inner.sensor_gain = None;
    if let Some(o) = inner.offset.as_mut() {
        o.offset_v /= best;
    }
    let inner_mse: Vec<f64> = scaled_data
        .iter()
        .zip(&sims)
        .map(|(d, s)| {
            let s: Vec<f64> = s.iter().map(|v| v / best).collect();
            super::data::mse(&d.y_v, &s)
        })
        .collect();
    // (its regressors, built on the scaled records, stay here: the caller's are keyed by the
    // same models without slow effects, on the records' own outputs)
    if let Some(f) = super::start::search(&inner, &scaled_data, &x, u_range, &inner_mse)
        && loop_width_v(&f.model).is_some_and(|w| best * w <= CENTRE_WIDTH_RATIO * width_now)
    {
        let m = read_back(f.model, best);
        if let Ok((sims, _)) = simulate_all(&m, data) {
            return Some((m, sims));
        }
    }
    Some((m, sims))
}

/// How many times more of the residual power above the floor the memoryless twin of a
/// table must leave than the table does for step 16a to admit `hysteresis` where the held
/// levels cannot tell a loop (our assumption: a tenth; a static misfit drawn into a loop
/// through the stage's dynamics leaves the twin about as much as the table, step 16).
pub const UNTOLD_TWIN_RATIO: f64 = 10.0;

/// The least share of the residual power above the floor the memoryless twin must leave for
/// step 16a (our assumption: a map that explains 95 % of it leaves no loop worth a table;
/// families cases 1019 and 1024, static shapes on random levels, had twins that explained
/// all of it as well as the table did).
pub const UNTOLD_TWIN_LEFT_MIN: f64 = 0.05;

/// Noise floors a sensor offset read from the table's level at the records' start must reach
/// to be named (step 13a; our assumption: the table's fit near a record's head is good to a
/// floor or two, measured on issue #12's single sines at 0.1-1.8 mV over the first 50 ms).
pub const START_LEVEL_FLOORS: f64 = 5.0;

/// Is the start memory `turns_v` (turning points after coming up from the bottom) a scan that
/// died away at the first input `u0_v`: at least four turning points on alternate sides of it
/// (a point repeated at the same level, as the table's floor clips a scan's lower turns, is
/// one; a point the input passes on its way on is none), each side's distances from it
/// shrinking (or held, where clipped), the last within [`CENTRED_LAST_SHARE`] of `span_v`?
fn centred_scan(turns_v: &[f64], u0_v: f64, span_v: f64) -> bool {
    let mut pts: Vec<f64> = Vec::new();
    for &p in turns_v {
        // (a point the input passes on its way on is no turn: after the floor, a scan's
        // first turn below the first input is a rise through it to the next)
        if pts.last().is_some_and(|&q| (q - p).abs() <= 1e-9) {
            continue;
        }
        if let [.., a, b] = pts[..]
            && (b - a) * (p - b) > 0.0
        {
            pts.pop();
        }
        pts.push(p);
    }
    let Some(&last) = pts.last() else {
        return false;
    };
    let alternate = pts
        .windows(2)
        .all(|w| (w[0] - u0_v).signum() * (w[1] - u0_v).signum() < 0.0);
    let shrinking = |above: bool| {
        let d: Vec<f64> = pts
            .iter()
            .filter(|&&p| (p > u0_v) == above)
            .map(|&p| (p - u0_v).abs())
            .collect();
        d.windows(2).all(|w| w[1] <= w[0] + 1e-9)
    };
    pts.len() >= 4
        && alternate
        && shrinking(true)
        && shrinking(false)
        && (last - u0_v).abs() <= CENTRED_LAST_SHARE * span_v
}

/// Share of the table's span within which a centred scan's last turning point lies from the
/// first input (our assumption: [`super::everett::start_candidates`]' scans end at 1 % of the
/// span, and the start search scales their excursions by up to [`super::start::START_SCALE`]).
const CENTRED_LAST_SHARE: f64 = 0.05;

/// How closely the table's levels at the first samples of several records must agree for
/// step 13a to read them as one sensor offset, volts of the table's output (our assumption: a
/// millivolt, about a noise floor of the records here).
const START_LEVELS_AGREE_V: f64 = 1e-3;

/// `model` with the level its table holds over its reversible map (`table_gain u`) at the
/// records' first sample moved into the sensor's `[offset]`, and that offset (volts), where the
/// start memory is a centred scan ([`centred_scan`]) at every record's first input and the
/// levels agree across records within [`START_LEVELS_AGREE_V`]. The reading moves per volt of
/// the table's level by [`reading_per_table_v`].
fn start_level_into_offset(
    model: &ModelFile,
    data: &[Data],
    table_gain: f64,
) -> Option<(ModelFile, f64)> {
    let h = model.hysteresis.as_ref()?;
    let [lo, hi] = h.input_range_v;
    let table = h.table().ok()?;
    let turns = h.start_turns_v.clone().unwrap_or_default();
    let history = h.start_history_v();
    let mut levels = Vec::new();
    for d in data {
        let &u0 = d.u_v.first()?;
        if !centred_scan(&turns, u0.clamp(lo, hi), hi - lo) {
            return None;
        }
        let mut mem = HysteresisMemory::new();
        mem.reset_after(&table, &history, u0 as f32);
        levels.push(table.forward(&mut mem, u0 as f32) as f64 - table_gain * u0);
    }
    let (min, max) = min_max(&levels);
    if levels.iter().any(|l| !l.is_finite()) || max - min > START_LEVELS_AGREE_V {
        return None;
    }
    let level_v = levels.iter().sum::<f64>() / levels.len() as f64;
    let per_v = reading_per_table_v(model)?;
    let mut moved = model.clone();
    moved.hysteresis.as_mut()?.offset_v -= level_v;
    let offset_v = moved.offset.as_ref().map_or(0.0, |o| o.offset_v) + level_v * per_v;
    moved.offset = Some(crate::io::model_file::OffsetSection { offset_v });
    Some((moved, offset_v))
}

/// Does no start memory but a centred scan explain the records: does the present model
/// (whose start is a centred scan, [`centred_scan`]) beat, by a start's worth of score (BIC,
/// [`start::START_PARAMS`]), every start candidate ([`super::everett::start_candidates`])
/// that is not one, each with the slow effects refitted on it? Step 13a reads the table's
/// level as the sensor's only then: a stage left off-centre (after excursions elsewhere, or
/// on its major curve) holds a level its relays the records never switch, which the convention
/// would name as a false offset (families cases 10116, 10103, 9088 and 9156: an off-centre
/// start, refitted, fitted as well or better than the centred one the search had kept).
/// Candidates that leave the table in the same state at every record's first input are
/// tried once, and none that leaves it as the present start does.
fn centred_start_told(
    model: &ModelFile,
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
    cur_mse: &[f64],
) -> bool {
    let range = slow_x.range();
    let span = range.1 - range.0;
    let form = slow_x.form();
    let Some(table) = model.hysteresis.as_ref().and_then(|h| h.table().ok()) else {
        return false;
    };
    let state_after = |hist: &[f32]| start::state_after(&table, data, hist);
    // (a rival that leaves the table as the present start does at every first input is the
    // present start to the records, and reads the same level: no rival)
    let now = model
        .hysteresis
        .as_ref()
        .map_or_else(Vec::new, |h| h.start_history_v());
    let mut seen = vec![state_after(&now)];
    let cands: Vec<Vec<f64>> = super::everett::start_candidates(data[0].u_v[0], range)
        .into_iter()
        .filter(|c| {
            let mem = super::everett::start_memory(range, form, c);
            if data
                .iter()
                .all(|d| centred_scan(&mem, d.u_v[0].clamp(range.0, range.1), span))
            {
                return false;
            }
            let hist: Vec<f32> = mem.iter().map(|&v| v as f32).collect();
            let state = state_after(&hist);
            let new = !seen.contains(&state);
            if new {
                seen.push(state);
            }
            new
        })
        .collect();
    let bar = start::start_worth(data);
    // The score of each rival against the present start: below the bar, the records do not
    // show the centred start (a rival that fails to refit is no rival). In chunks, the first
    // rival under the bar ends the search (each is a refit of the slow effects).
    let score = |c: &Vec<f64>| {
        let (_, m2) = start::refit_on_start(model, data, slow_x, u_range, c)?;
        let (_, ms) = super::data::simulate_all(&m2, data).ok()?;
        Some(start::log_likelihood_cost(data, &ms, cur_mse))
    };
    cands.chunks(RIVAL_CHUNK).all(|chunk| {
        par_map(chunk, score)
            .into_iter()
            .flatten()
            .all(|s| s >= bar)
    })
}

/// Rival starts refitted at once by [`centred_start_told`] before it looks for one under its
/// bar (our assumption: two per core on the two cores the suite is timed on).
const RIVAL_CHUNK: usize = 4;

/// Do two simulations read the same: every record's samples within
/// [`SAME_READING_FLOORS`] of its noise floor (`noise`, standard deviation) of each other,
/// plus `code_v` (one ADC code where the model reads through the ADC: a change far below a
/// code still moves a sample that sits on a code's edge to the next)?
fn same_readings(a: &[Vec<f64>], b: &[Vec<f64>], noise: &[f64], code_v: f64) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).zip(noise).all(|((a, b), floor)| {
            a.len() == b.len()
                && a.iter()
                    .zip(b)
                    .all(|(x, y)| (x - y).abs() <= SAME_READING_FLOORS * floor + code_v)
        })
}

/// One ADC code, volts, where `model` reads through the 16-bit ADC, else 0.
fn adc_code_v(model: &ModelFile) -> f64 {
    if model.converters.adc {
        f64::from(model_core::AdcCode::VOLT_PER_LSB)
    } else {
        0.0
    }
}

/// The joint step of a creep and a loop ([`CREEP_AND_LOOP`]): offered where the model has
/// neither, and the residual's holds show both a tail and a held levels' gap of
/// [`DRIFT_TAIL_MIN_NOISE`] and [`HYST_LOOP_MIN_NOISE`] noise floors, the gap at least
/// [`HELD_LOOP_OVER_TAIL`] times the tail.
fn creep_and_loop(
    model: &ModelFile,
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
    sigs: &signatures::Signatures,
) -> Option<Candidate> {
    let shown = tails_and_gap_shown(sigs) && sigs.held_loop_v >= HELD_LOOP_OVER_TAIL * sigs.tail_v;
    if !shown {
        return None;
    }
    Some(joint_candidate(
        &CREEP_AND_LOOP,
        creep_and_loop_fit(model, data, slow_x, u_range)?,
    ))
}

/// The creep and the loop fitted together beside `model`'s effects, where it has neither
/// (the fit both joint offers make, [`creep_and_loop`] and
/// [`creep_beside_loop_the_drift_cannot`]).
fn creep_and_loop_fit(
    model: &ModelFile,
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
) -> Option<Fitted> {
    if CREEP_AND_LOOP.iter().any(|e| catalogue::present(model, e)) {
        return None;
    }
    fit_slow_set(model, data, slow_x, &CREEP_AND_LOOP, u_range)
}

/// Do the holds show a creep's tails and a held levels' gap, each by the signatures' own bar
/// (the joint creep and loop's first gate, [`creep_and_loop`] and
/// [`creep_beside_loop_the_drift_cannot`])?
fn tails_and_gap_shown(sigs: &signatures::Signatures) -> bool {
    sigs.tail_v >= DRIFT_TAIL_MIN_NOISE * sigs.noise_v
        && sigs.held_loop_v >= HYST_LOOP_MIN_NOISE * sigs.noise_v
}

/// The joint creep and loop offered where [`creep_and_loop`]'s ratio of gap to tail held it
/// back but the drift, tried alone (`tried`: effect, refit, score, explained share), explained
/// less than [`MIN_EXPLAINED`] and the table alone scored lower with at least that share: the
/// gap is then not a creep that has not caught up (the drift's own form would take it). The
/// holds must still show the tails and the gap (the signatures' own bars).
fn creep_beside_loop_the_drift_cannot(
    model: &ModelFile,
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
    sigs: &signatures::Signatures,
    tried: &[(&str, bool, f64, f64)],
) -> Option<Candidate> {
    let shown = tails_and_gap_shown(sigs) && sigs.held_loop_v < HELD_LOOP_OVER_TAIL * sigs.tail_v;
    let alone = |e: &str| tried.iter().find(|t| t.0 == e && !t.1);
    let drift_none = alone("drift").is_some_and(|d| d.3 < MIN_EXPLAINED);
    let table_some = alone("hysteresis").is_some_and(|h| h.2 < 0.0 && h.3 >= MIN_EXPLAINED);
    if !(shown && drift_none && table_some) {
        return None;
    }
    let fitted = creep_and_loop_fit(model, data, slow_x, u_range)?;
    // (nor a static shape's beside a creep: a creep beside a scale, on random levels from a
    // random first level, left the drift alone nothing as well, and the table beside it took
    // the scale's part; the pair then led the steps to a false offset at 4.4x the floor,
    // families case 8232. The joint must leave less in every record than the drift fitted
    // with each static shape)
    let beside_shapes = par_map(&STATIC_SHAPES, |s| {
        fit_slow_set(model, data, slow_x, &["drift", s], u_range)
    });
    if beside_shapes
        .iter()
        .flatten()
        .any(|(_, _, ms)| !less_in_every_record(&fitted.2, ms))
    {
        return None;
    }
    Some(joint_candidate(&CREEP_AND_LOOP, fitted))
}

/// Candidates a step judged beside its own (each with its score, explained share and
/// whether it is admissible) added to the step's trace (`tried`), and the index of the best
/// admissible by the score.
fn traced_best(
    tried: &mut [Vec<(String, f64, f64, bool)>],
    judged: &[(Candidate, f64, f64, bool)],
) -> Option<usize> {
    if let Some(t) = tried.last_mut() {
        t.extend(
            judged
                .iter()
                .map(|(c, sc, ex, ok)| (c.effect.clone(), *sc, *ex, *ok)),
        );
    }
    judged
        .iter()
        .enumerate()
        .filter(|(_, x)| x.3)
        .min_by(|a, b| a.1.1.total_cmp(&b.1.1))
        .map(|(i, _)| i)
}

/// Effects fitted together as one step's candidate (`a+b`), its score counting the
/// parameters of each.
fn joint_candidate(effects: &[&str], (model, sims, mse): Fitted) -> Candidate {
    Candidate {
        effect: effects.join("+"),
        refit: false,
        model,
        k: effects.iter().map(|e| catalogue::param_count(e)).sum(),
        sims,
        mse,
    }
}

/// A creep and a loop, fitted as one step on held levels that show both.
const CREEP_AND_LOOP: [&str; 2] = ["drift", "hysteresis"];

/// A creep that counts from the records' first input, fitted as one step: the drift with
/// the offset that is its settled creep there taken back (step 12's reading, GAP.md step
/// 18). The model's lags start settled at each record's first input, so a stage whose creep
/// counts from that input (it came there just before the record: random levels that start at
/// a random level) reads the lags' settled creep less than the model at every sample, a
/// constant `-sum g_k K(u0) u0`. The drift alone cannot fit that: its gains pay the constant
/// at every sample and come out at zero (families case 3131, a power-law creep on random
/// levels from 8.5 V: the drift explained nothing at the first two steps, and a curvature, a
/// scale and a loop were named in its place at the floor). Fitted beside an offset, the
/// drift's gains are free of it, and the pair is offered only where the fitted offset is
/// that settled creep taken back ([`creep_start`], within its share): step 12 then moves it
/// into `[drift] unsettled_v` at the end. Only where no record starts at rest at 0 V (there
/// the two starts agree) and the holds show a creep's tails (the drift's own gate); the
/// pair's score counts both effects' parameters.
fn creep_from_first_input(
    model: &ModelFile,
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
    (sigs, noise): (&signatures::Signatures, &[f64]),
) -> Option<Candidate> {
    let shown = sigs.holds > 0 && sigs.tail_v >= DRIFT_TAIL_MIN_NOISE * sigs.noise_v;
    if !shown
        || CREEP_FROM_FIRST
            .iter()
            .any(|e| catalogue::present(model, e))
        || data.iter().any(|d| d.zero_rest_len().is_some())
    {
        return None;
    }
    // (the set fitted together, offered where its offset is the drift's start)
    let started = |set: &[&str]| -> Option<Candidate> {
        let fitted = fit_slow_set(model, data, slow_x, set, u_range)?;
        let named: Vec<String> = set.iter().map(|e| e.to_string()).collect();
        creep_start(&fitted.0, &named, data, noise)?;
        Some(joint_candidate(set, fitted))
    };
    if let Some(c) = started(&CREEP_FROM_FIRST) {
        return Some(c);
    }
    // Beside a scale error the pair's offset holds the scale's work as well and is not the
    // start (families case 3158, a log creep and a 1.1 % scale on random levels: -235 mV
    // against a settled creep of 202 mV, nothing named at 43x): the three fitted together,
    // offered where the offset is the start.
    if catalogue::present(model, "sensor-gain") {
        return None;
    }
    started(&CREEP_SCALE_FROM_FIRST)
}

/// The drift, the offset its start takes back and a scale error, fitted as one step.
const CREEP_SCALE_FROM_FIRST: [&str; 3] = ["drift", "offset", "sensor-gain"];

/// A swap's trial, `f` in the place of a named offset, fitted with the drift's start (step 18
/// for a swap; the caller asks it where the offset is not the drift's start by step 12's
/// test): where a drift is among the named slow effects `named_slow`, the slow effects of
/// `m0` (the model with the offset reverted) and `f` are fitted with an offset as well, and
/// where that offset is the settled creep at the records' first input taken back (step 12's
/// test, [`creep_start`]) it moves into `[drift] unsettled_v`. `None` where a record starts at
/// rest at 0 V (there the two starts agree), or where the offset is not the drift's start.
fn creep_counted_from_first(
    (m0, f): (&ModelFile, &str),
    named_slow: &[String],
    data: &[Data],
    (slow_x, u_range): (&SlowRegressors, (f64, f64)),
    noise: &[f64],
) -> Option<Fitted> {
    if !named_slow.iter().any(|n| n == "drift") || data.iter().any(|d| d.zero_rest_len().is_some())
    {
        return None;
    }
    let mut m = refit_slow(m0, &[f, "offset"], data, slow_x, u_range)?;
    // (the drift and the offset, as step 12 asks them named)
    let c = creep_start(&m, named_slow, data, noise)?;
    offset_into_drift_start(&mut m, &c)?;
    let (s, ms) = simulate_all(&m, data).ok()?;
    Some((m, s, ms))
}

/// Move `m`'s offset, which step 12's test `c` read as the drift's start, into
/// `[drift] unsettled_v` (the same readings); `None` without a drift.
fn offset_into_drift_start(m: &mut ModelFile, c: &CreepStart) -> Option<()> {
    m.drift.as_mut()?.unsettled_v = Some(c.offset_v);
    m.offset = None;
    Some(())
}

/// Did the trial `m` take a drift's start that `model` does not have
/// ([`creep_counted_from_first`])?
fn started_here(model: &ModelFile, m: &ModelFile) -> bool {
    let start = |m: &ModelFile| m.drift.as_ref().and_then(|d| d.unsettled_v);
    start(m).is_some() && start(m) != start(model)
}

/// The drift and the offset its start takes back, fitted as one step.
const CREEP_FROM_FIRST: [&str; 2] = ["drift", "offset"];

/// The pairs the issue names (#12 item 1): without holds, a drift lag and a hysteresis loop
/// both shape a slow periodic residual. Each is refitted in the other's place with the slow
/// effects (no start-memory search for the alternative: a tie is then a real one).
fn cannot_tell(
    model: &ModelFile,
    base: &ModelFile,
    named: &[String],
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
    cur_mse: &[f64],
) -> Vec<CannotTell> {
    if data.iter().any(Data::has_hold) {
        return Vec::new();
    }
    let pairs: Vec<(&str, &str)> = [("drift", "hysteresis"), ("hysteresis", "drift")]
        .into_iter()
        .filter(|(e, f)| named.iter().any(|n| n == e) && !named.iter().any(|n| n == f))
        .collect();
    pairs
        .into_iter()
        .filter_map(|(e, f)| {
            let m = catalogue::revert(model, base, e);
            // The alternative's slow set: a lag much longer than a
            // reversal's spacing is also a static scale, which a loop-only table leaves to
            // `sensor-gain`; a drift in a loop's place takes the loop's mean as well.
            let mut extra = vec![f];
            if f == "hysteresis" && !named.iter().any(|n| n == "sensor-gain") {
                extra.push("sensor-gain");
            }
            let m = refit_slow(&m, &extra, data, slow_x, u_range)?;
            let (_, ms) = simulate_all(&m, data).ok()?;
            let r2 = CANNOT_TELL_RATIO * CANNOT_TELL_RATIO;
            let near = ms.iter().zip(cur_mse).all(|(a, b)| *a <= r2 * *b);
            near.then(|| CannotTell {
                neither_named: false,
                taken_out: TakenOut::No,
                named: e.to_string(),
                alternative: f.to_string(),
                rms_v: rms_of(cur_mse),
                alternative_rms_v: rms_of(&ms),
                why: format!(
                    "no record holds its input for {HOLD_MIN_S} s, and {f} in place of {e} \
                     leaves {:.2} mV against {:.2} mV: record holds (the recommended \
                     protocol) to tell them apart",
                    1e3 * rms_of(&ms),
                    1e3 * rms_of(cur_mse)
                ),
            })
        })
        .collect()
}

/// The static shapes (not `named`) that could do the work of an offset the final check took
/// out as a level the records do not show: `m` the model without it, leaving the mean squares
/// `without`, and `with` what the model with it left. Each is fitted in the offset's place
/// beside `m`, and one that explains at least [`MIN_EXPLAINED`] of what is left (a step's
/// bar) is reported with the offset as a pair of which neither is named: the steps preferred
/// the offset by its score, and the final check found its work was not a level.
fn shapes_in_offsets_place(
    (m, without, with): (&ModelFile, &[f64], &[f64]),
    named: &[String],
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
    var: &[f64],
) -> Vec<CannotTell> {
    let every: Vec<usize> = (0..data.len()).collect();
    let share = |x: &[f64]| explained_share(without, x, var, &every);
    STATIC_SHAPES
        .iter()
        .filter(|s| **s != "offset" && !named.iter().any(|n| n == *s))
        .filter_map(|s| {
            let (_, _, s_mse) = fit_slow_set(m, data, slow_x, &[s], u_range)?;
            (share(&s_mse) >= MIN_EXPLAINED).then(|| CannotTell {
                named: s.to_string(),
                alternative: "offset".into(),
                neither_named: true,
                taken_out: TakenOut::InOffsetsPlace,
                rms_v: rms_of(&s_mse),
                alternative_rms_v: rms_of(with),
                why: format!(
                    "neither is named: beside the effects still named then, {s} fitted in the \
                     place of the offset the final check took out explains {:.0} % of what is \
                     left above the noise floor ({:.2} mV), the offset {:.0} % ({:.2} mV): the \
                     offset's work was a shape's, not a level's, and these records do not say \
                     which shape's; records at several held levels (the recommended protocol) \
                     tell a scale, an offset and a curvature apart",
                    100.0 * share(&s_mse),
                    1e3 * rms_of(&s_mse),
                    100.0 * share(with),
                    1e3 * rms_of(with)
                ),
            })
        })
        .collect()
}

/// The share of the residual power above the noise floor, over the records `set`, that a
/// model leaving the mean squares `after` explains of what one leaving `before` leaves (each
/// record's power above its noise variance `var`, none below it); 0 where `before` leaves
/// none. The steps' candidates and the look-alikes judged again after the final check are
/// weighed by it.
fn explained_share(before: &[f64], after: &[f64], var: &[f64], set: &[usize]) -> f64 {
    let above = |m: &[f64]| set.iter().map(|&i| (m[i] - var[i]).max(0.0)).sum::<f64>();
    let before = above(before);
    if before > 0.0 {
        1.0 - above(after) / before
    } else {
        0.0
    }
}

/// Do two fits explain alike: the second explains at least `1 / STATIC_TELL_RATIO` of what
/// the first explains (shares of the residual power above the floor, pooled over the records)
/// and leaves at most `STATIC_TELL_RATIO` times as much, and they leave alike in every record
/// ([`alike_in_every_record`]). `(explained share, per-record mean squares)` of each.
fn explain_alike(a: (f64, &[f64]), b: (f64, &[f64]), var: &[f64]) -> bool {
    b.0 * STATIC_TELL_RATIO >= a.0
        && (1.0 - b.0).max(1e-12) <= STATIC_TELL_RATIO * (1.0 - a.0).max(1e-12)
        && alike_in_every_record(a.1, b.1, var)
}

/// Do two fits leave alike in every record: the power above the noise floor each leaves
/// (plus one noise variance, below which a difference is noise) within [`STATIC_TELL_RATIO`]
/// of the other's? The records' pooled power is dominated by the record with the largest
/// residual; a record where one shape leaves clearly less tells the two apart however alike
/// the pool (the full thesis stage with a 24 mV sensor offset: `nonlinear-gain` and
/// `sensor-gain` explained 85 % and 83 % of the pool, and neither was named).
fn alike_in_every_record(a: &[f64], b: &[f64], var: &[f64]) -> bool {
    leave_within(a, b, var, STATIC_TELL_RATIO)
}

/// Does each of two fits leave, in every record, at most `ratio` times what the other leaves
/// above the noise floor (plus one noise variance)?
fn leave_within(a: &[f64], b: &[f64], var: &[f64], ratio: f64) -> bool {
    leaves_within_of(a, b, var, ratio) && leaves_within_of(b, a, var, ratio)
}

/// Does a fit leave, in every record, at most `ratio` times what another leaves above the
/// noise floor (plus one noise variance)? One-sided [`leave_within`]: a fit with fewer names
/// that leaves less is alike or better.
fn leaves_within_of(a: &[f64], b: &[f64], var: &[f64], ratio: f64) -> bool {
    (0..var.len()).all(|i| {
        let la = (a[i] - var[i]).max(0.0) + var[i];
        let lb = (b[i] - var[i]).max(0.0) + var[i];
        // (a fit that simulates to NaN leaves no less than anything)
        a[i].is_finite() && la <= ratio * lb
    })
}

/// The pairs tried where the steps could tell none of `drop` (static shapes that explain
/// alike) from the others: each shape among them with `offset` (a shape beside a level, the
/// offset among them or not), where the model has no offset yet. Not two shapes together: a
/// scale and a curvature make a free quadratic, which took up a loop's misfit on single
/// sines and put a `sensor-gain` the truth lacked in place of its offset (session 21).
fn static_pairs(drop: &[String], named: &[String], model: &ModelFile) -> Vec<(String, String)> {
    if named.iter().any(|n| n == "offset") || catalogue::present(model, "offset") {
        return Vec::new();
    }
    STATIC_SHAPES
        .iter()
        .filter(|s| **s != "offset" && drop.iter().any(|d| d == *s))
        .map(|s| (s.to_string(), "offset".to_string()))
        .collect()
}

/// `model` with the slow effects it has and `extra` fitted jointly (one round of the
/// structure search, as a step's candidates: [`refit_slow_rounds`]), simulated on every
/// record.
fn fit_slow_set(
    model: &ModelFile,
    data: &[Data],
    slow_x: &SlowRegressors,
    extra: &[&str],
    u_range: (f64, f64),
) -> Option<Fitted> {
    let m = refit_slow_rounds(model, extra, data, slow_x, u_range, CANDIDATE_ROUNDS)?;
    let (s, ms) = simulate_all(&m, data).ok()?;
    Some((m, s, ms))
}

/// Step 14 (a) and (c)'s search over K'(u)'s orders ([`scale_order::CURVATURE_ORDERS`], from
/// the cubic up): the first curvature `without(order)` (fitted in a scale's or an offset's
/// place) that leaves no more than the look-alike bar above the model's mean squares
/// `cur_mse` in any record, nor above its like-for-like rival's (the order below refitted
/// beside the shape, as many parameters: [`scale_order::refit_order`]; at the cubic, the
/// model as it stands), and that rival's mean squares. Above the cubic the records must show
/// something the model leaves ([`HIGHER_ORDER_SHOWN_VAR`] in some record), and the curvature
/// must tell: leave at most `1 / STATIC_TELL_RATIO` of what the model leaves above the floor
/// in every record (and [`LIKE_FOR_LIKE_SLACK_VAR`]). Near the floor the look-alike bar
/// cannot tell a true scale or offset from a curvature of enough orders (families guard
/// cases 1019, 1026, 1048 and 1077, true pairs at 1.1-1.7x the floor, lost their scale or
/// offset to the quartic and up by the bars alone; 2502, at 0.97x, its scale), while a shape
/// that stood in for a plateau's orders leaves the model clearly above what they leave
/// without it. `None` where no order does.
fn curvature_in_place_of(
    without: impl Fn(usize) -> Option<scale_order::CurvatureFit>,
    (model, named, data): (&ModelFile, &[String], &[Data]),
    cur_mse: &[f64],
    var: &[f64],
) -> Option<(scale_order::CurvatureFit, Vec<f64>)> {
    let lowest = scale_order::CUBIC;
    let excess = |mse: &[f64], i: usize| (mse[i] - var[i]).max(0.0) / var[i].max(f64::MIN_POSITIVE);
    let shown = higher_order_shown(cur_mse, var);
    for order in scale_order::CURVATURE_ORDERS {
        // (the orders above the cubic only where the records show what the model leaves)
        if order > lowest && !shown {
            break;
        }
        let Some(w) = without(order) else {
            continue;
        };
        let tells = (0..var.len()).all(|i| {
            excess(&w.mse, i) <= excess(cur_mse, i) / STATIC_TELL_RATIO + LIKE_FOR_LIKE_SLACK_VAR
        });
        if !leaves_within_of(&w.mse, cur_mse, var, STATIC_TELL_RATIO) || (order > lowest && !tells)
        {
            continue;
        }
        let rival = if order == lowest {
            cur_mse.to_vec()
        } else {
            match scale_order::refit_order(model, named, data, order - 1) {
                Some(r) => r.mse,
                None => continue,
            }
        };
        // (above the cubic, like for like with the power above the floor alone: the look-alike
        // bar's added noise variance lets a curvature of many orders stand for a true scale
        // that, beside the order below, leaves the records at their floor)
        let alike = if order == lowest {
            leaves_within_of(&w.mse, &rival, var, STATIC_TELL_RATIO)
        } else {
            (0..var.len()).all(|i| {
                (w.mse[i] - var[i]).max(0.0)
                    <= STATIC_TELL_RATIO * (rival[i] - var[i]).max(0.0)
                        + LIKE_FOR_LIKE_SLACK_VAR * var[i]
            })
        };
        if alike {
            return Some((w, rival));
        }
    }
    None
}

/// Do the records show what the model leaves, for K'(u) above the cubic (step 14) or above
/// the quadratic (step 14 (e)): some record [`HIGHER_ORDER_SHOWN_VAR`] noise variances or more
/// above its floor under the model (`cur_mse`, `var` per record)?
fn higher_order_shown(cur_mse: &[f64], var: &[f64]) -> bool {
    (0..var.len()).any(|i| {
        (cur_mse[i] - var[i]).max(0.0) / var[i].max(f64::MIN_POSITIVE) >= HIGHER_ORDER_SHOWN_VAR
    })
}

/// Step 14 (e): K'(u) refitted at the orders above the quadratic beside the named scale and
/// offset, stepping up from the model as it stands: an order is kept where it leaves less in
/// every record than the one kept before it (at first the quadratic), which leaves above the
/// floor in some record more by the final check's bar ([`PRUNE_RATIO`] and
/// [`PRUNE_PER_PARAM`] per added term); the last order kept is the answer. `None` where no order does, where the records show
/// nothing the model leaves ([`HIGHER_ORDER_SHOWN_VAR`]), or where `named` holds no
/// `nonlinear-gain` or a `hysteresis` (`refit_order`).
fn curvature_order(
    model: &ModelFile,
    named: &[String],
    data: &[Data],
    cur_mse: &[f64],
    var: &[f64],
) -> Option<scale_order::CurvatureFit> {
    if !higher_order_shown(cur_mse, var) || gain_order(model) != QUADRATIC {
        return None;
    }
    let orders: Vec<usize> = scale_order::CURVATURE_ORDERS.collect();
    let fits = par_map(&orders, |&o| {
        scale_order::refit_order(model, named, data, o)
    });
    let mut kept: Option<scale_order::CurvatureFit> = None;
    for w in fits.into_iter().flatten() {
        let (below, below_order) = match &kept {
            Some(k) => (k.mse.as_slice(), k.order),
            None => (cur_mse, QUADRATIC),
        };
        let bar = PRUNE_RATIO + PRUNE_PER_PARAM * (w.order - below_order) as f64;
        if less_in_every_record(&w.mse, below) && growth_above_floor(below, &w.mse, var) >= bar {
            kept = Some(w);
        }
    }
    kept
}

/// Step 14 (e)'s static shape beside K'(u) of its own order: of a `sensor-gain` and an
/// `offset` that `named` lacks, the one that, refitted with K'(u) at `model`'s order
/// (`refit_order`), leaves less in every record, and without which the residual above the
/// floor grows by at least the final check's bar (`prune_bar`), the larger growth first.
fn static_beside_order(
    model: &ModelFile,
    named: &[String],
    data: &[Data],
    (cur_mse, var): (&[f64], &[f64]),
) -> Option<(&'static str, scale_order::CurvatureFit)> {
    let order = gain_order(model);
    let shapes: Vec<&'static str> = ["sensor-gain", "offset"]
        .into_iter()
        .filter(|e| !named.iter().any(|n| n == e))
        .collect();
    let fits = par_map(&shapes, |&e| {
        let mut m = model.clone();
        match e {
            "sensor-gain" => {
                m.sensor_gain = Some(crate::io::model_file::SensorGainSection { gain: 1.0 });
            }
            _ => m.offset = Some(crate::io::model_file::OffsetSection { offset_v: 0.0 }),
        }
        let mut with: Vec<String> = named.to_vec();
        with.push(e.into());
        scale_order::refit_order(&m, &with, data, order)
    });
    shapes
        .into_iter()
        .zip(fits)
        .filter_map(|(e, f)| {
            let f = f?;
            let growth = growth_above_floor(cur_mse, &f.mse, var);
            (less_in_every_record(&f.mse, cur_mse) && growth >= prune_bar(&[e.to_string()]))
                .then_some((growth, e, f))
        })
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, e, f)| (e, f))
}

/// Step 14 (e)'s bookkeeping: the curvature of order `w.order` refits the named K'(u) (a
/// step saying so); the model, its simulations and mean squares.
fn take_curvature_order(
    w: scale_order::CurvatureFit,
    cur_mse: &[f64],
    steps: &mut Vec<Step>,
) -> (ModelFile, Vec<Vec<f64>>, Vec<f64>) {
    let why = format!(
        "a curvature of order {} (K'(u) to u^{}, its term {:.3e} per V^{}) beside the named \
         shapes leaves {:.2} mV against {:.2} mV with the quadratic; the added terms earn their \
         parameters by the final check's bar",
        w.order,
        w.order,
        w.top_term,
        w.order,
        1e3 * rms_of(&w.mse),
        1e3 * rms_of(cur_mse),
    );
    steps.push(Step {
        refit: true,
        params: params_json(&w.model, "nonlinear-gain"),
        ..Step::new(
            "nonlinear-gain".into(),
            why,
            cur_mse,
            &w.mse,
            w.sims.clone(),
        )
    });
    (w.model, w.sims, w.mse)
}

/// The catalogue's K'(u): a quadratic (`catalogue::with_slow_but`).
const QUADRATIC: usize = 2;

/// K'(u)'s order in `model` (its highest power with a term; 0 without a `[nonlinear-gain]`).
fn gain_order(model: &ModelFile) -> usize {
    model
        .nonlinear_gain
        .as_ref()
        .map_or(0, |g| g.poly.iter().rposition(|&c| c != 0.0).unwrap_or(0))
}

/// Noise variances by which a curvature above the cubic may leave more than its like-for-like
/// rival beside a scale or an offset (past [`STATIC_TELL_RATIO`] times the rival's power
/// above the floor) and still stand for the shape (step 14; our assumption: a tenth, seven
/// standard errors of a mean square over 10^4 samples of noise; families guard cases 1048 and
/// 1077, true scales that the order-6 curvature left 0.40-0.44 variances above what the
/// quintic beside the scale left at the floor, were lost under the look-alike bar's one
/// variance).
const LIKE_FOR_LIKE_SLACK_VAR: f64 = 0.1;

/// Noise variances of residual power above the floor some record must hold under the model
/// for step 14 to try K'(u) above the cubic (our assumption: a quarter, the residual at 1.12x
/// its floor; below it the records show nothing a curvature's form leaves out, and at the
/// floor a scale, an offset and the higher terms are alike: families case 2502, a true scale
/// beside a softplus at 0.97x the floor, lost its scale to the order-6 curvature).
const HIGHER_ORDER_SHOWN_VAR: f64 = 0.25;

/// Step 14 (a) and (c)'s bookkeeping: `removed` (a scale or an offset) gives way to the
/// curvature of higher order `w` (a step saying `why`, the pair `nonlinear-gain` / `removed`
/// reported in place of any pair that named `removed`, the name dropped); the model, its
/// simulations and mean squares to go on with.
fn curvature_takes_up(
    removed: &str,
    w: scale_order::CurvatureFit,
    why: String,
    cur_mse: &[f64],
    (steps, ambiguous, named): (&mut Vec<Step>, &mut Vec<CannotTell>, &mut Vec<String>),
) -> (ModelFile, Vec<Vec<f64>>, Vec<f64>) {
    steps.push(Step {
        removed: true,
        params: params_json(&w.model, "nonlinear-gain"),
        ..Step::new(removed.into(), why.clone(), cur_mse, &w.mse, w.sims.clone())
    });
    ambiguous.retain(|k| k.neither_named || k.named != removed);
    ambiguous.push(CannotTell {
        named: "nonlinear-gain".into(),
        alternative: removed.into(),
        neither_named: false,
        taken_out: TakenOut::No,
        rms_v: rms_of(&w.mse),
        alternative_rms_v: rms_of(cur_mse),
        why,
    });
    named.retain(|n| n != removed);
    (w.model, w.sims, w.mse)
}

/// Step 14 (b) and (d)'s bookkeeping: `into` (an offset or a scale, `w` beside the cubic,
/// `what` in words) takes the place of `out` (`v` beside the same cubic, like for like), a
/// step `into` saying so; where `out` leaves no more than the look-alike bar above `w` in
/// every record (`var`), the pair `into` / `out` is reported in place of any pair that
/// named `out`. The model, its simulations and mean squares to go on with.
fn like_for_like_swap(
    (out, into, what): (&str, &str, String),
    (w, v): (scale_order::CurvatureFit, &[f64]),
    (var, cur_mse): (&[f64], &[f64]),
    (steps, ambiguous, named): (&mut Vec<Step>, &mut Vec<CannotTell>, &mut Vec<String>),
) -> (ModelFile, Vec<Vec<f64>>, Vec<f64>) {
    let told = !leaves_within_of(v, &w.mse, var, STATIC_TELL_RATIO);
    let rival = if out == "offset" { "offset" } else { "scale" };
    let evidence = format!(
        "swapped in for {out}: beside a curvature of one more order (c3 = {:.3e} per V^3), \
         {what} leaves {:.2} mV against the {rival}'s {:.2} mV (refitted beside the same \
         curvature), less in every record{}",
        w.top_term,
        1e3 * rms_of(&w.mse),
        1e3 * rms_of(v),
        if told {
            ""
        } else {
            ", but by less than the look-alike bar: the records cannot tell the two; \
             records that start at rest at 0 V read the sensor's zero"
        }
    );
    let mut params = params_json(&w.model, into);
    params.extend(params_json(&w.model, "nonlinear-gain"));
    steps.push(Step {
        params,
        ..Step::new(
            into.into(),
            evidence.clone(),
            cur_mse,
            &w.mse,
            w.sims.clone(),
        )
    });
    ambiguous.retain(|k| k.neither_named || k.named != out);
    if !told {
        ambiguous.push(CannotTell {
            named: into.into(),
            alternative: out.into(),
            neither_named: false,
            taken_out: TakenOut::No,
            rms_v: rms_of(&w.mse),
            alternative_rms_v: rms_of(v),
            why: evidence,
        });
    }
    named.retain(|n| n != out);
    named.push(into.into());
    (w.model, w.sims, w.mse)
}

/// The opening words of the note a diagnosis gives where a table is named and the records
/// hold no reading of the sensor's zero (no rest at 0 V at a record's start, no input down to
/// the table's low end): a sensor offset is then not told from the table's constant. A note
/// on the protocol, given whatever the records' residual (tests and tallies tell it from the
/// notes a step's evidence gives by these words).
pub const STANDING_OFFSET_NOTE: &str =
    "no record starts at rest at 0 V input or goes down to the bottom of the table's range";

/// The closing words of the notes on an offset the records cannot tell from the table's
/// constant (the standing note and step 13): what records would tell them.
const ZERO_READING_TELLS: &str = "a rest at 0 V at a record's start (the recommended \
     protocol), or records that go down to the bottom of the range, tell a sensor offset from it";

/// The static shapes of the sensor and the gain: a scale, an offset and a curvature of the
/// output, which one sine or chirp beside a hysteresis loop can leave nearly collinear.
const STATIC_SHAPES: [&str; 3] = ["offset", "sensor-gain", "nonlinear-gain"];

/// A pruning trial: effect, model without it, its simulations and mean squares.
type Trial = (Vec<String>, ModelFile, Vec<Vec<f64>>, Vec<f64>);

/// A static shape in a named one's place (step 15): the shape, the model, its simulations
/// and mean squares.
type ShapeFit = (&'static str, ModelFile, Vec<Vec<f64>>, Vec<f64>);

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

/// The correlation of a record's output `y` with the model's simulated output `sim`, where
/// it is below `-REVERSED_CORRELATION` and the simulation moves more than
/// `REVERSED_MIN_FLOORS` noise floors (`floor_v`, standard deviation): a record whose sensor's
/// sign is reversed. `None` otherwise.
fn moves_against(y: &[f64], sim: &[f64], floor_v: f64) -> Option<f64> {
    let m = LineFit::of(y, sim)?;
    (m.sd_x > REVERSED_MIN_FLOORS * floor_v && m.correlation < -REVERSED_CORRELATION)
        .then_some(m.correlation)
}

/// How many times as far a record's output `y` moves as the model's simulated output `sim`
/// (the magnitude of the slope of `y` on `sim`, which a drift or an offset the model lacks
/// leaves near 1), where that is beyond `SCALE_APART_MAX` either way and the simulation moves
/// more than `REVERSED_MIN_FLOORS` of the record's floors (`floor_v`, in the record's units,
/// brought to the model's by the slope): a record in other units. `None` otherwise.
fn scale_apart(y: &[f64], sim: &[f64], floor_v: f64) -> Option<f64> {
    let m = LineFit::of(y, sim)?;
    let k = m.slope.abs();
    (m.sd_x * k.max(1e-300) > REVERSED_MIN_FLOORS * floor_v
        && !(1.0 / SCALE_APART_MAX..=SCALE_APART_MAX).contains(&k))
    .then_some(k)
}

/// The correlation of a record's output `y` with the model's simulated output `sim`, where
/// it is within `FOLLOW_MIN_CORRELATION` of zero while the simulation moves more than
/// `REVERSED_MIN_FLOORS` noise floors: a record whose output does not follow its input (a
/// disconnected sensor, another signal's column): the fit that says so. `None` otherwise.
fn not_following(y: &[f64], sim: &[f64], floor_v: f64) -> Option<LineFit> {
    let m = LineFit::of(y, sim)?;
    (m.sd_x > REVERSED_MIN_FLOORS * floor_v && m.correlation.abs() < FOLLOW_MIN_CORRELATION)
        .then_some(m)
}

/// Samples at an extreme that [`clipped`] and [`flattened`] need in a record of `n`:
/// `CLIP_MIN_SAMPLES`, or `CLIP_MIN_SHARE` of the record where that is more.
fn clip_need(n: usize) -> usize {
    CLIP_MIN_SAMPLES.max((CLIP_MIN_SHARE * n as f64).ceil() as usize)
}

/// A record's output clipped by its sensor or logger: the extreme value (volts) its output
/// reads exactly at `CLIP_MIN_SAMPLES` samples or more (`CLIP_MIN_SHARE` of the record where
/// that is more), how many, and how far past it the record's own line on the model's output
/// (`y = a + b sim`, fitted over the record) goes over them: more than `REVERSED_MIN_FLOORS`
/// noise floors `floor_v` (the model says the output went on where the record stands). A
/// coarse converter's one code at a sine's top, or an output that lags the model there (a
/// loop), keeps the line within a code or two of the level. `None` otherwise.
fn clipped(y: &[f64], sim: &[f64], floor_v: f64) -> Option<(f64, usize, f64)> {
    let n = y.len().min(sim.len());
    let need = clip_need(n);
    let m = LineFit::of(&y[..n], &sim[..n])?;
    let (lo, hi) = min_max(&y[..n]);
    [(hi, 1.0), (lo, -1.0)]
        .into_iter()
        .find_map(|(level, sign)| {
            let at: Vec<usize> = (0..n).filter(|&i| y[i] == level).collect();
            let past = at
                .iter()
                .map(|&i| sign * (m.at(sim[i]) - level))
                .fold(f64::NEG_INFINITY, f64::max);
            (at.len() >= need && past > REVERSED_MIN_FLOORS * floor_v).then_some((
                level,
                at.len(),
                past,
            ))
        })
}

/// A record's output flattened at an extreme under noise (a sensor whose electronics
/// saturated before the converter, read with the converter's own noise, so that no two
/// readings need be equal and [`clipped`] sees nothing): the level its top (or bottom)
/// `CLIP_MIN_SAMPLES` samples (`CLIP_MIN_SHARE` of the record where that is more) reach, the
/// samples within `CLIP_BAND_FLOORS` noise floors `floor_v` of it at which the record's own
/// line on the model's output goes past the record by `CLIP_SPAN_SHARE` of the line's span
/// over the whole record or more (and `REVERSED_MIN_FLOORS` floors), where there are
/// `CLIP_MIN_SAMPLES` of them and the line goes on towards the extreme by as much within
/// one unbroken run of them, as the input does (the model says the output went on, as the
/// input did, where the record stood still: the line's move counts no further than the
/// input's own over the same samples, at the line's span per volt of the input's over the
/// record; families case 10264, random levels beside a loop, was refused on the ringing of
/// the line after a step down to a held level, the input still), and how far past the line
/// goes there at most. A sine's crest or a
/// step's overshoot keeps the line with the record (a loop's branches meet at the top), a
/// held level the model misses keeps it still, and a loop's reading stays put only after a
/// reversal, while the line moves back from the extreme (families seeds 3100-3699: two
/// random-levels records whose extreme level a loop held flat after a reversal, 190-270 mV
/// from the line, were refused while the line's movement was taken either way), so none is
/// taken for one;
/// nor is a record whose input `u` comes near the amplifier's limits, where its saturation,
/// an effect of the catalogue, flattens the output the same way. `None` otherwise.
fn flattened(u: &[f64], y: &[f64], sim: &[f64], floor_v: f64) -> Option<(f64, usize, f64)> {
    let n = y.len().min(sim.len()).min(u.len());
    let need = clip_need(n);
    if n < 2 * need || floor_v.is_nan() || floor_v <= 0.0 || signatures::near_amp_limits(min_max(u))
    {
        return None;
    }
    let m = LineFit::of(&y[..n], &sim[..n])?;
    let line: Vec<f64> = sim[..n].iter().map(|s| m.at(*s)).collect();
    let (line_lo, line_hi) = min_max(&line);
    let bar = (CLIP_SPAN_SHARE * (line_hi - line_lo)).max(REVERSED_MIN_FLOORS * floor_v);
    let (u_lo, u_hi) = min_max(&u[..n]);
    let per_input_v = (line_hi - line_lo) / (u_hi - u_lo).max(f64::EPSILON);
    let mut sorted: Vec<f64> = y[..n].to_vec();
    sorted.sort_by(f64::total_cmp);
    [(sorted[n - need], 1.0), (sorted[need - 1], -1.0)]
        .into_iter()
        .find_map(|(level, sign)| {
            // (the samples at the level where the line goes on past the record by the bar)
            let at: Vec<usize> = (0..n)
                .filter(|&i| {
                    sign * (y[i] - level) >= -CLIP_BAND_FLOORS * floor_v
                        && sign * (line[i] - y[i]) >= bar
                })
                .collect();
            // (and goes on towards the extreme by the bar within one unbroken run of them, as
            // the input does: a held level the model misses keeps the line still, a loop's
            // reading stays put only after a reversal, the line moving back, and the line
            // rings after a step while the input holds)
            let mut moves = 0.0f64;
            let mut least = (f64::INFINITY, 0usize);
            for (k, &i) in at.iter().enumerate() {
                if k > 0 && i != at[k - 1] + 1 {
                    least = (f64::INFINITY, i);
                }
                if sign * line[i] < least.0 {
                    least = (sign * line[i], i);
                }
                let input_move_v = (sign * (u[i] - u[least.1])).max(0.0) * per_input_v;
                moves = moves.max((sign * line[i] - least.0).min(input_move_v));
            }
            (at.len() >= need && moves >= bar).then(|| {
                let most = at
                    .iter()
                    .map(|&i| sign * (line[i] - y[i]))
                    .fold(f64::NEG_INFINITY, f64::max);
                (level, at.len(), most)
            })
        })
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
    let (ulo, uhi) = data.iter().fold((0.0f64, 0.0f64), |(a, b), d| {
        let (l, h) = min_max(&d.u_v);
        (a.min(l), b.max(h))
    });
    let u_range = (ulo.max(-20.0), uhi.min(20.0).max(ulo + 1.0));

    let base_sims: Vec<Vec<f64>> = par_map(data, |d| sim(base, d))
        .into_iter()
        .collect::<anyhow::Result<_>>()?;
    let floors: Vec<NoiseFloor> = data
        .iter()
        .zip(&base_sims)
        .map(|(d, s)| noise_floor_of(d, Some(s)))
        .collect();
    let noise: Vec<f64> = floors.iter().map(|f| f.sigma_v).collect();
    let mut noise_notes: Vec<String> = floors
        .iter()
        .zip(data)
        .filter_map(|(f, d)| f.note(&d.name))
        .collect();
    for (d, f) in data.iter().zip(&floors) {
        if let Some(u_noise_v) = swapped_columns(d, f) {
            bail!(
                "record {}: its input column is noisy ({:.3} mV from sample to sample) and its \
                 output column is not (nothing above its rounding, {:.3} mV): a sensor's reading \
                 in the input's column and a command in the output's. Are u and y in each \
                 other's columns? (--vars t=NAME,u=NAME,y=NAME names them)",
                d.name,
                1e3 * u_noise_v,
                1e3 * f.sigma_v
            );
        }
    }
    // (a measured input's noise, which the model fed it carries into the residual and the
    // output does not show, is part of the floor: `input_noise`)
    // (the refusals below judge the output on its own floor: a raised one would make them
    // less keen)
    let output_noise = noise.clone();
    let noise: Vec<f64> = par_map(&(0..data.len()).collect::<Vec<_>>(), |&i| {
        input_noise::measured_input_noise(base, &data[i], &base_sims[i], &floors[i])
    })
    .into_iter()
    .zip(data)
    .zip(noise)
    .map(|((m, d), f)| match m {
        Some(m) => {
            noise_notes.push(m.note(&d.name));
            m.floor_v
        }
        None => f,
    })
    .collect();
    let var: Vec<f64> = noise.iter().map(|s| (s * s).max(MSE_MIN_V2)).collect();
    let noise_floor_v = (var.iter().sum::<f64>() / var.len() as f64).sqrt();
    // (a record clipped by its sensor or logger is refused on its own samples: the cleaning
    // below moves them)
    for ((d, s), f) in data.iter().zip(&base_sims).zip(&output_noise) {
        if let Some((level, count, past_v)) = clipped(&d.y_v, s, *f) {
            bail!(
                "record {}: its output reads exactly {level:.4} V at {count} samples ({:.1} % \
                 of the record), where the model's output, scaled to the record, goes {:.1} mV \
                 past it: the sensor or the logger clipped at its range. The workflow fits the \
                 stage, not a clipped recording: record within the range, or leave the clipped \
                 part out",
                d.name,
                100.0 * count as f64 / d.len() as f64,
                1e3 * past_v
            );
        }
        if let Some((level, count, past_v)) = flattened(&d.u_v, &d.y_v, s, *f) {
            bail!(
                "record {}: its output stays within {:.1} mV of {level:.4} V at {count} samples \
                 ({:.1} % of the record) where the model's output, scaled to the record, goes \
                 on, up to {:.1} mV past the reading: the sensor or its electronics saturated. The \
                 workflow fits the stage, not a saturated reading: record within the sensor's \
                 range, or leave the saturated part out",
                d.name,
                1e3 * CLIP_BAND_FLOORS * f,
                100.0 * count as f64 / d.len() as f64,
                1e3 * past_v
            );
        }
    }
    // (what the recording adds is taken out before anything is judged or fitted, and said
    // with the floors: first the mains' interference, a standing line, then the glitches,
    // on the residual without it, whose bursts are judged against the straight line through
    // twenty neighbours that a 50 Hz line bends; where both are found, the lines are fitted
    // again on the record without the glitches, which move a line's fit)
    let mut hum = Vec::new();
    let mut glitches = Vec::new();
    let cleaned: Vec<Data> = data
        .iter()
        .zip(&noise)
        .zip(&base_sims)
        .map(|((d, &f), s)| {
            let mut lines = mains::mains_lines(d, f, s);
            let mut quiet = mains::subtract(d, &lines);
            let (mut c, mut found, mut note) = without_glitches(&quiet, f, Some(s));
            if !lines.is_empty() && !found.is_empty() {
                // (a glitch of 0.7 V moves a 50 Hz line's fit over 10 s at 1 kHz by 0.3 mV:
                // the lines are fitted again on the record with its glitches replaced, the
                // hum put back on them)
                let without: Vec<(usize, f64)> = found
                    .iter()
                    .map(|&(i, v)| (i, v + d.y_v[i] - quiet.y_v[i]))
                    .collect();
                lines = mains::mains_lines(&d.with_samples_replaced(&without), f, s);
                quiet = mains::subtract(d, &lines);
                (c, found, note) = without_glitches(&quiet, f, Some(s));
            }
            noise_notes.extend(mains::note(&d.name, &lines, f));
            noise_notes.extend(note);
            hum.push(lines);
            glitches.push(found);
            c
        })
        .collect();
    let data: &[Data] = &cleaned;
    for ((d, s), f) in data.iter().zip(&base_sims).zip(&output_noise) {
        if let Some(m) = not_following(&d.y_v, s, *f) {
            bail!(
                "record {}: its output does not follow the model's (correlation {:.2} between \
                 the record's y and the model's simulated output, which moves {:.1} mV): is the \
                 sensor connected, and is y its column? The workflow names small departures \
                 from the model",
                d.name,
                m.correlation,
                1e3 * m.sd_x
            );
        }
        if let Some(c) = moves_against(&d.y_v, s, *f) {
            bail!(
                "record {}: its output moves against the model's (correlation {c:.2} between the \
                 record's y and the model's simulated output): is the sensor's sign reversed, or \
                 are u and y in each other's columns? The workflow names small departures from \
                 the model, not a reversed sign",
                d.name
            );
        }
        if let Some(k) = scale_apart(&d.y_v, s, *f) {
            let (ylo, yhi) = min_max(&d.y_v);
            let (slo, shi) = min_max(s);
            // (a lab that logs the amplifier's monitor, 10x its input, as u: the input then
            // spans beyond what the amplifier accepts, which the words say)
            let (ulo, uhi) = min_max(&d.u_v);
            let input = if ulo < model_core::params::AMP_INPUT_MIN_V
                || uhi > model_core::params::AMP_INPUT_MAX_V
            {
                format!(
                    " Its input u spans {ulo:.2} to {uhi:.2} V, beyond the amplifier's input \
                     range ({} to {} V): is u the amplifier's output (its input times the \
                     gain) or in other units?",
                    model_core::params::AMP_INPUT_MIN_V,
                    model_core::params::AMP_INPUT_MAX_V
                )
            } else {
                String::new()
            };
            bail!(
                "record {}: its output moves {} times as far as the model's (the slope of y on \
                 the model's simulated output; y spans {:.4} to {:.4} V, the model's output \
                 {:.4} to {:.4} V): is y in other units (mV, um, nm), or is the model not this \
                 stage's?{input} The workflow names small departures from the model; a scale \
                 error within {SCALE_APART_MAX}x is its `sensor-gain`",
                d.name,
                if k >= 1.0 {
                    format!("{k:.3}")
                } else {
                    format!("{k:.3e}")
                },
                ylo,
                yhi,
                slo,
                shi
            );
        }
    }
    let base_sigs = signatures::compute(data, &base_sims, &noise);
    let rows = solve_rows(data, base, &noise)?;
    let slow_x = slow_regressors(data, rows, &[], base.plant.static_gain, CentreLine::Band)
        .holding(base, data, u_range);
    let (kept_x, other_x, centre_line) = choose_centre_line(base, data, slow_x, &var, u_range);
    let setup = Setup {
        base,
        data,
        bar: bar.as_ref(),
        noise,
        noise_notes,
        glitches,
        hum,
        var,
        noise_floor_v,
        u_range,
        base_sims,
        base_sigs,
    };
    let first = diagnose_split(&setup, kept_x, centre_line.clone())?;
    // Hysteresis and drift alone left the two splits within CANNOT_TELL_RATIO (RMS) of each
    // other: the records cannot choose the split by the loop alone. When the first diagnosis
    // names hysteresis (else the split is no part of its model) and does not end at the
    // floor, the other split's runs too, and `fewer_names` keeps one.
    let (kept, other) = centre_line.kept_and_other();
    let close = other < CANNOT_TELL_RATIO * CANNOT_TELL_RATIO * kept;
    let d = if close
        && first.named.iter().any(|e| e == "hysteresis")
        && !at_floor_now(&first.final_mse(), &setup.var)
    {
        let rival = CentreChoice {
            chosen: other_x.form(),
            ..centre_line
        };
        if let Some(b) = &bar {
            b.set_message("the other split of the hysteresis basis");
        }
        // (a failure of the second diagnosis leaves the first as it was)
        match diagnose_split(&setup, other_x, rival) {
            Ok(second) => fewer_names(&setup.var, first, second),
            Err(_) => first,
        }
    } else {
        first
    };
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    Ok(d)
}

/// What the diagnoses of either split share: the records, their floors, the base model's
/// simulations.
struct Setup<'a> {
    base: &'a ModelFile,
    data: &'a [Data],
    bar: Option<&'a indicatif::ProgressBar>,
    noise: Vec<f64>,
    noise_notes: Vec<String>,
    glitches: Vec<Vec<(usize, f64)>>,
    hum: Vec<Vec<HumLine>>,
    var: Vec<f64>,
    noise_floor_v: f64,
    u_range: (f64, f64),
    base_sims: Vec<Vec<f64>>,
    base_sigs: signatures::Signatures,
}

/// The workflow's steps (module doc, 4-7) from the base model with the hysteresis basis
/// `slow_x` of the split `centre_line` chose.
fn diagnose_split(
    setup: &Setup,
    mut slow_x: SlowRegressors,
    centre_line: CentreChoice,
) -> anyhow::Result<Diagnosis> {
    let &Setup {
        base,
        data,
        bar,
        noise_floor_v,
        u_range,
        ref base_sims,
        ref base_sigs,
        ..
    } = setup;
    let (noise, var) = (setup.noise.clone(), setup.var.clone());
    if let Some(b) = bar {
        b.set_position(0);
    }
    let mut model = base.clone();
    let mut sims = base_sims.clone();
    let mut cur_mse: Vec<f64> = data
        .iter()
        .zip(&sims)
        .map(|(d, s)| mse(&d.y_v, s))
        .collect();
    let mut steps: Vec<Step> = Vec::new();
    let mut named: Vec<String> = Vec::new();
    let mut tried: Vec<Vec<(String, f64, f64, bool)>> = Vec::new();
    let mut not_searched: Vec<Vec<(String, String)>> = Vec::new();
    let mut ambiguous: Vec<CannotTell> = Vec::new();
    // The look-alike pairs of static shapes a step left unnamed, with the effects named
    // before that step (the model they were compared beside).
    let mut look_alikes: Vec<(String, String, Vec<String>)> = Vec::new();
    let any_hold = data.iter().any(Data::has_hold);
    // The first table the memoryless twin kept out (steps 16 and 16a): (the share the table
    // explained, the twin's, the RMS each left), for the pair said at the end where the
    // records keep an unexplained part.
    let mut twin_untold: Option<(f64, f64, f64, f64)> = None;

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
        let (mut cands, unsearched) = candidates(
            &model,
            data,
            &slow_x,
            (&cur_mse, &var),
            u_range,
            &sigs,
            &named,
        )?;
        // Holds that show tails and levels apart by the step's direction: a creep and a loop
        // together, the pair every piezo stage has. The loop alone is not admitted beside
        // tails (a creep that has not caught up leaves levels apart too), and the drift
        // alone can explain nothing while the loop's gap dominates the holds (a Preisach
        // loop beside a power creep on random levels: nothing named, 122x the floor), so
        // the two are also fitted together as one step (the final check then weighs each).
        if let Some(c) = creep_and_loop(&model, data, &slow_x, u_range, &sigs) {
            cands.push(c);
        }
        if let Some(c) = creep_from_first_input(&model, data, &slow_x, u_range, (&sigs, &noise)) {
            cands.push(c);
        }
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
        // A candidate's score (BIC against the current model over the records `set`), the
        // share of the residual power above the floor it explains, and whether it leaves every
        // record's excess within 3x of the current one.
        let judge = |c: &Candidate, set: &[usize]| -> (f64, f64, bool) {
            let n_set: usize = set.iter().map(|&i| data[i].len()).sum();
            let score = start::log_likelihood_cost_over(data, &c.mse, &cur_mse, set)
                + c.k as f64 * (n_set as f64).ln();
            let explained = explained_share(&cur_mse, &c.mse, &var, set);
            let harmless = (0..data.len()).all(|i| {
                let before = (cur_mse[i] - var[i]).max(0.0);
                let after = (c.mse[i] - var[i]).max(0.0);
                after <= 3.0 * before + var[i]
            });
            (score, explained, harmless)
        };
        // Static shapes fitted jointly with an offset (`static_pairs`), judged as a step's
        // candidates (admissible: a lower score, the share explained, no record harmed); the
        // callers add their own bars.
        let judge_pairs = |pairs: &[(String, String)]| -> Vec<(Candidate, f64, f64, bool)> {
            let fitted = par_map(pairs, |(a, b)| {
                fit_slow_set(&model, data, &slow_x, &[a.as_str(), b.as_str()], u_range)
            });
            pairs
                .iter()
                .zip(fitted)
                .filter_map(|((a, b), f)| {
                    let (m, sims, mse_v) = f?;
                    let c = Candidate {
                        effect: format!("{a}+{b}"),
                        refit: false,
                        model: m,
                        k: catalogue::param_count(a) + catalogue::param_count(b),
                        sims,
                        mse: mse_v,
                    };
                    let (score, explained, harmless) = judge(&c, &all_set);
                    let ok = score < 0.0
                        && explained >= MIN_EXPLAINED
                        && harmless
                        && catalogue::implausible(&c.model, &model, data).is_none();
                    Some((c, score, explained, ok))
                })
                .collect()
        };
        let mut scored = Vec::new();
        // Candidates fitted to a value no stage or sensor could have (`catalogue::implausible`)
        // that would otherwise have been admitted, and why, for the trace.
        let mut unsearched_too: Vec<(String, String)> = Vec::new();
        // The look-alikes a pair step stands for (`static_pairs`).
        let mut pair_note: Option<Vec<String>> = None;
        // (step 16: the memoryless twin of an admissible new table, for the trace)
        let mut twin_tried: Option<(String, f64, f64, bool)> = None;
        for c in cands {
            let set = if FAST.contains(&c.effect.as_str()) {
                &fast_set
            } else {
                &all_set
            };
            let (score, explained, harmless) = judge(&c, set);
            let sig_ok = c.effect.split('+').all(|e| sigs.supports(e, &c.model));
            // (a value no stage or sensor could have is a misfit of another form, whatever it
            // explains: said in the trace)
            let implausible = catalogue::implausible(&c.model, &model, data);
            let admissible =
                score < 0.0 && explained >= MIN_EXPLAINED && harmless && implausible.is_none();
            if let Some(why) = implausible
                && score < 0.0
                && explained >= MIN_EXPLAINED
            {
                unsearched_too.push((c.effect.clone(), why));
            }
            let mut ok = admissible && sig_ok;
            // Steps 16 and 16a: a table is memory, and the memoryless twin (the best map of
            // the input alone, `memory`) reads its gate. Step 16: where the signatures show a
            // loop, it is read again on the twin's residual, where a loop a static misfit drew
            // through the dynamics is gone. Step 16a: where the held levels cannot tell a loop
            // from a static shape (the direction into each hold follows from its level), no
            // record answered otherwise and the holds show no creep's tails, the twin asks the
            // records instead: a table that leaves UNTOLD_TWIN_RATIO times less above the floor
            // than the twin, where the twin leaves UNTOLD_TWIN_LEFT_MIN of it or more, shows
            // memory the static shapes cannot take (families case 2548: a Bouc-Wen loop on
            // random levels, every step up above 5 V and every step down below it, named
            // `nonlinear-gain` at 144x the floor).
            let untold = !sig_ok
                && sigs.held_loop_untold
                && !sigs.loop_answered
                && sigs.tail_v < DRIFT_TAIL_MIN_NOISE * sigs.noise_v;
            if admissible
                && (sig_ok || untold)
                && c.effect == "hysteresis"
                && !c.refit
                && let Some((t_sims, t_mse)) = memory::twin(
                    &model,
                    data,
                    &sims,
                    slow_x.fit_input(),
                    slow_x.range(),
                    slow_x.table_gain(),
                )
            {
                let twin = Candidate {
                    effect: memory::TWIN_NAME.into(),
                    refit: false,
                    model: model.clone(),
                    k: 0,
                    sims: Vec::new(),
                    mse: t_mse,
                };
                let (t_score, t_explained, _) = judge(&twin, set);
                let shown = if sig_ok {
                    signatures::compute(data, &t_sims, &noise).supports("hysteresis", &c.model)
                } else {
                    let (t_left, left) = (1.0 - t_explained, 1.0 - explained);
                    t_left >= UNTOLD_TWIN_LEFT_MIN && t_left >= UNTOLD_TWIN_RATIO * left
                };
                if !shown && twin_untold.is_none() {
                    twin_untold = Some((explained, t_explained, rms_of(&c.mse), rms_of(&twin.mse)));
                }
                twin_tried = Some((twin.effect, t_score, t_explained, shown));
                ok = shown;
            }
            scored.push((c, score, explained, ok));
        }
        // The joint creep and loop where the drift alone explains nothing: the held levels'
        // gap beside tails is no loop's evidence where a creep that has not caught up could
        // leave it (`HELD_LOOP_OVER_TAIL`), but such a creep is the drift's own form, and the
        // drift alone then takes the gap. Where the drift alone explains less than
        // `MIN_EXPLAINED` of what is above the floor while the table alone passes every bar
        // but the signature's, the gap is not a lag's, and the pair is offered as one step
        // (families case 9001: a Preisach loop beside a power creep on random levels, tails
        // of 86 mV against a 11 mV gap, the drift 0 %, the table 94 %: nothing named, 120x
        // the floor).
        if let Some(c) = creep_beside_loop_the_drift_cannot(
            &model,
            data,
            &slow_x,
            u_range,
            &sigs,
            &scored
                .iter()
                .map(|(c, s, e, _)| (c.effect.as_str(), c.refit, *s, *e))
                .collect::<Vec<_>>(),
        ) {
            let (score, explained, harmless) = judge(&c, &all_set);
            let sig_ok = c.effect.split('+').all(|e| sigs.supports(e, &c.model));
            let ok = score < 0.0 && explained >= MIN_EXPLAINED && harmless && sig_ok;
            scored.push((c, score, explained, ok));
        }
        tried.push(
            scored
                .iter()
                .map(|(c, s, e, ok)| (c.effect.clone(), *s, *e, *ok))
                .chain(twin_tried)
                .collect(),
        );
        not_searched.push(
            unsearched
                .iter()
                .map(|(e, why)| (e.to_string(), why.to_string()))
                .chain(unsearched_too)
                .collect(),
        );
        // Without a hold in any record, a drift's only evidence is a slow residual under the
        // moving input, and its lags longer than the reversals' spacing act as a constant and
        // a scale: where a static shape (which needs no hold to show) explains alike, the
        // drift gives way to it and the pair is reported (issue #12 item 1: say so, do not
        // guess).
        if !any_hold {
            let best = scored
                .iter()
                .filter(|x| x.3)
                .min_by(|a, b| a.1.total_cmp(&b.1));
            if let Some((d, _, d_ex, _)) = best
                && d.effect == "drift"
                && !d.refit
            {
                let d_rms = rms_of(&d.mse);
                // (alike: pooled, or near the floor in every record, where the pooled shares
                // left are both noise and their ratio says nothing: a shape that leaves no
                // more than `STATIC_TELL_RATIO` times the drift's power above the floor, plus
                // one noise variance, in any record does the drift's work; families case
                // 10292, a 0.75 % scale beside a Bouc-Wen loop on one long sine, named a
                // drift that left 1.01 mV where the scale left 1.02 mV, over a 1.01 mV floor)
                let rival = scored
                    .iter()
                    .filter(|x| {
                        x.3 && !x.0.refit
                            && STATIC_SHAPES.contains(&x.0.effect.as_str())
                            && x.2 * STATIC_TELL_RATIO >= *d_ex
                            && ((1.0 - x.2).max(1e-12)
                                <= STATIC_TELL_RATIO * (1.0 - d_ex).max(1e-12)
                                || leaves_within_of(&x.0.mse, &d.mse, &var, STATIC_TELL_RATIO))
                    })
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .map(|x| (x.0.effect.clone(), x.2, rms_of(&x.0.mse)));
                if let Some((r, r_ex, r_rms)) = rival {
                    if !ambiguous
                        .iter()
                        .any(|c: &CannotTell| c.named == r && c.alternative == "drift")
                    {
                        ambiguous.push(CannotTell {
                            named: r.clone(),
                            alternative: "drift".into(),
                            neither_named: false,
                            taken_out: TakenOut::No,
                            rms_v: r_rms,
                            alternative_rms_v: d_rms,
                            why: format!(
                                "no record holds its input for {HOLD_MIN_S} s: drift would explain \
                                 {:.0} % of the residual power above the noise floor and {r} \
                                 {:.0} %, and a lag longer than the reversals' spacing acts as a \
                                 constant and a scale; the drift gives way to {r}, which needs no \
                                 hold to show; record holds (the recommended protocol) to tell \
                                 them apart",
                                100.0 * d_ex,
                                100.0 * r_ex
                            ),
                        });
                    }
                    scored.retain(|x| x.0.refit || x.0.effect != "drift");
                }
            }
            // Its lags act as a constant and a scale at once: where no single shape stands in
            // for the drift, a shape fitted jointly with an offset (step 10's pairs) may. A pair
            // that explains alike or more (at least `1 / STATIC_TELL_RATIO` of the drift's
            // share, and in no record more than `STATIC_TELL_RATIO` times what it leaves above
            // the floor) takes the drift's place among the step's candidates (families cases
            // 1597 and 1647: an offset beside a scale or a curvature on one long sine, named
            // `drift`, whose 20-25 s lag started settled at the first input held the offset).
            // (Not beside a table, whose constant an offset trades with: families cases 1138
            // and 1006, a scale or a curvature with an offset of -0.1 to -0.5 V, the offset
            // then taken out by the final check and the other shape left in the true one's
            // place.)
            let table =
                named.iter().any(|n| n == "hysteresis") || catalogue::present(&model, "hysteresis");
            if let Some(di) = scored
                .iter()
                .position(|x| x.3 && !x.0.refit && x.0.effect == "drift")
                .filter(|_| !table)
            {
                let shapes: Vec<String> = STATIC_SHAPES
                    .iter()
                    .filter(|s| !named.iter().any(|n| n == *s))
                    .map(|s| s.to_string())
                    .collect();
                let judged = judge_pairs(&static_pairs(&shapes, &named, &model));
                let (d_ex, d_mse, d_rms) = {
                    let d = &scored[di];
                    (d.2, d.0.mse.clone(), rms_of(&d.0.mse))
                };
                if let Some(t) = tried.last_mut() {
                    t.extend(
                        judged
                            .iter()
                            .map(|(c, sc, ex, ok)| (c.effect.clone(), *sc, *ex, *ok)),
                    );
                }
                let stands_in = |(c, _, ex, ok): &(Candidate, f64, f64, bool)| {
                    *ok && ex * STATIC_TELL_RATIO >= d_ex
                        && (1.0 - ex).max(1e-12) <= STATIC_TELL_RATIO * (1.0 - d_ex).max(1e-12)
                        && leaves_within_of(&c.mse, &d_mse, &var, STATIC_TELL_RATIO)
                };
                if let Some(p) = judged
                    .into_iter()
                    .filter(stands_in)
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                {
                    let shape = p.0.effect.split('+').next().unwrap_or_default().to_string();
                    if !ambiguous
                        .iter()
                        .any(|c: &CannotTell| c.named == shape && c.alternative == "drift")
                    {
                        ambiguous.push(CannotTell {
                            named: shape.clone(),
                            alternative: "drift".into(),
                            neither_named: false,
                            taken_out: TakenOut::No,
                            rms_v: rms_of(&p.0.mse),
                            alternative_rms_v: d_rms,
                            why: format!(
                                "no record holds its input for {HOLD_MIN_S} s: drift would \
                                 explain {:.0} % of the residual power above the noise floor \
                                 and {} {:.0} % (leaving {:.2} mV against {:.2} mV), and a \
                                 lag longer than the reversals' spacing acts as a constant and \
                                 a scale; the drift gives way to the pair, which needs no hold \
                                 to show; record holds (the recommended protocol) to tell them \
                                 apart",
                                100.0 * d_ex,
                                p.0.effect.replace('+', " with an "),
                                100.0 * p.2,
                                1e3 * rms_of(&p.0.mse),
                                1e3 * d_rms
                            ),
                        });
                    }
                    scored.remove(di);
                    scored.push(p);
                }
            }
        }
        // The static effects the records cannot tell apart: when the best admissible
        // candidate is one of them and another both explains and leaves nearly as much
        // (within STATIC_TELL_RATIO either way, pooled and in every record), neither is named
        // (the records leave the choice to chance) and the pair is reported; each may then be
        // tried beside an offset.
        let best_effect = scored
            .iter()
            .filter(|x| x.3)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|x| {
                (
                    x.0.effect.clone(),
                    x.0.refit,
                    x.2,
                    rms_of(&x.0.mse),
                    &x.0.sims,
                    &x.0.mse,
                )
            });
        if let Some((e, false, ex, e_rms, e_sims, e_mse)) = best_effect
            && STATIC_SHAPES.contains(&e.as_str())
        {
            // Records that hold several levels tell two shapes apart where one puts those
            // levels clearly nearer the records than the other: the rival is then not a
            // look-alike, and where it is the nearer one, the step's shape gives way to it.
            let e_levels = held_level_error(data, e_sims, &var);
            let levels_favour = |sims: &[Vec<f64>]| -> Option<bool> {
                match (e_levels, held_level_error(data, sims, &var)) {
                    (Some(a), Some(b)) if a * STATIC_TELL_RATIO <= b => Some(true),
                    (Some(a), Some(b)) if b * STATIC_TELL_RATIO <= a => Some(false),
                    _ => None,
                }
            };
            let alike = |x: &(Candidate, f64, f64, bool)| {
                !x.0.refit
                    && x.0.effect != e
                    && STATIC_SHAPES.contains(&x.0.effect.as_str())
                    && explain_alike((ex, e_mse), (x.2, &x.0.mse), &var)
            };
            let verdicts: Vec<(usize, Option<bool>)> = scored
                .iter()
                .enumerate()
                .filter(|(_, x)| alike(x))
                .map(|(i, x)| (i, levels_favour(&x.0.sims)))
                .collect();
            let gives_way = verdicts
                .iter()
                .any(|&(i, v)| v == Some(false) && scored[i].3);
            let rivals: Vec<(String, f64, f64)> = verdicts
                .iter()
                .filter(|&&(_, v)| v.is_none())
                .map(|&(i, _)| &scored[i])
                .map(|x| (x.0.effect.clone(), x.2, rms_of(&x.0.mse)))
                .collect();
            if gives_way {
                scored.retain(|x| x.0.refit || x.0.effect != e);
            } else if !rivals.is_empty() {
                for (r, _, _) in &rivals {
                    look_alikes.push((e.clone(), r.clone(), named.clone()));
                }
                for (r, rx, r_rms) in &rivals {
                    if !ambiguous.iter().any(|c: &CannotTell| {
                        (c.named == e && c.alternative == *r)
                            || (c.named == *r && c.alternative == e)
                    }) {
                        ambiguous.push(CannotTell {
                            named: e.clone(),
                            alternative: r.clone(),
                            neither_named: true,
                            taken_out: TakenOut::No,
                            rms_v: e_rms,
                            alternative_rms_v: *r_rms,
                            why: format!(
                                "neither is named: {e} would explain {:.0} % of the residual power \
                                 above the noise floor and {r} {:.0} %; records at several held \
                                 levels (the recommended protocol) tell a scale, an offset and a \
                                 curvature apart",
                                100.0 * ex,
                                100.0 * rx
                            ),
                        });
                    }
                }
                let mut drop: Vec<String> = rivals
                    .into_iter()
                    .map(|(r, _, _)| r)
                    .chain([e.clone()])
                    .collect();
                // Without holds, a drift that explains alike is one more look-alike (its lags
                // longer than the reversals' spacing act as a constant and a scale): it goes
                // with the shapes it stands beside, instead of taking their place as the one
                // left (it did, and a curvature swapped in for it later stood where a scale
                // was true: families case 1006).
                // (and one that explains less than the shape: the shapes gone, it was named in
                // their place, by its lags' constant and scale; families cases 1540 and 2000, a
                // loop beside a scale or a curvature on one long sine, the drift leaving 1.5-1.6x
                // what the step's shape left)
                if !any_hold
                    && let Some(d) = scored.iter().find(|x| {
                        x.3 && !x.0.refit
                            && x.0.effect == "drift"
                            && (x.2 <= ex || explain_alike((ex, e_mse), (x.2, &x.0.mse), &var))
                    })
                {
                    // (a give-way note of this step, for the shape it now drops, is replaced)
                    ambiguous.retain(|c: &CannotTell| {
                        !(c.named == e && c.alternative == "drift" && !c.neither_named)
                    });
                    if !ambiguous
                        .iter()
                        .any(|c: &CannotTell| c.named == e && c.alternative == "drift")
                    {
                        ambiguous.push(CannotTell {
                            named: e.clone(),
                            alternative: "drift".into(),
                            neither_named: true,
                            taken_out: TakenOut::No,
                            rms_v: e_rms,
                            alternative_rms_v: rms_of(&d.0.mse),
                            why: format!(
                                "neither is named: no record holds its input for {HOLD_MIN_S} s, \
                                 {e} would explain {:.0} % of the residual power above the noise \
                                 floor and drift {:.0} %, and a lag longer than the reversals' \
                                 spacing acts as a constant and a scale; record holds (the \
                                 recommended protocol) to tell them apart",
                                100.0 * ex,
                                100.0 * d.2
                            ),
                        });
                    }
                    drop.push("drift".into());
                }
                // (the best score among the look-alikes: a pair must beat it)
                let best_dropped = scored
                    .iter()
                    .filter(|x| x.3 && !x.0.refit && drop.contains(&x.0.effect))
                    .map(|x| x.1)
                    .fold(f64::INFINITY, f64::min);
                scored.retain(|x| x.0.refit || !drop.contains(&x.0.effect));
                // Where that leaves nothing to name far above the floor, the shapes may be
                // told apart beside a level: each fitted jointly with an offset (the steps add
                // one effect at a time, and a scale beside an offset mimics a curvature beside
                // it; a creep on random levels whose start the lags' settled state misses
                // needs a constant beside it before the drift explains anything). A pair is
                // named only where no other pair explains alike (`explain_alike`).
                if !scored.iter().any(|x| x.3)
                    && cur_mse
                        .iter()
                        .zip(&var)
                        .any(|(m, v)| *m > PAIR_FLOOR_RATIO * PAIR_FLOOR_RATIO * v)
                {
                    // Admissible, and better than the look-alikes alone by the score, which
                    // counts the offset's parameter.
                    let mut judged = judge_pairs(&static_pairs(&drop, &named, &model));
                    for x in judged.iter_mut() {
                        x.3 = x.3 && x.1 < best_dropped;
                    }
                    // The best admissible pair, told apart from every other (by the steps' own
                    // test).
                    if let Some(i) = traced_best(&mut tried, &judged) {
                        let first = &judged[i];
                        let told = judged.iter().enumerate().all(|(j, q)| {
                            j == i || !explain_alike((first.2, &first.0.mse), (q.2, &q.0.mse), &var)
                        });
                        if told {
                            pair_note = Some(drop.clone());
                            scored.push(judged.swap_remove(i));
                        }
                    }
                }
                // A creep beside the level the look-alikes stand for: where the holds show a
                // creep's tails but the drift alone explained next to nothing (its lags start
                // settled and its gains are non-negative: a static level of the other sign,
                // which the look-alikes take, leaves them at zero), the drift is fitted with
                // each look-alike as one step, the best admissible named with it, and the
                // others it cannot be told from reported as the guess it is. The `thesis-full`
                // stage's step response from rest to 2-4.5 V (one record, one held level):
                // the scale, the curvature and the offset each explained 67-68 %, alike, the
                // drift 0 % against tails of hundreds of mV, and nothing was named at 46-70x
                // the floor.
                let drift_none = scored
                    .iter()
                    .find(|x| !x.0.refit && x.0.effect == "drift")
                    .is_some_and(|d| d.2 < MIN_EXPLAINED);
                if !scored.iter().any(|x| x.3)
                    && drift_none
                    && sigs.holds > 0
                    && sigs.tail_v >= DRIFT_TAIL_MIN_NOISE * sigs.noise_v
                    && !catalogue::present(&model, "drift")
                    && cur_mse
                        .iter()
                        .zip(&var)
                        .any(|(m, v)| *m > PAIR_FLOOR_RATIO * PAIR_FLOOR_RATIO * v)
                {
                    let shapes: Vec<&str> = STATIC_SHAPES
                        .iter()
                        .copied()
                        .filter(|s| drop.iter().any(|d| d == s))
                        .collect();
                    let fitted = par_map(&shapes, |s| {
                        fit_slow_set(&model, data, &slow_x, &["drift", s], u_range)
                    });
                    let mut judged: Vec<(Candidate, f64, f64, bool)> = shapes
                        .iter()
                        .zip(fitted)
                        .filter_map(|(s, f)| {
                            let c = joint_candidate(&["drift", s], f?);
                            let (score, explained, harmless) = judge(&c, &all_set);
                            let ok = score < 0.0
                                && explained >= MIN_EXPLAINED
                                && harmless
                                && sigs.supports("drift", &c.model)
                                && catalogue::implausible(&c.model, &model, data).is_none();
                            Some((c, score, explained, ok))
                        })
                        .collect();
                    if let Some(i) = traced_best(&mut tried, &judged) {
                        let shape = |c: &Candidate| c.effect["drift+".len()..].to_string();
                        let s = shape(&judged[i].0);
                        for (j, q) in judged.iter().enumerate() {
                            if j == i
                                || !leave_within(
                                    &q.0.mse,
                                    &judged[i].0.mse,
                                    &var,
                                    STATIC_TELL_RATIO,
                                )
                            {
                                continue;
                            }
                            let t = shape(&q.0);
                            ambiguous.retain(|c: &CannotTell| {
                                !((c.named == s && c.alternative == t)
                                    || (c.named == t && c.alternative == s))
                            });
                            ambiguous.push(CannotTell {
                                named: s.clone(),
                                alternative: t.clone(),
                                neither_named: false,
                                taken_out: TakenOut::No,
                                rms_v: rms_of(&judged[i].0.mse),
                                alternative_rms_v: rms_of(&q.0.mse),
                                why: format!(
                                    "fitted with the drift as one step (the drift alone explained \
                                     nothing beside the level they take), {s} leaves {:.2} mV \
                                     and {t} in its place {:.2} mV, within {STATIC_TELL_RATIO}x \
                                     of each other above the noise floor in every record: a \
                                     guess between the two; records at several held levels (the \
                                     recommended protocol) tell a scale, an offset and a \
                                     curvature apart",
                                    1e3 * rms_of(&judged[i].0.mse),
                                    1e3 * rms_of(&q.0.mse)
                                ),
                            });
                        }
                        scored.push(judged.swap_remove(i));
                    }
                }
            }
        }
        let Some((best, score, explained, _)) = scored
            .into_iter()
            .filter(|x| x.3)
            .min_by(|a, b| a.1.total_cmp(&b.1))
        else {
            break;
        };
        // (a pair of static shapes names both, with the parameters of each)
        let parts: Vec<String> = best.effect.split('+').map(str::to_string).collect();
        let params: serde_json::Map<String, serde_json::Value> = parts
            .iter()
            .flat_map(|p| params_json(&best.model, p))
            .collect();
        let words = if best.effect == CREEP_FROM_FIRST.join("+") {
            format!(
                "{}; fitted with the offset that is its settled creep at the records' first \
                 input taken back (the creep counts from that input: alone, the drift's gains \
                 would pay that constant at every sample)",
                sigs.describe("drift", &best.model)
            )
        } else if best.effect == CREEP_SCALE_FROM_FIRST.join("+") {
            format!(
                "{}; fitted with a scale error and the offset that is its settled creep at the \
                 records' first input taken back (the creep counts from that input; beside the \
                 drift and an offset alone, the offset held the scale's work as well and was \
                 not the creep's start)",
                sigs.describe("drift", &best.model)
            )
        } else if let (true, Some(alike)) = (parts.len() > 1, &pair_note) {
            format!(
                "{} fitted together: {} explained alike one at a time, and this pair explains \
                 clearly more than any other",
                parts.join(" and "),
                alike.join(", ")
            )
        } else {
            // (each part's own evidence: a creep and a loop fitted as one step)
            parts
                .iter()
                .map(|p| sigs.describe(p, &best.model))
                .filter(|w| !w.is_empty())
                .collect::<Vec<_>>()
                .join(", and ")
        };
        let evidence = format!(
            "{}; explains {:.0} % of the residual power above the noise floor; score {:.0} (BIC, {} parameter{})",
            words,
            100.0 * explained,
            score,
            best.k,
            if best.k == 1 { "" } else { "s" }
        );
        steps.push(Step {
            params,
            refit: best.refit,
            ..Step::new(
                best.effect.clone(),
                evidence,
                &cur_mse,
                &best.mse,
                best.sims.clone(),
            )
        });
        for p in parts {
            if !named.contains(&p) {
                named.push(p);
            }
        }
        model = best.model;
        sims = best.sims;
        cur_mse = best.mse;
        // A new or refitted hysteresis table: the start memory that suits it, the slow
        // effects refitted from it (folded into this step: it is the table's own state).
        if steps
            .last()
            .is_some_and(|s| s.effect.split('+').any(|e| e == "hysteresis"))
            && !at_floor_now(&cur_mse, &var)
            && let Some(f) = start::search(&model, data, &slow_x, u_range, &cur_mse)
        {
            slow_x = f.slow_x;
            model = f.model;
            sims = f.sims;
            cur_mse = f.mse;
            if let Some(s) = steps.last_mut() {
                s.rms_after_v = rms_of(&cur_mse);
                s.record_rms_after_v = cur_mse.iter().map(|m| m.sqrt()).collect();
                s.sims = sims.clone();
                s.params = s
                    .effect
                    .split('+')
                    .flat_map(|p| params_json(&model, p))
                    .collect();
            }
        }
    }
    // Step 14 (e): the curvature's own order beside the shapes that stay. The catalogue's
    // K'(u) is a quadratic; a curvature of another shape (a tanh knee) leaves part of itself
    // beside it, and the final check then weighs the other static shapes against a misfit
    // that is none of theirs (families case 9192: a tanh beside a 1.3 % scale on the
    // identification protocol; beside the quadratic the scale and an offset left 8.0 mV, and
    // the pair went for a growth of 1.56x against its 1.75x bar, leaving the curvature alone
    // at 12x the floor). The orders are refitted beside the named scale and offset
    // (`scale_order::refit_order`), and an order is kept where it leaves less in every record
    // than the order it replaces and the latter leaves above the floor, in some record, more
    // by the final check's bar for the added terms (each a parameter): the same test that
    // keeps an effect. Only where the records show what the model leaves (as step 14).
    // Before the final check only on records that start at rest at 0 V, which tell a scale,
    // an offset and K'(u) of any order apart (K'(0) = 1: the small steps from rest read the
    // gain a scale moves and a curvature does not, the rest the zero an offset moves). Over
    // records away from 0 V the three are look-alikes at higher orders, and the shapes the
    // final check weighed beside the order kept went either way (fresh families seeds
    // 9000-9399, sines and sweeps: four right shapes lost or swapped, two gained); there the
    // order is raised after the names are settled (below, after step 14), a refit that names
    // nothing.
    let zero_read = data.iter().any(|d| d.zero_rest_len().is_some());
    if zero_read && let Some(w) = curvature_order(&model, &named, data, &cur_mse, &var) {
        (model, sims, cur_mse) = take_curvature_order(w, &cur_mse, &mut steps);
        // Beside the curvature of its own order, a static shape the quadratic's misfit hid
        // (families case 9044: a 0.7 % scale beside a tanh on the identification protocol
        // explained 1 % beside the quadratic, which left 5.8 mV; the order-5 curvature left
        // 1.66 mV, 1.64x the floor, alone) is offered as the steps offer it, judged by the
        // final check's bar (without it the residual above the floor grows by it) and no
        // record left worse; the final check then weighs it like for like (the order kept).
        if let Some((shape, f)) = static_beside_order(&model, &named, data, (&cur_mse, &var)) {
            let why = format!(
                "beside the curvature of order {} the {shape} leaves {:.2} mV against {:.2} mV \
                 without it, more than the final check's bar for its parameter: the \
                 quadratic's misfit had hidden it",
                f.order,
                1e3 * rms_of(&f.mse),
                1e3 * rms_of(&cur_mse),
            );
            steps.push(Step {
                params: params_json(&f.model, shape),
                ..Step::new(shape.into(), why, &cur_mse, &f.mse, f.sims.clone())
            });
            named.push(shape.into());
            model = f.model;
            sims = f.sims;
            cur_mse = f.mse;
        }
    }
    // From here on a record with a periodic input is judged against the noise its residual
    // holds between the input's cycles where that exceeds its floor (`cycle_noise`: a
    // sensor's low-frequency noise, which the floor read from the fast part does not count),
    // read once on the residual of the fullest model: against the floor alone, such noise
    // compresses a true effect's growth below its bar (the thesis stage's 0.5 Hz triangle
    // with 4.5 mV of red noise: `nonlinear-gain` took 8.15 mV to 5.38 mV, 1.63x above the
    // 2.56 mV floor against its 1.75x bar, 2.3x above the bar of 4.49 mV between cycles).
    // The rule that keeps an effect adding PRUNE_KEEP_EXCESS_VAR noise variances, and the
    // polish (which can only lower the residual), keep the floors (`floor_var`).
    let floor_var = var.clone();
    let cycle_bar: Vec<Option<f64>> = data
        .iter()
        .zip(&sims)
        .map(|(d, s)| {
            let r: Vec<f64> = d.y_v.iter().zip(s).map(|(y, m)| y - m).collect();
            cycle_bar_v(d, &r)
        })
        .collect();
    let var: Vec<f64> = var
        .iter()
        .zip(&cycle_bar)
        .map(|(&v, c)| c.map_or(v, |c| v.max(c * c)))
        .collect();
    // Final check: take each named effect back out (refitting the slow ones left) and keep it
    // only if the residual above the noise floor grows by PRUNE_RATIO at least.
    let mut taken_out: Vec<String> = Vec::new();
    while !named.is_empty() {
        if let Some(b) = &bar {
            b.set_message("final check of each named effect");
        }
        // Removal units: each named effect, and the sensor's affine pair when both are named
        // (an offset and a scale together make `a + b y`, which mops up a misfit of the
        // table's form; each alone is then needed by the other and only the pair can go).
        let mut units: Vec<Vec<String>> = named.iter().map(|e| vec![e.clone()]).collect();
        let pair = ["offset", "sensor-gain"];
        if pair.iter().all(|p| named.iter().any(|n| n == p)) {
            units.push(pair.iter().map(|p| p.to_string()).collect());
        }
        let left_slow = |unit: &Vec<String>| -> Vec<&str> {
            named
                .iter()
                .filter(|n| SLOW.contains(&n.as_str()) && !unit.contains(n))
                .map(String::as_str)
                .collect()
        };
        let trials = par_map_costliest_first(
            &units,
            |u| slow_cost(&left_slow(u)),
            |unit| -> Option<Trial> {
                let mut m = model.clone();
                for e in unit {
                    m = catalogue::revert(&m, base, e);
                }
                let m = refit_slow(&m, &[], data, &slow_x, u_range)?;
                let (s, ms) = simulate_all(&m, data).ok()?;
                // (like for like: where the model's K'(u) is of a higher order than the
                // catalogue's quadratic the refit gives (step 14 (e)), the model without the unit
                // keeps that order, its terms refitted beside the shapes left)
                let order = gain_order(&model);
                if order > QUADRATIC
                    && !unit.iter().any(|e| e == "nonlinear-gain")
                    && let Some(w) = scale_order::refit_order(
                        &m,
                        &named
                            .iter()
                            .filter(|n| !unit.contains(n))
                            .cloned()
                            .collect::<Vec<_>>(),
                        data,
                        order,
                    )
                    && w.mse.iter().sum::<f64>() < ms.iter().sum::<f64>()
                {
                    return Some((unit.clone(), w.model, w.sims, w.mse));
                }
                Some((unit.clone(), m, s, ms))
            },
        );
        // The largest growth over the records of the residual power above the floor.
        let growth = |ms: &[f64]| growth_above_floor(ms, &cur_mse, &var);
        // A second mode whose removal brings its own line back into the residual spectrum
        // stays, whatever the growth: a misfit of another effect's form (Bouc-Wen hysteresis
        // under play operators) can dominate the fast record and hide the growth.
        // An offset the residual without it does not show (its line against the simulated
        // output sits far nearer zero, or on the other side, than the fitted constant) worked
        // through the refit of the others (a table's constant, a gain's polynomial), not as a
        // level of the records: it goes whatever the growth (`Signatures::shows_offset`).
        // An offset the residual without it shows over the records' rest at 0 V input stays
        // whatever the growth: nothing else predicts any output at 0 V, and a rest of a few
        // hundred samples is too small a share of a record for the growth to see (the full
        // thesis stage with +30 and +60 mV: the offset went by the level rule before).
        let mut unshown: Option<(f64, f64)> = None;
        let weakest = trials
            .into_iter()
            .flatten()
            .map(|(e, m, s, ms)| {
                // An offset that is the drift's settled creep at the first input taken back
                // (step 12 below reads it as the drift's start) cannot show as a level: it
                // cancels the drift's own; it is not taken out as unshown, and its growth
                // judges it.
                let drift_start = e.len() == 1
                    && e[0] == "offset"
                    && creep_start(&model, &named, data, &noise).is_some();
                if e.len() == 1 && e[0] == "offset" {
                    let sigs = signatures::compute(data, &s, &noise);
                    if !drift_start && !sigs.shows_offset(&model) {
                        unshown = Some((
                            model.offset.as_ref().map_or(0.0, |o| o.offset_v),
                            sigs.level_v,
                        ));
                        // (judged as one whose removal grows nothing: below its bar whatever
                        // the growth, but after an effect whose removal leaves the records
                        // as they are, whose refit may be what took the level up; families
                        // case 3280: a scale and an offset named beside a curvature that
                        // came first and did nothing after them, the offset taken out as
                        // unshown and the curvature left in the scale's place)
                        return (e, m, s, ms, 1.0);
                    }
                    if sigs.shows_offset_at_rest(&model) {
                        return (e, m, s, ms, f64::INFINITY);
                    }
                }
                let line_back = e.len() == 1
                    && e[0] == "resonance"
                    && signatures::compute(data, &s, &noise).supports(&e[0], &model);
                // A drift whose removal brings tails back into the holds (DRIFT_TAIL_KEEP_NOISE
                // floors: the creep's own signature, which no static effect makes during a
                // hold) stays whatever the growth: far from the floor, after a removed offset
                // the others had traded for, the growth of a true creep is compressed below its
                // bar (a creep and a PI loop on random levels: 1.67x against 2.62x, with tails
                // of 61 mV back).
                let creep_shown = e.len() == 1 && e[0] == "drift" && tails_back(data, &s, &noise);
                // An effect whose removal grows the residual by PRUNE_RATIO and adds more than
                // PRUNE_KEEP_EXCESS_VAR noise variances to some record's residual power
                // explains a component no noise makes: it stays whatever its per-parameter bar
                // (far from the floor, ratios are compressed).
                let g = growth(&ms);
                let large = g >= PRUNE_RATIO
                    && (0..ms.len())
                        .any(|i| ms[i] - cur_mse[i] > PRUNE_KEEP_EXCESS_VAR * floor_var[i]);
                let ratio = if line_back || creep_shown || large {
                    f64::INFINITY
                } else {
                    g
                };
                (e, m, s, ms, ratio)
            })
            // Among the units below their bars, the largest first (two effects explained by
            // the others are removed before one: fewer names for the same evidence), then
            // the one furthest below its bar.
            .min_by(|a, b| {
                // (units below their bar first, larger units first, then ratio to the bar)
                let key = |unit: &[String], ratio: f64| {
                    let bar = prune_bar(unit);
                    let size = if ratio < bar { unit.len() } else { 0 };
                    (std::cmp::Reverse(size), ratio / bar)
                };
                let (ka, kb) = (key(&a.0, a.4), key(&b.0, b.4));
                ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1))
            });
        let Some((unit, m, s, ms, ratio)) = weakest else {
            break;
        };
        let bar_e = prune_bar(&unit);
        if ratio >= bar_e {
            break;
        }
        for e in &unit {
            let with = if unit.len() > 1 {
                format!(" (as a pair: {})", unit.join(" and "))
            } else {
                String::new()
            };
            let evidence = match unshown {
                Some((fitted_v, level_v)) if unit.len() == 1 && e == "offset" => format!(
                    "removed in the final check: fitted at {:.1} mV, but the residual without it sits {:.1} mV off zero: the constant worked through the other effects' refit, not as a level of the records",
                    1e3 * fitted_v,
                    1e3 * level_v
                ),
                _ => format!(
                    "removed in the final check{with}: without it the residual above the noise floor grows only {ratio:.2}x (< {bar_e:.2}x)"
                ),
            };
            // Such an offset is one the records cannot tell from the table's own constant
            // (its relays the records never switch, and its start memory): say so.
            if let Some((fitted_v, level_v)) = unshown
                && unit.len() == 1
                && e == "offset"
                && named.iter().any(|n| n == "hysteresis")
            {
                let mut pair = CannotTell {
                    named: "hysteresis".into(),
                    alternative: "offset".into(),
                    neither_named: false,
                    taken_out: TakenOut::Unshown,
                    rms_v: rms_of(&ms),
                    alternative_rms_v: rms_of(&cur_mse),
                    why: String::new(),
                };
                // (where the model without it leaves clearly more, the constant worked through
                // the table's refit as a shape, not as a level: the refit takes up the level
                // only; families case 1001, a scale beside a Bouc-Wen loop: 1.53 mV with the
                // offset, 52.57 mV without)
                let refit = if pair.alternative_clearly_less() {
                    format!(
                        "takes up its level (the residual {:.1} mV off zero) but not the rest of \
                         its work: {:.2} mV. The final check takes out an offset that the \
                         residual without it does not show as a level: this one worked through \
                         the table's refit, as a scale's or a curvature's work beside a loop of \
                         another form can, and as a level the records cannot tell it from the \
                         table's own constant (its relays these records never switch, and its \
                         start memory)",
                        1e3 * level_v,
                        1e3 * pair.rms_v
                    )
                } else {
                    format!(
                        "takes the constant up ({:.2} mV, the residual {:.1} mV off zero): the \
                         table's relays these records never switch, and its start memory, hold \
                         a constant of their own",
                        1e3 * pair.rms_v,
                        1e3 * level_v
                    )
                };
                pair.why = format!(
                    "an offset fitted at {:.1} mV beside the hysteresis table leaves {:.2} mV; \
                     taken out, the table's refit {refit}; a hold at a known input before the \
                     record, or records that reach both ends of the range, tell a sensor offset \
                     from the table's constant",
                    1e3 * fitted_v,
                    1e3 * pair.alternative_rms_v
                );
                // A shape whose work the offset did: the other static shapes fitted in its
                // place beside the model without it, each reported with the offset where it
                // explains a step's share of what is left (families case 1001: a true 3.4 %
                // scale beside a Bouc-Wen loop on a chirp; the offset won step 2 by its score,
                // leaving half what the scale left, the final check took it out, and the
                // scale was in no pair).
                if pair.alternative_clearly_less() {
                    for k in shapes_in_offsets_place(
                        (&m, &ms, &cur_mse),
                        &named,
                        data,
                        &slow_x,
                        u_range,
                        &var,
                    ) {
                        // (a pair a step already reports stays as that step gave it)
                        if !ambiguous.iter().any(|c| {
                            (c.named == k.named && c.alternative == k.alternative)
                                || (c.named == k.alternative && c.alternative == k.named)
                        }) {
                            ambiguous.push(k);
                        }
                    }
                }
                ambiguous.push(pair);
            }
            // Such an offset beside a curvature and no table: K'(u) has no constant term, but
            // over records that never read the sensor's zero (no rest at 0 V, no input near
            // it) its polynomial takes up a level too, and the records cannot tell the two
            // (families cases 3222 and 3252: a tanh or softplus curvature and a sensor offset
            // on one sine or chirp, the offset taken out as unshown and in no pair).
            if let Some((fitted_v, level_v)) = unshown
                && unit.len() == 1
                && e == "offset"
                && !named.iter().any(|n| n == "hysteresis")
                && named.iter().any(|n| n == "nonlinear-gain")
                && reads_no_zero(data, 0.0)
            {
                ambiguous.push(CannotTell {
                    named: "nonlinear-gain".into(),
                    alternative: "offset".into(),
                    neither_named: false,
                    taken_out: TakenOut::Unshown,
                    rms_v: rms_of(&ms),
                    alternative_rms_v: rms_of(&cur_mse),
                    why: format!(
                        "an offset fitted at {:.1} mV beside the curvature leaves {:.2} mV; taken \
                         out, the curvature's refit takes up its level (the residual {:.1} mV off \
                         zero) and leaves {:.2} mV: K'(u) has no constant term, but over inputs \
                         that never come near 0 V its polynomial holds a level as a sensor \
                         offset does; a rest at 0 V before the record (the recommended \
                         protocol), or inputs down to 0 V, tell a sensor offset from the \
                         curvature",
                        1e3 * fitted_v,
                        1e3 * rms_of(&cur_mse),
                        1e3 * level_v,
                        1e3 * rms_of(&ms)
                    ),
                });
            }
            // A static shape beside a table on records without holds that the final check
            // took out below its bar, though the residual without it grew by more than a
            // misfit of form costs: the others' refit, the table's reversible slopes along the
            // range among them, took up most of its work, and such records cannot tell the two
            // static maps apart (families cases 1020, 1061, 1068: a true curvature beside a
            // Duhem or Bouc-Wen loop on one sine or chirp, taken out at 1.30-1.69x against its
            // 1.75x bar, was in no pair).
            if unit.len() == 1
                && STATIC_SHAPES.contains(&e.as_str())
                && e != "offset"
                && named.iter().any(|n| n == "hysteresis")
                && !data.iter().any(Data::has_hold)
                && ratio >= CANNOT_TELL_RATIO
            {
                ambiguous.push(CannotTell {
                    named: "hysteresis".into(),
                    alternative: e.clone(),
                    neither_named: false,
                    taken_out: TakenOut::BelowBar,
                    rms_v: rms_of(&ms),
                    alternative_rms_v: rms_of(&cur_mse),
                    why: format!(
                        "{e} fitted beside the hysteresis table leaves {:.2} mV; taken out, the \
                         others' refit, the table's among them, takes up most of its work \
                         ({:.2} mV: the residual above the noise floor grows {ratio:.2}x, more \
                         than the {CANNOT_TELL_RATIO}x a misfit of form costs, but under the \
                         {bar_e:.2}x its parameters must earn): without holds, the table's \
                         reversible slopes along the range make a static map as {e} does, and \
                         the records cannot tell which; records at several held levels (the \
                         recommended protocol) tell a static map from the loop's",
                        1e3 * rms_of(&cur_mse),
                        1e3 * rms_of(&ms)
                    ),
                });
            }
            steps.push(Step {
                removed: true,
                ..Step::new(e.clone(), evidence, &cur_mse, &ms, s.clone())
            });
        }
        named.retain(|x| !unit.contains(x));
        taken_out.extend(unit);
        model = m;
        sims = s;
        cur_mse = ms;
    }
    // Step 17: beside a table, the static shapes the final check kept must be ones the
    // records tell from the loop's own centre line and constant, all of them together (the
    // loop's misfit is shared between them: one at a time, a true curvature beside a false
    // scale is not told, the scale's refit taking its place): held levels they put clearly
    // nearer from both sides (`told_beside_loop`), or a rest at 0 V that shows the offset
    // among them. Untold, they go whatever
    // their growth, after the final check (before it, a drift or a table the final check
    // would have found redundant beside them stayed in their place).
    // (an offset on records that read no sensor zero is step 13's: it moves into the table's
    // own level, the same readings, and is not named; taken out here, the model lost the
    // constant: families case 1006, 3.5x -> 41.5x the floor)
    let statics = statics_to_tell(&named, data, slow_x.range().0);
    // (not beside the span split's table, `shapes_told_beside_loop`: the thesis stage on one
    // sine names its K'(u) there, `tests/gap.rs`)
    if shapes_told_beside_loop(&named, slow_x.form()) && !statics.is_empty() {
        let mut m = model.clone();
        for e in &statics {
            m = catalogue::revert(&m, base, e);
        }
        if let Some(m) = refit_slow(&m, &[], data, &slow_x, u_range)
            && let Ok((s, ms)) = simulate_all(&m, data)
        {
            let told = told_beside_loop(data, &sims, &s, &var)
                || (statics.iter().any(|x| x == "offset")
                    && signatures::compute(data, &s, &noise).shows_offset_at_rest(&model));
            if !told {
                let with = if statics.len() > 1 {
                    format!(" (with {})", statics.join(" and "))
                } else {
                    String::new()
                };
                for e in &statics {
                    ambiguous.push(CannotTell {
                        named: "hysteresis".into(),
                        alternative: e.clone(),
                        neither_named: false,
                        taken_out: TakenOut::Untold,
                        rms_v: rms_of(&ms),
                        alternative_rms_v: rms_of(&cur_mse),
                        why: format!(
                            "{e}{with} beside the hysteresis table leaves {:.2} mV, without it \
                             {:.2} mV, but a loop of another form than the table's leaves a \
                             centre line and a constant of its own, which a scale, a curvature \
                             or an offset takes up as readily (beside a loop, the suites' static \
                             names were right in fewer than half the cases); held levels reached \
                             from both sides (the recommended protocol), or a rest at 0 V for an \
                             offset, tell a static map from the loop's",
                            1e3 * rms_of(&cur_mse),
                            1e3 * rms_of(&ms)
                        ),
                    });
                    steps.push(Step {
                        removed: true,
                        ..Step::new(
                            e.clone(),
                            format!(
                                "removed{with}: beside the hysteresis table the records do not \
                                 tell it from the loop's own centre line and constant (no held \
                                 levels it puts {STATIC_TELL_RATIO}x nearer on both sides, those \
                                 reached from below and from above, no rest at 0 V that shows an \
                                 offset)"
                            ),
                            &cur_mse,
                            &ms,
                            s.clone(),
                        )
                    });
                }
                named.retain(|x| !statics.contains(x));
                taken_out.extend(statics);
                model = m;
                sims = s;
                cur_mse = ms;
            }
        }
    }
    // A look-alike settled by a stepping stone the final check took out: a static shape a
    // step left unnamed beside its rival (the two explained alike beside the effects named
    // then), named at a later step only after another effect came in, is back beside exactly
    // the effects it was compared beside once that effect is taken out. The records' own
    // comparison then says it cannot be told from its rival: it goes too, and the pair is
    // reported (families case 1074: a curvature and a scale alike beside a Bouc-Wen loop on a
    // chirp; a drift came in between, the curvature after it, and the drift went). Only where
    // the final check took out an effect named after the pair was found: a step that named a
    // refit of an effect already named leaves the named set as it was and may tell the two
    // apart by itself. (The swaps and the rest reading below may still bring the shape or its
    // rival back on their own evidence; the pair is then dropped from the report, as any pair
    // a later step names.)
    // The pair is judged again beside the final model, by the steps' own test: the rival
    // fitted in the shape's place must explain alike (`explain_alike`) what the shape explains
    // of the residual the model without it leaves; a shape the final model tells apart stays.
    let mut judged_again: Vec<(String, String)> = Vec::new();
    for _ in 0..2 * look_alikes.len() {
        let settled = look_alikes.iter().find_map(|(a, b, before)| {
            let stone_gone = taken_out.iter().any(|t| !before.contains(t));
            [(a, b), (b, a)].into_iter().find_map(|(e, r)| {
                let rest: Vec<&String> = named.iter().filter(|n| *n != e).collect();
                (stone_gone
                    && !judged_again.contains(&(e.clone(), r.clone()))
                    && named.contains(e)
                    && !named.contains(r)
                    && rest.len() == before.len()
                    && rest.iter().all(|n| before.contains(n)))
                .then(|| (e.clone(), r.clone()))
            })
        });
        let Some((e, r)) = settled else {
            break;
        };
        let m = catalogue::revert(&model, base, &e);
        let Some(m) = refit_slow(&m, &[], data, &slow_x, u_range) else {
            break;
        };
        let Ok((s, ms)) = simulate_all(&m, data) else {
            break;
        };
        judged_again.push((e.clone(), r.clone()));
        let Some((_, _, r_mse)) = fit_slow_set(&m, data, &slow_x, &[r.as_str()], u_range) else {
            continue;
        };
        let every: Vec<usize> = (0..data.len()).collect();
        let share = |x: &[f64]| explained_share(&ms, x, &var, &every);
        if !explain_alike((share(&cur_mse), &cur_mse), (share(&r_mse), &r_mse), &var) {
            continue;
        }
        let beside = if named.len() > 1 {
            named
                .iter()
                .filter(|n| **n != e)
                .cloned()
                .collect::<Vec<_>>()
                .join(", ")
        } else {
            "the base model".into()
        };
        steps.push(Step {
            removed: true,
            ..Step::new(
                e.clone(),
                format!(
                    "removed: beside {beside}, the effects still named, a step found that the \
                     records cannot tell it from {r}; it was named later only beside an effect \
                     the final check took out, and beside the final model {r} fitted in its \
                     place still explains alike ({:.0} % against {:.0} % of what the model \
                     without it leaves above the noise floor)",
                    100.0 * share(&r_mse),
                    100.0 * share(&cur_mse)
                ),
                &cur_mse,
                &ms,
                s.clone(),
            )
        });
        named.retain(|n| *n != e);
        model = m;
        sims = s;
        cur_mse = ms;
    }
    // Polish: the slow effects refitted together once more with every named effect in place
    // and the structure search's full rounds (a fast effect named after them, a slew limit,
    // moves the fast record their fit shares, and the steps' candidates search one round),
    // kept where no record's residual grows and their sum falls.
    if !at_floor_now(&cur_mse, &floor_var) {
        // (the set `refit_slow` refits)
        let slow = fitted_slow(&model, &slow_x);
        if !slow.is_empty()
            && let Some(m) = refit_slow(&model, &[], data, &slow_x, u_range)
            && let Ok((s, ms)) = simulate_all(&m, data)
            && ms.iter().zip(&cur_mse).all(|(a, b)| *a <= *b)
            && ms.iter().sum::<f64>() < cur_mse.iter().sum::<f64>()
        {
            steps.push(Step {
                refit: true,
                ..Step::new(
                    slow.join("+"),
                    "the slow effects refitted together with every named effect in place".into(),
                    &cur_mse,
                    &ms,
                    s.clone(),
                )
            });
            model = m;
            sims = s;
            cur_mse = ms;
        }
    }
    // Swaps (after the radii are refined, and each trial refined the same way): a slow effect
    // the greedy pass named first can stand in for another the records
    // cannot tell from it (without holds, a drift lag's mean over a sine acts as an offset);
    // each named slow effect is replaced in turn by each slow effect not named, the slow set
    // refitted, and the swap kept if it lowers the score over all records and no record's
    // residual power grows. At the floor too: a form that fits as well with fewer parameters
    // (an offset and a scale for a polynomial gain and an offset) is the one to name. Above
    // the floor, one static shape with fewer parameters (in the catalogue: an offset or a
    // scale for `nonlinear-gain`) that leaves within `OCCAM_SWAP_RATIO` in every record is
    // swapped in whatever the score (below). A named offset that is not the drift's start
    // (step 12's test) is also swapped with the drift's start fitted beside the new set
    // (`creep_counted_from_first`, GAP.md step 18).
    {
        let score = |ms: &[f64], set: &[String]| set_score(data, ms, set);
        let named_slow: Vec<String> = named
            .iter()
            .filter(|e| SLOW.contains(&e.as_str()))
            .cloned()
            .collect();
        let mut swaps: Vec<(String, String)> = Vec::new();
        for e in &named_slow {
            // Without holds the drift gave way to the static shapes at each step: no swap
            // brings it back.
            for f in SLOW
                .iter()
                .filter(|f| !named.iter().any(|n| n == *f))
                .filter(|f| any_hold || **f != "drift")
            {
                swaps.push((e.clone(), f.to_string()));
            }
        }
        // (an offset step 12 will read as the drift's start already is one: a swap of it
        // with the start would be a shape added, which the steps' gate is for)
        let offset_is_start = creep_start(&model, &named, data, &noise).is_some();
        let trials = par_map_costliest_first(
            &swaps,
            |(e, f)| {
                let set: Vec<&str> = named_slow
                    .iter()
                    .map(|n| if n == e { f.as_str() } else { n.as_str() })
                    .collect();
                slow_cost(&set)
            },
            |(e, f)| -> Option<Fitted> {
                let m0 = catalogue::revert(&model, base, e);
                let m = refit_slow(&m0, &[f.as_str()], data, &slow_x, u_range)?;
                let (s, ms) = simulate_all(&m, data).ok()?;
                // (and with the drift's start, where that leaves less: step 18 for a swap)
                let started = (e == "offset" && !offset_is_start)
                    .then(|| {
                        creep_counted_from_first(
                            (&m0, f),
                            &named_slow,
                            data,
                            (&slow_x, u_range),
                            &noise,
                        )
                    })
                    .flatten();
                Some(match started {
                    Some(t) if in_noise_vars(&t.2, &var) < in_noise_vars(&ms, &var) => t,
                    _ => (m, s, ms),
                })
            },
        );
        let cur_score = score(&cur_mse, &named);
        // A swapped-in effect passes the steps' signature gate on the residual of the model
        // it would join (a loop for hysteresis, a tail for drift where the records hold), and
        // an offset must be a level that residual shows (`Signatures::shows_offset`); no
        // swap names a value no stage or sensor could have (`catalogue::implausible`).
        let cur_sigs = signatures::compute(data, &sims, &noise);
        // The one static shape with fewer parameters that leaves within `OCCAM_SWAP_RATIO` in
        // every record in a named static shape's place (in the catalogue: an offset or a scale
        // for `nonlinear-gain`, whose linear term can do a scale's work beside a loop of
        // another form) is the one the records support: swapped in whatever the score, where
        // the model is above the floor (a misfit of another form is there) and no other shape
        // with fewer parameters does as well and passes the gate (a scale and an offset both
        // alike, and the records cannot choose). Families case 1074: `sensor-gain` in place of
        // the curvature left 3.98 against 3.87 mV.
        let occam_alike = |e: &str, f: &str, ms: &[f64]| {
            STATIC_SHAPES.contains(&e)
                && STATIC_SHAPES.contains(&f)
                && catalogue::param_count(f) < catalogue::param_count(e)
                && leave_within(ms, &cur_mse, &var, OCCAM_SWAP_RATIO)
        };
        let above_floor = !at_floor_now(&cur_mse, &var);
        let shown = |f: &str, m: &ModelFile| {
            cur_sigs.supports(f, m)
                && (f != "offset" || cur_sigs.shows_offset(m))
                && catalogue::implausible(m, &model, data).is_none()
        };
        // (step 17: beside a table, a static shape swapped in must be one the records tell
        // from the loop, as the final check asks)
        let beside_loop = shapes_told_beside_loop(&named, slow_x.form());
        // Per trial: the effect swapped in passes the gate, and it is an alike shape with
        // fewer parameters.
        let flags: Vec<(bool, bool)> = swaps
            .iter()
            .zip(&trials)
            .map(|((e, f), t)| {
                t.as_ref().map_or((false, false), |(m, s, ms)| {
                    // A drift whose place would bring its tails back into the holds is no
                    // swap's to take (families' creep and Preisach loop on random levels,
                    // seed 4003: a curvature took a drift whose tails were 51 mV).
                    if e == "drift" && tails_back(data, s, &noise) {
                        return (false, false);
                    }
                    let shown = shown(f, m)
                        && (!beside_loop
                            || !STATIC_SHAPES.contains(&f.as_str())
                            || told_beside_loop(data, s, &sims, &var));
                    (shown, shown && above_floor && occam_alike(e, f, ms))
                })
            })
            .collect();
        // What each swap leaves (for the look-alike test below, before the trials are
        // taken).
        let trial_ms: Vec<Option<Vec<f64>>> = trials
            .iter()
            .map(|t| t.as_ref().map(|(_, _, ms)| ms.clone()))
            .collect();
        // A static shape the score swaps in for another, where a third static shape fitted in
        // the same place leaves alike in every record (step 10's look-alike bar,
        // `STATIC_TELL_RATIO`, either way) and passes the same gate: the records do not tell
        // the two, and the pair is reported. The `thesis-full` stage on one step from rest to
        // 6 V (`piezo synth --protocol steps --seconds 10`): the score swapped a scale of
        // 0.923 in for an offset at 1.28x the floor, where one held level cannot tell a scale
        // from a curvature, and said nothing. (Not neither named, as step 10 would: the
        // offset it would leave was a level the residual's line showed, and stayed beside the
        // drift at 7.7x the floor.)
        let untold_rival = |j: usize| -> Option<usize> {
            let (e, f) = (&swaps[j].0, &swaps[j].1);
            if !STATIC_SHAPES.contains(&e.as_str()) || !STATIC_SHAPES.contains(&f.as_str()) {
                return None;
            }
            let ms = trial_ms[j].as_ref()?;
            (0..swaps.len()).find(|&k| {
                k != j
                    && swaps[k].0 == *e
                    && swaps[k].1 != *f
                    && STATIC_SHAPES.contains(&swaps[k].1.as_str())
                    && flags[k].0
                    && trial_ms[k]
                        .as_ref()
                        .is_some_and(|mk| leave_within(mk, ms, &var, STATIC_TELL_RATIO))
            })
        };
        let alike_count = |e: &str| {
            swaps
                .iter()
                .zip(&flags)
                .filter(|((e2, _), (_, occam))| e2 == e && *occam)
                .count()
        };
        let best = swaps
            .iter()
            .zip(trials)
            .zip(&flags)
            .enumerate()
            .filter_map(|(j, (((e, f), t), &(shown, occam)))| {
                let (m, s, ms) = t?;
                let set: Vec<String> = named
                    .iter()
                    .map(|n| if n == e { f.clone() } else { n.clone() })
                    .collect();
                // (the drift's start, where the trial took it, is a constant the score counts
                // as an offset's)
                let sc = if started_here(&model, &m) {
                    let with: Vec<String> = set.iter().cloned().chain(["offset".into()]).collect();
                    score(&ms, &with)
                } else {
                    score(&ms, &set)
                };
                // No record may get worse: the score is dominated by the longest record, and
                // a swap that trades a short fast record for it (an offset for the non-linear
                // gain of the full thesis stage) is no explanation.
                // Without holds and beside a table, the score alone does not put a shape with
                // more parameters in a named one's place: the extra parameter takes up the
                // loop's misfit as readily as a true curvature, and no held level tells the
                // two (families case 1006: a curvature for its true scale, 8.26 against
                // 10.54 mV, at 8x the floor).
                let more_beside_loop = !any_hold
                    && catalogue::present(&model, "hysteresis")
                    && STATIC_SHAPES.contains(&e.as_str())
                    && STATIC_SHAPES.contains(&f.as_str())
                    && catalogue::param_count(f) > catalogue::param_count(e);
                let better = no_record_worse(&ms, &cur_mse) && sc < cur_score && !more_beside_loop;
                let occam = occam && alike_count(e) == 1;
                (shown && (better || occam)).then_some((
                    j,
                    e.clone(),
                    f.clone(),
                    set,
                    m,
                    s,
                    ms,
                    sc,
                    better,
                ))
            })
            .min_by(|a, b| a.7.total_cmp(&b.7));
        if let Some((j, e, f, set, m, s, ms, sc, better)) = best {
            let params = params_json(&m, &f);
            // (swapped in by the score where a third shape leaves alike: said, in place of any
            // pair of the two a step left unnamed)
            if better && let Some(k) = untold_rival(j) {
                let g = &swaps[k].1;
                ambiguous.retain(|c: &CannotTell| {
                    !((c.named == f && c.alternative == *g)
                        || (c.named == *g && c.alternative == f))
                });
                let rms_g = trial_ms[k].as_deref().map_or(f64::NAN, rms_of);
                ambiguous.push(CannotTell {
                    named: f.clone(),
                    alternative: g.clone(),
                    neither_named: false,
                    taken_out: TakenOut::No,
                    rms_v: rms_of(&ms),
                    alternative_rms_v: rms_g,
                    why: format!(
                        "swapped in for {e} by the score ({:.2} mV against {:.2} mV with {e}), \
                         but {g} in the same place leaves {:.2} mV, within {STATIC_TELL_RATIO}x \
                         of it above the noise floor in every record: a guess between the two; \
                         records at several held levels (the recommended protocol) tell a \
                         scale, an offset and a curvature apart",
                        1e3 * rms_of(&ms),
                        1e3 * rms_of(&cur_mse),
                        1e3 * rms_g
                    ),
                });
            }
            // (a trial that took the drift's start says so, as step 12 does)
            let start_said = match m.drift.as_ref().and_then(|d| d.unsettled_v) {
                Some(start_v) if started_here(&model, &m) => {
                    let why = format!(
                        "the drift refitted beside {f} counts its creep from the records' first \
                         input: its start, {:.1} mV, is the settled creep there taken back \
                         (step 12's test), kept as [drift] unsettled_v; a rest at 0 V before \
                         the records, or records that start at other inputs, tell it from a \
                         sensor offset",
                        1e3 * start_v
                    );
                    ambiguous.push(CannotTell {
                        named: "drift".into(),
                        alternative: "offset".into(),
                        neither_named: false,
                        taken_out: TakenOut::No,
                        rms_v: rms_of(&ms),
                        alternative_rms_v: rms_of(&ms),
                        why: why.clone(),
                    });
                    format!("; {why}")
                }
                _ => String::new(),
            };
            let evidence = if better {
                format!(
                    "swapped in for {e}, which these records cannot tell from it (score {:.0} \
                     lower){start_said}",
                    cur_score - sc
                )
            } else {
                format!(
                    "swapped in for {e}, which these records cannot tell from it: {} parameter(s) \
                     against {}, within {OCCAM_SWAP_RATIO}x in every record ({:.2} mV against \
                     {:.2} mV), and no other shape with fewer parameters as close{start_said}",
                    catalogue::param_count(&f),
                    catalogue::param_count(&e),
                    1e3 * rms_of(&ms),
                    1e3 * rms_of(&cur_mse)
                )
            };
            steps.push(Step {
                params,
                ..Step::new(f.clone(), evidence, &cur_mse, &ms, s.clone())
            });
            named = set;
            model = m;
            sims = s;
            cur_mse = ms;
        }
    }
    // The sensor's reading at rest at 0 V with no offset named: an offset fitted beside the
    // others that takes it (on its side, half of it at least), lowers the score over all
    // records and makes none worse is named (the reading at 0 V is the sensor's zero); where
    // the table's own constant took the reading up and the offset does not pass, the two are
    // reported as a pair the records cannot tell. (Before the look-alike pairs are settled
    // below, so that a pair whose alternative this names is dropped.)
    if let Some(r) = rest_reading(
        &model,
        &named,
        data,
        &sims,
        &noise,
        noise_floor_v,
        &slow_x,
        u_range,
    ) {
        let fitted_v = r.with.offset.as_ref().map_or(0.0, |o| o.offset_v);
        let (rms_v, with_rms_v) = (rms_of(&cur_mse), rms_of(&r.mse));
        let with_offset: Vec<String> = named.iter().cloned().chain(["offset".into()]).collect();
        let takes_it = shows_share(fitted_v, r.reading_v, REST_ZERO_SHOWN_MIN);
        let better = set_score(data, &r.mse, &with_offset) < set_score(data, &cur_mse, &named)
            && no_record_worse(&r.mse, &cur_mse);
        let held = named.iter().any(|n| n == "hysteresis")
            && shows_share(r.predicted_v, r.reading_v, REST_ZERO_SHOWN_MIN);
        let reading = format!(
            "the sensor reads {:.1} mV over the records' rest at 0 V input, where no other \
             effect moves it, and the model without an offset predicts {:.1} mV there{}",
            1e3 * r.reading_v,
            1e3 * r.predicted_v,
            if held {
                " (the table's relays below the records' inputs, or its start memory, hold \
                 that constant)"
            } else {
                ""
            }
        );
        if takes_it && better {
            steps.push(Step {
                params: params_json(&r.with, "offset"),
                ..Step::new(
                    "offset".into(),
                    format!(
                        "{reading}; an offset fitted beside the others ({:.1} mV) leaves \
                         {:.2} mV against {:.2} mV",
                        1e3 * fitted_v,
                        1e3 * with_rms_v,
                        1e3 * rms_v
                    ),
                    &cur_mse,
                    &r.mse,
                    r.sims.clone(),
                )
            });
            named.push("offset".into());
            model = r.with;
            sims = r.sims;
            cur_mse = r.mse;
        } else if held
            && !ambiguous
                .iter()
                .any(|k| k.named == "hysteresis" && k.alternative == "offset")
        {
            ambiguous.push(CannotTell {
                named: "hysteresis".into(),
                alternative: "offset".into(),
                neither_named: false,
                taken_out: TakenOut::No,
                rms_v,
                alternative_rms_v: with_rms_v,
                why: format!(
                    "{reading}; an offset fitted beside the table ({:.1} mV) leaves {:.2} mV \
                     against {:.2} mV; records whose input goes below 0 V before the rest, \
                     down to where the table's range ends, tell a sensor offset from it",
                    1e3 * fitted_v,
                    1e3 * with_rms_v,
                    1e3 * rms_v
                ),
            });
        }
    }
    // Step 15 (before the pairs are settled): beside a loop, the static shapes the records
    // cannot tell apart. A loop of another form than the Everett table's (a Bouc-Wen or Duhem
    // loop, a Preisach plane whose relays reach past the records' span) leaves a centre line
    // the table does not hold, each static shape takes a part of it, and the steps then
    // choose between look-alikes by that misfit (families cases 1615 and 1444: a curvature
    // beside a Prandtl-Ishlinskii loop on random levels, where the true scale in its place
    // left 1.44x and 1.35x as much). Each named scale or curvature is refitted against every
    // static shape not named in its place (the table and the others refitted with it); the
    // shapes that leave no more than the look-alike bar above what the best of them leaves, in
    // every record, are alike. Of two or more alike, the one with the fewest parameters is
    // named (the simplest the records allow: `OCCAM_SWAP_RATIO`'s rule at the look-alike bar,
    // beside a loop); where two have as few, neither is named. The pairs are reported.
    // Only above the floor, where a misfit of another form is there to share (as the swaps'
    // Occam rule), and not beside a drift, whose K(u) is refitted with each rival and curves
    // the slow part for it (the thesis stage on random levels, `gap.rs`: a scale with the
    // drift's K(u) left 2.53 mV where K'(u) left 2.52, both at the floor).
    if named.iter().any(|n| n == "hysteresis")
        && !named.iter().any(|n| n == "drift")
        && !at_floor_now(&cur_mse, &var)
    {
        for e in ["nonlinear-gain", "sensor-gain"] {
            if !named.iter().any(|n| n == e) {
                continue;
            }
            let rivals: Vec<&str> = STATIC_SHAPES
                .iter()
                .copied()
                .filter(|f| *f != e && !named.iter().any(|n| n == f))
                .filter(|f| !catalogue::present(&model, f))
                .collect();
            let trials = par_map(&rivals, |f| {
                let m = catalogue::revert(&model, base, e);
                let m = refit_slow(&m, &[*f], data, &slow_x, u_range)?;
                let (s, ms) = simulate_all(&m, data).ok()?;
                Some((m, s, ms))
            });
            // (the shape, its model, simulations and mean squares: the named one first)
            let mut fits: Vec<ShapeFit> = vec![(e, model.clone(), sims.clone(), cur_mse.clone())];
            fits.extend(
                rivals
                    .iter()
                    .zip(trials)
                    .filter_map(|(f, t)| t.map(|(m, s, ms)| (*f, m, s, ms))),
            );
            let total = |ms: &[f64]| ms.iter().sum::<f64>();
            let Some(best) = fits
                .iter()
                .map(|x| x.3.clone())
                .min_by(|a, b| total(a).total_cmp(&total(b)))
            else {
                continue;
            };
            let alike: Vec<usize> = (0..fits.len())
                .filter(|&i| leaves_within_of(&fits[i].3, &best, &var, STATIC_TELL_RATIO))
                .collect();
            if alike.len() < 2 {
                continue;
            }
            let fewest = alike
                .iter()
                .map(|&i| catalogue::param_count(fits[i].0))
                .min()
                .unwrap_or(0);
            let simplest: Vec<usize> = alike
                .iter()
                .copied()
                .filter(|&i| catalogue::param_count(fits[i].0) == fewest)
                .collect();
            let said = alike
                .iter()
                .map(|&i| format!("{} {:.2} mV", fits[i].0, 1e3 * rms_of(&fits[i].3)))
                .collect::<Vec<_>>()
                .join(", ");
            let lead = format!(
                "beside the loop, each in the others' place leaves {said}, in no record more \
                 than {STATIC_TELL_RATIO}x as much above the floor as the best: a loop of \
                 another form than the table's leaves a centre line that each static shape \
                 takes a part of; records at several held levels reached from both sides, and \
                 a rest at 0 V (the recommended protocol), tell a scale, an offset and a \
                 curvature from the loop's own"
            );
            let (keep, why) = if let [i] = simplest[..] {
                (
                    Some(i),
                    format!("{lead}; the one with the fewest parameters is named"),
                )
            } else {
                (
                    None,
                    format!("neither is named: {lead}; as few parameters in more than one"),
                )
            };
            // (the pairs: the one named, or the named shape, against each other alike)
            let head = keep.unwrap_or(0);
            for &j in alike.iter().filter(|&&j| j != head) {
                let (a, b) = (fits[head].0, fits[j].0);
                ambiguous.retain(|k| {
                    !((k.named == a && k.alternative == b) || (k.named == b && k.alternative == a))
                });
                ambiguous.push(CannotTell {
                    named: a.into(),
                    alternative: b.into(),
                    neither_named: keep.is_none(),
                    taken_out: TakenOut::No,
                    rms_v: rms_of(&fits[head].3),
                    alternative_rms_v: rms_of(&fits[j].3),
                    why: why.clone(),
                });
            }
            match keep {
                Some(0) => {}
                Some(i) => {
                    let (f, m, s, ms) = fits.swap_remove(i);
                    steps.push(Step {
                        params: params_json(&m, f),
                        ..Step::new(
                            f.into(),
                            format!("swapped in for {e}: {why}"),
                            &cur_mse,
                            &ms,
                            s.clone(),
                        )
                    });
                    for n in named.iter_mut().filter(|n| *n == e) {
                        *n = f.into();
                    }
                    model = m;
                    sims = s;
                    cur_mse = ms;
                }
                None => {
                    let m = catalogue::revert(&model, base, e);
                    let Some(m) = refit_slow(&m, &[], data, &slow_x, u_range) else {
                        continue;
                    };
                    let Ok((s, ms)) = simulate_all(&m, data) else {
                        continue;
                    };
                    steps.push(Step {
                        removed: true,
                        ..Step::new(e.into(), why, &cur_mse, &ms, s.clone())
                    });
                    named.retain(|n| n != e);
                    model = m;
                    sims = s;
                    cur_mse = ms;
                }
            }
        }
    }
    // Step 14 (before the pairs are settled, and before steps 12 and 13, which read the named
    // set): a scale beside a curvature that a curvature of higher order does without, leaving
    // no more than the look-alike bar above what the model leaves in any record and above
    // what the order below it leaves beside the scale (like for like: as many parameters), is
    // a part of the curvature's shape the records do not tell from a scale (`scale_order`):
    // the model with one name fewer is kept, and the pair reported. The orders are tried
    // from the cubic up, and the lowest that does is kept. Where the scale may instead stand
    // in an offset's place (below), an offset beside the cubic that leaves less in every
    // record than the curvature of higher order is preferred to it (families case 2968: a
    // 23 mV offset beside a tanh, 1.37 mV, against 2.24 mV for the order-6 curvature alone).
    let swap = || {
        let w = scale_order::curvature_in_scales_place(
            &model,
            &named,
            data,
            InPlace::Offset,
            scale_order::CUBIC,
        )?;
        let v = scale_order::curvature_in_scales_place(
            &model,
            &named,
            data,
            InPlace::Scale,
            scale_order::CUBIC,
        )?;
        (less_in_every_record(&w.mse, &v.mse) && no_record_worse(&w.mse, &cur_mse))
            .then_some((w, v))
    };
    let higher = curvature_in_place_of(
        |order| {
            scale_order::curvature_in_scales_place(&model, &named, data, InPlace::Nothing, order)
        },
        (&model, &named, data),
        &cur_mse,
        &var,
    );
    let (higher, swap) = match higher {
        Some((w, rival)) if w.order > scale_order::CUBIC => match swap() {
            Some((o, v)) if less_in_every_record(&o.mse, &w.mse) => (None, Some((o, v))),
            _ => (Some((w, rival)), None),
        },
        Some(h) => (Some(h), None),
        None => (None, swap()),
    };
    if let Some((w, rival)) = higher {
        let why = format!(
            "a curvature of order {} (K'(u) to u^{}, its term {:.3e} per V^{}) without the \
             scale of {:.4} leaves {:.2} mV against {:.2} mV (and {:.2} mV with the scale \
             beside the order below, as many parameters), and in no record more than \
             {STATIC_TELL_RATIO}x as much above the floor: over these records the scale is a \
             part of the curvature's shape; small steps from rest at 0 V beside large ones \
             (the recommended protocol) show the gain at small inputs, which a scale moves and \
             a curvature does not",
            w.order,
            w.order,
            w.top_term,
            w.order,
            w.scale,
            1e3 * rms_of(&w.mse),
            1e3 * rms_of(&cur_mse),
            1e3 * rms_of(&rival)
        );
        (model, sims, cur_mse) = curvature_takes_up(
            "sensor-gain",
            w,
            why,
            &cur_mse,
            (&mut steps, &mut ambiguous, &mut named),
        );
    } else if let Some((w, v)) = swap {
        // Where it does not, the scale may stand in an offset's place: like for like (each
        // beside the curvature of one more order, as many parameters), an offset that leaves
        // less in every record is the likelier, and takes the scale's place; where the scale
        // leaves no more than the look-alike bar above it in any record, the records cannot
        // tell the two, and the pair is reported.
        let offset_v = w.model.offset.as_ref().map_or(0.0, |o| o.offset_v);
        let what = format!("an offset of {:.1} mV in the scale's place", 1e3 * offset_v);
        (model, sims, cur_mse) = like_for_like_swap(
            ("sensor-gain", "offset", what),
            (w, &v.mse),
            (&var, &cur_mse),
            (&mut steps, &mut ambiguous, &mut named),
        );
    }
    // Step 14 (c): an offset beside a curvature that a curvature of higher order does
    // without, by the same one-sided bars and orders, is a part of the curvature's shape over
    // records that stay away from 0 V (a knee or a plateau near one end of the span bends the
    // quadratic's ends, and a constant takes up the part it leaves there).
    if let Some((w, rival)) = curvature_in_place_of(
        |order| scale_order::curvature_in_offsets_place(&model, &named, data, order),
        (&model, &named, data),
        &cur_mse,
        &var,
    ) {
        let offset_v = model.offset.as_ref().map_or(0.0, |o| o.offset_v);
        let why = format!(
            "a curvature of order {} (K'(u) to u^{}, its term {:.3e} per V^{}) without the \
             offset of {:.1} mV leaves {:.2} mV against {:.2} mV (and {:.2} mV with the offset \
             beside the order below, as many parameters), and in no record more than \
             {STATIC_TELL_RATIO}x as much above the floor: over these records the constant is \
             a part of the curvature's shape; a rest at 0 V at a record's start (the \
             recommended protocol) reads the sensor's zero, which a curvature does not move",
            w.order,
            w.order,
            w.top_term,
            w.order,
            1e3 * offset_v,
            1e3 * rms_of(&w.mse),
            1e3 * rms_of(&cur_mse),
            1e3 * rms_of(&rival)
        );
        (model, sims, cur_mse) = curvature_takes_up(
            "offset",
            w,
            why,
            &cur_mse,
            (&mut steps, &mut ambiguous, &mut named),
        );
    }
    // Step 14 (d): the mirror of (b), a scale in an offset's place. The steps score a scale
    // and an offset beside the catalogue's quadratic K'(u), which has no term linear in the
    // input: beside a curvature of another shape (a tanh, a softplus) that the quadratic
    // bends to, a constant took up what a true scale left (families cases 3232, 3305, 3365 and
    // 3419: a scale 0.5-3 % off 1 beside a curvature, named as an offset). Like for like (each
    // beside the cubic, as many parameters), a scale that leaves less in every record, and no
    // record more than the model as it stands, takes the offset's place; where the offset
    // leaves no more than the look-alike bar above it in any record, the records cannot tell
    // the two, and the pair is reported.
    if let (Some(w), Some(v)) = (
        scale_order::scale_in_offsets_place(&model, &named, data, scale_order::CUBIC),
        scale_order::refit_order(&model, &named, data, scale_order::CUBIC),
    ) && less_in_every_record(&w.mse, &v.mse)
        && no_record_worse(&w.mse, &cur_mse)
    {
        let offset_v = model.offset.as_ref().map_or(0.0, |o| o.offset_v);
        let what = format!(
            "a scale of {:.4} in the place of the offset of {:.1} mV",
            w.scale,
            1e3 * offset_v
        );
        (model, sims, cur_mse) = like_for_like_swap(
            ("offset", "sensor-gain", what),
            (w, &v.mse),
            (&var, &cur_mse),
            (&mut steps, &mut ambiguous, &mut named),
        );
    }
    // Step 14 (e) on records that read no zero at rest: the curvature's order raised with the
    // names settled (above).
    if !zero_read && let Some(w) = curvature_order(&model, &named, data, &cur_mse, &var) {
        (model, sims, cur_mse) = take_curvature_order(w, &cur_mse, &mut steps);
    }
    let mut cannot_tell = cannot_tell(&model, base, &named, data, &slow_x, u_range, &cur_mse);
    // A pair left unnamed at one step whose shape a later step named (told apart then, by the
    // held levels or because the rival no longer explained alike), or the same step beside an
    // offset, is no longer a pair the records cannot tell.
    // A drift that gave way stays reported unless a later step named it.
    ambiguous.retain(|c| {
        if c.neither_named {
            !named.contains(&c.named) && !named.contains(&c.alternative)
        } else {
            // (a drift that gave way to a shape a later look-alike step dropped: that step's
            // own pair says so; a pair the final check made beside a table the final check
            // took out later no longer stands)
            !named.contains(&c.alternative)
                && (c.alternative != "drift" || named.contains(&c.named))
                && (c.taken_out == TakenOut::No || named.contains(&c.named))
        }
    });
    cannot_tell.extend(ambiguous);
    // Step 12: an offset that is the settled creep at the records' first input taken back is
    // the drift's start (the creep counts from the first input), not the sensor's zero: the
    // constant moves into `[drift] unsettled_v` (the same readings), the offset is no longer
    // named, and the pair is reported as one the records cannot tell. After the look-alike
    // pairs are settled on the named set with the offset (the drift's rival refitted beside
    // it, and a pair the offset's naming told apart stays dropped).
    if let Some(c) = creep_start(&model, &named, data, &noise)
        && offset_into_drift_start(&mut model, &c).is_some()
    {
        named.retain(|n| n != "offset");
        // (the lags slower than a third of the record leave a span: say it)
        let (of, within) = if (c.pinned_v - c.creep_v).abs() > 1e-9 {
            (
                format!(
                    ", {:.1} mV of it the lags faster than a third of the record's, whose start \
                     the record pins",
                    1e3 * c.pinned_v
                ),
                "of the span between the two",
            )
        } else {
            (String::new(), "of it")
        };
        let why = format!(
            "the offset fitted at {:.1} mV is the model's settled creep at the records' first \
             input ({:.1} mV at {:.2} V{of}) taken back, within {:.0} % {within}: a stage whose \
             creep counts from that input (not settled there, as the model's drift starts) reads \
             so, as would a sensor offset of that size; kept as the drift's start ([drift] \
             unsettled_v); a rest at 0 V before the records, or records that start at other \
             inputs, tell them apart",
            1e3 * c.offset_v,
            1e3 * c.creep_v,
            c.first_input_v,
            100.0 * CREEP_START_SHARE
        );
        // (a pair that named the offset no longer stands: it is not named)
        cannot_tell.retain(|k| k.neither_named || k.named != "offset");
        offset_moved(
            (&mut steps, &mut cannot_tell),
            "drift",
            why,
            (&cur_mse, &cur_mse),
            &sims,
        );
    }
    // Step 13a: on records that read no sensor zero, the table's level and a sensor offset
    // are one constant to the records; where the fitted start memory is a scan that died away
    // at the records' first input (a stage at rest, demagnetised there), the table sits on its
    // reversible map at that first sample, and the level it holds beyond it is the sensor's
    // offset (GAP.md, step 13a): moved out of the table (the same readings) and named where it
    // is START_LEVEL_FLOORS noise floors or more and the model explains every record (no
    // `unexplained` part: a table that misses a record's loop or scale reads its level wrong).
    let table_low_v = slow_x.range().0;
    let mut start_level_named = false;
    if named.iter().any(|n| n == "hysteresis")
        && slow_x.form() != CentreLine::Span
        && reads_no_zero(data, table_low_v)
        && (named.iter().any(|n| n == "offset") || !catalogue::present(&model, "offset"))
        && locate(data, &sims, &noise, &cycle_bar).0.is_none()
        && let Some((moved, offset_v)) = start_level_into_offset(&model, data, slow_x.table_gain())
        && offset_v.abs() >= START_LEVEL_FLOORS * noise_floor_v
        && let Ok((moved_sims, moved_mse)) = simulate_all(&moved, data)
        && same_readings(&moved_sims, &sims, &noise, adc_code_v(&model))
        && centred_start_told(&model, data, &slow_x, u_range, &cur_mse)
    {
        let before_v = model.offset.as_ref().map_or(0.0, |o| o.offset_v);
        let why = format!(
            "the fitted start memory is a scan that died away at the records' first input (a \
             stage at rest there sits on its reversible map), and the table held {:.1} mV over \
             that map at the first sample: a level its relays these records never switch hold \
             as well as a sensor offset, read as the sensor's ([offset] {:.1} mV -> {:.1} mV, \
             the same readings); {ZERO_READING_TELLS}",
            1e3 * (offset_v - before_v),
            1e3 * before_v,
            1e3 * offset_v
        );
        if !named.iter().any(|n| n == "offset") {
            steps.push(Step::new(
                "offset".into(),
                why,
                &cur_mse,
                &moved_mse,
                moved_sims.clone(),
            ));
            named.push("offset".into());
        }
        cannot_tell.retain(|k| k.alternative != "offset" && k.named != "offset");
        model = moved;
        sims = moved_sims;
        cur_mse = moved_mse;
        start_level_named = true;
    }
    // Step 13: an offset named beside a table on records that read no sensor zero is a
    // constant the table holds as well (its relays the records never switch, its start
    // memory): the records cannot tell the two, and which one the fit used depends on the
    // split (the band split's table has no constant of its own to take it; families case
    // 1044, a Preisach plane with no sensor offset on a chirp, named a false 71 mV offset). The
    // constant moves into the table's own output level (`[hysteresis] offset_v`, the same
    // readings), the offset is no longer named, and the pair is reported as one the records
    // cannot tell, as the standing note below says where no offset was fitted.
    if !start_level_named
        && named.iter().any(|n| n == "hysteresis")
        && named.iter().any(|n| n == "offset")
        && reads_no_zero(data, table_low_v)
        && let Some((moved, table_shift_v)) = offset_into_table(&model)
        && let Ok((moved_sims, moved_mse)) = simulate_all(&moved, data)
        && same_readings(&moved_sims, &sims, &noise, adc_code_v(&model))
    {
        let offset_v = model.offset.as_ref().map_or(0.0, |o| o.offset_v);
        let why = format!(
            "{STANDING_OFFSET_NOTE}: the offset fitted at {:.1} mV beside the table is a \
             constant that the table's relays these records never switch, and its start \
             memory, hold as well; kept as the table's own level ([hysteresis] offset_v moved \
             by {:.1} mV, the same readings); {ZERO_READING_TELLS}",
            1e3 * offset_v,
            1e3 * table_shift_v
        );
        // (a pair in which a shape gave way to the offset no longer stands: the offset is
        // not named)
        cannot_tell.retain(|k| k.named != "offset");
        offset_moved(
            (&mut steps, &mut cannot_tell),
            "hysteresis",
            why,
            (&cur_mse, &moved_mse),
            &moved_sims,
        );
        named.retain(|n| n != "offset");
        model = moved;
        sims = moved_sims;
        cur_mse = moved_mse;
    }
    // Step 21 (before step 20): static shapes that are the table's own centre line. Each
    // element of the band and rise splits leaves out `clamp(u, band)`, which is its own
    // centre line only where the bands beside it weigh alike; where a Preisach density
    // changes along the range the fitted table's centre line bends with the weights, and
    // `nonlinear-gain` takes the bend back (families cases 3450 and 3512: a Lorentz plane
    // with its centre curve taken out, on random levels). The span split's elements leave out
    // their centre line over the records' span, not over the table's range, and a narrow
    // plane's misfit there was taken up by a curvature, a scale and an offset together
    // (families cases 8139 and 8286, on the identification protocol; session 60). The
    // own-line split (`CentreLine::with_own_line`) holds the band split's relays, each element
    // less its own centre line over the table's range: a loop about a straight centre line,
    // the catalogue's division. The named effects are refitted on it with and without the
    // static shapes. Where they still earn their place there (the final check's growth bar),
    // they are the records' and stay. Else, where the model without them leaves no more over
    // the records and in none more than the split named with them, they were the basis', not
    // the records': they are taken out, the table refitted on the own-line split, and the
    // pairs reported. Only on records whose held levels are reached from both sides
    // (`levels_from_both_sides`): on one sine a table of wide relays bends its minor loops'
    // centre line, and there the own-line split took the thesis stage's true K'(u) into the
    // table (GAP.md, session 52).
    // The static shapes tested: the named ones, all together (a shape taken out alone has
    // its work done by the others', as in step 17); not an offset on records that read no
    // sensor zero (step 13's, as step 17 leaves it). Not one at a time as well: each unit
    // costs a refit and a start search, and on the gap bench's records (150 s at 1 kHz) the
    // group and its two shapes alone took the diagnosis from 5.9 s to 14.0 s (target 10 s);
    // families cases 8139 and 8286 went as a group.
    let statics = statics_to_tell(&named, data, slow_x.range().0);
    if named.iter().any(|n| n == "hysteresis")
        && !statics.is_empty()
        && !start_level_named
        && levels_from_both_sides(data)
        && let Some(own) = slow_x.form().with_own_line()
    {
        // (where the group earns its place: the named model refitted beside the own-line
        // table, its simulations and mean squares, and the regressors it stands on)
        let mut kept: Option<(Fitted, SlowRegressors)> = None;
        'group: {
            let own_x = slow_x.with_form(data, own);
            let mut without = model.clone();
            for e in &statics {
                without = catalogue::revert(&without, base, e);
            }
            let Some(m) = refit_slow(&without, &[], data, &own_x, u_range) else {
                break 'group;
            };
            let Ok((s, ms)) = simulate_all(&m, data) else {
                break 'group;
            };
            let (m, s, ms, x) = match start::search(&m, data, &own_x, u_range, &ms) {
                Some(f) => (f.model, f.sims, f.mse, f.slow_x),
                None => (m, s, ms, own_x),
            };
            // The named model refitted beside the own-line table, from the group's start
            // memory (a search of its own would cost as much as the group's): true shapes
            // still do their work there, and stay by the final check's own test (without them
            // the residual above the floor grows by their bar); the table then stands on the
            // own-line split where that leaves less in every record (families case 3594, an
            // exponential K'(u) beside a Gaussian plane: 1.01 mV against 1.61 mV on the band
            // split, the floor 1.02 mV).
            if let Some(w) = refit_slow(&model, &[], data, &x, u_range)
                && let Ok((ws, wms)) = simulate_all(&w, data)
                && growth_above_floor(&ms, &wms, &var) >= prune_bar(&statics)
            {
                kept = Some(((w, ws, wms), x));
                break 'group;
            }
            if !(in_noise_vars(&ms, &var) <= in_noise_vars(&cur_mse, &var)
                && no_record_worse(&ms, &cur_mse))
            {
                break 'group;
            }
            let (what, them, were) = if statics.len() > 1 {
                (statics.join(" and "), "them", "were")
            } else {
                (statics[0].clone(), "it", "was")
            };
            let why = format!(
                "the table's own centre line: the {} split (the same relays, each element less \
                 its own centre line over the table's range instead of clamp(u, band) or the \
                 records' span) refitted without {what} leaves {:.2} mV against {:.2} mV with \
                 {them}: the bend {were} the table's centre line moving with its weights, not \
                 the records'",
                own.describe().0,
                1e3 * rms_of(&ms),
                1e3 * rms_of(&cur_mse)
            );
            for e in &statics {
                cannot_tell.push(CannotTell {
                    named: "hysteresis".into(),
                    alternative: e.clone(),
                    neither_named: false,
                    taken_out: TakenOut::No,
                    rms_v: rms_of(&ms),
                    alternative_rms_v: rms_of(&cur_mse),
                    why: format!(
                        "{what} beside the {} split's table left {:.2} mV; the table whose \
                         elements leave out their own centre line leaves {:.2} mV without \
                         {them}, and beside that table {them} do not earn {} parameters: a \
                         Preisach density that changes along the range bends the centre line \
                         of the records' loops as a static map does, and these records are \
                         fitted as well by the loop alone, so {what} {} not named",
                        slow_x.form().describe().0,
                        1e3 * rms_of(&cur_mse),
                        1e3 * rms_of(&ms),
                        if statics.len() > 1 { "their" } else { "its" },
                        if statics.len() > 1 { "are" } else { "is" },
                    ),
                });
                steps.push(Step {
                    removed: true,
                    ..Step::new(e.clone(), why.clone(), &cur_mse, &ms, s.clone())
                });
            }
            named.retain(|n| !statics.contains(n));
            slow_x = x;
            model = m;
            sims = s;
            cur_mse = ms;
        }
        if let Some(((w, ws, wms), x)) = kept
            && less_in_every_record(&wms, &cur_mse)
        {
            let why = format!(
                "the table's own centre line: the {} split (the same relays, each element \
                 less its own centre line over the table's range) refitted with the named \
                 effects leaves {:.2} mV against {:.2} mV; {} stay beside it",
                own.describe().0,
                1e3 * rms_of(&wms),
                1e3 * rms_of(&cur_mse),
                statics.join(" and ")
            );
            steps.push(Step {
                params: params_json(&w, "hysteresis"),
                refit: true,
                ..Step::new("hysteresis".into(), why, &cur_mse, &wms, ws.clone())
            });
            slow_x = x;
            model = w;
            sims = ws;
            cur_mse = wms;
        }
    }
    // Step 20 (before step 19, which refits the table that stands): the table's density
    // between its bands. The band and rise splits' density is constant across each band, so a
    // loop whose density changes smoothly along the range (a Preisach plane) is fitted in
    // steps; their tent splits (`CentreLine::with_tents`) hold the same relays with a density
    // that is linear between the bands' centres. The named slow effects are refitted on it and
    // the start memory searched again; kept where that leaves less over the records and in
    // none more, as a refit of the named table (no effect is named or taken out: the names
    // were settled on the bands). Not after step 13a: the offset it read from the table's
    // level at the start would be refitted with the tents' table, which takes the constant
    // (issue #12's single sine, seed 22: 20.0 mV for the truth's 21.3 mV became 2.2 mV,
    // `single_sine_record_names_hysteresis_and_its_start`). Where step 19 then finds no
    // centre line on the tents' table but finds one on the bands' that ends lower, the bands'
    // table and step 19 stand instead (families cases 3163 and 3260, a Bouc-Wen loop and a sensor scale: the tents' refit took
    // part of the centre line's work, step 19 then explained too little to fold, and the pair
    // went unreported at a higher final residual).
    // (the model, simulations, mean squares and regressors before the tents, and the step
    // count then)
    type BeforeTents = (ModelFile, Vec<Vec<f64>>, Vec<f64>, SlowRegressors, usize);
    let mut before_tents: Option<BeforeTents> = None;
    if named.iter().any(|n| n == "hysteresis")
        && !start_level_named
        && let Some(tents) = slow_x.form().with_tents()
        && !at_floor_now(&cur_mse, &var)
        && let tent_x = slow_x.with_form(data, tents)
        && let Some(m) = refit_slow(&model, &[], data, &tent_x, u_range)
        && let Ok((s, ms)) = simulate_all(&m, data)
    {
        let (m, s, ms, x) = match start::search(&m, data, &tent_x, u_range, &ms) {
            Some(f) => (f.model, f.sims, f.mse, f.slow_x),
            None => (m, s, ms, tent_x),
        };
        if in_noise_vars(&ms, &var) < in_noise_vars(&cur_mse, &var)
            && no_record_worse(&ms, &cur_mse)
        {
            let why = format!(
                "the table's density between its bands: the {} split (the same relays, a \
                 density linear between the bands' centres instead of constant across each \
                 band) refitted with the named effects leaves {:.2} mV against {:.2} mV",
                tents.describe().0,
                1e3 * rms_of(&ms),
                1e3 * rms_of(&cur_mse)
            );
            let bands_x = std::mem::replace(&mut slow_x, x);
            before_tents = Some((
                model.clone(),
                sims.clone(),
                cur_mse.clone(),
                bands_x,
                steps.len(),
            ));
            steps.push(Step {
                params: params_json(&m, "hysteresis"),
                refit: true,
                ..Step::new("hysteresis".into(), why, &cur_mse, &ms, s.clone())
            });
            model = m;
            sims = s;
            cur_mse = ms;
        }
    }
    // Step 19: the table's own scale and constant. With a table named and neither a sensor
    // scale nor an offset named or in the model (step 17 took them out as untold, the final
    // check took them out below their bars, or no step offered them as a pair), a scale and a
    // constant fitted together beside the table that explain MIN_EXPLAINED of the residual
    // power above the floor (as a step's candidate must; their growth is no bar here: they
    // are not named, and a record's hum left in it compresses growths: families case 3003
    // with 2.2 mV of hum, `recording_artefacts_leave_the_diagnosis_as_it_was`) and leave no
    // record worse are the records' centre line, which the band and rise
    // splits hold at the base model's: a lab's calibration of a sensor to a model leaves such
    // a line (issue #12's measured record: a 1.7 % scale about mid-range). The records do not
    // tell it from a sensor's scale and zero (no held levels reached from both sides, no rest
    // at 0 V: step 17), so neither is named; its work moves into the table's own map (the
    // Everett values and the table's level times the scale, the drift's gains with them, the
    // constant into the table's level: the same readings), and the pairs are reported.
    // (the model, its simulations and mean squares, the step and the pairs it reports)
    type CentreStep = (ModelFile, Vec<Vec<f64>>, Vec<f64>, Step, Vec<CannotTell>);
    let centre_step =
        |model: &ModelFile, cur_mse: &[f64], slow_x: &SlowRegressors| -> Option<CentreStep> {
            if !(named.iter().any(|n| n == "hysteresis")
                && !named.iter().any(|n| n == "sensor-gain" || n == "offset")
                && !catalogue::present(model, "sensor-gain")
                && !catalogue::present(model, "offset")
                && model.drift.as_ref().is_none_or(|d| d.unsettled_v.is_none())
                && !at_floor_now(cur_mse, &var))
            {
                return None;
            }
            let (with, with_sims) = centre_line_fit(model, data, slow_x, u_range, &var)?;
            let scale = with.sensor_gain.as_ref().map(|g| g.gain)?;
            let folded = centre_line_into_table(&with)?;
            let (folded_sims, folded_mse) = simulate_all(&folded, data).ok()?;
            if !same_readings(&folded_sims, &with_sims, &noise, adc_code_v(&with)) {
                return None;
            }
            let all: Vec<usize> = (0..cur_mse.len()).collect();
            let share = explained_share(cur_mse, &folded_mse, &var, &all);
            if share < MIN_EXPLAINED || !no_record_worse(&folded_mse, cur_mse) {
                return None;
            }
            let offset_v = with.offset.as_ref().map_or(0.0, |o| o.offset_v);
            let why = format!(
                "the records' centre line: a scale of {scale:.4} and a constant of {:.1} mV \
             fitted together beside the table leave {:.2} mV against {:.2} mV ({:.0} % of the \
             residual power above the floor); neither a sensor scale nor an offset was \
             named (the final check or step 17 took them out, or no step offered the two \
             together), so the table's own map holds them (its values and level times the \
             scale, the constant into its level: the same readings), and a sensor's scale \
             and zero are not told from the loop's own centre line; held levels reached \
             from both sides (the recommended protocol) tell a static map from the loop's, \
             and {ZERO_READING_TELLS}",
                1e3 * offset_v,
                1e3 * rms_of(&folded_mse),
                1e3 * rms_of(cur_mse),
                100.0 * share
            );
            let mut params = serde_json::Map::new();
            params.insert("centre_scale".into(), scale.into());
            params.insert("centre_offset_v".into(), offset_v.into());
            let step = Step {
                params,
                refit: true,
                ..Step::new(
                    "hysteresis".into(),
                    why.clone(),
                    cur_mse,
                    &folded_mse,
                    folded_sims.clone(),
                )
            };
            let pairs = ["sensor-gain", "offset"]
                .into_iter()
                .map(|alternative| CannotTell {
                    named: "hysteresis".into(),
                    alternative: alternative.into(),
                    neither_named: false,
                    taken_out: TakenOut::No,
                    rms_v: rms_of(&folded_mse),
                    alternative_rms_v: rms_of(cur_mse),
                    why: why.clone(),
                })
                .collect();
            Some((folded, folded_sims, folded_mse, step, pairs))
        };
    let mut centred = centre_step(&model, &cur_mse, &slow_x);
    // (step 20's tents kept, and no centre line on their table: the bands' table's, if it
    // ends lower)
    if centred.is_none()
        && let Some((m0, s0, ms0, x0, at)) = before_tents
        && let Some(r) = centre_step(&m0, &ms0, &x0)
        && in_noise_vars(&r.2, &var) < in_noise_vars(&cur_mse, &var)
    {
        steps.truncate(at);
        model = m0;
        sims = s0;
        cur_mse = ms0;
        slow_x = x0;
        centred = Some(r);
    }
    if let Some((folded, folded_sims, folded_mse, step, pairs)) = centred {
        steps.push(step);
        for pair in pairs {
            cannot_tell.retain(|k| !(k.named == "hysteresis" && k.alternative == pair.alternative));
            cannot_tell.push(pair);
        }
        model = folded;
        sims = folded_sims;
        cur_mse = folded_mse;
    }
    // Never silent on an offset the records cannot see: with a table named, no offset named
    // or reported, no record that starts at rest at 0 V (the reading that is the sensor's
    // zero, above) and none that goes down to the table's low end (where every relay is off
    // and the table reads nothing of its own), a sensor offset is a constant that the table's
    // relays the records never switch, and its start memory, take up as well. Said where an
    // offset fitted beside the table leaves within CANNOT_TELL_RATIO of what the model leaves
    // (the records do not pin it).
    if named.iter().any(|n| n == "hysteresis")
        && !named.iter().any(|n| n == "offset")
        && !catalogue::present(&model, "offset")
        && !cannot_tell
            .iter()
            .any(|k| k.alternative == "offset" || k.named == "offset")
        && reads_no_zero(data, table_low_v)
        && let Some(with) = refit_slow(&model, &["offset"], data, &slow_x, u_range)
        && let Ok((_, mse_with)) = simulate_all(&with, data)
        && leave_within(&mse_with, &cur_mse, &var, CANNOT_TELL_RATIO)
    {
        let fitted_v = with.offset.as_ref().map_or(0.0, |o| o.offset_v);
        cannot_tell.push(CannotTell {
            named: "hysteresis".into(),
            alternative: "offset".into(),
            neither_named: false,
            taken_out: TakenOut::No,
            rms_v: rms_of(&cur_mse),
            alternative_rms_v: rms_of(&mse_with),
            why: format!(
                "{STANDING_OFFSET_NOTE}: a sensor offset is a constant that the table's relays \
                 these records never switch, and its start memory, hold too, and the records \
                 do not pin it (an offset fitted beside the table comes to {:.1} mV and leaves \
                 {:.2} mV against {:.2} mV); {ZERO_READING_TELLS}",
                1e3 * fitted_v,
                1e3 * rms_of(&mse_with),
                1e3 * rms_of(&cur_mse)
            ),
        });
    }
    let (unexplained, cycle_notes) = locate(data, &sims, &noise, &cycle_bar);
    // (never silent: where the twin kept a table out at a step and the records end with an
    // unexplained part and no table named, the loop and a map of the input alone explained
    // them alike, and the catalogue's curvature is the one memoryless shape it names: say so,
    // with what each left then. Families case 3219, a Preisach loop and a scale on random
    // levels that reach each of their nine levels once: the table explained all but 3e-6 of
    // the residual above the floor and a map through the nine levels all of it, and nothing
    // was named or reported at 227x the floor.)
    if let Some((t_ex, twin_ex, t_rms, twin_rms)) = twin_untold
        && unexplained.is_some()
        && !named.iter().any(|n| n == "hysteresis")
    {
        // (the curvature is the named side where a step named it)
        let curve_named = named.iter().any(|n| n == "nonlinear-gain");
        let (one, other, rms_v, alternative_rms_v) = if curve_named {
            ("nonlinear-gain", "hysteresis", twin_rms, t_rms)
        } else {
            ("hysteresis", "nonlinear-gain", t_rms, twin_rms)
        };
        cannot_tell.push(CannotTell {
            named: one.into(),
            alternative: other.into(),
            neither_named: !curve_named,
            taken_out: TakenOut::No,
            rms_v,
            alternative_rms_v,
            why: format!(
                "a hysteresis table would explain {:.1} % of the residual power above the noise \
                 floor (leaving {:.2} mV) and a map of the input alone (a curvature on the \
                 table's nodes, finer than K'(u)'s) {:.1} % ({:.2} mV): what the map leaves \
                 shows no loop, nor held levels apart by the direction into them, so the \
                 records show no memory a map cannot follow, and the loop is not named; levels \
                 reached from both sides (the recommended protocol) tell a loop from a curve",
                100.0 * t_ex,
                1e3 * t_rms,
                100.0 * twin_ex,
                1e3 * twin_rms
            ),
        });
    }
    let final_rms_v = (cur_mse.iter().sum::<f64>() / cur_mse.len() as f64).sqrt();
    let mut noise_notes = setup.noise_notes.clone();
    noise_notes.extend(cycle_notes);
    Ok(Diagnosis {
        named,
        steps,
        record_noise_v: noise,
        noise_notes,
        glitches: setup.glitches.clone(),
        hum: setup.hum.clone(),
        noise_floor_v,
        final_rms_v,
        record_final_rms_v: cur_mse.iter().map(|m| m.sqrt()).collect(),
        base_sims: base_sims.clone(),
        model,
        tried,
        not_searched,
        signatures: base_sigs.clone(),
        unexplained,
        cannot_tell,
        centre_line,
    })
}

/// The diagnosis kept of both splits', when the loop alone could not choose between them: the
/// one that explains every record (within 2x its floor, or of the bar the noise between a
/// periodic input's cycles sets where that is larger: no `unexplained` part) where only one
/// does, else the one that names fewer effects, and of two that name as many, the one that
/// ends lower. The split is a choice the records did not make, so the residuals the two leave
/// (at several times the floor, a loop of another form's misfit, not noise) are not evidence
/// for the extra names one of them gives: a Bouc-Wen loop under the `Band` split left a misfit
/// that an `offset` of 279 mV and a `sensor-gain` of 0.82 took, beside the true
/// `nonlinear-gain` the `Span` split's diagnosis named alone. Which names the other gave is kept with the choice
/// ([`CentreChoice::by_diagnosis`]).
///
/// A `drift` is not counted where the records' holds show tails of [`DRIFT_TAIL_KEEP_NOISE`]
/// floors or more under the base model (its signatures, before either split): the creep's own
/// signature, evidence the records give whichever split is kept, as the final check and the
/// swaps read it ([`tails_back`]). Measured in session 43: a Duhem loop that runs backwards
/// beside a log creep on the identification protocol (test
/// `a_creep_and_a_loop_together_are_both_named`, seed 4002, tails of 98.7 mV over a 0.99 mV
/// floor) was diagnosed `hysteresis` and `drift` under the band split and `hysteresis` alone
/// under the span split, at about twice the band's residual power; which one the span split
/// gave beside its table (an offset or nothing) turned on the last bits of the simulation, and
/// with it whether the drift was named.
fn fewer_names(var: &[f64], a: Diagnosis, b: Diagnosis) -> Diagnosis {
    let (fa, fb) = (a.final_noise_var(var), b.final_noise_var(var));
    let tails = creep_tails_shown(&a.signatures);
    let counted = |d: &Diagnosis| {
        d.named
            .iter()
            .filter(|n| !(tails && n.as_str() == "drift"))
            .count()
    };
    // A diagnosis that explains every record (no `unexplained` part) is kept before one that
    // does not, whatever it names: the thesis stage's 1 Hz sine over 0.5-9.5 V (10 s at 5 kHz)
    // ended at 1.53x the floor with drift, hysteresis and its curvature under the span split,
    // and at 6.7x with drift and hysteresis under the band split, which fewer names alone
    // kept; with 4.5 mV of red noise added (AR(1), 0.2 s) the first ended at 2.2x the floor
    // read from the fast part, and only the bar the noise between the input's cycles sets
    // (3.9 mV, `cycle_noise`) told that it explains the record. (an infinite or NaN residual never
    // wins a tie: `total_cmp` puts NaN last)
    let b_first = a
        .unexplained
        .is_none()
        .cmp(&b.unexplained.is_none())
        .then(counted(&b).cmp(&counted(&a)))
        .then(fb.total_cmp(&fa))
        .is_lt();
    let (mut keep, other, other_sum) = if b_first { (b, a, fa) } else { (a, b, fb) };
    keep.centre_line.by_diagnosis = Some(SplitRival {
        split: other.centre_line.chosen,
        named: other.named,
        final_noise_var: other_sum,
    });
    keep
}

/// The slow effects `m` has, in the catalogue's order (the set [`refit_slow`] refits).
fn present_slow(m: &ModelFile) -> Vec<&'static str> {
    SLOW.iter()
        .copied()
        .filter(|e| catalogue::present(m, e))
        .collect()
}

/// The slow effects in `m` a refit fits: those present less the base's own the diagnosis
/// holds ([`SlowRegressors::held`]).
fn fitted_slow(m: &ModelFile, slow_x: &SlowRegressors) -> Vec<&'static str> {
    let held = slow_x.held(m);
    present_slow(m)
        .into_iter()
        .filter(|e| !held.contains(e))
        .collect()
}

/// The parameters of `effect` in `m`, as a step's JSON holds them.
fn params_json(m: &ModelFile, effect: &str) -> serde_json::Map<String, serde_json::Value> {
    catalogue::params_of(m, effect)
        .into_iter()
        .map(|(k, v)| (k, serde_json::json!(v)))
        .collect()
}

/// The residual RMS over records of per-record mean squares, volts.
fn rms_of(mse: &[f64]) -> f64 {
    (mse.iter().sum::<f64>() / mse.len().max(1) as f64).sqrt()
}

/// Is every record within [`STOP_FLOOR_RATIO`] of its noise floor?
fn at_floor_now(cur_mse: &[f64], var: &[f64]) -> bool {
    cur_mse
        .iter()
        .zip(var)
        .all(|(m, v)| *m <= STOP_FLOOR_RATIO * STOP_FLOOR_RATIO * v)
}

/// How much the residual above the noise floor grows from `cur_mse` to `ms` (the final
/// check's growth): over the records, the largest ratio of the RMS above the floor, the
/// floor's own variance `var` taken out of each mean square (what is left above it counted
/// as at least a fiftieth of a noise variance, so that a model at the floor gives a finite
/// ratio).
fn growth_above_floor(ms: &[f64], cur_mse: &[f64], var: &[f64]) -> f64 {
    (0..ms.len())
        .map(|i| {
            let f = (cur_mse[i] - var[i]).max(0.02 * var[i]);
            ((ms[i] - var[i]).max(0.0) / f).sqrt()
        })
        .fold(0.0f64, f64::max)
}

/// The final check's bar for removing `unit`: the growth of the residual above the floor
/// that its parameters must earn.
fn prune_bar(unit: &[String]) -> f64 {
    PRUNE_RATIO
        + PRUNE_PER_PARAM
            * unit
                .iter()
                .map(|e| catalogue::param_count(e) as f64)
                .sum::<f64>()
}

/// Held levels a record must show for `held_level_error` to tell a scale, an offset and a
/// curvature apart: three parameters, three levels (our assumption: levels closer than
/// [`HELD_LEVEL_MIN_SEP_V`] count as one).
pub const HELD_LEVELS_MIN: usize = 3;

/// Held levels the holds reached from one side (below or above) must show for step 17's tell
/// and step 21 (our assumption, session 47: two levels give each side a slope of its own).
pub const HELD_LEVELS_PER_SIDE: usize = 2;

/// Input volts by which two held levels must differ to count as two (our assumption: a tenth
/// of a volt is a few per cent of the range a static shape bends over).
pub const HELD_LEVEL_MIN_SEP_V: f64 = 0.1;

/// The distinct input levels the records hold ([`Data::holds`], each read at the hold's
/// middle; levels closer than [`HELD_LEVEL_MIN_SEP_V`] counted once).
pub(super) fn held_levels(data: &[Data]) -> usize {
    held_levels_on(data, None)
}

/// A hold's input level: the input at its middle sample.
fn hold_level_v(d: &Data, h: &std::ops::Range<usize>) -> f64 {
    d.u_v[h.start + (h.end - h.start) / 2]
}

/// Is hold `h` of `d` on `side`: reached from below (`Some(true)`, [`reached_from_below`]),
/// from above (`Some(false)`), or any (`None`)?
fn on_side(d: &Data, h: &std::ops::Range<usize>, side: Option<bool>) -> bool {
    side.is_none_or(|up| reached_from_below(d, h) == Some(up))
}

/// [`held_levels`] over the holds on `side` ([`on_side`]).
fn held_levels_on(data: &[Data], side: Option<bool>) -> usize {
    let mut levels: Vec<f64> = Vec::new();
    for d in data {
        for h in d.holds().iter().filter(|h| on_side(d, h, side)) {
            let u = hold_level_v(d, h);
            if levels.iter().all(|l| (l - u).abs() > HELD_LEVEL_MIN_SEP_V) {
                levels.push(u);
            }
        }
    }
    levels.len()
}

/// The named static shapes a table's loop could hold (steps 17 and 21): not an offset on
/// records that read no sensor zero ([`reads_no_zero`] from `lo_v`, the table's range's
/// foot): that one moves into the table's own level (step 13), the same readings.
fn statics_to_tell(named: &[String], data: &[Data], lo_v: f64) -> Vec<String> {
    let zero_unread = reads_no_zero(data, lo_v);
    named
        .iter()
        .filter(|n| STATIC_SHAPES.contains(&n.as_str()))
        .filter(|n| !(zero_unread && n.as_str() == "offset"))
        .cloned()
        .collect()
}

/// Must the static shapes beside the named set's table be told from its loop (GAP.md step 17;
/// the final check's and the swaps' test, [`told_beside_loop`])? Where `hysteresis` is named,
/// unless the table is the span split's ([`CentreLine::Span`]: its elements leave out their
/// own centre line over the records' span, so its loop's centre line is straight, as the
/// thesis' table's is, and a shape beside it is the records' centre line's). Asked there too
/// on records with held levels from both sides (session 60), the test took a true curvature
/// and scale out (hidden-effect case 1061, 2.90 mV -> 13.79 mV); step 21 asks such shapes
/// instead whether they earn their place beside the own-line table.
fn shapes_told_beside_loop(named: &[String], form: CentreLine) -> bool {
    named.iter().any(|n| n == "hysteresis") && form != CentreLine::Span
}

/// Do the records hold levels reached from both sides, as [`told_beside_loop`] asks of them:
/// [`HELD_LEVELS_MIN`] distinct levels in all (as the pooled test asked: a scale, an offset
/// and a curvature are three parameters), [`HELD_LEVELS_PER_SIDE`] or more reached from below
/// and as many from above ([`held_levels_on`])?
fn levels_from_both_sides(data: &[Data]) -> bool {
    held_levels(data) >= HELD_LEVELS_MIN
        && [true, false]
            .into_iter()
            .all(|from_below| held_levels_on(data, Some(from_below)) >= HELD_LEVELS_PER_SIDE)
}

/// Do the records tell the static shapes beside a table from the loop's own centre line and
/// constant (GAP.md step 17)? Held levels can, reached from **both** sides: the holds reached
/// from below and those reached from above ([`reached_from_below`]) must each reach two
/// distinct levels, and the model with the shapes (`with`) must put each side's levels
/// [`STATIC_TELL_RATIO`] times nearer ([`held_level_error_from`]) than the model without them
/// (`without`, the others refitted), and all the holds [`HELD_LEVELS_MIN`] levels (a record's
/// first hold, reached from no other input, counts on neither side). A static shape moves a
/// level alike from either side; a
/// loop of another form than the table's misses its branches, and a shape that takes up one
/// branch's miss need not bring the other's levels nearer (session 47: with all holds pooled,
/// families random-levels cases 1602, 1637, 2045 and 2295 named a false scale or curvature
/// beside a loop; 1444's true scale is one the two sides no longer tell). On one sine or
/// chirp a loop of another form leaves a centre line and a constant that a scale, a
/// curvature or an offset takes up alike; on the families seeds 1000-1899 the static shapes
/// named beside a loop were right 19 times and false 26. An offset's rest at 0 V is the other
/// test (the final check asks it beside this one).
fn told_beside_loop(data: &[Data], with: &[Vec<f64>], without: &[Vec<f64>], var: &[f64]) -> bool {
    levels_from_both_sides(data)
        && [true, false].into_iter().all(|from_below| {
            match (
                held_level_error_from(data, with, var, Some(from_below)),
                held_level_error_from(data, without, var, Some(from_below)),
            ) {
                (Some(a), Some(b)) => a * STATIC_TELL_RATIO <= b,
                _ => false,
            }
        })
}

/// How far a simulation leaves the records' held levels: over every hold of the records
/// ([`Data::holds`]), the squared mean residual of the hold's second half (where a step's
/// fast effects have settled), each in its record's noise variances (`var`), summed; `None`
/// unless the holds reach [`HELD_LEVELS_MIN`] distinct input levels. A scale error moves the
/// levels in proportion to the output, an offset all alike and a curvature by the input's
/// square: at three levels or more they differ, where over one sine or chirp they are alike.
/// Measured (held levels in noise variances, the step's shape against its rival): on
/// `thesis-full`'s identification records after drift and hysteresis, `nonlinear-gain` 229
/// against `sensor-gain` 439 (the truth's K'(u): told apart, named), where the two explained
/// 79 % and 77 % of the residual power; on two hidden-effect cases whose static leftover is
/// another form's misfit (log creep, 1054; a Bouc-Wen loop, 1091) 8.3 against 7.7 and 126
/// against 133 (not told apart: neither named; naming the winner there gave three false
/// names); on `thesis-full`'s 150 s records (seed 1) the step's best, `sensor-gain`, 393
/// against `nonlinear-gain` 198 (told apart the other way: the step's shape gives way to the
/// nearer one, and the five seeds went from 18x the floor with drift and hysteresis alone to
/// the truth's names).
fn held_level_error(data: &[Data], sims: &[Vec<f64>], var: &[f64]) -> Option<f64> {
    held_level_error_from(data, sims, var, None)
}

/// Was hold `h` of `d` reached from below (the last input before it that lies more than
/// [`HELD_LEVEL_MIN_SEP_V`] from its level is lower)? `None` where no such input comes first.
fn reached_from_below(d: &Data, h: &std::ops::Range<usize>) -> Option<bool> {
    let level = hold_level_v(d, h);
    d.u_v[..h.start]
        .iter()
        .rev()
        .find(|u| (*u - level).abs() > HELD_LEVEL_MIN_SEP_V)
        .map(|u| *u < level)
}

/// [`held_level_error`] over the holds reached from below (`Some(true)`), from above
/// (`Some(false)`) or all (`None`); `None` unless those holds reach [`HELD_LEVELS_MIN`]
/// distinct levels (two for one side).
fn held_level_error_from(
    data: &[Data],
    sims: &[Vec<f64>],
    var: &[f64],
    side: Option<bool>,
) -> Option<f64> {
    let needed = if side.is_some() {
        HELD_LEVELS_PER_SIDE
    } else {
        HELD_LEVELS_MIN
    };
    if held_levels_on(data, side) < needed {
        return None;
    }
    let mut err = 0.0;
    for ((d, s), &v) in data.iter().zip(sims).zip(var) {
        for h in d.holds().iter().filter(|h| on_side(d, h, side)) {
            let from = h.start + (h.end - h.start) / 2;
            let n = (h.end - from) as f64;
            let mean = (from..h.end).map(|i| d.y_v[i] - s[i]).sum::<f64>() / n;
            err += mean * mean / v.max(1e-18);
        }
    }
    Some(err)
}

/// The hysteresis basis' centre line the records choose ([`CentreLine`]): hysteresis and
/// drift fitted from the base model with each (a drift the records hold would otherwise sit
/// in the hysteresis-only fits and decide between them: thesis-full chose `Band` by 8 % so,
/// and ended at 26x the floor), simulated on every record, the one with the lower
/// sum of mean squared residuals in noise variances kept (the `Band` one on a tie or when a
/// fit fails). Which memoryless part a table's relays carry is a property of the stage's
/// density, not of the workflow: a PI stage's loop bends its centre line near the records'
/// extremes, the thesis' table keeps it straight, and the split that fixes the wrong one
/// leaves 15-350 mV that `nonlinear-gain` and `sensor-gain` then take falsely. Where the
/// band split is kept, the rise split ([`CentreLine::Rise`]) is fitted too and kept instead
/// if it leaves less than [`RISE_CHOICE_RATIO`] of the band split's: records whose first rise
/// no start memory of the band split sets (on the single PI sines of issue #12 hysteresis and
/// drift left 1.7 to 25 noise variances with it, 129 to 235 with the band split). Returns the
/// chosen split's basis, the span or band split's (for its own diagnosis where the two leave
/// nearly as much, [`diagnose`]) and the choice.
fn choose_centre_line(
    base: &ModelFile,
    data: &[Data],
    band: SlowRegressors,
    var: &[f64],
    u_range: (f64, f64),
) -> (SlowRegressors, SlowRegressors, CentreChoice) {
    let span = band.with_form(data, CentreLine::Span);
    let score = |x: &SlowRegressors| -> f64 {
        refit_slow(base, &["hysteresis", "drift"], data, x, u_range)
            .and_then(|m| {
                data.iter()
                    .zip(var)
                    .map(|(d, v)| sim(&m, d).ok().map(|s| mse(&d.y_v, &s) / v))
                    .sum::<Option<f64>>()
            })
            .filter(|v| v.is_finite())
            .unwrap_or(f64::INFINITY)
    };
    // (the two fits side by side: each is one long drift search)
    let both = crate::util::par_map(&[&band, &span], |x| score(x));
    let (sb, ss) = (both[0], both[1]);
    let choice = |chosen, rise_noise_var| CentreChoice {
        chosen,
        band_noise_var: sb,
        span_noise_var: ss,
        rise_noise_var,
        by_diagnosis: None,
    };
    if ss < sb {
        return (span, band, choice(CentreLine::Span, None));
    }
    // The band split's first rise: the rise split kept where it leaves far less.
    let rise = band.with_form(data, CentreLine::Rise);
    let sr = score(&rise);
    if sr < RISE_CHOICE_RATIO * sb {
        (rise, span, choice(CentreLine::Rise, Some(sr)))
    } else {
        (band, span, choice(CentreLine::Band, Some(sr)))
    }
}

/// Do the simulated outputs `sims` (a model without its drift) leave tails of
/// [`DRIFT_TAIL_KEEP_NOISE`] noise floors or more during the records' holds: the creep's own
/// signature, which no static effect makes during a hold (the final check keeps such a drift,
/// and no swap takes its place)? It reads the level the model without the drift leaves, not
/// its change from the model with it: a drift named beside tails it does not reduce would stay
/// too (none in the suites: a drift is named only where it explains the records).
fn tails_back(data: &[Data], sims: &[Vec<f64>], noise: &[f64]) -> bool {
    creep_tails_shown(&signatures::compute(data, sims, noise))
}

/// Do the signatures `sg` show the creep's own signature: holds, and tails of
/// [`DRIFT_TAIL_KEEP_NOISE`] noise floors or more during them?
fn creep_tails_shown(sg: &signatures::Signatures) -> bool {
    sg.holds > 0 && sg.tail_v >= DRIFT_TAIL_KEEP_NOISE * sg.noise_v
}

/// `m` with its slow effects, and those of `extra` it lacks, fitted afresh together to the
/// residual of `m` without slow effects; `m` itself if it has none and no `extra`.
pub(super) fn refit_slow(
    m: &ModelFile,
    extra: &[&str],
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
) -> Option<ModelFile> {
    refit_slow_rounds(m, extra, data, slow_x, u_range, STRUCTURE_ROUNDS)
}

/// [`refit_slow`] with `rounds` of the structure search.
fn refit_slow_rounds(
    m: &ModelFile,
    extra: &[&str],
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
    rounds: usize,
) -> Option<ModelFile> {
    // (the base's own effects the diagnosis holds stay as they are, unless `extra` asks)
    let held = slow_x.held(m);
    let mut set = fitted_slow(m, slow_x);
    for e in extra {
        if !set.contains(e) {
            set.push(e);
        }
    }
    if set.is_empty() {
        return Some(m.clone());
    }
    let keep: Vec<&str> = held.into_iter().filter(|e| !set.contains(e)).collect();
    let b0 = catalogue::without_slow_but(m, &keep);
    let y0: Vec<Vec<f64>> = data
        .iter()
        .map(|d| sim(&b0, d))
        .collect::<anyhow::Result<_>>()
        .ok()?;
    let p = fit_slow(data, &y0, slow_x.for_set(&set), &set, u_range, rounds)?;
    catalogue::with_slow_but(m, &p, u_range, &keep)
}

/// A fitted candidate model, its simulations of the records and their mean squares.
type Fitted = (ModelFile, Vec<Vec<f64>>, Vec<f64>);

/// A rank of the cost of a slow fit of `set` (for ordering parallel jobs): the drift's
/// search and the hysteresis basis dominate, then the number of effects.
fn slow_cost(set: &[&str]) -> usize {
    4 * usize::from(set.contains(&"drift"))
        + 4 * usize::from(set.contains(&"hysteresis"))
        + set.len()
}

/// A fast effect whose search a step left out, and why.
type LeftOut = (&'static str, &'static str);

/// Fit every candidate and simulate it on every record; the fast effects left out because
/// no fit of them could pass the step's gate ([`signatures::Signatures::search_left_out`])
/// come back apart with why, for the trace.
fn candidates(
    model: &ModelFile,
    data: &[Data],
    slow_x: &SlowRegressors,
    (cur_mse, var): (&[f64], &[f64]),
    u_range: (f64, f64),
    sigs: &signatures::Signatures,
    named: &[String],
) -> anyhow::Result<(Vec<Candidate>, Vec<LeftOut>)> {
    let peak_hz = sigs.peak_hz;
    // Slow effects: one joint solve per candidate set. The base's own effects the diagnosis
    // holds (`SlowRegressors::held`) stay as they are beside a new effect; a refit of one of
    // them is its own candidate.
    let present_all = present_slow(model);
    let held = slow_x.held(model);
    let present_slow = fitted_slow(model, slow_x);
    // The held effects a set leaves in the model the slow fits start from.
    let keep_of = |set: &[&str]| -> Vec<&'static str> {
        held.iter().copied().filter(|e| !set.contains(e)).collect()
    };
    // The model without the slow effects a set fits, on every record (the slow fits' base),
    // one per distinct set of held effects kept; the common one simulated in the pool below as
    // its first job (the slow records' simulation is a core's work for a while).
    let mut keeps: Vec<Vec<&'static str>> = vec![held.clone()];
    for e in &held {
        keeps.push(held.iter().copied().filter(|h| h != e).collect());
    }
    if !held.is_empty() {
        keeps.push(Vec::new());
    }
    type Y0Cell = std::sync::OnceLock<Result<Vec<Vec<f64>>, String>>;
    let y0_cells: Vec<Y0Cell> = keeps.iter().map(|_| std::sync::OnceLock::new()).collect();
    let y0_for = |keep: &[&str]| -> anyhow::Result<&Vec<Vec<f64>>> {
        // (every set's kept effects are among these: the held ones, all but one of them, or
        // none; any other would be an error of this function, said, not a wrong base)
        let i = keeps.iter().position(|k| k == keep).ok_or_else(|| {
            anyhow::anyhow!("no model without slow effects kept for the held {keep:?}")
        })?;
        y0_cells[i]
            .get_or_init(|| {
                let base0 = catalogue::without_slow_but(model, &keeps[i]);
                data.iter()
                    .map(|d| sim(&base0, d))
                    .collect::<anyhow::Result<_>>()
                    .map_err(|e| format!("{e:#}"))
            })
            .as_ref()
            .map_err(|e| anyhow::anyhow!("{e}"))
    };
    let y0 = || y0_for(&held);
    let mut sets: Vec<(String, bool, Vec<&str>)> = SLOW
        .iter()
        .filter(|e| !present_all.contains(e))
        .map(|e| {
            let mut s = present_slow.clone();
            s.push(e);
            (e.to_string(), false, s)
        })
        .collect();
    for e in &present_all {
        // (in the catalogue's order, as the refit of everything has it: one solve for the two
        // where they are the same set)
        let s: Vec<&str> = SLOW
            .iter()
            .copied()
            .filter(|x| present_slow.contains(x) || (x == e && held.contains(e)))
            .collect();
        sets.push((e.to_string(), true, s));
    }
    // Beside each, where the diagnosis holds some of the base's own effects, the same
    // candidate with every present slow effect refitted (the base's among them): kept in the
    // held one's place only where the held one leaves some record unexplained (above
    // `UNEXPLAINED_FLOOR_RATIO` times its floor) and the refit leaves clearly less
    // (`REFIT_ALL_SHARE`): a base whose table or drift the records show to be off by more
    // than a new effect's work. A base that explains the records with the new effect stays
    // as it is: a model fitted to earlier records of the stage, given records with a 20 mV
    // offset more, had its table refitted beside the offset (leaving 0.22 of what it left
    // held), the table's constant took most of it, the offset came to 160 mV and the final
    // check took it out as a level the records do not show; held, the offset is 20 mV.
    let all_sets: Vec<Vec<&str>> = if held.is_empty() {
        Vec::new()
    } else {
        sets.iter()
            .map(|(e, _, _)| {
                let mut s = present_all.clone();
                if let Some(e) = SLOW.iter().find(|x| **x == e.as_str())
                    && !s.contains(e)
                {
                    s.push(e);
                }
                s
            })
            .collect()
    };
    // One joint solve per distinct set (every refit of a present effect shares the set of
    // the present ones), the solves in parallel.
    let mut distinct: Vec<Vec<&str>> = Vec::new();
    for set in sets.iter().map(|(_, _, set)| set).chain(&all_sets) {
        if !distinct.contains(set) {
            distinct.push(set.clone());
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
    let cur_fast_cost: f64 = fast_idx
        .iter()
        .map(|&i| log_mse_term(data[i].len() as f64, cur_mse[i]))
        .sum();
    let n_fast: f64 = fast_idx.iter().map(|&i| data[i].len() as f64).sum();
    let fast_fit = |e: &str| -> Option<ModelFile> {
        // Coordinate descent: the candidate, then the fast effects already named, then the
        // candidate again (fast effects compensate each other: a slew limit mimics a delay).
        let (mut m, mut cost) = fit_fast(model, data, &fast_idx, e, peak_hz)?;
        let others: Vec<&String> = named
            .iter()
            .filter(|n| n.as_str() != e && FAST.contains(&n.as_str()))
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
            if start - cost < n_fast * 0.02 {
                break;
            }
        }
        // Simulated in full only if it helps on the fast records (10 % of their MSE at least).
        (cost < cur_fast_cost + n_fast * (0.9f64).ln()).then_some(m)
    };
    // The fast effects searched: those the model has (refitted), and those whose fit could
    // pass the step's signature gate on this residual (`Signatures::search_left_out`: a
    // second mode without a line in the residual spectrum, a saturation of an input far from
    // the amplifier's limits, could not: the search is left out and the step is the same).
    let mut skipped: Vec<LeftOut> = Vec::new();
    let mut searched: Vec<&'static str> = Vec::new();
    for e in FAST {
        let why = if catalogue::present(model, e) {
            None
        } else {
            sigs.search_left_out(e)
        };
        match why {
            Some(w) => skipped.push((e, w)),
            None => searched.push(e),
        }
    }
    // Every slow set's joint solve and every fast effect's search, each with its simulation of
    // every record, in one pool, so that no core waits at a barrier between a phase of fits and
    // one of simulations: the slow fits' base first and the costliest fast search beside it
    // (the slow fits need the base; a second mode's search, over a hundred simulations of the
    // fast records, started near the end, kept one core busy alone at the step's end: a 10 s
    // record at 50 kHz), then the slow sets costliest first (those with the drift's search and
    // the hysteresis basis, then the larger ones), then the other fast searches.
    enum Task<'a> {
        Base,
        Slow(Vec<&'a str>),
        Fast(&'static str),
    }
    let mut by_cost = distinct.clone();
    by_cost.sort_by_key(|set| std::cmp::Reverse(slow_cost(set)));
    let first_fast = if searched.contains(&"resonance") {
        Some("resonance")
    } else {
        searched.first().copied()
    };
    let mut tasks: Vec<Task> = vec![Task::Base];
    tasks.extend(first_fast.map(Task::Fast));
    tasks.extend(by_cost.into_iter().map(Task::Slow));
    tasks.extend(
        searched
            .iter()
            .copied()
            .filter(|&e| Some(e) != first_fast)
            .map(Task::Fast),
    );
    let simulated = |m: ModelFile| -> anyhow::Result<Fitted> {
        let (sims, mse_v) = simulate_all(&m, data)?;
        Ok((m, sims, mse_v))
    };
    let done: Vec<anyhow::Result<Option<Fitted>>> = par_map(&tasks, |t| {
        let m = match t {
            Task::Base => return y0().map(|_| None),
            Task::Slow(set) => {
                let keep = keep_of(set);
                fit_slow(
                    data,
                    y0_for(&keep)?,
                    slow_x.for_set(set),
                    set,
                    u_range,
                    CANDIDATE_ROUNDS,
                )
                .and_then(|p| catalogue::with_slow_but(model, &p, u_range, &keep))
            }
            Task::Fast(e) => fast_fit(e),
        };
        m.map(simulated).transpose()
    });
    let mut slow_done: Vec<(Vec<&str>, Fitted)> = Vec::new();
    let mut fast_done: Vec<(&str, Fitted)> = Vec::new();
    for (t, r) in tasks.iter().zip(done) {
        if let Some(x) = r? {
            match t {
                Task::Base => {}
                Task::Slow(set) => slow_done.push((set.clone(), x)),
                Task::Fast(e) => fast_done.push((e, x)),
            }
        }
    }
    let candidate = |effect: &str, refit: bool, (m, sims, mse_v): &Fitted| Candidate {
        effect: effect.to_string(),
        refit,
        model: m.clone(),
        k: catalogue::param_count(effect),
        sims: sims.clone(),
        mse: mse_v.clone(),
    };
    // In the order the candidates always had: the slow effects' sets, then the fast effects.
    let mut results = Vec::new();
    // (the power a fit leaves above the records' floors)
    let excess = |ms: &[f64]| -> f64 { ms.iter().zip(var).map(|(m, v)| (m - v).max(0.0)).sum() };
    // (some record left above the bar of an unexplained part)
    let r2 = super::unexplained::UNEXPLAINED_FLOOR_RATIO.powi(2);
    let unexplained_by = |ms: &[f64]| ms.iter().zip(var).any(|(m, v)| *m > r2 * v);
    for (i, (effect, refit, set)) in sets.iter().enumerate() {
        let held_fit = slow_done.iter().find(|(s, _)| s == set).map(|(_, x)| x);
        let all_fit = all_sets
            .get(i)
            .and_then(|a| slow_done.iter().find(|(s, _)| s == a))
            .map(|(_, x)| x);
        let chosen = match (held_fit, all_fit) {
            (Some(h), Some(a))
                if unexplained_by(&h.2) && excess(&a.2) < REFIT_ALL_SHARE * excess(&h.2) =>
            {
                Some((a, true))
            }
            (Some(h), _) => Some((h, false)),
            // (the refit of everything is weighed against the held fit; without one, no
            // candidate)
            (None, _) => None,
        };
        if let Some((x, all)) = chosen {
            let mut c = candidate(effect, *refit, x);
            // (a candidate that refits the base's held effects as well is scored with their
            // parameters: the same evidence asked of naming them)
            if all {
                c.k += held
                    .iter()
                    .filter(|h| **h != effect.as_str())
                    .map(|h| catalogue::param_count(h))
                    .sum::<usize>();
            }
            results.push(c);
        }
    }
    for e in FAST {
        if let Some((_, x)) = fast_done.iter().find(|(f, _)| *f == e) {
            results.push(candidate(e, catalogue::present(model, e), x));
        }
    }
    Ok((results, skipped))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::csv::Record;

    /// Step 13's move: an offset beside a table goes into the table's own level with the
    /// same readings (every sample within the `f32` rounding) where no K'(u) scales the table,
    /// and reads differently (refused by [`same_readings`]) where the thesis' K'(u) does; a
    /// record reads the sensor's zero ([`reads_no_zero`] false) where it starts at rest at 0 V
    /// or goes down to the table's low end.
    #[test]
    fn an_offset_beside_a_table_moves_into_its_level() {
        let rate = 5e3;
        // 0.5 s of a 4 Hz sine between `lo` and 9 V, after `rest_s` at 0 V.
        let record = |lo: f64, rest_s: f64| {
            let n = ((0.5 + rest_s) * rate) as usize;
            let t: Vec<f64> = (0..n).map(|i| i as f64 / rate).collect();
            let u: Vec<f64> = t
                .iter()
                .map(|&t| {
                    if t < rest_s {
                        0.0
                    } else {
                        let x = (2.0 * std::f64::consts::PI * 4.0 * (t - rest_s)).cos();
                        lo + 0.5 * (9.0 - lo) * (1.0 - x)
                    }
                })
                .collect();
            Data::from_record(
                "sine.csv",
                Record::new(t, u.clone(), Some(u), None).unwrap(),
            )
            .unwrap()
        };
        let sine = [record(1.0, 0.0)];
        let noise = [1e-3];
        let mut model = ModelFile::built_in("thesis-full").unwrap();
        model.converters.adc = false;
        model.converters.sensor_gain = 1.05;
        model.offset = Some(crate::io::model_file::OffsetSection { offset_v: 0.03 });
        let table_lo = model.hysteresis.as_ref().unwrap().input_range_v[0];
        let sims =
            |m: &ModelFile| -> Vec<Vec<f64>> { sine.iter().map(|d| sim(m, d).unwrap()).collect() };
        // With the thesis' K'(u) (its gain changes over 1..9 V) the readings move.
        let (moved, _) = offset_into_table(&model).unwrap();
        assert!(moved.offset.is_none());
        assert!(!same_readings(&sims(&moved), &sims(&model), &noise, 0.0));
        // Without it, the same readings to the f32 rounding (and the first sample too).
        model.nonlinear_gain = None;
        let (moved, shift_v) = offset_into_table(&model).unwrap();
        let (a, b) = (sims(&moved), sims(&model));
        let worst = a[0]
            .iter()
            .zip(&b[0])
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-5, "{worst}");
        assert!(same_readings(&a, &b, &noise, 0.0));
        // The table's level moved by the offset over the sensor's scale (1.05).
        assert!((shift_v * 1.05 - 0.03).abs() < 1e-5, "{shift_v}");
        // Through the ADC the move reads the same within a code, not within a tenth of the
        // floor alone.
        model.converters.adc = true;
        let (moved, _) = offset_into_table(&model).unwrap();
        let (a, b) = (sims(&moved), sims(&model));
        assert!(same_readings(&a, &b, &noise, adc_code_v(&model)));
        // Which records read the sensor's zero.
        assert!(reads_no_zero(&sine, table_lo));
        assert!(!reads_no_zero(&[record(table_lo, 0.0)], table_lo));
        assert!(!reads_no_zero(&[record(1.0, 0.1)], table_lo));
        // (the rest alone, with the table's low end below the records' inputs)
        assert!(reads_no_zero(&sine, -0.5));
        assert!(!reads_no_zero(&[record(1.0, 0.1)], -0.5));
        assert!(!reads_no_zero(
            &[sine[0].clone(), record(1.0, 0.1)],
            table_lo
        ));
    }

    /// 2 s of a 1 Hz sine over 0.5..9.5 V at 5 kHz, read through `m` (no noise, no
    /// converters): step 14's records.
    fn sine(m: &ModelFile) -> Vec<Data> {
        sine_between(m, 0.5, 9.5)
    }

    /// [`sine`] between `lo_v` and `hi_v`.
    fn sine_between(m: &ModelFile, lo_v: f64, hi_v: f64) -> Vec<Data> {
        let rate = 5e3;
        let n = (2.0 * rate) as usize;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / rate).collect();
        let (mid, amp) = (0.5 * (lo_v + hi_v), 0.5 * (hi_v - lo_v));
        let u: Vec<f64> = t
            .iter()
            .map(|&t| mid - amp * (2.0 * std::f64::consts::PI * t).cos())
            .collect();
        let rec = |y: Vec<f64>| Record::new(t.clone(), u.clone(), Some(y), None).unwrap();
        let d = Data::from_record("sine.csv", rec(u.clone())).unwrap();
        let y = sim(m, &d).unwrap();
        vec![Data::from_record("sine.csv", rec(y)).unwrap()]
    }

    /// Effect names as the workflow keeps them.
    fn named(s: &[&str]) -> Vec<String> {
        s.iter().map(|x| x.to_string()).collect()
    }

    /// A K'(u) of coefficients `poly` over 0..10 V.
    fn gain(c: &[f64]) -> Option<crate::io::model_file::GainSection> {
        let mut poly = [0.0; model_core::gain::POLY_TERMS];
        poly[..c.len()].copy_from_slice(c);
        Some(crate::io::model_file::GainSection {
            poly,
            range_v: [0.0, 10.0],
        })
    }

    /// Step 14: a scale beside a curvature gives way to a curvature of one more order where
    /// that leaves as little (a cubic K'(u) read through the quadratic and a scale: the cubic
    /// found to the `f32` simulation's rounding), and not where the scale is true (a 2 % scale
    /// beside the thesis' quadratic K'(u), on a sine over 0.5-9.5 V, which reaches small
    /// inputs: the cubic alone leaves far more than the look-alike bar over a 1 mV floor).
    /// Like for like (each beside the cubic), an offset in the scale's place leaves less where
    /// the truth has an offset (found to 10 uV) and more where it has the scale.
    #[test]
    fn a_scale_gives_way_to_a_curvature_of_one_more_order_only_where_it_leaves_as_little() {
        use crate::io::model_file::SensorGainSection;
        let both = named(&["nonlinear-gain", "sensor-gain"]);
        let var = [1e-6];
        // A cubic truth, given as the quadratic and a scale.
        let mut truth = ModelFile::built_in("thesis-linear").unwrap();
        truth.nonlinear_gain = gain(&[1.0, 0.01, -0.002, 1e-4]);
        let data = sine(&truth);
        let mut given = truth.clone();
        given.nonlinear_gain = gain(&[1.0, 0.01, -0.002, 0.0]);
        given.sensor_gain = Some(SensorGainSection { gain: 1.003 });
        let (_, given_mse) = simulate_all(&given, &data).unwrap();
        let w = scale_order::curvature_in_scales_place(
            &given,
            &both,
            &data,
            InPlace::Nothing,
            scale_order::CUBIC,
        )
        .unwrap();
        assert!(w.model.sensor_gain.is_none());
        let poly = w.model.nonlinear_gain.as_ref().unwrap().poly;
        assert!((poly[3] - 1e-4).abs() < 1e-7, "{poly:?}");
        assert!(w.mse[0].sqrt() < 1e-5, "{} V", w.mse[0].sqrt());
        assert!(leaves_within_of(
            &w.mse,
            &given_mse,
            &var,
            STATIC_TELL_RATIO
        ));
        // Only where both are named and no table is (K'(u) scales a table: not modelled here).
        let with_table = named(&["hysteresis", "nonlinear-gain", "sensor-gain"]);
        assert!(
            scale_order::curvature_in_scales_place(
                &given,
                &with_table,
                &data,
                InPlace::Nothing,
                scale_order::CUBIC
            )
            .is_none()
        );
        assert!(
            scale_order::curvature_in_scales_place(
                &given,
                &both[..1],
                &data,
                InPlace::Nothing,
                scale_order::CUBIC
            )
            .is_none()
        );
        // A true 2 % scale beside the thesis' quadratic.
        let mut truth = ModelFile::built_in("thesis-linear").unwrap();
        truth.nonlinear_gain = gain(&model_core::params::FAST_GAIN_POLY);
        truth.sensor_gain = Some(SensorGainSection { gain: 1.02 });
        let data = sine(&truth);
        let (_, exact) = simulate_all(&truth, &data).unwrap();
        let w = scale_order::curvature_in_scales_place(
            &truth,
            &both,
            &data,
            InPlace::Nothing,
            scale_order::CUBIC,
        )
        .unwrap();
        println!(
            "a true 2 % scale: the cubic leaves {:.2} mV",
            1e3 * w.mse[0].sqrt()
        );
        assert!(!leaves_within_of(&w.mse, &exact, &var, STATIC_TELL_RATIO));
        // Like for like, the true scale beside the cubic leaves less than an offset there.
        let off = scale_order::curvature_in_scales_place(
            &truth,
            &both,
            &data,
            InPlace::Offset,
            scale_order::CUBIC,
        );
        let sc = scale_order::curvature_in_scales_place(
            &truth,
            &both,
            &data,
            InPlace::Scale,
            scale_order::CUBIC,
        );
        let (off, sc) = (off.unwrap(), sc.unwrap());
        assert!(sc.mse[0] < off.mse[0], "{:?} {:?}", sc.mse, off.mse);
        assert!((sc.model.sensor_gain.as_ref().unwrap().gain - 1.02).abs() < 1e-4);
        // A cubic truth with a 25 mV offset, given as the quadratic and a scale: the offset
        // in the scale's place leaves less (and is found), and none is added where one is
        // named.
        let mut truth = ModelFile::built_in("thesis-linear").unwrap();
        truth.nonlinear_gain = gain(&[1.0, 0.01, -0.002, 1e-4]);
        truth.offset = Some(crate::io::model_file::OffsetSection { offset_v: 0.025 });
        let data = sine(&truth);
        let mut given = truth.clone();
        given.nonlinear_gain = gain(&[1.0, 0.01, -0.002, 0.0]);
        given.offset = None;
        given.sensor_gain = Some(SensorGainSection { gain: 1.003 });
        let off = scale_order::curvature_in_scales_place(
            &given,
            &both,
            &data,
            InPlace::Offset,
            scale_order::CUBIC,
        );
        let sc = scale_order::curvature_in_scales_place(
            &given,
            &both,
            &data,
            InPlace::Scale,
            scale_order::CUBIC,
        );
        let (off, sc) = (off.unwrap(), sc.unwrap());
        assert!(off.mse[0] < sc.mse[0], "{:?} {:?}", off.mse, sc.mse);
        assert!(off.model.sensor_gain.is_none());
        let offset_v = off.model.offset.as_ref().unwrap().offset_v;
        assert!((offset_v - 0.025).abs() < 1e-5, "{offset_v}");
        let with_offset = named(&["nonlinear-gain", "sensor-gain", "offset"]);
        assert!(
            scale_order::curvature_in_scales_place(
                &truth,
                &with_offset,
                &data,
                InPlace::Offset,
                scale_order::CUBIC
            )
            .is_none()
        );
    }

    /// Step 14's orders above the cubic: a plateau (a `tanh` of 0.144 V centred at 4.64 V,
    /// 1.7 V wide, as K'(u) to `u^6` within 2.4 mV of it over 0.3-10 V) on a sine over 2-9 V,
    /// given as the quadratic and a scale fitted at their best, is no cubic: the cubic without
    /// the scale leaves more than the look-alike bar above the model (a quasi-static estimate:
    /// 4.5 mV against 2.7 mV), and the search finds a higher order that does without it,
    /// leaving less than the model (the quartic: 1.2 mV). A true 2 % scale beside the thesis'
    /// quadratic, on a sine over 0.5-9.5 V, is one no order up to `u^6` takes.
    #[test]
    fn a_scale_gives_way_to_a_curvature_of_higher_order_where_no_cubic_takes_a_plateau() {
        use crate::io::model_file::SensorGainSection;
        let both = named(&["nonlinear-gain", "sensor-gain"]);
        let var = [1e-6];
        let plateau = [1.0, 3.80e-3, -5.21e-3, 2.78e-3, -5.38e-4, 4.43e-5, -1.33e-6];
        let mut truth = ModelFile::built_in("thesis-linear").unwrap();
        truth.nonlinear_gain = gain(&plateau);
        let data = sine_between(&truth, 2.0, 9.0);
        let mut given = truth.clone();
        given.nonlinear_gain = gain(&[1.0, 0.0, 0.0]);
        given.sensor_gain = Some(SensorGainSection { gain: 1.0 });
        let given = scale_order::refit_order(&given, &both, &data, 2).unwrap();
        let cubic = scale_order::curvature_in_scales_place(
            &given.model,
            &both,
            &data,
            InPlace::Nothing,
            scale_order::CUBIC,
        )
        .unwrap();
        assert!(
            !leaves_within_of(&cubic.mse, &given.mse, &var, STATIC_TELL_RATIO),
            "{:?} {:?}",
            cubic.mse,
            given.mse
        );
        let search = |m: &ModelFile, mse: &[f64], data: &[Data]| {
            curvature_in_place_of(
                |order| {
                    scale_order::curvature_in_scales_place(m, &both, data, InPlace::Nothing, order)
                },
                (m, &both, data),
                mse,
                &var,
            )
        };
        let (w, rival) = search(&given.model, &given.mse, &data).expect("a higher order");
        assert!(w.order > 3 && w.model.sensor_gain.is_none());
        assert!(w.mse[0] < given.mse[0], "{:?} {:?}", w.mse, given.mse);
        assert!(leaves_within_of(&w.mse, &rival, &var, STATIC_TELL_RATIO));
        // A true 2 % scale beside the thesis' quadratic.
        let mut truth = ModelFile::built_in("thesis-linear").unwrap();
        truth.nonlinear_gain = gain(&model_core::params::FAST_GAIN_POLY);
        truth.sensor_gain = Some(SensorGainSection { gain: 1.02 });
        let data = sine(&truth);
        let (_, exact) = simulate_all(&truth, &data).unwrap();
        assert!(search(&truth, &exact, &data).is_none());
    }

    /// Step 14 (c): an offset beside a curvature that a curvature of one more order does
    /// without (a cubic truth given as the quadratic and a 3 mV offset) goes, by the one-sided
    /// look-alike bar; a true 25 mV offset beside the thesis' quadratic, over a sine that
    /// stays 0.5 V above 0 V, is one no cubic takes; neither a table nor a drift is looked at.
    #[test]
    fn an_offset_gives_way_to_a_curvature_of_one_more_order_only_where_it_leaves_as_little() {
        use crate::io::model_file::OffsetSection;
        let both = named(&["nonlinear-gain", "offset"]);
        // 1 mV of noise: the families' records.
        let var = [1e-6];
        let mut truth = ModelFile::built_in("thesis-linear").unwrap();
        truth.nonlinear_gain = gain(&[1.0, 0.01, -0.002, 1e-4]);
        let data = sine(&truth);
        let mut given = truth.clone();
        given.nonlinear_gain = gain(&[1.0, 0.01, -0.002, 0.0]);
        given.offset = Some(OffsetSection { offset_v: 0.003 });
        let (_, given_mse) = simulate_all(&given, &data).unwrap();
        let w = scale_order::curvature_in_offsets_place(&given, &both, &data, scale_order::CUBIC)
            .unwrap();
        assert!(w.model.offset.is_none());
        let poly = w.model.nonlinear_gain.as_ref().unwrap().poly;
        assert!((poly[3] - 1e-4).abs() < 1e-7, "{poly:?}");
        assert!(leaves_within_of(
            &w.mse,
            &given_mse,
            &var,
            STATIC_TELL_RATIO
        ));
        // A true offset: the cubic without it leaves far more than the model with it.
        let mut truth = ModelFile::built_in("thesis-linear").unwrap();
        truth.nonlinear_gain = gain(&model_core::params::FAST_GAIN_POLY);
        truth.offset = Some(OffsetSection { offset_v: 0.025 });
        let data = sine(&truth);
        let (_, exact) = simulate_all(&truth, &data).unwrap();
        let w = scale_order::curvature_in_offsets_place(&truth, &both, &data, scale_order::CUBIC)
            .unwrap();
        println!(
            "a true 25 mV offset: the cubic leaves {:.2} mV",
            1e3 * w.mse[0].sqrt()
        );
        assert!(!leaves_within_of(&w.mse, &exact, &var, STATIC_TELL_RATIO));
        for other in ["hysteresis", "drift"] {
            let with = named(&["nonlinear-gain", "offset", other]);
            assert!(
                scale_order::curvature_in_offsets_place(&truth, &with, &data, scale_order::CUBIC)
                    .is_none()
            );
        }
        assert!(
            scale_order::curvature_in_offsets_place(&truth, &both[..1], &data, scale_order::CUBIC)
                .is_none()
        );
    }

    /// Step 14 (d), the mirror of (b): a scale in an offset's place beside the cubic. A cubic
    /// truth with a 2 % scale, given as the quadratic and an offset: the scale in the offset's
    /// place beside the cubic takes the records to their truth (the scale found within 1e-4)
    /// and leaves less than the offset refitted there (like for like). A cubic truth with a
    /// 25 mV offset, given so too: the offset is the one that leaves less. Only where an
    /// offset and a curvature are named, and no scale, table or drift.
    #[test]
    fn a_scale_takes_an_offsets_place_beside_the_cubic_only_where_it_leaves_less() {
        use crate::io::model_file::{OffsetSection, SensorGainSection};
        let both = named(&["nonlinear-gain", "offset"]);
        let cubic = [1.0, 0.01, -0.002, 1e-4];
        let mut truth = ModelFile::built_in("thesis-linear").unwrap();
        truth.nonlinear_gain = gain(&cubic);
        truth.sensor_gain = Some(SensorGainSection { gain: 1.02 });
        let data = sine(&truth);
        let mut given = truth.clone();
        given.nonlinear_gain = gain(&[1.0, 0.01, -0.002, 0.0]);
        given.sensor_gain = None;
        given.offset = Some(OffsetSection { offset_v: 0.01 });
        let sc =
            scale_order::scale_in_offsets_place(&given, &both, &data, scale_order::CUBIC).unwrap();
        let off = scale_order::refit_order(&given, &both, &data, scale_order::CUBIC).unwrap();
        assert!(sc.model.offset.is_none());
        assert!((sc.scale - 1.02).abs() < 1e-4, "{}", sc.scale);
        assert!(sc.mse[0].sqrt() < 1e-5, "{} V", sc.mse[0].sqrt());
        assert!(sc.mse[0] < off.mse[0], "{:?} {:?}", sc.mse, off.mse);
        // A true 25 mV offset.
        let mut truth = ModelFile::built_in("thesis-linear").unwrap();
        truth.nonlinear_gain = gain(&cubic);
        truth.offset = Some(OffsetSection { offset_v: 0.025 });
        let data = sine(&truth);
        let mut given = truth.clone();
        given.nonlinear_gain = gain(&[1.0, 0.01, -0.002, 0.0]);
        given.offset = Some(OffsetSection { offset_v: 0.01 });
        let sc =
            scale_order::scale_in_offsets_place(&given, &both, &data, scale_order::CUBIC).unwrap();
        let off = scale_order::refit_order(&given, &both, &data, scale_order::CUBIC).unwrap();
        let offset_v = off.model.offset.as_ref().unwrap().offset_v;
        assert!((offset_v - 0.025).abs() < 1e-5, "{offset_v}");
        assert!(off.mse[0] < sc.mse[0], "{:?} {:?}", off.mse, sc.mse);
        // Not where a scale, a table or a drift is named, nor without the offset.
        for other in ["sensor-gain", "hysteresis", "drift"] {
            let with = named(&["nonlinear-gain", "offset", other]);
            assert!(
                scale_order::scale_in_offsets_place(&given, &with, &data, scale_order::CUBIC)
                    .is_none()
            );
        }
        assert!(
            scale_order::scale_in_offsets_place(&given, &both[..1], &data, scale_order::CUBIC)
                .is_none()
        );
    }

    /// Step 12 reads an offset as the drift's start only where it is the settled creep at
    /// every record's first input taken back (within a tenth; of the span from the pinned
    /// lags' creep to all lags' on a record too short to pin the slower lags' start), that
    /// creep is clearly above the noise, and both effects are named.
    #[test]
    fn an_offset_that_takes_back_the_settled_creep_is_the_drifts_start() {
        let mut model = ModelFile::built_in("thesis-full").unwrap();
        // `seconds` at `rate` Hz from u0, a step of 1 V half way.
        let record_at = |u0: f64, rate: f64, seconds: f64| {
            let n = (seconds * rate).round() as usize;
            let t: Vec<f64> = (0..n).map(|i| i as f64 / rate).collect();
            let u: Vec<f64> = (0..n)
                .map(|i| if i < n / 2 { u0 } else { u0 + 1.0 })
                .collect();
            Data::from_record(
                "levels.csv",
                Record::new(t, u.clone(), Some(u), None).unwrap(),
            )
            .unwrap()
        };
        // Short records (0.2 s) for the simulations; the lags (0.06, 0.75, 12 s) are pinned
        // by records of 36 s and more (CREEP_START_UNPINNED_SHARE), which `long` are.
        let record = |u0: f64| record_at(u0, 1e3, 0.2);
        let long = |u0: f64| record_at(u0, 1e3, 40.0);
        let creep_v = model.settled_creep_reading_v(6.0).unwrap();
        // The thesis' drift: about 0.16 of the static output, settled (its three lags).
        assert!(creep_v > 0.3, "{creep_v}");
        // It is what a simulation reads at its start with the drift less without it (1 mV:
        // the 16-bit ADC's steps of 0.3 mV).
        let d6 = record(6.0);
        let mut without = model.clone();
        without.drift = None;
        let (y_with, y_without) = (sim(&model, &d6).unwrap(), sim(&without, &d6).unwrap());
        assert!(
            (y_with[0] - y_without[0] - creep_v).abs() < 1e-3,
            "{} {} {creep_v}",
            y_with[0],
            y_without[0]
        );
        // The step's move changes no reading, and the model file keeps it.
        let mut with_offset = model.clone();
        with_offset.offset = Some(crate::io::model_file::OffsetSection { offset_v: -creep_v });
        let mut moved = model.clone();
        moved.drift.as_mut().unwrap().unsettled_v = Some(-creep_v);
        let moved = ModelFile::parse(&moved.to_toml().unwrap()).unwrap();
        assert_eq!(moved.drift.as_ref().unwrap().unsettled_v, Some(-creep_v));
        assert_eq!(sim(&moved, &d6).unwrap(), sim(&with_offset, &d6).unwrap());
        let named: Vec<String> = ["drift", "offset"].iter().map(|s| s.to_string()).collect();
        let at = |model: &ModelFile, named: &[String], data: &[Data]| {
            creep_start(model, named, data, &vec![1e-3; data.len()]).map(|c| c.offset_v)
        };
        // Offsets at `share` of the creep, taken as its start or not, on `rec`.
        let shares = |model: &mut ModelFile, rec: &Data, cases: &[(f64, bool)]| {
            for &(share, taken) in cases {
                model.offset = Some(crate::io::model_file::OffsetSection {
                    offset_v: -share * creep_v,
                });
                assert_eq!(
                    at(model, &named, std::slice::from_ref(rec)).is_some(),
                    taken,
                    "offset at {share} of the creep, on {} s",
                    rec.t_s.last().unwrap()
                );
            }
        };
        shares(
            &mut model,
            &long(6.0),
            &[
                (1.0, true),
                (0.92, true),
                (1.08, true),
                (0.85, false),
                (1.2, false),
            ],
        );
        // On 0.2 s only the 0.06 s lag is pinned (its gain 0.05 of the three's 0.155):
        // the offset may be anywhere from its creep to all lags', a tenth beyond either end.
        let drift = model.drift.as_ref().unwrap();
        let fast_share = drift.gains[0] / drift.gains.iter().sum::<f64>();
        shares(
            &mut model,
            &record(6.0),
            &[
                (0.85, true),
                (0.5, true),
                (0.95 * fast_share, true),
                (0.8 * fast_share, false),
                (1.2, false),
            ],
        );
        // On 0.15 s no lag is pinned: the one value of all the lags, as on a long record
        // (the span would reach zero).
        model.offset = Some(crate::io::model_file::OffsetSection {
            offset_v: -0.5 * creep_v,
        });
        assert!(at(&model, &named, &[record_at(6.0, 1e4, 0.15)]).is_none());
        model.offset = Some(crate::io::model_file::OffsetSection { offset_v: -creep_v });
        // The other sign: a sensor offset, not a creep taken back.
        let mut other = model.clone();
        other.offset = Some(crate::io::model_file::OffsetSection { offset_v: creep_v });
        assert!(at(&other, &named, &[long(6.0)]).is_none());
        assert!(at(&other, &named, &[record(6.0)]).is_none());
        // Records starting elsewhere have another settled creep: one offset cannot be both.
        assert!(at(&model, &named, &[long(6.0), long(3.0)]).is_none());
        assert!(at(&model, &named, &[long(6.0), long(6.0)]).is_some());
        // No drift named, or no offset named: nothing to read.
        assert!(at(&model, &named[..1], &[record(6.0)]).is_none());
        assert!(at(&model, &named[1..], &[record(6.0)]).is_none());
        // A record that starts at 0 V has no settled creep to take back.
        let small = ModelFile::built_in("thesis-full").unwrap();
        let near_zero = small.settled_creep_reading_v(0.01).unwrap();
        let mut m0 = small.clone();
        m0.offset = Some(crate::io::model_file::OffsetSection {
            offset_v: -near_zero,
        });
        assert!(
            near_zero.abs() < CREEP_START_MIN_FLOORS * 1e-3,
            "{near_zero}"
        );
        assert!(at(&m0, &named, &[record(0.01)]).is_none());
    }

    /// Two fits explain alike only where every record agrees: a record in which one leaves
    /// clearly less (beyond `STATIC_TELL_RATIO`, a noise variance allowed) tells them apart
    /// however alike the pooled shares.
    #[test]
    fn a_record_that_tells_two_fits_apart_makes_them_not_alike() {
        let var = [1.0, 1.0];
        // Pooled: 85 % and 83 % explained. Per record: alike in both.
        assert!(explain_alike(
            (0.85, &[40.0, 3.0]),
            (0.83, &[45.0, 3.5]),
            &var
        ));
        // The second record leaves 2 variances above the floor with one, 9 with the other.
        assert!(!explain_alike(
            (0.85, &[40.0, 3.0]),
            (0.83, &[40.0, 10.0]),
            &var
        ));
        // Differences within a noise variance are not evidence.
        assert!(alike_in_every_record(&[1.2, 1.0], &[1.0, 1.4], &var));
        // Pooled shares far apart: not alike whatever the records.
        assert!(!explain_alike((0.9, &[2.0, 2.0]), (0.3, &[2.0, 2.0]), &var));
    }

    /// The pairs a step tries when its static shapes explain alike: each shape with the
    /// offset, never two shapes, none once the offset is named or the model has one.
    #[test]
    fn look_alike_shapes_are_paired_with_the_offset_only() {
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<String>>();
        let base = ModelFile::built_in("thesis-linear").unwrap();
        assert_eq!(
            static_pairs(
                &s(&["nonlinear-gain", "sensor-gain"]),
                &s(&["hysteresis"]),
                &base
            ),
            vec![
                ("sensor-gain".to_string(), "offset".to_string()),
                ("nonlinear-gain".to_string(), "offset".to_string())
            ]
        );
        assert_eq!(
            static_pairs(&s(&["offset", "nonlinear-gain"]), &[], &base),
            vec![("nonlinear-gain".to_string(), "offset".to_string())]
        );
        let look_alikes = s(&["nonlinear-gain", "sensor-gain"]);
        assert!(static_pairs(&look_alikes, &s(&["offset"]), &base).is_empty());
        // An offset the model has (a base model's, refitted with each step) is no new effect.
        let mut with_offset = base.clone();
        with_offset.offset = Some(crate::io::model_file::OffsetSection { offset_v: 0.01 });
        assert!(static_pairs(&look_alikes, &[], &with_offset).is_empty());
    }

    /// A diagnosis under `split` that named `named` and ended at `rms_v` on one record.
    fn outcome(split: CentreLine, named: &[&str], rms_v: f64) -> Diagnosis {
        Diagnosis {
            named: named.iter().map(|e| e.to_string()).collect(),
            steps: Vec::new(),
            record_noise_v: vec![1e-3],
            noise_notes: Vec::new(),
            glitches: Vec::new(),
            hum: Vec::new(),
            noise_floor_v: 1e-3,
            final_rms_v: rms_v,
            record_final_rms_v: vec![rms_v],
            base_sims: Vec::new(),
            model: ModelFile::built_in("thesis-linear").unwrap(),
            tried: Vec::new(),
            not_searched: Vec::new(),
            signatures: signatures::Signatures::default(),
            unexplained: None,
            cannot_tell: Vec::new(),
            centre_line: CentreChoice {
                chosen: split,
                band_noise_var: 100.0,
                span_noise_var: 90.0,
                rise_noise_var: None,
                by_diagnosis: None,
            },
        }
    }

    /// Of both splits' diagnoses the one naming fewer effects is kept, however much lower the
    /// other ends (hidden-effect case 1038: a false offset and scale beside a Bouc-Wen loop,
    /// 3x lower), unless only the other explains every record; of two naming as many, the one
    /// ending lower; a residual that is not a number never wins the tie; the other's outcome
    /// goes with the choice, in the JSON too.
    #[test]
    fn the_split_whose_diagnosis_names_fewer_effects_is_kept() {
        let var = [1e-6];
        let span = outcome(CentreLine::Span, &["hysteresis", "nonlinear-gain"], 22e-3);
        let band = || {
            outcome(
                CentreLine::Band,
                &["offset", "hysteresis", "nonlinear-gain", "sensor-gain"],
                7e-3,
            )
        };
        for (a, b) in [(span.clone(), band()), (band(), span.clone())] {
            let d = fewer_names(&var, a, b);
            assert_eq!(d.centre_line.chosen, CentreLine::Span);
            assert_eq!(d.named, ["hysteresis", "nonlinear-gain"]);
            let r = d.centre_line.by_diagnosis.as_ref().unwrap();
            assert_eq!((r.split, r.named.len()), (CentreLine::Band, 4));
            assert!(
                (r.final_noise_var - 49.0).abs() < 1e-9,
                "{}",
                r.final_noise_var
            );
            assert_eq!(
                d.to_json()["hysteresis_split"]["by_diagnosis"]["split"],
                "band"
            );
        }
        let lower = outcome(CentreLine::Band, &["hysteresis", "nonlinear-gain"], 11e-3);
        let higher = outcome(CentreLine::Span, &["hysteresis", "offset"], 14e-3);
        for (a, b) in [
            (lower.clone(), higher.clone()),
            (higher.clone(), lower.clone()),
        ] {
            assert_eq!(
                fewer_names(&var, a, b).named,
                ["hysteresis", "nonlinear-gain"]
            );
        }
        let nan = outcome(CentreLine::Span, &["hysteresis", "offset"], f64::NAN);
        assert_eq!(
            fewer_names(&var, lower.clone(), nan.clone())
                .centre_line
                .chosen,
            CentreLine::Band
        );
        assert_eq!(
            fewer_names(&var, nan, lower).centre_line.chosen,
            CentreLine::Band
        );
        // One explains every record and the other leaves an unexplained part: the first is
        // kept, though it names more (the thesis stage's sine over most of the range).
        let explained = outcome(
            CentreLine::Span,
            &["drift", "hysteresis", "nonlinear-gain"],
            1.5e-3,
        );
        let mut short = outcome(CentreLine::Band, &["drift", "hysteresis"], 6.7e-3);
        short.unexplained = Some(Unexplained {
            rms_v: 6.6e-3,
            where_: "sine.csv".into(),
        });
        for (a, b) in [
            (explained.clone(), short.clone()),
            (short.clone(), explained.clone()),
        ] {
            assert_eq!(fewer_names(&var, a, b).centre_line.chosen, CentreLine::Span);
        }
        // The loop alone chose: no `by_diagnosis` key at all (the JSON holds no null).
        let alone = outcome(CentreLine::Band, &["hysteresis"], 2e-3).to_json();
        assert!(alone["hysteresis_split"].get("by_diagnosis").is_none());
    }

    /// A 1 kHz record that holds `levels` volts for a second each, its output `0.8 u`.
    fn held(levels: &[f64]) -> Data {
        let n = 1000 * levels.len();
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 1e-3).collect();
        let u: Vec<f64> = (0..n).map(|i| levels[i / 1000]).collect();
        let y: Vec<f64> = u.iter().map(|u| 0.8 * u).collect();
        Data::from_record("held.csv", Record::new(t, u, Some(y), None).unwrap()).unwrap()
    }

    /// Step 13a reads the table's level only after a start that died away at the first input:
    /// of the start search's candidates on a 10 V table at 5 V, exactly the centred scans (two
    /// signs of each of `START_DECAYS`) are recognised, under the rise split's memory as
    /// well; a scan clipped by the table's floor still is; a memory that came down from above,
    /// a scan around another level, one whose excursions grow and one that ends far from the
    /// first input are not.
    #[test]
    fn only_a_scan_that_died_away_at_the_first_input_is_a_centred_start() {
        let range = (0.0, 10.0);
        let span = range.1 - range.0;
        for form in [CentreLine::Band, CentreLine::Rise] {
            let centred = super::super::everett::start_candidates(5.0, range)
                .iter()
                .filter(|c| {
                    let mem = super::super::everett::start_memory(range, form, c);
                    centred_scan(&mem, 5.0, span)
                })
                .count();
            assert_eq!(
                centred,
                2 * super::super::everett::START_DECAYS.len(),
                "{form:?}"
            );
        }
        let floor = 10.0 / 44.0;
        let clipped = [
            10.0, floor, 4.2, floor, 3.2, floor, 1.9, 0.3, 0.8, 0.4, 0.62,
        ];
        assert!(centred_scan(&clipped, 0.5, span));
        assert!(centred_scan(&[7.0, 3.5, 6.0, 4.3, 5.4], 5.0, span));
        assert!(!centred_scan(&[8.0], 5.0, span));
        assert!(!centred_scan(&[10.0, floor], 0.5, span));
        assert!(!centred_scan(&[4.0, 1.5, 3.2, 2.1], 5.0, span));
        assert!(!centred_scan(&[6.0, 4.0, 7.0, 3.0, 5.2], 5.0, span));
        assert!(!centred_scan(&[9.0, 1.0, 8.0, 2.0], 5.0, span));
    }

    /// Step 17's tell asks both sides: a level error common to every hold (a static map's) is
    /// told, one on the holds reached from below only (a loop branch's miss) is not, though
    /// the pooled holds put the model without it 1.5x farther.
    #[test]
    fn static_shapes_beside_a_loop_are_told_from_both_sides() {
        let d = held(&[0.0, 2.0, 6.0, 4.0, 8.0, 1.0]);
        let holds = d.holds();
        let sides: Vec<Option<bool>> = holds.iter().map(|h| reached_from_below(&d, h)).collect();
        assert_eq!(
            sides,
            [
                None,
                Some(true),
                Some(true),
                Some(false),
                Some(true),
                Some(false)
            ]
        );
        let var = [1e-6];
        let data = std::slice::from_ref(&d);
        let shifted = |common_v: f64, below_v: f64| -> Vec<f64> {
            let mut y = d.y_v.clone();
            for (h, side) in holds.iter().zip(&sides) {
                for v in &mut y[h.clone()] {
                    *v += common_v + if *side == Some(true) { below_v } else { 0.0 };
                }
            }
            y
        };
        // A 2 mV static error at every level, taken away by the shapes: told.
        let with = shifted(0.5e-3, 0.0);
        assert!(told_beside_loop(
            data,
            std::slice::from_ref(&with),
            &[shifted(2.5e-3, 0.0)],
            &var
        ));
        // The same 2 mV on the holds reached from below only: not told from both sides...
        let branch = shifted(0.5e-3, 2e-3);
        assert!(!told_beside_loop(
            data,
            std::slice::from_ref(&with),
            std::slice::from_ref(&branch),
            &var
        ));
        // ... where the pooled holds would have told it.
        let (a, b) = (
            held_level_error(data, &[with], &var).unwrap(),
            held_level_error(data, &[branch], &var).unwrap(),
        );
        assert!(a * STATIC_TELL_RATIO <= b, "{a} {b}");
        // Levels reached from below only tell nothing, however much nearer the shapes put them.
        let rising = held(&[0.0, 2.0, 5.0, 8.0]);
        let off: Vec<f64> = rising.y_v.iter().map(|y| y + 2e-3).collect();
        assert!(!told_beside_loop(
            std::slice::from_ref(&rising),
            std::slice::from_ref(&rising.y_v),
            &[off],
            &var
        ));
    }

    /// The held levels' error is the squared level misfit in noise variances, summed over the
    /// holds; a scale error and an offset of the same size at the middle level differ at the
    /// others; fewer than three levels tell nothing.
    #[test]
    fn held_levels_measure_the_level_misfit() {
        let d = held(&[2.0, 5.0, 8.0]);
        let var = [1e-6];
        let exact =
            held_level_error(std::slice::from_ref(&d), std::slice::from_ref(&d.y_v), &var).unwrap();
        assert!(exact < 1e-18, "{exact}");
        // 1 mV off at every level: 1 noise variance a hold (the first hold starts at sample 1).
        let off: Vec<f64> = d.y_v.iter().map(|y| y + 1e-3).collect();
        let e_off = held_level_error(std::slice::from_ref(&d), &[off], &var).unwrap();
        assert!((e_off - 3.0).abs() < 1e-6, "{e_off}");
        // A scale error of 1 mV at 5 V: 0.4, 1 and 1.6 mV at the three levels.
        let scaled: Vec<f64> = d.y_v.iter().map(|y| y * (1.0 + 1e-3 / 4.0)).collect();
        let e_sc = held_level_error(std::slice::from_ref(&d), &[scaled], &var).unwrap();
        assert!((e_sc - (0.16 + 1.0 + 2.56)).abs() < 1e-6, "{e_sc}");
        let two = held(&[2.0, 8.0, 2.0]);
        assert!(
            held_level_error(
                std::slice::from_ref(&two),
                std::slice::from_ref(&two.y_v),
                &var
            )
            .is_none()
        );
    }
}
