//! The overall model of the stage (ch. 6, fig. 6.2): the virtual P-753 / E-505 / E-509 that
//! every other part of the project is tested against.
//!
//! # The wiring (the one place it is stated)
//! ```text
//!            ┌──────────── drift: K(u) u ─► G_drift(s) (eq. 5.1-5.3) ───────────┐
//!            │                                                                   ▼
//! u ─► DAC ─► E-505: clamp, x10, slew ─► /10 = ue ─┬─► hysteresis H(ue) ─► x K'(ue) ─► (+) ─► d
//!   14 bit    (amplifier.rs)                      (hysteresis.rs, or 0.79 ue)  (gain.rs)      │
//!                                                                                             ▼
//!  y ◄─ ADC 16 bit ◄─ + noise ◄─ x gain ◄─ [2nd mode] ◄─ G_inertial ◄─ G_electrical ◄─ delay
//!        (sensor.rs)                          (stage.rs)    (plant.rs, eq. 4.4 with unity gain)
//! ```
//! * `u`: volts at the amplifier's control input; `ue = v_out / 10`: the amplifier output
//!   expressed in control-input volts, so that the thesis' polynomials (fitted against step
//!   heights at the control input) apply unchanged and an amplifier gain error shows up as a
//!   gain error of the whole stage.
//! * `d`: the static (quasi-static) displacement in sensor volts: the fast transduction (with
//!   the plant's static gain 0.79 inside it) plus the drift.
//! * `y`: sensor monitor volts.
//!
//! Why this order:
//! 1. **The amplifier comes first** because its limits act on volts at its output, before the
//!    stack sees anything: a clamped or slew-limited drive is what the piezo transduces.
//! 2. **The 2 kHz pole belongs to the plant ([`crate::plant`]), after the non-linear blocks**,
//!    as in the thesis' fig. 6.2: eq. 4.4 identified the electrical and inertial parts together
//!    at small amplitude, and the thesis argues (sec. 6.2) that the electrical bandwidth is so
//!    far above the hysteresis and drift dynamics that the piezo block may see the undelayed
//!    input. Keeping the pole in `LinearPlant` also keeps eq. 4.4 in one block, identical to the
//!    linear model the controller was designed on. [`crate::amplifier`] therefore holds only the
//!    ranges and the slew limiter. (The physical order of fig. 6.1, pole before transduction,
//!    differs from this only while the amplifier is slewing through its pole, i.e. above 1 kHz,
//!    where hysteresis is a small part of the response.)
//! 3. **Hysteresis, then K'(u)**: the hysteresis table returns sensor volts with the static gain
//!    0.79 inside it; K'(u) scales it by the amplitude-dependent gain of the fast part (without
//!    the table, the fast part is `0.79 K'(ue) ue`). Both are memoryless in time (the table's
//!    turning-point memory is rate independent), so they may sit in front of the dynamics.
//! 4. **Drift in parallel**, driven by the same `ue` (fig. 6.2: `K(u) G_drift(s)` on the input),
//!    added to the fast part before the dynamics (its lags are 3000x slower than the plant, so
//!    the order does not matter for it; summing first costs one plant instead of two).
//! 5. **The dynamics have unity static gain** (the static gain lives in the static map), and the
//!    plant's delay carries the thesis' 85 us (plus any extra delay the model file asks for).
//! 6. **A second resonance** (the "two peaks near 5.7 kHz", sec. 4.1.1, not in eq. 4.4), when
//!    switched on, is a unity-gain second-order section in series after the stage mode. The
//!    pole, both modes and the delay are then discretised together as one 5-state system, exact
//!    for the held input like [`LinearPlant`] (a series section discretised on its own would see
//!    the plant's output as held, which it is not: 4 % error at 6.3 kHz during fast edges).
//! 7. **Sensor last**: gain, seeded noise and the 16-bit ADC.
//!
//! # Switchable effects
//! Every effect the model-gap workflow (issue #7) names is a field of [`StageConfig`]:
//! `time-delay` = `delay_s` (0 is off), `amplifier-pole` = `amp_pole_hz` (`None` is off),
//! `resonance` = `second_mode` (the stage's own mode is always there), `drift` = `drift`,
//! `hysteresis` = `hysteresis` (the table), `nonlinear-gain` = `nonlinear_gain`,
//! `slew-rate-limit` = `amplifier.slew_v_per_s`, `saturation` = `amplifier.saturation`.
//! The converters are `dac` and `sensor.adc`, the noise `sensor.noise_v`.
//!
//! # Cost
//! Fixed per step: a DAC rounding, the amplifier (4 compares), one table look-up when the
//! hysteresis is on (bounded by its own design), two polynomials, three compensated lags, the
//! 3-state plant with its delay line, the optional 2-state mode, one SplitMix64 draw and an ADC
//! rounding. No allocation, no loops that depend on history, no panics. `Stage` and
//! `StageState` are plain `Copy` values (no heap): a QEMU smoke run can hold them in a static.

use crate::amplifier::{Amplifier, AmplifierConfig, AmplifierState};
use crate::codes::DacCode;
use crate::discretize::zoh_delayed;
use crate::drift::{Drift, DriftConfig, DriftState};
use crate::gain::{FastGain, FastGainConfig};
use crate::held::HeldMap;
use crate::hysteresis::{HysteresisMemory, HysteresisTable};
use crate::limits::clamp_f32;
use crate::limits::{ConfigError, check_finite, check_period, check_range};
use crate::params;
use crate::plant::{
    LinearPlant, LinearPlantConfig, MAX_DELAY_SAMPLES, PlantState, continuous_state_space,
};
use crate::play::{Play, PlayConfig, PlayState};
use crate::sections::Accumulator;
use crate::sensor::{Sensor, SensorConfig, SensorState};
use core::f64::consts::PI;
use core::ops::Bound::{Excluded, Included};

