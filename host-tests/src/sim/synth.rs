//! Measured-style records from any model, with its sensor noise (seeded) and converters: the
//! library half of `piezo synth --model MODEL --protocol forc|steps|triangle|sine|chirp --seed N
//! --output FILE.csv`. Each field of [`SynthSpec`] is the verb's flag of the same name, so the
//! protocols are described by their flags below. (The verb's `identification` protocol writes
//! two records and is the model-gap workflow's own, in `gap::protocol`.)
//!
//! The input is built at the record's rate (`--rate`) and simulated exactly as
//! `piezo simulate` does ([`crate::sim::open_loop::simulate`]), so simulating the written
//! record's `u` with the same model reproduces its `y` apart from the noise.
//!
//! Protocols (all start at `--offset` and span `--amplitude` above it):
//! * `steps`: `--offset` for the first tenth of `--hold` (at most 0.1 s), then a step to
//!   `offset + amplitude`; every further `--hold` seconds a new level drawn uniformly in
//!   `offset..offset + amplitude` from `--seed`. The default `--hold` is the whole record: one
//!   step, the drift identification's input.
//! * `triangle`: `offset + amplitude * tri(freq t)`, rising first.
//! * `sine`: `offset + amplitude (1 - cos(2 pi freq t)) / 2` (starts at rest).
//! * `chirp`: the same with the frequency swept linearly from `--freq` to `--freq-end`.
//! * `forc`: first-order reversal curves as the thesis recorded them (sec. 5.3.4), from the
//!   hysteresis identification's generator [`forc_protocol`]: preconditioning sine at `--freq`
//!   (1 Hz in the thesis), turning values every 0.15 V over `offset..offset + amplitude`,
//!   10 V/s ramps; the record is as long as the protocol needs (`--seconds` is ignored).

use crate::identify::hysteresis::{ForcProtocol, forc_protocol};
use crate::io::checks::{self, within};
use crate::io::csv::Record;
use crate::io::model_file::ModelFile;
use crate::sim::open_loop::simulate_after;
use anyhow::{bail, ensure};
use rand::{Rng, SeedableRng};
use std::f64::consts::PI;

/// The input protocols of a single record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Protocol {
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
}

/// One synthetic record: the model, the protocol and its parameters.
#[derive(Clone, Debug)]
pub struct SynthSpec {
    /// Model file or built-in name (thesis-linear, thesis-full).
    pub model: String,
    /// Input protocol.
    pub protocol: Protocol,
    /// Seed of the sensor noise and of random levels.
    pub seed: u64,
    /// Record length, seconds.
    pub seconds: f64,
    /// Record sampling rate, Hz.
    pub rate: f64,
    /// Span of the input above the offset, volts (forc: use 10 for the 0..10 V table).
    pub amplitude: f64,
    /// Lowest input, volts.
    pub offset: f64,
    /// Frequency of triangle/sine, start frequency of the chirp, Hz.
    pub freq: f64,
    /// End frequency of the chirp, Hz.
    pub freq_end: f64,
    /// Time per level of `steps`, seconds (default: the whole record, i.e. one step).
    pub hold: Option<f64>,
    /// Sensor noise, volts 1-sigma (default: the model's).
    pub noise_v: Option<f64>,
}

impl SynthSpec {
    /// A `steps` record of `model` (`piezo synth --protocol steps`): one step from rest at
    /// `offset` V, then levels drawn over `offset + [0, amplitude]` V every `hold` s (without
    /// one, the first level held to the end); `seconds` long at `rate` Hz, noise seed `seed`,
    /// the model's own sensor noise.
    pub fn steps(
        model: &str,
        (seed, seconds, rate): (u64, f64, f64),
        (offset, amplitude): (f64, f64),
        hold: Option<f64>,
    ) -> Self {
        Self {
            model: model.into(),
            protocol: Protocol::Steps,
            seed,
            seconds,
            rate,
            amplitude,
            offset,
            freq: 1.0,
            freq_end: 100.0,
            hold,
            noise_v: None,
        }
    }

