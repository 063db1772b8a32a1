//! Converter and timer arithmetic of the board, kept out of the register code so it is
//! tested on the host.
//!
//! * **ADC**: the analog front end (README) maps about -10..+10 V at the BNC to 0..VREF+ at
//!   the pin, so the right-aligned 16-bit result is nearly offset binary over +-10 V, the
//!   DS1103 convention of `AdcCode` ([`adc_code`]). "Nearly": with standard resistor values
//!   the front end's gain is 1.3 % below the ideal (so that +-10 V stays inside the pin's
//!   range) and its offset is not exactly mid-scale. [`AdcCalibration`] corrects both: its
//!   default is computed from the resistor values in [`crate::design_parameters`], and the `cal` command replaces
//!   it with figures measured on the board. In closed loop this correction sets the position
//!   accuracy: the loop regulates what the ADC reports.
//! * **DAC**: the external 14-bit DAC takes `DacCode::spi_frame()` directly. The internal
//!   12-bit DAC (feature `internal-dac`) takes the top 12 of the 14 offset-binary bits:
//!   [`internal_dac_value`] (4 codes of the 14-bit convention per step, 4.9 mV).
//! * **Timer**: [`TimerSetting::for_rate`] finds prescaler and auto-reload for a loop rate
//!   and reports the rate actually obtained (the controller is configured with that rate).

use crate::design_parameters;
use model_core::{AdcCode, DacCode, params};

/// The `AdcCode` of a right-aligned 16-bit ADC result (0 = -10 V, 65535 = +10 V - 1 LSB).
#[inline]
pub fn adc_code(raw: u32) -> AdcCode {
    // The data register is 32 bits wide; in 16-bit mode without offset or shift the upper
    // half is zero. Saturate anything wider rather than wrap.
    AdcCode::from_offset_binary(raw.min(u32::from(u16::MAX)) as u16)
}

/// Gain and offset that turn the nominal reading of the front end into sensor volts:
/// `y = gain * nominal_volts + offset_v`, then rounded to an `AdcCode`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdcCalibration {
    /// Multiplies the nominal reading.
    pub gain: f32,
    /// Added after the gain, volts.
    pub offset_v: f32,
}

/// Why a calibration was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CalibrationError {
    /// NaN, infinite, or a correction larger than `design_parameters::CAL_MAX_*`.
    OutOfRange,
}

impl AdcCalibration {
    /// No correction.
    pub const IDENTITY: Self = Self {
        gain: 1.0,
        offset_v: 0.0,
    };

    /// A checked calibration: gain within 1 +- `design_parameters::CAL_MAX_GAIN_ERROR`, offset within
    /// +- `design_parameters::CAL_MAX_OFFSET_V`.
    pub fn new(gain: f64, offset_v: f64) -> Result<Self, CalibrationError> {
        let g_ok = (gain - 1.0).abs() <= design_parameters::CAL_MAX_GAIN_ERROR;
        let o_ok = offset_v.abs() <= design_parameters::CAL_MAX_OFFSET_V;
        if g_ok && o_ok {
            Ok(Self {
                gain: gain as f32,
                offset_v: offset_v as f32,
            })
        } else {
            Err(CalibrationError::OutOfRange)
        }
    }

    /// The correction implied by the front end's resistors: the input resistor `r_in` from
    /// the sensor, `r_ref` from VREF+, `r_gnd` to ground, all meeting at the buffer input.
    /// The pin sees `(v G_in + vref G_ref) / G_sum`; the nominal reading assumes
    /// `vref (1/2 + v/20)`; solving for `v` gives the gain and offset.
    ///
    /// ```
    /// use firmware::scaling::AdcCalibration;
    /// let c = AdcCalibration::from_front_end(100e3, 32.4e3, 48.7e3, 3.3).unwrap();
    /// assert!((c.gain - 1.0131).abs() < 1e-4 && (c.offset_v + 0.0545).abs() < 1e-4);
    /// ```
    pub fn from_front_end(
        r_in: f64,
        r_ref: f64,
        r_gnd: f64,
        vref: f64,
    ) -> Result<Self, CalibrationError> {
        if !(r_in > 0.0 && r_ref > 0.0 && r_gnd > 0.0 && vref > 0.0) {
            return Err(CalibrationError::OutOfRange);
        }
        let (g_in, g_ref, g_gnd) = (1.0 / r_in, 1.0 / r_ref, 1.0 / r_gnd);
        let g_sum = g_in + g_ref + g_gnd;
        let half_span = params::CONVERTER_SPAN_V; // nominal reading = 20 (pin/vref - 1/2)
        Self::new(
            vref * g_sum / (half_span * g_in),
            vref * (0.5 * g_sum - g_ref) / g_in,
        )
    }

