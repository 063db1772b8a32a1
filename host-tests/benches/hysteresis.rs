//! Cost of the hysteresis table per step on the host: forward (prediction) and inverse
//! (feedforward), each over a decaying sine with nested reversals and over noisy holds (many
//! small reversals), and the table's size in bytes.

use criterion::{Criterion, Throughput, black_box, criterion_group, criterion_main};
use model_core::hysteresis::{HysteresisMemory, HysteresisTable};

fn inputs() -> Vec<(&'static str, Vec<f32>)> {
    let n = 10_000;
    let sine = (0..n)
        .map(|k| {
            let t = k as f32 * 1e-3;
            5.0 + 4.9 * (-t / 3.0).exp() * (2.0 * core::f32::consts::PI * t).sin()
        })
        .collect();
    let mut seed = 1u32;
    let noisy = (0..n)
        .map(|_| {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            5.0 + ((seed >> 8) as f32 / (1u32 << 24) as f32 - 0.5) * 2e-3
        })
        .collect();
    vec![("decaying sine", sine), ("noise at 5 V", noisy)]
}

fn bench(c: &mut Criterion) {
    let table = HysteresisTable::thesis_default();
    println!(
        "HysteresisTable: {} bytes; HysteresisMemory: {} bytes",
        core::mem::size_of::<HysteresisTable>(),
        core::mem::size_of::<HysteresisMemory>()
    );
    let mut g = c.benchmark_group("hysteresis");
    for (name, u) in inputs() {
        g.throughput(Throughput::Elements(u.len() as u64));
        g.bench_function(format!("forward per step, {name}"), |b| {
            let mut m = HysteresisMemory::new();
            b.iter(|| {
                let mut acc = 0.0f32;
                for &x in &u {
                    acc += table.forward(&mut m, black_box(x));
                }
                acc
            })
        });
        // Wanted outputs: what the table gives for the same inputs.
        let mut m = HysteresisMemory::new();
        let y: Vec<f32> = u.iter().map(|&x| table.forward(&mut m, x)).collect();
        g.bench_function(format!("inverse per step, {name}"), |b| {
            let mut m = HysteresisMemory::new();
            b.iter(|| {
                let mut acc = 0.0f32;
                for &w in &y {
                    acc += table.inverse(&mut m, black_box(w));
                }
                acc
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
