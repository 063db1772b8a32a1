//! The joint fit of the slow effects (drift, hysteresis, non-linear gain): linear in their
//! weights given a few shape constants, so one weighted least-squares solve on the settled
//! samples of all records ([`SlowRegressors`]: the drift lags for each grid time constant, the
//! play operators, the gain terms), with the drift's and the play operators' weights kept
//! non-negative ([`super::nnls`]). The three drift time constants are chosen from a log grid,
//! then refined in `log tau` (a wide coordinate pass by [`crate::util::golden_n`], then damped
//! Newton steps of the three, `newton_step`), each try ranked by a Schur complement on the
//! other columns' free set and the chosen ones solved exactly; one round of structural
//! refinement follows where the stage's form is not linear in the parameters (the drift's
//! `K(u)`, `K'(u)` on the play sum).
//!
//! Records weigh equally (each record's normal equations are divided by its settled samples).

use super::catalogue::{self, SlowParams};
use super::constants::{
    COUPLE_ROUNDS_MAX, COUPLE_SETTLED, DRIFT_KNEES, DRIFT_REFINE_ITERATIONS, DRIFT_REFINE_TOL_V2,
    DRIFT_TAU_MAX_RECORDS, SETTLE_S,
};
use super::data::{Data, sim};
use super::everett::{self, HYST_COLS, HYST_FIT_COLS, HystFit};
use super::nnls::{nnls_normal_from, ridge};
use crate::io::model_file::ModelFile;
use crate::util::golden_n;
use model_core::params;
use nalgebra::{DMatrix, DVector};

/// One regressor column at a record's rows.
type Col = std::sync::Arc<[f64]>;

/// The slow effects' regressors at the rows the solve uses (they depend on the input only).
pub struct SlowRegressors {
    /// Per record: columns at the rows (drift lags for each grid time constant, the
    /// hysteresis basis, gain terms; shared with the regressors they were derived from where
    /// they are the same: the basis without K'(u), the gain terms).
    cols: Vec<Vec<Col>>,
    /// Per record: the samples the solve uses, rising: the settled ones, evenly thinned to at
    /// most [`MAX_SLOW_ROWS`].
    rows: Vec<Vec<usize>>,
    /// Per record: the drift lags' input, `K(u) u` (`u` while K = 1), every sample.
    drive: Vec<Vec<f64>>,
    /// Per record: the input the static columns (hysteresis basis, gain terms) are computed
    /// from: the recorded input delayed by the stage's group delay ([`SolveRows`]).
    u_fit: std::sync::Arc<Vec<Vec<f64>>>,
    /// Per record: the hysteresis basis at the rows, before the K'(u) scaling (computed once:
    /// it is the costly part).
    hyst: std::sync::Arc<Vec<Vec<Col>>>,
    /// The hysteresis table's input range.
    range: (f64, f64),
    /// The K'(u) the hysteresis columns in `cols` are scaled by (`None`: 1), and the span
    /// its input is held to.
    kprime: Option<(f64, f64)>,
    kprime_range: (f64, f64),
    /// The weighted moments of the input-only columns before K'(u) ([`KMoments`]): shared by
    /// every regressor set derived from the same basis, computed at the first K'(u) that
    /// needs a Gram matrix.
    moments: std::sync::Arc<std::sync::OnceLock<KMoments>>,
    /// The hysteresis start memory the basis was computed with.
    start_v: Vec<f64>,
    /// The centre line the basis' loop columns leave out.
    form: everett::CentreLine,
    /// The reversible slope the fitted table keeps (the base model's static gain, sensor
    /// volts per volt): the bound of each band's loop weights ([`solve_slow`]).
    table_gain: f64,
    /// The records' weighted Gram matrix of the columns that depend on the input alone and
    /// the offset's (the sensor gain's row and column zero), computed at the first solve and
    /// kept: every candidate of a step solves on the same regressors, adding only the
    /// products with its target and sensor-gain column (themselves kept in `products`).
    gram: std::sync::OnceLock<DMatrix<f64>>,
    /// The columns' weighted products with a target and with the sensor gain's column, for
    /// the last few models without slow effects (`y0`, keyed by its bits:
    /// [`TargetProducts`]): a step's candidates, and the final check's and the swaps' trials
    /// that take out a slow effect, solve on the same regressors against the same `y0`.
    products: std::sync::Mutex<Vec<(u64, std::sync::Arc<TargetProducts>)>>,
    /// The products the regressors these were shaped from kept when they were shaped, where
    /// the two differ in the drift's lags alone (a structural round's K(u) under the same
    /// K'(u)): a target found here needs only the lags' products computed again
    /// ([`target_products`]).
    lag_parent: Vec<(u64, std::sync::Arc<TargetProducts>)>,
    /// The slow fits already run on these regressors ([`fit_slow`] looks here first), the
    /// oldest first.
    fits: std::sync::Mutex<std::collections::VecDeque<KeptFit>>,
    /// The base model whose own slow effects a diagnosis holds as it gives them ([`Self::held`];
    /// `None` where it has none).
    held_base: Option<std::sync::Arc<ModelFile>>,
    /// The records' span the held base's K'(u) is clamped to in [`Self::beside_kprime`].
    held_range: (f64, f64),
    /// Where the held base has a table: the same regressors with K'(u)'s terms as they act on
    /// it ([`Self::for_set`]).
    beside_table: Option<Box<SlowRegressors>>,
    /// Where the held base has a K'(u): the same regressors with the table's columns scaled by
    /// it, as the stage scales the table ([`Self::for_set`]).
    beside_kprime: Option<Box<SlowRegressors>>,
}

/// What a [`fit_slow`] on one [`SlowRegressors`] depends on besides them, the records and its
/// rounds: the bits of the model without slow effects (`y0`, every sample of every record,
/// hashed), the set and the inputs' span.
#[derive(PartialEq)]
struct FitKey {
    y0: u64,
    set: Vec<String>,
    u_range_bits: (u64, u64),
}

/// A slow fit a [`SlowRegressors`] keeps: its key, how its rounds went ([`RoundsRun`]) and
/// its result.
struct KeptFit {
    key: FitKey,
    run: RoundsRun,
    fit: Option<SlowParams>,
}

/// How a [`fit_slow`]'s rounds went, enough to tell whether a call with other `rounds` would
/// run the same ones ([`rounds_to_run`]): the state after the same rounds is the same fit.
#[derive(Clone, Debug, Default)]
struct RoundsRun {
    /// Per round reached, for a set that couples K'(u) with the table (empty otherwise): had
    /// K'(u) settled (`COUPLE_SETTLED`) at its start?
    settled: Vec<bool>,
    /// The round whose solve failed (the loop stops there with the fit before it).
    failed_at: Option<usize>,
    /// The rounds run in full: the result is the fit after them (`None`: the same for any
    /// `rounds`, the linear fit alone or its failure).
    ran: Option<usize>,
}

/// The rounds [`fit_slow`] runs in full with `rounds` asked for, given how they went
/// (`run.settled`, `run.failed_at`); `None` where a coupled run does not reach a round the
/// call would check. A coupled set (K'(u) beside a drift's K) runs
/// `max(rounds, COUPLE_ROUNDS_MAX)` at most and stops at the first round from `rounds` on that
/// starts settled; the others run `rounds` (one without the drift's K), an answer that may
/// reach past the kept run: the memo serves a call only where the answer is the kept run's
/// own `ran`.
fn rounds_to_run(couple: bool, has_drift: bool, rounds: usize, run: &RoundsRun) -> Option<usize> {
    let (rounds, max_rounds) = round_limits(couple, has_drift, rounds);
    for round in 0..max_rounds {
        if couple && round >= rounds && *run.settled.get(round)? {
            return Some(round);
        }
        if run.failed_at == Some(round) {
            return Some(round);
        }
    }
    Some(max_rounds)
}

/// Slow fits a [`SlowRegressors`] keeps (our assumption: a diagnosis fits the same set against
/// the same `y0` again in the next step's refit of the present set, in the final check's
/// trials that take out a fast effect or the effect a step added, and in the swaps; measured
/// on the gap bench, the coupled sets of drift, hysteresis and curvature, a second each, are
/// the repeats, and a step adds at most a few sets).
const FITS_KEPT: usize = 16;

/// The regressors' weighted products with the target `y - y0` (`b`) and with the sensor
/// gain's column `y0` (`g_s`, that column's row of the Gram matrix; its entry with itself
/// and with the offset's column included), over the records.
struct TargetProducts {
    b: DVector<f64>,
    g_s: DVector<f64>,
}

/// Models without slow effects whose products a [`SlowRegressors`] keeps (our assumption: a
/// step's candidates share one, the final check's trials a few).
const PRODUCTS_KEPT: usize = 4;

impl SlowRegressors {
    /// The centre line the basis' loop columns leave out.
    pub fn form(&self) -> everett::CentreLine {
        self.form
    }

    /// The hysteresis table's input range.
    pub fn range(&self) -> (f64, f64) {
        self.range
    }

    /// The hysteresis start memory of the basis.
    pub fn start_v(&self) -> &[f64] {
        &self.start_v
    }

    /// The reversible slope of the fitted table, sensor volts per volt.
    pub fn table_gain(&self) -> f64 {
        self.table_gain
    }

    /// Per record, the rows the solve uses and the input its static columns are computed
    /// from (the recorded input delayed by the stage's group delay): what a memoryless map
    /// beside the basis is fitted on ([`super::memory::twin`]).
    pub fn fit_input(&self) -> (&[Vec<usize>], &[Vec<f64>]) {
        (&self.rows, &self.u_fit)
    }
}

/// Rows of one record the slow solve uses at most (our assumption: the slow effects change
/// over milliseconds or more, so 20 000 settled samples, evenly spread, carry what the whole
/// record does; the Gram matrix of the 96 columns then costs the same for any record length,
/// and the regressors' memory stays at 15 MB a record).
pub const MAX_SLOW_ROWS: usize = 20_000;

/// Rows of one record the drift time constants' refinement evaluates on (every try of the
/// search; the final solve at the chosen time constants uses all, up to [`MAX_SLOW_ROWS`]).
/// Our assumption: a drift lag of 10 ms or more is sampled evenly by 2000 of a record's
/// settled samples (the lags themselves advance through every sample). Measured against 4000
/// rows: the same names and residual on `thesis-full`'s 150 s records (5.29x the floor), the
/// diagnosis 28.5 s -> 24.6 s; the hidden-effect suite unchanged.
const DRIFT_SEARCH_ROWS: usize = 2_000;

/// How the slow regressors are shaped by the slow effects' non-linear parameters (the
/// structural refinement of [`fit_slow`]).
#[derive(Clone, Copy, Debug, Default)]
struct Shape {
    /// K'(u) = 1 + c1 u + c2 u^2 multiplies the play sum (the stage scales the whole fast map).
    kprime: Option<(f64, f64)>,
    /// The drift's K(u) and the input above which it is held (its knee, volts): its lags
    /// see `K(u) u`.
    kdrift: Option<([f64; 4], f64)>,
    /// The inputs' span: K' is held at its edges and K below it (above, at its knee), as in
    /// the stage.
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
        self.kdrift.map_or(u, |(k, knee)| {
            let x = u.clamp(self.range.0, knee);
            (k[0] + x * (k[1] + x * (k[2] + x * k[3]))) * u
        })
    }
}

const N_TAU: usize = catalogue::DRIFT_TAU_GRID_S.len();
const COL_HYST: usize = N_TAU;
const COL_GAIN: usize = N_TAU + HYST_COLS;
/// Columns that depend on the input alone (kept in [`SlowRegressors`]).
const N_INPUT_COLS: usize = N_TAU + HYST_COLS + 2;
/// The offset's column: a constant 1.
const COL_OFFSET: usize = N_INPUT_COLS;
/// The sensor gain's column: the simulated output without slow effects (`y0`): a scale error
/// of the monitor scales the whole output.
const COL_SGAIN: usize = N_INPUT_COLS + 1;
const N_COLS: usize = N_INPUT_COLS + 2;

/// Value of regressor column `c` of record `r` at row `j` (`y0`: the simulated output
/// without slow effects, the sensor gain's column).
#[inline]
fn col(x: &SlowRegressors, y0: &[Vec<f64>], r: usize, c: usize, j: usize) -> f64 {
    match c {
        COL_OFFSET => 1.0,
        COL_SGAIN => y0[r][x.rows[r][j]],
        _ => x.cols[r][c][j],
    }
}

/// The columns of the hysteresis basis the split `form` fits.
fn hyst_cols(form: everett::CentreLine) -> impl Iterator<Item = usize> {
    (0..HYST_FIT_COLS)
        .filter(move |&c| form.fits(c))
        .map(|c| COL_HYST + c)
}

/// The columns of the slow effects in `set` other than the drift's lags, the hysteresis
/// basis' those of the split `form`.
fn fixed_cols(set: &[&str], form: everett::CentreLine) -> Vec<usize> {
    let mut fixed: Vec<usize> = Vec::new();
    if set.contains(&"hysteresis") {
        fixed.extend(hyst_cols(form));
    }
    if set.contains(&"nonlinear-gain") {
        fixed.extend([COL_GAIN, COL_GAIN + 1]);
    }
    if set.contains(&"offset") {
        fixed.push(COL_OFFSET);
    }
    if set.contains(&"sensor-gain") {
        fixed.push(COL_SGAIN);
    }
    fixed
}

/// The regressors of `data` at the rows `rows` ([`solve_rows`]), the hysteresis basis
/// starting every record from the memory `start_v` (turning points,
/// [`everett::start_candidates`]), for a table whose reversible slope is `table_gain` (the
/// base model's static gain), its loop columns leaving out the centre line `form`.
pub(super) fn slow_regressors(
    data: &[Data],
    rows: SolveRows,
    start_v: &[f64],
    table_gain: f64,
    form: everett::CentreLine,
) -> SlowRegressors {
    let SolveRows { rows, u_fit } = rows;
    let (lo, hi) = data
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| {
            let (l, h) = super::data::min_max(&d.u_v);
            (a.min(l), b.max(h))
        });
    let range = everett::hyst_range(lo, hi, form);
    let hyst = crate::util::par_map(&u_fit.iter().zip(&rows).collect::<Vec<_>>(), |(u, r)| {
        everett::columns(u, r, range, start_v, form)
            .into_iter()
            .map(Col::from)
            .collect::<Vec<_>>()
    });
    let base = SlowRegressors {
        cols: Vec::new(),
        rows,
        drive: Vec::new(),
        u_fit: std::sync::Arc::new(u_fit),
        hyst: std::sync::Arc::new(hyst),
        range,
        kprime: None,
        kprime_range: (0.0, 0.0),
        moments: Default::default(),
        start_v: start_v.to_vec(),
        form,
        table_gain,
        gram: std::sync::OnceLock::new(),
        products: Default::default(),
        lag_parent: Vec::new(),
        fits: Default::default(),
        held_base: None,
        held_range: (0.0, 0.0),
        beside_table: None,
        beside_kprime: None,
    };
    slow_regressors_shaped(data, &Shape::default(), &base)
}

impl SlowRegressors {
    /// The same regressors with the hysteresis basis started from the memory `start_v`.
    pub(super) fn with_start(&self, data: &[Data], start_v: &[f64]) -> SlowRegressors {
        self.rebuilt(data, start_v, self.form)
    }

    /// The same regressors with the loop columns leaving out the centre line `form`.
    pub(super) fn with_form(&self, data: &[Data], form: everett::CentreLine) -> SlowRegressors {
        self.rebuilt(data, &self.start_v, form)
    }

    /// The same regressors for records whose outputs differ from those these were built on
    /// and whose inputs do not (step 19's outputs divided by a sensor scale): the columns,
    /// which depend on the inputs alone, shared; the products with targets and the fits kept,
    /// which depend on the outputs, left behind. Those caches are keyed by the model without
    /// slow effects alone, which is the same whatever the outputs: one set of regressors from
    /// here must serve one set of outputs (step 19 takes a fresh one for every scale).
    pub(super) fn for_other_outputs(&self) -> SlowRegressors {
        SlowRegressors {
            cols: self.cols.clone(),
            rows: self.rows.clone(),
            drive: self.drive.clone(),
            u_fit: self.u_fit.clone(),
            hyst: self.hyst.clone(),
            range: self.range,
            kprime: self.kprime,
            kprime_range: self.kprime_range,
            moments: self.moments.clone(),
            start_v: self.start_v.clone(),
            form: self.form,
            table_gain: self.table_gain,
            gram: self.gram.clone(),
            products: Default::default(),
            lag_parent: Vec::new(),
            fits: Default::default(),
            held_base: self.held_base.clone(),
            held_range: self.held_range,
            beside_table: self
                .beside_table
                .as_ref()
                .map(|t| Box::new(t.for_other_outputs())),
            beside_kprime: self
                .beside_kprime
                .as_ref()
                .map(|t| Box::new(t.for_other_outputs())),
        }
    }

