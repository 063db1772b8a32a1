//! `piezo track`: how well the loop follows a periodic reference, with feedback alone, with
//! trajectory planning only, or with the full pre-filter ([`host_tests::sim::tracking`]).

use clap::{Args, ValueEnum};
use host_tests::io::model_file::ModelFile;
use host_tests::sim::tracking::{TrackShape, TrackSpec, plot, plot_learning, simulate};
use model_core::learning::LearningConfig;
use model_core::params;
use model_core::prefilter::PreFilterMode;

/// Shapes `piezo track` offers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ShapeArg {
    /// `offset + amplitude sin(2 pi f t)`.
    Sine,
    /// Triangle between `offset - amplitude` and `offset + amplitude`.
    Triangle,
    /// Periodic steps (square wave) between `offset - amplitude` and `offset + amplitude`.
    Step,
}

impl ShapeArg {
    fn shape(self) -> TrackShape {
        match self {
            Self::Sine => TrackShape::Sine,
            Self::Triangle => TrackShape::Triangle,
            Self::Step => TrackShape::Step,
        }
    }
}

/// Pre-filter setting of `piezo track`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PrefilterArg {
    /// Feedback alone.
    Off,
    /// Reference through `1/(tau s + 1)^4` (with its preview).
    Planning,
    /// The full pre-filter `H'`.
    On,
}

impl PrefilterArg {
    fn mode(self) -> PreFilterMode {
        match self {
            Self::Off => PreFilterMode::Off,
            Self::Planning => PreFilterMode::Planning,
            Self::On => PreFilterMode::Full,
        }
    }
}

/// Hysteresis feedforward setting of `piezo track`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FfArg {
    /// Feedback (and pre-filter) only.
    Off,
    /// Add the hysteresis feedforward (the model's table, or the thesis default table).
    On,
}

/// Arguments of `piezo track`.
#[derive(Args, Debug)]
pub struct TrackArgs {
    /// Reference shape.
    #[arg(long, value_enum, default_value_t = ShapeArg::Sine)]
    pub shape: ShapeArg,
    /// Frequency, Hz.
    #[arg(long, default_value_t = 100.0, allow_negative_numbers = true)]
    pub freq: f64,
    /// Peak amplitude (half of peak-to-peak), sensor volts.
    #[arg(long, default_value_t = 3.0, allow_negative_numbers = true)]
    pub amplitude: f64,
    /// Offset, sensor volts.
    #[arg(long, default_value_t = 4.0, allow_negative_numbers = true)]
    pub offset: f64,
    /// Pre-filter: off (feedback alone), planning, on (full pre-filter).
    #[arg(long, value_enum, default_value_t = PrefilterArg::On)]
    pub prefilter: PrefilterArg,
    /// Time constant of the four planning poles, seconds (1e-5..1e-3).
    #[arg(long, default_value_t = params::PREFILTER_TAU_S, allow_negative_numbers = true)]
    pub tau: f64,
    /// The stage the loop drives: a built-in name (thesis-linear, thesis-full) or a model
    /// file. Its sensor noise is replaced by 1 mV (1 sigma), as on the lab's E-509.
    #[arg(long, default_value = "thesis-linear")]
    pub model: String,
    /// Hysteresis feedforward: on adds it (with the model's hysteresis table if it has one).
    #[arg(long, value_enum, default_value_t = FfArg::Off)]
    pub ff: FfArg,
    /// Repeats of iterative learning before the measurement (0: none). Each repeat is one
    /// period of the reference, or the few periods that make a whole number of samples.
    #[arg(long, default_value_t = 0)]
    pub learn: u32,
    /// Cut-off of the learning's robustness filter, Hz.
    #[arg(long, default_value_t = LearningConfig::default().cutoff_hz)]
    pub learn_cutoff: f64,
    /// Time constant of the learning filter's planning poles, seconds.
    #[arg(long, default_value_t = LearningConfig::default().tau_s)]
    pub learn_tau: f64,
    /// Learning gain, in (0, 1].
    #[arg(long, default_value_t = LearningConfig::default().gain)]
    pub learn_gain: f64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Draw reference, output and error of the measured periods to this SVG file.
    #[arg(long)]
    pub plot: Option<std::path::PathBuf>,
}

