//! The firmware's present settings and how they become what the interrupt runs.
//!
//! The command task keeps one [`Settings`] value. A command that changes it builds a
//! candidate, turns it into a [`LoopConfig`] with [`Settings::loop_config`] (which calls
//! `Controller::new`, so every range model-core checks is checked here, outside the
//! interrupt), and only if that succeeds posts the `LoopConfig` to the interrupt and keeps the
//! candidate. A refused command leaves both the settings and the running loop untouched.
//!
//! What the controller in model-core offers today: the lag compensator (gain `kc`), the
//! sample period, the output window, slew limit and safe value, and a reference level set
//! each sample. The pre-filter (`tau`), the hysteresis feedforward (`ff`) and the periodic
//! reference generators (sine, triangle) are not in `Controller` yet: the commands for them
//! are parsed and validated but answered with an error saying so, and change nothing.

use model_core::controller::{Controller, ControllerConfig};
use model_core::lag::LagConfig;
use model_core::limits::ConfigError;
use model_core::params;

use crate::command::ReferenceRequest;
use crate::scaling::AdcCalibration;

/// What the command task keeps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Lag compensator gain.
    pub kc: f64,
    /// The reference.
    pub reference: ReferenceRequest,
    /// Loop rate, Hz (as obtained from the timer).
    pub rate_hz: f64,
    /// ADC front-end correction.
    pub adc_cal: AdcCalibration,
}

/// What the interrupt receives: `Copy`, swapped in whole.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopConfig {
    /// The controller.
    pub controller: Controller,
    /// The reference level, volts (sensor volts in closed loop, amplifier volts in open loop).
    pub reference_v: f32,
    /// ADC front-end correction.
    pub adc_cal: AdcCalibration,
}

/// Why settings cannot be applied.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SettingsError {
    /// The controller refused the configuration.
    Config(ConfigError),
    /// The feature is not in model-core's controller yet.
    Unsupported(&'static str),
}

impl core::fmt::Display for SettingsError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Config(e) => write!(f, "{e}"),
            Self::Unsupported(what) => write!(f, "{what} is not in model-core's controller yet"),
        }
    }
}

impl Default for Settings {
    /// The thesis loop at 50 kHz, reference at the safe value.
    fn default() -> Self {
        Self {
            kc: params::LAG_KC,
            reference: ReferenceRequest::Step {
                level_v: params::SAFE_OUTPUT_V,
            },
            rate_hz: params::SAMPLE_RATE_HZ,
            adc_cal: AdcCalibration::front_end_default(),
        }
    }
}

impl Settings {
    /// The controller configuration of these settings.
    pub fn controller_config(&self) -> ControllerConfig {
        ControllerConfig {
            lag: LagConfig {
                kc: self.kc,
                period_s: 1.0 / self.rate_hz,
                ..LagConfig::default()
            },
            ..ControllerConfig::default()
        }
    }

    /// Builds and checks what the interrupt will run.
    ///
    /// ```
    /// use firmware::settings::Settings;
    /// let cfg = Settings::default().loop_config().unwrap();
    /// assert_eq!(cfg.reference_v, 0.0);
    /// assert!(Settings { kc: -1.0, ..Settings::default() }.loop_config().is_err());
    /// ```
    pub fn loop_config(&self) -> Result<LoopConfig, SettingsError> {
        let reference_v = match self.reference {
            ReferenceRequest::Step { level_v } if level_v.is_finite() => level_v as f32,
            ReferenceRequest::Step { .. } => {
                return Err(SettingsError::Config(ConfigError::NotFinite));
            }
            ReferenceRequest::Sine { .. } => {
                return Err(SettingsError::Unsupported("the sine reference generator"));
            }
            ReferenceRequest::Triangle { .. } => {
                return Err(SettingsError::Unsupported(
                    "the triangle reference generator",
                ));
            }
        };
        let controller =
            Controller::new(&self.controller_config()).map_err(SettingsError::Config)?;
        Ok(LoopConfig {
            controller,
            reference_v,
            adc_cal: self.adc_cal,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use model_core::AdcCode;
    use model_core::controller::{ControllerState, Mode};

    #[test]
    fn defaults_build_and_bad_values_are_refused() {
        let base = Settings::default();
        assert!(base.loop_config().is_ok());
        let bad = [
            Settings { kc: 0.0, ..base },
            Settings {
                kc: f64::NAN,
                ..base
            },
            Settings {
                kc: 2.0 * params::LAG_KC_MAX,
                ..base
            },
            Settings {
                rate_hz: 5_000.0,
                ..base
            },
            Settings {
                rate_hz: 1e6,
                ..base
            },
            Settings {
                reference: ReferenceRequest::Step {
                    level_v: f64::INFINITY,
                },
                ..base
            },
        ];
        for s in bad {
            let e = s.loop_config();
            println!("{s:?} -> {e:?}");
            assert!(matches!(e, Err(SettingsError::Config(_))), "{s:?} accepted");
        }
        let sine = Settings {
            reference: ReferenceRequest::Sine {
                offset_v: 5.0,
                amplitude_v: 1.0,
                freq_hz: 10.0,
            },
            ..base
        };
        assert!(matches!(
            sine.loop_config(),
            Err(SettingsError::Unsupported(_))
        ));
    }

    #[test]
    fn the_rate_sets_the_controller_period() {
        // At 100 kHz the slew limit per sample halves: 150 V/ms * 10 us = 1.5 V.
        let fast = Settings {
            rate_hz: 100_000.0,
            ..Settings::default()
        }
        .loop_config()
        .unwrap();
        let slew = fast.controller.lag.limits.slew_v_per_step;
        println!("slew per sample at 100 kHz: {slew} V");
        assert!((slew - 1.5).abs() < 1e-6);
    }

    #[test]
    fn a_swapped_config_drives_the_same_state() {
        // The interrupt keeps its ControllerState across swaps: open loop towards 4 V, then a
        // new reference of 6 V arrives; the command moves on from where it was, at the slew
        // limit (3 V per 20 us sample), never jumping.
        let a = Settings {
            reference: ReferenceRequest::Step { level_v: 4.0 },
            ..Settings::default()
        }
        .loop_config()
        .unwrap();
        let b = Settings {
            reference: ReferenceRequest::Step { level_v: 6.0 },
            ..Settings::default()
        }
        .loop_config()
        .unwrap();
        let mut st = ControllerState::new(&a.controller);
        st.set_mode(Mode::OpenLoop);
        let y = AdcCode::from_volts(3.0);
        let mut last = 0.0f32;
        for (i, cfg) in [a, a, a, b, b, b].iter().enumerate() {
            st.set_reference(cfg.reference_v);
            let s = cfg.controller.step(&mut st, y);
            assert!(
                (s.command_v - last).abs() <= 3.0 + 1e-5,
                "sample {i}: jump {last} -> {}",
                s.command_v
            );
            last = s.command_v;
        }
        println!("command after the swap: {last} V");
        assert!((last - 6.0).abs() < 1e-6);
    }
}