    /// The regressors on the same rows with the hysteresis basis computed afresh.
    fn rebuilt(&self, data: &[Data], start_v: &[f64], form: everett::CentreLine) -> Self {
        let rows = SolveRows {
            rows: self.rows.clone(),
            u_fit: self.u_fit.as_ref().clone(),
        };
        let mut x = slow_regressors(data, rows, start_v, self.table_gain, form);
        x.held_base = self.held_base.clone();
        x.held_range = self.held_range;
        x.with_held_twins(data)
    }

    /// The same regressors for a diagnosis from `base` over records spanning `u_range`, whose
    /// own slow effects it holds as `base` gives them until a step names one
    /// ([`Self::held`]).
    pub(super) fn holding(mut self, base: &ModelFile, data: &[Data], u_range: (f64, f64)) -> Self {
        if catalogue::SLOW.iter().any(|e| catalogue::present(base, e)) {
            self.held_base = Some(std::sync::Arc::new(base.clone()));
            self.held_range = u_range;
        }
        self.with_held_twins(data)
    }

    /// [`Self::with_held_gain_cols`] and, where the held base has a K'(u) of the catalogue's
    /// quadratic form, the twin whose table columns it scales: a table fitted beside a held
    /// K'(u) is scaled by it in the stage, as `fit_slow`'s rounds scale it beside a fitted one
    /// (the table's fit beside the thesis' K'(u) held, unscaled, left 31.6 mV on a chirp of
    /// the thesis stage without its table, 13x the floor). K'(u) is clamped to the records'
    /// span here, to its own range in the stage: the same where the records stay within it.
    fn with_held_twins(mut self, data: &[Data]) -> Self {
        let kprime = self.held_base.as_deref().and_then(held_kprime);
        if let Some(k) = kprime {
            let shape = Shape {
                kprime: Some(k),
                range: self.held_range,
                ..Shape::default()
            };
            self.beside_kprime = Some(Box::new(slow_regressors_shaped(data, &shape, &self)));
        }
        self.with_held_gain_cols()
    }

    /// The regressors a fit of `set` solves on: beside a table the base holds (the set
    /// without `hysteresis`, the base with a table: the table is then the held one, in the
    /// model the fit starts from), those whose K'(u) terms act on that table
    /// ([`Self::with_held_gain_cols`]); else these.
    pub(super) fn for_set(&self, set: &[&str]) -> &SlowRegressors {
        let table = set.contains(&"hysteresis");
        match (&self.beside_table, &self.beside_kprime) {
            (Some(x), _) if !table => x,
            (_, Some(x)) if table && !set.contains(&"nonlinear-gain") => x,
            _ => self,
        }
    }

    /// Where the base holds a table of its own, these regressors with a twin
    /// ([`Self::for_set`]) whose K'(u) terms act on it: K'(u) multiplies the table's output
    /// `h(u)` (`model_core::gain`), so beside a held table the curvature's columns are
    /// `u h(u)` and `u^2 h(u)` along each record's input (the table run from its start
    /// memory), not the linear map's `G u^2` and `G u^3` (which left the thesis' K'(u) beside
    /// its own table 13 mV from the records on a chirp, 5.4x the floor: the loop's share of
    /// the product). A fit that refits the table keeps the linear map's terms: its K'(u)
    /// scales the table's columns (`fit_slow`'s rounds).
    fn with_held_gain_cols(mut self) -> Self {
        let Some(table_section) = self.held_base.as_ref().and_then(|b| b.hysteresis.as_ref())
        else {
            return self;
        };
        let Ok(table) = table_section.table() else {
            return self;
        };
        let history = table_section.start_history_v();
        let mut twin = self.for_other_outputs();
        for (r, cols) in twin.cols.iter_mut().enumerate() {
            let (Some(u), Some(rows)) = (twin.u_fit.get(r), twin.rows.get(r)) else {
                continue;
            };
            if cols.len() < COL_GAIN + 2 || u.is_empty() {
                continue;
            }
            let mut mem = model_core::hysteresis::HysteresisMemory::default();
            mem.reset_after(&table, &history, u[0] as f32);
            let h: Vec<f64> = u
                .iter()
                .map(|&x| table.forward(&mut mem, x as f32) as f64)
                .collect();
            cols[COL_GAIN] = rows.iter().map(|&i| u[i] * h[i]).collect();
            cols[COL_GAIN + 1] = rows.iter().map(|&i| u[i] * u[i] * h[i]).collect();
        }
        // (its Gram matrix and moments are of the other columns: computed afresh; it is a
        // twin, with none of its own)
        twin.gram = std::sync::OnceLock::new();
        twin.moments = Default::default();
        twin.beside_table = None;
        twin.beside_kprime = None;
        self.beside_table = Some(Box::new(twin));
        self
    }

    /// The base model's slow effects `m` holds as the base gives them: present in the base
    /// and in `m` with the base's own section (no step has refitted them). A diagnosis keeps
    /// them in the model that the slow fits start from instead of refitting them beside every
    /// candidate: the base is the lab's model, and a refit of its table or drift that no step
    /// names would take up an effect's work silently (the thesis' full stage with a 20 mV
    /// sensor offset, diagnosed from `thesis-full`: the offset went into a refitted table and
    /// nothing was named). Empty for a base without slow effects (`thesis-linear`).
    ///
    /// Not held, refitted beside every candidate as before: a `sensor-gain` (it scales every
    /// other slow effect in the stage, and the solve divides their terms by a fitted scale
    /// only), a K'(u) of higher order than the quadratic and a play-form table (no twin of
    /// the regressors carries them: [`Self::for_set`]).
    pub(super) fn held(&self, m: &ModelFile) -> Vec<&'static str> {
        self.held_base.as_ref().map_or_else(Vec::new, |b| {
            catalogue::SLOW
                .iter()
                .copied()
                .filter(|e| match *e {
                    "sensor-gain" => false,
                    "nonlinear-gain" => held_kprime(b).is_some(),
                    "hysteresis" => b.hysteresis_play.is_none(),
                    _ => true,
                })
                .filter(|e| catalogue::present(b, e) && catalogue::as_in(m, b, e))
                .collect()
        })
    }
}

/// The base's K'(u) as the regressors' shape holds it (`1 + c1 u + c2 u^2`): `None` without
/// one, or for one of another form (higher terms, another constant), which is not held.
fn held_kprime(base: &ModelFile) -> Option<(f64, f64)> {
    base.nonlinear_gain
        .as_ref()
        .filter(|g| g.poly.iter().skip(3).all(|c| *c == 0.0) && g.poly[0] == 1.0)
        .map(|g| (g.poly[1], g.poly[2]))
}

/// After the group delay (`solve_rows`), the stage's output may leave its quasi-static map by
/// at most this many noise floors near a row the slow solve uses (our assumption: where the
/// dynamics move the output off the delayed static map by `d`, a column of a tenth of the
/// input's size is off by about a tenth of `d`, so 10 noise floors keep that error near the
/// noise). Measured on a 0.6-240 Hz chirp of a Bouc-Wen truth (families case 1018 without its
/// sensor gain): solved on every settled row with the undelayed input, the table left 15.5 mV
/// (15x the floor), the rows above 5 Hz pulling the loop off by the stage's 0.19 ms lag;
/// solved on the first 2.5 s alone (below 7 Hz), 4.9 mV at every frequency of the chirp; with
/// the delay and this rule, 4.0 mV.
pub const DYN_ROW_MAX_NOISE: f64 = 10.0;

/// Half-width of the window over which a row's deviation from the quasi-static map is taken
/// at its largest, seconds (our assumption: a tenth of a second holds a good part of a cycle of
/// the slowest sines a record carries, 0.5 Hz and up, so the rows kept are whole stretches of
/// slow motion, not the turning points of fast cycles where the input pauses).
pub const DYN_ROW_WINDOW_S: f64 = 0.1;

/// For samples `(index, value)` in rising index order, the largest value among those whose
/// index lies within `half` of each one's (a monotone deque: linear time).
fn window_max(s: &[(usize, f64)], half: usize) -> Vec<f64> {
    let mut out = Vec::with_capacity(s.len());
    let mut q: std::collections::VecDeque<usize> = std::collections::VecDeque::new();
    let mut next = 0usize;
    for &(i, _) in s {
        while next < s.len() && s[next].0 <= i + half {
            while q.back().is_some_and(|&b| s[b].1 <= s[next].1) {
                q.pop_back();
            }
            q.push_back(next);
            next += 1;
        }
        while q.front().is_some_and(|&f| s[f].0 + half < i) {
            q.pop_front();
        }
        out.push(q.front().map_or(0.0, |&f| s[f].1));
    }
    out
}

/// ... but the solve keeps at least this share of a record's settled rows, the least dynamic
/// ones (our assumption: a record that never moves slowly enough still shows its loop on a
/// quarter of its samples, at a cost the simulation then measures).
pub const DYN_ROW_MIN_SHARE: f64 = 0.25;

/// The rows of each record the slow solve uses, and the input its static columns are
/// computed from.
pub(super) struct SolveRows {
    /// Per record: the rows, rising.
    pub rows: Vec<Vec<usize>>,
    /// Per record: the input delayed by the stage's group delay, every sample.
    pub u_fit: Vec<Vec<f64>>,
}

/// Longest group delay `solve_rows` accepts, seconds (our assumption: the thesis stage's
/// is about 0.19 ms, plus half a sample of a 1 kHz record's hold; anything far longer is
/// not a delay the static columns should follow).
pub const MAX_GROUP_DELAY_S: f64 = 5e-3;

/// The rows of each record the slow solve uses and the input of its static columns.
///
/// The slow regressors are static: a hysteresis column is the table's output for the input
/// history, not that output passed through the stage's dynamics, which the simulation applies.
/// Below the stage's bandwidth the dynamics are a gain and a group delay `tau` (the amplifier's
/// and sensor's lags, half a sample of the record's hold): the columns are computed from the
/// input delayed by `tau`, fitted per record to the output of `base` without its slow effects
/// (its deviation from its own quasi-static map against the map's slope times the input's
/// rate). Rows where the deviation left after that delay (higher-order dynamics: a chirp's
/// top octaves, ringing) exceeds [`DYN_ROW_MAX_NOISE`] noise floors (`noise_v`, one per
/// record) within [`DYN_ROW_WINDOW_S`] are left out (at least [`DYN_ROW_MIN_SHARE`] of the
/// settled rows are kept, the calmest); so are samples within [`SETTLE_S`] of an input jump.
/// The rows are evenly thinned to at most [`MAX_SLOW_ROWS`].
pub(super) fn solve_rows(
    data: &[Data],
    base: &ModelFile,
    noise_v: &[f64],
) -> anyhow::Result<SolveRows> {
    let fast = catalogue::without_slow(base);
    let mut quiet = fast.clone();
    quiet.converters.noise_v = 0.0;
    let stage = quiet.build_stage()?;
    let history = quiet.start_history_v();
    // The quasi-static map on a fine grid over the records' inputs, read linearly between.
    let (lo, hi) = data
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| {
            let (l, h) = super::data::min_max(&d.u_v);
            (a.min(l), b.max(h))
        });
    const GRID: usize = 512;
    let step = ((hi - lo) / GRID as f64).max(1e-9);
    let map: Vec<f64> = (0..=GRID)
        .map(|k| {
            let u = lo + k as f64 * step;
            stage
                .steady_state_after(&history, u as f32)
                .signals()
                .measured_v as f64
        })
        .collect();
    let static_at = |u: f64| {
        let x = ((u - lo) / step).clamp(0.0, GRID as f64);
        let k = (x.floor() as usize).min(GRID - 1);
        map[k] + (x - k as f64) * (map[k + 1] - map[k])
    };
    let slope_at = |u: f64| {
        let x = ((u - lo) / step).clamp(0.0, GRID as f64);
        let k = (x.floor() as usize).min(GRID - 1);
        (map[k + 1] - map[k]) / step
    };
    let sims: Vec<Vec<f64>> = crate::util::par_map(data, |d| sim(&fast, d))
        .into_iter()
        .collect::<anyhow::Result<_>>()?;
    let mut rows = Vec::with_capacity(data.len());
    let mut u_fit = Vec::with_capacity(data.len());
    for ((d, y), &sigma) in data.iter().zip(&sims).zip(noise_v) {
        let n = d.len();
        let ts = d.period_s();
        let settle = (SETTLE_S / ts).ceil() as usize;
        let mut settled: Vec<usize> = Vec::with_capacity(n);
        let mut last_jump: Option<usize> = None;
        for i in 0..n {
            if d.is_jump(i) {
                last_jump = Some(i);
            }
            if last_jump.is_none_or(|j| i - j > settle) {
                settled.push(i);
            }
        }
        // The group delay: y - map(u) ~ -tau map'(u) du/dt on the settled rows.
        let (mut num, mut den) = (0.0, 0.0);
        for &i in &settled {
            if i == 0 || i + 1 >= n {
                continue;
            }
            let v = slope_at(d.u_v[i]) * (d.u_v[i + 1] - d.u_v[i - 1]) / (2.0 * ts);
            num -= (y[i] - static_at(d.u_v[i])) * v;
            den += v * v;
        }
        let tau = if den > 0.0 {
            (num / den).clamp(0.0, MAX_GROUP_DELAY_S)
        } else {
            0.0
        };
        let shift = tau / ts;
        let whole = shift.floor() as usize;
        let frac = shift - whole as f64;
        let at = |k: isize| d.u_v[k.clamp(0, n as isize - 1) as usize];
        let u_del: Vec<f64> = (0..n as isize)
            .map(|i| {
                let k = i - whole as isize;
                (1.0 - frac) * at(k) + frac * at(k - 1)
            })
            .collect();
        // The deviation left, at its largest within the window.
        let dev: Vec<(usize, f64)> = settled
            .iter()
            .map(|&i| (i, (y[i] - static_at(u_del[i])).abs()))
            .collect();
        let half = (DYN_ROW_WINDOW_S / ts).round().max(1.0) as usize;
        let env = window_max(&dev, half);
        let bar = DYN_ROW_MAX_NOISE * sigma;
        let calm = env.iter().filter(|e| **e <= bar).count();
        let least = (DYN_ROW_MIN_SHARE * settled.len() as f64).ceil() as usize;
        let mut kept: Vec<usize> = if calm >= least {
            settled
                .iter()
                .zip(&env)
                .filter(|(_, e)| **e <= bar)
                .map(|(i, _)| *i)
                .collect()
        } else {
            let mut by_env: Vec<(usize, f64)> = settled.iter().copied().zip(env).collect();
            by_env.sort_by(|a, b| a.1.total_cmp(&b.1));
            let mut k: Vec<usize> = by_env.iter().take(least).map(|(i, _)| *i).collect();
            k.sort_unstable();
            k
        };
        let stride = kept.len().div_ceil(MAX_SLOW_ROWS).max(1);
        if stride > 1 {
            kept = kept.into_iter().step_by(stride).collect();
        }
        rows.push(kept);
        u_fit.push(u_del);
    }
    Ok(SolveRows { rows, u_fit })
}

