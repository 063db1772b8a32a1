//! The hysteresis form of the model-gap workflow (issue #12 item 2): a Preisach model fitted
//! as weights on a basis of band-limited play operators, whose result is the model-core
//! Everett table ([`model_core::hysteresis::HysteresisTable`], 3980 bytes) the stage and the
//! firmware's feedforward run. One representation from identification to board.
//!
//! # The basis
//! A Preisach model sums relays `gamma(alpha, beta)` weighted by a density `mu >= 0`. Write a
//! relay by its centre `c = (alpha + beta) / 2` and half-width `r = (alpha - beta) / 2`. All the
//! relays of one half-width `r` with centres spread uniformly make a play operator of radius
//! `r` (Prandtl-Ishlinskii: symmetric, congruent loops everywhere); those with centres in one
//! band `[c_k, c_k+1]` make a **band-limited play operator**, whose output is the play
//! operator's position clamped to the band. A weight per (radius, band) pair is a density that
//! is piecewise constant along the centre (piecewise linear for the tent split, below) and
//! free along the width: narrow and wide
//! operators, loops that differ from one end of the range to the other (asymmetric loops, a
//! loop that is wider at the top), any shape of Everett table at that resolution.
//!
//! Each basis element `(r, k)` has the Everett function
//!
//! ```text
//!     T_rk(a, b) = | [ max(c_k, b + r), min(c_k+1, a - r) ] |      (length of the interval, >= 0)
//! ```
//!
//! with the relays clipped to the table's range (`b + r` read as `-inf` at the bottom node,
//! `a - r` as `+inf` at the top one: a relay whose threshold lies beyond the range switches
//! at its end),
//!
//! and enters the fit as a **loop-only column**: the response of the model-core table with
//! `T_rk` as its grid, minus the reversible part of the same relays (`clamp(u, c_k, c_k+1)`):
//! with no hysteresis the columns vanish, the base model's `static_gain * u` stays the
//! reversible map, and curvature of that map is left to `nonlinear-gain` (so the two effects
//! stay apart). Because the column *is* the table's own response (same grid, bilinear
//! interpolation, turning-point memory, start on the major rising curve as
//! [`model_core::stage::Stage`] starts), the fitted table reproduces the fit exactly: the
//! weights `m_rk >= 0` become the grid
//!
//! ```text
//!     E(a, b) = g (a - b) + sum_rk m_rk ( T_rk(a, b) - |[b, a] ^ [c_k, c_k+1]| ),   offset g lo
//! ```
//!
//! (`g` the plant's static gain), which the stage checks as any table (non-negative, rising in
//! `a`, falling in `b`: the reversible slope must stay positive).
//!
//! The table is the whole static map, as the thesis' is: one more column per band,
//! `clamp(u, c_k, c_k+1) - c_k` with a weight of either sign, lets the reversible slope
//! change along the range (`+ s_k |[b, a] ^ band_k|` in `E`). Without it, the curvature a
//! non-Preisach loop (Bouc-Wen) leaves in the reversible part is named `nonlinear-gain`; with
//! it, `nonlinear-gain` is named beside `hysteresis` only when the records show a curvature the
//! table's per-band slopes cannot take (a stage's K'(u) and its Everett table are one static map
//! to any record: the workflow says so in GAP.md rather than guess).
//!
//! # The span split's triangle (session 19)
//! The [`CentreLine::Span`] split is the form of a stage whose table ends at the records'
//! extremes (the thesis' table over its 0..10 V protocol). Its loop elements hold only the
//! relays **inside the span's triangle**, both thresholds within the records' span
//! (`lo + r <= c <= hi - r`); the relays of each radius with a
//! threshold beyond the records' inputs (below `lo`, or else above `hi`) make two columns
//! of their own ([`out_col`]), which the band penalty does not tie to the others. Before,
//! each band's element held its relays of both kinds under one weight, so a relay below the
//! records' lowest input (which switches on once and stays on, or stays as the start memory
//! left it) moved with the loop's relays of its band: on the thesis' table the ascending
//! curve from the records' bottom could not be fitted (2.55-2.59x the floor on the 150 s
//! records). The elements with no relay inside the triangle are left out of the solve
//! ([`CentreLine::fits`]), so the split has fewer columns than before (the gap bench
//! 9.1 s -> 7.0 s). The [`CentreLine::Band`] split is unchanged.
//!
//! # The rise split (session 24)
//! A record that starts at its lowest input and never goes back below it (one sine from its
//! bottom) shows the relays below its inputs only on its first rise: those the stage had on
//! stay on, the others switch on once. For a PI stage at rest after a scan that died away at
//! the first input `u0`, the relays of radius `r` are on where `alpha < u0 + r`, a threshold
//! that differs by radius; the table clips all of them onto its bottom line, whose relays a
//! start memory can set only by one threshold. The band split then fits the first rise
//! wrongly, and the least squares spread the error over the record: on the single PI sines of
//! issue #12 the basis alone left 5.0-11.4 mV, fitted after the first cycle only 0.6-1.7 mV.
//! [`CentreLine::Rise`] is the band split with those relays on at the start and
//! once-switching relays on the grid line above them ([`rise_col`], weights >= 0, so the
//! table stays valid): the first rise is then fitted as the records show it. The records
//! choose it (`select`: kept where hysteresis and drift leave less than
//! [`crate::gap::RISE_CHOICE_RATIO`] of the band split's).
//!
//! # The tent split (session 57)
//! A band's weight is a density constant across the band, so a density that changes smoothly
//! along the centre axis (a Gaussian or Lorentzian Preisach plane) is fitted as a staircase,
//! and its loop by the steps' misfit: on issue #12's single sine with the families' Preisach
//! planes the band split left 1.4-7.9x the floor. [`CentreLine::Tent`] holds the same relays
//! with tents instead of bands (`Centres::Hat`): tent `k` of radius `r` weights the centres
//! by a hat of unit height on node [`HYST_TENT_INTERVALS`]` k`, falling to zero a band's width
//! each side, the two at the range's ends half hats, so that with equal weights the tents sum
//! to a uniform density (a play operator) and the density is linear between the peaks. Its
//! Everett function is the hat's mass over the interval `T_rk` measures, and its memoryless
//! part the hat's mass below the input, read at the nodes and interpolated between them as the
//! table reads it (`Centres::below_on_nodes`; the exact mass is quadratic between nodes, and
//! a column that left that out would differ from the fitted table's response). Twelve tents
//! per radius against eleven bands. The workflow names its effects on the band split and
//! refits the named table on the tent split at the end (`select`, step 20): as the split of
//! every diagnosis the tents fitted the planes closer but named a false `offset` beside the
//! four Bouc-Wen loops with a resonance of the hidden-effect suite (GAP.md, session 57).
//!
//! # The own centre line (session 59)
//! A band split's element leaves out `clamp(u, band)`, the mass of its centres below the
//! input. Its own centre line (the mean of its major branches) is that clamp smoothed over
//! its radius, so the two differ within a radius of the band's edges, and the differences
//! cancel only where the bands beside it weigh alike. Where a Preisach density changes along
//! the centre axis (a Gaussian or Lorentzian plane), the fitted table's centre line bends with
//! the weights, and `nonlinear-gain` takes the bend back: a curvature the records do not
//! hold. [`CentreLine::Own`] and [`CentreLine::RiseOwn`] hold the band and rise splits'
//! relays, each element less its own centre line over the table's range (read from its grid
//! as the span split's is over the records' span), so that their loop is centred on the
//! reversible map whatever the weights. They are not chosen by the loop alone: on one sine a
//! table of wide relays bends its minor loops' centre line, and the own line took the thesis
//! stage's true K'(u) into the table (GAP.md, session 52). `select`'s step 21 tries them
//! only where static shapes are named beside a table on records whose held levels are reached
//! from both sides. The span split's table (session 60) tries [`CentreLine::Own`] too: its
//! elements leave out their centre line over the records' span, which on records that span
//! less than the table's range is not the line over the table's range, and a narrow plane's
//! misfit there was taken up by a curvature, a scale and an offset together.
//!
//! # Resolution and regulariser
//! Radii: [`HYST_RADII`] at odd multiples of half the table's grid interval ([`radius_v`]:
//! the basis follows the table's own resolution instead of a fixed list of radii);
//! bands over the records' input span, edges on grid nodes, as many as the split uses
//! ([`CentreLine::bands`]: eleven for each split, [`HYST_BANDS_BAND`] and [`HYST_BANDS_SPAN`];
//! the span split also has the edge relays [`edge_col`]). The table spans the records' inputs and a
//! margin that depends on the split ([`hyst_range`]). The weights of one
//! radius in adjacent bands are tied by a smoothness penalty (Tikhonov on their differences,
//! [`HYST_BAND_SMOOTH`] times the mean Gram diagonal of that radius): a record that excites
//! one band only, or cannot tell the bands apart, gets equal weights (a play operator); one
//! whose loops differ along the range pays the penalty for the difference it shows.

use crate::io::model_file::HysteresisSection;
use model_core::hysteresis::{
    GRID_NODES, HysteresisMemory, HysteresisTable, TABLE_LEN, packed_index,
};
use model_core::params;

/// Bands along the Preisach plane's centre axis: the layout's capacity, the largest of the
/// splits' counts ([`CentreLine::bands`]); a split with fewer leaves the columns of the
/// bands it does not use at zero and out of the solve.
pub const HYST_BANDS: usize = if HYST_TENTS_BAND > HYST_BANDS_SPAN {
    HYST_TENTS_BAND
} else {
    HYST_BANDS_SPAN
};

/// Grid intervals between the [`CentreLine::Tent`] split's tents' peaks, and each tent's
/// half-width (our assumption: the band split's band of four intervals, so the two splits
/// resolve the centre axis alike and differ only in the density's shape between nodes).
pub const HYST_TENT_INTERVALS: usize = 4;

/// Tents of the [`CentreLine::Tent`] split: one on every [`HYST_TENT_INTERVALS`]-th node,
/// the two at the range's ends half tents (so that with equal weights they sum to a uniform
/// density: a play operator).
pub const HYST_TENTS_BAND: usize = INTERVALS / HYST_TENT_INTERVALS + 1;

/// Reversible columns: one per band of [`HYST_BANDS_BAND`] ([`rev_col`]).
pub const HYST_REV_BANDS: usize = HYST_BANDS_BAND;

/// Bands of the [`CentreLine::Band`] (and [`CentreLine::Rise`]) split (our assumption,
/// measured; 44 grid intervals divide into eleven bands of four). Eleven, as the span split
/// has: a Preisach density that changes along the range (a Gaussian or Lorentzian plane, PI
/// operators whose weights differ from one end to the other) is resolved at a band of 0.9 V
/// instead of 2.5 V. Measured in session 30 against four bands:
/// * issue #12's single sine (PI truths with radii from 0.02 V, seeds 21-28): hysteresis
///   alone at 1.30-2.43x the floor, under 2x on six of eight (four bands: 1.34-5.76x, one);
/// * Preisach-plane truths of the families' generator on that sine with a sensor offset
///   (seeds 7001-7008): 1.9-28.6x (four bands: 3.1-43x);
/// * families suite: 82 exact of 100, 4 false names of 110 (four: 83, 5 of 112), the loops of
///   every form fitted closer (on the 33 cases with a loop the median final residual went
///   from 6.6x to 3.7x the floor, lower on 28 and higher on 3), at 1.4x the time per case;
/// * hidden-effect suite unchanged (92/92, 0 false), gap bench +0.4 s.
///
/// Before session 30 the split had four: eleven had then given five Bouc-Wen cases of the
/// hidden-effect suite a false `offset` or `sensor-gain` (98.9 % -> 94.6 % exact), and in
/// session 21 the families 77 against 79 exact; the rules since (the look-alike static
/// shapes, the final check's offset rules, the rise split) leave those false names out.
pub const HYST_BANDS_BAND: usize = 11;

