//! `piezo demo`: the model-gap workflow without a board. Synthesises the `identification`
//! records ([`host_tests::gap::protocol`]) from a virtual stage that has two effects the base
//! model `thesis-linear` lacks ([`host_tests::gap::demo`]), runs the workflow from
//! `thesis-linear`, prints the table and writes the report.

use clap::Args;
use host_tests::gap::demo::demo_truth;
use host_tests::gap::{Data, Options, diagnose, protocol, report};
use host_tests::io::model_file::ModelFile;
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

/// Run `piezo demo`.
pub fn run(a: &DemoArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.slow_seconds.is_finite() && (20.0..=600.0).contains(&a.slow_seconds),
        "--slow-seconds must be within 20..600"
    );
    std::fs::create_dir_all(&a.dir)?;
    let truth = demo_truth(a.seed);
    let mut data = Vec::new();
    for (tag, rec) in protocol::records(&truth, a.slow_seconds)? {
        let name = format!("{tag}.csv");
        rec.write(&a.dir.join(&name))?;
        data.push(Data::from_record(&name, rec)?);
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
