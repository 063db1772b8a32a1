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
//! 7. **Final check** (each named effect taken back out, kept only if the residual grows),
//!    then, unless every record is at its floor, a **last refit** of the slow effects
//!    together with every named effect in place (kept where no record's residual grows and
//!    their sum falls: a fast effect named after them moves the fast record their fit
//!    shares), then **swaps** of slow effects the records cannot tell apart.
//!
//! Steps 4-7 run with the hysteresis basis' split the records choose
//! ([`everett::CentreLine`]: band, span, or the band split's rise variant where the
//! records' first rise needs it); where hysteresis and drift alone leave the band and span
//! splits within
//! [`CANNOT_TELL_RATIO`] of each other and the diagnosis names hysteresis without ending at
//! the floor, they run under the other split too and the diagnosis that explains every
//! record (within 2x its floor, or of the noise between a periodic input's cycles where that
//! is larger: [`cycle_noise`]) is kept where only one does, else the one naming fewer
//! effects.
//!
//! # What it trades
//! The slow effects are fitted by a linear solve on settled samples, the fast ones by a
//! bounded one- or two-dimensional search on the fast records; only the few candidates are
//! simulated in full. Greedy selection can in principle miss a pair whose members only help
//! together; refitting every present slow effect with each new one limits that.
//!
//! # Where each part lives
//! * [`constants`]: the workflow's thresholds (our assumptions, each with its reason);
//! * [`data`]: the records as the workflow sees them, their noise floor, simulation of a model
//!   on them (steps 1 and 2); [`input_noise`]: a measured input's noise, which the model
//!   carries into the residual (step 2);
//! * [`signatures`]: the localisation in time and frequency (step 3);
//! * [`catalogue`]: the effects, how each sits in the model file, its bounds;
//! * [`fast_fit`] and [`slow_fit`] (with [`nnls`], the sign-constrained solve): the fits of
//!   step 4;
//! * [`everett`]: the hysteresis form, weights on a basis that is the model-core Everett
//!   table's own response; [`start`]: the table's memory at the start of the records;
//!   [`memory`]: whether the records' loop needs memory at all (a hysteresis candidate's
//!   memoryless twin);
//! * [`select`]: the greedy driver: candidates, scores, selection, the final check (steps 4-6);
//! * [`report`]: the table and the HTML report of a [`Diagnosis`]; [`unexplained`]: what is
//!   left above twice the floor and where (never silent); [`shrink`]: how far each named
//!   effect cut the residual (the measure, for the tests and readers);
//! * [`protocol`]: the recording protocol whose records show every effect; [`demo`]: the
//!   virtual stage of `piezo demo`.

pub mod catalogue;
pub mod constants;
pub mod cycle_noise;
pub mod data;
pub mod demo;
pub mod everett;
pub mod fast_fit;
pub mod input_noise;
pub mod mains;
pub mod memory;
pub mod nnls;
pub mod protocol;
pub mod report;
pub mod scale_order;
pub mod select;
pub mod shrink;
pub mod signatures;
pub mod slow_fit;
pub mod start;
pub mod unexplained;

pub use constants::*;
pub use data::{Data, decimate_to_fit, load_data, min_max, mse, noise_floor, sim};
pub use select::{CannotTell, Diagnosis, Options, STANDING_OFFSET_NOTE, Step, diagnose};