/// A second-order mode `wn^2 / (s^2 + 2 zeta wn s + wn^2)` (unity static gain).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModeConfig {
    /// Natural frequency, Hz.
    pub mode_hz: f64,
    /// Damping ratio.
    pub damping: f64,
}

/// The whole stage, design-time form (`f64`). Each effect is a field that can be switched off.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StageConfig {
    /// Fixed step, seconds (10..200 kHz).
    pub period_s: f64,
    /// Quantise the command to the 14-bit DAC (+-10 V) before the amplifier.
    pub dac: bool,
    /// The E-505: ranges (`saturation`) and slew limiter (`slew-rate-limit`).
    pub amplifier: AmplifierConfig,
    /// Static gain of the fast part without hysteresis, sensor volts per volt (0.79, eq. 4.4).
    /// With a hysteresis table the table's own curve replaces it.
    pub static_gain: f64,
    /// The hysteresis table (`hysteresis`; `None`: the fast part is `static_gain * ue`).
    pub hysteresis: Option<HysteresisTable>,
    /// The play-operator hysteresis the model-gap workflow fits (`hysteresis`,
    /// [`crate::play`]), added to the fast map before K'(u); `None`: off.
    pub play: Option<PlayConfig>,
    /// K'(u), the fast part's amplitude-dependent gain (`nonlinear-gain`).
    pub nonlinear_gain: Option<FastGainConfig>,
    /// The drift branch (`drift`).
    pub drift: Option<DriftConfig>,
    /// The amplifier's "electrical" pole, Hz (`amplifier-pole`; `None`: no pole).
    pub amp_pole_hz: Option<f64>,
    /// The stage's own ("inertial") mode of eq. 4.4.
    pub mode: ModeConfig,
    /// A second mode in series (`resonance`).
    pub second_mode: Option<ModeConfig>,
    /// Pure delay, seconds (`time-delay`; 0 is off).
    pub delay_s: f64,
    /// The sensor monitor and ADC.
    pub sensor: SensorConfig,
}

impl StageConfig {
    /// Eq. 4.4 alone (the built-in model `thesis-linear`): delay, 2 kHz pole, stage mode,
    /// gain 0.79; amplifier limits, converters and noise off, so that it is exactly the linear
    /// model the controller was designed on.
    pub fn thesis_linear() -> Self {
        Self {
            period_s: params::STAGE_PERIOD_S,
            dac: false,
            amplifier: AmplifierConfig {
                slew_v_per_s: None,
                saturation: false,
                ..AmplifierConfig::default()
            },
            static_gain: params::PLANT_GAIN,
            hysteresis: None,
            play: None,
            nonlinear_gain: None,
            drift: None,
            amp_pole_hz: Some(params::AMP_POLE_HZ),
            mode: ModeConfig {
                mode_hz: params::STAGE_MODE_HZ,
                damping: params::STAGE_DAMPING,
            },
            second_mode: None,
            delay_s: params::PLANT_DELAY_S,
            sensor: SensorConfig {
                noise_v: 0.0,
                adc: false,
                ..SensorConfig::default()
            },
        }
    }

    /// The ch. 6 overall model: eq. 4.4 plus the default hysteresis table
    /// ([`HysteresisTable::thesis_default`]), drift, K'(u), the amplifier's ranges and slew
    /// limiter, the converters and the sensor noise.
    pub fn thesis_full() -> Self {
        Self {
            dac: true,
            hysteresis: Some(HysteresisTable::thesis_default()),
            amplifier: AmplifierConfig::default(),
            nonlinear_gain: Some(FastGainConfig::default()),
            drift: Some(DriftConfig::default()),
            sensor: SensorConfig::default(),
            ..Self::thesis_linear()
        }
    }

    /// The linear plant this configuration uses (unity static gain).
    pub fn plant_config(&self) -> LinearPlantConfig {
        let nyquist = 0.5 / self.period_s;
        LinearPlantConfig {
            gain: 1.0,
            // "No pole": the largest the plant accepts, 10x Nyquist, settles within a step.
            amp_pole_hz: self.amp_pole_hz.unwrap_or(9.99 * nyquist),
            mode_hz: self.mode.mode_hz,
            damping: self.mode.damping,
            delay_s: self.delay_s,
            period_s: self.period_s,
        }
    }
}

/// The dynamics with a second mode: amplifier pole, stage mode and the second mode in series,
/// as one 5-state system discretised exactly for the held (delayed) input, like
/// [`LinearPlant`] does for 3 states. States: pole output `p`, position `x`, velocity / wn,
/// second-mode output `z`, its velocity / w2.
#[derive(Clone, Copy, Debug, PartialEq)]
struct TwoModes {
    phi: [[f32; 5]; 5],
    gamma_new: [f32; 5],
    gamma_old: [f32; 5],
    delay_samples: usize,
}

/// State of [`TwoModes`]: five states and the delay line.
#[derive(Clone, Copy, Debug, PartialEq)]
struct TwoModesState {
    x: [f32; 5],
    line: [f32; MAX_DELAY_SAMPLES],
    head: usize,
}

impl TwoModesState {
    /// The state as a held stretch's closed form advances it ([`crate::held`]).
    fn section(&mut self) -> crate::held::SectionState<'_, 5, MAX_DELAY_SAMPLES> {
        crate::held::SectionState {
            x: &mut self.x,
            line: &mut self.line,
            head: &mut self.head,
        }
    }
}

