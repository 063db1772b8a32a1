//! The hysteresis start memory (issue #12, item 2): a stage at rest after earlier motion is not
//! on its major rising curve, and a record that starts there shows it until the input wipes
//! that memory out. Without a model of it the fit of a single 1 Hz sine puts most of its
//! residual in the first second and names `drift` to mop it up.
//!
//! # How it is found
//! The start memory is a short list of turning points ([`super::everett::start_candidates`]:
//! none, came down from above, came down from the top and back up, a decaying oscillation
//! around the first input or around another level before the move to it).
//! Once `hysteresis` is fitted, each candidate is tried on the fitted model where it matters:
//! each record is simulated only up to the sample from which the table's outputs from the
//! candidate's memory and from the present one differ by a constant (none where the input has
//! wiped the difference out; plus [`START_SETTLE_S`] for the plant to forget it), at most
//! [`START_HEAD_MAX_S`] (beyond, the residual's change is the table's difference times the
//! stage's response to it fitted over the head), and the candidate that lowers the residual
//! power the most is taken; on a single record the best [`START_REFITTED`] are taken, each
//! with its excursions from the first input scaled to the depth that lowers it most
//! ([`START_SCALE`]: the candidates are a coarse grid). The hysteresis basis is then
//! recomputed from that memory and the slow effects refitted with it (on a single record for
//! each of them, the one that leaves the least kept); the result is kept only if every
//! record's residual is no worse, the total is lower, and it scores better as an effect would
//! (BIC, [`START_PARAMS`]). Two rounds (the refitted table can prefer another start).
//!
//! # What it trades
//! One start memory for all records (the records of one session start from the same rest, as
//! the identification protocol asks); a handful of candidates instead of a free memory (a
//! free Preisach boundary would be as many parameters as the table has and could mop up any
//! first-second residual: the candidates are the states a lab's stage is left in).

use super::constants::MSE_MIN_V2;
use super::data::{Data, mse, sim};
use super::everett::{start_candidates, start_memory};
use super::select::refit_slow;
use super::slow_fit::SlowRegressors;
use crate::io::model_file::ModelFile;
use crate::util::par_map;
use model_core::hysteresis::{HysteresisMemory, HysteresisTable};

/// Time the plant and drift are given to forget a different start after the table's outputs
/// from two memories stop moving apart, seconds (our assumption: the thesis' plant settles in
/// about 1 ms and the fast drift lag is 2.5 ms or more; 50 ms covers the slow tail of what a
/// start moves without simulating the whole record for each candidate).
pub const START_SETTLE_S: f64 = 0.05;

/// Longest head simulated for a candidate start, seconds (our assumption: beyond, the
/// residual's change is ranked by the table's own difference; the identification protocol's
/// 150 s record first reaches its top at 89 s, and its heads simulated in full took 1.3 s of a
/// diagnosis' 15 s).
pub const START_HEAD_MAX_S: f64 = 10.0;

/// Rounds of start search and refit.
const START_ROUNDS: usize = 2;

/// Candidates refitted on a single record, the best by their heads (our assumption: the
/// heads rank the right start among the first three; each refit of a single record's table
/// costs a fraction of a second).
pub const START_REFITTED: usize = 3;

/// Range of the factor on the chosen start candidate's excursions from the first input, and
/// the golden-section steps over it (our assumption: the candidates' depths are a factor 1.5
/// to 2 apart, so 0.4..1.6 reaches past the neighbours; 12 steps resolve 0.1 % of the
/// factor's range, each one head simulation).
pub const START_SCALE: (f64, f64) = (0.4, 1.6);
/// Golden-section steps over [`START_SCALE`].
pub const START_SCALE_STEPS: usize = 12;

/// Parameters a start memory is scored with (our assumption: a candidate is set by at most
/// four numbers, a scan's centre, first amplitude, decay and first direction
/// ([`start_candidates`]), or fewer and the depth it is scaled to on a single record).
pub const START_PARAMS: usize = 4;

/// The result of a start search: the new regressors, model, simulations and mean squares.
pub struct StartFit {
    pub slow_x: SlowRegressors,
    pub model: ModelFile,
    pub sims: Vec<Vec<f64>>,
    pub mse: Vec<f64>,
}

