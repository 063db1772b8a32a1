//! `piezo demo`: the model-gap workflow without a board. Synthesises the `identification`
//! records ([`crate::gap::protocol`]) from a virtual stage that has two effects the base model
//! `thesis-linear` lacks (drift and hysteresis, the thesis' two big ones, with 1 mV sensor
//! noise), runs the workflow from `thesis-linear`, prints the table and writes the report.

use crate::gap::{Data, Options, diagnose, protocol, report};
use crate::model_file::{DriftSection, ModelFile, PlaySection};
use crate::record::Record;
use crate::simulate::simulate;
use clap::Args;
use model_core::params;
use std::path::PathBuf;

/// Arguments of `piezo demo`.
#[derive(Args, Debug, Clone)]
pub struct DemoArgs {
    /// Directory for the records, the report and the augmented model.
    #[arg(long, default_value = "gap-demo")]
    pub dir: PathBuf,
    /// Length of the slow record, seconds.
    #[arg(long, default_value_t = 40.0)]
    pub slow_seconds: f64,
    /// Seed of the sensor noise.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
}

/// Weights of the demo stage's play-sum hysteresis on [`params::PLAY_RADII_V`] (our
/// assumption: a loop of about 0.28 V, 3.5 % of the sensor span, on a full 0-10 V cycle).
pub const DEMO_PLAY_WEIGHTS: [f64; params::PLAY_OPERATORS] =
    [0.01, 0.01, 0.02, 0.02, 0.02, 0.02, 0.015, 0.01];

/// The demo's virtual stage: `thesis-linear` plus the thesis' drift (eq. 5.1) and a play-sum
/// hysteresis of about 15 % of the span, 1 mV noise.
pub fn demo_truth(seed: u64) -> ModelFile {
    let mut m = ModelFile::built_in("thesis-linear").unwrap_or_else(|| unreachable!());
    m.name = "demo truth".into();
    m.converters.noise_v = 1e-3;
    m.converters.seed = seed;
    m.drift = Some(DriftSection {
        gains: params::DRIFT_GAINS,
        taus_s: params::DRIFT_TAUS_S,
        poly: [1.0, 0.0, 0.0, 0.0],
        poly_range_v: [0.0, 10.0],
    });
    m.hysteresis_play = Some(PlaySection {
        radii_v: params::PLAY_RADII_V,
        weights: DEMO_PLAY_WEIGHTS,
    });
    m
}

/// Run `piezo demo`.
pub fn run(a: &DemoArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.slow_seconds.is_finite() && (20.0..=600.0).contains(&a.slow_seconds),
        "--slow-seconds must be within 20..600"
    );
    std::fs::create_dir_all(&a.dir)?;
    let truth = demo_truth(a.seed);
    let stage = truth.build_stage()?;
    let mut data = Vec::new();
    for (name, (t, u)) in [
        (
            "fast.csv",
            protocol::fast_input(model_core::params::SAMPLE_RATE_HZ, 0.2),
        ),
        ("slow.csv", protocol::slow_input(1_000.0, a.slow_seconds)),
    ] {
        let y = simulate(&stage, truth.period_s, &t, &u);
        let rec = Record::new(t, u, Some(y), None)?;
        rec.write(&a.dir.join(name))?;
        data.push(Data::from_record(name, rec)?);
    }
    println!(
        "records {} and {} synthesised from a virtual stage the model thesis-linear does not describe",
        a.dir.join("fast.csv").display(),
        a.dir.join("slow.csv").display()
    );
    let base = ModelFile::built_in("thesis-linear").unwrap_or_else(|| unreachable!());
    let d = diagnose(&base, &data, &Options { progress: true })?;
    print!("{}", d.table());
    let out = a.dir.join("model.toml");
    d.model.write(&out)?;
    report::write(&a.dir.join("report"), &base, &data, &d)?;
    println!(
        "augmented model: {}\nreport: {}",
        out.display(),
        a.dir.join("report").join("index.html").display()
    );
    Ok(())
}
