//! A measured input's noise (step 2 of the loop, beside the output's floor).
//!
//! # Design note
//! A lab that logs the amplifier's control input through an ADC (or off the E-505's input
//! monitor) records the command plus that converter's noise, and the stage was driven by the
//! command alone. The workflow simulates the model from the recorded input, so the model's
//! output carries the input's noise through the stage (at a record's rate of a few kHz, below
//! the stage's bandwidth, nearly all of it), while the measured output does not: the residual
//! holds noise that no model fed this input can explain, and the output's own floor
//! ([`super::data::noise_floor_of`]) does not see it. Measured (CLI, a `thesis-full` sine,
//! 10 s at 5 kHz, 1 mV of sensor noise): 2 mV of input noise took the final residual from
//! 1.80x to 2.50x the output's floor with an `unexplained` part, 10 mV to 7.0x with 115 noise
//! samples replaced as glitches and a pole tried.
//!
//! Where the input's noise did drive the stage (a noisy amplifier input, recorded as it
//! was), the output follows it. So the records tell the two cases apart: the input's own
//! noise is read off it (each sample less the binomial mean of the five around it, left
//! out at edges) and put through the base model; the output less the model's output from the input
//! without that noise is correlated with that response, both by their fourth differences
//! (which a sine, a chirp or a drift barely move), at lags up to the longest delay the
//! catalogue fits. Where the best correlation is below [`INPUT_NOISE_FOLLOWED`] of the
//! response's share of what it is correlated with (the correlation noise that drove the
//! stage, carried as the model carries it, would show), the noise is the measurement's: the
//! record's floor becomes the output's and the noise carried through the base model (a drawn
//! white sequence of the input noise's size) in quadrature, and the table says so. Where the
//! output follows it, the floor stays the output's own, as before. Measured on the test's
//! records (`a_measured_inputs_noise_is_part_of_the_floor`) and two CLI sines, as shares of
//! that: measured-only noise 0.016-0.14; noise that drove the stage 0.73 (the full thesis
//! stage), 0.88 (a linear stage with a delay the model lacks) and 1.0 (with a pole it lacks).
//! Both fourth differences are clipped at 5 robust standard deviations first: a glitch, an
//! edge's misfit or a clipped output would otherwise weigh as much as the record's noise
//! (before the clip the full thesis stage's edges held its driven share at 0.36).
//!
//! What this leaves: the noise is carried by the base model, and a fitted model with a loop
//! carries less of it (its slope just after a reversal is below the base's): on a
//! `thesis-full` sine with 10 mV of input noise the final model's residual sat at 0.89x the
//! floor so raised. Noise that drove the stage stays in the output's floor, which then holds
//! what a model fed the recorded input explains (the test's chirp at 20 kHz: the floor
//! 2.1 mV, the final residual 1.0 mV), as it did before. A floor raised by a measured input
//! can hide a small fast effect.

use super::constants::{INPUT_NOISE_FOLLOWED, INPUT_NOISE_MIN_SHARE};
use super::data::{Data, NoiseFloor, mse, noise_floor_of, sim};
use crate::io::model_file::ModelFile;
use model_core::params;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// A record's input noise that the stage did not see, carried into the residual by the model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputNoise {
    /// The input column's noise, volts (its floor, read as an output's).
    pub input_v: f64,
    /// That noise carried through the base model, volts RMS (the residual's share no model
    /// fed this input explains).
    pub carried_v: f64,
    /// The output's own floor, volts.
    pub output_v: f64,
    /// The record's floor with the carried noise, volts.
    pub floor_v: f64,
}

impl InputNoise {
    /// Words for the table's noise notes.
    pub fn note(&self, name: &str) -> String {
        format!(
            "{name}: the input column carries {:.2} mV of noise that the output does not \
             follow (an input measured, not the command the stage saw): the model fed it \
             carries {:.2} mV of it into its output, which no model explains, so the floor is \
             {:.2} mV (the output's own {:.2} mV)",
            1e3 * self.input_v,
            1e3 * self.carried_v,
            1e3 * self.floor_v,
            1e3 * self.output_v
        )
    }
}

/// The seed of the drawn input noise (any fixed seed: the carried noise's size, not its
/// samples, is used, and a fixed one keeps a diagnosis repeatable).
const DRAW_SEED: u64 = 0x1a7_5eed;