/// The difference of a table's outputs driven from memory `a` and from memory `b`, as a
/// simulation's output at each sample sees it (element `i`: after the inputs before sample
/// `i`, one element a sample), zero where it is under 1 uV; and the first sample from which it
/// no longer changes (by 1 uV). Where the memories come to agree (the input wiped the
/// difference out: the same turning points and output) the rest is zero without running on.
fn table_difference(
    t: &HysteresisTable,
    u_v: &[f64],
    mut a: HysteresisMemory,
    mut b: HysteresisMemory,
) -> (Vec<f64>, usize) {
    let n = u_v.len();
    let mut diff = Vec::with_capacity(n);
    for &u in u_v {
        let same = a.turning_points_v().eq(b.turning_points_v())
            && (a.output_v() - b.output_v()).abs() < 1e-6;
        if same {
            let from = diff.len();
            diff.resize(n, 0.0);
            // Zero from here on: the difference stops changing where it last was not zero.
            let last_moving = diff[..from].iter().rposition(|v: &f64| v.abs() >= 1e-6);
            return (diff, last_moving.map_or(0, |i| i + 1));
        }
        let d = (a.output_v() - b.output_v()) as f64;
        diff.push(if d.abs() < 1e-6 { 0.0 } else { d });
        t.forward(&mut a, u as f32);
        t.forward(&mut b, u as f32);
    }
    let Some(&last) = diff.last() else {
        return (diff, 0);
    };
    let from = diff
        .iter()
        .rposition(|v| (v - last).abs() > 1e-6)
        .map_or(0, |i| i + 1);
    (diff, from)
}

/// The first `k` samples of `d`.
fn head(d: &Data, k: usize) -> Data {
    Data {
        name: d.name.clone(),
        t_s: d.t_s[..k].to_vec(),
        u_v: d.u_v[..k].to_vec(),
        y_v: d.y_v[..k].to_vec(),
        hold_band_v: d.hold_band_v,
        memo: Default::default(),
        fine: d.fine.as_ref().map(|f| std::sync::Arc::new(f.head(k))),
    }
}

/// The state `table` is left in at each record's first input after the memory `hist`
/// (turning points, volts), as bits: two memories with the same state are one start to the
/// records (the move to the first input wiped out where they differ).
pub(super) fn state_after(
    table: &HysteresisTable,
    data: &[Data],
    hist: &[f32],
) -> Vec<(Vec<u32>, u32)> {
    data.iter()
        .map(|d| {
            let mut a = HysteresisMemory::new();
            a.reset_after(table, hist, d.u_v[0] as f32);
            let points = a.turning_points_v().map(f32::to_bits).collect();
            (points, a.output_v().to_bits())
        })
        .collect()
}

/// `model` with the start memory `start_v` (turning points after coming up from the bottom,
/// [`start_candidates`]) and the slow effects refitted on it, with the regressors built from
/// that memory.
pub(super) fn refit_on_start(
    model: &ModelFile,
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
    start_v: &[f64],
) -> Option<(SlowRegressors, ModelFile)> {
    let x2 = slow_x.with_start(data, start_v);
    let mut m2 = model.clone();
    if let Some(h) = m2.hysteresis.as_mut() {
        let full = start_memory(slow_x.range(), slow_x.form(), start_v);
        h.start_turns_v = (!full.is_empty()).then_some(full);
    }
    let m2 = refit_slow(&m2, &[], data, &x2, u_range)?;
    Some((x2, m2))
}

/// The BIC's fit term of mean squares `ms` against `ms_now` over the records (each record's
/// length times the log of its ratio, summed): below zero, `ms` fits better.
pub(super) fn log_likelihood_cost(data: &[Data], ms: &[f64], ms_now: &[f64]) -> f64 {
    let all: Vec<usize> = (0..data.len()).collect();
    log_likelihood_cost_over(data, ms, ms_now, &all)
}

/// [`log_likelihood_cost`] over the records `set` only (indices into `data`, `ms` and
/// `ms_now`).
pub(super) fn log_likelihood_cost_over(
    data: &[Data],
    ms: &[f64],
    ms_now: &[f64],
    set: &[usize],
) -> f64 {
    set.iter()
        .map(|&i| data[i].len() as f64 * (ms[i].max(MSE_MIN_V2) / ms_now[i].max(MSE_MIN_V2)).ln())
        .sum()
}

/// A start memory's worth in the BIC over the records: [`START_PARAMS`] times the log of
/// their samples.
pub(super) fn start_worth(data: &[Data]) -> f64 {
    let n_all: f64 = data.iter().map(|d| d.len() as f64).sum();
    START_PARAMS as f64 * n_all.ln()
}