/// Bands of the [`CentreLine::Span`] split (our assumption, measured in session 11: the
/// thesis' table, whose loop widens along its range, fitted by the basis alone on its static
/// output over the identification protocol's slow record to 0.33 mV with eleven bands and
/// the edge columns; 44 grid intervals divide into eleven bands of four).
pub const HYST_BANDS_SPAN: usize = 11;

/// Radii of the basis: one per odd multiple of half a grid interval up to the span's half
/// ([`radius_v`]).
pub const HYST_RADII: usize = INTERVALS / 2;

/// Radius `i` of the basis in half grid intervals (odd: a relay centred on a node switches
/// midway between nodes); [`radius_v`] in volts, [`span_inside`] in the const layout.
const fn radius_halves(i: usize) -> usize {
    2 * i + 1
}

/// Loop columns of the basis: every (radius, band) pair, radius-major.
pub const HYST_LOOP_COLS: usize = HYST_RADII * HYST_BANDS;

/// Tents along each edge of the records' span that spread the edge relays' free thresholds
/// ([`edge_col`]; our assumption: one every [`EDGE_TENT_INTERVALS`] grid intervals, the
/// bands' resolution).
pub const EDGE_TENTS: usize = (INTERVALS - 2 * EDGE_NODE) / EDGE_TENT_INTERVALS + 1;

/// Grid intervals between the edge tents' centres, and each tent's half-width.
pub const EDGE_TENT_INTERVALS: usize = 4;

/// Edge-relay columns: [`EDGE_TENTS`] at the bottom of the span, then as many at its top.
pub const HYST_EDGE_COLS: usize = 2 * EDGE_TENTS;

/// Columns of the relays outside the span's triangle ([`CentreLine::Span`] only), two per
/// radius ([`out_col`]).
pub const HYST_OUT_COLS: usize = 2 * HYST_RADII;

/// Columns of the once-switching relays of the [`CentreLine::Rise`] split ([`rise_col`]):
/// [`EDGE_TENTS`] on the line [`RISE_NODE`].
pub const HYST_RISE_COLS: usize = EDGE_TENTS;

/// Columns whose weights are kept non-negative (densities of relays): the loop columns, the
/// edge columns, the outside columns and the once-switching columns.
pub const HYST_NONNEG_COLS: usize =
    HYST_LOOP_COLS + HYST_EDGE_COLS + HYST_OUT_COLS + HYST_RISE_COLS;

/// Columns of the basis: the non-negative ones, then one reversible column per band
/// ([`rev_col`]).
pub const HYST_COLS: usize = HYST_NONNEG_COLS + HYST_REV_BANDS;

/// Column index of band `k`'s reversible part (`clamp(u, band) - c_k`: a change of the
/// reversible slope within the band; sign free).
pub const fn rev_col(k: usize) -> usize {
    HYST_NONNEG_COLS + k
}

/// Column index of once-switching tent `k` ([`CentreLine::Rise`] only): relays whose lower
/// threshold is the grid line [`RISE_NODE`], below the records' inputs, and whose upper one
/// the tent spreads. Off at the start above the first input ([`start_memory`]), they switch
/// on as the input first rises past them and never off (the records do not go down to the
/// line): the column is the relays less their mass, zero once the input has risen past the
/// tent, as the span split's bottom edge columns.
pub const fn rise_col(k: usize) -> usize {
    HYST_LOOP_COLS + HYST_EDGE_COLS + HYST_OUT_COLS + k
}

/// The column of tent `k` on the bottom (`top == false`) or top line under split `form`: an
/// edge column for the span split, a once-switching column for the rise split (bottom
/// only), none for the band split.
pub const fn tent_col(form: CentreLine, top: bool, k: usize) -> Option<usize> {
    if form.edges() {
        Some(edge_col(top, k))
    } else if form.rises() && !top {
        Some(rise_col(k))
    } else {
        None
    }
}

/// Column index of edge tent `k` at the bottom (`top == false`) or top of the span.
pub const fn edge_col(top: bool, k: usize) -> usize {
    HYST_LOOP_COLS + if top { EDGE_TENTS } else { 0 } + k
}

/// Column index of radius `i`'s relays outside the span's triangle: those whose lower
/// threshold lies below the records' lowest input (`top == false`), or else whose upper one
/// lies above their highest (their centres: below `lo + r`, or else above `hi - r`).
pub const fn out_col(top: bool, i: usize) -> usize {
    HYST_LOOP_COLS + HYST_EDGE_COLS + 2 * i + top as usize
}

/// The group of basis column `c` a search keeps or leaves whole: a loop or outside column's
/// radius; the edge columns in two groups (bottom, top) after the radii, the once-switching
/// columns in one after those, the reversible ones each its own.
pub const fn radius_group(c: usize) -> usize {
    if c < HYST_LOOP_COLS {
        c / HYST_BANDS
    } else if c < HYST_LOOP_COLS + HYST_EDGE_COLS {
        HYST_RADII + (c - HYST_LOOP_COLS) / EDGE_TENTS
    } else if c < HYST_LOOP_COLS + HYST_EDGE_COLS + HYST_OUT_COLS {
        (c - HYST_LOOP_COLS - HYST_EDGE_COLS) / 2
    } else if c < HYST_NONNEG_COLS {
        HYST_RADII + 2
    } else {
        HYST_RADII + 3 + (c - HYST_NONNEG_COLS)
    }
}

/// Are the reversible slopes of the bands fitted with the loop (`false`: their columns stay
/// zero and the table's reversible map is the base model's `static_gain * u`)? A table is the
/// whole static map, so with them a scale error and a curvature of the centre line
/// (`sensor-gain`, `nonlinear-gain`) disappear into the table and are never named; without
/// them the split is the catalogue's: `hysteresis` the loop about the centre line, the other
/// two the centre line's scale and shape. Measured on the randomised families suite: with
/// them 67 % exact, 17 % false names, 29 effects missed (mostly the scale or curvature beside
/// a loop).
pub const HYST_FIT_REVERSIBLE: bool = false;

/// The basis columns the fit solves for: the loop columns, and the reversible ones if
/// [`HYST_FIT_REVERSIBLE`].
pub const HYST_FIT_COLS: usize = if HYST_FIT_REVERSIBLE {
    HYST_COLS
} else {
    HYST_NONNEG_COLS
};

/// Weight of the smoothness penalty between adjacent bands of one radius, as a fraction of
/// that radius' mean Gram diagonal (our assumption: a difference between bands is kept when
/// it lowers the weighted residual power by more than a tenth of what the radius' column
/// itself carries; tested on PI truths, where it must leave the bands equal, and on
/// asymmetric Everett truths, where it must not).
pub const HYST_BAND_SMOOTH: f64 = 0.1;

/// Which memoryless part a loop column leaves out: the centre line the fitted table keeps
/// at the base model's `static_gain * u` is that of one of the splits of the same relays,
/// and the records choose (`select`: the split whose hysteresis alone fits them better, or,
/// where the band and span splits fit within `CANNOT_TELL_RATIO`, the one whose diagnosis
/// explains every record where only one does, else the one naming fewer effects; the rise
/// split where it leaves far less than the band split).
///
/// * [`CentreLine::Band`]: each band's relays less their reversible part `clamp(u, band)`.
///   A Prandtl-Ishlinskii truth is exactly that (its play operators less `u`), and so is its
///   loop's centre line, which bends within an operator's radius of the records' extremes.
/// * [`CentreLine::Span`]: each element less its own centre line over the records' span (the
///   mean of its major loop's rising and falling branches between the records' extremes): the
///   loop of a table whose centre line over the records is straight, as the thesis' table's
///   is over its 0..10 V (a uniform density over the Preisach triangle). Its elements are cut
///   along the span's triangle (module doc, "The span split's triangle"). Measured with the
///   basis alone on that table's static output over the identification protocol's slow record:
///   `Band` 14.5 mV, `Span` 0.3 mV; on two PI truths over a 1 Hz sine, `Band` 0.5 and 2.1 mV,
///   `Span` 346 and 273 mV. Neither split serves both families.
/// * [`CentreLine::Rise`]: the band split with the relays below the records on at the start
///   and once-switching relays above them (module doc, "The rise split").
/// * [`CentreLine::Tent`], [`CentreLine::RiseTent`]: the band and rise splits with tents
///   instead of bands (module doc, "The tent split"; `select`'s step 20).
/// * [`CentreLine::Own`], [`CentreLine::RiseOwn`]: the band and rise splits with each element
///   less its own centre line over the table's range (module doc, "The own centre line";
///   `select`'s step 21).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CentreLine {
    /// Band relays less `clamp(u, band)`.
    Band,
    /// Each element less its centre line over the records' span.
    Span,
    /// The band split with the relays below the records on at the start and once-switching
    /// relays above them ([`rise_col`], [`start_memory`]).
    Rise,
    /// The band split with its relays' centres spread by tents instead of bands: a density
    /// piecewise linear along the centre axis (module doc, "The tent split").
    Tent,
    /// The rise split with tents instead of bands, as [`CentreLine::Tent`] for the band split.
    #[serde(rename = "rise-tent")]
    RiseTent,
    /// The band split's relays, each element less its own centre line over the table's range
    /// (module doc, "The own centre line"; `select`'s step 21).
    Own,
    /// The rise split's relays, each band's element less its own centre line over the
    /// table's range, as [`CentreLine::Own`] for the band split.
    #[serde(rename = "rise-own")]
    RiseOwn,
}

impl CentreLine {
    /// Bands along the centre axis this split uses ([`HYST_BANDS_BAND`],
    /// [`HYST_BANDS_SPAN`]); the loop columns of the others stay zero.
    pub const fn bands(self) -> usize {
        match self {
            CentreLine::Tent | CentreLine::RiseTent => HYST_TENTS_BAND,
            CentreLine::Band | CentreLine::Rise | CentreLine::Own | CentreLine::RiseOwn => {
                HYST_BANDS_BAND
            }
            CentreLine::Span => HYST_BANDS_SPAN,
        }
    }

    /// Does this split spread its relays' centres by tents instead of bands?
    /// [`CentreLine::Tent`] and [`CentreLine::RiseTent`].
    pub const fn tents(self) -> bool {
        matches!(self, CentreLine::Tent | CentreLine::RiseTent)
    }

    /// The same split with tents instead of bands (step 20 of `select`), where it has one:
    /// the band and rise splits'.
    pub const fn with_tents(self) -> Option<CentreLine> {
        match self {
            CentreLine::Band => Some(CentreLine::Tent),
            CentreLine::Rise => Some(CentreLine::RiseTent),
            CentreLine::Span
            | CentreLine::Tent
            | CentreLine::RiseTent
            | CentreLine::Own
            | CentreLine::RiseOwn => None,
        }
    }

