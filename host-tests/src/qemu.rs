//! `piezo qemu`: the control code on a Cortex-M, under QEMU (issue #6).
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

use anyhow::{Context, Result, anyhow, bail};
use model_core::scenarios::{self, Figures, Scenario};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The embedded target.
pub const TARGET: &str = "thumbv7em-none-eabihf";
/// The package of the QEMU images.
pub const PACKAGE: &str = "piezo-qemu";
/// Longest a QEMU run may take before it is killed as hung, unless `PIEZO_QEMU_TIMEOUT_S`
/// says otherwise. The images take well under a second of host time; the margin covers a
/// loaded CI machine.
pub const RUN_TIMEOUT: Duration = Duration::from_secs(120);

/// [`RUN_TIMEOUT`] or `$PIEZO_QEMU_TIMEOUT_S` (seconds, may be fractional).
pub fn run_timeout() -> Duration {
    std::env::var("PIEZO_QEMU_TIMEOUT_S")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s > 0.0)
        .map(Duration::from_secs_f64)
        .unwrap_or(RUN_TIMEOUT)
}
/// Instructions per SysTick tick under `-icount shift=0` on the mps2 machines (1 ns per
/// instruction, SysTick at 25 MHz); checked by the bench's calibration block.
pub const INSTRUCTIONS_PER_TICK: f64 = 40.0;
/// Goal for the whole control step, instructions (1 us at 480 MHz, 5 % of the 20 us period).
pub const STEP_BUDGET_GOAL: f64 = 300.0;
/// Above this the control step is a defect.
pub const STEP_BUDGET_DEFECT: f64 = 500.0;

/// How to install what the runs need, for error messages.
pub const INSTALL_HINT: &str = "install them with `sudo apt-get install qemu-system-arm` and \
     `cargo install defmt-print --locked` (and `rustup target add thumbv7em-none-eabihf`); \
     `.ci/run` does all three";

/// A QEMU machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Machine {
    /// `-machine` value.
    pub machine: &'static str,
    /// `-cpu` value.
    pub cpu: &'static str,
    /// CPUID part number the image must report.
    pub part: u32,
}

/// Cortex-M4F.
pub const AN386: Machine = Machine {
    machine: "mps2-an386",
    cpu: "cortex-m4",
    part: 0xC24,
};
/// Cortex-M7.
pub const AN500: Machine = Machine {
    machine: "mps2-an500",
    cpu: "cortex-m7",
    part: 0xC27,
};
/// Both machines.
pub const MACHINES: [Machine; 2] = [AN386, AN500];

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
        QemuCommand::Vectors(v) => crate::qemu_vectors::write_or_check(v.write),
    }
}

/// Fails, saying how to install them, if `qemu-system-arm` or `defmt-print` is missing.
pub fn check_tools() -> Result<()> {
    for (tool, arg) in [
        ("qemu-system-arm", "--version"),
        ("defmt-print", "--version"),
    ] {
        let ok = Command::new(tool)
            .arg(arg)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .map(|s| s.success())
            .unwrap_or(false);
        if !ok {
            bail!("`{tool}` is not installed or does not run: {INSTALL_HINT}");
        }
    }
    Ok(())
}

/// The workspace root (the parent of host-tests).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

/// Where the images are built: `$PIEZO_QEMU_TARGET_DIR`, else `qemu/` inside
/// `$CARGO_TARGET_DIR` or the workspace's `target/`. Never the outer cargo's own directory.
pub fn target_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("PIEZO_QEMU_TARGET_DIR") {
        return PathBuf::from(d);
    }
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("target"))
        .join("qemu")
}

fn cargo() -> Command {
    let mut c = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    // From the QEMU workspace's own directory, so the linker picks up its memory.x.
    c.current_dir(workspace_root().join("firmware").join("qemu"))
        .env_remove("CARGO_TARGET_DIR")
        .env_remove("CARGO_BUILD_TARGET")
        .env_remove("RUSTFLAGS")
        .env_remove("CARGO_ENCODED_RUSTFLAGS");
    c
}

