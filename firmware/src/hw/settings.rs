//! TEMPORARY: settings -> ControllerConfig (moves to the lib once the controller API lands).
use super::ctl::{ControllerConfig, ReferenceConfig};
use firmware::command::ReferenceRequest;
use model_core::lag::LagConfig;
use model_core::limits::ConfigError;

#[derive(Clone, Copy, Debug)]
pub struct Settings {
    pub kc: f64,
    pub tau_s: f64,
    pub feedforward: bool,
    pub reference: ReferenceRequest,
    pub rate_hz: f64,
}

impl Settings {
    pub fn controller_config(&self) -> Result<ControllerConfig, ConfigError> {
        let lag = LagConfig {
            kc: self.kc,
            period_s: 1.0 / self.rate_hz,
            ..LagConfig::default()
        };
        let reference = match self.reference {
            ReferenceRequest::Step { level_v } => ReferenceConfig::Step { level_v },
            ReferenceRequest::Sine {
                offset_v,
                amplitude_v,
                freq_hz,
            } => ReferenceConfig::Sine {
                offset_v,
                amplitude_v,
                freq_hz,
            },
            ReferenceRequest::Triangle {
                offset_v,
                amplitude_v,
                freq_hz,
            } => ReferenceConfig::Triangle {
                offset_v,
                amplitude_v,
                freq_hz,
            },
        };
        Ok(ControllerConfig {
            lag,
            reference,
            prefilter_tau_s: self.tau_s,
            hysteresis_ff: self.feedforward,
        })
    }
}