impl TwoModes {
    fn new(p: &LinearPlantConfig, m: &ModeConfig) -> Result<Self, ConfigError> {
        // The 3-state part is checked by LinearPlant::new (called by Stage::new first).
        check_finite("second_mode.mode_hz", m.mode_hz)?;
        check_finite("second_mode.damping", m.damping)?;
        check_range(
            "second_mode.mode_hz",
            m.mode_hz,
            Excluded(0.0),
            Excluded(0.5 / p.period_s),
        )?;
        check_range(
            "second_mode.damping",
            m.damping,
            Excluded(0.0),
            Included(10.0),
        )?;
        let (a3, b3) = continuous_state_space(p);
        let w2 = 2.0 * PI * m.mode_hz;
        let mut a = [[0.0; 5]; 5];
        for i in 0..3 {
            a[i][..3].copy_from_slice(&a3[i]);
        }
        a[3][4] = w2;
        a[4][1] = w2;
        a[4][3] = -w2;
        a[4][4] = -2.0 * m.damping * w2;
        let b = [b3[0], b3[1], b3[2], 0.0, 0.0];
        let (phi, gn, go, d) = zoh_delayed::<5, 6>(&a, &b, p.period_s, p.delay_s);
        let f = |v: [f64; 5]| v.map(|x| x as f32);
        Ok(Self {
            phi: phi.map(f),
            gamma_new: f(gn),
            gamma_old: f(go),
            delay_samples: d.min(MAX_DELAY_SAMPLES - 2),
        })
    }

    /// The coefficients as a held stretch's closed form reads them ([`crate::held`]).
    fn section(&self) -> crate::held::Section<'_, 5> {
        crate::held::Section {
            phi: &self.phi,
            gamma_new: &self.gamma_new,
            gamma_old: &self.gamma_old,
            delay_samples: self.delay_samples,
        }
    }

    /// The (unused) state when the second mode is off.
    fn idle() -> TwoModesState {
        TwoModesState {
            x: [0.0; 5],
            line: [0.0; MAX_DELAY_SAMPLES],
            head: 0,
        }
    }

    fn steady_state(&self, d: f32) -> TwoModesState {
        TwoModesState {
            x: [d, d, 0.0, d, 0.0],
            line: [d; MAX_DELAY_SAMPLES],
            head: 0,
        }
    }

    #[inline]
    fn step(&self, s: &mut TwoModesState, u: f32) -> f32 {
        let n = MAX_DELAY_SAMPLES;
        s.head = (s.head + 1) % n;
        if let Some(slot) = s.line.get_mut(s.head) {
            *slot = u;
        }
        let u_new = s
            .line
            .get((s.head + n - self.delay_samples) % n)
            .copied()
            .unwrap_or(u);
        let u_old = s
            .line
            .get((s.head + n - self.delay_samples - 1) % n)
            .copied()
            .unwrap_or(u);
        let x = s.x;
        for (i, xi) in s.x.iter_mut().enumerate() {
            let row = &self.phi[i];
            *xi = row[0] * x[0]
                + row[1] * x[1]
                + row[2] * x[2]
                + row[3] * x[3]
                + row[4] * x[4]
                + self.gamma_new[i] * u_new
                + self.gamma_old[i] * u_old;
        }
        s.x[3]
    }
}

/// The stage, run-time form: coefficients only (`Copy`, `f32`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stage {
    dac: bool,
    amplifier: Amplifier,
    inv_nominal_gain: f32,
    static_gain: f32,
    hysteresis: Option<HysteresisTable>,
    play: Option<Play>,
    nonlinear_gain: Option<FastGain>,
    drift: Option<Drift>,
    plant: LinearPlant,
    second_mode: Option<TwoModes>,
    sensor: Sensor,
    /// The fingerprint a [`HeldMap`] built for this stage carries ([`crate::held`]).
    held_key: u64,
}

/// Everything the stage remembers between steps, and the signals of the last step.
/// (`Clone`, not `Copy`: the hysteresis memory is a bounded `heapless` stack.)
#[derive(Clone, Debug, PartialEq)]
pub struct StageState {
    amplifier: AmplifierState,
    hysteresis: HysteresisMemory,
    play: PlayState,
    drift: DriftState,
    plant: PlantState,
    second_mode: TwoModesState,
    sensor: SensorState,
    signals: Signals,
}

/// The internal signals of the last step, for tests and plots.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Signals {
    /// Command after the DAC, volts at the amplifier input.
    pub command_v: f32,
    /// Amplifier output, volts (-20..120 V with saturation on).
    pub amplifier_v: f32,
    /// Fast static displacement (hysteresis or 0.79 ue, times K'), sensor volts.
    pub fast_v: f32,
    /// Drift, sensor volts.
    pub drift_v: f32,
    /// Position before the sensor, sensor volts (no noise, no ADC).
    pub position_v: f32,
    /// Sensor monitor reading, volts.
    pub measured_v: f32,
}

impl StageState {
    /// The signals of the last step.
    pub fn signals(&self) -> &Signals {
        &self.signals
    }
}

