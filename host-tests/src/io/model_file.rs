//! The model file: a TOML description of the virtual stage ([`model_core::stage`]), and the
//! built-in models.
//!
//! Every effect of the model-gap catalogue (issue #7) is an optional table named exactly like
//! the effect; **a table present means the effect is on**, with its parameters; a table absent
//! means off. Unknown keys and tables are refused (`deny_unknown_fields`), so a typo never
//! silently drops an effect. All values are SI with the unit in the key name.
//!
//! ```toml
//! # piezo model file
//! name = "thesis-full"            # free text
//! period_s = 2e-5                 # fixed simulation step (10..200 kHz)
//!
//! [plant]                         # eq. 4.4 without delay and 2 kHz pole: always present
//! static_gain = 0.79              # sensor V per amplifier-input V (used without hysteresis)
//! mode_hz = 5792.0                # the stage's own mode
//! damping = 0.08
//!
//! [amplifier]                     # E-505 (always present)
//! gain = 10.0
//!
//! [converters]                    # quantisation and sensor (always present)
//! dac = true                      # 14-bit DAC at the amplifier input
//! adc = true                      # 16-bit ADC on the monitor
//! sensor_gain = 1.0
//! noise_v = 0.0025                # 1-sigma sensor noise
//! seed = 1                        # noise generator seed (synth --seed overrides)
//!
//! [time-delay]                    # effect `time-delay`
//! delay_s = 8.5e-5
//!
//! [amplifier-pole]                # effect `amplifier-pole` (the 2 kHz "electrical" pole)
//! pole_hz = 2000.0
//!
//! [resonance]                     # effect `resonance`: a second mode in series
//! mode_hz = 6300.0
//! damping = 0.05
//!
//! [drift]                         # effect `drift`, eq. 5.1-5.3
//! gains = [0.05, 0.05, 0.055]
//! taus_s = [0.06, 0.75, 12.0]
//! poly = [0.6121, 0.5472, -0.1733, 0.014]   # K(u), lowest power first
//! poly_range_v = [0.0, 6.0]
//! # unsettled_v = -0.26          # optional: the creep had not settled at the records' first
//! #                               # input (added to every reading; model-gap step 12)
//!
//! [nonlinear-gain]                # effect `nonlinear-gain`, K'(u), lowest power first
//! poly = [1.0, 0.02, -0.001]      # (up to four more, the terms to u^6, are optional)
//! range_v = [0.0, 10.0]
//!
//! [slew-rate-limit]               # effect `slew-rate-limit`, at the amplifier output
//! output_v_per_s = 1.5e6
//!
//! [sensor-gain]                   # effect `sensor-gain`: the monitor's scale error,
//! gain = 1.02                     # multiplies [converters] sensor_gain
//!
//! [offset]                        # effect `offset`: the monitor's / ADC's zero error
//! offset_v = 0.012                # added to every reading
//!
//! [saturation]                    # effect `saturation`: amplifier ranges
//! input_range_v = [-2.0, 12.0]
//! output_range_v = [-20.0, 120.0]
//!
//! [hysteresis]                    # effect `hysteresis`: the Everett table
//! input_range_v = [0.0, 10.0]
//! offset_v = 0.0
//! everett_v = [0.0175, 0.0359, ...]  # 990 values: the grid, packed lower triangle
//! # or, instead of everett_v, the parametric congruent-loop form:
//! # dc_gain = 0.79
//! # loop_width_frac = 0.185
//! ```
//! The built-in names are `thesis-linear` (eq. 4.4 alone: plant, `time-delay`,
//! `amplifier-pole`; no converters, no noise) and `thesis-full` (the ch. 6 overall model: all of
//! the above but `resonance`, with the default hysteresis table stored as its grid, converters and the thesis' 2.5 mV noise). Wherever a model
//! is asked for, a path or a built-in name is accepted ([`ModelFile::load`]).

use anyhow::{Context, bail};
use model_core::amplifier::AmplifierConfig;
use model_core::drift::DriftConfig;
use model_core::gain::{FastGainConfig, POLY_TERMS};
use model_core::hysteresis::HysteresisTable;
use model_core::params;
use model_core::sensor::SensorConfig;
use model_core::stage::{ModeConfig, Stage, StageConfig};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The built-in model names.
pub const BUILT_IN: [&str; 2] = ["thesis-linear", "thesis-full"];

