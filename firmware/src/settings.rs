//! The firmware's present settings and how they become what the interrupt runs.
//!
//! The command task keeps one [`Settings`] value. A command that changes it builds a
//! candidate, turns it into a [`LoopConfig`] with [`Settings::loop_config`] (which calls
//! `Controller::new`, so every range model-core checks is checked here, outside the
//! interrupt), and only if that succeeds posts the `LoopConfig` to the interrupt and keeps the
//! candidate. A refused command leaves both the settings and the running loop untouched.
//!
//! A step reference is the controller's *external* reference (set every sample, passed
//! through the pre-filter without preview, so a new level is approached smoothly). Sine and
//! triangle use the controller's on-board *generator* with preview. When the generator, the
//! pre-filter or the feedforward change while the loop is closed, [`LoopConfig::restart`]
//! asks the interrupt to re-enter closed loop (generator from its start, pre-filter settled,
//! compensator bumpless: `ControllerState::set_mode`); a new gain or step level needs no
//! restart.

use model_core::controller::{Controller, ControllerConfig, ReferenceSource};
use model_core::lag::LagConfig;
use model_core::limits::ConfigError;
use model_core::params;
use model_core::plant::LinearPlantConfig;
use model_core::prefilter::PreFilterConfig;
use model_core::reference::{ReferenceConfig, Shape};

use crate::command::ReferenceRequest;
use crate::design_parameters;
use crate::scaling::AdcCalibration;

/// What the command task keeps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Lag compensator gain.
    pub kc: f64,
    /// Pre-filter time constant, seconds.
    pub tau_s: f64,
    /// Hysteresis feedforward in closed loop.
    pub feedforward: bool,
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
    /// Re-enter closed loop with this configuration (generator, pre-filter or feedforward
    /// changed).
    pub restart: bool,
}

/// Why settings cannot be applied.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SettingsError {
    /// The controller refused the configuration.
    Config(ConfigError),
}

impl core::fmt::Display for SettingsError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Config(e) => write!(f, "{e}"),
        }
    }
}

impl core::error::Error for SettingsError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Config(e) => Some(e),
        }
    }
}

impl Default for Settings {
    /// The thesis loop at 50 kHz, reference at the safe value.
    fn default() -> Self {
        Self {
            kc: params::LAG_KC,
            tau_s: PreFilterConfig::default().tau_s,
            feedforward: false,
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
        let period_s = 1.0 / self.rate_hz;
        let (source, reference) = match self.reference {
            ReferenceRequest::Step { .. } => {
                (ReferenceSource::External, ReferenceConfig::default())
            }
            ReferenceRequest::Sine {
                offset_v,
                amplitude_v,
                freq_hz,
            } => (
                ReferenceSource::Generator,
                ReferenceConfig {
                    shape: Shape::Sine,
                    offset_v,
                    amplitude_v,
                    freq_hz,
                    period_s,
                },
            ),
            ReferenceRequest::Triangle {
                offset_v,
                amplitude_v,
                freq_hz,
            } => (
                ReferenceSource::Generator,
                ReferenceConfig {
                    shape: Shape::Triangle,
                    offset_v,
                    amplitude_v,
                    freq_hz,
                    period_s,
                },
            ),
        };
        let base = ControllerConfig::default();
        ControllerConfig {
            lag: LagConfig {
                kc: self.kc,
                period_s,
                ..LagConfig::default()
            },
            // The loop's delay as the board has it: the plant's (eq. 4.4) plus the DAC's
            // sample of computational delay, which the pre-filter's preview covers.
            plant: LinearPlantConfig {
                delay_s: base.plant.delay_s
                    + f64::from(design_parameters::COMPUTATIONAL_DELAY_SAMPLES) * period_s,
                ..base.plant
            },
            prefilter: PreFilterConfig {
                tau_s: self.tau_s,
                ..base.prefilter
            },
            reference,
            source,
            hysteresis_ff: self.feedforward,
            ..base
        }
    }

    /// Builds and checks what the interrupt will run (no restart).
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
                return Err(SettingsError::Config(ConfigError::not_finite("level_v")));
            }
            ReferenceRequest::Sine { offset_v, .. }
            | ReferenceRequest::Triangle { offset_v, .. } => offset_v as f32,
        };
        let controller =
            Controller::new(&self.controller_config()).map_err(SettingsError::Config)?;
        Ok(LoopConfig {
            controller,
            reference_v,
            adc_cal: self.adc_cal,
            restart: false,
        })
    }

    /// What the interrupt runs after changing from `old` to `self`: restart when the
    /// generator, the pre-filter, the feedforward or the rate changed.
    pub fn transition_from(&self, old: &Settings) -> Result<LoopConfig, SettingsError> {
        let mut cfg = self.loop_config()?;
        let periodic = |r: &ReferenceRequest| !matches!(r, ReferenceRequest::Step { .. });
        let reference_changed = (periodic(&self.reference) || periodic(&old.reference))
            && self.reference != old.reference;
        cfg.restart = reference_changed
            || self.tau_s != old.tau_s
            || self.feedforward != old.feedforward
            || self.rate_hz != old.rate_hz;
        Ok(cfg)
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
        let cfg = sine.loop_config().unwrap();
        assert!(!cfg.restart);
        let bad_tau = Settings {
            tau_s: -1.0,
            ..base
        };
        assert!(matches!(
            bad_tau.loop_config(),
            Err(SettingsError::Config(_))
        ));
        // Restart only when the generator, pre-filter, feedforward or rate change.
        assert!(sine.transition_from(&base).unwrap().restart);
        let level = Settings {
            reference: ReferenceRequest::Step { level_v: 3.0 },
            ..base
        };
        assert!(!level.transition_from(&base).unwrap().restart);
        assert!(
            !Settings { kc: 5000.0, ..base }
                .transition_from(&base)
                .unwrap()
                .restart
        );
        assert!(
            Settings {
                feedforward: true,
                ..base
            }
            .transition_from(&base)
            .unwrap()
            .restart
        );
        assert!(
            Settings {
                tau_s: 2e-4,
                ..base
            }
            .transition_from(&base)
            .unwrap()
            .restart
        );
        println!(
            "size of the configuration the interrupt takes: {} bytes",
            core::mem::size_of::<LoopConfig>()
        );
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