/// The regressors for `shape`, at the rows of `base` and with its hysteresis basis.
#[allow(clippy::needless_range_loop)] // several arrays indexed together
fn slow_regressors_shaped(data: &[Data], shape: &Shape, base: &SlowRegressors) -> SlowRegressors {
    // Under the base's K'(u) the scaled basis is the base's own: shared, not scaled again
    // (the same values; a basis of two hundred columns, a third of this function's time).
    let same_basis = shape.kprime == base.kprime
        && (shape.kprime.is_none() || shape.range == base.kprime_range)
        && base.cols.len() == data.len()
        && base.cols.iter().all(|c| c.len() == N_INPUT_COLS);
    let mut cols = Vec::new();
    let mut drives = Vec::new();
    for (r, d) in data.iter().enumerate() {
        let n = d.len();
        let rows = &base.rows[r];
        let uf = &base.u_fit[r];
        let t = d.period_s();
        let drive: Vec<f64> = d.u_v.iter().map(|&u| shape.drive(u)).collect();
        // Exact ZOH first-order lags of the held drive, at rest at its first value: the grid's
        // time constants side by side (independent recursions, so they run in lanes, not as
        // one long chain of dependent multiply-adds each).
        let a: [f64; N_TAU] = catalogue::DRIFT_TAU_GRID_S.map(|tau| (-t / tau).exp());
        let mut lag = [drive.first().copied().unwrap_or(0.0); N_TAU];
        let mut at: Vec<[f64; N_TAU]> = Vec::with_capacity(rows.len());
        let mut next = 0usize;
        for (i, &v) in drive.iter().enumerate().take(n) {
            if next < rows.len() && rows[next] == i {
                at.push(lag);
                next += 1;
            }
            for k in 0..N_TAU {
                lag[k] = a[k] * lag[k] + (1.0 - a[k]) * v;
            }
        }
        let mut c: Vec<Col> = Vec::with_capacity(N_COLS);
        for k in 0..N_TAU {
            c.push(at.iter().map(|l| l[k]).collect());
        }
        if same_basis {
            c.extend(base.cols[r][COL_HYST..COL_HYST + HYST_COLS].iter().cloned());
        } else if shape.kprime.is_none() {
            c.extend(base.hyst[r].iter().cloned());
        } else {
            let kp: Vec<f64> = rows.iter().map(|&i| shape.kprime(uf[i])).collect();
            for h in base.hyst[r].iter() {
                c.push(h.iter().zip(&kp).map(|(v, k)| v * k).collect());
            }
        }
        // The gain terms depend on the input alone: shared where the base has them.
        match base.cols.get(r) {
            Some(bc) if bc.len() == N_INPUT_COLS => {
                c.extend(bc[COL_GAIN..COL_GAIN + 2].iter().cloned());
            }
            _ => {
                c.push(
                    rows.iter()
                        .map(|&i| params::PLANT_GAIN * uf[i] * uf[i])
                        .collect(),
                );
                c.push(
                    rows.iter()
                        .map(|&i| params::PLANT_GAIN * uf[i] * uf[i] * uf[i])
                        .collect(),
                );
            }
        }
        cols.push(c);
        drives.push(drive);
    }
    let x = SlowRegressors {
        cols,
        rows: base.rows.clone(),
        drive: drives,
        u_fit: base.u_fit.clone(),
        hyst: base.hyst.clone(),
        range: base.range,
        kprime: shape.kprime,
        kprime_range: shape.range,
        moments: base.moments.clone(),
        start_v: base.start_v.clone(),
        form: base.form,
        table_gain: base.table_gain,
        gram: std::sync::OnceLock::new(),
        products: Default::default(),
        lag_parent: if same_basis {
            base.products.lock().map(|p| p.clone()).unwrap_or_default()
        } else {
            Vec::new()
        },
        fits: Default::default(),
        held_base: base.held_base.clone(),
        held_range: base.held_range,
        beside_table: None,
        beside_kprime: None,
    };
    // With the base's K'(u) only the lags changed.
    if shape.kprime == base.kprime
        && let Some(g) = base.gram.get()
    {
        let _ = x.gram.set(gram_new_lags(&x, g));
    }
    x
}

/// The dot product of two columns.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The weighted Gram matrix of the input-only columns and the offset's ([`SlowRegressors`]'
/// `gram`): from the basis' moments where K'(u) scales it ([`KMoments`]), else directly.
fn input_gram(x: &SlowRegressors) -> DMatrix<f64> {
    if let Some((c1, c2)) = x.kprime {
        let km = x.moments.get_or_init(|| k_moments(x));
        if km.range == x.kprime_range {
            return km.gram(c1, c2, x);
        }
    }
    input_gram_direct(x)
}

/// [`input_gram`] from the columns themselves, row by row (in blocks).
#[allow(clippy::needless_range_loop)] // a triangle of the matrix
fn input_gram_direct(x: &SlowRegressors) -> DMatrix<f64> {
    let active = active_cols(x.form);
    let mut g = DMatrix::<f64>::zeros(N_COLS, N_COLS);
    for (cols, rows) in x.cols.iter().zip(&x.rows) {
        let w = 1.0 / rows.len().max(1) as f64;
        // The record's design matrix (its columns the split fits, then the offset's ones)
        // times itself: a blocked product (nalgebra's gemm), several times the speed of a
        // row-by-row sum over the two hundred columns of the hysteresis basis; the other
        // split's columns (zero, never solved for) are left out.
        let mut gl = DMatrix::<f64>::zeros(active.len(), active.len());
        for block in row_blocks(rows.len()) {
            let m = design(cols, block, &active);
            gl += m.transpose() * &m;
        }
        for (i, &ci) in active.iter().enumerate() {
            for (j, &cj) in active.iter().enumerate() {
                g[(ci, cj)] += w * gl[(i, j)];
            }
        }
    }
    g
}

/// The weighted moments `M_p = sum w x^p c_i c_j` (`p = 0..4`, `x` the input held to K'(u)'s
/// span, `w` a record's row weight) of the columns that depend on the input alone but for the
/// drift's lags: the hysteresis basis before K'(u), the gain terms and the offset's ones. With
/// `K'(x) = 1 + c1 x + c2 x^2`, the Gram matrix of the scaled basis is `sum_p k2_p M_p` (`k2`
/// the coefficients of `K'^2`) and its products with the unscaled columns `sum_p k1_p M_p`
/// (`k1` those of K'), for any K': five products per basis instead of a Gram matrix per K'
/// (19 of them, 2.2 s of the standard records' 22 s of CPU, before), exact but for rounding.
struct KMoments {
    /// K'(u)'s span the moments hold the input to.
    range: (f64, f64),
    /// The columns (indices into the regressors), in the moments' order.
    cols: Vec<usize>,
    m: [DMatrix<f64>; 5],
}

/// The [`KMoments`] of `x`'s basis at its K'(u) span.
fn k_moments(x: &SlowRegressors) -> KMoments {
    let cols: Vec<usize> = hyst_cols(x.form)
        .chain([COL_GAIN, COL_GAIN + 1, COL_OFFSET])
        .collect();
    let nc = cols.len();
    let (lo, hi) = x.kprime_range;
    let mut m: [DMatrix<f64>; 5] = std::array::from_fn(|_| DMatrix::zeros(nc, nc));
    for (r, rows) in x.rows.iter().enumerate() {
        let w = 1.0 / rows.len().max(1) as f64;
        // The columns before K'(u): the basis as computed, the rest as the regressors have it.
        let mut unscaled: Vec<Col> = x.cols[r].clone();
        for (k, h) in x.hyst[r].iter().enumerate() {
            unscaled[COL_HYST + k] = h.clone();
        }
        let u: Vec<f64> = rows.iter().map(|&i| x.u_fit[r][i].clamp(lo, hi)).collect();
        let mut acc: [DMatrix<f64>; 5] = std::array::from_fn(|_| DMatrix::zeros(nc, nc));
        for block in row_blocks(rows.len()) {
            let f = design(&unscaled, block.clone(), &cols);
            let ub = DVector::from_column_slice(&u[block]);
            let mut fp = f.clone();
            for (p, a) in acc.iter_mut().enumerate() {
                if p > 0 {
                    for mut c in fp.column_iter_mut() {
                        c.component_mul_assign(&ub);
                    }
                }
                *a += f.transpose() * &fp;
            }
        }
        for (mp, a) in m.iter_mut().zip(acc) {
            *mp += a * w;
        }
    }
    KMoments {
        range: x.kprime_range,
        cols,
        m,
    }
}

impl KMoments {
    /// The input Gram matrix ([`input_gram`]) of `x`, whose basis is scaled by
    /// `K'(u) = 1 + c1 u + c2 u^2` at this span: the moments' combination, then the drift
    /// lags' rows ([`gram_new_lags`]).
    fn gram(&self, c1: f64, c2: f64, x: &SlowRegressors) -> DMatrix<f64> {
        let k1 = [1.0, c1, c2, 0.0, 0.0];
        let k2 = [1.0, 2.0 * c1, c1 * c1 + 2.0 * c2, 2.0 * c1 * c2, c2 * c2];
        let is_hyst = |c: usize| (COL_HYST..COL_HYST + HYST_COLS).contains(&c);
        let mut g = DMatrix::<f64>::zeros(N_COLS, N_COLS);
        // One triangle, mirrored (the products `f' (u^p f)` are symmetric but for rounding).
        for (a, &ca) in self.cols.iter().enumerate() {
            for (b, &cb) in self.cols.iter().enumerate().take(a + 1) {
                let k = match (is_hyst(ca), is_hyst(cb)) {
                    (true, true) => k2,
                    (true, false) | (false, true) => k1,
                    (false, false) => [1.0, 0.0, 0.0, 0.0, 0.0],
                };
                let v: f64 = (0..5).map(|p| k[p] * self.m[p][(a, b)]).sum();
                g[(ca, cb)] = v;
                g[(cb, ca)] = v;
            }
        }
        gram_new_lags(x, &g)
    }
}

/// The columns of the Gram matrix a split's solves use: the lags, the split's hysteresis
/// columns, the gain terms and the offset (last).
fn active_cols(form: everett::CentreLine) -> Vec<usize> {
    (0..N_TAU)
        .chain(hyst_cols(form))
        .chain([COL_GAIN, COL_GAIN + 1, COL_OFFSET])
        .collect()
}

/// A record's design matrix over the `active` columns (the offset's ones last), at its rows
/// `block`.
fn design(cols: &[Col], block: std::ops::Range<usize>, active: &[usize]) -> DMatrix<f64> {
    // Column by column into one buffer (no zeroed matrix written twice).
    let mut v = Vec::with_capacity(block.len() * active.len());
    for &c in active {
        if c == COL_OFFSET {
            v.resize(v.len() + block.len(), 1.0);
        } else {
            v.extend_from_slice(&cols[c][block.clone()]);
        }
    }
    DMatrix::from_vec(block.len(), active.len(), v)
}

/// Rows a Gram product takes at a time: a block of the design matrix stays in the cache
/// (a record's whole one is tens of megabytes).
const GRAM_BLOCK_ROWS: usize = 1024;

/// The blocks of [`GRAM_BLOCK_ROWS`] rows of `n`.
fn row_blocks(n: usize) -> impl Iterator<Item = std::ops::Range<usize>> {
    (0..n)
        .step_by(GRAM_BLOCK_ROWS)
        .map(move |a| a..(a + GRAM_BLOCK_ROWS).min(n))
}

/// [`input_gram`] of regressors whose columns differ from `base`'s (Gram matrix `g_base`)
/// only in the drift's lags: the lags' rows and columns computed again, the rest kept (a
/// structural round's K(u), its hysteresis columns under the same K'(u) as `base`'s).
fn gram_new_lags(x: &SlowRegressors, g_base: &DMatrix<f64>) -> DMatrix<f64> {
    let active = active_cols(x.form);
    let lags: Vec<usize> = (0..N_TAU).collect();
    let mut g = g_base.clone();
    for c in &lags {
        for &a in &active {
            g[(*c, a)] = 0.0;
            g[(a, *c)] = 0.0;
        }
    }
    for (cols, rows) in x.cols.iter().zip(&x.rows) {
        let w = 1.0 / rows.len().max(1) as f64;
        let mut gl = DMatrix::<f64>::zeros(lags.len(), active.len());
        for block in row_blocks(rows.len()) {
            let l = design(cols, block.clone(), &lags);
            let m = design(cols, block, &active);
            gl += l.transpose() * &m;
        }
        for (i, &ci) in lags.iter().enumerate() {
            for (j, &cj) in active.iter().enumerate() {
                g[(ci, cj)] += w * gl[(i, j)];
                if !lags.contains(&cj) {
                    g[(cj, ci)] += w * gl[(i, j)];
                }
            }
        }
    }
    g
}

/// The slow effects in `set` fitted to the residual of the model without slow effects (`y0`):
/// the linear fit ([`fit_slow_linear`]), then `rounds` rounds of structural
/// refinement where the stage's form is not linear in the parameters:
/// * with `drift`: its K(u) (`k0 + k1 u + k2 u^2 + k3 u^3`, k0 = 1, held above a knee) from
///   the three lags of `x u, x^2 u, x^3 u` weighted by the fitted gains ([`fit_drift_poly`]),
///   then the lags refitted on `K(u) u`;
/// * with `hysteresis` and `nonlinear-gain`: the play columns scaled by the fitted K'(u), as
///   the stage scales the whole fast map (`K'(u) (0.79 u + h(u))`).
///
/// A refinement whose solve is singular keeps the previous fit.
///
/// `u_range` is the range the model file gets for K'(u) and K(u) below its knee
/// ([`catalogue::with_slow_but`]), so a K accepted here is one the stage accepts.
///
/// A fit these regressors ran before against the same `y0` (every bit, as a 64-bit hash, as
/// the products' key), set and span, whose rounds went as this call's would
/// ([`rounds_to_run`]), is not run again: the diagnosis fits the same set more than once
/// ([`FITS_KEPT`]), and the fit depends on these and the regressors alone (the records are
/// the ones the regressors were made for; their lazily computed Gram matrix, moments and
/// products are read only at their final values), so the kept result is the fit itself.
pub(super) fn fit_slow(
    data: &[Data],
    y0: &[Vec<f64>],
    x: &SlowRegressors,
    set: &[&str],
    u_range: (f64, f64),
    rounds: usize,
) -> Option<SlowParams> {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for y in y0 {
        y.len().hash(&mut h);
        for v in y {
            v.to_bits().hash(&mut h);
        }
    }
    let key = FitKey {
        y0: h.finish(),
        set: set.iter().map(|e| e.to_string()).collect(),
        u_range_bits: (u_range.0.to_bits(), u_range.1.to_bits()),
    };
    let (couple, has_drift) = coupling(data, set);
    let same = |k: &KeptFit| {
        k.key == key
            && match k.run.ran {
                None => true,
                ran => rounds_to_run(couple, has_drift, rounds, &k.run) == ran,
            }
    };
    if let Some(p) = x
        .fits
        .lock()
        .ok()
        .and_then(|f| f.iter().find(|k| same(k)).map(|k| k.fit.clone()))
    {
        return p;
    }
    let (fit, run) = fit_slow_once(data, y0, x, set, u_range, rounds);
    if let Ok(mut f) = x.fits.lock()
        && !f.iter().any(same)
    {
        if f.len() >= FITS_KEPT {
            f.pop_front();
        }
        f.push_back(KeptFit {
            key,
            run,
            fit: fit.clone(),
        });
    }
    fit
}

/// The rounds [`fit_slow`] runs at least before K'(u) may stop it as settled, and at most,
/// with `rounds` asked for.
fn round_limits(couple: bool, has_drift: bool, rounds: usize) -> (usize, usize) {
    let rounds = if has_drift { rounds } else { rounds.min(1) };
    let max_rounds = if couple && has_drift {
        rounds.max(COUPLE_ROUNDS_MAX)
    } else {
        rounds
    };
    (rounds, max_rounds)
}

/// Whether `set` couples K'(u) with the hysteresis table (`hysteresis` and `nonlinear-gain`
/// both), and whether it fits the drift's K(u).
fn coupling(data: &[Data], set: &[&str]) -> (bool, bool) {
    let couple = set.contains(&"hysteresis") && set.contains(&"nonlinear-gain");
    // The drift's K(u) shows as tails of different heights after steps to different levels;
    // without held levels its `K(u) u` through the slow lags is a static curvature the
    // records cannot tell from K'(u) (the thesis stage's 1 Hz sine named `nonlinear-gain`
    // with K = 1 and lost it to a knee'd K, session 15).
    let has_drift = set.contains(&"drift")
        && super::select::held_levels(data) >= super::select::HELD_LEVELS_MIN;
    (couple, has_drift)
}

/// [`fit_slow`] itself, run, and how its rounds went.
fn fit_slow_once(
    data: &[Data],
    y0: &[Vec<f64>],
    x: &SlowRegressors,
    set: &[&str],
    u_range: (f64, f64),
    rounds: usize,
) -> (Option<SlowParams>, RoundsRun) {
    let mut run = RoundsRun::default();
    let Some(mut p) = fit_slow_linear(data, y0, x, set, None) else {
        return (None, run);
    };
    let (couple, has_drift) = coupling(data, set);
    if !couple && !has_drift {
        return (Some(p), run);
    }
    // (beside a K'(u) the regressors already hold, the held base's, it stays: `for_set`)
    let mut shape = Shape {
        kprime: if couple { None } else { x.kprime },
        range: if couple || x.kprime.is_none() {
            u_range
        } else {
            x.kprime_range
        },
        ..Shape::default()
    };
    // The later rounds are for the drift's K (its time constants found with K = 1 are off
    // until K is known); K'(u) on the play sum alone settles in one (session 14). Beside the
    // drift's K it need not: the two trade, and K' after one round is a step of an
    // oscillation (`COUPLE_ROUNDS_MAX`), so the rounds go on until K' settles.
    let (rounds, max_rounds) = round_limits(couple, has_drift, rounds);
    // (K' as the stage has it: `Shape::kprime`)
    let kprime_at = |g: Option<(f64, f64)>, u: f64| {
        Shape {
            kprime: g,
            range: u_range,
            ..Shape::default()
        }
        .kprime(u)
    };
    for round in 0..max_rounds {
        if couple {
            // (settled: K' moved less than `COUPLE_SETTLED` at both ends of the span and its
            // middle in the last round; kept for every round, for the memo's `rounds_to_run`)
            let settled = [u_range.0, 0.5 * (u_range.0 + u_range.1), u_range.1]
                .iter()
                .all(|&u| {
                    (kprime_at(p.gain, u) - kprime_at(shape.kprime, u)).abs() < COUPLE_SETTLED
                });
            run.settled.push(settled);
            if round >= rounds && settled {
                run.ran = Some(round);
                return (Some(p), run);
            }
            shape.kprime = p.gain;
        }
        // The regressors with this round's K'(u) and K = 1, their Gram matrix computed once:
        // K(u)'s fit takes its fixed columns' block from it, and the round's solve (only the
        // lags changed) all but the lags' rows.
        let plain_shape = Shape {
            kdrift: None,
            ..shape
        };
        // `x`, the step's regressors, has K = 1: with its K' it is the plain one itself.
        let plain = if plain_shape.kprime == x.kprime {
            None
        } else {
            Some(slow_regressors_shaped(data, &plain_shape, x))
        };
        let plain = plain.as_ref().unwrap_or(x);
        if has_drift && let Some(k) = fit_drift_poly(data, y0, plain, &shape, &p) {
            shape.kdrift = Some(k);
        }
        let shaped;
        let xs = if shape.kdrift.is_some() {
            shaped = slow_regressors_shaped(data, &shape, plain);
            &shaped
        } else {
            plain
        };
        match fit_slow_linear(data, y0, xs, set, p.drift.map(|d| d.1)) {
            Some(mut q) => {
                q.drift_poly = shape.kdrift;
                p = q;
            }
            None => {
                run.failed_at = Some(round);
                run.ran = Some(round);
                return (Some(p), run);
            }
        }
    }
    run.ran = Some(max_rounds);
    (Some(p), run)
}

