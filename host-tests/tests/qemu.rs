//! The control code on a Cortex-M under QEMU, on both machines (mps2-an386 Cortex-M4F,
//! mps2-an500 Cortex-M7): the closed-loop scenarios must pass their checks on the target and
//! agree bit for bit with the host's run of the same code, and the on-target defmt-test suite
//! must pass. Needs `qemu-system-arm` and `defmt-print`: without them these tests FAIL (they
//! never skip), saying how to install them.
use host_tests::qemu::{self, MACHINES};

#[test]
fn scenarios_on_qemu_match_the_host_bit_for_bit() {
    if let Err(e) = qemu::check_tools() {
        panic!("{e}");
    }
    for machine in MACHINES {
        let report = qemu::scenarios_on(machine).unwrap_or_else(|e| panic!("{e:#}"));
        println!("{}", report.table());
        assert!(report.passed(), "{}", report.table());
    }
}

#[test]
fn on_target_tests_pass_on_qemu() {
    if let Err(e) = qemu::check_tools() {
        panic!("{e}");
    }
    for machine in MACHINES {
        let run = qemu::on_target_tests(machine).unwrap_or_else(|e| panic!("{e:#}"));
        for l in &run.output.lines {
            println!("{}: {l}", machine.machine);
        }
        println!(
            "{}: {} on-target tests passed in {:.2} s",
            machine.machine,
            run.passed,
            run.output.elapsed.as_secs_f64()
        );
        assert!(run.passed > 0, "no test ran");
    }
}