fn run_cargo(mut c: Command, what: &str) -> Result<String> {
    let out = c
        .stderr(Stdio::inherit())
        .output()
        .with_context(|| format!("running cargo to build {what}"))?;
    if !out.status.success() {
        bail!(
            "building {what} failed ({}); is the target installed? \
             `rustup target add {TARGET}`",
            out.status
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Build a binary of the QEMU package; returns the ELF's path.
pub fn build_bin(bin: &str) -> Result<PathBuf> {
    let dir = target_dir();
    let mut c = cargo();
    c.args([
        "build",
        "--release",
        "--quiet",
        "--target",
        TARGET,
        "-p",
        PACKAGE,
        "--bin",
        bin,
    ])
    .arg("--target-dir")
    .arg(&dir);
    run_cargo(c, &format!("the `{bin}` image"))?;
    let elf = dir.join(TARGET).join("release").join(bin);
    if !elf.is_file() {
        bail!("the build left no image at {}", elf.display());
    }
    Ok(elf)
}

/// Build the on-target test suite; returns the ELF's path.
pub fn build_tests() -> Result<PathBuf> {
    let mut c = cargo();
    c.args([
        "test",
        "--release",
        "--no-run",
        "--quiet",
        "--message-format=json-render-diagnostics",
        "--target",
        TARGET,
        "-p",
        PACKAGE,
        "--test",
        "on_target",
    ])
    .arg("--target-dir")
    .arg(target_dir());
    let json = run_cargo(c, "the on-target tests")?;
    json.lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v["reason"] == "compiler-artifact" && v["profile"]["test"] == true)
        .find_map(|v| v["executable"].as_str().map(PathBuf::from))
        .ok_or_else(|| anyhow!("cargo reported no test executable"))
}

/// What a QEMU run printed and how it ended.
#[derive(Clone, Debug)]
pub struct RunOutput {
    /// Decoded defmt lines.
    pub lines: Vec<String>,
    /// QEMU's exit status (the image's semihosting exit code); `None` if killed.
    pub status: Option<i32>,
    /// Host time the run took.
    pub elapsed: Duration,
    /// QEMU's own stderr.
    pub stderr: String,
}

impl RunOutput {
    fn fail_context(&self) -> String {
        let tail: Vec<&str> = self
            .lines
            .iter()
            .rev()
            .take(15)
            .rev()
            .map(String::as_str)
            .collect();
        format!(
            "exit status {:?}; last output:\n{}\nqemu stderr:\n{}",
            self.status,
            tail.join("\n"),
            self.stderr.trim()
        )
    }

    /// The stack high-water mark the image printed as `STACK <name> <bytes>`.
    pub fn stack_bytes(&self, name: &str) -> Option<u32> {
        self.lines.iter().find_map(|l| {
            let mut w = l.split_whitespace().skip_while(|w| *w != "STACK");
            w.next()?;
            (w.next()? == name).then_some(())?;
            w.next()?.parse().ok()
        })
    }

    /// The CPUID part number the image printed (`CPU <n>`).
    pub fn cpu_part(&self) -> Option<u32> {
        self.lines
            .iter()
            .find_map(|l| l.trim().strip_prefix("CPU ")?.trim().parse().ok())
    }
}

/// Run `elf` on `machine` under the timeout, decode its defmt output.
pub fn run_image(machine: Machine, elf: &Path) -> Result<RunOutput> {
    check_tools()?;
    let timeout = run_timeout();
    let start = Instant::now();
    let mut qemu = Command::new("qemu-system-arm")
        .args([
            "-machine",
            machine.machine,
            "-cpu",
            machine.cpu,
            "-nographic",
        ])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", "shift=0", "-kernel"])
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context("starting qemu-system-arm")?;
    let qemu_out = qemu.stdout.take().context("qemu stdout")?;
    let mut qemu_err = qemu.stderr.take().context("qemu stderr")?;
    let mut decoder = Command::new("defmt-print")
        .arg("-e")
        .arg(elf)
        .arg("--log-format")
        .arg("{L} {s}")
        .stdin(Stdio::from(qemu_out))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .context("starting defmt-print")?;
    let mut dec_out = decoder.stdout.take().context("defmt-print stdout")?;
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = dec_out.read_to_string(&mut s);
        s
    });
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = qemu_err.read_to_string(&mut s);
        s
    });
    let status = loop {
        if let Some(st) = qemu.try_wait().context("waiting for qemu")? {
            break st.code();
        }
        if start.elapsed() > timeout {
            let _ = qemu.kill();
            let _ = qemu.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let _ = decoder.wait();
    let text = reader.join().unwrap_or_default();
    let stderr = err_reader.join().unwrap_or_default();
    let out = RunOutput {
        lines: text.lines().map(str::to_owned).collect(),
        status,
        elapsed: start.elapsed(),
        stderr,
    };
    if status.is_none() {
        bail!(
            "{} hung: killed after {:?}; {}",
            machine.machine,
            timeout,
            out.fail_context()
        );
    }
    match out.cpu_part() {
        Some(p) if p == machine.part => {}
        other => bail!(
            "{}: the image reported CPU part {other:?}, expected {:#x}; {}",
            machine.machine,
            machine.part,
            out.fail_context()
        ),
    }
    Ok(out)
}

/// One scenario's outcome on one machine.
#[derive(Clone, Debug)]
pub struct ScenarioOutcome {
    /// The scenario.
    pub scenario: Scenario,
    /// Figures the target printed, in `Figures::fields` order.
    pub target: Vec<(String, u32)>,
    /// The host's figures.
    pub host: Figures,
    /// The target's own check: `Ok` or the reason it gave.
    pub target_check: Result<(), String>,
    /// The host's check of its own figures.
    pub host_check: Result<(), &'static str>,
    /// Fields whose bits differ: `(name, target, host)`.
    pub mismatches: Vec<(String, u32, u32)>,
}

/// The scenarios on one machine.
#[derive(Clone, Debug)]
pub struct ScenarioReport {
    /// The machine.
    pub machine: Machine,
    /// Per scenario.
    pub outcomes: Vec<ScenarioOutcome>,
    /// QEMU's exit status.
    pub status: Option<i32>,
    /// Host time of the QEMU run.
    pub elapsed: Duration,
    /// Stack the scenarios needed on the target, bytes (configuration included).
    pub stack_bytes: Option<u32>,
}

impl ScenarioReport {
    /// Everything passed and agreed.
    pub fn passed(&self) -> bool {
        self.status == Some(0)
            && self.outcomes.len() == Scenario::ALL.len()
            && self
                .outcomes
                .iter()
                .all(|o| o.target_check.is_ok() && o.host_check.is_ok() && o.mismatches.is_empty())
    }

    /// A readable table.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{} ({}), QEMU exit {:?}, {:.2} s host time, stack {} bytes; figures compared bit for bit with the host\n",
            self.machine.machine,
            self.machine.cpu,
            self.status,
            self.elapsed.as_secs_f64(),
            self.stack_bytes.map_or("?".to_string(), |b| b.to_string())
        );
        s += "| scenario | RMS err V | peak err V | final y V | final u V | max du V | faults | latched at | safe at | QEMU check | host == QEMU |\n";
        s += "|---|---|---|---|---|---|---|---|---|---|---|\n";
        let idx = |v: u32| {
            if v == scenarios::NEVER {
                "-".to_string()
            } else {
                v.to_string()
            }
        };
        for o in &self.outcomes {
            let f = &o.host;
            let agree = if o.mismatches.is_empty() {
                "bit-exact".to_string()
            } else {
                let names: Vec<String> = o
                    .mismatches
                    .iter()
                    .map(|(n, t, h)| format!("{n} {}", describe_diff(n, *t, *h)))
                    .collect();
                format!("DIFFERS: {}", names.join("; "))
            };
            s += &format!(
                "| {} | {:.4e} | {:.4e} | {:.5} | {:.5} | {:.4} | {:#04x} | {} | {} | {} | {} |\n",
                o.scenario.name(),
                f.rms_err_v(),
                f.peak_err_v,
                f.final_output_v,
                f.final_command_v,
                f.max_slew_v,
                f.faults,
                idx(f.fault_latched_at),
                idx(f.safe_reached_at),
                match &o.target_check {
                    Ok(()) => "ok".to_string(),
                    Err(e) => format!("FAIL: {e}"),
                },
                agree
            );
        }
        s
    }
}