    /// The same relays with each band's element less its own centre line over the table's
    /// range instead of `clamp(u, band)` (step 21 of `select`), where there is one: the band
    /// and rise splits', and for the span split (whose elements leave out their centre line
    /// over the records' span) the band split's, [`CentreLine::Own`].
    pub const fn with_own_line(self) -> Option<CentreLine> {
        match self {
            CentreLine::Band | CentreLine::Span => Some(CentreLine::Own),
            CentreLine::Rise => Some(CentreLine::RiseOwn),
            CentreLine::Tent | CentreLine::RiseTent | CentreLine::Own | CentreLine::RiseOwn => None,
        }
    }

    /// Does this split carry the once-switching columns ([`rise_col`]) and start from the
    /// memory [`start_memory`] makes? [`CentreLine::Rise`] and [`CentreLine::RiseTent`].
    pub const fn rises(self) -> bool {
        matches!(
            self,
            CentreLine::Rise | CentreLine::RiseTent | CentreLine::RiseOwn
        )
    }

    /// Does this split carry the edge columns ([`edge_col`]) on a range whose margin puts
    /// the records' extremes on grid nodes ([`EDGE_NODE`])? The [`CentreLine::Span`] split
    /// does: a table with a straight centre line that ends at the records' extremes has
    /// relays switching exactly there. The [`CentreLine::Band`] split keeps the play basis'
    /// 0.5 V margin ([`HYST_RANGE_MARGIN_V`]) without them, where PI truths fit it best.
    pub const fn edges(self) -> bool {
        matches!(self, CentreLine::Span)
    }

    /// The split's name in tables and JSON, and what its loop columns leave out.
    pub const fn describe(self) -> (&'static str, &'static str) {
        match self {
            CentreLine::Band => (
                "band",
                "each centre band's relays less clamp(u, band), a PI stage's loop",
            ),
            CentreLine::Rise => (
                "rise",
                "each centre band's relays less clamp(u, band), the relays below the records on \
                 at their start and once-switching relays above them: a PI stage's loop whose \
                 first rise no start memory of the band split sets",
            ),
            CentreLine::Tent => (
                "tent",
                "each centre tent's relays less their memoryless part: a PI stage's loop whose \
                 density changes smoothly along the range",
            ),
            CentreLine::RiseTent => (
                "rise-tent",
                "the rise split with each centre tent's relays less their memoryless part",
            ),
            CentreLine::Own => (
                "own",
                "each centre band's relays less their own centre line over the table's range: \
                 a loop whose centre line is straight where its density changes along the range",
            ),
            CentreLine::RiseOwn => (
                "rise-own",
                "the rise split with each centre band's relays less their own centre line over \
                 the table's range",
            ),
            CentreLine::Span => (
                "span",
                "each element less its centre line over the records' span, with edge relays: \
                 a loop whose centre line is straight",
            ),
        }
    }

    /// Is basis column `c` one this split fits: the loop columns of the bands it uses
    /// ([`Self::bands`]; for the split with edges only those with relays inside the span's
    /// triangle), the edge and outside columns ([`out_col`]) if it has edges
    /// ([`Self::edges`]), the once-switching ones ([`rise_col`]) if it rises
    /// ([`Self::rises`]), and the reversible ones if [`HYST_FIT_REVERSIBLE`].
    pub const fn fits(self, c: usize) -> bool {
        if c < HYST_LOOP_COLS {
            let (i, k) = (c / HYST_BANDS, c % HYST_BANDS);
            k < self.bands() && (!self.edges() || span_inside(i, k, self.bands()))
        } else if c < HYST_LOOP_COLS + HYST_EDGE_COLS + HYST_OUT_COLS {
            self.edges()
        } else if c < HYST_NONNEG_COLS {
            self.rises()
        } else {
            c < HYST_FIT_COLS
        }
    }
}

/// Grid intervals of the table.
const INTERVALS: usize = GRID_NODES - 1;

/// Does loop element (radius `i`, band `k` of `bands`) of the [`CentreLine::Span`] split have
/// relays inside the span's triangle ([`element_centres`])? In half grid intervals from the
/// table's bottom: band `k` holds the centres `per k..per (k + 1)` (`per` twice the band's
/// intervals), the triangle those from `2 EDGE_NODE + 2i + 1` to
/// `2 (INTERVALS - EDGE_NODE) - 2i - 1`.
const fn span_inside(i: usize, k: usize, bands: usize) -> bool {
    let per = 2 * (INTERVALS / bands);
    let (b0, b1) = (per * k, per * (k + 1));
    let r = radius_halves(i);
    let (c0, c1) = (2 * EDGE_NODE + r, 2 * (INTERVALS - EDGE_NODE));
    if c1 < r {
        return false;
    }
    let c1 = c1 - r;
    let lo = if b0 > c0 { b0 } else { c0 };
    let hi = if b1 < c1 { b1 } else { c1 };
    lo < hi
}
const _: () = assert!(INTERVALS.is_multiple_of(HYST_BANDS_BAND));
const _: () = assert!(INTERVALS.is_multiple_of(HYST_BANDS_SPAN));
const _: () = assert!(HYST_BANDS_BAND <= HYST_BANDS && HYST_BANDS_SPAN <= HYST_BANDS);
const _: () = assert!(HYST_TENTS_BAND <= HYST_BANDS);
const _: () = assert!(INTERVALS.is_multiple_of(HYST_TENT_INTERVALS));

/// Grid intervals of the table's range beyond each end of the records' inputs (our
/// assumption, measured). A relay whose lower threshold lies below the records' lowest input
/// never switches off during them (a stage whose earlier motion went lower keeps it on), and
/// one whose upper threshold lies above their highest input never switches on. A table that
/// ends at the records' extremes clips those relays onto its edges, where every visit
/// switches them: the loop gets a drop at its ends that the stage does not have (a 1 Hz sine
/// over 0.5..9.5 V of a PI truth was fitted to 170 mV; with a margin, 16 mV before any start
/// memory). The margin gives them room; whether they are on at the start is the start
/// memory's part ([`start_candidates`]). It is a whole number of grid intervals, so that the
/// records' extremes are grid nodes: a stage's relays that switch exactly at those extremes
/// (a table that ends there, as the thesis' does over its 0..10 V protocol) are the edge
/// columns ([`edge_col`]), which the table's bilinear interpolation reads exactly only on a
/// node. Measured on the thesis table's static output over the identification protocol's
/// slow record (least squares of the basis alone): a margin of 0.5 V and no edge columns
/// left 126 mV, two intervals and the edge columns 14.5 mV (with [`HYST_BANDS`] at 11).
pub const EDGE_NODE: usize = 2;

/// Margin of the table's range beyond the records' inputs for the [`CentreLine::Band`]
/// split, volts (our assumption, measured on the single-sine records of issue #12: without it
/// a 1 Hz sine over 0.5..9.5 V of a PI truth was fitted to 170 mV, with 0.5 V to 16 mV before
/// any start memory; the split has no edge columns, see [`EDGE_NODE`] for why the margin).
/// With the [`CentreLine::Span`] split's node margin and edge columns instead, the same
/// records ended at 6.8x and 6.3x the floor against 3.2x and 7.2x.
pub const HYST_RANGE_MARGIN_V: f64 = 0.5;

/// The table's input range for records whose inputs span `lo..hi` volts, kept within the
/// amplifier's input range and at least 1 V wide: for the [`CentreLine::Span`] split that
/// span widened by [`EDGE_NODE`] grid intervals each side (so `lo` and `hi` are nodes
/// `EDGE_NODE` and `INTERVALS - EDGE_NODE`), for the [`CentreLine::Band`] split by
/// [`HYST_RANGE_MARGIN_V`].
pub fn hyst_range(lo: f64, hi: f64, form: CentreLine) -> (f64, f64) {
    let (hi, m) = if form.edges() {
        // A span of at least 0.9 V, so that with its margins the table is about 1 V wide.
        let hi = hi.max(lo + 0.9);
        (
            hi,
            EDGE_NODE as f64 * (hi - lo) / (INTERVALS - 2 * EDGE_NODE) as f64,
        )
    } else {
        (hi, HYST_RANGE_MARGIN_V)
    };
    let lo = (lo - m).clamp(params::AMP_INPUT_MIN_V, params::AMP_INPUT_MAX_V - 1.0);
    let hi = (hi + m).clamp(lo + 1.0, params::AMP_INPUT_MAX_V);
    (lo, hi)
}

/// The decaying oscillations among the start candidates: (first amplitude as a share of the
/// span, ratio of each turn's amplitude to the last). Our assumption: 0.6 is a scan that died
/// away quickly; 0.85 (up to 25 turns) comes close to the anti-diagonal itself, the state of
/// every play operator centred on the first input.
pub const START_DECAYS: [(f64, f64); 6] = [
    (0.125, 0.6),
    (0.25, 0.6),
    (0.5, 0.6),
    (0.125, 0.85),
    (0.25, 0.85),
    (0.5, 0.85),
];

/// The start memories tried for records whose first input is `u0_v`, on a table over `range`
/// (turning points after coming up from the bottom, as `[hysteresis] start_turns_v`): none
/// (the major rising curve); came down from above (`[p]`, five heights); came down from the
/// top to `v` and up again (`[hi, v]`, three depths); and a decaying oscillation around
/// `u0` (`u0 +- A, u0 -+ r A, ...` down to 1 % of the span, three amplitudes, ratios `r` 0.6
/// and 0.85 ([`START_DECAYS`]), first excursion up or down: the state a stage is left in
/// after a scan that died away, close to the Preisach plane's anti-diagonal); and such a scan
/// around another eighth of the span, the stage then moved to `u0` ([`START_AWAY_LEVELS`]:
/// parked after work elsewhere). Our assumption: a lab record starts from rest after one of
/// these; up to 49 candidates, each checked on the fitted model over the head of each record
/// its memory changes ([`super::start::search`], which counts those that leave the table in
/// the same state at the first input once).
pub fn start_candidates(u0_v: f64, range: (f64, f64)) -> Vec<Vec<f64>> {
    let (lo, hi) = range;
    let u0 = u0_v.clamp(lo, hi);
    let span = hi - lo;
    let mut out: Vec<Vec<f64>> = vec![vec![]];
    for f in [0.125, 0.25, 0.5, 0.75, 1.0] {
        let p = u0 + (hi - u0) * f;
        if p - u0 > 0.01 * span {
            out.push(vec![p]);
        }
    }
    for f in [0.25, 0.5, 0.75] {
        let v = lo + (u0 - lo) * f;
        if u0 - v > 0.01 * span && v - lo > 0.01 * span {
            out.push(vec![hi, v]);
        }
    }
    // A scan that died away around `c`: turns `c + a`, `c - r a`, ... (first up for `sign`
    // 1), held to the range, down to 1 % of the span (two turns fewer than a model file
    // holds: the rise split's memory puts its descent first, `start_memory`).
    let scan = |c: f64, a: f64, ratio: f64, sign: f64| -> Vec<f64> {
        let mut amp = a * span;
        let mut s = sign;
        let mut h = Vec::new();
        while amp > 0.01 * span && h.len() + 2 < crate::io::model_file::MAX_START_TURNS {
            h.push((c + s * amp).clamp(lo, hi));
            amp *= ratio;
            s = -s;
        }
        h
    };
    for (a, ratio) in START_DECAYS {
        for sign in [1.0, -1.0] {
            out.push(scan(u0, a, ratio, sign));
        }
    }
    // Such a scan around another level, the stage then moved to the first input (the move
    // wipes out what it passes: `HysteresisMemory::reset_after`).
    for k in 1..START_AWAY_LEVELS {
        let c = lo + span * k as f64 / START_AWAY_LEVELS as f64;
        if (c - u0).abs() < 0.5 * span / START_AWAY_LEVELS as f64 {
            continue;
        }
        for a in START_AWAY_AMPLITUDES {
            for sign in [1.0, -1.0] {
                out.push(scan(c, a, START_AWAY_RATIO, sign));
            }
        }
    }
    out
}