    /// Checks the parameters; every refusal names the flag.
    pub fn check(&self) -> anyhow::Result<()> {
        ensure!(
            self.seconds.is_finite() && self.seconds > 0.0 && self.seconds <= 3600.0,
            "--seconds must be within (0, 3600] s (got {})",
            self.seconds
        );
        ensure!(
            self.rate.is_finite() && (10.0..=1e6).contains(&self.rate),
            "--rate must be within 10..1e6 Hz (got {})",
            self.rate
        );
        ensure!(
            self.seconds * self.rate <= 5e7,
            "record too long: {:e} samples, at most 5e7 (lower --seconds or --rate)",
            self.seconds * self.rate
        );
        ensure!(
            self.seconds * self.rate >= 2.0,
            "record too short: {} s at {} Hz is fewer than 2 samples",
            self.seconds,
            self.rate
        );
        ensure!(
            self.amplitude.is_finite() && self.offset.is_finite(),
            "--amplitude and --offset must be finite (got {} and {})",
            self.amplitude,
            self.offset
        );
        ensure!(
            self.offset >= -2.0 && self.offset + self.amplitude <= 12.0 && self.amplitude >= 0.0,
            "the input must stay within the amplifier's -2..12 V: offset {} + amplitude {}",
            self.offset,
            self.amplitude
        );
        ensure!(
            self.freq.is_finite() && self.freq > 0.0 && self.freq < self.rate / 2.0,
            "--freq must be within (0, rate/2) = (0, {}) Hz (got {})",
            self.rate / 2.0,
            self.freq
        );
        ensure!(
            self.freq_end.is_finite() && self.freq_end > 0.0 && self.freq_end < self.rate / 2.0,
            "--freq-end must be within (0, rate/2) = (0, {}) Hz (got {})",
            self.rate / 2.0,
            self.freq_end
        );
        if let Some(h) = self.hold {
            // At least one sample per level: the work is then bounded by the record's length.
            within("--hold", h, 1.0 / self.rate, 3600.0, "s")?;
        }
        if let Some(n) = self.noise_v {
            ensure!(
                n.is_finite() && (0.0..=1.0).contains(&n),
                "--noise-v must be within 0..1 V (got {n})"
            );
        }
        Ok(())
    }
}

/// The protocol's input at the record times `t_s`.
pub fn input(a: &SynthSpec, t_s: &[f64]) -> anyhow::Result<Vec<f64>> {
    let (o, amp, f) = (a.offset, a.amplitude, a.freq);
    Ok(match a.protocol {
        Protocol::Steps => {
            let hold = a.hold.unwrap_or(a.seconds);
            let t_step = (0.1 * hold).min(0.1);
            let mut rng = rand::rngs::StdRng::seed_from_u64(a.seed ^ 0xA5A5_5A5A);
            let mut level = o + amp;
            let mut next = t_step + hold;
            t_s.iter()
                .map(|&t| {
                    if t < t_step {
                        return o;
                    }
                    while t >= next {
                        level = o + amp * rng.r#gen::<f64>();
                        next += hold;
                    }
                    level
                })
                .collect()
        }
        Protocol::Triangle => t_s
            .iter()
            .map(|&t| {
                let p = (t * f).rem_euclid(1.0);
                o + amp * if p < 0.5 { 2.0 * p } else { 2.0 - 2.0 * p }
            })
            .collect(),
        Protocol::Sine => t_s
            .iter()
            .map(|&t| o + amp * 0.5 * (1.0 - (2.0 * PI * f * t).cos()))
            .collect(),
        Protocol::Chirp => {
            let k = (a.freq_end - f) / a.seconds;
            t_s.iter()
                .map(|&t| o + amp * 0.5 * (1.0 - (2.0 * PI * (f * t + 0.5 * k * t * t)).cos()))
                .collect()
        }
        Protocol::Forc => bail!("the forc protocol defines its own sample times"),
    })
}

/// Build the record `a` asks for.
pub fn synth(a: &SynthSpec) -> anyhow::Result<Record> {
    a.check()?;
    let mut model = ModelFile::load(&a.model)?;
    model.converters.seed = a.seed;
    if let Some(n) = a.noise_v {
        model.converters.noise_v = n;
    }
    let stage = model.build_stage()?;
    let (t_s, u_v) = if a.protocol == Protocol::Forc {
        let p = ForcProtocol {
            rate_hz: a.rate,
            u_min_v: a.offset,
            u_max_v: a.offset + a.amplitude,
            precondition_hz: a.freq,
            ..ForcProtocol::default()
        };
        let u = forc_protocol(&p)?;
        ensure!(u.len() >= 2, "the FORC protocol gave fewer than 2 samples");
        let t: Vec<f64> = (0..u.len()).map(|i| i as f64 / a.rate).collect();
        (t, u)
    } else {
        let n = (a.seconds * a.rate).round() as usize;
        let t_s: Vec<f64> = (0..n).map(|i| i as f64 / a.rate).collect();
        let u_v = input(a, &t_s)?;
        (t_s, u_v)
    };
    let span_s = t_s[t_s.len() - 1] - t_s[0];
    checks::bound_steps(
        &format!(
            "a {span_s} s record at the model's step of {} s",
            model.period_s
        ),
        checks::stage_steps(span_s, model.period_s),
        checks::max_stage_steps(),
    )?;
    let y = simulate_after(&stage, model.period_s, &model.start_history_v(), &t_s, &u_v);
    Ok(Record::new(t_s, u_v, Some(y), None)?)
}
