//! Converter and timer arithmetic of the board, kept out of the register code so it is
//! tested on the host.
//!
//! * **ADC**: the analog front end (README) maps -10..+10 V at the BNC to 0..VREF+ at the
//!   pin, so the right-aligned 16-bit result is offset binary over +-10 V, the DS1103
//!   convention of `AdcCode`: [`adc_code`] is the one place that converts.
//! * **DAC**: the external 14-bit DAC takes `DacCode::spi_frame()` directly. The internal
//!   12-bit DAC (feature `internal-dac`) takes the top 12 of the 14 offset-binary bits:
//!   [`internal_dac_value`] (4 codes of the 14-bit convention per step, 4.9 mV).
//! * **Timer**: [`TimerSetting::for_rate`] finds prescaler and auto-reload for a loop rate
//!   and reports the rate actually obtained (the controller is configured with that rate).

use model_core::{AdcCode, DacCode, params};

/// The `AdcCode` of a right-aligned 16-bit ADC result (0 = -10 V, 65535 = +10 V - 1 LSB).
#[inline]
pub fn adc_code(raw: u32) -> AdcCode {
    // The data register is 32 bits wide; in 16-bit mode without offset or shift the upper
    // half is zero. Saturate anything wider rather than wrap.
    AdcCode::from_offset_binary(raw.min(u32::from(u16::MAX)) as u16)
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
}
