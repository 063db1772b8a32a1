//! Host side of the project: independent `f64` reference models, the simulations and
//! analyses the tests and the `piezo` command line share.
//!
//! The control maths itself lives in `model-core`; this crate calls it and checks it. The
//! command line (`src/bin/piezo/`, one file per verb) only parses arguments, calls the
//! library and prints; the library never sees clap and never imports a verb
//! (`tests/layout.rs` checks both, and that the modules below import each other without a
//! cycle).
//!
//! # Module map
//! | module | what | uses |
//! |---|---|---|
//! | [`io`] | records (CSV, MATLAB `.mat`) and the TOML model file | |
//! | [`sim`] | the loop on the host, open-loop runs, loop figures, tracking, synthetic records | `io`, `identify` |
//! | [`oracle`] | independent `f64` models of every block, another form than model-core's | |
//! | [`identify`] | drift and hysteresis identification, and writing them into a model file | `io` |
//! | [`gap`] | the model-gap workflow: catalogue, fits, selection, report | `io`, `sim`, `util` |
//! | [`board`] | the serial link to the board and the capture receiver | |
//! | [`qemu`] | the control code under QEMU: runs, scenarios, budget, reference vectors | `oracle`, `util` |
//! | [`util`] | workspace root, thread pool, median, golden section | |
//! | [`testing`] | float comparisons for tests | |

pub mod board;
pub mod gap;
pub mod identify;
pub mod io;
pub mod oracle;
pub mod qemu;
pub mod sim;
pub mod testing;
pub mod util;