/// A fixed-size array of exactly `N` values: serde alone would take the first `N` of a longer
/// one and drop the rest without a word.
fn exact<'de, D, T, const N: usize>(d: D) -> Result<[T; N], D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    let v: Vec<T> = Vec::deserialize(d)?;
    let len = v.len();
    v.try_into()
        .map_err(|_| serde::de::Error::invalid_length(len, &format!("exactly {N} values").as_str()))
}

/// Three to seven values, the missing higher terms 0 (K'(u) to `u^6`; older files hold three
/// or four).
fn three_to_seven<'de, D>(d: D) -> Result<[f64; POLY_TERMS], D::Error>
where
    D: serde::Deserializer<'de>,
{
    let v: Vec<f64> = Vec::deserialize(d)?;
    if !(3..=POLY_TERMS).contains(&v.len()) {
        return Err(serde::de::Error::invalid_length(
            v.len(),
            &"three to seven values",
        ));
    }
    let mut poly = [0.0; POLY_TERMS];
    poly[..v.len()].copy_from_slice(&v);
    Ok(poly)
}

/// K'(u) written with four values (the cubic term, zero or not, as files had it before the
/// higher terms), and with the higher terms up to the last that is not zero.
fn four_or_more<S>(poly: &[f64; POLY_TERMS], s: S) -> Result<S::Ok, S::Error>
where
    S: serde::Serializer,
{
    let len = poly
        .iter()
        .rposition(|c| *c != 0.0)
        .map_or(4, |i| (i + 1).max(4));
    poly[..len].serialize(s)
}

/// `[plant]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlantSection {
    /// Static gain without hysteresis.
    pub static_gain: f64,
    /// Stage mode, Hz.
    pub mode_hz: f64,
    /// Stage mode damping.
    pub damping: f64,
}

/// `[amplifier]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AmplifierSection {
    /// Voltage gain.
    pub gain: f64,
}

/// `[converters]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConvertersSection {
    /// 14-bit DAC quantisation.
    pub dac: bool,
    /// 16-bit ADC quantisation.
    pub adc: bool,
    /// Sensor gain.
    pub sensor_gain: f64,
    /// Sensor noise, 1 sigma, volts.
    pub noise_v: f64,
    /// Noise seed.
    pub seed: u64,
}

/// `[time-delay]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DelaySection {
    /// Pure delay, seconds.
    pub delay_s: f64,
}

/// `[amplifier-pole]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoleSection {
    /// Pole, Hz.
    pub pole_hz: f64,
}

/// `[resonance]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResonanceSection {
    /// Mode, Hz.
    pub mode_hz: f64,
    /// Damping ratio.
    pub damping: f64,
}

/// `[drift]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriftSection {
    /// Lag gains.
    #[serde(deserialize_with = "exact")]
    pub gains: [f64; 3],
    /// Lag time constants, s.
    #[serde(deserialize_with = "exact")]
    pub taus_s: [f64; 3],
    /// K(u), lowest power first.
    #[serde(deserialize_with = "exact")]
    pub poly: [f64; 4],
    /// Range over which K is evaluated, V.
    #[serde(deserialize_with = "exact")]
    pub poly_range_v: [f64; 2],
    /// The records' constant where the creep had not settled at their first input, volts,
    /// added to every reading (the model-gap workflow's step 12, GAP.md): the model's creep
    /// starts settled at the first input, while a stage whose creep counts from that input
    /// reads the settled creep less there. Absent: settled. It holds for records that start
    /// at the same input (the settled creep grows with the input), and a refit of the drift
    /// drops it (its gains then change the settled creep).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unsettled_v: Option<f64>,
}

/// `[nonlinear-gain]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainSection {
    /// K'(u), lowest power first: three values (the thesis' quadratic) up to seven (terms up
    /// to `u^6`, which the model-gap workflow may fit, [`POLY_TERMS`]); written with four, or
    /// up to the last higher term that is not zero.
    #[serde(deserialize_with = "three_to_seven", serialize_with = "four_or_more")]
    pub poly: [f64; POLY_TERMS],
    /// Range over which K' is evaluated, V.
    #[serde(deserialize_with = "exact")]
    pub range_v: [f64; 2],
}

/// `[slew-rate-limit]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlewSection {
    /// Slew limit at the amplifier output, V/s.
    pub output_v_per_s: f64,
}