/// Levels of the table's span (its `k / START_AWAY_LEVELS`, `k >= 1`) around which a start
/// candidate's scan died away before the stage was moved to the record's first input; those
/// within half a level of the first input are the centred ones above. Our assumption: a lab
/// parks its stage after scanning around a working point anywhere in the span; eighths are
/// 1.25 V apart on a 10 V table, a fraction of the loop's width.
pub const START_AWAY_LEVELS: usize = 8;
/// First amplitudes (shares of the span) of those scans.
pub const START_AWAY_AMPLITUDES: [f64; 2] = [0.25, 0.5];
/// Each turn's amplitude as a share of the last in those scans.
pub const START_AWAY_RATIO: f64 = 0.85;

/// The grid line of the once-switching relays ([`rise_col`]) and the lowest turning point of
/// the [`CentreLine::Rise`] split's start memory ([`start_memory`]): one interval above the
/// table's bottom. The table's bilinear grid spreads those relays' lower threshold up to the
/// next node, so they stay on while the records stay above node `RISE_NODE + 1`: on tables
/// up to 10.75 V wide, whose two intervals are within [`HYST_RANGE_MARGIN_V`] (0.47 V on a
/// 10 V table); on wider ones the records' lowest inputs switch some of them off again,
/// which the columns, simulated as the table runs, follow.
pub const RISE_NODE: usize = 1;

/// The table's memory at the records' start for the start `start_v` (turning points after
/// coming up from the bottom, [`start_candidates`]) under split `form`: `start_v` itself,
/// but for [`CentreLine::Rise`] first down from the top to the line [`RISE_NODE`], then
/// `start_v` with its points kept at or above that line, cut to
/// [`crate::io::model_file::MAX_START_TURNS`] (which [`start_candidates`] leave room for). The descent leaves every relay on the table's
/// bottom line on (the relays below the records' inputs a stage switched on in its earlier
/// motion, clipped onto that line) and those on the line above off; the table's model file
/// keeps the whole memory (`[hysteresis] start_turns_v`).
pub fn start_memory(range: (f64, f64), form: CentreLine, start_v: &[f64]) -> Vec<f64> {
    if !form.rises() {
        return start_v.to_vec();
    }
    let floor = node_v(range, RISE_NODE);
    let mut h = vec![range.1, floor];
    h.extend(start_v.iter().map(|&v| v.clamp(floor, range.1)));
    h.truncate(crate::io::model_file::MAX_START_TURNS);
    h
}

/// Node `i` of the grid over `range`, volts.
pub(super) fn node_v(range: (f64, f64), i: usize) -> f64 {
    range.0 + (range.1 - range.0) * i as f64 / INTERVALS as f64
}

/// Edges of band `k` of `bands`, volts.
fn band_v(range: (f64, f64), k: usize, bands: usize) -> (f64, f64) {
    let per = INTERVALS / bands;
    (node_v(range, k * per), node_v(range, (k + 1) * per))
}

/// The relay centres a loop element holds, and their density along the centre axis.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Centres {
    /// Every centre in `[lo, hi]`, unit density: a band or a part of one.
    Flat(f64, f64),
    /// A tent: unit density at `peak`, falling linearly to zero at `peak +- half`, only the
    /// centres within `cut`.
    Hat {
        peak: f64,
        half: f64,
        cut: (f64, f64),
    },
}

impl Centres {
    /// The relay mass with centres in `[x0, x1]`, volts of centre.
    fn mass(self, x0: f64, x1: f64) -> f64 {
        match self {
            Centres::Flat(lo, hi) => (hi.min(x1) - lo.max(x0)).max(0.0),
            Centres::Hat { peak, half, cut } => hat_mass(x0, x1, peak, half, cut),
        }
    }

    /// The whole relay mass.
    #[cfg(test)]
    fn total(self) -> f64 {
        self.mass(f64::NEG_INFINITY, f64::INFINITY)
    }

    /// The memoryless part of the element's relays at input `u` within `range`: the mass of
    /// the centres below it (each relay reversible, switching at its centre).
    fn below(self, u: f64, range: (f64, f64)) -> f64 {
        self.mass(f64::NEG_INFINITY, u.clamp(range.0, range.1))
    }

    /// [`Self::below`] as the table holds it: read at the grid's nodes and interpolated
    /// linearly between them (the table's bilinear interpolation of `f(a) - f(b)` is `f`'s
    /// node interpolant at `a` less at `b`). A band whose edges are nodes is linear between
    /// them, so [`Self::below`] itself is returned (the band splits' columns as they were, to
    /// the last bit: an interpolated form moved families case 3384 onto another path); a
    /// tent's is quadratic between nodes, and a column that left out the exact one would
    /// differ from the fitted table's response by the difference.
    fn below_on_nodes(self, u: f64, range: (f64, f64)) -> f64 {
        if let Centres::Flat(..) = self {
            return self.below(u, range);
        }
        let step = (range.1 - range.0) / INTERVALS as f64;
        let x = ((u.clamp(range.0, range.1) - range.0) / step).max(0.0);
        let i = (x.floor() as usize).min(INTERVALS - 1);
        let f = x - i as f64;
        let at = |j: usize| self.below(node_v(range, j), range);
        (1.0 - f) * at(i) + f * at(i + 1)
    }
}

/// The integral over `[x0, x1]` of the hat of unit height at `m`, half-width `h`, cut to
/// `cut`.
fn hat_mass(x0: f64, x1: f64, m: f64, h: f64, cut: (f64, f64)) -> f64 {
    let x0 = x0.max(cut.0).max(m - h);
    let x1 = x1.min(cut.1).min(m + h);
    if x1 <= x0 {
        return 0.0;
    }
    // The hat's antiderivative, 0 at m - h.
    let f = |x: f64| {
        let d = x - m;
        if d <= 0.0 {
            (d + h) * (d + h) / (2.0 * h)
        } else {
            h - (h - d) * (h - d) / (2.0 * h)
        }
    };
    f(x1) - f(x0)
}

/// Column index of (radius `i`, band `k`).
pub const fn col(i: usize, k: usize) -> usize {
    i * HYST_BANDS + k
}

/// Band-limited play operator `(r, band)`'s Everett function at `(a, b)` on a table over
/// `range` (`band` the centres it holds: a band, or the part of one an element keeps,
/// [`element_centres`], [`out_centres`]): the measure of the centres `c` in it whose relay,
/// clipped to the range
/// (thresholds `max(c - r, lo)` and `min(c + r, hi)`), lies inside `[b, a]`. Clipped, a relay
/// near an end of the range still switches within it, so the column stays loop-only there
/// (unclipped, the relays that would need an input beyond the range never switch and leave
/// a constant and a ramp in the column that an `offset` then soaks up).
fn t_rk(a: f64, b: f64, r: f64, centres: Centres, range: (f64, f64)) -> f64 {
    let from = if b <= range.0 {
        f64::NEG_INFINITY
    } else {
        b + r
    };
    let to = if a >= range.1 { f64::INFINITY } else { a - r };
    centres.mass(from, to)
}

/// Where the tents of split `form` spread their relays' free thresholds: the span `[node
/// EDGE_NODE, node INTERVALS - EDGE_NODE]` for the span split's edge relays; for the rise
/// split's once-switching relays from node `EDGE_NODE` up to the last node at or below the
/// records' highest input (the range's top less [`HYST_RANGE_MARGIN_V`]): a relay above it
/// would never switch on, a constant of its own beside the `offset`.
fn tent_cut(range: (f64, f64), form: CentreLine) -> (f64, f64) {
    if form.edges() {
        return span_v(range);
    }
    let step = (range.1 - range.0) / INTERVALS as f64;
    let top = ((range.1 - HYST_RANGE_MARGIN_V - range.0) / step + 1e-9).floor();
    (
        node_v(range, EDGE_NODE),
        range.0 + top.max(EDGE_NODE as f64) * step,
    )
}

/// The integral over `[x0, x1]` of edge tent `k`: the hat of half-width four grid intervals
/// centred on node `EDGE_NODE + 4 k`, cut to [`tent_cut`].
fn edge_tent_integral(x0: f64, x1: f64, k: usize, range: (f64, f64), form: CentreLine) -> f64 {
    let h = EDGE_TENT_INTERVALS as f64 * (range.1 - range.0) / INTERVALS as f64;
    let m = node_v(range, EDGE_NODE + EDGE_TENT_INTERVALS * k);
    hat_mass(x0, x1, m, h, tent_cut(range, form))
}

/// The relay mass of edge tent `k` of split `form` (its integral over [`tent_cut`]), input
/// volts.
fn edge_mass(k: usize, range: (f64, f64), form: CentreLine) -> f64 {
    edge_tent_integral(f64::NEG_INFINITY, f64::INFINITY, k, range, form)
}

/// Edge tent `k`'s Everett function at `(a, b)`: relays that switch off exactly at the span's
/// bottom (`top == false`: `beta` on node `EDGE_NODE`, `alpha` spread by the tent) or on
/// exactly at its top (`alpha` on node `INTERVALS - EDGE_NODE`, `beta` spread). A table that
/// ends at the records' extremes, as a stage's own table may, has such relays on its edges
/// (the relays beyond its range, clipped onto them); the play basis, whose relays switch
/// at `c +- r`, reaches those lines only at single points. For the rise split the bottom
/// tents are its once-switching relays, `beta` on node [`RISE_NODE`] ([`rise_col`]).
fn t_edge(a: f64, b: f64, top: bool, k: usize, range: (f64, f64), form: CentreLine) -> f64 {
    let eps = 1e-9 * (range.1 - range.0);
    // The edge relays sit on the span's edges, the once-switching ones on line RISE_NODE.
    let (lo, hi) = if form.edges() {
        span_v(range)
    } else {
        (node_v(range, RISE_NODE), range.1)
    };
    if top {
        if a >= hi - eps {
            edge_tent_integral(b, hi, k, range, form)
        } else {
            0.0
        }
    } else {
        if b <= lo + eps {
            edge_tent_integral(lo, a, k, range, form)
        } else {
            0.0
        }
    }
}

