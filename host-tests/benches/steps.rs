//! Host cost of one compensator step and one plant step (ns). Instructions on the Cortex-M
//! are counted under QEMU (see README, "Performance").
use criterion::{Criterion, black_box, criterion_group, criterion_main};
use model_core::lag::{LagCompensator, LagConfig, LagState};
use model_core::plant::{LinearPlant, LinearPlantConfig};

fn bench(c: &mut Criterion) {
    let lag = LagCompensator::new(&LagConfig::default()).unwrap();
    let mut st = LagState::new(5.0);
    let mut e = 1e-4f32;
    c.bench_function("lag compensator step", |b| {
        b.iter(|| {
            e = -e;
            black_box(lag.update(&mut st, black_box(e)))
        })
    });
    let plant = LinearPlant::new(&LinearPlantConfig::default()).unwrap();
    let mut ps = plant.steady_state(5.0);
    c.bench_function("linear plant step", |b| {
        b.iter(|| black_box(plant.step(&mut ps, black_box(5.0))))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