impl Stage {
    /// Checks and discretises `cfg`.
    ///
    /// ```
    /// use model_core::stage::{Stage, StageConfig};
    /// let stage = Stage::new(&StageConfig::thesis_linear()).unwrap();
    /// let mut s = stage.steady_state(0.0);
    /// let mut y = 0.0;
    /// for _ in 0..5000 {
    ///     y = stage.step(&mut s, 1.0);
    /// }
    /// assert!((y - 0.79).abs() < 1e-4);
    /// ```
    pub fn new(cfg: &StageConfig) -> Result<Self, ConfigError> {
        let t = check_period(cfg.period_s)?;
        check_finite("static_gain", cfg.static_gain)?;
        check_finite("delay_s", cfg.delay_s)?;
        check_range(
            "static_gain",
            cfg.static_gain,
            Excluded(0.05),
            Excluded(20.0),
        )?;
        check_range(
            "delay_s",
            cfg.delay_s,
            Included(0.0),
            Included(params::MAX_DELAY_S),
        )?;
        Ok(Self {
            dac: cfg.dac,
            amplifier: Amplifier::new(&cfg.amplifier, t)?,
            inv_nominal_gain: (1.0 / params::AMP_GAIN) as f32,
            static_gain: cfg.static_gain as f32,
            hysteresis: cfg.hysteresis,
            play: cfg.play.as_ref().map(Play::new).transpose()?,
            nonlinear_gain: cfg.nonlinear_gain.as_ref().map(FastGain::new).transpose()?,
            drift: cfg.drift.as_ref().map(|d| Drift::new(d, t)).transpose()?,
            plant: LinearPlant::new(&cfg.plant_config())?,
            second_mode: cfg
                .second_mode
                .as_ref()
                .map(|m| TwoModes::new(&cfg.plant_config(), m))
                .transpose()?,
            sensor: Sensor::new(&cfg.sensor)?,
            held_key: 0,
        }
        .keyed())
    }

    /// `self` with [`Self::held_key`] computed: the fingerprint of the coefficients a
    /// [`HeldMap`] is built from (the section's, the lags'), so that a map built for another
    /// stage is not applied to this one.
    fn keyed(mut self) -> Self {
        let ratios = self.held_ratios();
        self.held_key = match &self.second_mode {
            Some(m) => crate::held::fingerprint(&m.section(), ratios),
            None => crate::held::fingerprint(&self.plant.section(), ratios),
        };
        self
    }

    /// The drift lags' ratios `1 - alpha` (0 without a drift: its errors are 0 too).
    fn held_ratios(&self) -> [f64; 3] {
        self.drift
            .as_ref()
            .map_or([0.0; 3], |d| d.lags.map(|l| 1.0 - l.alpha as f64))
    }

    /// The amplifier block (its limits, for checks).
    pub fn amplifier(&self) -> &Amplifier {
        &self.amplifier
    }

    /// The drift block, if on.
    pub fn drift(&self) -> Option<&Drift> {
        self.drift.as_ref()
    }

    /// The command as the DAC delivers it.
    #[inline]
    fn dac(&self, u_v: f32) -> f32 {
        if self.dac {
            DacCode::from_volts(u_v).volts()
        } else {
            u_v
        }
    }

    /// The amplifier's output in control-input volts (`ue`, what the static map and the drift
    /// take): one expression for every caller, so that [`Self::step_held`] computes the `ue`
    /// [`Self::step`] does, to the bit.
    #[inline]
    fn control_input_v(&self, amplifier_v: f32) -> f32 {
        amplifier_v * self.inv_nominal_gain
    }

    /// K'(u) times `h`, or `h` without the non-linear gain.
    #[inline]
    fn scale(&self, ue_v: f32, h: f32) -> f32 {
        match &self.nonlinear_gain {
            Some(g) => g.gain(ue_v) * h,
            None => h,
        }
    }

    /// The fast static map without hysteresis (`static_gain K'(ue) ue`).
    #[inline]
    fn fast_memoryless(&self, ue_v: f32) -> f32 {
        self.scale(ue_v, self.static_gain * ue_v)
    }

    /// The fast static map for the amplifier output in control-input volts; advances the
    /// hysteresis memory.
    #[inline]
    fn fast(&self, mem: &mut HysteresisMemory, ue_v: f32) -> f32 {
        match &self.hysteresis {
            Some(t) => {
                // A held input (holds, or a slow signal between two DAC codes) changes nothing
                // in the table's memory: reuse its last output instead of a look-up.
                let h = if ue_v == mem.input_v() && mem.depth() > 0 {
                    mem.output_v()
                } else {
                    t.forward(mem, ue_v)
                };
                self.scale(ue_v, h)
            }
            None => self.fast_memoryless(ue_v),
        }
    }

    /// The static displacement, sensor volts, reached with `u_v` held for ever (drift
    /// settled; with hysteresis: on the major rising curve, as after [`Self::steady_state`]):
    /// what the plant's output settles to (before the sensor).
    pub fn static_output(&self, u_v: f32) -> f32 {
        let ue = self.control_input_v(self.amplifier.static_output(self.dac(u_v)));
        let drift = self
            .drift
            .as_ref()
            .map_or(0.0, |d| d.output(&d.steady_state(ue)));
        let mut mem = HysteresisMemory::new();
        if let Some(t) = &self.hysteresis {
            mem.reset(t, ue);
        }
        self.fast(&mut mem, ue) + drift
    }

    /// The input, volts at the amplifier, at which [`Self::static_output`] is `y_v`: the
    /// operating point of a loop holding `y_v`. Bisection over `[lo_v, hi_v]` (the static map
    /// is strictly increasing); outside the map's range, or for a non-finite `y_v`, the nearer
    /// end (`lo_v` for NaN). Design time, bounded (32 halvings: below f32 resolution).
    pub fn static_input(&self, y_v: f32, lo_v: f32, hi_v: f32) -> f32 {
        bisect_increasing(|u| self.static_output(u), y_v, lo_v, hi_v)
    }

    /// The hysteresis table, if on.
    pub fn hysteresis(&self) -> Option<&HysteresisTable> {
        self.hysteresis.as_ref()
    }