/// `[hysteresis]`: the Everett table of [`model_core::hysteresis`], either as its grid
/// (`everett_v`, the packed lower triangle, [`model_core::hysteresis::TABLE_LEN`] values) or in
/// the parametric congruent-loop form (`dc_gain` and `loop_width_frac`, see
/// [`HysteresisTable::quadratic_everett`]); exactly one of the two.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HysteresisSection {
    /// Input range of the table, volts at the amplifier input.
    #[serde(deserialize_with = "exact")]
    pub input_range_v: [f64; 2],
    /// Output at the bottom of the range, sensor volts.
    pub offset_v: f64,
    /// Parametric form: average gain over the major loop.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dc_gain: Option<f64>,
    /// Parametric form: largest loop width as a fraction of the output span.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loop_width_frac: Option<f64>,
    /// Grid form: the packed Everett values, sensor volts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub everett_v: Option<Vec<f32>>,
    /// The memory the stage starts a record with: the turning points of the input before the
    /// record, volts at the amplifier input, after coming up from the bottom of the range
    /// (`[8.0]`: it came down from 8 V to the record's first input). Absent or empty: on the
    /// major rising curve. At most [`MAX_START_TURNS`] points, inside the table's range.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_turns_v: Option<Vec<f64>>,
}

/// Turning points a `start_turns_v` may hold (the memory's depth less the bottom and the
/// record's first input).
pub const MAX_START_TURNS: usize = model_core::hysteresis::MEMORY_DEPTH - 2;

impl HysteresisSection {
    /// The grid form of `t`.
    pub fn from_table(t: &HysteresisTable) -> Self {
        let (lo, hi) = t.input_range_v();
        Self {
            input_range_v: [lo as f64, hi as f64],
            offset_v: t.offset_v() as f64,
            dc_gain: None,
            loop_width_frac: None,
            everett_v: Some(t.everett_grid_v().to_vec()),
            start_turns_v: None,
        }
    }

    /// The start memory's turning points (empty: the major rising curve).
    pub fn start_history_v(&self) -> Vec<f32> {
        self.start_turns_v
            .as_deref()
            .unwrap_or(&[])
            .iter()
            .map(|&v| v as f32)
            .collect()
    }

    /// The table, or an error naming the problem (the start memory is checked too).
    pub fn table(&self) -> anyhow::Result<HysteresisTable> {
        let [lo, hi] = self.input_range_v;
        if let Some(turns) = &self.start_turns_v {
            if turns.len() > MAX_START_TURNS {
                bail!(
                    "[hysteresis] start_turns_v: {} turning points, at most {MAX_START_TURNS}",
                    turns.len()
                );
            }
            if let Some(v) = turns
                .iter()
                .find(|v| !v.is_finite() || **v < lo || **v > hi)
            {
                bail!(
                    "[hysteresis] start_turns_v: {v} V is outside the table's range {lo}..{hi} V"
                );
            }
        }
        let r = match (&self.everett_v, self.dc_gain, self.loop_width_frac) {
            (Some(e), None, None) => {
                HysteresisTable::from_grid(lo as f32, hi as f32, self.offset_v as f32, e)
            }
            (None, Some(g), Some(w)) => {
                HysteresisTable::quadratic_everett(lo, hi, self.offset_v, g, w)
            }
            _ => bail!(
                "[hysteresis] needs either `everett_v` (the grid) or both `dc_gain` and `loop_width_frac`"
            ),
        };
        r.map_err(|e| {
            anyhow::anyhow!(
                "[hysteresis]: {e} (grid of {} values, non-negative, rising in alpha and falling in beta; range inside -2..12 V)",
                model_core::hysteresis::TABLE_LEN
            )
        })
    }
}

/// `[hysteresis-play]`: the play-operator hysteresis the model-gap workflow fits
/// ([`model_core::play`]), added to the fast map beside (or instead of) the table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaySection {
    /// Thresholds, volts.
    #[serde(deserialize_with = "exact")]
    pub radii_v: [f64; model_core::params::PLAY_OPERATORS],
    /// Weights, sensor volts per volt.
    #[serde(deserialize_with = "exact")]
    pub weights: [f64; model_core::params::PLAY_OPERATORS],
}

/// `[sensor-gain]`: the monitor's static scale error.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorGainSection {
    /// Factor on `[converters] sensor_gain` (the nominal calibration).
    pub gain: f64,
}

