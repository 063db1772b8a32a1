//! `piezo synth --model MODEL --protocol forc|steps|triangle|sine|chirp --seed N --output FILE.csv`:
//! measured-style records from any model ([`host_tests::sim::synth`]; the `identification`
//! protocol's two records from [`host_tests::gap::protocol`]).

use clap::{Args, ValueEnum};
use host_tests::gap::protocol;
use host_tests::io::checks;
use host_tests::sim::synth::{Protocol, SynthSpec, synth};
use std::path::{Path, PathBuf};

/// The input protocols.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ProtocolArg {
    /// First-order reversal curves (sec. 5.3.4).
    Forc,
    /// A step, then random levels.
    Steps,
    /// Triangle.
    Triangle,
    /// Raised sine.
    Sine,
    /// Raised sine with a linear frequency sweep.
    Chirp,
    /// The model-gap recording protocol: a fast and a slow record
    /// (`crate::gap::protocol`; `--seconds` is the slow record's length, 20..3600 s).
    Identification,
}

/// Arguments of `piezo synth`.
#[derive(Args, Debug, Clone)]
pub struct SynthArgs {
    /// Model file or built-in name (thesis-linear, thesis-full).
    #[arg(long)]
    pub model: String,
    /// Input protocol.
    #[arg(long, value_enum)]
    pub protocol: ProtocolArg,
    /// Seed of the sensor noise and of random levels.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output record (CSV t,u,y).
    #[arg(long)]
    pub output: PathBuf,
    /// Record length, seconds [default: 2] (0..3600; identification: the slow record,
    /// 20..3600, default 20; forc: set by the protocol).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Record sampling rate, Hz (10..1e6).
    #[arg(long, default_value_t = model_core::params::SAMPLE_RATE_HZ)]
    pub rate: f64,
    /// Span of the input above the offset, volts (forc: use 10 for the 0..10 V table).
    #[arg(long, default_value_t = 6.0)]
    pub amplitude: f64,
    /// Lowest input, volts.
    #[arg(long, default_value_t = 0.0)]
    pub offset: f64,
    /// Frequency of triangle/sine, start frequency of the chirp, Hz.
    #[arg(long, default_value_t = 1.0)]
    pub freq: f64,
    /// End frequency of the chirp, Hz.
    #[arg(long, default_value_t = 100.0)]
    pub freq_end: f64,
    /// Time per level of `steps`, seconds (default: the whole record, i.e. one step; at least
    /// one sample, at most 3600 s).
    #[arg(long)]
    pub hold: Option<f64>,
    /// Sensor noise, volts 1-sigma (default: the model's).
    #[arg(long)]
    pub noise_v: Option<f64>,
}

impl ProtocolArg {
    /// The library's protocol; `None` for `identification` (two records, not one).
    fn protocol(self) -> Option<Protocol> {
        match self {
            Self::Forc => Some(Protocol::Forc),
            Self::Steps => Some(Protocol::Steps),
            Self::Triangle => Some(Protocol::Triangle),
            Self::Sine => Some(Protocol::Sine),
            Self::Chirp => Some(Protocol::Chirp),
            Self::Identification => None,
        }
    }
}

/// Run `piezo synth`.
pub fn run(a: &SynthArgs) -> anyhow::Result<()> {
    checks::refuse_overwrite(&a.output, &[Path::new(&a.model)])?;
    let spec = SynthSpec {
        model: a.model.clone(),
        protocol: a.protocol.protocol().unwrap_or(Protocol::Steps),
        seed: a.seed,
        seconds: a.seconds.unwrap_or(2.0),
        rate: a.rate,
        amplitude: a.amplitude,
        offset: a.offset,
        freq: a.freq,
        freq_end: a.freq_end,
        hold: a.hold,
        noise_v: a.noise_v,
    };
    let Some(p) = a.protocol.protocol() else {
        // The identification protocol has its own rates and levels, but every flag given is
        // still checked (a NaN is never taken silently); its slow record is 20..3600 s.
        let seconds = checks::within("--seconds", a.seconds.unwrap_or(20.0), 20.0, 3600.0, "s")?;
        SynthSpec {
            seconds: 1.0,
            ..spec.clone()
        }
        .check()?;
        for (tag, rec) in protocol::synth_identification(&a.model, a.seed, a.noise_v, seconds)? {
            let path = protocol::record_path(&a.output, tag);
            rec.write(&path)?;
            eprintln!(
                "wrote {} samples ({tag} record) to {}",
                rec.len(),
                path.display()
            );
        }
        return Ok(());
    };
    debug_assert_eq!(spec.protocol, p);
    let rec = synth(&spec)?;
    rec.write(&a.output)?;
    // What was written (forc sets its own length).
    eprintln!(
        "wrote {} samples ({:.3} s at {:.1} Hz, protocol {:?}) to {}",
        rec.len(),
        rec.t_s[rec.len() - 1] - rec.t_s[0] + rec.period_s(),
        rec.rate_hz(),
        a.protocol,
        a.output.display()
    );
    Ok(())
}
