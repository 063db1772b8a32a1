//! The instruction budget: the bench image's SysTick counts per call of the control step and of
//! each block, under `-icount shift=0`, as instructions.

use crate::qemu::run::{Machine, RunOutput, build_bin, check_tools, run_image};
use anyhow::{Context, Result, bail};

/// Instructions per SysTick tick under `-icount shift=0` on the mps2 machines (1 ns per
/// instruction, SysTick at 25 MHz); checked by the bench's calibration block.
pub const INSTRUCTIONS_PER_TICK: f64 = 40.0;
/// Goal for the whole control step, instructions (our assumption: under 1 us at the board's
/// 400 MHz even at one instruction per cycle, 5 % of the 20 us period).
pub const STEP_BUDGET_GOAL: f64 = 300.0;
/// Above this the control step is a defect.
pub const STEP_BUDGET_DEFECT: f64 = 500.0;

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
        "controller_step_learning" => {
            "the same with the learning's read-and-add and error record (`learning::correction`, `step_with_correction`, `learning::record`)"
        }
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
    use crate::qemu::run::AN386;
    use std::time::Duration;

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