/// K(u) of the drift and its knee given the present fit `p` (gains, time constants) on the
/// regressors `x` with K = 1 and the round's K'(u) on their play columns (`shape` gives the
/// inputs' span): for each knee of [`DRIFT_KNEES`], one weighted solve with the three
/// lags of `u`, the lags of `c(u) u` for `c = x, x^2, x^3` (`x` the input held above the knee)
/// weighted by the present gains (their coefficients are `k1..k3`), and the other slow effects'
/// columns. The knees are ranked by an unconstrained solve (the fixed columns' block factored
/// once, a 6 x 6 Schur complement per knee), then solved with the constraints in that order
/// until one gives a valid K. A K whose `K(u) u` is not strictly
/// increasing (the stage refuses it) is drawn towards K = 1 until it is; `None` if no solve is
/// regular.
///
/// Why a knee: the thesis fitted its cubic K on steps of 1..6 V and the cubic turns steeply
/// beyond; a cubic over the whole span cannot hold still above the steps it was shaped on.
/// Measured on `thesis-full`'s 150 s records with everything else the truth's, the drift alone
/// left 25.8 mV (10x the floor) with K over the span and a false `hysteresis` and
/// `sensor-gain` beside it; with the knee (and the second round of [`fit_slow`]) 1.02x, the
/// knee at 6.0 V and the time constants within 1.5 % of the truth's (0.0595, 0.739 and
/// 11.99 s against 0.06, 0.75 and 12 s).
#[allow(clippy::needless_range_loop)] // lags, powers and gains indexed together
fn fit_drift_poly(
    data: &[Data],
    y0: &[Vec<f64>],
    x: &SlowRegressors,
    shape: &Shape,
    p: &SlowParams,
) -> Option<([f64; 4], f64)> {
    let (gains, taus) = p.drift?;
    let mut fixed: Vec<usize> = Vec::new();
    if p.hysteresis.is_some() {
        fixed.extend(hyst_cols(x.form));
    }
    if p.gain.is_some() {
        fixed.extend([COL_GAIN, COL_GAIN + 1]);
    }
    if p.offset_v.is_some() {
        fixed.push(COL_OFFSET);
    }
    if p.sensor_gain.is_some() {
        fixed.push(COL_SGAIN);
    }
    let (lo, hi) = shape.range;
    let knees: Vec<f64> = DRIFT_KNEES.iter().map(|f| lo + f * (hi - lo)).collect();
    let nk = knees.len();
    let nf = fixed.len();
    let np = 6 + nf;
    let nd = 6 * nk;
    // The fixed columns' block is the same for every knee: the regressors' own Gram matrix
    // with this `y0`'s sensor-gain row (computed once, and kept for the round's solve). Per
    // knee only the six drift columns' products with everything.
    let (g, b) = target_gram(data, y0, x);
    let g_ff = DMatrix::<f64>::from_fn(nf, nf, |i, j| g[(fixed[i], fixed[j])]);
    let b_f = DVector::<f64>::from_fn(nf, |i, _| b[fixed[i]]);
    let mut g_d = vec![DMatrix::<f64>::zeros(6, np); nk];
    let mut b_d = vec![DVector::<f64>::zeros(6); nk];
    for (r, d) in data.iter().enumerate() {
        let t = d.period_s();
        let a = taus.map(|tau| (-t / tau).exp());
        // Per knee, the input's drives `x^j u` (j = 1..3, `x` the input held above the knee),
        // each through the three lags: nine states, index `3 j + k`.
        let drives = |u: f64, knee: f64| {
            let x = u.clamp(lo, knee);
            let d1 = x * u;
            let d2 = x * d1;
            [d1, d1, d1, d2, d2, d2, x * d2, x * d2, x * d2]
        };
        let c9: [f64; 9] = std::array::from_fn(|m| 1.0 - a[m % 3]);
        // Lags at rest at the first sample.
        let mut lu = [d.u_v[0]; 3];
        let mut lp: Vec<[f64; 9]> = knees.iter().map(|&kn| drives(d.u_v[0], kn)).collect();
        let rows = &x.rows[r];
        let n = rows.len();
        let w = 1.0 / n.max(1) as f64;
        // Every knee's six drift columns at the settled samples, row-major (a row's `6 nk`
        // values side by side, so a product with a column runs over them in lanes).
        let mut dr: Vec<f64> = Vec::with_capacity(n * nd);
        let mut next = 0usize;
        for i in 0..d.len() {
            if next < n && rows[next] == i {
                for l in &lp {
                    dr.extend_from_slice(&lu);
                    for j in 0..3 {
                        dr.push((0..3).map(|k| gains[k] * l[3 * j + k]).sum());
                    }
                }
                next += 1;
            }
            let u = d.u_v[i];
            for k in 0..3 {
                lu[k] += c9[k] * (u - lu[k]);
            }
            for (l, &kn) in lp.iter_mut().zip(&knees) {
                let v = drives(u, kn);
                for m in 0..9 {
                    l[m] += c9[m] * (v[m] - l[m]);
                }
            }
        }
        let e: Vec<f64> = rows.iter().map(|&i| d.y_v[i] - y0[r][i]).collect();
        let s: Vec<f64> = rows.iter().map(|&i| y0[r][i]).collect();
        let ones = vec![1.0; n];
        let column = |c: usize| -> &[f64] {
            match c {
                COL_OFFSET => &ones,
                COL_SGAIN => &s,
                _ => &x.cols[r][c],
            }
        };
        // The drift columns' products with a column, all knees at once.
        let with_drift = |v: &[f64]| -> Vec<f64> {
            let mut acc = vec![0.0; nd];
            for (row, vi) in dr.chunks_exact(nd).zip(v) {
                for (a, di) in acc.iter_mut().zip(row) {
                    *a += vi * di;
                }
            }
            acc
        };
        // The fixed columns' products with the drift columns: a blocked matrix product
        // (nalgebra's gemm) over the columns the regressors keep, the sensor gain's apart.
        let kept_cols: Vec<usize> = fixed.iter().copied().filter(|&c| c != COL_SGAIN).collect();
        // (The drift columns stored row by row are, read column by column, their transpose.)
        let mut df = DMatrix::<f64>::zeros(nd, kept_cols.len());
        for block in row_blocks(n) {
            let f = design(&x.cols[r], block.clone(), &kept_cols);
            let dt =
                DMatrix::from_column_slice(nd, block.len(), &dr[block.start * nd..block.end * nd]);
            df += dt * f;
        }
        // (`p`: the column's place among those the product took. The fixed columns' products
        // with the target and the sensor gain's are the regressors' kept ones, below.)
        let mut p = 0;
        for (i, &ci) in fixed.iter().enumerate() {
            let gd: Vec<f64> = if ci == COL_SGAIN {
                with_drift(column(ci))
            } else {
                p += 1;
                df.column(p - 1).iter().copied().collect()
            };
            for q in 0..nk {
                for k in 0..6 {
                    g_d[q][(k, 6 + i)] += w * gd[6 * q + k];
                }
            }
        }
        let be = with_drift(&e);
        for row in dr.chunks_exact(nd) {
            for q in 0..nk {
                let v = &row[6 * q..6 * q + 6];
                for k in 0..6 {
                    for l in 0..6 {
                        g_d[q][(k, l)] += w * v[k] * v[l];
                    }
                }
            }
        }
        for q in 0..nk {
            for k in 0..6 {
                b_d[q][k] += w * be[6 * q + k];
            }
        }
    }
    let nonneg: Vec<bool> = (0..np)
        .map(|k| k < 3 || (k >= 6 && is_nonneg_col(fixed[k - 6])))
        .collect();
    let valid = |k: [f64; 4], knee: f64| {
        model_core::drift::DriftConfig {
            gains,
            taus_s: taus,
            poly: k,
            poly_range_v: (lo, knee),
        }
        .validate()
        .is_ok()
    };
    // The knees ranked by what an unconstrained solve leaves out: with the fixed block `F`
    // factored once, each knee's gain over the fixed columns alone is `r' S^-1 r`, with
    // `S = G_dd - G_df F^-1 G_fd` and `r = b_d - G_df F^-1 b_f`.
    let mut order: Vec<(f64, usize)> = Vec::with_capacity(nk);
    let mut f_reg = g_ff.clone();
    ridge(&mut f_reg);
    match f_reg.cholesky() {
        Some(ch) => {
            let fb = ch.solve(&b_f);
            for q in 0..nk {
                let gdf = g_d[q].columns(6, nf);
                let fx = ch.solve(&gdf.transpose());
                let mut sq = g_d[q].columns(0, 6) - gdf * &fx;
                ridge(&mut sq);
                let r = &b_d[q] - gdf * &fb;
                if let Some(cs) = sq.cholesky() {
                    order.push((r.dot(&cs.solve(&r)), q));
                }
            }
            order.sort_by(|a, b| b.0.total_cmp(&a.0));
        }
        None => order.extend((0..nk).map(|q| (0.0, q))),
    }
    // In that order: the fit's K (drawn towards 1 until valid, the first such kept as a
    // fallback), until one is valid as it stands.
    let gg: f64 = gains.iter().map(|g| g * g).sum();
    let mut best: Option<([f64; 4], f64)> = None;
    for (_, q) in order {
        let mut g = DMatrix::<f64>::zeros(np, np);
        let mut b = DVector::<f64>::zeros(np);
        g.view_mut((0, 0), (6, np)).copy_from(&g_d[q]);
        let gdf = g_d[q].columns(6, nf).transpose();
        g.view_mut((6, 0), (nf, 6)).copy_from(&gdf);
        g.view_mut((6, 6), (nf, nf)).copy_from(&g_ff);
        b.rows_mut(0, 6).copy_from(&b_d[q]);
        b.rows_mut(6, nf).copy_from(&b_f);
        let Some((beta, _)) = solve_slow(g, &b, &fixed, 6, &nonneg, None, x.table_gain) else {
            continue;
        };
        // The lags of `u` came out at `s` times the present gains (least squares over the
        // three): K's constant term is `s`, so the other terms are taken relative to it.
        let s = (0..3).map(|k| beta[k] * gains[k]).sum::<f64>() / gg;
        if s.is_nan() || s <= 0.0 {
            continue;
        }
        let k = [1.0, beta[3] / s, beta[4] / s, beta[5] / s];
        if !k.iter().all(|v| v.is_finite()) {
            continue;
        }
        let Some((whole, ka)) = (0..10).rev().find_map(|i| {
            let s = (i + 1) as f64 / 10.0;
            let ka = [1.0, s * k[1], s * k[2], s * k[3]];
            valid(ka, knees[q]).then_some((i == 9, ka))
        }) else {
            continue;
        };
        if whole {
            return Some((ka, knees[q]));
        }
        best.get_or_insert((ka, knees[q]));
    }
    best
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
    let (g, b) = target_gram(data, y0, x);
    let solve = |idx: &[usize], warm: Option<&[bool]>| -> Option<(Vec<f64>, f64)> {
        let p = idx.len();
        let mut a = DMatrix::<f64>::zeros(p, p);
        let mut v = DVector::<f64>::zeros(p);
        for (i, &ki) in idx.iter().enumerate() {
            v[i] = b[ki];
            for (j, &kj) in idx.iter().enumerate() {
                a[(i, j)] = g[(ki, kj)];
            }
        }
        let nonneg: Vec<bool> = idx.iter().map(|&k| is_nonneg_col(k)).collect();
        let (beta, red) = solve_slow(a, &v, idx, 0, &nonneg, warm, x.table_gain)?;
        Some((beta.iter().copied().collect(), red))
    };
    let fixed = fixed_cols(set, x.form);
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
            hysteresis: set.contains(&"hysteresis").then(|| HystFit {
                start_v: x.start_v.clone(),
                range: x.range,
                form: x.form,
                weights: (0..HYST_COLS).map(|i| get(COL_HYST + i)).collect(),
            }),
            gain: set
                .contains(&"nonlinear-gain")
                .then(|| (get(COL_GAIN), get(COL_GAIN + 1))),
            drift_poly: None,
            sensor_gain: set.contains(&"sensor-gain").then(|| 1.0 + get(COL_SGAIN)),
            offset_v: set.contains(&"offset").then(|| get(COL_OFFSET)),
        }
    };
    if set.contains(&"drift") {
        // Time constants beyond DRIFT_TAU_MAX_RECORDS record lengths are not drift the records
        // can show: such a lag barely moves within them and acts as a constant (an offset) or
        // a ramp.
        let tau_max = DRIFT_TAU_MAX_RECORDS * super::data::longest_record_s(data);
        let n_tau = catalogue::DRIFT_TAU_GRID_S
            .iter()
            .filter(|t| **t <= tau_max)
            .count()
            .max(3);
        let grid = catalogue::DRIFT_TAU_GRID_S;
        let problem = DriftProblem::new(data, y0, x, &fixed, &g, &b, usize::MAX);
        // A refit from earlier time constants (the structural round) starts there: the grid
        // is for a fit from nothing.
        let (taus0, beta_grid) = if let Some(t0) = start {
            let (beta, _) = problem.solve(&t0)?;
            (t0, beta)
        } else {
            // The grid is ranked by the Schur evaluation (the fixed part's free set taken from an
            // exact solve at a spread of the grid, then again at the first ranking's best), and
            // its best triple solved exactly; every triple solved exactly where that fails.
            let solve_aug = |idx: &[usize], warm: Option<&[bool]>| {
                let p = idx.len();
                let a = DMatrix::from_fn(p, p, |i, j| g[(idx[i], idx[j])]);
                let v = DVector::from_fn(p, |i, _| b[idx[i]]);
                let nonneg: Vec<bool> = idx.iter().map(|&k| is_nonneg_col(k)).collect();
                solve_slow_augmented(a, &v, idx, 0, &nonneg, warm, x.table_gain)
            };
            let with_fixed =
                |t: [usize; 3]| -> Vec<usize> { t.iter().chain(&fixed).copied().collect() };
            let nf = fixed.len();
            let g_ff = DMatrix::from_fn(nf, nf, |i, j| g[(fixed[i], fixed[j])]);
            let b_f = DVector::from_fn(nf, |i, _| b[fixed[i]]);
            let rank = |beta_a: &DVector<f64>| -> Option<[usize; 3]> {
                let schur = Schur::new(&g_ff, &b_f, &fixed, x.table_gain, beta_a)?;
                let z: Vec<DVector<f64>> = (0..n_tau)
                    .map(|l| {
                        let gdf: Vec<f64> = fixed.iter().map(|&c| g[(l, c)]).collect();
                        schur.project(&gdf)
                    })
                    .collect();
                let mut best: Option<(f64, [usize; 3])> = None;
                for i in 0..n_tau {
                    for j in i + 1..n_tau {
                        for k in j + 1..n_tau {
                            let t = [i, j, k];
                            let g_dd = [0, 1, 2].map(|a| [0, 1, 2].map(|c| g[(t[a], t[c])]));
                            let b_d = t.map(|l| b[l]);
                            let (red, gains) = schur.value(&g_dd, &b_d, [&z[i], &z[j], &z[k]]);
                            if gains.iter().all(|g| *g <= 1.0) && best.is_none_or(|b| red > b.0) {
                                best = Some((red, t));
                            }
                        }
                    }
                }
                best.map(|b| b.1)
            };
            // Each exact solve starts from the last one's positive set ([`warm_set`]): the
            // fixed columns are the same and only the three lags change (the same optimum
            // within the solver's tolerance, fewer factorisations).
            let spread = [0, n_tau / 2, n_tau - 1];
            let ranked = solve_aug(&with_fixed(spread), None)
                .and_then(|(b0, _, a)| Some((rank(&a)?, warm_set(b0.as_slice()))))
                .and_then(|(t, w)| {
                    let (b1, _, a) = solve_aug(&with_fixed(t), Some(&w))?;
                    Some((rank(&a)?, warm_set(b1.as_slice())))
                })
                .and_then(|(t, w)| {
                    let (beta, red, _) = solve_aug(&with_fixed(t), Some(&w))?;
                    let ok = beta.iter().take(3).all(|g| g.abs() <= 1.0);
                    ok.then(|| (red, t, beta.iter().copied().collect::<Vec<f64>>()))
                });
            let mut best: Option<(f64, [usize; 3], Vec<f64>)> = ranked;
            // Each solve starts from the previous one's positive set ([`warm_set`]): neighbouring
            // triples share most of it.
            let mut warm: Option<Vec<bool>> = None;
            if best.is_none() {
                for i in 0..n_tau {
                    for j in i + 1..n_tau {
                        for k in j + 1..n_tau {
                            let mut idx = vec![i, j, k];
                            idx.extend(&fixed);
                            if let Some((beta, red)) = solve(&idx, warm.as_deref()) {
                                warm = Some(warm_set(&beta));
                                let ok = beta.iter().take(3).all(|g| g.abs() <= 1.0);
                                if ok && best.as_ref().is_none_or(|b| red > b.0) {
                                    best = Some((red, [i, j, k], beta));
                                }
                            }
                        }
                    }
                }
            }
            let (_, ti, beta_grid) = best?;
            (ti.map(|i| grid[i]), beta_grid)
        };
        // The refinement searches with the hysteresis radii the grid's best solve uses (all
        // the columns of each, its bands and its outside columns, so the band penalty stays
        // whole: `everett::radius_group`) and every other fixed column; the final solve has
        // them all (the basis' 22 radii x 11 bands would otherwise enter each of the
        // refinement's few hundred solves).
        let radius_of = |c: usize| everett::radius_group(c - COL_HYST);
        let is_hyst = |c: usize| (COL_HYST..COL_HYST + HYST_COLS).contains(&c);
        let used_radii: std::collections::BTreeSet<usize> = fixed
            .iter()
            .enumerate()
            .filter(|&(p, &c)| is_hyst(c) && beta_grid[3 + p] != 0.0)
            .map(|(_, &c)| radius_of(c))
            .collect();
        let fixed_search: Vec<usize> = fixed
            .iter()
            .copied()
            .filter(|&c| !is_hyst(c) || used_radii.contains(&radius_of(c)))
            .collect();
        // Refine the three time constants continuously (in log tau, between their
        // neighbours), each try with the other columns.
        let mut taus = taus0;
        // The search evaluates on evenly thinned rows (DRIFT_SEARCH_ROWS a record), the final
        // solve on all of them.
        let search = DriftProblem::new(data, y0, x, &fixed_search, &g, &b, DRIFT_SEARCH_ROWS);
        // The searches' and the final solve's first active-set solves start from the grid's
        // best solution's positive set (the lags free): the same optimum within the solver's
        // tolerance, fewer changes of the set than from none.
        let positive = |c: usize| {
            fixed
                .iter()
                .position(|&f| f == c)
                .is_some_and(|p| beta_grid[3 + p] > 0.0)
        };
        *search.warm.borrow_mut() = Some(
            [true; 3]
                .into_iter()
                .chain(fixed_search.iter().map(|&c| positive(c)))
                .collect(),
        );
        if problem.warm.borrow().is_none() {
            *problem.warm.borrow_mut() = Some(warm_set(&beta_grid));
        }
        // Each try is ranked by the Schur evaluation, its fixed part's free set from an exact
        // solve at the grid's best (every try solved exactly where that fails).
        let schur = search.schur_at(&taus);
        let eval = |taus: &[f64; 3]| -> f64 {
            let (gains, red) = match &schur {
                Some(s) => search.value(s, taus),
                None => match search.solve(taus) {
                    Some((beta, red)) => ([beta[0], beta[1], beta[2]], red),
                    None => return f64::NEG_INFINITY,
                },
            };
            if gains.iter().all(|g| g.abs() <= 1.0) {
                red
            } else {
                f64::NEG_INFINITY
            }
        };
        // The valley is narrow (a shorter first lag and a play operator of small threshold
        // trade against each other): coordinate descent zig-zags down it (it used all of its
        // 12 passes on the demo's fits, 500-560 evaluations each). So after one wide
        // coordinate pass (a fit from nothing: the grid's best may sit a grid step off), a
        // damped Newton step in log tau ([`newton_step`]) moves the three together; where it
        // cannot (a difference point outside the bounds or past a gain of 1, no damping that
        // gains), a narrow coordinate pass does. It stops when an iteration gains less than
        // DRIFT_REFINE_TOL_V2 of weighted residual power.
        let tau_hi = (grid[N_TAU - 1] * 2.0).min(tau_max.max(grid[n_tau - 1]));
        let bounds = |m: usize, taus: &[f64; 3]| -> (f64, f64) {
            let lo = if m > 0 {
                taus[m - 1] * TAU_SEPARATION
            } else {
                grid[0] * 0.5
            };
            let hi = if m < 2 {
                taus[m + 1] / TAU_SEPARATION
            } else {
                tau_hi
            };
            (lo, hi)
        };
        let inside = |taus: &[f64; 3]| {
            (0..3).all(|m| {
                let (lo, hi) = bounds(m, taus);
                taus[m] >= lo && taus[m] <= hi
            })
        };
        let coordinate_pass =
            |taus: &mut [f64; 3], cur_val: &mut f64, factor: f64, iters: usize| {
                for m in 0..3 {
                    let (lo, hi) = bounds(m, taus);
                    // Also skips NaN bounds.
                    if lo.partial_cmp(&hi) != Some(std::cmp::Ordering::Less) {
                        continue;
                    }
                    let a = lo.max(taus[m] / factor).ln();
                    let b = hi.min(taus[m] * factor).ln();
                    if a.partial_cmp(&b) != Some(std::cmp::Ordering::Less) {
                        continue;
                    }
                    let cur = *taus;
                    let lt = golden_n(a, b, a, b, iters, |lt| {
                        let mut t = cur;
                        t[m] = lt.exp();
                        -eval(&t)
                    });
                    let mut t = cur;
                    t[m] = lt.exp();
                    let v = eval(&t);
                    if v > *cur_val {
                        (*taus, *cur_val) = (t, v);
                    }
                }
            };
        let mut cur_val = eval(&taus);
        // The wide pass searches a factor 3 either side to about 5 % of tau (the Newton
        // steps do the rest), the narrow ones 1.25 to about 0.1 %; a refit from earlier time
        // constants (the structural round) has no wide pass.
        if start.is_none() {
            coordinate_pass(&mut taus, &mut cur_val, 3.0, 8);
        }
        let at_log = |lt: [f64; 3]| -> f64 {
            let t = lt.map(f64::exp);
            if inside(&t) {
                eval(&t)
            } else {
                f64::NEG_INFINITY
            }
        };
        // The log time constants kept beside `taus`, so that the parts of a Newton step's
        // points are found again by the next (`exp(ln(tau))` need not give `tau` back).
        let mut lt = taus.map(f64::ln);
        for _ in 0..DRIFT_REFINE_ITERATIONS {
            let last = cur_val;
            match newton_step(&at_log, lt, cur_val) {
                Newton::Moved(l, v) => (lt, taus, cur_val) = (l, l.map(f64::exp), v),
                Newton::Converged => break,
                Newton::Stuck => {
                    coordinate_pass(&mut taus, &mut cur_val, 1.25, 12);
                    lt = taus.map(f64::ln);
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
        Some(descale(p))
    } else {
        if fixed.is_empty() {
            return None;
        }
        let (beta, _) = solve(&fixed, None)?;
        Some(descale(unpack(&fixed, &beta, None)))
    }
}

/// The weighted Gram matrix of all of `x`'s columns and their products with the target, for
/// the model without slow effects `y0`: the input-only part is the regressors' own (computed
/// once), the sensor gain's row and the target's products are this `y0`'s
/// ([`target_products`], kept for the few last).
fn target_gram(data: &[Data], y0: &[Vec<f64>], x: &SlowRegressors) -> (DMatrix<f64>, DVector<f64>) {
    let mut g = x.gram.get_or_init(|| input_gram(x)).clone();
    let tp = target_products(data, y0, x);
    // (The kept Gram matrix's sensor-gain row and column are zero.)
    for k in 0..N_COLS {
        if k != COL_SGAIN {
            g[(k, COL_SGAIN)] += tp.g_s[k];
            g[(COL_SGAIN, k)] += tp.g_s[k];
        }
    }
    g[(COL_SGAIN, COL_SGAIN)] += tp.g_s[COL_SGAIN];
    (g, tp.b.clone())
}

/// The [`TargetProducts`] of `x` for the model without slow effects `y0` (kept in `x` for
/// the last [`PRODUCTS_KEPT`] of them). `data` are the records `x` was built from.
fn target_products(
    data: &[Data],
    y0: &[Vec<f64>],
    x: &SlowRegressors,
) -> std::sync::Arc<TargetProducts> {
    use std::hash::{Hash, Hasher};
    // The products read `y0` at the regressors' rows only: the key is those values' bits.
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for (y, rows) in y0.iter().zip(&x.rows) {
        rows.len().hash(&mut h);
        for &i in rows {
            y[i].to_bits().hash(&mut h);
        }
    }
    let key = h.finish();
    let kept = |k: u64| {
        x.products
            .lock()
            .ok()
            .and_then(|p| p.iter().find(|(q, _)| *q == k).map(|(_, t)| t.clone()))
    };
    if let Some(t) = kept(key) {
        return t;
    }
    // Regressors that differ from their parent's in the lags alone take the parent's products
    // of the other columns (the same values, summed in the same order) and compute the lags'.
    let parent = x
        .lag_parent
        .iter()
        .find(|(q, _)| *q == key)
        .map(|(_, t)| t.clone());
    let mut b = DVector::<f64>::zeros(N_COLS);
    let mut g_s = DVector::<f64>::zeros(N_COLS);
    if let Some(p) = &parent {
        for k in N_TAU..N_COLS {
            b[k] = p.b[k];
            g_s[k] = p.g_s[k];
        }
    }
    for (r, d) in data.iter().enumerate() {
        let cols = &x.cols[r];
        let rows = &x.rows[r];
        let w = 1.0 / rows.len().max(1) as f64;
        let e: Vec<f64> = rows.iter().map(|&i| d.y_v[i] - y0[r][i]).collect();
        let s: Vec<f64> = rows.iter().map(|&i| y0[r][i]).collect();
        let taken = if parent.is_some() { N_TAU } else { cols.len() };
        for (k, c) in cols.iter().enumerate().take(taken) {
            // Both products in one pass over the column (the pass is memory-bound).
            let (ce, cs) = c
                .iter()
                .zip(e.iter().zip(&s))
                .fold((0.0, 0.0), |(a, b), (v, (x, y))| (a + v * x, b + v * y));
            b[k] += w * ce;
            g_s[k] += w * cs;
        }
        if parent.is_none() {
            b[COL_OFFSET] += w * e.iter().sum::<f64>();
            b[COL_SGAIN] += w * dot(&s, &e);
            g_s[COL_OFFSET] += w * s.iter().sum::<f64>();
            g_s[COL_SGAIN] += w * dot(&s, &s);
        }
    }
    let t = std::sync::Arc::new(TargetProducts { b, g_s });
    if let Ok(mut p) = x.products.lock() {
        // (A parallel candidate may have computed the same ones meanwhile.)
        if let Some((_, kept)) = p.iter().find(|(q, _)| *q == key) {
            return kept.clone();
        }
        if p.len() >= PRODUCTS_KEPT {
            p.remove(0);
        }
        p.push((key, t.clone()));
    }
    t
}

/// The slow effects' weights as the stage has them: the monitor's scale error `g` multiplies
/// everything before the sensor, so the solve's coefficients of the drift, play and gain
/// columns are `g` times the stage's parameters.
fn descale(mut p: SlowParams) -> SlowParams {
    let Some(g) = p.sensor_gain.filter(|g| *g > 0.1) else {
        return p;
    };
    if let Some((gains, _)) = p.drift.as_mut() {
        for v in gains.iter_mut() {
            *v /= g;
        }
    }
    if let Some(h) = p.hysteresis.as_mut() {
        for v in h.weights.iter_mut() {
            *v /= g;
        }
    }
    if let Some((c1, c2)) = p.gain.as_mut() {
        *c1 /= g;
        *c2 /= g;
    }
    p
}

/// Is regressor column `k` one whose coefficient is kept >= 0: a drift lag's or a play
/// operator's? A stage creeps in the direction of its step (the thesis' three drift gains are
/// positive); unconstrained, two lags of nearly equal time constants and opposite gains of
/// +-0.45 make a band-pass that mimics hysteresis. With negative play weights the fitted loop
/// could turn clockwise or the output run backwards after a reversal, which no stage does;
/// unconstrained, a lone hysteresis fit soaks up drift and gain errors with weights of +-2.
fn is_nonneg_col(k: usize) -> bool {
    k < N_TAU || (COL_HYST..COL_HYST + everett::HYST_NONNEG_COLS).contains(&k)
}

/// Weight of the table-validity penalty of `solve_slow`, in units of the data's own
/// curvature along the penalised direction (our assumption: a band's loop weights then exceed
/// the table's reversible slope by at most a thousandth of what the unconstrained fit would
/// take, which the grid's repair ([`everett`]'s `monotone`) absorbs without a visible change,
/// while the system's condition grows by the same thousand only).
pub const HYST_VALID_WEIGHT: f64 = 1e3;

/// The non-negative solve of a slow system: Gram matrix `g` and products `b` (without the
/// band penalty), whose variables from `at` on are the regressor columns `cols`; `nonneg`
/// marks the variables kept non-negative, `warm` guesses their free set
/// ([`nnls_normal_from`]). Returns the coefficients and the reduction of the weighted SSR
/// they bring (`2 x'b - x'Gx`).
///
/// # The table's validity
/// A loop column is a band-limited play's relays minus their reversible part, so the fitted
/// table is `E = sum_k s_k |[b, a] ^ band_k| + sum_rk m_rk T_rk` with `s_k` = the table's
/// reversible slope `g0` ([`SlowRegressors::table_gain`]) less the band's loop weights
/// `sum_r m_rk`. With every `m_rk >= 0` and every `s_k >= 0` that is a sum of valid Everett
/// functions with non-negative weights, so a table the stage accepts; with `s_k < 0` it falls
/// near its diagonal (a branch that goes down as the input goes up). A record that does not
/// probe the whole Preisach triangle (one sine: two branches of it) lets the unconstrained
/// fit do that, and the grid's repair then moved 217 of 990 values of a Duhem fit by up to
/// 290 mV, a 16 mV fit simulated at 70 mV (families case 1037). So each band with loop
/// columns gets a slack `s_k >= 0` and the penalty
/// `HYST_VALID_WEIGHT c_k (sum_r m_rk + s_k - g0)^2` (`c_k`: the data's curvature along the
/// band's weights): zero while the band's weights stay within `g0`, steep beyond.
fn solve_slow(
    g: DMatrix<f64>,
    b: &DVector<f64>,
    cols: &[usize],
    at: usize,
    nonneg: &[bool],
    warm: Option<&[bool]>,
    table_gain: f64,
) -> Option<(DVector<f64>, f64)> {
    solve_slow_augmented(g, b, cols, at, nonneg, warm, table_gain).map(|(beta, red, _)| (beta, red))
}

/// A slow system with the band penalty, the ridge and the validity slacks of [`solve_slow`]:
/// the Gram matrix and products over the variables then one slack per band with loop columns
/// (none when there is no reversible slope to keep), and which variables are non-negative.
struct Augmented {
    g: DMatrix<f64>,
    b: DVector<f64>,
    nonneg: Vec<bool>,
    /// The number of variables before the slacks.
    p: usize,
    /// The Gram matrix with the band penalty and the ridge, without the slacks' terms.
    g_plain: DMatrix<f64>,
}

fn augment(
    mut g: DMatrix<f64>,
    b: &DVector<f64>,
    cols: &[usize],
    at: usize,
    nonneg: &[bool],
    table_gain: f64,
) -> Augmented {
    band_penalty(&mut g, cols, at);
    ridge(&mut g);
    let p = g.nrows();
    // The positions of each band's loop columns.
    let bands: Vec<Vec<usize>> = (0..everett::HYST_BANDS)
        .map(|k| {
            (0..everett::HYST_RADII)
                .filter_map(|i| {
                    let c = COL_HYST + everett::col(i, k);
                    cols.iter().position(|&q| q == c).map(|q| at + q)
                })
                .collect::<Vec<usize>>()
        })
        .filter(|ps| !ps.is_empty())
        .collect();
    // (a NaN gain holds nothing either)
    if bands.is_empty() || table_gain.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Augmented {
            g: g.clone(),
            b: b.clone(),
            nonneg: nonneg.to_vec(),
            p,
            g_plain: g,
        };
    }
    let n = p + bands.len();
    let mut ga = DMatrix::<f64>::zeros(n, n);
    ga.view_mut((0, 0), (p, p)).copy_from(&g);
    let mut ba = DVector::<f64>::zeros(n);
    ba.rows_mut(0, p).copy_from(b);
    for (k, ps) in bands.iter().enumerate() {
        let curv: f64 = ps
            .iter()
            .map(|&i| ps.iter().map(|&j| g[(i, j)]).sum::<f64>())
            .sum();
        let lam = HYST_VALID_WEIGHT * curv.max(1e-300);
        let s = p + k;
        let all: Vec<usize> = ps.iter().copied().chain([s]).collect();
        for &i in &all {
            ba[i] += lam * table_gain;
            for &j in &all {
                ga[(i, j)] += lam;
            }
        }
    }
    let nonneg_a: Vec<bool> = nonneg
        .iter()
        .copied()
        .chain(bands.iter().map(|_| true))
        .collect();
    Augmented {
        g: ga,
        b: ba,
        nonneg: nonneg_a,
        p,
        g_plain: g,
    }
}

/// [`solve_slow`], also returning the solution of the augmented system (the slacks after the
/// variables), whose positive set starts a [`Schur`] search.
fn solve_slow_augmented(
    g: DMatrix<f64>,
    b: &DVector<f64>,
    cols: &[usize],
    at: usize,
    nonneg: &[bool],
    warm: Option<&[bool]>,
    table_gain: f64,
) -> Option<(DVector<f64>, f64, DVector<f64>)> {
    let a = augment(g, b, cols, at, nonneg, table_gain);
    let p = a.p;
    let warm_a: Option<Vec<bool>> = warm.map(|w| {
        w.iter()
            .copied()
            .chain(std::iter::repeat_n(true, a.g.nrows() - p))
            .collect()
    });
    let beta_a = nnls_normal_from(&a.g, &a.b, &a.nonneg, warm_a.as_deref())?;
    let beta = beta_a.rows(0, p).into_owned();
    let red = 2.0 * beta.dot(b) - beta.dot(&(&a.g_plain * &beta));
    (beta.iter().all(|v| v.is_finite()) && red.is_finite()).then_some((beta, red, beta_a))
}

/// The drift searches' fast evaluation (grid and refinement): with the fixed columns' free set
/// held at a reference solve's, the fixed part is factored once and each try of three time
/// constants solves only their 3 x 3 Schur complement (non-negative gains by enumeration of
/// its 8 active sets), `O(n^2)` instead of an active-set solve of the `n` fixed columns
/// (`O(n^3)` a factorisation, several a solve). It ranks the tries; the chosen time constants
/// are then solved exactly ([`solve_slow`]). Measured on `thesis-full`'s 150 s records (265
/// fixed columns): the grid's 364 exact solves took 1-2 s a fit and the refinement's 0.2-1 s.
struct Schur {
    /// The fixed columns' free positions (in the augmented fixed system).
    free: Vec<usize>,
    /// The factor of the free block.
    chol: nalgebra::Cholesky<f64, nalgebra::Dyn>,
    /// `L^-1 b_F`.
    zb: DVector<f64>,
    /// The number of fixed columns (before the slacks).
    nf: usize,
}

impl Schur {
    /// From the fixed columns' Gram matrix and products (`g_ff`, `b_f`, columns `fixed`) and
    /// a reference solution of the augmented system with the three lags first (`beta_a`).
    fn new(
        g_ff: &DMatrix<f64>,
        b_f: &DVector<f64>,
        fixed: &[usize],
        table_gain: f64,
        beta_a: &DVector<f64>,
    ) -> Option<Self> {
        let nonneg: Vec<bool> = fixed.iter().map(|&c| is_nonneg_col(c)).collect();
        let a = augment(g_ff.clone(), b_f, fixed, 0, &nonneg, table_gain);
        let n = a.g.nrows();
        if beta_a.len() != n + 3 {
            return None;
        }
        let free: Vec<usize> = (0..n)
            .filter(|&q| !a.nonneg[q] || beta_a[3 + q] > 0.0)
            .collect();
        let sub = DMatrix::from_fn(free.len(), free.len(), |i, j| a.g[(free[i], free[j])]);
        let chol = sub.cholesky()?;
        let mut zb = DVector::from_fn(free.len(), |i, _| a.b[free[i]]);
        chol.l_dirty().solve_lower_triangular_mut(&mut zb);
        Some(Self {
            free,
            chol,
            zb,
            nf: a.p,
        })
    }

    /// The free positions that are fixed columns (not slacks), rising.
    fn free_fixed(&self) -> Vec<usize> {
        self.free.iter().copied().filter(|&q| q < self.nf).collect()
    }

    /// `L^-1 G_Fd` for lag columns given by their products with the fixed columns
    /// (`gdf(k)`: lag k's products, one per fixed column).
    fn project(&self, gdf: &[f64]) -> DVector<f64> {
        let mut z = DVector::from_fn(self.free.len(), |i, _| {
            let q = self.free[i];
            if q < self.nf { gdf[q] } else { 0.0 }
        });
        self.chol.l_dirty().solve_lower_triangular_mut(&mut z);
        z
    }

    /// The reduction of the weighted SSR with three lags (Gram `g_dd`, products `b_d`, their
    /// projections `z`) beside the fixed part, and their gains (non-negative).
    fn value(
        &self,
        g_dd: &[[f64; 3]; 3],
        b_d: &[f64; 3],
        z: [&DVector<f64>; 3],
    ) -> (f64, [f64; 3]) {
        let mut s = [[0.0f64; 3]; 3];
        let mut r = [0.0f64; 3];
        for k in 0..3 {
            r[k] = b_d[k] - z[k].dot(&self.zb);
            for l in 0..3 {
                s[k][l] = g_dd[k][l] - z[k].dot(z[l]);
            }
        }
        let base = self.zb.dot(&self.zb);
        // Every active set of the three gains: the best feasible one is the constrained
        // optimum of the (convex) 3-variable problem.
        let mut best = (0.0f64, [0.0f64; 3]);
        for mask in 1u8..8 {
            let idx: Vec<usize> = (0..3).filter(|k| mask & (1 << k) != 0).collect();
            let m = idx.len();
            let a = DMatrix::from_fn(m, m, |i, j| s[idx[i]][idx[j]]);
            let v = DVector::from_fn(m, |i, _| r[idx[i]]);
            let Some(c) = a.cholesky() else { continue };
            let x = c.solve(&v);
            if x.iter().any(|v| v.is_nan() || *v < 0.0) {
                continue;
            }
            let gain = x.dot(&v);
            if gain > best.0 {
                let mut full = [0.0f64; 3];
                for (i, &k) in idx.iter().enumerate() {
                    full[k] = x[i];
                }
                best = (gain, full);
            }
        }
        (base + best.0, best.1)
    }
}

/// The hysteresis basis' smoothness penalty ([`everett::add_band_penalty`]) on a Gram matrix
/// whose rows from `at` on are the regressor columns `cols`.
fn band_penalty(g: &mut DMatrix<f64>, cols: &[usize], at: usize) {
    everett::add_band_penalty(g, |c| {
        cols.iter().position(|&k| k == COL_HYST + c).map(|p| at + p)
    });
}

/// Adds `w` times the Gram matrix of the design matrix `f` (rows x columns) to `g`, and `w`
/// times its products with the target `e` to `b`: blocked products (nalgebra's gemm), several
/// times the speed of row-by-row sums over a hysteresis basis of a hundred columns.
fn add_weighted_gram(
    g: &mut DMatrix<f64>,
    b: &mut DVector<f64>,
    f: &DMatrix<f64>,
    e: &[f64],
    w: f64,
) {
    // (A transposed copy and a product: nalgebra's `tr_mul` takes each entry as a dot
    // product, three times slower than the blocked product here.)
    *g += (f.transpose() * f) * w;
    b.axpy(w, &f.tr_mul(&DVector::from_column_slice(e)), 1.0);
}

/// Record `r`'s columns `cols` at the regressors' rows `js` (all where `None`), as a rows x
/// columns design matrix. Built column by column: each column is gathered from its own
/// vector and written in one run (row by row, every row read all the columns' vectors: 3 %
/// of a diagnosis' CPU time, a third of it now).
fn fixed_at(
    x: &SlowRegressors,
    y0: &[Vec<f64>],
    r: usize,
    cols: &[usize],
    js: Option<&[usize]>,
) -> DMatrix<f64> {
    let n = js.map_or(x.rows[r].len(), <[usize]>::len);
    let mut f = Vec::with_capacity(n * cols.len());
    for &c in cols {
        match (c, js) {
            (COL_OFFSET, _) => f.resize(f.len() + n, 1.0),
            (COL_SGAIN, _) => f.extend((0..n).map(|j| col(x, y0, r, c, js.map_or(j, |js| js[j])))),
            (_, Some(js)) => {
                let v = &x.cols[r][c];
                f.extend(js.iter().map(|&j| v[j]));
            }
            (_, None) => f.extend_from_slice(&x.cols[r][c]),
        }
    }
    DMatrix::from_vec(n, cols.len(), f)
}

/// The products of record `r`'s column `c` at the regressors' rows `js` (all where `None`)
/// with the three lags `v`, the column read once.
fn fixed_dot3(
    x: &SlowRegressors,
    y0: &[Vec<f64>],
    r: usize,
    c: usize,
    js: Option<&[usize]>,
    v: &[Vec<f64>; 3],
) -> [f64; 3] {
    let mut acc = [0.0f64; 3];
    match (c, js) {
        (COL_OFFSET, _) => {
            for k in 0..3 {
                acc[k] = v[k].iter().sum();
            }
        }
        (COL_SGAIN, _) | (_, Some(_)) => {
            for j in 0..v[0].len() {
                let cj = col(x, y0, r, c, js.map_or(j, |js| js[j]));
                for k in 0..3 {
                    acc[k] += cj * v[k][j];
                }
            }
        }
        (_, None) => {
            for (j, cj) in x.cols[r][c].iter().enumerate() {
                for k in 0..3 {
                    acc[k] += cj * v[k][j];
                }
            }
        }
    }
    acc
}

/// The warm start ([`nnls_normal_from`]) a drift solve passes to the next: its three lags
/// (first) free, the other columns where the solve left them positive.
fn warm_set(beta: &[f64]) -> Vec<bool> {
    beta.iter()
        .enumerate()
        .map(|(p, v)| p < 3 || *v > 0.0)
        .collect()
}

/// The drift refinement's fixed part, computed once per [`fit_slow`] call: per record the
/// target at the settled samples, and the weighted Gram matrix of the fixed columns, so that
/// each evaluation only runs the three lags and their products (the fixed columns read where
/// the regressors keep them).
struct DriftProblem<'a> {
    data: &'a [Data],
    /// The regressors the fixed columns and the lags' input (`K(u) u`) are read from, and
    /// the model's output without slow effects (the sensor gain's column).
    x: &'a SlowRegressors,
    y0: &'a [Vec<f64>],
    /// Per record: the drive's runs of equal values ([`drive_runs`]).
    runs: Vec<Vec<(usize, usize, usize)>>,
    /// Per record: (weight, settled sample indices, target at them, their positions among
    /// the regressors' rows).
    recs: Vec<DriftRecord>,
    /// The fixed columns (indices into the regressors).
    fixed: Vec<usize>,
    /// Number of fixed columns.
    nf: usize,
    /// Weighted Gram matrix of the fixed columns, and their weighted products with the target.
    g_ff: DMatrix<f64>,
    b_f: DVector<f64>,
    /// The last solve's positive set, the next one's start ([`nnls_normal_from`]).
    warm: std::cell::RefCell<Option<Vec<bool>>>,
    /// The table's reversible slope ([`SlowRegressors::table_gain`]).
    table_gain: f64,
}