/// `d`'s input noise where the records show it is the measurement's ([`InputNoise`]), given
/// the base model `model`, its simulation `model_y` of `d` and the output's floor
/// `y_floor`. `None` where the input shows no noise above its rounding (a logged command),
/// where its noise carried through the model is below [`INPUT_NOISE_MIN_SHARE`] of the
/// output's floor, or where the output follows the input's noise (it drove the stage).
pub fn measured_input_noise(
    model: &ModelFile,
    d: &Data,
    model_y: &[f64],
    y_floor: &NoiseFloor,
) -> Option<InputNoise> {
    if model_y.len() != d.len() || !y_floor.sigma_v.is_finite() || d.len() < 16 {
        // (too short to read a noise off)
        return None;
    }
    let as_output = |y_v: Vec<f64>| Data {
        y_v,
        memo: Default::default(),
        ..d.clone()
    };
    let with_input = |u_v: Vec<f64>| Data {
        u_v,
        memo: Default::default(),
        // (another input: an averaged record's own input no longer drives it)
        fine: None,
        ..d.clone()
    };
    let u_floor = noise_floor_of(&as_output(d.u_v.clone()), None);
    if u_floor.by_resolution || !u_floor.sigma_v.is_finite() || u_floor.sigma_v <= 0.0 {
        return None;
    }
    let input_v = u_floor.sigma_v;
    // The simulations below run on inputs at the record's own rate; an averaged record's
    // `model_y` ran on its input at the faster rate (`Data::fine`), so for it they are
    // compared with the model's output from its input as recorded at this rate instead (the
    // two simulations' difference is not the input's noise).
    let reference = if d.fine.is_some() {
        sim(model, &with_input(d.u_v.clone())).ok()?
    } else {
        model_y.to_vec()
    };
    // The noise carried by the model: its output from the input with a drawn white noise of
    // the input's size added, less its output from the input as recorded.
    let normal = Normal::new(0.0, input_v).ok()?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(DRAW_SEED);
    let drawn = d.u_v.iter().map(|u| u + normal.sample(&mut rng)).collect();
    let y2 = sim(model, &with_input(drawn)).ok()?;
    let carried_v = mse(&y2, &reference).sqrt();
    if !carried_v.is_finite() || carried_v < INPUT_NOISE_MIN_SHARE * y_floor.sigma_v {
        return None;
    }
    // The input's own noise, read off it, through the model; does the output, less the
    // model's output from the input without that noise, follow it?
    let own = own_noise(&d.u_v, input_v);
    let quiet: Vec<f64> = d.u_v.iter().zip(&own).map(|(u, n)| u - n).collect();
    let y3 = sim(model, &with_input(quiet)).ok()?;
    let response: Vec<f64> = reference.iter().zip(&y3).map(|(a, b)| a - b).collect();
    let rest: Vec<f64> = if d.fine.is_some() {
        // (the output less the model's, plus the response at this rate)
        d.y_v
            .iter()
            .zip(model_y)
            .zip(&response)
            .map(|((y, m), r)| y - m + r)
            .collect()
    } else {
        d.y_v.iter().zip(&y3).map(|(a, b)| a - b).collect()
    };
    if !rest.iter().chain(&response).all(|v| v.is_finite()) {
        return None;
    }
    // (both clipped at `CLIP_SPREADS` of their own spread: a glitch of the recording, an
    // edge's misfit or a clipped output is a few large samples that would weigh in the sums
    // as much as the whole record's noise)
    let (rest4, response4) = (
        clipped(fourth_differences(&rest)),
        clipped(fourth_differences(&response)),
    );
    let max_lag = (params::MAX_DELAY_S / d.period_s()).ceil() as usize;
    let followed = best_correlation(&rest4, &response4, max_lag);
    // (the correlation noise that drove the stage as the model carries it would show: the
    // response's share of what is left)
    let share = (rms(&response4) / rms(&rest4).max(1e-15)).min(1.0);
    // (too few samples to tell a correlation of that share from none, three standard
    // deviations of a correlation of independent samples: the floor stays the output's)
    if !followed.is_finite()
        || !share.is_finite()
        || INPUT_NOISE_FOLLOWED * share * (rest4.len() as f64).sqrt() < 3.0
    {
        return None;
    }
    (followed < INPUT_NOISE_FOLLOWED * share).then(|| InputNoise {
        input_v,
        carried_v,
        output_v: y_floor.sigma_v,
        floor_v: y_floor.sigma_v.hypot(carried_v),
    })
}