    /// The default: the README's front end.
    pub fn front_end_default() -> Self {
        Self::from_front_end(
            design_parameters::ADC_R_IN_OHM,
            design_parameters::ADC_R_REF_OHM,
            design_parameters::ADC_R_GND_OHM,
            design_parameters::ADC_VREF_V,
        )
        .unwrap_or(Self::IDENTITY)
    }

    /// The corrected code of a raw 16-bit result.
    #[inline]
    pub fn apply(&self, raw: u32) -> AdcCode {
        let nominal = adc_code(raw).volts();
        AdcCode::from_volts(self.gain * nominal + self.offset_v)
    }
}

/// The README's ADC front end as a circuit model (f64), for the host tests and the virtual
/// board: the voltage at the pin for a driven input `Some(volts)` or an unplugged one
/// (`None`). Driven, the source sets the input node and the pull resistor only loads the
/// source; open, the node settles where the pull resistor ([`design_parameters::ADC_R_PULL_OHM`]
/// to [`design_parameters::ADC_PULL_RAIL_V`]) meets the network seen through R1 (Thevenin:
/// `VREF R3/(R2+R3)` behind `R1 + R2||R3`).
pub fn front_end_pin_v(input_v: Option<f64>) -> f64 {
    use design_parameters::{
        ADC_PULL_RAIL_V, ADC_R_GND_OHM, ADC_R_IN_OHM, ADC_R_PULL_OHM, ADC_R_REF_OHM, ADC_VREF_V,
    };
    let (g_in, g_ref, g_gnd) = (1.0 / ADC_R_IN_OHM, 1.0 / ADC_R_REF_OHM, 1.0 / ADC_R_GND_OHM);
    let node_v = match input_v {
        Some(v) => v,
        None => {
            let v_th = ADC_VREF_V * g_ref / (g_ref + g_gnd);
            let r_th = ADC_R_IN_OHM + 1.0 / (g_ref + g_gnd);
            (v_th / r_th + ADC_PULL_RAIL_V / ADC_R_PULL_OHM) / (1.0 / r_th + 1.0 / ADC_R_PULL_OHM)
        }
    };
    (node_v * g_in + ADC_VREF_V * g_ref) / (g_in + g_ref + g_gnd)
}

/// The right-aligned 16-bit result the ADC gives for `pin_v` (clamped to the rails).
pub fn adc_raw_of_pin(pin_v: f64) -> u32 {
    let vref = design_parameters::ADC_VREF_V;
    // `as` truncates: the floor, for the non-negative values left after the clamp.
    (pin_v / vref * 65536.0).clamp(0.0, 65535.0) as u32
}

/// The 12-bit value for the internal DAC: the 14-bit offset-binary code without its two
/// least significant bits.
#[inline]
pub fn internal_dac_value(code: DacCode) -> u16 {
    code.offset_binary() >> 2
}

/// Prescaler and auto-reload of the control timer for one loop rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimerSetting {
    /// PSC register value (the counter clock is the timer clock / (psc + 1)).
    pub psc: u16,
    /// ARR register value (the period is arr + 1 counter ticks).
    pub arr: u32,
    /// The loop rate this gives, Hz.
    pub rate_hz: f64,
    /// One period in timer-clock ticks.
    pub period_ticks: u32,
}

/// Why a rate cannot be set.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RateError {
    /// Not finite, or outside 10..200 kHz.
    OutOfRange,
    /// The timer clock is too slow or the counter too narrow to come within
    /// [`MAX_RATE_ERROR`] of the rate.
    NotReachable,
}

impl TimerSetting {
    /// The setting nearest to `rate_hz` for a timer clocked at `timer_clock_hz` with a
    /// `counter_bits`-bit counter (16 or 32).
    ///
    /// ```
    /// use firmware::scaling::TimerSetting;
    /// let t = TimerSetting::for_rate(200_000_000, 50_000.0, 32).unwrap();
    /// assert_eq!((t.psc, t.arr, t.rate_hz), (0, 3999, 50_000.0));
    /// ```
    pub fn for_rate(
        timer_clock_hz: u32,
        rate_hz: f64,
        counter_bits: u32,
    ) -> Result<Self, RateError> {
        let allowed =
            params::MIN_SAMPLE_RATE_HZ * (1.0 - 1e-9)..=params::MAX_SAMPLE_RATE_HZ * (1.0 + 1e-9);
        if !allowed.contains(&rate_hz) {
            return Err(RateError::OutOfRange);
        }
        let ticks = (f64::from(timer_clock_hz) / rate_hz + 0.5) as u64;
        let max_count: u64 = if counter_bits >= 32 {
            1 << 32
        } else {
            1 << counter_bits.max(1)
        };
        // Smallest prescaler that makes the period fit the counter.
        let psc = ticks.div_ceil(max_count).max(1) - 1;
        if psc > u64::from(u16::MAX) {
            return Err(RateError::NotReachable);
        }
        let counts = (ticks as f64 / (psc + 1) as f64 + 0.5) as u64;
        if counts < 2 {
            return Err(RateError::NotReachable);
        }
        let period_ticks = counts * (psc + 1);
        let actual_hz = f64::from(timer_clock_hz) / period_ticks as f64;
        if (actual_hz - rate_hz).abs() > MAX_RATE_ERROR * rate_hz {
            return Err(RateError::NotReachable);
        }
        Ok(Self {
            psc: psc as u16,
            arr: (counts - 1) as u32,
            rate_hz: actual_hz,
            period_ticks: u32::try_from(period_ticks).map_err(|_| RateError::NotReachable)?,
        })
    }
}