/// One record of a [`DriftProblem`]: (weight, settled sample indices, target at them, their
/// positions among the regressors' rows, `None` where they are all of them).
type DriftRecord = (f64, Vec<usize>, Vec<f64>, Option<Vec<usize>>);

impl<'a> DriftProblem<'a> {
    /// The problem on the regressors' rows, evenly thinned to at most `max_rows` a record;
    /// `g` and `b` are the weighted Gram matrix and products of all rows (used as they are
    /// when no record is thinned).
    fn new(
        data: &'a [Data],
        y0: &'a [Vec<f64>],
        x: &'a SlowRegressors,
        fixed: &[usize],
        g: &DMatrix<f64>,
        b: &DVector<f64>,
        max_rows: usize,
    ) -> Self {
        let nf = fixed.len();
        let recs: Vec<DriftRecord> = data
            .iter()
            .enumerate()
            .map(|(r, d)| {
                let stride = x.rows[r].len().div_ceil(max_rows.max(1)).max(1);
                let js: Vec<usize> = (0..x.rows[r].len()).step_by(stride).collect();
                let idx: Vec<usize> = js.iter().map(|&j| x.rows[r][j]).collect();
                let w = 1.0 / idx.len().max(1) as f64;
                let e = idx.iter().map(|&i| d.y_v[i] - y0[r][i]).collect();
                (w, idx, e, (stride > 1).then_some(js))
            })
            .collect();
        let (g_ff, b_f) = if recs.iter().any(|r| r.3.is_some()) {
            let mut g_ff = DMatrix::<f64>::zeros(nf, nf);
            let mut b_f = DVector::<f64>::zeros(nf);
            for (r, (w, _, e, js)) in recs.iter().enumerate() {
                let f = fixed_at(x, y0, r, fixed, js.as_deref());
                add_weighted_gram(&mut g_ff, &mut b_f, &f, e, *w);
            }
            (g_ff, b_f)
        } else {
            (
                DMatrix::from_fn(nf, nf, |i, j| g[(fixed[i], fixed[j])]),
                DVector::from_fn(nf, |i, _| b[fixed[i]]),
            )
        };
        Self {
            data,
            x,
            y0,
            runs: x.drive.iter().map(|d| drive_runs(d)).collect(),
            recs,
            fixed: fixed.to_vec(),
            nf,
            g_ff,
            b_f,
            warm: std::cell::RefCell::new(None),
            table_gain: x.table_gain,
        }
    }