/// Run `piezo track`.
pub fn run(a: &TrackArgs) -> anyhow::Result<()> {
    let model = ModelFile::load(&a.model)?;
    model.check()?;
    let spec = TrackSpec::new(
        a.shape.shape(),
        a.freq,
        a.amplitude,
        a.offset,
        a.prefilter.mode(),
    )
    .with_tau(a.tau)
    .with_stage(model.stage_config()?)
    .with_feedforward(a.ff == FfArg::On)
    .with_learning(a.learn);
    let spec = TrackSpec {
        learning: LearningConfig {
            cutoff_hz: a.learn_cutoff,
            gain: a.learn_gain,
            tau_s: a.learn_tau,
            ..spec.learning
        },
        ..spec
    };
    let r = simulate(&spec, a.plot.is_some())?;
    if let Some(path) = &a.plot {
        // The last two periods of the measured ones.
        let keep = ((2.0 / (a.freq * spec.lag.period_s)).ceil() as usize).min(r.trace.len());
        let title = format!(
            "{:?} {} Hz, {} V peak, pre-filter {:?}, ff {:?}, {}: last two periods",
            a.shape, a.freq, a.amplitude, a.prefilter, a.ff, a.model
        );
        plot(&r.trace[r.trace.len() - keep..], &title, path)?;
        if !r.learn_rms_error_v.is_empty() {
            let learn_path = path.with_extension("learn.svg");
            let title = format!(
                "{:?} {} Hz, {}: RMS error per learning repeat",
                a.shape, a.freq, a.model
            );
            plot_learning(&r.learn_rms_error_v, &title, &learn_path)?;
            eprintln!("convergence drawn to {}", learn_path.display());
        }
    }
    let f = r.figures;
    for (name, v) in [
        ("RMS error", f.rms_error_v),
        ("peak error", f.max_error_v),
        ("largest command slew", f.max_slew_v_per_ms),
    ] {
        host_tests::io::checks::finite(name, v)?;
    }
    if a.json {
        println!("{}", serde_json::to_string(&r.json()?)?);
        return Ok(());
    }
    println!(
        "{:?} {} Hz, {} V peak around {} V, pre-filter {:?} (tau {} us, preview {} samples)",
        a.shape,
        a.freq,
        a.amplitude,
        a.offset,
        a.prefilter,
        a.tau * 1e6,
        r.preview_samples
    );
    println!(
        "stage `{}`, hysteresis feedforward {:?}, 1 mV sensor noise",
        model.name, a.ff
    );
    if let (Some(first), Some(last)) = (r.learn_rms_error_v.first(), r.learn_rms_error_v.last()) {
        println!(
            "learning: {} repeats, RMS error {:.3} -> {:.3} mV, status {:?}; {} samples limited, command {:.3} .. {:.3} V",
            r.learn_rms_error_v.len(),
            first * 1e3,
            last * 1e3,
            r.learn_status,
            r.learn_limited_samples,
            r.learn_command_range_v.0,
            r.learn_command_range_v.1
        );
    }
    println!("{:<28}{:>14.3} mV", "RMS error", f.rms_error_v * 1e3);
    println!("{:<28}{:>14.3} mV", "peak error", f.max_error_v * 1e3);
    println!(
        "{:<28}{:>14.3} V/ms",
        "largest command slew", f.max_slew_v_per_ms
    );
    println!(
        "{:<28}{:>14.4}",
        "window-clamped fraction", f.dac_saturated_fraction
    );
    println!(
        "{:<28}{:>14.4}",
        "slew-limited fraction", r.slew_limited_fraction
    );
    println!(
        "{:<28}{:>8.3} .. {:.3} V",
        "command range", r.command_range_v.0, r.command_range_v.1
    );
    Ok(())
}