/// Largest relative difference between the asked and the obtained loop rate.
pub const MAX_RATE_ERROR: f64 = 1e-3;

/// Cycles to microseconds at `cpu_hz`.
pub fn cycles_to_us(cycles: u32, cpu_hz: u32) -> f32 {
    if cpu_hz == 0 {
        0.0
    } else {
        cycles as f32 * 1e6 / cpu_hz as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adc_scaling_matches_the_front_end() {
        assert_eq!(adc_code(0), AdcCode::MIN);
        assert_eq!(adc_code(0x8000).0, 0);
        assert_eq!(adc_code(0xFFFF), AdcCode::MAX);
        assert_eq!(adc_code(0x1_0000), AdcCode::MAX, "wider values saturate");
        // 0..10 V of the sensor monitor uses the upper half of the range.
        let ten = adc_code(0xFFFF).volts();
        assert!((ten - 10.0).abs() < 1e-3, "{ten}");
    }

    /// The front end of the README, simulated in f64: a sensor voltage through the resistor
    /// network to the pin, quantised by a 16-bit ADC, corrected by the default calibration,
    /// must read back within 1 LSB plus the rounding of the correction.
    #[test]
    fn default_calibration_inverts_the_front_end() {
        let (r_in, r_ref, r_gnd, vref) = (100e3, 32.4e3, 48.7e3, 3.3);
        let cal = AdcCalibration::from_front_end(r_in, r_ref, r_gnd, vref).unwrap();
        assert_eq!(cal, AdcCalibration::front_end_default());
        let g_sum = 1.0 / r_in + 1.0 / r_ref + 1.0 / r_gnd;
        let mut worst = 0.0f64;
        for i in 0..=200 {
            let v = -10.0 + 0.1 * i as f64;
            let pin = (v / r_in + vref / r_ref) / g_sum;
            assert!(
                pin > 0.0 && pin < vref,
                "{v} V maps to {pin} V at the pin: outside 0..VREF"
            );
            let raw = (pin / vref * 65536.0).floor().min(65535.0) as u32;
            let got = f64::from(cal.apply(raw).volts());
            worst = worst.max((got - v).abs());
        }
        println!(
            "front end -10..10 V: worst read-back error {:.3} mV ({:.2} LSB)",
            worst * 1e3,
            worst / f64::from(AdcCode::VOLT_PER_LSB)
        );
        assert!(worst < 2.5 * f64::from(AdcCode::VOLT_PER_LSB));
        // Without the correction the error would be tens of millivolts.
        let raw10 = ((10.0 / r_in + vref / r_ref) / g_sum / vref * 65536.0) as u32;
        let uncorrected = (f64::from(adc_code(raw10).volts()) - 10.0).abs();
        println!("uncorrected error at 10 V: {:.1} mV", uncorrected * 1e3);
        assert!(uncorrected > 0.05);
    }

    #[test]
    fn calibration_refuses_absurd_values() {
        for (g, o) in [
            (f64::NAN, 0.0),
            (1.0, f64::NAN),
            (1.2, 0.0),
            (0.8, 0.0),
            (1.0, 0.6),
            (f64::INFINITY, 0.0),
        ] {
            assert_eq!(
                AdcCalibration::new(g, o),
                Err(CalibrationError::OutOfRange),
                "{g} {o}"
            );
        }
        assert!(AdcCalibration::from_front_end(0.0, 1.0, 1.0, 3.3).is_err());
        assert!(AdcCalibration::from_front_end(f64::NAN, 1.0, 1.0, 3.3).is_err());
        assert_eq!(AdcCalibration::IDENTITY.apply(0x8000).0, 0);
        // Saturates instead of wrapping.
        let c = AdcCalibration::new(1.09, 0.5).unwrap();
        assert_eq!(c.apply(0xFFFF), AdcCode::MAX);
    }

    #[test]
    fn internal_dac_drops_two_bits() {
        assert_eq!(internal_dac_value(DacCode::MIN), 0);
        assert_eq!(internal_dac_value(DacCode::MAX), 4095);
        assert_eq!(internal_dac_value(DacCode::new(0)), 2048);
        // Monotonic and at most 1 LSB12 apart for codes 4 apart.
        let mut last = 0;
        for c in DacCode::MIN.value()..=DacCode::MAX.value() {
            let v = internal_dac_value(DacCode::new(c));
            assert!(v >= last && v - last <= 1);
            last = v;
        }
    }

    #[test]
    fn timer_rates() {
        let clk = 200_000_000;
        for rate in [10_000.0, 50_000.0, 100_000.0, 200_000.0] {
            let t = TimerSetting::for_rate(clk, rate, 32).unwrap();
            assert_eq!(t.psc, 0);
            assert_eq!(t.rate_hz, rate, "{t:?}");
        }
        // A 16-bit counter on a 1 GHz clock at 10 kHz (100 000 ticks) needs a prescaler.
        let t = TimerSetting::for_rate(1_000_000_000, 10_000.0, 16).unwrap();
        assert!(t.psc > 0 && t.arr <= 0xFFFF);
        assert!((t.rate_hz - 10_000.0).abs() < 1e-6);
        // A rate that does not divide the clock is approximated and reported.
        let t = TimerSetting::for_rate(clk, 30_001.0, 32).unwrap();
        let err = (t.rate_hz - 30_001.0).abs() / 30_001.0;
        println!("30001 Hz -> {} Hz, relative error {err:.2e}", t.rate_hz);
        assert!(err < 1.0 / 6666.0);
        for bad in [f64::NAN, f64::INFINITY, 0.0, -50e3, 9_999.0, 200_001.0] {
            assert_eq!(
                TimerSetting::for_rate(clk, bad, 32),
                Err(RateError::OutOfRange),
                "{bad}"
            );
        }
        assert_eq!(
            TimerSetting::for_rate(100_000, 30_001.0, 32),
            Err(RateError::NotReachable)
        );
        assert!((cycles_to_us(400, 400_000_000) - 1.0).abs() < 1e-6);
        assert_eq!(cycles_to_us(400, 0), 0.0);
    }

    /// Issue 13 item 2: an unplugged sensor must read outside the controller's plausible
    /// range (it read 1.98 V before the pull resistor), through the pin and the default
    /// calibration, and the controller must latch SENSOR_RANGE on it at the first sample.
    #[test]
    fn open_input_reads_out_of_range_and_latches_sensor_range() {
        use model_core::controller::{Controller, ControllerConfig, ControllerState, Faults, Mode};
        let pin = front_end_pin_v(None);
        let vref = design_parameters::ADC_VREF_V;
        assert!(
            pin > 0.05 && pin < vref - 0.05,
            "the ADC still reads it: {pin} V"
        );
        let y = f64::from(
            AdcCalibration::front_end_default()
                .apply(adc_raw_of_pin(pin))
                .volts(),
        );
        let old_open_pin = vref * design_parameters::ADC_R_GND_OHM
            / (design_parameters::ADC_R_REF_OHM + design_parameters::ADC_R_GND_OHM);
        let old_y = f64::from(
            AdcCalibration::front_end_default()
                .apply(adc_raw_of_pin(old_open_pin))
                .volts(),
        );
        println!(
            "open input: pin {pin:.3} V, reads {y:.3} V (valid {}..{} V); without the pull resistor it read {old_y:.3} V",
            params::SENSOR_VALID_MIN_V,
            params::SENSOR_VALID_MAX_V
        );
        assert!(y < params::SENSOR_VALID_MIN_V - 1.0, "{y}");
        // Connected, the pull resistor changes nothing: 0 and 10 V read back as before.
        for v in [0.0, 5.0, 10.0] {
            let got = f64::from(
                AdcCalibration::front_end_default()
                    .apply(adc_raw_of_pin(front_end_pin_v(Some(v))))
                    .volts(),
            );
            assert!((got - v).abs() < 1e-3, "{v} -> {got}");
        }
        let c = Controller::new(&ControllerConfig::default()).unwrap();
        let mut st = ControllerState::new(&c);
        st.set_mode(Mode::ClosedLoop);
        st.set_reference(5.0);
        let s = c.step(&mut st, AdcCode::from_volts(y as f32));
        assert!(s.faults.contains(Faults::SENSOR_RANGE));
    }
}