    /// The lags' weighted products over the records: with themselves, with the target and
    /// with each fixed column (an exact solve's; the searches' tries go through
    /// [`Self::value`]).
    fn lag_products(&self, taus: &[f64; 3]) -> ([[f64; 3]; 3], [f64; 3], [Vec<f64>; 3]) {
        let nf = self.nf;
        let mut gll = [[0.0f64; 3]; 3];
        let mut gle = [0.0f64; 3];
        let mut glf = [vec![0.0f64; nf], vec![0.0f64; nf], vec![0.0f64; nf]];
        for (r, ((d, drive), (w, idx, e, js))) in self
            .data
            .iter()
            .zip(&self.x.drive)
            .zip(&self.recs)
            .enumerate()
        {
            let t = d.period_s();
            let a = taus.map(|tau| (-t / tau).exp());
            let mut lag = [drive[0]; 3];
            let mut ll = [[0.0f64; 3]; 3];
            let mut le = [0.0f64; 3];
            // The lags at the rows; their products with the fixed columns after, one column
            // at a time where the regressors keep it.
            let mut at = [
                Vec::with_capacity(idx.len()),
                Vec::with_capacity(idx.len()),
                Vec::with_capacity(idx.len()),
            ];
            let mut next = 0usize;
            for (j, &i) in idx.iter().enumerate() {
                // Advance the lags to sample i (their value there uses inputs before i).
                while next < i {
                    for k in 0..3 {
                        lag[k] = a[k] * lag[k] + (1.0 - a[k]) * drive[next];
                    }
                    next += 1;
                }
                for k in 0..3 {
                    le[k] += lag[k] * e[j];
                    for l in 0..=k {
                        ll[k][l] += lag[k] * lag[l];
                    }
                    at[k].push(lag[k]);
                }
            }
            let mut lf = [
                vec![0.0f64; self.nf],
                vec![0.0f64; self.nf],
                vec![0.0f64; self.nf],
            ];
            for (q, &c) in self.fixed.iter().enumerate() {
                let p = fixed_dot3(self.x, self.y0, r, c, js.as_deref(), &at);
                for k in 0..3 {
                    lf[k][q] = p[k];
                }
            }
            for k in 0..3 {
                gle[k] += w * le[k];
                for l in 0..=k {
                    gll[k][l] += w * ll[k][l];
                    gll[l][k] = gll[k][l];
                }
                for (g, acc) in glf[k].iter_mut().zip(&lf[k]) {
                    *g += w * acc;
                }
            }
        }
        (gll, gle, glf)
    }