fn describe_diff(name: &str, t: u32, h: u32) -> String {
    if Figures::is_f32_field(name) {
        let (ft, fh) = (f32::from_bits(t), f32::from_bits(h));
        let ulps = (t as i64 - h as i64).abs();
        format!("qemu {ft:e} host {fh:e} ({ulps} ulp)")
    } else {
        format!("qemu {t} host {h}")
    }
}

/// Parse the scenario image's output into per-scenario figures and checks.
pub fn parse_scenarios(out: &RunOutput) -> Result<Vec<ScenarioOutcome>> {
    let mut outcomes = Vec::new();
    for s in Scenario::ALL {
        let (controller, host) =
            scenarios::run(s).map_err(|e| anyhow!("host scenario {}: {e}", s.name()))?;
        let mut target = Vec::new();
        let mut target_check = Err("the image printed no check".to_string());
        for l in &out.lines {
            let mut w = l
                .split_whitespace()
                .skip_while(|w| *w != "FIG" && *w != "CHECK");
            match (w.next(), w.next()) {
                (Some("FIG"), Some(name)) if name == s.name() => {
                    if let (Some(field), Some(v)) = (w.next(), w.next()) {
                        let v: u32 = v
                            .parse()
                            .with_context(|| format!("bad figure line `{l}`"))?;
                        target.push((field.to_string(), v));
                    }
                }
                (Some("CHECK"), Some(name)) if name == s.name() => {
                    let rest: Vec<&str> = w.collect();
                    target_check = match rest.first() {
                        Some(&"ok") => Ok(()),
                        _ => Err(rest.get(1..).unwrap_or_default().join(" ")),
                    };
                }
                _ => {}
            }
        }
        let host_fields = host.fields();
        let mut mismatches = Vec::new();
        if target.len() != host_fields.len() {
            mismatches.push((
                "figure count".to_string(),
                target.len() as u32,
                host_fields.len() as u32,
            ));
        }
        for ((tn, tv), (hn, hv)) in target.iter().zip(host_fields.iter()) {
            if tn != hn || tv != hv {
                mismatches.push((tn.clone(), *tv, *hv));
            }
        }
        outcomes.push(ScenarioOutcome {
            scenario: s,
            target,
            host_check: host.check(s, &controller),
            host,
            target_check,
            mismatches,
        });
    }
    Ok(outcomes)
}

