//! The virtual stage of `piezo demo`: the model-gap workflow without a board. The stage is the
//! thesis' own overall model (`thesis-full`, ch. 6: its Everett hysteresis table of sec. 5.3,
//! the drift of eq. 5.1-5.3 with its input-dependent gain K(u), the non-linear gain K'(u), the
//! amplifier's slew limit, converters and 2.5 mV of sensor noise) with a sensor offset, a
//! real lab's first effect, added. The demo records the [`super::protocol`] records from it
//! and runs the workflow from `thesis-linear`.
//!
//! No hidden effect has the catalogue's form (issue #12 item 6): the table is the thesis'
//! congruent quadratic Everett function on its own 45-node grid over 0..10 V, not the fit's
//! band-limited play basis on the records' span; the drift's K(u) is the thesis' cubic, which
//! the fit must find in its structural round; K'(u) multiplies the whole hysteretic map.

use crate::io::model_file::{ModelFile, OffsetSection};

/// The demo stage's sensor offset, volts (our assumption: a 12 mV zero error).
pub const DEMO_OFFSET_V: f64 = 0.012;

/// The demo's virtual stage: `thesis-full` with a 12 mV sensor offset.
pub fn demo_truth(seed: u64) -> ModelFile {
    let mut m = ModelFile::built_in("thesis-full").unwrap_or_else(|| unreachable!());
    m.name = "demo truth: thesis-full with a sensor offset".into();
    m.converters.seed = seed;
    m.offset = Some(OffsetSection {
        offset_v: DEMO_OFFSET_V,
    });
    m
}