    /// A state at rest with `u_v` held for ever (drift settled, hysteresis on the major rising
    /// curve as after coming up from the bottom of its range, sensor noise from the seed).
    pub fn steady_state(&self, u_v: f32) -> StageState {
        self.steady_state_after(&[], u_v)
    }

    /// As [`Self::steady_state`], but the hysteresis memory is that of a stage that came up
    /// from the bottom of the table's range through the turning points `history_v` (amplifier
    /// control-input volts) before coming to rest at `u_v` ([`HysteresisMemory::reset_after`]);
    /// the other blocks are at rest at `u_v` as in [`Self::steady_state`]. Without a table
    /// the history changes nothing.
    pub fn steady_state_after(&self, history_v: &[f32], u_v: f32) -> StageState {
        let u_v = if u_v.is_finite() { u_v } else { 0.0 };
        let command_v = self.dac(u_v);
        let amplifier = self.amplifier.steady_state(command_v);
        let ue = self.control_input_v(amplifier.output_v);
        let drift = self
            .drift
            .as_ref()
            .map_or(DriftState::default(), |d| d.steady_state(ue));
        let mut hysteresis = HysteresisMemory::new();
        if let Some(t) = &self.hysteresis {
            hysteresis.reset_after(t, history_v, ue);
        }
        let fast_v = self.fast(&mut hysteresis, ue);
        let drift_v = self.drift.as_ref().map_or(0.0, |d| d.output(&drift));
        let d = fast_v + drift_v;
        // The position and the reading at rest are those the first step would give with the
        // input held: the play operators at rest add nothing and the plant and the two modes
        // have unity static gain, so the position is `d`, read through the sensor. Before
        // session 39 the reading was `d` too: the first sample of every simulation lacked the
        // sensor's scale, offset and ADC (a model with a 12 mV offset read 12 mV off at t = 0).
        StageState {
            amplifier,
            hysteresis,
            play: self
                .play
                .as_ref()
                .map_or(PlayState::default(), |p| p.steady_state(ue)),
            drift,
            plant: self.plant.steady_state(d),
            second_mode: match &self.second_mode {
                Some(m) => m.steady_state(d),
                None => TwoModes::idle(),
            },
            sensor: self.sensor.initial_state(),
            signals: Signals {
                command_v,
                amplifier_v: amplifier.output_v,
                fast_v,
                drift_v,
                position_v: d,
                measured_v: self.sensor.reading_at_rest(d),
            },
        }
    }

    /// Apply the command `u_v` (volts at the amplifier input, held for one step), advance one
    /// step and return the sensor monitor reading. A non-finite command holds the amplifier's
    /// output (see [`crate::amplifier`]).
    #[inline]
    pub fn step(&self, s: &mut StageState, u_v: f32) -> f32 {
        let command_v = self.dac(u_v);
        let amplifier_v = self.amplifier.step(&mut s.amplifier, command_v);
        let ue = self.control_input_v(amplifier_v);
        let mut fast_v = self.fast(&mut s.hysteresis, ue);
        if let Some(p) = &self.play {
            fast_v += self.scale(ue, p.step(&mut s.play, ue));
        }
        let drift_v = match &self.drift {
            Some(d) => d.step(&mut s.drift, ue),
            None => 0.0,
        };
        let position_v = match &self.second_mode {
            Some(m) => m.step(&mut s.second_mode, fast_v + drift_v),
            None => self.plant.step(&mut s.plant, fast_v + drift_v),
        };
        let measured_v = self.sensor.measure(&mut s.sensor, position_v);
        s.signals = Signals {
            command_v,
            amplifier_v,
            fast_v,
            drift_v,
            position_v,
            measured_v,
        };
        measured_v
    }

    /// `n` steps of [`Self::step`] with the command `u_v` held: the same state and the same
    /// reading, to the bit, in fewer operations (the host's simulations of records sampled
    /// slower than the stage: a 1 kHz record holds each input for 50 steps).
    ///
    /// Once a step leaves the amplifier's output where it was and the hysteresis table will
    /// reuse its last output (or there is no table), the fast part is at a fixed point: the
    /// DAC and the amplifier give the same `ue`, the table the same output, the play
    /// operators (clamps, so applying the same input twice is applying it once) the same
    /// sum, K'(u) and the drift's weight the same values. The remaining steps then advance
    /// only the drift's lags and the dynamics with that value, and read the sensor (a pure
    /// function without noise) once at the end; with noise, every step, so that the noise
    /// sequence is the one `n` calls of [`Self::step`] draw. Bounded: `n` steps at most; no
    /// panic. Not for the 50 kHz path (the board steps once per sample).
    ///
    /// [`Self::settle_held`] and [`Self::finish_held`] are its two halves, for a caller that
    /// takes the remaining steps in closed form ([`HeldMap`]).
    pub fn step_held(&self, s: &mut StageState, u_v: f32, n: u32) -> f32 {
        let left = self.settle_held(s, u_v, n);
        self.finish_held(s, left, None)
    }

    /// The first half of [`Self::step_held`]: whole steps of `u_v` until the fast part is at
    /// its fixed point, `n` at most. Returns the steps left of `n`; the reading so far is in
    /// [`StageState::signals`].
    pub fn settle_held(&self, s: &mut StageState, u_v: f32, n: u32) -> u32 {
        let mut left = n;
        while left > 0 {
            let before_v = s.amplifier.output_v;
            self.step(s, u_v);
            left -= 1;
            let ue = self.control_input_v(s.signals.amplifier_v);
            let table_reuses = match &self.hysteresis {
                Some(_) => s.hysteresis.depth() > 0 && ue == s.hysteresis.input_v(),
                None => true,
            };
            if s.amplifier.output_v.to_bits() == before_v.to_bits() && table_reuses {
                break;
            }
        }
        left
    }