/// `[offset]`: the monitor's (or the ADC's) zero error.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OffsetSection {
    /// Added to every monitor reading, volts.
    pub offset_v: f64,
}

/// `[saturation]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SaturationSection {
    /// Amplifier control input range, V.
    #[serde(deserialize_with = "exact")]
    pub input_range_v: [f64; 2],
    /// Amplifier output range, V.
    #[serde(deserialize_with = "exact")]
    pub output_range_v: [f64; 2],
}

/// A model file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelFile {
    /// Free text.
    #[serde(default)]
    pub name: String,
    /// Simulation step, seconds.
    pub period_s: f64,
    /// The linear stage.
    pub plant: PlantSection,
    /// The amplifier.
    pub amplifier: AmplifierSection,
    /// Converters and sensor.
    pub converters: ConvertersSection,
    /// `time-delay`.
    #[serde(
        rename = "time-delay",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub time_delay: Option<DelaySection>,
    /// `amplifier-pole`.
    #[serde(
        rename = "amplifier-pole",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub amplifier_pole: Option<PoleSection>,
    /// `resonance`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resonance: Option<ResonanceSection>,
    /// `drift`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drift: Option<DriftSection>,
    /// `nonlinear-gain`.
    #[serde(
        rename = "nonlinear-gain",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub nonlinear_gain: Option<GainSection>,
    /// `slew-rate-limit`.
    #[serde(
        rename = "slew-rate-limit",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub slew_rate_limit: Option<SlewSection>,
    /// `saturation`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub saturation: Option<SaturationSection>,
    /// `sensor-gain`.
    #[serde(
        rename = "sensor-gain",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub sensor_gain: Option<SensorGainSection>,
    /// `offset`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset: Option<OffsetSection>,
    /// `hysteresis` in the fitted play form.
    #[serde(
        rename = "hysteresis-play",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub hysteresis_play: Option<PlaySection>,
    /// `hysteresis` (last: its grid is long).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hysteresis: Option<HysteresisSection>,
}

impl ModelFile {
    /// A built-in model by name.
    pub fn built_in(name: &str) -> Option<Self> {
        match name {
            "thesis-linear" => Some(Self::from_stage_config(
                "thesis-linear",
                &StageConfig::thesis_linear(),
            )),
            "thesis-full" => Some(Self::from_stage_config(
                "thesis-full",
                &StageConfig::thesis_full(),
            )),
            _ => None,
        }
    }

    /// A built-in name, or else a path to a model file.
    pub fn load(name_or_path: &str) -> anyhow::Result<Self> {
        if let Some(m) = Self::built_in(name_or_path) {
            return Ok(m);
        }
        let path = Path::new(name_or_path);
        if !path.exists() {
            bail!(
                "model `{name_or_path}` is neither a file nor a built-in name ({})",
                BUILT_IN.join(", ")
            );
        }
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read model file {}", path.display()))?;
        Self::parse(&text).with_context(|| format!("model file {}", path.display()))
    }