/// The best start memory for the fitted `model` (which has a `[hysteresis]` table fitted on
/// `slow_x`), with the slow effects refitted on it; `None` if no candidate does better than
/// the present start.
pub fn search(
    model: &ModelFile,
    data: &[Data],
    slow_x: &SlowRegressors,
    u_range: (f64, f64),
    cur_mse: &[f64],
) -> Option<StartFit> {
    let mut best: Option<StartFit> = None;
    let mut model = model.clone();
    let mut ms_now: Vec<f64> = cur_mse.to_vec();
    for _ in 0..START_ROUNDS {
        let sec = model.hysteresis.as_ref()?;
        let table = sec.table().ok()?;
        let now: Vec<f32> = sec.start_history_v();
        let sims_now: Vec<Vec<f64>> = par_map(data, |d| sim(&model, d).ok())
            .into_iter()
            .collect::<Option<_>>()?;
        // Candidates that leave the table in the same state at every record's first input
        // (the move there wiped out where they differ) are one: the first is kept, so that
        // the few refitted on a single record are different starts.
        let state_after = |hist: &[f32]| state_after(&table, data, hist);
        let state_of = |c: &[f64]| {
            let hist: Vec<f32> = start_memory(slow_x.range(), slow_x.form(), c)
                .iter()
                .map(|&v| v as f32)
                .collect();
            state_after(&hist)
        };
        let mut seen = vec![state_after(&now)];
        let cands: Vec<Vec<f64>> = start_candidates(data[0].u_v[0], slow_x.range())
            .into_iter()
            .filter(|c| {
                let s = state_of(c);
                let new = !seen.contains(&s);
                if new {
                    seen.push(s);
                }
                new
            })
            .collect();
        // Residual power change over each record, for a candidate memory: simulated over its
        // head, ranked by the table's difference beyond.
        let gain_of = |c: &Vec<f64>| -> Option<f64> {
            let full = start_memory(slow_x.range(), slow_x.form(), c);
            let hist: Vec<f32> = full.iter().map(|&v| v as f32).collect();
            let mut m = model.clone();
            if let Some(h) = m.hysteresis.as_mut() {
                h.start_turns_v = (!full.is_empty()).then_some(full);
            }
            let mut delta = 0.0;
            for (r, (d, s_now)) in data.iter().zip(&sims_now).enumerate() {
                let mut a = HysteresisMemory::new();
                a.reset_after(&table, &hist, d.u_v[0] as f32);
                let mut b = HysteresisMemory::new();
                b.reset_after(&table, &now, d.u_v[0] as f32);
                let settle = (START_SETTLE_S / d.period_s()).ceil() as usize;
                // The table's outputs from the two memories differ until the input wipes the
                // difference out, or for good (relays the record never switches, such as
                // those above its largest input that one memory holds on): the head ends
                // where the difference stops changing, or after START_HEAD_MAX_S. Beyond, the
                // residual's change is the table's difference times the stage's response to
                // it (fitted over the head): the ranking only, the start kept is refitted and
                // simulated in full.
                let (diff, fixed_from) = table_difference(&table, &d.u_v, a, b);
                let cap = (START_HEAD_MAX_S / d.period_s()).ceil() as usize;
                let k = (fixed_from.min(cap) + settle).min(d.len());
                if k == 0 {
                    continue;
                }
                let h = head(d, k);
                let y = sim(&m, &h).ok()?;
                let mut e_new: f64 = h.y_v.iter().zip(&y).map(|(a, b)| (a - b).powi(2)).sum();
                let mut e_now: f64 = h
                    .y_v
                    .iter()
                    .zip(&s_now[..k])
                    .map(|(a, b)| (a - b).powi(2))
                    .sum();
                if diff[k..d.len()].iter().any(|v| *v != 0.0) {
                    let (num, den) = (0..k).fold((0.0, 0.0), |(n, q), i| {
                        (n + (y[i] - s_now[i]) * diff[i], q + diff[i] * diff[i])
                    });
                    // (Where the head shows no difference, 1: the table's output is in the
                    // monitor's volts, and K'(u) and a sensor gain stay near 1.)
                    let scale = if den > 0.0 { num / den } else { 1.0 };
                    for i in k..d.len() {
                        let r = d.y_v[i] - s_now[i];
                        e_new += (r - scale * diff[i]).powi(2);
                        e_now += r * r;
                    }
                }
                // Records weigh by their own residual power, as the selection's score does.
                delta += (e_new - e_now) / (d.len() as f64 * ms_now[r].max(MSE_MIN_V2));
            }
            Some(delta)
        };
        let gains = par_map(&cands, gain_of);
        let mut ranked: Vec<(&Vec<f64>, f64)> = cands
            .iter()
            .zip(gains)
            .filter_map(|(c, g)| Some((c, g?)))
            .filter(|(_, g)| *g < 0.0)
            .collect();
        ranked.sort_by(|a, b| a.1.total_cmp(&b.1));
        // On a single record the best few by their heads are each refitted and the one that
        // leaves the least kept: the head is judged on the table fitted for the present start,
        // which favours starts near it (a record of plays centred on its first input chose a
        // single turn over the decaying oscillation that is its own state).
        ranked.truncate(if data.len() == 1 { START_REFITTED } else { 1 });
        if ranked.is_empty() {
            break;
        }
        let tries = par_map(&ranked, |&(c, g)| {
            // The candidates are a coarse grid of a lab's rest states: on a single record the
            // chosen one's excursions from the first input are then scaled (golden section
            // over a factor 0.4..1.6, kept in the table's range) to the depth the record
            // shows. Not on several: each record started from its own rest and the one memory
            // they share is a compromise; tuned to the mix of their heads it left, on the
            // hidden-effect suite's two-record protocol, a start-level error that an `offset`
            // took up (Bouc-Wen truths, seeds 1015 and 1053: 96.7 % exact names -> 94.6 %).
            let fine: Option<Vec<f64>> = (data.len() == 1 && !c.is_empty()).then(|| {
                let range = slow_x.range();
                let u0 = data[0].u_v[0].clamp(range.0, range.1);
                let scaled = |f: f64| -> Vec<f64> {
                    c.iter()
                        .map(|&v| (u0 + f * (v - u0)).clamp(range.0, range.1))
                        .collect()
                };
                let f = crate::util::golden_n(
                    START_SCALE.0,
                    START_SCALE.1,
                    START_SCALE.0,
                    START_SCALE.1,
                    START_SCALE_STEPS,
                    |f| gain_of(&scaled(f)).unwrap_or(f64::INFINITY),
                );
                scaled(f)
            });
            // Kept only if it does better than the candidate itself.
            let c = match &fine {
                Some(cf) if gain_of(cf).is_some_and(|gf| gf < g) => cf.clone(),
                _ => c.clone(),
            };
            let (x2, m2) = refit_on_start(&model, data, slow_x, u_range, &c)?;
            let sims: Vec<Vec<f64>> = par_map(data, |d| sim(&m2, d).ok())
                .into_iter()
                .collect::<Option<_>>()?;
            let ms: Vec<f64> = data
                .iter()
                .zip(&sims)
                .map(|(d, y)| mse(&d.y_v, y))
                .collect();
            Some((c, x2, m2, sims, ms))
        });
        let Some((_, x2, m2, sims, ms)) = tries
            .into_iter()
            .flatten()
            .min_by(|a, b| a.4.iter().sum::<f64>().total_cmp(&b.4.iter().sum::<f64>()))
        else {
            break;
        };
        let no_worse = ms.iter().zip(&ms_now).all(|(a, b)| *a <= *b * 1.000_001);
        // Scored as the selection scores an effect (BIC over all records): a start that buys
        // less than its parameters' worth is the table's refit chasing what another effect
        // left (hidden-effect case 1084, a Bouc-Wen loop beside a curvature: a scan centred
        // mid-span, taken for a 1e-5 share of the residual power, bent the table so far that
        // the curvature was never named and the final residual stayed at 98x the floor).
        // Charged in full also where it replaces an earlier start (the second round): a swap
        // that gains less than a start's worth is the same chase (our assumption, on the
        // conservative side: a start is kept only where the records show it).
        let score = log_likelihood_cost(data, &ms, &ms_now) + start_worth(data);
        if !no_worse || ms.iter().sum::<f64>() >= ms_now.iter().sum::<f64>() || score >= 0.0 {
            break;
        }
        model = m2.clone();
        ms_now = ms.clone();
        best = Some(StartFit {
            slow_x: x2,
            model: m2,
            sims,
            mse: ms,
        });
    }
    best
}