    /// The second half of [`Self::step_held`]: `left` more steps of the input held, the fast
    /// part at its fixed point ([`Self::settle_held`] got it there). Stepped, to the bit, or
    /// with `map` (this stage's [`Self::held_map`] of `left` steps) in closed form: one
    /// product, the same to well under an ADC code ([`crate::held`]). The map is not used
    /// with sensor noise (each step draws from it) nor when it was built for another length
    /// or stage; the stretch is then stepped. Returns the reading at the end.
    pub fn finish_held(&self, s: &mut StageState, left: u32, map: Option<&HeldMap>) -> f32 {
        if left == 0 {
            return s.signals.measured_v;
        }
        let fast_v = s.signals.fast_v;
        let ue = self.control_input_v(s.signals.amplifier_v);
        let weight = self.drift.as_ref().map(|d| d.weight(ue));
        let noisy = self.sensor.is_noisy();
        if let Some(m) = map.filter(|m| m.steps() == left && !noisy)
            && self.finish_held_closed(s, weight, m)
        {
            return s.signals.measured_v;
        }
        let mut measured_v = s.signals.measured_v;
        let mut drift_v = s.signals.drift_v;
        let mut position_v = s.signals.position_v;
        for _ in 0..left {
            if let (Some(d), Some(w)) = (&self.drift, weight) {
                drift_v = d.advance(&mut s.drift, w);
            }
            position_v = match &self.second_mode {
                Some(m) => m.step(&mut s.second_mode, fast_v + drift_v),
                None => self.plant.step(&mut s.plant, fast_v + drift_v),
            };
            if noisy {
                measured_v = self.sensor.measure(&mut s.sensor, position_v);
            }
        }
        if !noisy {
            measured_v = self.sensor.measure(&mut s.sensor, position_v);
        }
        s.signals.drift_v = drift_v;
        s.signals.position_v = position_v;
        s.signals.measured_v = measured_v;
        measured_v
    }

    /// The closed form of [`Self::finish_held`]; `false` (nothing changed) when `map` was
    /// built for another stage (its section's or its lags' coefficients differ).
    fn finish_held_closed(&self, s: &mut StageState, weight: Option<f32>, map: &HeldMap) -> bool {
        if map.key() != self.held_key {
            return false;
        }
        // The lags' targets `g w` (in f32, as a step computes them) and their errors.
        let mut targets = [0.0f64; 3];
        let mut errors = [0.0f64; 3];
        let level = match (&self.drift, weight) {
            (Some(d), Some(w)) => {
                let w = if w.is_finite() { w } else { 0.0 };
                for (j, (lag, y)) in d.lags.iter().zip(&s.drift.y).enumerate() {
                    targets[j] = (lag.gain * w) as f64;
                    errors[j] = y.exact() - targets[j];
                }
                s.signals.fast_v as f64 + targets.iter().sum::<f64>()
            }
            _ => (s.signals.fast_v + s.signals.drift_v) as f64,
        };
        let position_v = match &self.second_mode {
            Some(_) => {
                map.apply(s.second_mode.section(), level, errors);
                s.second_mode.x[3]
            }
            None => {
                map.apply(s.plant.section(), level, errors);
                self.plant.output(&s.plant)
            }
        };
        if let Some(d) = &self.drift
            && weight.is_some()
        {
            let decay = map.decay();
            for (j, y) in s.drift.y.iter_mut().enumerate() {
                *y = Accumulator::from_exact(targets[j] + errors[j] * decay[j]);
            }
            s.signals.drift_v = d.output(&s.drift);
        }
        s.signals.position_v = position_v;
        s.signals.measured_v = self.sensor.measure(&mut s.sensor, position_v);
        true
    }

    /// The closed form of `steps` held steps past the fast part's fixed point, for
    /// [`Self::finish_held`] (host use: built in `f64`, `steps` steps of a small product).
    /// `None` for 0 steps, and with sensor noise (each step draws from it, so
    /// [`Self::finish_held`] steps).
    pub fn held_map(&self, steps: u32) -> Option<HeldMap> {
        if self.sensor.is_noisy() {
            return None;
        }
        let ratios = self.held_ratios();
        match &self.second_mode {
            Some(m) => HeldMap::build(&m.section(), ratios, steps, self.held_key),
            None => HeldMap::build(&self.plant.section(), ratios, steps, self.held_key),
        }
    }
}

/// Open-loop feedforward of the static map and the drift (issue #4, item 8): the command that
/// makes the model's quasi-static output follow a wanted position.
///
/// Per step, with `r` the wanted output (sensor volts):
/// 1. the drift the model predicts from the commands already sent is `D` (its own copy of the
///    drift branch, driven by its own output, so no sensor is needed);
/// 2. the fast part must supply `r - D`; the command is the inverse of the fast static map at
///    that value:
///    * without hysteresis, `0.79 K'(u) u` (strictly increasing by [`FastGainConfig::validate`])
///      is inverted by bisection over `[lo_v, hi_v]` (32 halvings: bounded, below 1 uV);
///    * with hysteresis, `K'(u) H(u)`: the table's own inverse
///      ([`HysteresisTable::inverse`], its own memory kept in step) is asked for
///      `(r - D) / K'(u_last)`, with K' taken at the last command (K' changes by under 1e-5 per
///      step at 1500 V/ms, so the lag is invisible), then clamped to `[lo_v, hi_v]`;
/// 3. the drift branch is advanced with that command.
///
/// The drift estimate is one step old when the command is computed (no algebraic loop); its
/// fastest lag (60 ms) moves by 3e-4 of its span per step, far below the DAC's resolution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Feedforward {
    stage: Stage,
    lo_v: f32,
    hi_v: f32,
}

