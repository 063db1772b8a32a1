//! How well the loop follows a periodic reference, with feedback alone, with trajectory
//! planning only, or with the full pre-filter (issue #3, sec. 4.1.2.4): the library half of
//! `piezo track`.
//!
//! # Simulation
//! The one closed-loop harness ([`model_core::closed_loop`]), sample by sample the board's
//! [`Controller::step`]: its on-board [`ReferenceGenerator`](model_core::reference::ReferenceGenerator) (with the preview the pre-filter
//! asks for) -> [`PreFilter`] -> lag compensator (+ hysteresis feedforward when asked) ->
//! output limits -> 14-bit DAC -> the stage -> the stage's sensor (seeded Gaussian noise, 1 mV
//! by default, replacing the model's own) -> 16-bit ADC, at 50 kHz. The stage is any ch. 6
//! model ([`TrackSpec::stage`]: `thesis-linear` by default, the plant of eq. 4.4 with its
//! 85 us delay; `thesis-full` or a model file from the command line); the controller's
//! pre-filter inverts the linear design plant ([`TrackSpec::plant`]) whatever the stage, as on
//! the board. The tracking error is the generator's present value minus the true stage output
//! (not the noisy measurement). The loop starts at rest at the first reference value
//! ([`closed_loop::settled_stage`]: drift and hysteresis in their steady state, controller
//! primed in open loop, then closed); after a warm-up of at least 0.2 s and 3 periods (the
//! periodic steady state), the figures are taken over whole periods: at least 0.1 s and 2
//! periods.
//!
//! # Learning (issue #14)
//! With [`TrackSpec::learn_periods`] > 0, after the warm-up the loop runs on until the
//! generator's repeat starts (index 0), then that many repeats with iterative learning
//! control ([`model_core::learning`]): each sample reads the table at the generator's index
//! and steps with the correction ([`ClosedLoop::step_with_correction`](model_core::closed_loop::ClosedLoop::step_with_correction)),
//! records reference minus measurement, and at each repeat's end the update runs, as the
//! board's task will. The figures are then measured as without learning, the table frozen
//! in force; [`TrackRun::learn_rms_error_v`] holds each learning repeat's RMS error (true
//! output, as the figures).
use crate::io::checks::within;
use crate::sim::closed_loop;
use anyhow::{Context, bail};
use model_core::closed_loop::LoopSample;
use model_core::controller::{Controller, ControllerConfig, Mode, ReferenceSource};
use model_core::hysteresis::HysteresisTable;
use model_core::lag::LagConfig;
use model_core::learning::{self, Learning, LearningConfig, LearningState, Period, Status};
use model_core::limits::Flags;
use model_core::params;
use model_core::plant::LinearPlantConfig;
use model_core::prefilter::{DelayHandling, PreFilter, PreFilterConfig, PreFilterMode};
use model_core::reference::{ReferenceConfig, Shape};
use model_core::stage::StageConfig;

/// Shapes of the tracking experiments.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrackShape {
    /// `offset + amplitude sin(2 pi f t)`.
    Sine,
    /// Triangle between `offset - amplitude` and `offset + amplitude`.
    Triangle,
    /// Periodic steps (square wave) between `offset - amplitude` and `offset + amplitude`.
    Step,
}

/// One tracking experiment.
#[derive(Clone, Copy, Debug)]
pub struct TrackSpec {
    /// Reference shape.
    pub shape: TrackShape,
    /// Frequency, Hz.
    pub freq_hz: f64,
    /// Peak amplitude (half of peak-to-peak), volts.
    pub amplitude_v: f64,
    /// Offset, volts.
    pub offset_v: f64,
    /// Pre-filter configuration.
    pub prefilter: PreFilterConfig,
    /// Sensor noise, volts (1 sigma).
    pub noise_v: f64,
    /// Noise seed.
    pub seed: u64,
    /// Compensator.
    pub lag: LagConfig,
    /// The linear design plant the pre-filter inverts (the controller's model).
    pub plant: LinearPlantConfig,
    /// The stage the loop drives (re-timed to the loop's period; its sensor noise is
    /// [`Self::noise_v`]).
    pub stage: StageConfig,
    /// Add the hysteresis feedforward (the stage's own table if it has one, else the thesis
    /// default table).
    pub feedforward: bool,
    /// Repeats of learning before the measurement (0: none, today's behaviour).
    pub learn_periods: u32,
    /// The learning's settings.
    pub learning: LearningConfig,
}

