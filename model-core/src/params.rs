//! Every number of the loop, in one place, with the thesis section it comes from or the
//! words "our assumption". Design-time values are `f64`; the per-sample code works in `f32`.
//! The board's own numbers (resistors, baud, SPI clock, watchdog, capture size, command
//! limits) live in the firmware crate, `firmware::design_parameters`.
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
/// Rate of the ramp to the safe value (after a fault, and on `mode safe`), V/s at the
/// amplifier input: 1 V/ms, so the full 10 V window takes 10 ms, 150 times slower than the
/// amplifier's own slew limit (issue 13 item 4: the full-slew ramp rang to -0.52 V). Our
/// assumption; a setting (`ControllerConfig::safe_ramp_v_per_s`).
pub const SAFE_RAMP_INPUT_V_PER_S: f64 = 1_000.0;

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

// ----- Fault detection in the controller (our assumptions). -----
/// Lowest plausible sensor reading, volts: the E-509 monitor spans 0..10 V (sec. 2.4); half a
/// volt below means a broken or disconnected sensor.
pub const SENSOR_VALID_MIN_V: f64 = -0.5;
/// Highest plausible sensor reading, volts (over-range above this).
pub const SENSOR_VALID_MAX_V: f64 = 10.5;
/// A sensor is stuck if its code stays within +-[`SENSOR_STUCK_BAND_LSB`] of where it was for
/// this many samples (5 ms at 50 kHz) after the command moved by more than
/// [`SENSOR_STUCK_COMMAND_V`]. A live E-509 answers such a move with about 260 codes, so a
/// code held inside the noise band while the command moves is a fault.
pub const SENSOR_STUCK_SAMPLES: u32 = 250;
/// Command movement that must show on the sensor, volts at the amplifier input (moves the
/// stage by about 80 mV of monitor signal, 260 ADC codes).
pub const SENSOR_STUCK_COMMAND_V: f64 = 0.1;
/// The command held at a window edge while the loop error pushes further out for this long,
/// seconds, is a fault ([`crate::controller::Faults::SATURATED`]): the loop has lost control
/// (an unplugged or stuck sensor read in range, a reference the stage cannot reach). 20 ms is
/// twenty closed-loop settling times of the thesis loop (1.14 ms) and short against the drift
/// (our assumption).
pub const SATURATION_FAULT_S: f64 = 0.02;
/// Loop error (sensor volts) beyond which a command at the window edge counts towards
/// [`SATURATION_FAULT_S`]: 200 times the sensor noise, so noise at a set-point near an edge
/// never counts (our assumption).
pub const SATURATION_ERROR_V: f64 = 0.5;
/// Noise band of the stuck-sensor detector, ADC codes: a sensor whose code stays within
/// +-this of the code at the start of the window is "not moving" (our assumption: a live
/// E-509 moves 260 codes for [`SENSOR_STUCK_COMMAND_V`]; a frozen input with a few LSB of
/// converter noise stays inside 8).
pub const SENSOR_STUCK_BAND_LSB: i32 = 8;
/// In closed loop the stuck-sensor window counts only while the loop error exceeds this,
/// sensor volts: a regulated loop rejecting a disturbance moves the command with the sensor
/// held still on purpose; a stuck sensor away from the reference leaves an error that the
/// integrator keeps ramping on (our assumption: 20 times the E-509's 2.5 mV noise, 7 times
/// the pre-filtered sine's tracking error).
pub const SENSOR_STUCK_ERROR_V: f64 = 0.05;
// ----- Hysteresis table (sec. 3.2, 5.3; issue #4). -----
/// Nodes per axis of the Everett grid (turning-up value alpha, turning-down value beta).
/// The table stores the strictly lower triangle alpha > beta: 45 * 44 / 2 = 990 `f32`, so the
/// whole table is 3980 bytes, under the 4 KiB budget of issue #4 (our assumption).
pub const HYST_GRID_NODES: usize = 45;
/// Turning points the memory keeps, the bottom of the range included (our assumption: a
/// history of 15 nested minor loops; beyond that the two innermost are merged).
pub const HYST_MEMORY_DEPTH: usize = 32;
/// Grid cells the exact hysteresis inverse walks from the last input before it binary-searches
/// the rest of the segment (our assumption: at 50 kHz a 100 Hz full-range sine moves at most
/// 0.063 V per sample, about a quarter of a 0.23 V cell, so one or two cells hold the answer;
/// three cover any move of at least 0.45 V).
pub const HYST_INVERSE_WALK_CELLS: usize = 3;
/// Fixed bisection steps of the inverse: 10 V / 2^24 = 0.6 uV, below the `f32` spacing at
/// 10 V (our assumption).
pub const HYST_INVERSE_ITERATIONS: u32 = 24;
/// Lower edge of the default table's input range, volts at the amplifier input (the safe
/// window; our assumption).
pub const HYST_DEFAULT_INPUT_MIN_V: f64 = SAFE_WINDOW_MIN_V;
/// Upper edge of the default table's input range (the safe window; our assumption).
pub const HYST_DEFAULT_INPUT_MAX_V: f64 = SAFE_WINDOW_MAX_V;
/// Output at the bottom of the range after coming down to it, sensor volts (our assumption:
/// the sensor's zero is set there).
pub const HYST_DEFAULT_OFFSET_V: f64 = 0.0;
/// Average static gain over the full major loop, sensor V per input V (eq. 4.4's 0.79).
pub const HYST_DEFAULT_DC_GAIN: f64 = PLANT_GAIN;
/// Largest vertical width of the full-amplitude loop as a fraction of the output span. Sec.
/// 3.2 gives 15-20 % of range and about 9-10 deg of phase lag at 1 Hz; for a loop whose
/// shape depends on amplitude only (congruent loops, sec. 3.2: "same-amplitude loops look
/// alike at different offsets") these two figures are tied (about 0.48 deg per %), so 15 %
/// gives 7.3 deg. We take 18.5 %, inside the thesis' band, which gives 9.0 deg (our
/// assumption; the phase lag is measured in host-tests).
pub const HYST_DEFAULT_LOOP_WIDTH_FRAC: f64 = 0.185;
/// Spacing of the turning values of the first-order reversal curves (sec. 5.3.4).
pub const HYST_FORC_STEP_V: f64 = 0.15;
/// Frequency of the preconditioning sinusoid (sec. 5.3.4).
pub const HYST_FORC_PRECONDITION_HZ: f64 = 1.0;

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
/// Longest repeat of the on-board generator, samples, and so the longest period the learning
/// control learns (issue #14; our assumption: 82 ms at 50 kHz, a fundamental down to 12.2 Hz).
/// One `f32` table of it is 16 KiB; the learning's five buffers (the table the interrupt
/// reads, the one being computed, the error the interrupt records, the one being read, one
/// scratch) are 80 KiB: they fit the H743's 128 KiB DTCM, not the AXI SRAM beside the
/// 400 kB capture buffer (see `model_core::learning`).
pub const MAX_LEARN_PERIOD_SAMPLES: u32 = 4096;
/// Sensor monitor range, volts (E-509: 0..10 V for 0..12 um, sec. 2.4).
pub const SENSOR_MIN_V: f64 = 0.0;
/// Sensor monitor range, volts (E-509: 0..10 V for 0..12 um, sec. 2.4).
pub const SENSOR_MAX_V: f64 = 10.0;
/// Sensor noise used by the tracking measurements of issue #3 (1 mV, 1 sigma).
pub const TRACK_NOISE_V: f64 = 1e-3;

