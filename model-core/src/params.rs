//! Every number of the loop, in one place, with the thesis section it comes from or the
//! words "our assumption". Design-time values are `f64`; the per-sample code works in `f32`.
//!
//! Thesis: "Modelling and Control of Piezoelectric Actuators" (Purdue, 2001), summarised in
//! `shared/model-card.md`.

// ----- Sampling (sec. 2.3.1): the DS1103 closed the loop at 50 kHz. -----
/// Loop rate of the DS1103 and of our firmware (sec. 2.3.1).
pub const SAMPLE_RATE_HZ: f64 = 50_000.0;
/// Lowest loop rate a configuration may ask for (issue #2; our assumption).
pub const MIN_SAMPLE_RATE_HZ: f64 = 10_000.0;
/// Highest loop rate a configuration may ask for (issue #2; our assumption).
pub const MAX_SAMPLE_RATE_HZ: f64 = 200_000.0;

// ----- Converters (sec. 2.3.1, 2.4): DS1103 ADC 16 bit and DAC 14 bit, both over +-10 V. -----
/// Full-scale span of both converters, volts (+-10 V).
pub const CONVERTER_SPAN_V: f64 = 20.0;
/// ADC resolution (sec. 2.4).
pub const ADC_BITS: u32 = 16;
/// DAC resolution (sec. 2.3.1).
pub const DAC_BITS: u32 = 14;

// ----- Sensor E-509.C1 (sec. 2.4). -----
/// Monitor volts per micrometre: 10 V for 12 um.
pub const SENSOR_V_PER_UM: f64 = 10.0 / 12.0;
/// Monitor noise, volts (about +-2.5 mV, sec. 2.4); used as a 1-sigma figure (our assumption).
pub const SENSOR_NOISE_V: f64 = 2.5e-3;
/// Sensor bandwidth, Hz (sec. 2.4).
pub const SENSOR_BANDWIDTH_HZ: f64 = 10_000.0;

// ----- Amplifier E-505.00 (sec. 2.3, 4.1.1.1). -----
/// Voltage gain (10 +- 0.1).
pub const AMP_GAIN: f64 = 10.0;
/// Control input range, volts.
pub const AMP_INPUT_MIN_V: f64 = -2.0;
/// Control input range, volts.
pub const AMP_INPUT_MAX_V: f64 = 12.0;
/// Output range, volts.
pub const AMP_OUTPUT_MIN_V: f64 = -20.0;
/// Output range, volts.
pub const AMP_OUTPUT_MAX_V: f64 = 120.0;
/// Slew limiter at the output as the lab set it: 1500 V/ms (settable 15..1500 V/ms).
pub const AMP_SLEW_OUTPUT_V_PER_S: f64 = 1.5e6;
/// Lowest slew setting of the limiter at the output, V/s (15 V/ms).
pub const AMP_SLEW_OUTPUT_MIN_V_PER_S: f64 = 1.5e4;
/// The same limit seen at the control input: 150 V/ms, i.e. 3 V per 20 us sample.
pub const AMP_SLEW_INPUT_V_PER_S: f64 = AMP_SLEW_OUTPUT_V_PER_S / AMP_GAIN;

// ----- Safe output window (issue #2; our assumption). -----
/// Lower edge of the window the controller may command, volts at the amplifier input.
pub const SAFE_WINDOW_MIN_V: f64 = 0.0;
/// Upper edge of the window the controller may command, volts at the amplifier input.
pub const SAFE_WINDOW_MAX_V: f64 = 10.0;
/// The value the output rests at (boot, faults): the bottom of the window, stage retracted.
pub const SAFE_OUTPUT_V: f64 = 0.0;

// ----- Linear plant, eq. 4.4 / 4.6 (sec. 4.1.1). -----
/// Static gain from amplifier control input to sensor monitor, V/V.
pub const PLANT_GAIN: f64 = 0.79;
/// "Electrical" pole of the amplifier driving 1.8 uF, Hz.
pub const AMP_POLE_HZ: f64 = 2000.0;
/// "Inertial" stage mode, Hz.
pub const STAGE_MODE_HZ: f64 = 5792.0;
/// Damping of the stage mode (the printed "20.08" is 2 * 0.08).
pub const STAGE_DAMPING: f64 = 0.08;
/// Loop delay, seconds (0.085 ms).
pub const PLANT_DELAY_S: f64 = 85e-6;

// ----- Lag compensator with free integrator, eq. 4.5 / 4.7 (sec. 4.1.2). -----
/// Compensator gain Kc.
pub const LAG_KC: f64 = 10_000.0;
/// Lag zero, rad/s.
pub const LAG_ZERO_RAD_S: f64 = 1.0;
/// Lag pole, rad/s.
pub const LAG_POLE_RAD_S: f64 = 0.398;
/// Largest gain a configuration may ask for (our assumption: 100x the thesis value, far past
/// instability, so that only nonsense is refused).
pub const LAG_KC_MAX: f64 = 1.0e6;

// ----- Thesis figures for the closed loop (sec. 4.1.2), and the independent recomputation. -----
/// Gain margin the thesis reports, dB.
pub const THESIS_GAIN_MARGIN_DB: f64 = 11.0;
/// Phase margin the thesis reports, degrees.
pub const THESIS_PHASE_MARGIN_DEG: f64 = 60.0;
/// Recomputed with a 6th-order Pade delay (model card): gain margin, dB.
pub const RECOMPUTED_GAIN_MARGIN_DB: f64 = 11.5;
/// Recomputed phase margin, degrees.
pub const RECOMPUTED_PHASE_MARGIN_DEG: f64 = 60.5;
/// Recomputed gain crossover, rad/s.
pub const RECOMPUTED_CROSSOVER_RAD_S: f64 = 3076.0;
/// Recomputed closed-loop -3 dB bandwidth, Hz.
pub const RECOMPUTED_BANDWIDTH_HZ: f64 = 1001.0;

// ----- Pre-filter and reference generators (sec. 4.1.2.4, eq. 4.8-4.13; issue #3). -----
/// Time constant of the four planning poles `1/(tau s + 1)^4` (our assumption, chosen by the
/// trade-off measured in `host-tests/tests/prefilter.rs`: see the design note of
/// `prefilter.rs`). The thesis gives no value.
pub const PREFILTER_TAU_S: f64 = 50e-6;
/// Shortest tau a configuration may ask for (our assumption: below it the pre-filter's
/// high-frequency gain `1/(p we wn^2 Kc K tau^4)` passes 1000).
pub const PREFILTER_TAU_MIN_S: f64 = 10e-6;
/// Longest tau a configuration may ask for (our assumption: 4 tau = 4 ms of preview).
pub const PREFILTER_TAU_MAX_S: f64 = 1e-3;
/// Longest preview (reference advance) a generator offers, samples (our assumption: covers
/// 4 tau + loop delay at the longest tau and the highest rate).
pub const MAX_PREVIEW_SAMPLES: u32 = 1024;
/// Sensor monitor range, volts (E-509: 0..10 V for 0..12 um, sec. 2.4).
pub const SENSOR_MIN_V: f64 = 0.0;
/// Sensor monitor range, volts (E-509: 0..10 V for 0..12 um, sec. 2.4).
pub const SENSOR_MAX_V: f64 = 10.0;
/// Sensor noise used by the tracking measurements of issue #3 (1 mV, 1 sigma).
pub const TRACK_NOISE_V: f64 = 1e-3;