impl TrackSpec {
    /// The thesis loop at 50 kHz with 1 mV of sensor noise.
    pub fn new(
        shape: TrackShape,
        freq_hz: f64,
        amplitude_v: f64,
        offset_v: f64,
        mode: PreFilterMode,
    ) -> Self {
        Self {
            shape,
            freq_hz,
            amplitude_v,
            offset_v,
            prefilter: PreFilterConfig {
                mode,
                ..PreFilterConfig::default()
            },
            noise_v: params::TRACK_NOISE_V,
            seed: 1,
            lag: LagConfig::default(),
            plant: LinearPlantConfig::default(),
            stage: StageConfig::thesis_linear(),
            feedforward: false,
            learn_periods: 0,
            learning: LearningConfig::default(),
        }
    }

    /// The same with `periods` repeats of learning before the measurement.
    pub fn with_learning(mut self, periods: u32) -> Self {
        self.learn_periods = periods;
        self
    }

    /// The same on another stage.
    pub fn with_stage(mut self, stage: StageConfig) -> Self {
        self.stage = stage;
        self
    }

    /// The same with the hysteresis feedforward on or off.
    pub fn with_feedforward(mut self, on: bool) -> Self {
        self.feedforward = on;
        self
    }

    /// The controller this experiment runs: the board's, with this compensator, design plant,
    /// pre-filter and feedforward, and the on-board generator as the reference.
    pub fn controller_config(&self) -> ControllerConfig {
        let shape = match self.shape {
            TrackShape::Sine => Shape::Sine,
            TrackShape::Triangle => Shape::Triangle,
            TrackShape::Step => Shape::Square,
        };
        ControllerConfig {
            lag: self.lag,
            plant: self.plant,
            prefilter: self.prefilter,
            reference: ReferenceConfig {
                shape,
                offset_v: self.offset_v,
                amplitude_v: self.amplitude_v,
                freq_hz: self.freq_hz,
                period_s: self.lag.period_s,
            },
            source: ReferenceSource::Generator,
            hysteresis: self
                .stage
                .hysteresis
                .unwrap_or_else(HysteresisTable::thesis_default),
            hysteresis_ff: self.feedforward,
            ..ControllerConfig::default()
        }
    }

    /// The same with another tau.
    pub fn with_tau(mut self, tau_s: f64) -> Self {
        self.prefilter.tau_s = tau_s;
        self
    }

    /// The same with another delay handling.
    pub fn with_delay(mut self, delay: DelayHandling) -> Self {
        self.prefilter.delay = delay;
        self
    }
}

/// What `piezo track --json` prints.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct TrackFigures {
    /// RMS of reference minus output over whole periods, volts.
    pub rms_error_v: f64,
    /// Largest |reference - output|, volts.
    pub max_error_v: f64,
    /// Largest change of the DAC command between samples, V/ms.
    pub max_slew_v_per_ms: f64,
    /// Fraction of samples whose command the window clamped.
    pub dac_saturated_fraction: f64,
}

/// Everything measured, with what the JSON leaves out.
#[derive(Clone, Debug)]
pub struct TrackRun {
    /// The contract figures.
    pub figures: TrackFigures,
    /// Fraction of samples the slew limit held back.
    pub slew_limited_fraction: f64,
    /// Lowest and highest DAC command, volts.
    pub command_range_v: (f64, f64),
    /// Preview used, samples.
    pub preview_samples: u32,
    /// Recorded (time s, reference V, output V, command V) over the measured periods.
    pub trace: Vec<(f64, f64, f64, f64)>,
    /// RMS error (reference minus true output) of each learning repeat, volts; empty without
    /// learning.
    pub learn_rms_error_v: Vec<f64>,
    /// Learning's status after the last repeat (`None` without learning).
    pub learn_status: Option<Status>,
    /// Samples during the learning repeats that the window clamped or the slew limit held
    /// back, and the command's range then, volts.
    pub learn_limited_samples: usize,
    /// Lowest and highest command during the learning repeats, volts.
    pub learn_command_range_v: (f64, f64),
    /// Largest |value| of the learned table in force, its clamp and the clamp's predicted
    /// part ([`Learning::predicted_peak_v`]), volts (0 without learning).
    pub learn_table_peak_v: (f64, f64, f64),
}

impl TrackRun {
    /// How far the recorded output went beyond `[lo_v, hi_v]` (the levels of a square-wave
    /// reference), in percent of `hi_v - lo_v`; 0 inside. Needs a run made with `record`.
    pub fn overshoot_pct(&self, lo_v: f64, hi_v: f64) -> f64 {
        let top = self.trace.iter().map(|s| s.2).fold(f64::MIN, f64::max);
        let bottom = self.trace.iter().map(|s| s.2).fold(f64::MAX, f64::min);
        ((top - hi_v).max(lo_v - bottom) / (hi_v - lo_v) * 100.0).max(0.0)
    }
}