    /// The weighted solve with three drift lags of time constants `taus` and the fixed
    /// columns: (coefficients, drift first; reduction of the weighted SSR; the augmented
    /// system's solution, for [`Schur::new`]).
    fn solve_full(&self, taus: &[f64; 3]) -> Option<(Vec<f64>, f64, DVector<f64>)> {
        let nf = self.nf;
        let p = 3 + nf;
        let mut g = DMatrix::<f64>::zeros(p, p);
        let mut bv = DVector::<f64>::zeros(p);
        g.view_mut((3, 3), (nf, nf)).copy_from(&self.g_ff);
        bv.rows_mut(3, nf).copy_from(&self.b_f);
        let (gll, gle, glf) = self.lag_products(taus);
        for k in 0..3 {
            bv[k] = gle[k];
            for l in 0..3 {
                g[(k, l)] = gll[k][l];
            }
            for (c, &v) in glf[k].iter().enumerate() {
                g[(k, 3 + c)] = v;
                g[(3 + c, k)] = v;
            }
        }
        let nonneg: Vec<bool> = (0..p)
            .map(|k| k < 3 || is_nonneg_col(self.fixed[k - 3]))
            .collect();
        let warm = self.warm.borrow().clone();
        let (beta, red, beta_a) = solve_slow_augmented(
            g,
            &bv,
            &self.fixed,
            3,
            &nonneg,
            warm.as_deref(),
            self.table_gain,
        )?;
        *self.warm.borrow_mut() = Some(warm_set(beta.as_slice()));
        Some((beta.iter().copied().collect(), red, beta_a))
    }

    /// [`Self::solve_full`] without the augmented solution.
    fn solve(&self, taus: &[f64; 3]) -> Option<(Vec<f64>, f64)> {
        self.solve_full(taus).map(|(beta, red, _)| (beta, red))
    }

    /// The [`Schur`] evaluation at `taus` with the fixed part of `search` (built on this
    /// problem's fixed columns): (the lags' gains, the reduction of the weighted SSR).
    /// Only the free fixed columns enter the Schur complement, so the lags' products are
    /// taken with those alone. Each lag's part (its values at the rows, its product with the
    /// target, its projection on the fixed part) depends on its own time constant only, and a
    /// coordinate search or a Newton step's difference point changes one of the three at a
    /// time: the parts are kept ([`SchurSearch::parts`]) and only the new time constant's
    /// computed.
    fn value(&self, search: &SchurSearch, taus: &[f64; 3]) -> ([f64; 3], f64) {
        let parts = taus.map(|tau| search.part(self, tau));
        let mut gll = [[0.0f64; 3]; 3];
        let mut gle = [0.0f64; 3];
        for k in 0..3 {
            gle[k] = parts[k].le;
            for l in 0..=k {
                let v: f64 = self
                    .recs
                    .iter()
                    .zip(parts[k].lags.iter().zip(&parts[l].lags))
                    .map(|(r, (a, b))| r.0 * a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>())
                    .sum();
                gll[k][l] = v;
                gll[l][k] = v;
            }
        }
        let (red, x) = search
            .schur
            .value(&gll, &gle, [&parts[0].z, &parts[1].z, &parts[2].z]);
        (x, red)
    }

    /// One lag's part of a [`Self::value`]: its values at each record's rows, its weighted
    /// product with the target, and its products with the free fixed columns projected by
    /// `schur`.
    fn lag_part(&self, schur: &Schur, free_cols: &[DMatrix<f64>], tau: f64) -> LagPart {
        let mut le = 0.0;
        let mut gdf_free = vec![0.0f64; free_cols.first().map_or(0, |f| f.ncols())];
        let mut lags = Vec::with_capacity(self.recs.len());
        for (((d, drive), starts), ((w, idx, e, _), f)) in self
            .data
            .iter()
            .zip(&self.x.drive)
            .zip(&self.runs)
            .zip(self.recs.iter().zip(free_cols))
        {
            let at = lag_at_rows(drive, starts, idx, (-d.period_s() / tau).exp());
            le += w * at.iter().zip(e).map(|(x, y)| x * y).sum::<f64>();
            // The free columns times the lag: one pass over the columns (stored column by
            // column), memory-bound.
            let fl = f.tr_mul(&DVector::from_column_slice(&at));
            for (g, v) in gdf_free.iter_mut().zip(fl.iter()) {
                *g += w * v;
            }
            lags.push(at);
        }
        let mut gdf = vec![0.0f64; self.nf];
        for (&q, v) in schur.free_fixed().iter().zip(gdf_free) {
            gdf[q] = v;
        }
        LagPart {
            lags,
            le,
            z: schur.project(&gdf),
        }
    }

    /// A [`Schur`] evaluator on this problem's fixed columns, from an exact solve at `taus`,
    /// with each record's free fixed columns at the rows.
    fn schur_at(&self, taus: &[f64; 3]) -> Option<SchurSearch> {
        let (_, _, beta_a) = self.solve_full(taus)?;
        let schur = Schur::new(&self.g_ff, &self.b_f, &self.fixed, self.table_gain, &beta_a)?;
        let keep = schur.free_fixed();
        let free: Vec<usize> = keep.iter().map(|&i| self.fixed[i]).collect();
        let free_cols = self
            .recs
            .iter()
            .enumerate()
            .map(|(r, rec)| fixed_at(self.x, self.y0, r, &free, rec.3.as_deref()))
            .collect();
        Some(SchurSearch {
            schur,
            free_cols,
            parts: std::cell::RefCell::new(Vec::new()),
        })
    }
}

/// Minimum ratio between neighbouring drift time constants in the refinement (our
/// assumption: two lags closer than 5 % are one lag with its gain split).
const TAU_SEPARATION: f64 = 1.05;

/// The finite-difference step of [`newton_step`], in log tau (our assumption: 1 % of tau,
/// ten times the coordinate search's resolution; the difference formulas' error, of order
/// the step squared, moves the optimum by about 1e-4 of tau).
const NEWTON_STEP_LN: f64 = 0.01;

/// The Levenberg damping factors [`newton_step`] tries in turn, in units of the Hessian's
/// diagonal (our assumption: a plain Newton step first, then ever shorter ones towards the
/// gradient, four decades).
const NEWTON_DAMPING: [f64; 6] = [0.0, 0.01, 0.1, 1.0, 10.0, 100.0];

/// The longest Newton step, in log tau (our assumption: a factor e, the span the wide
/// coordinate pass searches).
const NEWTON_MAX_LN: f64 = 1.0;

/// One damped Newton step that raises `f` (a function of three log time constants,
/// `-inf` outside its domain) from `x` where it is `fx`: the gradient and Hessian by central
/// and forward differences of step [`NEWTON_STEP_LN`] (up to nine evaluations, which a caller
/// that keeps each coordinate's part shares: a move of one coordinate reuses the other two),
/// then `(-H + lambda diag|H|) d = g` for each damping of [`NEWTON_DAMPING`] until a step (at
/// most [`NEWTON_MAX_LN`] long) raises `f`. A coordinate whose difference points leave the
/// domain (a time constant at its bound, a gain at 1) is held where it is and the step taken
/// in the others. [`Newton::Converged`] where every coordinate is free and the plain Newton
/// step would gain less than [`DRIFT_REFINE_TOL_V2`]; [`Newton::Stuck`] where no coordinate
/// is free or no damping gains: the caller falls back to a coordinate search.
fn newton_step(f: &impl Fn([f64; 3]) -> f64, x: [f64; 3], fx: f64) -> Newton {
    let h = NEWTON_STEP_LN;
    let moved = |d: [f64; 3]| f([x[0] + d[0], x[1] + d[1], x[2] + d[2]]);
    let unit = |k: usize, s: f64| {
        let mut d = [0.0; 3];
        d[k] = s;
        d
    };
    if !fx.is_finite() {
        return Newton::Stuck;
    }
    let fp = [0, 1, 2].map(|k| moved(unit(k, h)));
    let fm = [0, 1, 2].map(|k| moved(unit(k, -h)));
    let free: Vec<usize> = (0..3)
        .filter(|&k| fp[k].is_finite() && fm[k].is_finite())
        .collect();
    let n = free.len();
    if n == 0 {
        return Newton::Stuck;
    }
    let g = DVector::from_fn(n, |i, _| (fp[free[i]] - fm[free[i]]) / (2.0 * h));
    let mut hess = DMatrix::<f64>::zeros(n, n);
    for i in 0..n {
        let k = free[i];
        hess[(i, i)] = (fp[k] - 2.0 * fx + fm[k]) / (h * h);
        for j in 0..i {
            let l = free[j];
            let mut d = unit(k, h);
            d[l] = h;
            let v = moved(d);
            if !v.is_finite() {
                return Newton::Stuck;
            }
            let c = (v - fp[k] - fp[l] + fx) / (h * h);
            hess[(i, j)] = c;
            hess[(j, i)] = c;
        }
    }
    for lambda in NEWTON_DAMPING {
        let mut a = -hess.clone();
        for i in 0..n {
            a[(i, i)] += lambda * hess[(i, i)].abs().max(1e-300);
        }
        let Some(ch) = a.cholesky() else {
            continue;
        };
        let d = ch.solve(&g);
        // The quadratic model's gain of the plain step, `g.d / 2`.
        if lambda == 0.0 && n == 3 && 0.5 * g.dot(&d) < DRIFT_REFINE_TOL_V2 {
            return Newton::Converged;
        }
        let len = d.amax();
        if !len.is_finite() || len == 0.0 {
            continue;
        }
        let s = (NEWTON_MAX_LN / len).min(1.0);
        let mut step = [0.0; 3];
        for (i, &k) in free.iter().enumerate() {
            step[k] = s * d[i];
        }
        let v = moved(step);
        if v > fx {
            return Newton::Moved([x[0] + step[0], x[1] + step[1], x[2] + step[2]], v);
        }
    }
    Newton::Stuck
}

/// What a [`newton_step`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Newton {
    /// Moved to these log time constants, where the function is this.
    Moved([f64; 3], f64),
    /// Nothing left to gain.
    Converged,
    /// No step gains: search coordinate by coordinate instead.
    Stuck,
}

/// The runs of equal values of `drive`: (first sample, end of the run, and for a run of one
/// sample the end of the stretch of such runs it begins).
fn drive_runs(drive: &[f64]) -> Vec<(usize, usize, usize)> {
    let starts: Vec<usize> = (0..drive.len())
        .filter(|&n| n == 0 || drive[n] != drive[n - 1])
        .collect();
    let mut runs: Vec<(usize, usize, usize)> = starts
        .iter()
        .enumerate()
        .map(|(q, &st)| {
            let end = starts.get(q + 1).copied().unwrap_or(drive.len());
            (st, end, end)
        })
        .collect();
    for q in (0..runs.len()).rev() {
        let (st, end, _) = runs[q];
        if end - st == 1 && q + 1 < runs.len() && runs[q + 1].1 - runs[q + 1].0 == 1 {
            runs[q].2 = runs[q + 1].2;
        }
    }
    runs
}

/// The first-order lag of pole `a`, at rest at `drive[0]`, at the samples `idx` (rising; its
/// value at sample `i` uses the inputs before `i`); `runs` are the drive's runs
/// ([`drive_runs`]). Over a run of `m` equal inputs `v` the lag moves in one step,
/// `l <- v + a^m (l - v)`: records that hold their input (the recommended protocol's levels)
/// cost a step a hold instead of one a sample. Inputs that change every sample go two a step
/// (`l <- a^2 l + a c d[n] + c d[n+1]`, `c = 1 - a`: half the chain of dependent
/// multiply-adds, which bounds the loop).
fn lag_at_rows(drive: &[f64], runs: &[(usize, usize, usize)], idx: &[usize], a: f64) -> Vec<f64> {
    let c = 1.0 - a;
    let (a2, ac) = (a * a, a * c);
    let mut lag = drive.first().copied().unwrap_or(0.0);
    let mut next = 0usize;
    let mut run = 0usize;
    let mut at = Vec::with_capacity(idx.len());
    for &i in idx {
        let i = i.min(drive.len());
        while next < i {
            while run + 1 < runs.len() && runs[run].1 <= next {
                run += 1;
            }
            let (_, end, stretch) = runs[run];
            if end - next > 1 {
                let stop = end.min(i);
                let v = drive[next];
                lag = v + a.powi((stop - next) as i32) * (lag - v);
                next = stop;
            } else {
                let stop = stretch.min(i);
                while next + 2 <= stop {
                    lag = a2 * lag + (ac * drive[next] + c * drive[next + 1]);
                    next += 2;
                }
                if next < stop {
                    lag = a * lag + c * drive[next];
                    next += 1;
                }
            }
        }
        at.push(lag);
    }
    at
}

/// One lag's part of a [`DriftProblem::value`] (see [`DriftProblem::lag_part`]).
struct LagPart {
    /// Per record, the lag at the rows.
    lags: Vec<Vec<f64>>,
    /// The weighted product with the target.
    le: f64,
    /// The projection of its products with the free fixed columns.
    z: DVector<f64>,
}

/// A [`Schur`] evaluator with each record's free fixed columns at the rows, and the lag parts
/// computed so far, by time constant (the last [`SCHUR_PARTS_KEPT`]).
struct SchurSearch {
    schur: Schur,
    free_cols: Vec<DMatrix<f64>>,
    parts: std::cell::RefCell<Vec<(f64, std::rc::Rc<LagPart>)>>,
}

/// Lag parts a [`SchurSearch`] keeps: a coordinate step reuses the two time constants it
/// does not move, and a Newton step's difference points (each moves one) the other two and
/// each other's (its three time constants, each at three points, and its trial step's).
const SCHUR_PARTS_KEPT: usize = 16;