// =====================================================================================
// ----- The non-linear stage (issue #4): drift, fast gain, amplifier model, sensor model. -----
// =====================================================================================

// Drift, eq. 5.1 (sec. 5.2): three parallel first-order lags fitted on a 1 V step.
/// Gains of the three drift lags, sensor volts per volt of (gain-weighted) input (eq. 5.1).
pub const DRIFT_GAINS: [f64; 3] = [0.05, 0.05, 0.055];
/// Time constants of the three drift lags, seconds (eq. 5.1).
pub const DRIFT_TAUS_S: [f64; 3] = [0.06, 0.75, 12.0];
/// Normalised drift gain polynomial K(u) = c0 + c1 u + c2 u^2 + c3 u^3, eq. 5.3, coefficients
/// lowest power first (K(1) = 1).
pub const DRIFT_POLY: [f64; 4] = [0.6121, 0.5472, -0.1733, 0.0140];
/// The un-normalised eq. 5.2 (drift gain per volt of step over about 600 s), lowest power
/// first; kept for the record and for the normalisation test.
pub const DRIFT_POLY_UNNORMALISED: [f64; 4] = [0.1204, 0.1077, -0.0341, 0.0027];
/// Range of step heights over which K(u) is evaluated; outside it K is held at the edge value
/// (our assumption: the thesis fitted 1..6 V steps from 0 V, fig. 3.9; K(0) = 0.61 is finite so
/// the range is extended down to 0 V; above 6 V the cubic turns up steeply, K(10) = 2.75,
/// which no data supports).
pub const DRIFT_POLY_U_RANGE_V: (f64, f64) = (0.0, 6.0);