impl TrackRun {
    /// What `piezo track --json` prints: the four [`TrackFigures`] keys, and
    /// `learn_rms_error_v` (one value per learning repeat) only when learning ran.
    pub fn json(&self) -> anyhow::Result<serde_json::Value> {
        let mut v = serde_json::to_value(self.figures)?;
        if let (false, Some(o)) = (self.learn_rms_error_v.is_empty(), v.as_object_mut()) {
            o.insert(
                "learn_rms_error_v".into(),
                serde_json::to_value(&self.learn_rms_error_v)?,
            );
        }
        Ok(v)
    }
}

/// Checks the experiment; every refusal says why.
pub fn validate(spec: &TrackSpec) -> anyhow::Result<()> {
    let t = spec.lag.period_s;
    for (name, v) in [
        ("--freq", spec.freq_hz),
        ("--amplitude", spec.amplitude_v),
        ("--offset", spec.offset_v),
        ("--tau", spec.prefilter.tau_s),
    ] {
        if !v.is_finite() {
            bail!("{name} must be a finite number, got {v}");
        }
    }
    let nyquist = 0.5 / t;
    if !(spec.freq_hz > 0.0 && spec.freq_hz < nyquist) {
        bail!(
            "--freq must be above 0 and below the Nyquist rate {nyquist} Hz, got {}",
            spec.freq_hz
        );
    }
    if spec.freq_hz < 1.0 {
        bail!(
            "--freq below 1 Hz would need minutes of simulation; got {}",
            spec.freq_hz
        );
    }
    if spec.amplitude_v < 0.0 {
        bail!(
            "--amplitude is a peak value and must not be negative, got {}",
            spec.amplitude_v
        );
    }
    let (lo, hi) = (
        spec.offset_v - spec.amplitude_v,
        spec.offset_v + spec.amplitude_v,
    );
    if lo < params::SENSOR_MIN_V || hi > params::SENSOR_MAX_V {
        bail!(
            "the reference spans {lo}..{hi} V, outside the sensor range {}..{} V",
            params::SENSOR_MIN_V,
            params::SENSOR_MAX_V
        );
    }
    if !(spec.noise_v.is_finite() && spec.noise_v >= 0.0) {
        bail!("the noise must be a finite non-negative number of volts");
    }
    within(
        "--tau",
        spec.prefilter.tau_s,
        params::PREFILTER_TAU_MIN_S,
        params::PREFILTER_TAU_MAX_S,
        "s",
    )?;
    PreFilter::new(&spec.lag, &spec.plant, &spec.prefilter).map_err(|e| {
        anyhow::anyhow!("invalid pre-filter (--tau {} s): {e}", spec.prefilter.tau_s)
    })?;
    if spec.learn_periods > MAX_LEARN_PERIODS {
        bail!(
            "--learn is at most {MAX_LEARN_PERIODS} repeats, got {}",
            spec.learn_periods
        );
    }
    if spec.learn_periods > 0 {
        Learning::new(&spec.learning, &spec.controller_config()).map_err(|e| {
            anyhow::anyhow!(
                "no learning for this reference ({e}): learning needs a period of a whole number of samples, or a few periods that make one, up to {} samples",
                params::MAX_LEARN_PERIOD_SAMPLES
            )
        })?;
    }
    Ok(())
}

/// Most learning repeats `simulate` runs.
pub const MAX_LEARN_PERIODS: u32 = 10_000;