/// Build and run the scenario image on `machine`, compare with the host.
pub fn scenarios_on(machine: Machine) -> Result<ScenarioReport> {
    check_tools()?;
    let elf = build_bin("scenarios")?;
    let out = run_image(machine, &elf)?;
    let outcomes = parse_scenarios(&out)?;
    let report = ScenarioReport {
        machine,
        outcomes,
        status: out.status,
        elapsed: out.elapsed,
        stack_bytes: out.stack_bytes("scenarios"),
    };
    if report.outcomes.iter().all(|o| o.target.is_empty()) {
        bail!(
            "{}: no figures in the output; {}",
            machine.machine,
            out.fail_context()
        );
    }
    Ok(report)
}

/// The on-target suite's result.
#[derive(Clone, Debug)]
pub struct TestRun {
    /// Tests that ran (defmt-test stops at the first failure, so all of them passed).
    pub passed: usize,
    /// The run.
    pub output: RunOutput,
}

/// Build and run the defmt-test suite on `machine`; an error if any test failed.
pub fn on_target_tests(machine: Machine) -> Result<TestRun> {
    check_tools()?;
    let elf = build_tests()?;
    let output = run_image(machine, &elf)?;
    let passed = output
        .lines
        .iter()
        .filter(|l| l.contains(" running `"))
        .count();
    let all = output.lines.iter().any(|l| l.contains("all tests passed"));
    if output.status != Some(0) || !all {
        bail!(
            "{}: on-target tests failed; {}",
            machine.machine,
            output.fail_context()
        );
    }
    Ok(TestRun { passed, output })
}

/// One row of the instruction budget.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchRow {
    /// Block name.
    pub name: String,
    /// Instructions per call, the empty loop subtracted.
    pub instructions: f64,
}

/// The instruction budget on one machine.
#[derive(Clone, Debug)]
pub struct Bench {
    /// The machine.
    pub machine: Machine,
    /// Ticks the 4000-instruction calibration block took.
    pub calibration_ticks: u32,
    /// Instructions of the calibration block.
    pub calibration_instructions: u32,
    /// Per block.
    pub rows: Vec<BenchRow>,
    /// Stack one control step needs, bytes.
    pub step_stack_bytes: Option<u32>,
}

