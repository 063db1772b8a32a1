//! The closed-loop scenarios of `model_core::scenarios`, run on the Cortex-M: prints every
//! scenario's figures (f32 as IEEE bits) over defmt, checks them, exits 0 if every check
//! passed and 1 otherwise. The host (`piezo qemu scenarios`) runs the same scenarios and
//! compares the figures bit for bit.
//!
//! Output lines (one per figure): `CPU <part>`, `FIG <scenario> <field> <u32>`,
//! `CHECK <scenario> ok` or `CHECK <scenario> FAIL <reason>`, `STACK scenarios <bytes>` (the
//! stack the scenarios needed, configuration included), `DONE <failures>`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod image {
    use model_core::scenarios::{Scenario, run};
    use piezo_qemu::{EXIT_FAIL, EXIT_PASS, StackProbe, cpu_part, exit};

    #[cortex_m_rt::entry]
    fn main() -> ! {
        defmt::println!("CPU {=u32}", cpu_part());
        let probe = StackProbe::paint();
        let mut failures = 0u32;
        for s in Scenario::ALL {
            match run(s) {
                Ok((controller, figures)) => {
                    for (name, bits) in figures.fields() {
                        defmt::println!("FIG {=str} {=str} {=u32}", s.name(), name, bits);
                    }
                    match figures.check(s, &controller) {
                        Ok(()) => defmt::println!("CHECK {=str} ok", s.name()),
                        Err(why) => {
                            failures += 1;
                            defmt::println!("CHECK {=str} FAIL {=str}", s.name(), why);
                        }
                    }
                }
                Err(_) => {
                    failures += 1;
                    defmt::println!("CHECK {=str} FAIL the configuration was refused", s.name());
                }
            }
        }
        defmt::println!("STACK scenarios {=u32}", probe.used_bytes());
        defmt::println!("DONE {=u32}", failures);
        exit(if failures == 0 { EXIT_PASS } else { EXIT_FAIL })
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("this image runs on QEMU: cargo run -p host-tests --bin piezo -- qemu scenarios");
}