/// Samples either side of a jump of the input (an edge of a held level) whose own noise is
/// read as zero: the five-sample mean straddles the edge there.
const EDGE_GUARD: usize = 2;

/// A jump of the input: its second difference, in the standard deviations white noise gives
/// it (our assumption: 8 sigma, with probability 1e-15 a sample).
const EDGE_SIGMAS: f64 = 8.0;

/// The input's own noise: each sample less the binomial mean of the five around it (weights
/// 1, 4, 6, 4, 1: a smooth command moves it by its curvature only, which the fourth
/// differences below take out), zero from three samples before an edge to two after it. The
/// binomial mean passes no frequency with a negative gain (its response is `cos^4(w / 2)`),
/// so the part of a measured noise it leaves in the input, which the output less the model's
/// then holds with the opposite sign, correlates with the part read off as the input's noise
/// negatively at lag 0, and at other lags only through the spectrum's shape (measured: 0.14
/// at most; a five-sample plain mean's negative side lobe made measured-only noise correlate
/// at 0.47 on a 5 kHz sine).
fn own_noise(u: &[f64], sigma_v: f64) -> Vec<f64> {
    let n = u.len();
    let mut near_edge = vec![false; n];
    // (a jump is a break in the input's slope: a chirp moves far between samples, smoothly)
    let bar = EDGE_SIGMAS * 6f64.sqrt() * sigma_v;
    for i in 2..n {
        if (u[i] - 2.0 * u[i - 1] + u[i - 2]).abs() > bar {
            for flag in &mut near_edge[i.saturating_sub(EDGE_GUARD + 1)..(i + EDGE_GUARD).min(n)] {
                *flag = true;
            }
        }
    }
    (0..n)
        .map(|i| {
            if i < 2 || i + 2 >= n || near_edge[i] {
                0.0
            } else {
                u[i] - (u[i - 2] + 4.0 * u[i - 1] + 6.0 * u[i] + 4.0 * u[i + 1] + u[i + 2]) / 16.0
            }
        })
        .collect()
}

/// How far from zero, in robust standard deviations (1.4826 times the median absolute
/// value), a fourth difference is clipped before it is correlated (our assumption: Gaussian
/// noise goes 5 sigma off with probability 6e-7, so the noise is left as it is).
const CLIP_SPREADS: f64 = 5.0;

/// `x` clipped at [`CLIP_SPREADS`] robust standard deviations from zero.
fn clipped(x: Vec<f64>) -> Vec<f64> {
    let mut a: Vec<f64> = x.iter().map(|v| v.abs()).collect();
    let bound = CLIP_SPREADS * 1.4826 * crate::util::median(&mut a);
    x.into_iter().map(|v| v.clamp(-bound, bound)).collect()
}

/// Root mean square (0 for no samples).
fn rms(x: &[f64]) -> f64 {
    if x.is_empty() {
        0.0
    } else {
        (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
    }
}

/// Fourth differences (a smooth signal's are its fourth derivative times the step's fourth
/// power: white noise stands out).
fn fourth_differences(x: &[f64]) -> Vec<f64> {
    x.windows(5)
        .map(|w| w[4] - 4.0 * w[3] + 6.0 * w[2] - 4.0 * w[1] + w[0])
        .collect()
}

/// The largest correlation of `a` (later by a lag of 0 to `max_lag` samples) with `b`:
/// `sum a[i + lag] b[i] / sqrt(sum a^2 sum b^2)` over the common samples.
fn best_correlation(a: &[f64], b: &[f64], max_lag: usize) -> f64 {
    (0..=max_lag.min(a.len().saturating_sub(1)))
        .map(|lag| {
            let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
            for (x, y) in a[lag..].iter().zip(b) {
                ab += x * y;
                aa += x * x;
                bb += y * y;
            }
            if aa > 0.0 && bb > 0.0 {
                ab / (aa * bb).sqrt()
            } else {
                0.0
            }
        })
        .fold(0.0, f64::max)
}