// Non-linear fast gain K'(u), sec. 3.1 / 5.1 (fig. 3.10): no coefficients printed.
/// K'(u) = c0 + c1 u + c2 u^2 (our assumption): 1 at 0 V, growing almost linearly
/// with the input (+2 %/V near 0 V) and flattening to +10 % at 10 V, where its slope is 0 (the
/// "plateau" of sec. 5.1); no higher terms. `0.79 K'(u) u` stays strictly increasing on the
/// range. (The terms up to `u^6`, [`crate::gain::POLY_TERMS`], are there for fits: curvatures
/// of higher order than the thesis' quadratic, which the model-gap workflow weighs against a
/// sensor scale and an offset.)
pub const FAST_GAIN_POLY: [f64; crate::gain::POLY_TERMS] = [1.0, 0.02, -0.001, 0.0, 0.0, 0.0, 0.0];
/// Range of inputs over which K'(u) is evaluated; held at the edge values outside (our
/// assumption: the amplifier's useful 0..10 V at its control input).
pub const FAST_GAIN_U_RANGE_V: (f64, f64) = (0.0, 10.0);

// Sensor and converters in the stage model.
/// Sensor gain of the stage model, monitor volts per volt of position (1: the plant's 0.79
/// already maps to monitor volts; our assumption).
pub const SENSOR_GAIN: f64 = 1.0;
/// Offset of the stage model's sensor monitor, volts (0: a calibrated monitor reads 0 V at
/// zero position; our assumption. A real record's offset is the model-gap effect `offset`).
pub const SENSOR_OFFSET_V: f64 = 0.0;
/// Default seed of the sensor noise generator (any value; our assumption).
pub const SENSOR_NOISE_SEED: u64 = 0x005E_ED0F_E509;

// Second resonance mode (issue #7, "two peaks near 5.7 kHz", sec. 4.1.1): disabled by default.
/// Frequency of a second stage mode when one is switched on, Hz (our assumption).
pub const SECOND_MODE_HZ: f64 = 6300.0;
/// Damping of the second mode (our assumption).
pub const SECOND_MODE_DAMPING: f64 = 0.05;
/// Largest extra delay the model file accepts, seconds (our assumption; the plant's delay line
/// holds 62 samples at 50 kHz = 1.24 ms in total).
pub const MAX_DELAY_S: f64 = 1.0e-3;

// Stage simulation step.
/// Fixed step of the stage model (the loop rate, sec. 2.3.1).
pub const STAGE_PERIOD_S: f64 = 1.0 / SAMPLE_RATE_HZ;
// =====================================================================================
// ----- The model-gap workflow (issue #7): fitted hysteresis form. -----
// =====================================================================================
/// Number of play operators of the fitted hysteresis form [`crate::play`] (our assumption,
/// measured on the model-gap hidden-effect tests: on the same 69 cases, four gave 66 exactly
/// right named sets, eight gave 68, and halved the misfit of a Bouc-Wen loop's small
/// reversals).
pub const PLAY_OPERATORS: usize = 8;
/// Thresholds of the fitted play operators, volts at the amplifier input (our assumption:
/// roughly geometric over the 0..10 V range, from 50 mV, so that small and large loops both
/// have an operator of their size).
pub const PLAY_RADII_V: [f64; PLAY_OPERATORS] = [0.05, 0.12, 0.25, 0.5, 0.9, 1.5, 2.5, 4.0];