impl Bench {
    /// Instructions per call of `name`.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.rows
            .iter()
            .find(|r| r.name == name)
            .map(|r| r.instructions)
    }

    /// A readable table.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{} ({}): instructions per call (QEMU -icount shift=0, SysTick, calibration {} ticks for {} nops)\n",
            self.machine.machine,
            self.machine.cpu,
            self.calibration_ticks,
            self.calibration_instructions
        );
        s += "| block | instructions |\n|---|---|\n";
        for r in &self.rows {
            let note = if r.name == "controller_step" {
                if r.instructions > STEP_BUDGET_DEFECT {
                    " DEFECT (> 500)"
                } else if r.instructions > STEP_BUDGET_GOAL {
                    " over the 300 goal"
                } else {
                    " (goal <= 300)"
                }
            } else {
                ""
            };
            s += &format!("| {} | {:.1}{} |\n", r.name, r.instructions, note);
        }
        s
    }
}

/// What each bench row measures.
pub fn bench_description(name: &str) -> &'static str {
    match name {
        "controller_step" => {
            "`Controller::step`, closed loop, on-board generator + pre-filter: ADC code to DAC code (the ISR's maths)"
        }
        "controller_step_hysteresis_ff" => "the same with hysteresis feedforward on",
        "controller_step_external_no_prefilter" => {
            "`Controller::step`, external reference, pre-filter off"
        }
        "controller_step_faulted" => "`Controller::step` with a latched fault (safe ramp)",
        "lag_update" => "`LagCompensator::update_flags` (with its limits)",
        "limits_apply" => "`OutputLimits::apply` (NaN guard, slew, window)",
        "adc_to_volts" => "`AdcCode::volts`",
        "dac_from_volts" => "`DacCode::from_volts`",
        "plant_step" => "`LinearPlant::step` (simulation only, not in the ISR)",
        "prefilter_step" => "`PreFilter::step` (full pre-filter, default tau)",
        "reference_sine" => "`ReferenceGenerator::next`, sine",
        "reference_triangle" => "`ReferenceGenerator::next`, triangle",
        "stage_step" => "`Stage::step`, ch. 6 model (simulation only, not in the ISR)",
        "hysteresis_forward" => "`HysteresisTable::forward`",
        "hysteresis_inverse" => "`HysteresisTable::inverse` (feedforward)",
        _ => "",
    }
}

/// The instruction table of one or more machines, side by side.
pub fn bench_table(benches: &[Bench]) -> String {
    let mut s = String::from(
        "Instructions per call on thumbv7em-none-eabihf (QEMU -icount shift=0, SysTick over 1000 calls, empty loop subtracted)\n",
    );
    s += "| block |";
    for b in benches {
        s += &format!(" {} ({}) |", b.machine.machine, b.machine.cpu);
    }
    s += " what |\n|---|";
    for _ in benches {
        s += "---|";
    }
    s += "---|\n";
    let Some(first) = benches.first() else {
        return s;
    };
    for r in &first.rows {
        s += &format!("| {} |", r.name);
        for b in benches {
            s += &format!(" {:.1} |", b.get(&r.name).unwrap_or(f64::NAN));
        }
        s += &format!(" {} |\n", bench_description(&r.name));
    }
    s += "| stack of `Controller::step`, bytes |";
    for b in benches {
        s += &format!(
            " {} |",
            b.step_stack_bytes
                .map_or("?".to_string(), |v| v.to_string())
        );
    }
    s += " painted below the caller's frame |\n";
    let step = first.get("controller_step").unwrap_or(f64::NAN);
    s += &format!(
        "Whole step: {step:.1} instructions (goal <= {STEP_BUDGET_GOAL}, defect > {STEP_BUDGET_DEFECT}){}\n",
        if step <= STEP_BUDGET_GOAL {
            ": within the goal"
        } else if step <= STEP_BUDGET_DEFECT {
            ": OVER THE GOAL"
        } else {
            ": DEFECT"
        }
    );
    s
}

/// Build and run the bench image on `machine`.
pub fn bench_on(machine: Machine) -> Result<Bench> {
    check_tools()?;
    let elf = build_bin("bench")?;
    let out = run_image(machine, &elf)?;
    if out.status != Some(0) {
        bail!(
            "{}: the bench failed; {}",
            machine.machine,
            out.fail_context()
        );
    }
    parse_bench(machine, &out)
}

