//! The control code on a Cortex-M, under QEMU (issue #6): the library half of `piezo qemu`.
//!
//! Builds the images of `firmware/qemu` for `thumbv7em-none-eabihf` (release, in a separate
//! target directory so that a build started from inside `cargo test` never waits on the
//! outer cargo's lock), runs them on `qemu-system-arm` on both machines,
//!
//! | machine | CPU |
//! |---|---|
//! | `mps2-an386` | Cortex-M4F (`-cpu cortex-m4`) |
//! | `mps2-an500` | Cortex-M7 (`-cpu cortex-m7`) |
//!
//! with `-nographic -semihosting-config enable=on,target=native -icount shift=0` under a
//! timeout, decodes the defmt stream that semihosting carries to QEMU's stdout with
//! `defmt-print -e ELF`, and checks:
//!
//! * `scenarios`: every scenario of `model_core::scenarios` passes its checks on the target
//!   (window, slew, fault latch, safe ramp) *and* its figures equal, bit for bit, those of the
//!   same function run on the host (`f32` on both sides, no fused multiply-add, no library
//!   maths: IEEE arithmetic gives the same bits);
//! * `test`: the defmt-test suite `firmware/qemu/tests/on_target.rs` passes;
//! * `bench`: prints the instructions per call of the control step and of each block.
//!
//! QEMU's exit status is the image's semihosting exit code (0 pass, 1 a check failed, 101 a
//! panic, 102 a HardFault); a run that does not end within the timeout is killed and fails.
//! The image also reports its CPUID part number, checked against the machine asked for.
//!
//! * [`run`]: tools, builds and one QEMU run, the on-target suite;
//! * [`scenarios`]: the scenario image's figures against the host's;
//! * [`mod@bench`]: the instruction budget;
//! * [`vectors`]: the on-target tests' reference vectors from the [`crate::oracle`] models.

pub mod bench;
pub mod run;
pub mod scenarios;
pub mod vectors;

pub use bench::{Bench, BenchRow, bench_on, bench_table};
pub use run::{
    AN386, AN500, MACHINES, Machine, RunOutput, TestRun, check_tools, on_target_tests, run_image,
};
pub use scenarios::{ScenarioOutcome, ScenarioReport, scenarios_on};
