//! Host side of the project: independent `f64` reference models, the simulations and
//! analyses the tests and the `piezo` command line share, and the command line's verbs.
//!
//! Every verb of `piezo` is a function here; `src/bin/piezo.rs` only parses arguments.
//! The control maths itself lives in `model-core`; this crate calls it and checks it.

pub mod analysis;
pub mod demo;
pub mod gap;
pub mod gap_cmd;
pub mod identify;
pub mod identify_cmd;
pub mod loop_cmd;
pub mod mat;
pub mod model_file;
pub mod qemu;
pub mod qemu_vectors;
pub mod record;
pub mod record_cmd;
pub mod reference;
pub mod sim;
pub mod simulate;
pub mod synth;
pub mod testing;
pub mod track;