/// Parse `CAL` and `BENCH` lines.
pub fn parse_bench(machine: Machine, out: &RunOutput) -> Result<Bench> {
    let mut cal = None;
    let mut raw: Vec<(String, u32, u32)> = Vec::new();
    for l in &out.lines {
        let mut w = l
            .split_whitespace()
            .skip_while(|w| *w != "BENCH" && *w != "CAL");
        match w.next() {
            Some("CAL") => {
                let t: u32 = w.next().context("CAL ticks")?.parse()?;
                let n: u32 = w.next().context("CAL count")?.parse()?;
                cal = Some((t, n));
            }
            Some("BENCH") => {
                let name = w.next().context("BENCH name")?.to_string();
                let t: u32 = w.next().context("BENCH ticks")?.parse()?;
                let n: u32 = w.next().context("BENCH calls")?.parse()?;
                raw.push((name, t, n));
            }
            _ => {}
        }
    }
    let (ct, cn) = cal.context("no calibration line")?;
    if (ct as f64 * INSTRUCTIONS_PER_TICK - cn as f64).abs() > INSTRUCTIONS_PER_TICK {
        bail!(
            "calibration: {cn} instructions took {ct} ticks, not {INSTRUCTIONS_PER_TICK} \
             instructions per tick: is QEMU run with -icount shift=0?"
        );
    }
    let (_, ot, on) = raw
        .iter()
        .find(|(n, _, _)| n == "overhead")
        .cloned()
        .context("no overhead line")?;
    let per_call = |t: u32, n: u32| t as f64 * INSTRUCTIONS_PER_TICK / n.max(1) as f64;
    let base = per_call(ot, on);
    let rows = raw
        .iter()
        .filter(|(n, _, _)| n != "overhead")
        .map(|(n, t, c)| BenchRow {
            name: n.clone(),
            instructions: per_call(*t, *c) - base,
        })
        .collect();
    Ok(Bench {
        machine,
        calibration_ticks: ct,
        calibration_instructions: cn,
        rows,
        step_stack_bytes: out.stack_bytes("controller_step"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn output_of(s: Scenario, tweak: Option<&str>) -> RunOutput {
        let (_, f) = scenarios::run(s).unwrap();
        let mut lines = vec!["CPU 3108".to_string()];
        for (name, bits) in f.fields() {
            let bits = if Some(name) == tweak { bits ^ 1 } else { bits };
            lines.push(format!("FIG {} {name} {bits}", s.name()));
        }
        lines.push(format!("CHECK {} ok", s.name()));
        RunOutput {
            lines,
            status: Some(0),
            elapsed: Duration::ZERO,
            stderr: String::new(),
        }
    }

    #[test]
    fn one_flipped_bit_is_a_mismatch() {
        let good = parse_scenarios(&output_of(Scenario::Step, None)).unwrap();
        let step = good.iter().find(|o| o.scenario == Scenario::Step).unwrap();
        assert!(step.mismatches.is_empty(), "{:?}", step.mismatches);
        assert_eq!(step.target_check, Ok(()));
        let bad = parse_scenarios(&output_of(Scenario::Step, Some("final_output_v"))).unwrap();
        let step = bad.iter().find(|o| o.scenario == Scenario::Step).unwrap();
        println!("flipped bit reported as: {:?}", step.mismatches);
        assert_eq!(step.mismatches.len(), 1);
        assert_eq!(step.mismatches[0].0, "final_output_v");
        // Scenarios absent from the output are failures, not passes.
        let report = ScenarioReport {
            machine: AN386,
            outcomes: good,
            status: Some(0),
            elapsed: Duration::ZERO,
            stack_bytes: None,
        };
        assert!(!report.passed());
    }

    #[test]
    fn bench_lines_are_parsed_and_the_tick_size_checked() {
        let lines = [
            "CPU 3108",
            "CAL 100 4000",
            "BENCH overhead 200 1000",
            "BENCH x 450 1000",
        ];
        let mut out = RunOutput {
            lines: lines.iter().map(|s| s.to_string()).collect(),
            status: Some(0),
            elapsed: Duration::ZERO,
            stderr: String::new(),
        };
        let b = parse_bench(AN386, &out).unwrap();
        assert_eq!(b.get("x"), Some(10.0));
        out.lines[1] = "CAL 4000 4000".into();
        assert!(
            parse_bench(AN386, &out).is_err(),
            "no -icount: one tick per instruction"
        );
    }
}