/// Run one experiment; `record` keeps the trace of the measured periods.
pub fn simulate(spec: &TrackSpec, record: bool) -> anyhow::Result<TrackRun> {
    validate(spec)?;
    let t = spec.lag.period_s;
    let cfg = spec.controller_config();
    let controller = Controller::new(&cfg).map_err(|e| anyhow::anyhow!("{e}"))?;
    let r0 = controller.generator.now(&controller.generator.start());
    let mut lp = closed_loop::settled_stage(&cfg, &spec.stage, spec.noise_v, spec.seed, r0)?;
    let period_samples = 1.0 / (spec.freq_hz * t);
    let warm_periods = (0.2 * spec.freq_hz).ceil().max(3.0);
    let meas_periods = (0.1 * spec.freq_hz).ceil().max(2.0);
    let warm = (warm_periods * period_samples).round() as usize;
    let n = (meas_periods * period_samples).round() as usize;
    let (mut sum2, mut max_e, mut max_du) = (0.0f64, 0.0f64, 0.0f64);
    let (mut clamped, mut slewed) = (0usize, 0usize);
    let (mut u_lo, mut u_hi) = (f64::MAX, f64::MIN);
    let mut u_prev = lp.state.command_v() as f64;
    let mut trace = Vec::new();
    let mut learn = Learned::default();
    let mut table = Vec::new();
    if spec.learn_periods > 0 {
        for k in 0..warm {
            let s = lp.step();
            check_faults(&s, k, t)?;
        }
        learn = learn_repeats(spec, &cfg, &mut lp, &mut table, warm)?;
        u_prev = lp.state.command_v() as f64;
    }
    let start = if spec.learn_periods > 0 { warm } else { 0 };
    for k in start..warm + n {
        let i = controller.reference_index(&lp.state);
        let s = lp.step_with_correction(learning::correction(&table, i));
        check_faults(&s, k, t)?;
        let u = s.sample.command_v as f64;
        if k >= warm {
            let (r, y) = (s.sample.reference_v as f64, s.output_v as f64);
            let e = r - y;
            sum2 += e * e;
            max_e = max_e.max(e.abs());
            max_du = max_du.max((u - u_prev).abs());
            u_lo = u_lo.min(u);
            u_hi = u_hi.max(u);
            clamped += s.sample.flags.contains(Flags::CLAMPED) as usize;
            slewed += s.sample.flags.contains(Flags::SLEW_LIMITED) as usize;
            if record {
                trace.push((k as f64 * t, r, y, s.sample.dac.volts() as f64));
            }
        }
        u_prev = u;
    }
    let nf = n.max(1) as f64;
    Ok(TrackRun {
        figures: TrackFigures {
            rms_error_v: (sum2 / nf).sqrt(),
            max_error_v: max_e,
            max_slew_v_per_ms: max_du / t * 1e-3,
            dac_saturated_fraction: clamped as f64 / nf,
        },
        slew_limited_fraction: slewed as f64 / nf,
        command_range_v: (u_lo, u_hi),
        preview_samples: controller.prefilter.preview_samples(),
        trace,
        learn_rms_error_v: learn.rms_v,
        learn_status: learn.status,
        learn_limited_samples: learn.limited,
        learn_command_range_v: learn.command_range_v,
        learn_table_peak_v: learn.table_peak_v,
    })
}

fn check_faults(s: &LoopSample, k: usize, t: f64) -> anyhow::Result<()> {
    if !s.sample.faults.is_empty() {
        bail!(
            "the controller latched a fault ({:?}) at {:.4} s: the loop does not run on this stage",
            s.sample.faults,
            k as f64 * t
        );
    }
    Ok(())
}

/// What the learning repeats left.
#[derive(Default)]
struct Learned {
    rms_v: Vec<f64>,
    status: Option<Status>,
    limited: usize,
    command_range_v: (f64, f64),
    table_peak_v: (f64, f64, f64),
}

/// Run on to the start of the generator's repeat, then `spec.learn_periods` repeats of
/// learning, updating `table` (sized here) at the end of each, as the board's task will.
fn learn_repeats(
    spec: &TrackSpec,
    cfg: &ControllerConfig,
    lp: &mut closed_loop::StageLoop,
    table: &mut Vec<f32>,
    mut k: usize,
) -> anyhow::Result<Learned> {
    let t = spec.lag.period_s;
    let l = Learning::new(&spec.learning, cfg).map_err(|e| anyhow::anyhow!("learning: {e}"))?;
    let n = l.period_samples() as usize;
    *table = vec![0.0f32; n];
    let (mut error, mut scratch) = (vec![0.0f32; n], vec![0.0f32; n]);
    let mut st = LearningState::new();
    let controller = lp.controller;
    // Bounded: the index returns to 0 within one repeat.
    while controller.reference_index(&lp.state) != 0 {
        let s = lp.step();
        check_faults(&s, k, t)?;
        k += 1;
    }
    let mut out = Learned {
        command_range_v: (f64::MAX, f64::MIN),
        ..Learned::default()
    };
    for _ in 0..spec.learn_periods {
        let mut sum2 = 0.0f64;
        for _ in 0..n {
            let i = controller.reference_index(&lp.state);
            let s = lp.step_with_correction(learning::correction(table, i));
            check_faults(&s, k, t)?;
            k += 1;
            learning::record(&mut error, i, &s.sample);
            let e = s.error_v() as f64;
            sum2 += e * e;
            let u = s.sample.command_v as f64;
            out.command_range_v = (out.command_range_v.0.min(u), out.command_range_v.1.max(u));
            out.limited += s
                .sample
                .flags
                .contains(Flags::CLAMPED | Flags::SLEW_LIMITED) as usize;
        }
        out.rms_v.push((sum2 / n as f64).sqrt());
        let period = Period {
            error_v: &error,
            faults: lp.state.faults(),
            closed_loop: lp.state.mode() == Mode::ClosedLoop,
            generator: &lp.controller.generator,
        };
        out.status = Some(l.update(&mut st, table, &mut scratch, &period));
    }
    out.table_peak_v = (
        table.iter().fold(0.0f64, |a, &c| a.max((c as f64).abs())),
        l.max_correction_v() as f64,
        l.predicted_peak_v() as f64,
    );
    Ok(out)
}