/// The grid of `f(a, b)` at the nodes, packed.
pub(super) fn grid(range: (f64, f64), f: impl Fn(f64, f64) -> f64) -> Vec<f32> {
    let mut e = vec![0.0f32; TABLE_LEN];
    for i in 1..GRID_NODES {
        for j in 0..i {
            if let Some(p) = packed_index(i, j) {
                e[p] = f(node_v(range, i), node_v(range, j)) as f32;
            }
        }
    }
    e
}

/// The smallest grid above `e` that model-core accepts: non-negative, rising in `alpha`,
/// falling in `beta` (running maxima along both directions; the second keeps the first).
/// The weights are non-negative but the reversible slopes of the bands have either sign,
/// and a band whose loop columns outweigh its slope leaves a grid with a falling branch: a
/// stage the table cannot be. The repair is small where the fit is near-valid and the
/// candidate is scored on its full simulation, so a large repair only costs it the step.
fn monotone(mut e: Vec<f32>) -> Vec<f32> {
    let at = |i: usize, j: usize| packed_index(i, j);
    // Rising in alpha: E(i, j) >= E(i - 1, j), with E(j, j) = 0.
    for j in 0..GRID_NODES - 1 {
        let mut run = 0.0f32;
        for i in j + 1..GRID_NODES {
            if let Some(p) = at(i, j) {
                run = run.max(e[p]);
                e[p] = run;
            }
        }
    }
    // Falling in beta: E(i, j) >= E(i, j + 1), with E(i, i) = 0.
    for i in 1..GRID_NODES {
        let mut run = 0.0f32;
        for j in (0..i).rev() {
            if let Some(p) = at(i, j) {
                run = run.max(e[p]);
                e[p] = run;
            }
        }
    }
    e
}

/// Radius `i` of the basis on a table over `range`, volts: `2 i + 1` half grid intervals.
///
/// On the table's nodes, where its bilinear interpolation reads it, a band-limited play
/// operator's Everett function is piecewise linear in its radius with breaks only at
/// half-interval multiples (where `b + r`, `a - r` or `b + r = a - r` cross a node). An operator
/// whose radius lies between two radii of the basis is, on the nodes, the mix of its two
/// neighbours except at the one break between them (a node error of at most its weight times
/// half an interval, at one node distance), and one narrower than half an interval is exactly
/// the mix of the first radius and of none (a reversible part). So a truth's radii (a PI
/// stage's, a Preisach density's) need not be guessed: measured on the single-sine records
/// of issue #12 (Prandtl-Ishlinskii truths with random radii), the fixed geometric list this
/// replaced (16 radii, 30 mV..5 V, ratio 1.41: gaps of 1 V between the widest) left 14.9 and
/// 16.0 mV after the hysteresis step, this basis 10.8 and 9.1 mV. Every half interval (43
/// radii) instead of every other one gained another 0.8 mV for seven times the solves'
/// cubic cost (the gap bench 15 s -> 27 s).
pub fn radius_v(range: (f64, f64), i: usize) -> f64 {
    radius_halves(i) as f64 * (range.1 - range.0) / (2 * INTERVALS) as f64
}

/// The basis columns at `rows` of a record with inputs `u_v`: for each loop element the split
/// fits ([`CentreLine::fits`]: (radius, band) pairs, and the outside columns of the split
/// with edges) the table's response minus the element's memoryless part, the edge columns
/// (the once-switching ones for the rise split), and the reversible ones (zero for columns
/// the split does not fit); every table started from [`start_memory`] of `start_v`.
pub fn columns(
    u_v: &[f64],
    rows: &[usize],
    range: (f64, f64),
    start_v: &[f64],
    form: CentreLine,
) -> Vec<Vec<f64>> {
    let start: Vec<f32> = start_memory(range, form, start_v)
        .iter()
        .map(|&v| v as f32)
        .collect();
    let mut out = vec![vec![0.0; rows.len()]; HYST_COLS];
    let path = table_path(u_v, rows);
    // Each element's table runs over the whole record (a 150 s record at 1 kHz and the span
    // split's 164 elements: about 0.5 s on one core), so the elements are shared out over the
    // cores.
    let elements = loop_elements(range, form);
    let cols = crate::util::par_map(&elements, |&(_, i, centres)| {
        let (e, rev) = element(range, i, centres, form);
        let mut c = vec![0.0; rows.len()];
        table_column(&e, range, &start, u_v, &path, rows, rev, &mut c);
        c
    });
    for (&(c_at, _, _), c) in elements.iter().zip(cols) {
        out[c_at] = c;
    }
    // The edge relays enter as a relay density >= 0 on the span's edges, their reversible part
    // not taken out (their weights move the table's centre line near the span's ends, where a
    // table that ends there bends it). The bottom ones are on whenever the input has risen
    // past their upper threshold since it last touched the bottom, most of a record: their
    // columns are the relays less their mass (zero when all are on), and the table's offset
    // carries the mass ([`HystFit::section`]), so that they do not make a constant the
    // `offset` then takes back.
    for top in [false, true] {
        for k in 0..EDGE_TENTS {
            let Some(at) = tent_col(form, top, k) else {
                continue;
            };
            let e = grid(range, |a, b| t_edge(a, b, top, k, range, form));
            let on = if top { 0.0 } else { edge_mass(k, range, form) };
            table_column(&e, range, &start, u_v, &path, rows, |_| on, &mut out[at]);
        }
    }
    for k in 0..HYST_REV_BANDS {
        let band = band_v(range, k, HYST_REV_BANDS);
        out[rev_col(k)] = rows
            .iter()
            .map(|&row| Centres::Flat(band.0, band.1).below(u_v[row], range))
            .collect();
    }
    out
}

/// Points per grid interval at which a [`CentreLine::Span`] centre line is sampled (our
/// assumption: the table is bilinear between nodes, so its branches are smooth within an
/// interval and eight points follow them to well below the records' noise).
const CENTRE_POINTS_PER_INTERVAL: usize = 8;

/// Loop element of radius `i` over the relay centres `centres` (a band's, or a part of it:
/// [`element_centres`], [`out_centres`]): its Everett grid and the memoryless part its column
/// leaves out (`rev(u)`, the band's `clamp(u, band)` or the element's centre line; its value
/// at the bottom of `range` is carried by the table's offset: [`HystFit::section`]).
fn element(
    range: (f64, f64),
    i: usize,
    centres: Centres,
    form: CentreLine,
) -> (Vec<f32>, Box<dyn Fn(f64) -> f64>) {
    let r = radius_v(range, i);
    let e = grid(range, |a, b| t_rk(a, b, r, centres, range));
    let rev: Box<dyn Fn(f64) -> f64> = match form {
        CentreLine::Band | CentreLine::Rise | CentreLine::Tent | CentreLine::RiseTent => {
            Box::new(move |u: f64| centres.below_on_nodes(u, range))
        }
        CentreLine::Span => centre_line(&e, range, span_v(range)),
        CentreLine::Own | CentreLine::RiseOwn => centre_line(&e, range, range),
    };
    (e, rev)
}

/// The records' span on the table's grid ([`CentreLine::Span`]): nodes `EDGE_NODE` and
/// `INTERVALS - EDGE_NODE`, volts. They are the records' extremes but where [`hyst_range`]
/// clamps the range to the amplifier's input range (inputs within the margin of its ends) or
/// widens a span under 0.9 V: the edge relays and the outside columns ([`out_col`]) then sit
/// at those nodes, and the records switch some of the relays they hold.
fn span_v(range: (f64, f64)) -> (f64, f64) {
    (
        node_v(range, EDGE_NODE),
        node_v(range, INTERVALS - EDGE_NODE),
    )
}

/// The relay centres of loop element (radius `i`, band `k`): the band's, and for the
/// [`CentreLine::Span`] split only those inside the span's triangle (both thresholds within
/// the records' span, `lo + r <= c <= hi - r`; empty where [`span_inside`] is false).
fn element_centres(range: (f64, f64), i: usize, k: usize, form: CentreLine) -> Centres {
    // The centres this split may hold: the range's, or the span's triangle's.
    let cut = if form.edges() {
        let r = radius_v(range, i);
        let (lo, hi) = span_v(range);
        (lo + r, (hi - r).max(lo + r))
    } else {
        range
    };
    if form.tents() {
        let step = (range.1 - range.0) / INTERVALS as f64;
        return Centres::Hat {
            peak: node_v(range, k * HYST_TENT_INTERVALS),
            half: HYST_TENT_INTERVALS as f64 * step,
            cut,
        };
    }
    let band = band_v(range, k, form.bands());
    let c0 = band.0.max(cut.0);
    Centres::Flat(c0, band.1.min(cut.1).max(c0))
}

/// The relay centres of radius `i` outside the span's triangle ([`out_col`]): below
/// `lo + r` (a lower threshold below the records' lowest input), or else above `hi - r` (an
/// upper threshold above their highest), within the table's range. With the triangle's
/// elements they cover the range once.
fn out_centres(range: (f64, f64), i: usize, top: bool) -> Centres {
    let r = radius_v(range, i);
    let (lo, hi) = span_v(range);
    let split = lo + r;
    if top {
        Centres::Flat((hi - r).max(split), range.1)
    } else {
        Centres::Flat(range.0, split)
    }
}

/// The loop elements split `form` fits ([`CentreLine::fits`]): column, radius index and
/// relay centres of each.
fn loop_elements(range: (f64, f64), form: CentreLine) -> Vec<(usize, usize, Centres)> {
    let mut out: Vec<(usize, usize, Centres)> = (0..HYST_RADII)
        .flat_map(|i| (0..form.bands()).map(move |k| (i, k)))
        .filter(|&(i, k)| form.fits(col(i, k)))
        .map(|(i, k)| (col(i, k), i, element_centres(range, i, k, form)))
        .collect();
    if form.edges() {
        for i in 0..HYST_RADII {
            for top in [false, true] {
                out.push((out_col(top, i), i, out_centres(range, i, top)));
            }
        }
    }
    out
}

/// The centre line over `(lo, hi)` (grid nodes: the records' span, nodes `EDGE_NODE` to
/// `INTERVALS - EDGE_NODE`, for [`CentreLine::Span`]; the whole range for the own-line splits)
/// of the table with grid `e` over `range`: the mean of its rising branch from `lo` and its
/// falling branch from `hi`, held constant beyond them.
fn centre_line(e: &[f32], range: (f64, f64), (lo, hi): (f64, f64)) -> Box<dyn Fn(f64) -> f64> {
    let step = (range.1 - range.0) / INTERVALS as f64;
    let intervals = ((hi - lo) / step).round().max(1.0) as usize;
    let n = CENTRE_POINTS_PER_INTERVAL * intervals;
    let Ok(t) = HysteresisTable::from_grid(range.0 as f32, range.1 as f32, 0.0, e) else {
        return Box::new(|_| 0.0);
    };
    let c = major_centre_v(&t, (lo, hi), n);
    Box::new(move |u: f64| {
        let p = ((u - lo) / (hi - lo) * n as f64).clamp(0.0, n as f64);
        let j = (p.floor() as usize).min(n - 1);
        let f = p - j as f64;
        c[j] * (1.0 - f) + c[j + 1] * f
    })
}