impl SchurSearch {
    /// The part of the lag of time constant `tau` on `problem` (kept or computed).
    fn part(&self, problem: &DriftProblem, tau: f64) -> std::rc::Rc<LagPart> {
        if let Some((_, p)) = self.parts.borrow().iter().find(|(t, _)| *t == tau) {
            return p.clone();
        }
        let p = std::rc::Rc::new(problem.lag_part(&self.schur, &self.free_cols, tau));
        let mut parts = self.parts.borrow_mut();
        if parts.len() >= SCHUR_PARTS_KEPT {
            parts.remove(0);
        }
        parts.push((tau, p.clone()));
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The damped Newton step ([`newton_step`]) on a narrow valley (curvatures 1 and 400
    /// across it, where coordinate descent crawls): from a point off the valley it reaches
    /// the optimum in a few steps and then says so; a coordinate whose difference points
    /// leave the domain is held and the others still move. Tolerance 1e-4 in log tau: the
    /// difference step's error (its square times the third derivative, zero on a quadratic)
    /// plus the stopping rule's gain of 1e-10.
    #[test]
    fn newton_steps_follow_a_narrow_valley_and_respect_the_domain() {
        let opt = [-3.0, 0.5, 2.5];
        let f = |x: [f64; 3]| {
            let (a, b, c) = (x[0] - opt[0], x[1] - opt[1], x[2] - opt[2]);
            -(200.0 * (a - b) * (a - b) + 0.5 * (a + b) * (a + b) + 3.0 * c * c + 0.1 * a * c)
        };
        let mut x = [-2.0, -0.2, 3.1];
        let mut fx = f(x);
        let mut steps = 0;
        loop {
            match newton_step(&f, x, fx) {
                Newton::Moved(y, v) => {
                    assert!(v > fx);
                    (x, fx) = (y, v);
                    steps += 1;
                    assert!(steps <= 5, "still moving after {steps} steps: {x:?}");
                }
                Newton::Converged => break,
                Newton::Stuck => panic!("stuck at {x:?}"),
            }
        }
        for k in 0..3 {
            assert!((x[k] - opt[k]).abs() < 1e-4, "{x:?} against {opt:?}");
        }
        // The first coordinate may not go below -2.005: its lower difference point is outside,
        // so it stays at -2.0 while the others move towards their optimum given it.
        let g = |x: [f64; 3]| {
            if x[0] < -2.005 {
                f64::NEG_INFINITY
            } else {
                f(x)
            }
        };
        let start = [-2.0, 0.5, 2.0];
        match newton_step(&g, start, g(start)) {
            Newton::Moved(y, v) => {
                assert_eq!(y[0], -2.0);
                assert!(v > g(start));
                // Given a = 1, the second coordinate's optimum is b = 0.5 + 399 / 401.
                assert!((y[1] - (0.5 + 399.0 / 401.0)).abs() < 1e-6, "{y:?}");
            }
            other => panic!("{other:?}"),
        }
        // A curved valley (Rosenbrock's, in the first two coordinates) from a start more than
        // a step's cap away: steps capped at NEWTON_MAX_LN and damped where the Hessian is
        // not negative definite; every step gains, and the steps end near the optimum (to
        // 3e-3: the difference formulas' error, the step squared times the valley's third
        // derivatives, 12 x 20 here, over its curvature; there a step that gains by the
        // differences no longer gains, `Stuck`, and the caller's coordinate pass takes over).
        let r = |x: [f64; 3]| {
            -((x[0] - 1.0).powi(2) + 20.0 * (x[1] - x[0] * x[0]).powi(2) + (x[2] + 0.5).powi(2))
        };
        let (mut x, mut fx) = ([-1.5, 2.5, 2.0], r([-1.5, 2.5, 2.0]));
        let mut longest = 0.0f64;
        for _ in 0..200 {
            match newton_step(&r, x, fx) {
                Newton::Moved(y, v) => {
                    assert!(v > fx);
                    let len = (0..3).map(|k| (y[k] - x[k]).abs()).fold(0.0, f64::max);
                    longest = longest.max(len);
                    (x, fx) = (y, v);
                }
                Newton::Converged | Newton::Stuck => break,
            }
        }
        assert!(longest <= NEWTON_MAX_LN + 1e-12, "a step of {longest}");
        assert!(longest > 0.5, "the start was far: {longest}");
        for (k, want) in [1.0, 1.0, -0.5].into_iter().enumerate() {
            assert!((x[k] - want).abs() < 3e-3, "{x:?}");
        }
        // Nothing free: the caller must search otherwise.
        let h = |x: [f64; 3]| if x == start { g(x) } else { f64::NEG_INFINITY };
        assert_eq!(newton_step(&h, start, h(start)), Newton::Stuck);
    }

    /// The Gram matrix of a basis scaled by K'(u), from the basis' moments
    /// ([`KMoments::gram`]), equals the one computed from the scaled columns themselves, on a
    /// record that visits the span's edges (where K' is held) and for both centre lines.
    /// Tolerance 1e-9 of the matrix's largest entry: the moments add terms up to `u^4` times
    /// the basis' products (10^4 at 10 V), a few roundings of 1e-16 each.
    #[test]
    fn scaled_gram_from_moments_equals_the_direct_one() {
        use crate::io::csv::Record;
        // Two records of different lengths (each weighs by its own rows).
        let record = |n: usize, f_hz: f64, grow: f64| {
            let t: Vec<f64> = (0..n).map(|i| i as f64 * 1e-3).collect();
            let u: Vec<f64> = t
                .iter()
                .map(|&x| {
                    5.0 + 5.5 * (2.0 * std::f64::consts::PI * f_hz * x).sin() * (0.3 + x / grow)
                })
                .collect();
            let y = vec![0.0; n];
            let d = Data::from_record("sine", Record::new(t, u.clone(), Some(y), None).unwrap())
                .unwrap();
            (d, u)
        };
        let (d1, u1) = record(3000, 0.7, 3.0);
        let (d2, u2) = record(1700, 1.3, 1.5);
        let data = [d1, d2];
        for form in [everett::CentreLine::Band, everett::CentreLine::Span] {
            let rows = SolveRows {
                rows: vec![
                    (0..3000).step_by(2).collect(),
                    (5..1700).step_by(3).collect(),
                ],
                u_fit: vec![u1.clone(), u2.clone()],
            };
            let base = slow_regressors(&data, rows, &[], 0.79, form);
            for (c1, c2) in [(0.02, -0.001), (-0.05, 0.004)] {
                let shape = Shape {
                    kprime: Some((c1, c2)),
                    kdrift: None,
                    range: (0.0, 10.0),
                };
                let x = slow_regressors_shaped(&data, &shape, &base);
                let fast = input_gram(&x);
                assert!(
                    x.moments.get().is_some_and(|m| m.range == x.kprime_range),
                    "the moments path was not taken"
                );
                let direct = input_gram_direct(&x);
                let scale = direct.amax();
                let err = (&fast - &direct).amax();
                assert!(
                    err <= 1e-9 * scale,
                    "{form:?} K' ({c1}, {c2}): {err} of {scale}"
                );
            }
        }
    }

    /// The lag by runs and pairs ([`lag_at_rows`]) equals the plain one-sample recursion, on
    /// drives that mix holds, single-sample changes and runs of two, at rows anywhere
    /// (inside runs, at their edges, repeated), for fast and slow poles. Tolerance: 1e-12 of
    /// the drive's scale, a few roundings of the closed form `a^m` against `m` products.
    #[test]
    fn lag_by_runs_equals_the_plain_recursion() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        for _ in 0..40 {
            let n = rng.gen_range(1..3000);
            let mut drive = Vec::with_capacity(n);
            while drive.len() < n {
                let v: f64 = rng.gen_range(-5.0..5.0);
                let len = match rng.gen_range(0..3) {
                    0 => 1,
                    1 => 2,
                    _ => rng.gen_range(3..400),
                };
                drive.extend(std::iter::repeat_n(v, len.min(n - drive.len())));
            }
            let mut idx: Vec<usize> = (0..rng.gen_range(1..60))
                .map(|_| rng.gen_range(0..n))
                .collect();
            idx.sort_unstable();
            let a = [0.0, 0.3, 0.99, 1.0 - 1e-6][rng.gen_range(0..4)];
            let got = lag_at_rows(&drive, &drive_runs(&drive), &idx, a);
            let mut lag = drive[0];
            let mut want = Vec::new();
            let mut next = 0;
            for &i in &idx {
                while next < i {
                    lag = a * lag + (1.0 - a) * drive[next];
                    next += 1;
                }
                want.push(lag);
            }
            for (g, w) in got.iter().zip(&want) {
                assert!((g - w).abs() <= 5e-12, "a = {a}: {g} against {w}");
            }
        }
    }

    /// The sliding maximum equals the brute-force one, for windows narrower and wider than
    /// the gaps between the samples' indices.
    #[test]
    fn window_max_is_the_largest_value_within_the_window() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for _ in 0..50 {
            let mut i = 0usize;
            let s: Vec<(usize, f64)> = (0..rng.gen_range(1..200))
                .map(|_| {
                    i += rng.gen_range(1..5);
                    (i, rng.gen_range(-1.0..1.0))
                })
                .collect();
            let half = rng.gen_range(0..12);
            let fast = window_max(&s, half);
            for (k, &(ik, _)) in s.iter().enumerate() {
                let slow = s
                    .iter()
                    .filter(|(j, _)| j.abs_diff(ik) <= half)
                    .map(|(_, v)| *v)
                    .fold(f64::NEG_INFINITY, f64::max);
                assert_eq!(fast[k], slow);
            }
        }
    }

    /// The Schur evaluation of the drift searches is the exact constrained optimum when the
    /// fixed part's free set is the reference's: on random systems with free fixed columns
    /// (the gain terms and the offset) and three non-negative lags, its reduction and gains
    /// match the active-set solve of the whole system to 1e-9.
    #[test]
    fn schur_evaluation_matches_the_whole_solve() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let fixed = [COL_GAIN, COL_GAIN + 1, COL_OFFSET];
        for case in 0..200 {
            let rows = 40;
            let m = DMatrix::<f64>::from_fn(rows, 6, |_, _| rng.gen_range(-1.0..1.0));
            let y = DVector::<f64>::from_fn(rows, |_, _| rng.gen_range(-1.0..1.0));
            let g = m.transpose() * &m;
            let b = m.transpose() * &y;
            // Columns 0..3 are lags (grid indices), then the fixed ones.
            let cols: Vec<usize> = [0, 1, 2].into_iter().chain(fixed).collect();
            let nonneg: Vec<bool> = cols.iter().map(|&c| is_nonneg_col(c)).collect();
            let (beta, red, beta_a) =
                solve_slow_augmented(g.clone(), &b, &cols, 0, &nonneg, None, 1.0).unwrap();
            let g_ff = g.view((3, 3), (3, 3)).into_owned();
            let b_f = b.rows(3, 3).into_owned();
            let schur = Schur::new(&g_ff, &b_f, &fixed, 1.0, &beta_a).unwrap();
            let z: Vec<DVector<f64>> = (0..3)
                .map(|k| schur.project(&[g[(k, 3)], g[(k, 4)], g[(k, 5)]]))
                .collect();
            let g_dd = [0, 1, 2].map(|k| [0, 1, 2].map(|l| g[(k, l)]));
            let b_d = [b[0], b[1], b[2]];
            let (r, gains) = schur.value(&g_dd, &b_d, [&z[0], &z[1], &z[2]]);
            assert!(
                (r - red).abs() <= 1e-9 * red.abs().max(1.0),
                "case {case}: {r} against {red}"
            );
            for k in 0..3 {
                assert!(
                    (gains[k] - beta[k]).abs() <= 1e-9 * beta.amax().max(1.0),
                    "case {case}: gains {gains:?} against {beta}"
                );
            }
        }
    }

    /// A band whose data pull its loop weights to twice the table's reversible slope keeps
    /// them within it (to the penalty's thousandth of the excess) and spends all of it; a band
    /// whose data ask for less is fitted as without the penalty; the reduction reported is the
    /// data's.
    #[test]
    fn the_validity_penalty_holds_each_band_within_the_reversible_slope() {
        let g0 = params::PLANT_GAIN;
        let n = everett::HYST_RADII;
        // Band 0 wants 2 g0 in all, band 2 wants 0.5 g0; unit Gram (independent columns).
        let cols: Vec<usize> = (0..n)
            .map(|i| COL_HYST + everett::col(i, 0))
            .chain((0..n).map(|i| COL_HYST + everett::col(i, 2)))
            .collect();
        let p = cols.len();
        let g = DMatrix::<f64>::identity(p, p);
        let b =
            DVector::<f64>::from_fn(p, |j, _| if j < n { 2.0 * g0 } else { 0.5 * g0 } / n as f64);
        let nonneg = vec![true; p];
        let (beta, red) = solve_slow(g.clone(), &b, &cols, 0, &nonneg, None, g0).unwrap();
        let sum0: f64 = beta.rows(0, n).sum();
        let sum2: f64 = beta.rows(n, n).sum();
        assert!(
            sum0 <= g0 * (1.0 + 2e-3) && sum0 >= 0.99 * g0,
            "band 0: {sum0} for {g0}"
        );
        // The free band is fitted as without the penalty (the smoothness penalty couples only
        // adjacent bands of one radius, and bands 0 and 2 are not adjacent).
        assert!((sum2 - 0.5 * g0).abs() < 1e-6 * g0, "band 2: {sum2}");
        let data_red = 2.0 * beta.dot(&b) - beta.dot(&(&g * &beta));
        assert!((red - data_red).abs() < 1e-9 && red > 0.0);
        // Without a reversible slope to keep (no table gain), nothing is held.
        let (free, _) = solve_slow(g, &b, &cols, 0, &nonneg, None, 0.0).unwrap();
        assert!((free.rows(0, n).sum() - 2.0 * g0).abs() < 1e-6);
    }

    /// The rounds a fit's memo says another `rounds` would run: a coupled set with a drift
    /// stops at the first settled round from `rounds` on (at most `COUPLE_ROUNDS_MAX`), and
    /// where the kept run never reached a round that call would check, it cannot say.
    #[test]
    fn the_memo_tells_which_rounds_a_call_would_run() {
        let run = |settled: &[bool], failed_at| RoundsRun {
            settled: settled.to_vec(),
            failed_at,
            ran: None,
        };
        // Settled first at round 2: rounds 1 and 2 stop there, rounds 3 runs on.
        let r = run(&[false, false, true], None);
        assert_eq!(rounds_to_run(true, true, 1, &r), Some(2));
        assert_eq!(rounds_to_run(true, true, 2, &r), Some(2));
        assert_eq!(rounds_to_run(true, true, 3, &r), None);
        // Settled at round 1 already: rounds 1 stops at 1, rounds 2 at 2 (not known here).
        let r = run(&[false, true], None);
        assert_eq!(rounds_to_run(true, true, 1, &r), Some(1));
        assert_eq!(rounds_to_run(true, true, 2, &r), None);
        // Never settled: COUPLE_ROUNDS_MAX for any rounds up to it.
        let r = run(&[false; COUPLE_ROUNDS_MAX], None);
        for rounds in 1..=COUPLE_ROUNDS_MAX {
            assert_eq!(
                rounds_to_run(true, true, rounds, &r),
                Some(COUPLE_ROUNDS_MAX)
            );
        }
        // A failed solve stops every call that reaches it.
        let r = run(&[false, false], Some(1));
        assert_eq!(rounds_to_run(true, true, 1, &r), Some(1));
        assert_eq!(rounds_to_run(true, true, 2, &r), Some(1));
        // Without the coupling the rounds asked for run (one without the drift's K).
        assert_eq!(rounds_to_run(false, true, 2, &run(&[], None)), Some(2));
        assert_eq!(rounds_to_run(true, false, 2, &run(&[false], None)), Some(1));
    }

    /// A fit served from the regressors' memo is the fit itself, bit for bit, whichever
    /// rounds asked for it first: on the full thesis stage's random levels (held levels, so
    /// the drift's K(u) beside K'(u)), the coupled set of drift, hysteresis and curvature
    /// asked with one round, two (the steps' candidates and the structure search) and one
    /// more than `COUPLE_ROUNDS_MAX`, in several orders, against each fitted without the memo.
    #[test]
    fn a_kept_slow_fit_is_the_fit_itself() {
        use crate::sim::synth::{Protocol, SynthSpec, synth};
        let spec = SynthSpec {
            model: "thesis-full".into(),
            protocol: Protocol::Steps,
            seed: 7,
            seconds: 8.0,
            rate: 1_000.0,
            amplitude: 8.0,
            offset: 1.0,
            freq: 1.0,
            freq_end: 100.0,
            hold: Some(0.6),
            noise_v: None,
        };
        let data = vec![Data::from_record("steps.csv", synth(&spec).unwrap()).unwrap()];
        let base = ModelFile::built_in("thesis-linear").unwrap();
        let y0: Vec<Vec<f64>> = data
            .iter()
            .map(|d| sim(&catalogue::without_slow(&base), d).unwrap())
            .collect();
        let set = ["drift", "hysteresis", "nonlinear-gain"];
        assert_eq!(coupling(&data, &set), (true, true), "the set must couple");
        let u_range = (1.0, 9.0);
        let x = || {
            let rows = solve_rows(&data, &base, &[1e-3]).unwrap();
            slow_regressors(
                &data,
                rows,
                &[],
                base.plant.static_gain,
                everett::CentreLine::Band,
            )
        };
        let text = |p: &Option<SlowParams>| format!("{p:?}");
        // (rounds 6 runs one more than COUPLE_ROUNDS_MAX where K'(u) does not settle: a memo
        // that ignored the rounds would serve it the others' fit)
        let asked = [1, 2, COUPLE_ROUNDS_MAX + 1];
        let fresh: Vec<String> = asked
            .iter()
            .map(|&r| text(&fit_slow_once(&data, &y0, &x(), &set, u_range, r).0))
            .collect();
        assert!(fresh[0].contains("drift_poly: Some"), "{}", fresh[0]);
        // (K'(u) does not settle after the first round here: rounds 1 and 2 run the same
        // rounds, so the later of the two must be served from the memo)
        assert_eq!(fresh[0], fresh[1], "rounds 1 and 2 ran different rounds");
        let mut distinct = fresh.clone();
        distinct.sort();
        distinct.dedup();
        assert!(distinct.len() > 1, "every rounds asked gave one fit");
        for order in [[0, 1, 2], [2, 1, 0], [1, 2, 0]] {
            let x = x();
            for i in order {
                let kept = text(&fit_slow(&data, &y0, &x, &set, u_range, asked[i]));
                assert_eq!(kept, fresh[i], "rounds {} in order {order:?}", asked[i]);
            }
            // A call whose rounds run as a kept fit's was served from the memo: one fit kept
            // per distinct result.
            let kept = x.fits.lock().map(|f| f.len()).unwrap_or(0);
            assert_eq!(kept, distinct.len(), "fits kept in order {order:?}");
            // Asked again, each is served from the memo: nothing more is kept.
            for i in order {
                let again = text(&fit_slow(&data, &y0, &x, &set, u_range, asked[i]));
                assert_eq!(again, fresh[i], "rounds {} asked again", asked[i]);
            }
            let kept = x.fits.lock().map(|f| f.len()).unwrap_or(0);
            assert_eq!(
                kept,
                distinct.len(),
                "fits kept after asking again in {order:?}"
            );
        }
    }
}