    /// Parse TOML text and check that it builds a stage.
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        let m: Self =
            toml::from_str(text).map_err(|e| anyhow::anyhow!("{}", e.to_string().trim_end()))?;
        m.build_stage()?;
        Ok(m)
    }

    /// The TOML text, with a comment header.
    pub fn to_toml(&self) -> anyhow::Result<String> {
        let body = toml::to_string(self).context("serialising the model")?;
        Ok(format!(
            "# piezo model file (see host-tests/src/io/model_file.rs for every key).\n\
             # A table named after an effect switches it on.\n{body}"
        ))
    }

    /// Write to `path`.
    pub fn write(&self, path: &Path) -> anyhow::Result<()> {
        crate::io::checks::write_bytes(path, self.to_toml()?.as_bytes())
    }

    /// The model file describing `c`.
    pub fn from_stage_config(name: &str, c: &StageConfig) -> Self {
        let pair = |p: (f64, f64)| [p.0, p.1];
        Self {
            name: name.into(),
            period_s: c.period_s,
            plant: PlantSection {
                static_gain: c.static_gain,
                mode_hz: c.mode.mode_hz,
                damping: c.mode.damping,
            },
            amplifier: AmplifierSection {
                gain: c.amplifier.gain,
            },
            converters: ConvertersSection {
                dac: c.dac,
                adc: c.sensor.adc,
                sensor_gain: c.sensor.gain,
                noise_v: c.sensor.noise_v,
                seed: c.sensor.seed,
            },
            time_delay: (c.delay_s > 0.0).then_some(DelaySection { delay_s: c.delay_s }),
            amplifier_pole: c.amp_pole_hz.map(|pole_hz| PoleSection { pole_hz }),
            resonance: c.second_mode.map(|m| ResonanceSection {
                mode_hz: m.mode_hz,
                damping: m.damping,
            }),
            drift: c.drift.map(|d| DriftSection {
                gains: d.gains,
                taus_s: d.taus_s,
                poly: d.poly,
                poly_range_v: pair(d.poly_range_v),
                unsettled_v: None,
            }),
            nonlinear_gain: c.nonlinear_gain.map(|g| GainSection {
                poly: g.poly,
                range_v: pair(g.range_v),
            }),
            slew_rate_limit: c
                .amplifier
                .slew_v_per_s
                .map(|s| SlewSection { output_v_per_s: s }),
            saturation: c.amplifier.saturation.then_some(SaturationSection {
                input_range_v: pair(c.amplifier.input_range_v),
                output_range_v: pair(c.amplifier.output_range_v),
            }),
            sensor_gain: None,
            offset: (c.sensor.offset_v != 0.0).then_some(OffsetSection {
                offset_v: c.sensor.offset_v,
            }),
            hysteresis: c.hysteresis.as_ref().map(HysteresisSection::from_table),
            hysteresis_play: c.play.map(|p| PlaySection {
                radii_v: p.radii_v,
                weights: p.weights,
            }),
        }
    }

    /// The stage configuration this file describes; the hysteresis table is checked here, the
    /// rest by [`Self::build_stage`].
    pub fn stage_config(&self) -> anyhow::Result<StageConfig> {
        let hysteresis = self
            .hysteresis
            .as_ref()
            .map(HysteresisSection::table)
            .transpose()?;
        let pair = |p: [f64; 2]| (p[0], p[1]);
        let sat = self.saturation.as_ref();
        Ok(StageConfig {
            period_s: self.period_s,
            hysteresis,
            play: self
                .hysteresis_play
                .as_ref()
                .map(|h| model_core::play::PlayConfig {
                    radii_v: h.radii_v,
                    weights: h.weights,
                }),
            dac: self.converters.dac,
            amplifier: AmplifierConfig {
                gain: self.amplifier.gain,
                input_range_v: sat
                    .map_or((params::AMP_INPUT_MIN_V, params::AMP_INPUT_MAX_V), |s| {
                        pair(s.input_range_v)
                    }),
                output_range_v: sat
                    .map_or((params::AMP_OUTPUT_MIN_V, params::AMP_OUTPUT_MAX_V), |s| {
                        pair(s.output_range_v)
                    }),
                slew_v_per_s: self.slew_rate_limit.as_ref().map(|s| s.output_v_per_s),
                saturation: sat.is_some(),
            },
            static_gain: self.plant.static_gain,
            nonlinear_gain: self.nonlinear_gain.as_ref().map(|g| FastGainConfig {
                poly: g.poly,
                range_v: pair(g.range_v),
            }),
            drift: self.drift.as_ref().map(|d| DriftConfig {
                gains: d.gains,
                taus_s: d.taus_s,
                poly: d.poly,
                poly_range_v: pair(d.poly_range_v),
            }),
            amp_pole_hz: self.amplifier_pole.as_ref().map(|p| p.pole_hz),
            mode: ModeConfig {
                mode_hz: self.plant.mode_hz,
                damping: self.plant.damping,
            },
            second_mode: self.resonance.as_ref().map(|r| ModeConfig {
                mode_hz: r.mode_hz,
                damping: r.damping,
            }),
            delay_s: self.time_delay.as_ref().map_or(0.0, |d| d.delay_s),
            sensor: SensorConfig {
                gain: self.converters.sensor_gain
                    * self.sensor_gain.as_ref().map_or(1.0, |g| g.gain),
                offset_v: self
                    .offset
                    .as_ref()
                    .map_or(params::SENSOR_OFFSET_V, |o| o.offset_v)
                    + self
                        .drift
                        .as_ref()
                        .and_then(|d| d.unsettled_v)
                        .unwrap_or(0.0),
                noise_v: self.converters.noise_v,
                adc: self.converters.adc,
                seed: self.converters.seed,
            },
        })
    }

    /// Checks each table on its own, so that an error names the table and the rule.
    pub fn check(&self) -> anyhow::Result<()> {
        let c = self.stage_config()?;
        let rate = 1.0 / c.period_s;
        if !(c.period_s.is_finite()
            && (params::MIN_SAMPLE_RATE_HZ..=params::MAX_SAMPLE_RATE_HZ * (1.0 + 1e-9))
                .contains(&rate))
        {
            bail!(
                "period_s = {} must give a rate within 10..200 kHz",
                c.period_s
            );
        }
        let nyquist = 0.5 * rate;
        if !(c.static_gain.is_finite() && c.static_gain > 0.05 && c.static_gain < 20.0) {
            bail!(
                "[plant] static_gain = {} must be within 0.05..20",
                c.static_gain
            );
        }
        if !(c.mode.mode_hz > 0.0
            && c.mode.mode_hz < nyquist
            && c.mode.damping > 0.0
            && c.mode.damping <= 10.0)
        {
            bail!("[plant] mode_hz must be within 0..{nyquist} Hz and damping within 0..10");
        }
        if !(c.delay_s >= 0.0 && c.delay_s <= params::MAX_DELAY_S) {
            bail!(
                "[time-delay] delay_s = {} must be within 0..{} s",
                c.delay_s,
                params::MAX_DELAY_S
            );
        }
        if let Some(p) = c.amp_pole_hz
            && !(p > 0.0 && p < 10.0 * nyquist)
        {
            bail!(
                "[amplifier-pole] pole_hz = {p} must be within 0..{} Hz",
                10.0 * nyquist
            );
        }
        if let Some(m) = c.second_mode
            && !(m.mode_hz > 0.0 && m.mode_hz < nyquist && m.damping > 0.0 && m.damping <= 10.0)
        {
            bail!("[resonance] mode_hz must be within 0..{nyquist} Hz and damping within 0..10");
        }
        if let Some(d) = c.drift {
            d.validate().map_err(|e| anyhow::anyhow!("[drift]: {e}"))?;
        }
        if let Some(g) = c.nonlinear_gain {
            g.validate()
                .map_err(|e| anyhow::anyhow!("[nonlinear-gain]: {e}"))?;
        }
        c.amplifier
            .validate()
            .map_err(|e| anyhow::anyhow!("[amplifier] / [slew-rate-limit] / [saturation]: {e}"))?;
        model_core::sensor::Sensor::new(&c.sensor).map_err(|e| {
            anyhow::anyhow!("[converters] / [sensor-gain] / [offset] / [drift] unsettled_v: {e}")
        })?;
        Ok(())
    }

    /// The turning points the stage's hysteresis memory starts a record with (`[hysteresis]
    /// start_turns_v`; empty without a table or a start memory).
    pub fn start_history_v(&self) -> Vec<f32> {
        self.hysteresis
            .as_ref()
            .map_or_else(Vec::new, HysteresisSection::start_history_v)
    }

    /// The creep's share of the reading at rest with `u_v` held for ever (the drift settled,
    /// as a simulation starts), sensor volts: 0 without `[drift]`.
    pub fn settled_creep_reading_v(&self, u_v: f64) -> anyhow::Result<f64> {
        if self.drift.is_none() {
            return Ok(0.0);
        }
        let mut without = self.clone();
        without.drift = None;
        Ok(self.static_reading_v(u_v)? - without.static_reading_v(u_v)?)
    }

    /// The reading at rest with `u_v` held for ever, less the sensor's offset, sensor volts:
    /// the stage's static output ([`Stage::static_output`]) through the sensor's scale as the
    /// stage applies it (`[converters]` times `[sensor-gain]`), without the ADC's codes (the
    /// differences of two such readings are what the callers compare).
    pub fn static_reading_v(&self, u_v: f64) -> anyhow::Result<f64> {
        let gain = self.stage_config()?.sensor.gain;
        Ok(gain * self.build_stage()?.static_output(u_v as f32) as f64)
    }

    /// The model-core stage, or an error naming the refused table.
    pub fn build_stage(&self) -> anyhow::Result<Stage> {
        self.check()?;
        Stage::new(&self.stage_config()?).map_err(|e| anyhow::anyhow!("invalid model: {e}"))
    }
}
