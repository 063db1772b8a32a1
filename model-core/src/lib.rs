//! The control maths of the piezo positioning loop, in one `no_std` crate without an
//! allocator: what the firmware's 50 kHz interrupt runs, what the QEMU smoke runs run, and
//! what the host tools simulate.
//!
//! # The signal chain
//! ```text
//!  reference r ──► PreFilter ──► (+)──► LagCompensator ──► OutputLimits ──► DacCode ──► E-505
//!                                 ▲ -                                                     │
//!                                 └── AdcCode ◄── E-509 monitor y ◄── P-753 stage ◄───────┘
//! ```
//! Units: `u` is volts at the amplifier's control input (-2..12 V; window 0..10 V by default),
//! `y` is sensor monitor volts (10 V = 12 um). Converter codes follow the DS1103: 16-bit ADC
//! and 14-bit DAC, both over +-10 V ([`codes`]).
//!
//! # What lives where
//! * [`params`]: every number, with its thesis section or marked as our assumption.
//! * [`codes`]: `AdcCode`, `DacCode`, volts, sensor scale.
//! * [`discretize`]: design-time `f64` maths (matrix exponential, delayed ZOH).
//! * [`sections`]: `f32` building blocks that stay accurate near z = 1.
//! * [`limits`]: window, slew limit and NaN guard at the last stage.
//! * [`lag`]: the lag compensator with its free integrator (eq. 4.5).
//! * [`plant`]: the linear plant of eq. 4.4 as an exact fixed-step simulator.
//! * [`controller`]: the one per-sample function the firmware's interrupt and the QEMU runs
//!   call: modes, faults, compensator, limits.
//! * [`hysteresis`]: the static hysteretic map (Everett table) with its turning-point memory.
//! * [`prefilter`]: the reference pre-filter `H'` (eq. 4.12), derived from the loop at run time.
//! * [`reference`](mod@reference): reference generators (step, ramp, sine, triangle, square, sweep) with preview.
//! * [`drift`], [`gain`], [`amplifier`], [`sensor`]: the non-linear blocks of ch. 5.
//! * [`stage`]: the ch. 6 overall model composed of all blocks (the wiring is stated there).
//! * [`held`]: a held input's steps past the stage's fast fixed point in closed form (the
//!   host's simulations of slow records; not the 50 kHz path).
//! * [`frame`]: the capture wire format (firmware encoder, host decoder).
//! * [`learning`]: iterative learning control over the generator's repeat (the table the
//!   interrupt reads, the update a task runs once per repeat).
//! * [`closed_loop`]: the one closed-loop harness ([`controller::Controller::step`] around a
//!   stage through the converters) that the QEMU [`scenarios`] and the host's loop and tracking
//!   figures all run.
//!
//! Each block keeps its configuration (coefficients, `Copy`) apart from its state, so a new
//! configuration can be computed outside the interrupt and swapped in whole.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod amplifier;
pub mod closed_loop;
pub mod codes;
pub mod controller;
pub mod discretize;
pub mod drift;
pub mod frame;
pub mod gain;
pub mod held;
pub mod hysteresis;
pub mod lag;
pub mod learning;
pub mod limits;
pub mod params;
pub mod plant;
pub mod play;
pub mod prefilter;
pub mod reference;
pub mod scenarios;
pub mod sections;
pub mod sensor;
pub mod stage;

pub use codes::{AdcCode, DacCode};