/// The feedforward's own drift state, hysteresis memory and last command.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FeedforwardState {
    drift: DriftState,
    hysteresis: HysteresisMemory,
    last_v: f32,
}

impl Feedforward {
    /// A feedforward inverting the static map and drift of `stage`, with commands kept in
    /// `[lo_v, hi_v]` (for example the safe window 0..10 V).
    pub fn new(stage: &Stage, lo_v: f32, hi_v: f32) -> Result<Self, ConfigError> {
        check_finite("lo_v", lo_v as f64)?;
        check_finite("hi_v", hi_v as f64)?;
        if lo_v >= hi_v {
            return Err(ConfigError::not_below("lo_v", "hi_v"));
        }
        Ok(Self {
            stage: *stage,
            lo_v,
            hi_v,
        })
    }

    /// The state at rest with `u_v` held.
    pub fn steady_state(&self, u_v: f32) -> FeedforwardState {
        let mut hysteresis = HysteresisMemory::new();
        if let Some(t) = &self.stage.hysteresis {
            hysteresis.reset(t, u_v);
        }
        FeedforwardState {
            hysteresis,
            last_v: u_v,
            drift: self
                .stage
                .drift
                .as_ref()
                .map_or(DriftState::default(), |d| d.steady_state(u_v)),
        }
    }

    /// The command for the wanted output `r_v`. A non-finite `r_v` gives `lo_v`.
    #[inline]
    pub fn step(&self, s: &mut FeedforwardState, r_v: f32) -> f32 {
        let drift_v = self
            .stage
            .drift
            .as_ref()
            .map_or(0.0, |d| d.output(&s.drift));
        let want = r_v - drift_v;
        let (a, b) = (self.lo_v, self.hi_v);
        let st = &self.stage;
        let u = if let Some(t) = &st.hysteresis {
            let k = st.scale(s.last_v, 1.0);
            let u = t.inverse(&mut s.hysteresis, want / k);
            // The table clamps to its own range; the window may be narrower.
            clamp_f32(u, a, b)
        } else {
            bisect_increasing(|u| st.fast_memoryless(u), want, a, b)
        };
        s.last_v = u;
        if let Some(d) = &self.stage.drift {
            d.step(&mut s.drift, u);
        }
        u
    }
}