/// The centre line of table `t` between `lo` and `hi` at `n + 1` evenly spaced inputs: the
/// mean of its rising branch from `lo` (after coming down from `hi`) and its falling branch
/// from `hi`.
fn major_centre_v(t: &HysteresisTable, (lo, hi): (f64, f64), n: usize) -> Vec<f64> {
    let us: Vec<f64> = (0..=n)
        .map(|j| lo + (hi - lo) * j as f64 / n as f64)
        .collect();
    let mut mem = HysteresisMemory::new();
    mem.reset(t, hi as f32);
    t.forward(&mut mem, lo as f32);
    let up: Vec<f64> = us
        .iter()
        .map(|&u| t.forward(&mut mem, u as f32) as f64)
        .collect();
    let down: Vec<f64> = us
        .iter()
        .rev()
        .map(|&u| t.forward(&mut mem, u as f32) as f64)
        .collect();
    (0..=n).map(|j| 0.5 * (up[j] + down[n - j])).collect()
}

/// The samples of `u_v` a rate-independent table must be driven through to give, at every
/// one of `rows` (rising), the output and memory the whole record gives there: the rows, and
/// the turning points of the input as the table sees it (f32). A table's memory changes only
/// at reversals (wiping out depends on the thresholds a move passes, not on its steps), and a
/// repeated input changes nothing, so the samples inside a strictly monotone run or a run of
/// equal values are left out. Every sample up to the last row when an input is not finite
/// (the table holds its last input there, which this reduction does not model). On a 50 kHz
/// sine thinned to [`super::slow_fit::MAX_SLOW_ROWS`] rows, a tenth of the samples or fewer.
fn table_path(u_v: &[f64], rows: &[usize]) -> Vec<usize> {
    debug_assert!(
        rows.windows(2).all(|w| w[0] < w[1]) && rows.last().is_none_or(|&r| r < u_v.len()),
        "rows rising and within the record"
    );
    let Some(&last) = rows.last() else {
        return Vec::new();
    };
    let end = last.min(u_v.len().saturating_sub(1));
    let v: Vec<f32> = u_v.iter().take(end + 1).map(|&u| u as f32).collect();
    if v.iter().any(|x| !x.is_finite()) {
        return (0..=end).collect();
    }
    // The first sample of each run of equal values stands for the run.
    let starts: Vec<usize> = (0..v.len())
        .filter(|&i| i == 0 || v[i] != v[i - 1])
        .collect();
    let mut keep = vec![false; v.len()];
    for (k, &i) in starts.iter().enumerate() {
        keep[i] = match (k.checked_sub(1), starts.get(k + 1)) {
            (Some(before), Some(&after)) => (v[i] > v[starts[before]]) != (v[after] > v[i]),
            _ => true,
        };
    }
    for &r in rows {
        if let Some(k) = keep.get_mut(r) {
            *k = true;
        }
    }
    (0..v.len()).filter(|&i| keep[i]).collect()
}

/// The response at `rows` of the table with grid `e` over `range` to `u_v` driven through the
/// samples `path` ([`table_path`] of `rows`), started from the memory `start`, less `rev(u)`,
/// into `c` (left as it is if `e` is not a table).
#[allow(clippy::too_many_arguments)]
fn table_column(
    e: &[f32],
    range: (f64, f64),
    start: &[f32],
    u_v: &[f64],
    path: &[usize],
    rows: &[usize],
    rev: impl Fn(f64) -> f64,
    c: &mut [f64],
) {
    let Ok(t) = HysteresisTable::from_grid(range.0 as f32, range.1 as f32, 0.0, e) else {
        return;
    };
    let Some(&u0) = u_v.first() else {
        return;
    };
    let mut mem = HysteresisMemory::new();
    mem.reset_after(&t, start, u0 as f32);
    let mut at = 0usize;
    for &i in path {
        let y = t.forward(&mut mem, u_v[i] as f32);
        while let (Some(&row), Some(out)) = (rows.get(at), c.get_mut(at)) {
            if row != i {
                break;
            }
            *out = y as f64 - rev(u_v[row]);
            at += 1;
        }
    }
}

/// Adds the smoothness penalty between adjacent bands to the Gram block of the basis, whose
/// column `c` sits at `at(c)` in `g` (`None`: not in the solve): for each radius, between
/// each two of its loop columns in the solve whose bands are adjacent (the [`CentreLine::Span`]
/// split's elements with relays inside the span's triangle are a run of adjacent bands), at
/// [`HYST_BAND_SMOOTH`] times the mean Gram diagonal of the radius' columns in the solve. The
/// outside columns ([`out_col`]) are not tied to them.
pub fn add_band_penalty(g: &mut nalgebra::DMatrix<f64>, at: impl Fn(usize) -> Option<usize>) {
    for i in 0..HYST_RADII {
        let idx: Vec<Option<usize>> = (0..HYST_BANDS).map(|k| at(col(i, k))).collect();
        let present: Vec<usize> = idx.iter().flatten().copied().collect();
        if present.len() < 2 {
            continue;
        }
        let mean = present.iter().map(|&p| g[(p, p)]).sum::<f64>() / present.len() as f64;
        let lam = HYST_BAND_SMOOTH * mean;
        if lam <= 0.0 || !lam.is_finite() {
            continue;
        }
        for w in idx.windows(2) {
            let (Some(p), Some(q)) = (w[0], w[1]) else {
                continue;
            };
            g[(p, p)] += lam;
            g[(q, q)] += lam;
            g[(p, q)] -= lam;
            g[(q, p)] -= lam;
        }
    }
}

/// The fitted hysteresis: the table's range and the basis weights.
#[derive(Clone, Debug, PartialEq)]
pub struct HystFit {
    /// Input range of the table, volts.
    pub range: (f64, f64),
    /// Weight of each (radius, band) column, sensor volts per volt.
    pub weights: Vec<f64>,
    /// The start memory the columns were computed with, as the start search tries it
    /// ([`start_candidates`]); `[hysteresis] start_turns_v` holds [`start_memory`] of it.
    pub start_v: Vec<f64>,
    /// The centre line the loop columns left out.
    pub form: CentreLine,
}

impl HystFit {
    /// The `[hysteresis]` section: the Everett grid of `g u` plus the weighted basis
    /// ([`Self::grid_v`]), repaired into a table the stage accepts where it is not one
    /// (`monotone`; a fit whose bands keep their loop weights within the reversible slope needs
    /// no repair, see `slow_fit`'s validity penalty).
    pub fn section(&self, static_gain: f64) -> HysteresisSection {
        let range = self.range;
        let e = monotone(self.grid_v(static_gain));
        HysteresisSection {
            input_range_v: [range.0, range.1],
            offset_v: static_gain * range.0 - self.bottom_edge_mass_v() - self.rev_at_bottom_v(),
            dc_gain: None,
            loop_width_frac: None,
            everett_v: Some(e),
            start_turns_v: Some(start_memory(range, self.form, &self.start_v))
                .filter(|h| !h.is_empty()),
        }
    }

    /// The weighted mass of the bottom edge relays, sensor volts: their columns are the
    /// relays less that mass ([`columns`]), so the table's output at the bottom of its range
    /// is lower by it.
    fn bottom_edge_mass_v(&self) -> f64 {
        (0..EDGE_TENTS)
            .map(|k| self.tent_weight(false, k) * edge_mass(k, self.range, self.form))
            .sum()
    }

    /// The weight of tent `k` on the bottom (`top == false`) or top line of this split: an
    /// edge column's for the span split, a once-switching column's for the rise split (bottom
    /// only), none for the band split.
    fn tent_weight(&self, top: bool, k: usize) -> f64 {
        tent_col(self.form, top, k).map_or(0.0, |c| self.weights[c])
    }

    /// The weighted memoryless parts the loop columns leave out, at the bottom of the range
    /// (zero for [`CentreLine::Band`] and [`CentreLine::Rise`]): the table's offset carries them, as a memoryless `f`
    /// enters the grid as `f(a) - f(b)`, zero at the bottom.
    fn rev_at_bottom_v(&self) -> f64 {
        let mut v = 0.0;
        for (c, i, centres) in loop_elements(self.range, self.form) {
            let w = self.weights[c];
            if w != 0.0 {
                v += w * element(self.range, i, centres, self.form).1(self.range.0);
            }
        }
        v
    }

    /// The Everett grid of `g u` plus the weighted basis, before any repair:
    /// `E(a, b) = g (a - b) + sum_k s_k |[b, a] ^ band_k| + sum_rk m_rk (T_rk - |[b, a] ^ band_k|)`.
    pub fn grid_v(&self, static_gain: f64) -> Vec<f32> {
        let range = self.range;
        let rev_bands: Vec<(f64, f64)> = (0..HYST_REV_BANDS)
            .map(|k| band_v(range, k, HYST_REV_BANDS))
            .collect();
        let mut e: Vec<f64> = grid(range, |a, b| {
            let mut v = static_gain * (a - b);
            for (k, band) in rev_bands.iter().enumerate() {
                v += self.weights[rev_col(k)] * Centres::Flat(band.0, band.1).mass(b, a);
            }
            for top in [false, true] {
                for k in 0..EDGE_TENTS {
                    let w = self.tent_weight(top, k);
                    if w != 0.0 {
                        v += w * t_edge(a, b, top, k, range, self.form);
                    }
                }
            }
            v
        })
        .into_iter()
        .map(f64::from)
        .collect();
        // The loop elements: each its grid less its memoryless part `rev(a) - rev(b)`.
        for (c, i, centres) in loop_elements(range, self.form) {
            let w = self.weights[c];
            if w == 0.0 {
                continue;
            }
            let r = radius_v(range, i);
            let (_, rev) = element(range, i, centres, self.form);
            let part = grid(range, |a, b| {
                w * (t_rk(a, b, r, centres, range) - (rev(a) - rev(b)))
            });
            for (x, p) in e.iter_mut().zip(part) {
                *x += f64::from(p);
            }
        }
        e.into_iter().map(|x| x as f32).collect()
    }
}

