//! The control code on a Cortex-M under QEMU, on both machines (mps2-an386 Cortex-M4F,
//! mps2-an500 Cortex-M7): the closed-loop scenarios must pass their checks on the target and
//! agree bit for bit with the host's run of the same code, and the on-target defmt-test suite
//! must pass. Needs `qemu-system-arm` and `defmt-print`: without them these tests FAIL (they
//! never skip), saying how to install them.
use host_tests::qemu::{self, MACHINES};
use model_core::closed_loop::{ClosedLoop, LoopPlant};
use model_core::scenarios::{self, FNV_OFFSET, SAMPLES, Scenario, fnv1a};

/// The one closed-loop harness driven as the host tools drive it (a controller in front of a
/// plant adapter, stepped sample by sample, the reference set before each step), with the
/// scenario's controller, plant and reference: the hash of the DAC codes it sends.
fn harness_checksum<P: LoopPlant>(s: Scenario, plant: P) -> u32 {
    let c = scenarios::scenario_controller(s).expect("the scenario's configuration");
    let mut lp = ClosedLoop::new(c, plant);
    lp.close(s.reference_v(0));
    let mut hash = FNV_OFFSET;
    for n in 0..SAMPLES {
        lp.state.set_reference(s.reference_v(n));
        hash = fnv1a(hash, lp.step().sample.dac.offset_binary());
    }
    hash
}

#[test]
fn scenarios_on_qemu_match_the_host_bit_for_bit() {
    if let Err(e) = qemu::check_tools() {
        panic!("{e}");
    }
    for machine in MACHINES {
        let report = qemu::scenarios_on(machine).unwrap_or_else(|e| panic!("{e:#}"));
        println!("{}", report.table());
        assert!(report.passed(), "{}", report.table());
        // The harness's DAC codes equal the image's, bit for bit, for the fault-free loops
        // (the faulted ones inject at the ADC, which only the scenario runner does).
        for o in &report.outcomes {
            let s = o.scenario;
            if s.expected_fault().is_some() || s == Scenario::AbsurdGain {
                continue;
            }
            let harness = if s.on_full_stage() {
                harness_checksum(s, scenarios::full_plant().unwrap())
            } else {
                harness_checksum(s, scenarios::linear_plant().unwrap())
            };
            let target = o
                .target
                .iter()
                .find(|(name, _)| name == "dac_checksum")
                .map(|(_, v)| *v);
            println!(
                "{}: {:<26} DAC code hash: harness {harness:#010x}, QEMU {}",
                machine.machine,
                s.name(),
                target.map_or("none".to_string(), |v| format!("{v:#010x}"))
            );
            assert_eq!(
                Some(harness),
                target,
                "{}: the harness's DAC codes differ from the QEMU scenario {}",
                machine.machine,
                s.name()
            );
        }
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