/// The `u` in `[lo, hi]` where the increasing `f` reaches `want`, by 32 halvings (below f32
/// resolution over the amplifier's range); the nearer end if `want` lies outside
/// `f([lo, hi])`, `lo` if it is not finite. Bounded: no panic, no unbounded loop.
fn bisect_increasing(f: impl Fn(f32) -> f32, want: f32, lo: f32, hi: f32) -> f32 {
    let (mut a, mut b) = (lo, hi);
    if !want.is_finite() || f(a) >= want {
        return a;
    }
    if f(b) <= want {
        return b;
    }
    for _ in 0..32 {
        let m = 0.5 * (a + b);
        if f(m) < want {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

#[cfg(test)]
mod held_tests {
    //! The closed form of a hold ([`crate::held`]) against an `f64` reference: the same
    //! recursions as [`Stage::finish_held`]'s steps (the section's own `f32` coefficients,
    //! promoted; the lags' `y + alpha (g w - y)`), run in `f64`, one step at a time.
    use super::*;

    /// What the reference leaves after a hold: the section's states, the lags' values, and
    /// the section's inputs, newest last.
    struct Reference<const P: usize> {
        x: [f64; P],
        lags: [f64; 3],
        inputs: std::vec::Vec<f64>,
    }

    /// `n` held steps of the lags and the section in `f64`, from `s` (the fast part at its
    /// fixed point), the section's state given as its states, line and head.
    fn reference<const P: usize>(
        sec: &crate::held::Section<'_, P>,
        stage: &Stage,
        s: &StageState,
        (x_f32, line, head): (&[f32; P], &[f32; MAX_DELAY_SAMPLES], usize),
        n: u32,
    ) -> Reference<P> {
        let d = sec.delay_samples;
        let ue = stage.control_input_v(s.signals.amplifier_v);
        let mut x = x_f32.map(|v| v as f64);
        // The inputs, oldest first: the line's last d + 1, then each step's.
        let mut inputs: std::vec::Vec<f64> = (0..=d)
            .rev()
            .map(|m| line[(head + MAX_DELAY_SAMPLES - m) % MAX_DELAY_SAMPLES] as f64)
            .collect();
        let mut y = s.drift.y.map(|a| a.exact());
        for _ in 0..n {
            let level = match &stage.drift {
                Some(drift) => {
                    let w = drift.weight(ue);
                    for (yj, lag) in y.iter_mut().zip(&drift.lags) {
                        *yj += lag.alpha as f64 * ((lag.gain * w) as f64 - *yj);
                    }
                    s.signals.fast_v as f64 + y.iter().sum::<f64>()
                }
                None => (s.signals.fast_v + s.signals.drift_v) as f64,
            };
            inputs.push(level);
            let k = inputs.len() - 1;
            let (u_new, u_old) = (inputs[k - d], inputs[k - d - 1]);
            let before = x;
            for (i, xi) in x.iter_mut().enumerate() {
                *xi = sec.gamma_new[i] as f64 * u_new + sec.gamma_old[i] as f64 * u_old;
                for (p, b) in sec.phi[i].iter().zip(&before) {
                    *xi += *p as f64 * b;
                }
            }
        }
        Reference { x, lags: y, inputs }
    }

    /// Within half an `f32` step of a value below 16 V: the closed form rounds once.
    const HALF_STEP_V: f64 = 4.8e-7;

    /// The closed form's section state (states, line, head) against the reference: the states
    /// and the last `d + 2` inputs of the line (all that later steps read) within
    /// [`HALF_STEP_V`], the head where `n` steps leave it.
    fn check<const P: usize>(
        what: &str,
        r: &Reference<P>,
        (x, line, head): (&[f32; P], &[f32; MAX_DELAY_SAMPLES], usize),
        (head0, n, d): (usize, u32, usize),
    ) {
        for (i, (g, w)) in x.iter().zip(&r.x).enumerate() {
            let g = *g as f64;
            assert!(
                (g - w).abs() < HALF_STEP_V,
                "{what}: state {i}: {g} against {w}"
            );
        }
        assert_eq!(
            head,
            (head0 + n as usize) % MAX_DELAY_SAMPLES,
            "{what}: head"
        );
        for m in 0..(d + 2).min(n as usize) {
            let g = line[(head + MAX_DELAY_SAMPLES - m) % MAX_DELAY_SAMPLES] as f64;
            let w = r.inputs[r.inputs.len() - 1 - m];
            assert!(
                (g - w).abs() < HALF_STEP_V,
                "{what}: input of age {m}: {g} against {w}"
            );
        }
    }

    /// From a state reached by a step to 8 V after a ramp, 1, 3, 37, 2000 and 50 000 held
    /// steps in closed form (fewer than the delay, about a 1 kHz sample, the host's longest)
    /// leave the section's states, its line's inputs and the lags within half an `f32` step
    /// of the `f64` reference (the closed form keeps full `f32` precision: it rounds once, at
    /// the end), and the head where the steps leave it: on the plant and on the two modes,
    /// with and without a drift. Stepping in `f32` instead drifts from the reference by more
    /// on the lightly damped two modes (printed).
    #[test]
    fn a_hold_in_closed_form_matches_the_f64_reference() {
        for (second, drift) in [(false, true), (true, true), (false, false), (true, false)] {
            let mut cfg = StageConfig::thesis_full();
            cfg.sensor.noise_v = 0.0;
            cfg.hysteresis = Some(HysteresisTable::thesis_default());
            if !drift {
                cfg.drift = None;
            }
            if second {
                cfg.second_mode = Some(ModeConfig {
                    mode_hz: params::SECOND_MODE_HZ,
                    damping: params::SECOND_MODE_DAMPING,
                });
            }
            let stage = Stage::new(&cfg).unwrap();
            for n in [1u32, 3, 37, 2000, 50_000] {
                let what = std::format!("second mode {second}, drift {drift}, {n} steps");
                let mut s = stage.steady_state(1.0);
                for k in 0..500 {
                    stage.step(&mut s, 1.0 + 0.01 * k as f32);
                }
                let left = stage.settle_held(&mut s, 8.0, n + 2);
                assert_eq!(left, n, "{what}: the fixed point after two steps");
                let map = stage.held_map(n).unwrap();
                let mut closed = s.clone();
                stage.finish_held(&mut closed, n, Some(&map));
                let lags = if let Some(m) = &stage.second_mode {
                    let (st, c) = (&s.second_mode, &closed.second_mode);
                    let r = reference(&m.section(), &stage, &s, (&st.x, &st.line, st.head), n);
                    let d = m.delay_samples;
                    check(&what, &r, (&c.x, &c.line, c.head), (st.head, n, d));
                    let mut stepped = s.clone();
                    stage.finish_held(&mut stepped, n, None);
                    let worst = (0..5)
                        .map(|i| (stepped.second_mode.x[i] as f64 - r.x[i]).abs())
                        .fold(0.0, f64::max);
                    std::println!("{what}: f32 stepping {worst:.2e} V off");
                    r.lags
                } else {
                    let (st, c) = (&s.plant, &closed.plant);
                    let r = reference(
                        &stage.plant.section(),
                        &stage,
                        &s,
                        (&st.x, &st.line, st.head),
                        n,
                    );
                    let d = stage.plant.delay_samples();
                    check(&what, &r, (&c.x, &c.line, c.head), (st.head, n, d));
                    r.lags
                };
                for (j, (a, w)) in closed.drift.y.iter().zip(lags).enumerate() {
                    assert!((a.exact() - w).abs() < HALF_STEP_V, "{what}: lag {j}");
                }
            }
        }
    }

    /// A map is applied only by the stage it was built for: one built for a stage whose
    /// drift is slower leaves the state as it was and the stretch is stepped (the same
    /// reading, to the bit, as without a map); with sensor noise no map is built.
    #[test]
    fn a_map_of_another_stage_is_not_applied() {
        let mut cfg = StageConfig::thesis_full();
        cfg.sensor.noise_v = 0.0;
        let stage = Stage::new(&cfg).unwrap();
        let mut slower = cfg;
        if let Some(d) = slower.drift.as_mut() {
            d.taus_s[2] *= 2.0;
        }
        let other = Stage::new(&slower).unwrap().held_map(48).unwrap();
        let mut s = stage.steady_state(1.0);
        let left = stage.settle_held(&mut s, 6.0, 50);
        let mut with = s.clone();
        let mut without = s.clone();
        let a = stage.finish_held(&mut with, left, Some(&other));
        let b = stage.finish_held(&mut without, left, None);
        assert_eq!(a.to_bits(), b.to_bits());
        assert_eq!(with, without);
        let noisy = Stage::new(&StageConfig::thesis_full()).unwrap();
        assert!(noisy.held_map(48).is_none());
    }
}