/// Draw reference, output (top) and error (bottom) of a recorded trace to an SVG file.
pub fn plot(
    tr: &[(f64, f64, f64, f64)],
    title: &str,
    path: &std::path::Path,
) -> anyhow::Result<()> {
    if tr.is_empty() {
        bail!("nothing recorded to plot");
    }
    crate::io::checks::write_atomic(path, |tmp| draw(tr, title, tmp))
}

fn draw(tr: &[(f64, f64, f64, f64)], title: &str, path: &std::path::Path) -> anyhow::Result<()> {
    use plotters::prelude::*;
    let t0 = tr[0].0;
    let ms = |t: f64| (t - t0) * 1e3;
    let t_end = ms(tr[tr.len() - 1].0).max(1e-6);
    let (y_lo, y_hi) = tr.iter().fold((f64::MAX, f64::MIN), |(a, b), s| {
        (a.min(s.1).min(s.2), b.max(s.1).max(s.2))
    });
    let e_max = tr.iter().map(|s| (s.1 - s.2).abs()).fold(1e-6, f64::max) * 1e3;
    let root = SVGBackend::new(path, (1000, 700)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, bottom) = root.split_vertically(420);
    let mut c = ChartBuilder::on(&top)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..t_end, (y_lo - 0.2)..(y_hi + 0.2))?;
    c.configure_mesh()
        .x_desc("time, ms")
        .y_desc("sensor, V")
        .draw()?;
    c.draw_series(LineSeries::new(tr.iter().map(|s| (ms(s.0), s.1)), &BLUE))?
        .label("reference")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    c.draw_series(LineSeries::new(tr.iter().map(|s| (ms(s.0), s.2)), &RED))?
        .label("output")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    c.configure_series_labels()
        .background_style(WHITE)
        .border_style(BLACK)
        .draw()?;
    let mut c2 = ChartBuilder::on(&bottom)
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..t_end, -e_max * 1.1..e_max * 1.1)?;
    c2.configure_mesh()
        .x_desc("time, ms")
        .y_desc("error, mV")
        .draw()?;
    c2.draw_series(LineSeries::new(
        tr.iter().map(|s| (ms(s.0), (s.1 - s.2) * 1e3)),
        &BLACK,
    ))?;
    root.present().context("writing the SVG")?;
    Ok(())
}

/// Draw the RMS error of each learning repeat (log scale, mV) to an SVG file.
pub fn plot_learning(rms_v: &[f64], title: &str, path: &std::path::Path) -> anyhow::Result<()> {
    crate::io::checks::write_atomic(path, |tmp| draw_learning(rms_v, title, tmp))
}

fn draw_learning(rms_v: &[f64], title: &str, path: &std::path::Path) -> anyhow::Result<()> {
    use plotters::prelude::*;
    if rms_v.is_empty() {
        bail!("no learning repeat to plot");
    }
    let mv: Vec<f64> = rms_v.iter().map(|v| (v * 1e3).max(1e-3)).collect();
    let (lo, hi) = mv
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    let root = SVGBackend::new(path, (800, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut c = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..mv.len() as f64, (lo * 0.5..hi * 2.0).log_scale())?;
    c.configure_mesh()
        .x_desc("learning repeat")
        .y_desc("RMS error, mV")
        .draw()?;
    c.draw_series(LineSeries::new(
        mv.iter().enumerate().map(|(k, &v)| (k as f64 + 1.0, v)),
        &BLUE,
    ))?;
    c.draw_series(
        mv.iter()
            .enumerate()
            .map(|(k, &v)| Circle::new((k as f64 + 1.0, v), 3, BLUE.filled())),
    )?;
    root.present().context("writing the SVG")?;
    Ok(())
}