/// Figures of a fitted table for tables and JSON: its range, and the width of its full-range
/// major loop (largest falling-minus-rising output at a node, sensor volts) in the lower and
/// upper half of the range.
pub fn summary(h: &HysteresisSection) -> Vec<(String, f64)> {
    let Ok(t) = h.table() else {
        return vec![];
    };
    let (lo, hi) = t.input_range_v();
    let mut mem = HysteresisMemory::new();
    mem.reset(&t, lo);
    let nodes: Vec<f32> = (0..GRID_NODES).map(|k| t.node_v(k)).collect();
    let rising: Vec<f32> = nodes.iter().map(|&u| t.forward(&mut mem, u)).collect();
    let falling: Vec<f32> = nodes
        .iter()
        .rev()
        .map(|&u| t.forward(&mut mem, u))
        .collect();
    let width = |range: std::ops::Range<usize>| {
        range
            .map(|k| (falling[GRID_NODES - 1 - k] - rising[k]) as f64)
            .fold(0.0f64, f64::max)
    };
    let half = GRID_NODES / 2;
    let mut out = vec![
        ("range_lo_v".into(), lo as f64),
        ("range_hi_v".into(), hi as f64),
        ("loop_width_low_v".into(), width(0..half)),
        ("loop_width_high_v".into(), width(half..GRID_NODES)),
    ];
    // The start memory, when it is not the major rising curve: how many turning points and
    // the first (highest reach) of them.
    if let Some(turns) = h.start_turns_v.as_ref().filter(|t| !t.is_empty()) {
        out.push(("start_turns".into(), turns.len() as f64));
        out.push(("start_first_turn_v".into(), turns[0]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The section's table, driven by the same input, gives `g u + sum w column` (the fit's
    /// model) to f32 rounding: the basis and the table are one representation.
    #[test]
    fn the_table_reproduces_the_weighted_columns() {
        for form in [
            CentreLine::Band,
            CentreLine::Span,
            CentreLine::Rise,
            CentreLine::Tent,
            CentreLine::RiseTent,
            CentreLine::Own,
            CentreLine::RiseOwn,
        ] {
            reproduces(form);
        }
    }

    fn reproduces(form: CentreLine) {
        let n = 4000;
        let u: Vec<f64> = (0..n)
            .map(|i| {
                let t = i as f64 / n as f64;
                4.0 + 3.0 * (2.0 * std::f64::consts::PI * 3.0 * t).sin() * (1.0 - 0.7 * t)
                    + 0.4 * (2.0 * std::f64::consts::PI * 17.0 * t).sin()
            })
            .collect();
        // The records' own range: their extremes on the edge relays' nodes.
        let (lo, hi) = crate::gap::min_max(&u);
        let range = hyst_range(lo, hi, form);
        let rows: Vec<usize> = (0..n).step_by(7).collect();
        let cols = columns(&u, &rows, range, &[], form);
        let mut weights = vec![0.0; HYST_COLS];
        // An asymmetric density: wide operators at the top, narrow ones at the bottom.
        // (columns both splits fit: for the span's, (12, 3) is cut by the triangle)
        weights[col(2, 1)] = 0.3;
        weights[col(6, 2)] = 0.1;
        weights[col(9, 3)] = 0.08;
        weights[col(12, 3)] = 0.02;
        weights[rev_col(2)] = -0.1;
        weights[rev_col(3)] = 0.05;
        if form.edges() {
            weights[edge_col(false, 1)] = 0.04;
            weights[edge_col(false, 6)] = 0.02;
            weights[edge_col(true, 3)] = 0.03;
            weights[out_col(false, 5)] = 0.05;
            weights[out_col(true, 8)] = 0.03;
        }
        if form.rises() {
            weights[rise_col(4)] = 0.05;
            weights[rise_col(6)] = 0.03;
        }
        let g = params::PLANT_GAIN;
        let fit = HystFit {
            range,
            weights: weights.clone(),
            start_v: vec![],
            form,
        };
        let section = fit.section(g);
        let t = section.table().expect("a valid table");
        let mut mem = HysteresisMemory::new();
        mem.reset_after(&t, &section.start_history_v(), u[0] as f32);
        let y: Vec<f32> = u.iter().map(|&v| t.forward(&mut mem, v as f32)).collect();
        let mut worst = 0.0f64;
        for (j, &row) in rows.iter().enumerate() {
            let model = g * u[row] + (0..HYST_COLS).map(|c| weights[c] * cols[c][j]).sum::<f64>();
            worst = worst.max((model - y[row] as f64).abs());
        }
        // f32 table values of up to ~6 V: a few ulps (0.5 uV each) summed over the segments.
        assert!(
            worst < 2e-5,
            "{form:?}: table vs weighted columns: {worst} V"
        );
        // And the loop is really there: the columns are not all flat (a band-limited play
        // swings by its band's width when its radius is wider).
        let mass = element_centres(range, 9, 3, form).total();
        let swing = cols[col(9, 3)].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(swing > 0.5 * mass, "column swing {swing} of {mass}");
        let swing = cols[edge_col(false, 1)]
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        if form.edges() {
            assert!(swing > 0.1, "edge column swing {swing}");
        } else {
            assert_eq!(swing, 0.0, "{form:?} has no edge columns");
        }
        let swing = cols[rise_col(6)].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if form.rises() {
            assert!(swing > 0.1, "once-switching column swing {swing}");
            // Once the input has reached its highest value every once-switching relay is on
            // and every such column zero: none holds a constant beside the `offset` (a tent
            // above the records' inputs would, `tent_cut`).
            let top = (0..n).max_by(|&i, &j| u[i].total_cmp(&u[j])).unwrap_or(0);
            for k in 0..HYST_RISE_COLS {
                let after = rows
                    .iter()
                    .zip(&cols[rise_col(k)])
                    .filter(|(r, _)| **r >= top)
                    .fold(0.0f64, |m, (_, v)| m.max(v.abs()));
                // (f32 rounding of the table: ulps of 1e-7 V)
                assert!(after < 1e-6, "tent {k}: {after} V after the records' top");
            }
        } else {
            assert_eq!(swing, 0.0, "{form:?} has no once-switching columns");
        }
    }

    /// A Prandtl-Ishlinskii stage started with every operator centred on the first input (the
    /// rest a scan that died away there leaves), on a sine that starts at its bottom: the
    /// relays below the records are on at the start where `alpha < u0 + r`, a threshold that
    /// differs by radius, which no start memory of the band split sets (they all sit on the
    /// table's bottom line: the band split is given the best of the start search's
    /// candidates); the rise split's once-switching relays carry the difference. The basis
    /// alone (least squares with a constant, the relay weights non-negative) on the truth's
    /// noise-free output: truths not drawn by the single-sine test, radii off the basis'
    /// own. With four bands the band split could not fit that rise (2.4-2.6 mV against the
    /// rise split's 0.9-1.1 mV); with eleven it can.
    #[test]
    fn the_rise_split_fits_a_first_rise_from_a_rest() {
        let rate = 2000.0;
        let n = 6000;
        let u: Vec<f64> = (0..n)
            .map(|i| 5.0 - 4.5 * (2.0 * std::f64::consts::PI * i as f64 / rate).cos())
            .collect();
        let rows: Vec<usize> = (0..n).step_by(3).collect();
        let g = params::PLANT_GAIN;
        let truths: [(&[f64], &[f64]); 2] = [
            (&[0.07, 0.4, 1.3, 2.6, 4.1], &[0.12, 0.06, 0.05, 0.05, 0.04]),
            (&[0.2, 0.75, 1.9, 3.3, 4.7], &[0.05, 0.08, 0.03, 0.06, 0.05]),
        ];
        for (radii, weights) in truths {
            // The stage's output less the table's reversible `g u`, which the basis keeps.
            let mut truth = crate::oracle::hysteresis_truth::PlayOperatorTruth::new(
                0.0,
                1.0 - weights.iter().sum::<f64>(),
                radii.to_vec(),
                weights.to_vec(),
                g,
                0.0,
            );
            truth.centre_on(u[0]);
            let y: Vec<f64> = u.iter().map(|&x| truth.step(x) - g * x).collect();
            // The basis of `form` started from `start` (the rise split's once-switching
            // columns left out unless `rise`), least squares with a constant: the RMS left.
            let rms = |form: CentreLine, start: &[f64], rise: bool| -> f64 {
                let range = hyst_range(0.5, 9.5, form);
                let cols = columns(&u, &rows, range, start, form);
                let is_rise = |c: usize| (rise_col(0)..rise_col(0) + HYST_RISE_COLS).contains(&c);
                let used: Vec<usize> = (0..HYST_FIT_COLS)
                    .filter(|&c| form.fits(c) && (rise || !is_rise(c)))
                    .collect();
                let m = used.len() + 1;
                let a = nalgebra::DMatrix::from_fn(rows.len(), m, |i, j| {
                    used.get(j).map_or(1.0, |&c| cols[c][i])
                });
                let b = nalgebra::DVector::from_iterator(rows.len(), rows.iter().map(|&i| y[i]));
                let mut gram = a.transpose() * &a;
                crate::gap::nnls::ridge(&mut gram);
                let nonneg: Vec<bool> = (0..m).map(|j| j < used.len()).collect();
                let x = crate::gap::nnls::nnls_normal(&gram, &(a.transpose() * &b), &nonneg)
                    .expect("a solution");
                let r = &b - &a * &x;
                (r.norm_squared() / r.len() as f64).sqrt()
            };
            // The band split from its best start memory of those the start search tries.
            let band_range = hyst_range(0.5, 9.5, CentreLine::Band);
            let band = start_candidates(u[0], band_range)
                .iter()
                .map(|c| rms(CentreLine::Band, c, false))
                .fold(f64::INFINITY, f64::min);
            let rise = rms(CentreLine::Rise, &[], true);
            let rise_start_only = rms(CentreLine::Rise, &[], false);
            // Measured with four bands (before session 30): the band split from its best
            // start 2.40 / 2.59 mV, the rise split's start without its once-switching columns
            // 47.9 / 73.9 mV, the rise split 0.90 / 1.09 mV. With eleven bands
            // (`HYST_BANDS_BAND`) the band split's best start fits the first rise as well:
            // band 0.55 / 0.78 mV, rise start alone 31.5 / 48.8 mV, rise 0.70 / 0.66 mV.
            // Asserted: the rise split reaches below 1.5 mV, inside the issue's 2x of a 1 mV
            // floor (a misfit of 1.73 mV), its once-switching columns are what does it (the
            // start alone leaves ten times more), and it stays within 1.5x of the band split's
            // best (the records choose between the two: `RISE_CHOICE_RATIO`).
            println!(
                "radii {radii:?}: band {band:.2e} V, rise start alone {rise_start_only:.2e} V, rise {rise:.2e} V"
            );
            assert!(
                rise < 1.5 * band && rise_start_only > 10.0 * rise && rise < 1.5e-3,
                "radii {radii:?}: band {band} V, rise start alone {rise_start_only} V, rise {rise} V"
            );
        }
    }

    /// A valid grid is kept as it is; an invalid one is lifted to the smallest valid grid.
    #[test]
    fn the_repaired_grid_is_a_valid_table_and_keeps_a_valid_one() {
        let range = (0.0, 10.0);
        // A valid grid is left as it is.
        let good = grid(range, |a, b| 0.8 * (a - b) + 0.05 * (a - b).powi(2));
        assert_eq!(monotone(good.clone()), good);
        // A grid with a falling branch (a negative slope in the middle band) is lifted to
        // the smallest valid grid above it: accepted, and no node lowered.
        let bad = grid(range, |a, b| {
            let f = |u: f64| u - 1.5 * (u.clamp(4.0, 6.0) - 4.0);
            f(a) - f(b)
        });
        assert!(HysteresisTable::from_grid(0.0, 10.0, 0.0, &bad).is_err());
        let fixed = monotone(bad.clone());
        assert!(HysteresisTable::from_grid(0.0, 10.0, 0.0, &fixed).is_ok());
        assert!(fixed.iter().zip(&bad).all(|(f, b)| f >= b));
    }

    /// The validity rule `slow_fit` keeps: non-negative loop weights whose sum in each band
    /// stays within the reversible slope give a grid the stage accepts with no repair (random
    /// weights, every radius and band); a band whose weights exceed the slope by half gives a
    /// grid that falls near its diagonal.
    #[test]
    fn loop_weights_within_the_reversible_slope_need_no_repair() {
        use rand::{Rng, SeedableRng};
        let g = params::PLANT_GAIN;
        for seed in 0..20u64 {
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let range = (rng.gen_range(-1.0..2.0), rng.gen_range(6.0..10.0));
            let mut weights = vec![0.0; HYST_COLS];
            for k in 0..CentreLine::Band.bands() {
                let raw: Vec<f64> = (0..HYST_RADII)
                    .map(|_| {
                        if rng.gen_bool(0.4) {
                            rng.gen_range(0.0..1.0)
                        } else {
                            0.0
                        }
                    })
                    .collect();
                let total: f64 = raw.iter().sum::<f64>().max(1e-9);
                // Band sums from a tenth of the slope up to the whole of it.
                let share = rng.gen_range(0.1..1.0) * g;
                for (i, w) in raw.iter().enumerate() {
                    weights[col(i, k)] = w / total * share;
                }
            }
            let fit = HystFit {
                range,
                weights: weights.clone(),
                start_v: vec![],
                form: CentreLine::Band,
            };
            let raw = fit.grid_v(g);
            assert_eq!(
                monotone(raw.clone()),
                raw,
                "seed {seed}: a valid fit was repaired"
            );
            // Band 1 at 1.5 times the slope, on its narrowest radius: a falling branch.
            for i in 0..HYST_RADII {
                weights[col(i, 1)] = 0.0;
            }
            weights[col(0, 1)] = 1.5 * g;
            let over = HystFit {
                range,
                weights,
                start_v: vec![],
                form: CentreLine::Band,
            }
            .grid_v(g);
            assert_ne!(
                monotone(over.clone()),
                over,
                "seed {seed}: an invalid fit passed"
            );
        }
    }

    /// The own-line splits' loop is centred on the reversible map: with wide operators whose
    /// weights peak mid-range (a Preisach density that changes along the centre axis), the
    /// mean of the table's major rising and falling branches over its range is `g u` to f32
    /// rounding (the branches of a bilinear table are linear between its nodes, so the
    /// element's centre line read on eight points per interval is exact there), where the band
    /// split's, each element less `clamp(u, band)`, bends with the weights (0.8 uV against
    /// 51 mV here).
    #[test]
    fn the_own_line_split_keeps_the_loops_centre_line_straight() {
        let range = (0.0, 11.0);
        let g = params::PLANT_GAIN;
        let bend_v = |form: CentreLine| -> f64 {
            let mut weights = vec![0.0; HYST_COLS];
            for k in 0..form.bands() {
                let peak = 1.0 - ((k as f64 - 5.0) / 3.0).powi(2);
                for i in [3, 6, 9] {
                    weights[col(i, k)] = 0.03 * peak.max(0.0);
                }
            }
            let fit = HystFit {
                range,
                weights,
                start_v: vec![],
                form,
            };
            let t = fit.section(g).table().expect("a valid table");
            // (the centre line less g u, less its value at the bottom: the table's level; at
            // 400 inputs, off the nodes and the eight points per interval the fit reads)
            let n = 400;
            let c: Vec<f64> = major_centre_v(&t, range, n)
                .into_iter()
                .enumerate()
                .map(|(j, v)| v - g * (range.0 + (range.1 - range.0) * j as f64 / n as f64))
                .collect();
            c.iter().fold(0.0f64, |m, v| m.max((v - c[0]).abs()))
        };
        let own = bend_v(CentreLine::Own);
        let band = bend_v(CentreLine::Band);
        assert!(own < 2e-5, "own-line split's centre line bends {own} V");
        assert!(band > 1e-3, "band split's centre line bends only {band} V");
    }

    /// The tent split's relays are the band split's, spread otherwise: for every radius its
    /// tents with equal weights hold each centre of the range once (their masses over any
    /// interval sum to its length, so the tent split holds a play operator as the band split
    /// does), each tent is a hat (its density at the peak node 1 and half way to the next 1/2),
    /// and its memoryless part, read as the table reads it, agrees with the exact mass on the
    /// nodes and lies within the hat's curvature between them.
    #[test]
    fn the_tents_hold_each_centre_once_and_are_hats() {
        for range in [(-0.5, 10.5), (1.3, 4.1), (-2.0, 9.0)] {
            let step = (range.1 - range.0) / INTERVALS as f64;
            for form in [CentreLine::Tent, CentreLine::RiseTent] {
                let tents: Vec<Centres> = (0..form.bands())
                    .map(|k| element_centres(range, 3, k, form))
                    .collect();
                for (x0, x1) in [
                    (range.0, range.1),
                    (range.0 + 0.37 * step, range.0 + 9.81 * step),
                    (range.0 + 17.2 * step, range.0 + 17.9 * step),
                ] {
                    let sum: f64 = tents.iter().map(|t| t.mass(x0, x1)).sum();
                    assert!(
                        (sum - (x1 - x0)).abs() < 1e-9 * (range.1 - range.0),
                        "{range:?} {form:?} [{x0}, {x1}]: {sum}"
                    );
                }
                // Tent 2 peaks on node 8: density 1 there, 1/2 two nodes away.
                let density = |x: f64| (tents[2].mass(x - 1e-6, x + 1e-6)) / 2e-6;
                let peak = node_v(range, 2 * HYST_TENT_INTERVALS);
                assert!((density(peak) - 1.0).abs() < 1e-4);
                assert!((density(peak + 2.0 * step) - 0.5).abs() < 1e-4);
                assert!((density(peak - 2.0 * step) - 0.5).abs() < 1e-4);
                assert!(density(peak + 4.5 * step).abs() < 1e-4);
                for j in 0..=INTERVALS {
                    let u = node_v(range, j);
                    let exact = tents[2].below(u, range);
                    assert!((tents[2].below_on_nodes(u, range) - exact).abs() < 1e-12);
                    // Between nodes the chord of a curve whose second derivative is at most
                    // 1 / half-width: within step^2 / (8 half).
                    if j < INTERVALS {
                        let mid = u + 0.5 * step;
                        let err = (tents[2].below_on_nodes(mid, range)
                            - tents[2].below(mid, range))
                        .abs();
                        let half = HYST_TENT_INTERVALS as f64 * step;
                        assert!(err <= step * step / (8.0 * half) + 1e-12, "node {j}: {err}");
                    }
                }
            }
        }
    }

    /// The span split's relays are the band split's, cut along the span's triangle: for every
    /// radius, its triangle elements and its two outside columns hold each relay of the
    /// range once (their Everett functions sum to the bands' at every node), and
    /// [`span_inside`] names exactly the elements with relays inside the triangle.
    #[test]
    fn the_span_split_cuts_the_bands_along_the_triangle() {
        for range in [(-0.5, 10.5), (1.3, 4.1), (-2.0, 9.0)] {
            let per = |centres: Centres| centres.total();
            for i in 0..HYST_RADII {
                let r = radius_v(range, i);
                let mut parts: Vec<Centres> = (0..CentreLine::Span.bands())
                    .map(|k| element_centres(range, i, k, CentreLine::Span))
                    .collect();
                for (k, &part) in parts.iter().enumerate() {
                    let inside = per(part) > 1e-9 * (range.1 - range.0);
                    let told = span_inside(i, k, CentreLine::Span.bands());
                    assert_eq!(told, inside, "{range:?} radius {i} band {k}");
                }
                parts.push(out_centres(range, i, false));
                parts.push(out_centres(range, i, true));
                let total: f64 = parts.iter().map(|&c| per(c)).sum();
                assert!(
                    (total - (range.1 - range.0)).abs() < 1e-9,
                    "{range:?} radius {i}"
                );
                for a_i in 1..GRID_NODES {
                    for b_i in 0..a_i {
                        let (a, b) = (node_v(range, a_i), node_v(range, b_i));
                        let cut: f64 = parts.iter().map(|&c| t_rk(a, b, r, c, range)).sum();
                        let bands: f64 = (0..HYST_BANDS_SPAN)
                            .map(|k| {
                                let band = band_v(range, k, HYST_BANDS_SPAN);
                                t_rk(a, b, r, Centres::Flat(band.0, band.1), range)
                            })
                            .sum();
                        assert!(
                            (cut - bands).abs() < 1e-9,
                            "{range:?} radius {i} at ({a}, {b})"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn zero_weights_give_the_linear_map() {
        let fit = HystFit {
            range: (0.0, 10.0),
            weights: vec![0.0; HYST_COLS],
            start_v: vec![],
            form: CentreLine::Band,
        };
        let t = fit.section(0.79).table().unwrap();
        let mut mem = HysteresisMemory::new();
        for u in [0.0f32, 3.0, 7.5, 2.0, 9.0] {
            assert!((t.forward(&mut mem, u) - 0.79 * u).abs() < 1e-5);
        }
    }

    /// Driven through [`table_path`]'s samples only, every element's table gives at every row
    /// the same output, bit for bit, as driven through every sample: on inputs with holds,
    /// noise reversals, excursions past the table's range, a decaying oscillation deep enough
    /// to fill the memory (merges), and rows at random, thinned and bunched.
    #[test]
    fn a_table_driven_through_its_turning_points_gives_every_row_exactly() {
        use rand::{Rng, SeedableRng};
        let range = (0.0, 10.0);
        let mut reduced_share = Vec::new();
        for seed in 0..6u64 {
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let n = 30_000;
            let noise = [0.0, 1e-4, 0.02][seed as usize % 3];
            let u: Vec<f64> = (0..n)
                .map(|i| {
                    let t = i as f64 / n as f64;
                    let sweep = 5.0 + 5.6 * (2.0 * std::f64::consts::PI * 4.0 * t).sin();
                    // A decaying oscillation (nested loops past the memory's depth), then holds.
                    let ring =
                        4.0 * (-6.0 * t).exp() * (2.0 * std::f64::consts::PI * 90.0 * t).sin();
                    let held = ((t * 40.0).floor() / 40.0 * 9.0).min(9.0);
                    let base = if t < 0.4 {
                        sweep
                    } else if t < 0.7 {
                        5.0 + ring
                    } else {
                        held
                    };
                    base + noise * rng.gen_range(-1.0..1.0)
                })
                .collect();
            let stride = [25, 1][seed as usize / 3];
            let rows: Vec<usize> = (0..n)
                .filter(|&i| i % stride == 0 && rng.gen_bool(0.8))
                .collect();
            let path = table_path(&u, &rows);
            let every: Vec<usize> = (0..=*rows.last().unwrap()).collect();
            reduced_share.push(path.len() as f64 / every.len() as f64);
            for form in [CentreLine::Band, CentreLine::Span] {
                let range = hyst_range(range.0, range.1, form);
                let start: Vec<f32> = start_memory(range, form, &[7.0, 2.0])
                    .iter()
                    .map(|&v| v as f32)
                    .collect();
                for (_, i, centres) in loop_elements(range, form).into_iter().step_by(5) {
                    let (e, rev) = element(range, i, centres, form);
                    let mut full = vec![0.0; rows.len()];
                    let mut part = vec![f64::NAN; rows.len()];
                    table_column(&e, range, &start, &u, &every, &rows, &rev, &mut full);
                    table_column(&e, range, &start, &u, &path, &rows, &rev, &mut part);
                    for (a, b) in full.iter().zip(&part) {
                        assert_eq!(a.to_bits(), b.to_bits(), "seed {seed}, radius {i}");
                    }
                }
            }
        }
        // The noiseless inputs lose most of their samples (the reduction is not vacuous).
        assert!(reduced_share[0] < 0.2, "{reduced_share:?}");
    }
}
