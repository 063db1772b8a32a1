//! Whole-stage step time (issue #4 item 9: the stage must simulate at >= 10 M steps/s on one
//! core). Criterion measures `thesis-linear`, `thesis-full` without and with its hysteresis
//! table, and with a second mode; a plain timing of 20 M steps of each prints steps/s.

use criterion::{Criterion, black_box, criterion_group};
use model_core::params;
use model_core::stage::{ModeConfig, Stage, StageConfig};
use std::time::Instant;

/// One period of a sine in 32 samples (1.56 kHz at 50 kHz).
fn sine_table() -> [f32; 32] {
    std::array::from_fn(|k| (2.0 * std::f64::consts::PI * k as f64 / 32.0).sin() as f32)
}

fn configs() -> Vec<(&'static str, StageConfig)> {
    let full = StageConfig::thesis_full();
    let two = StageConfig {
        second_mode: Some(ModeConfig {
            mode_hz: params::SECOND_MODE_HZ,
            damping: params::SECOND_MODE_DAMPING,
        }),
        ..full
    };
    let no_table = StageConfig {
        hysteresis: None,
        ..full
    };
    vec![
        ("thesis-linear", StageConfig::thesis_linear()),
        ("thesis-full-without-table", no_table),
        ("thesis-full", full),
        ("thesis-full+second-mode", two),
    ]
}

fn bench_stage(c: &mut Criterion) {
    for (name, cfg) in configs() {
        let stage = Stage::new(&cfg).expect("built-in config");
        let mut s = stage.steady_state(0.0);
        let mut k = 0u32;
        let sine = sine_table();
        c.bench_function(&format!("stage step {name}"), |b| {
            b.iter(|| {
                k = k.wrapping_add(1);
                // Worst case for the table: a 3 V, 1.5 kHz sine around 5 V changes the DAC
                // code (and the table's input) at every step.
                let u = 5.0 + 3.0 * sine[(k % 32) as usize];
                black_box(stage.step(&mut s, black_box(u)))
            })
        });
    }
}

/// CPU time of this thread, seconds, from `/proc/thread-self/stat` (utime + stime, in clock
/// ticks of 10 ms): on a machine shared with other work, wall time counts the time the thread
/// waited for a core; CPU time is the "one core" figure. `None` off Linux.
fn thread_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").ok()?;
    // Fields after the command name (which is in parentheses and may hold spaces).
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the whole line, 12 and 13 after ")".
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

fn steps_per_second() {
    for (name, cfg) in configs() {
        let stage = Stage::new(&cfg).expect("built-in config");
        let mut s = stage.steady_state(0.0);
        let n = 20_000_000u32;
        let sine = sine_table();
        let start = Instant::now();
        let cpu0 = thread_cpu_s();
        let mut acc = 0.0f32;
        for k in 0..n {
            let u = 5.0 + 3.0 * sine[(k % 32) as usize];
            acc += stage.step(&mut s, black_box(u));
        }
        let dt = start.elapsed().as_secs_f64();
        let cpu = thread_cpu_s().zip(cpu0).map(|(b, a)| b - a);
        black_box(acc);
        println!(
            "{name}: {n} steps in {dt:.3} s wall = {:.1} M steps/s ({:.1} ns/step; target >= 10 M steps/s)",
            n as f64 / dt / 1e6,
            dt / n as f64 * 1e9
        );
        if let Some(c) = cpu.filter(|c| *c > 0.0) {
            println!(
                "{name}: {c:.2} s of this thread's CPU time = {:.1} M steps/s on one core ({:.1} ns/step)",
                n as f64 / c / 1e6,
                c / n as f64 * 1e9
            );
        }
    }
}

criterion_group!(benches, bench_stage);

fn main() {
    steps_per_second();
    benches();
    Criterion::default().configure_from_args().final_summary();
}
