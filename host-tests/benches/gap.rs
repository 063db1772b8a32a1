//! Speed of the model-gap workflow (issue #7, item 7): a 150 s record at 1 kHz plus a 0.2 s
//! record at 50 kHz, diagnosed from `thesis-linear`, on all cores. Target: <= 10 s on the
//! project's 2-core machine. A timed run (three repetitions, the figure printed), not
//! criterion's statistics: one run takes seconds.

use host_tests::gap::demo::demo_truth;
use host_tests::gap::{Data, Options, diagnose, protocol};
use host_tests::io::csv::Record;
use host_tests::io::model_file::ModelFile;
use host_tests::sim::open_loop::simulate;
use std::time::Instant;

fn main() {
    let truth = demo_truth(3);
    let stage = truth.build_stage().expect("truth");
    let mut records = Vec::new();
    for (name, (t, u)) in [
        ("fast", protocol::fast_input(50_000.0, 0.2)),
        ("slow", protocol::slow_input(1_000.0, 150.0)),
    ] {
        let y = simulate(&stage, truth.period_s, &t, &u);
        records.push((name, Record::new(t, u, Some(y), None).expect("record")));
    }
    let base = ModelFile::built_in("thesis-linear").expect("built-in");
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut times = Vec::new();
    for _ in 0..3 {
        // Fresh records each time: a record keeps the simulations run on it (`Data::memo`),
        // and a repetition must not start from the last one's.
        let data: Vec<Data> = records
            .iter()
            .map(|(name, r)| Data::from_record(name, r.clone()).expect("data"))
            .collect();
        let t0 = Instant::now();
        let d = diagnose(&base, &data, &Options::default()).expect("diagnosis");
        let s = t0.elapsed().as_secs_f64();
        println!(
            "gap: 150 s @ 1 kHz + 0.2 s @ 50 kHz diagnosed in {s:.2} s on {cores} cores; named {:?}, final {:.2}x the floor",
            d.named,
            d.final_rms_v / d.noise_floor_v
        );
        times.push(s);
    }
    times.sort_by(f64::total_cmp);
    println!("gap: median {:.2} s (target <= 10 s)", times[1]);
}
