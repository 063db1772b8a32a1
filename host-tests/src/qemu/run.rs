//! Building the QEMU images, running one on a machine under a timeout and decoding its defmt
//! output; the on-target defmt-test suite (see [`super`] for the whole picture).

use crate::util::workspace_root;
use anyhow::{Context, Result, anyhow, bail};
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

/// Longest timeout `PIEZO_QEMU_TIMEOUT_S` may ask for, seconds (our assumption: a day; a
/// run that needs more is hung).
pub const MAX_RUN_TIMEOUT_S: f64 = 86_400.0;

/// [`RUN_TIMEOUT`] or `$PIEZO_QEMU_TIMEOUT_S` (seconds, may be fractional, in
/// (0, [`MAX_RUN_TIMEOUT_S`]]); a value that is not such a number is an error that says so.
pub fn run_timeout() -> Result<Duration> {
    match std::env::var("PIEZO_QEMU_TIMEOUT_S") {
        Err(_) => Ok(RUN_TIMEOUT),
        Ok(text) => timeout_from(&text),
    }
}

/// The timeout `PIEZO_QEMU_TIMEOUT_S=text` asks for.
fn timeout_from(text: &str) -> Result<Duration> {
    let s: f64 = text
        .trim()
        .parse()
        .map_err(|_| anyhow::anyhow!("PIEZO_QEMU_TIMEOUT_S=`{text}` is not a number of seconds"))?;
    if !(s > 0.0 && s <= MAX_RUN_TIMEOUT_S) {
        bail!(
            "PIEZO_QEMU_TIMEOUT_S={text} is outside (0, {MAX_RUN_TIMEOUT_S}] seconds; unset it for the default {} s",
            RUN_TIMEOUT.as_secs()
        );
    }
    Ok(Duration::from_secs_f64(s))
}

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
    /// The exit status, the output's last lines and QEMU's stderr, for error messages.
    pub fn fail_context(&self) -> String {
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
    let timeout = run_timeout()?;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every value of `PIEZO_QEMU_TIMEOUT_S` is answered: a time in range is taken, anything
    /// else (not a number, zero, negative, NaN, infinite, 1e308 that `Duration` cannot hold)
    /// is an error naming the variable, never a panic.
    #[test]
    fn timeout_variable_is_checked() {
        assert_eq!(timeout_from("2.5").unwrap(), Duration::from_millis(2500));
        assert_eq!(
            timeout_from(" 86400 ").unwrap(),
            Duration::from_secs(86_400)
        );
        for bad in [
            "",
            "abc",
            "0",
            "-1",
            "nan",
            "inf",
            "1e308",
            "86400.5",
            "18446744073709551616",
        ] {
            let e = timeout_from(bad).expect_err(bad).to_string();
            assert!(e.contains("PIEZO_QEMU_TIMEOUT_S"), "{bad}: {e}");
        }
    }
}
