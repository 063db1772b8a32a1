//! Cost of one pre-filter step (and one reference-generator step) on the host.
use criterion::{Criterion, black_box, criterion_group, criterion_main};
use model_core::lag::LagConfig;
use model_core::plant::LinearPlantConfig;
use model_core::prefilter::{PreFilter, PreFilterConfig};
use model_core::reference::{ReferenceConfig, ReferenceGenerator, Shape};

fn bench(c: &mut Criterion) {
    let pf = PreFilter::new(
        &LagConfig::default(),
        &LinearPlantConfig::default(),
        &PreFilterConfig::default(),
    )
    .expect("the thesis loop is valid");
    let cfg = ReferenceConfig {
        shape: Shape::Sine,
        offset_v: 4.0,
        amplitude_v: 3.0,
        freq_hz: 100.0,
        ..ReferenceConfig::default()
    };
    let g = ReferenceGenerator::new(&cfg, pf.preview_samples()).expect("valid reference");
    let mut ps = pf.settled_state(4.0);
    let mut gs = g.start();
    c.bench_function("prefilter_step", |b| {
        b.iter(|| pf.step(&mut ps, black_box(4.5)))
    });
    c.bench_function("reference_next_sine", |b| {
        b.iter(|| g.next(black_box(&mut gs)))
    });
    c.bench_function("reference_then_prefilter", |b| {
        b.iter(|| {
            let r = g.next(&mut gs);
            pf.step(&mut ps, black_box(r))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
