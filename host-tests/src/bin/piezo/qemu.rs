//! `piezo qemu scenarios|test|bench|vectors`: the control code on a Cortex-M under QEMU
//! ([`host_tests::qemu`]).

use anyhow::{Result, bail};
use host_tests::qemu::bench::STEP_BUDGET_DEFECT;
use host_tests::qemu::{
    MACHINES, Machine, bench_on, bench_table, on_target_tests, scenarios_on, vectors,
};

/// Which machines to run on.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum MachineChoice {
    /// mps2-an386, Cortex-M4F.
    An386,
    /// mps2-an500, Cortex-M7.
    An500,
    /// Both.
    #[default]
    Both,
}

impl MachineChoice {
    fn machines(self) -> &'static [Machine] {
        match self {
            Self::An386 => &MACHINES[..1],
            Self::An500 => &MACHINES[1..],
            Self::Both => &MACHINES,
        }
    }
}

/// `piezo qemu`.
#[derive(clap::Args, Debug)]
pub struct QemuArgs {
    /// What to run.
    #[command(subcommand)]
    pub what: QemuCommand,
}

/// The `piezo qemu` sub-commands.
#[derive(clap::Subcommand, Debug)]
pub enum QemuCommand {
    /// Run the closed-loop scenarios on QEMU and compare them with the host, bit for bit.
    Scenarios(MachineArgs),
    /// Run the on-target defmt-test suite of model-core on QEMU.
    Test(MachineArgs),
    /// Print the instructions per control step and per block.
    Bench(BenchArgs),
    /// Check (or with `--write`, regenerate) the on-target tests' reference vectors.
    Vectors(VectorsArgs),
}

/// `piezo qemu bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Machine(s) to run on.
    #[arg(long, value_enum, default_value_t = MachineChoice::Both)]
    pub machine: MachineChoice,
    /// Exit with an error when the control step exceeds the 500-instruction defect line.
    #[arg(long)]
    pub enforce: bool,
}

/// `piezo qemu vectors`.
#[derive(clap::Args, Debug)]
pub struct VectorsArgs {
    /// Write the file instead of checking it.
    #[arg(long)]
    pub write: bool,
}

/// Machine selection.
#[derive(clap::Args, Debug)]
pub struct MachineArgs {
    /// Machine(s) to run on.
    #[arg(long, value_enum, default_value_t = MachineChoice::Both)]
    pub machine: MachineChoice,
}

/// Run the verb.
pub fn run(args: &QemuArgs) -> Result<()> {
    match &args.what {
        QemuCommand::Scenarios(m) => {
            let mut failed = false;
            for &machine in m.machine.machines() {
                let report = scenarios_on(machine)?;
                print!("{}", report.table());
                failed |= !report.passed();
            }
            if failed {
                bail!("a QEMU scenario failed or differed from the host");
            }
            Ok(())
        }
        QemuCommand::Test(m) => {
            for &machine in m.machine.machines() {
                let out = on_target_tests(machine)?;
                for l in &out.output.lines {
                    println!("{}: {l}", machine.machine);
                }
                println!("{}: {} on-target tests passed", machine.machine, out.passed);
            }
            Ok(())
        }
        QemuCommand::Bench(m) => {
            let benches = m
                .machine
                .machines()
                .iter()
                .map(|&machine| bench_on(machine))
                .collect::<Result<Vec<_>>>()?;
            print!("{}", bench_table(&benches));
            for b in benches.iter().filter(|_| m.enforce) {
                let step = b.get("controller_step").unwrap_or(f64::NAN);
                if step.is_nan() || step > STEP_BUDGET_DEFECT {
                    bail!(
                        "{}: the control step takes {step:.1} instructions, more than {STEP_BUDGET_DEFECT}",
                        b.machine.machine
                    );
                }
            }
            Ok(())
        }
        QemuCommand::Vectors(v) => {
            if v.write {
                println!("wrote {}", vectors::write()?.display());
            } else {
                println!("{} is current", vectors::check()?.display());
            }
            Ok(())
        }
    }
}
