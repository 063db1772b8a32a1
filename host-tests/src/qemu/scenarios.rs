//! The scenario image: every scenario of `model_core::scenarios` run on the target, its checks
//! and its figures compared bit for bit with the same function run on the host.

use crate::qemu::run::{Machine, RunOutput, build_bin, check_tools, run_image};
use anyhow::{Context, Result, anyhow, bail};
use model_core::scenarios::{self, Figures, Scenario};
use std::time::Duration;

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::qemu::run::AN386;

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
}
