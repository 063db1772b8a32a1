//! The host's way into the one closed-loop harness, [`model_core::closed_loop`]: build a loop
//! of the board's [`Controller`] around a stage (the linear plant of eq. 4.4, or any ch. 6
//! stage from a model file), put it at rest in an operating point, and hand it to the
//! experiments ([`super::analysis`]'s margins and bandwidth, [`super::tracking`]'s tracking
//! figures). Nothing here steps a block of the loop by hand: every sample is
//! [`ClosedLoop::step`], that is [`Controller::step`] between the converters.
//!
//! # Starting in an operating point
//! A lab closes the loop from rest: the stage sits at some input, the controller holds that
//! input in open loop, then closes the loop bumplessly. [`settled`] does the same: the stage
//! starts at rest ([`StageModel`] constructors put drift and hysteresis in their steady state),
//! the controller is primed in open loop on an external reference
//! ([`ClosedLoop::prime`]), then the configuration to run is swapped in, as the firmware swaps
//! a new configuration between two samples, and the loop closes.

use anyhow::{Context, bail};
use model_core::closed_loop::{ClosedLoop, Converted, FullStage, NoNoise, StageModel};
use model_core::controller::{Controller, ControllerConfig, ReferenceSource};
use model_core::sensor::SensorConfig;
use model_core::stage::{Stage, StageConfig};

/// A loop around a ch. 6 stage whose sensor (noise, gain, ADC) is the stage's own.
pub type StageLoop = ClosedLoop<Converted<FullStage, NoNoise>>;

/// `cfg`'s stage re-timed to the loop's sample period, its sensor noise `noise_v` (1 sigma)
/// from `seed`: the stage a host experiment closes the loop around.
pub fn loop_stage(
    cfg: &StageConfig,
    period_s: f64,
    noise_v: f64,
    seed: u64,
) -> anyhow::Result<Stage> {
    let c = StageConfig {
        period_s,
        sensor: SensorConfig {
            noise_v,
            seed,
            ..cfg.sensor
        },
        ..*cfg
    };
    Stage::new(&c).map_err(|e| anyhow::anyhow!("the stage at the loop's rate: {e}"))
}

/// `run` closed around `stage` at rest in `u0_v` (its output then is the reference
/// `reference_v`, or the generator's start when `run` uses the generator): the controller is
/// primed at `u0_v` in open loop, on an external reference, then `run` is swapped in and the
/// loop closes.
pub fn settled<S: StageModel>(
    run: &ControllerConfig,
    stage: S,
    u0_v: f32,
    reference_v: f32,
) -> anyhow::Result<ClosedLoop<Converted<S, NoNoise>>> {
    let priming = Controller::new(&ControllerConfig {
        source: ReferenceSource::External,
        ..*run
    })
    .map_err(|e| anyhow::anyhow!("invalid controller: {e}"))?;
    let running = Controller::new(run).map_err(|e| anyhow::anyhow!("invalid controller: {e}"))?;
    let mut lp = ClosedLoop::new(priming, Converted::new(stage, NoNoise));
    if !lp.prime(u0_v) {
        bail!(
            "the controller could not hold {u0_v} V in open loop (outside its window, or a fault: {:?})",
            lp.state.faults()
        );
    }
    lp.controller = running;
    lp.close(reference_v);
    Ok(lp)
}

/// `run` closed around the stage `cfg` (re-timed to the loop, sensor noise `noise_v` from
/// `seed`), at rest where its static output is `reference_v`.
pub fn settled_stage(
    run: &ControllerConfig,
    cfg: &StageConfig,
    noise_v: f64,
    seed: u64,
    reference_v: f32,
) -> anyhow::Result<StageLoop> {
    let stage = loop_stage(cfg, run.lag.period_s, noise_v, seed)?;
    let (lo, hi) = (run.lag.min_v as f32, run.lag.max_v as f32);
    let u0 = stage.static_input(reference_v, lo, hi);
    settled(run, FullStage::new(stage, u0), u0, reference_v)
        .with_context(|| format!("starting the loop at {reference_v} V"))
}
