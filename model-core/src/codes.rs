//! Converter codes and volts.
//!
//! The DS1103 that the firmware replaces converted +-10 V with a 16-bit ADC (0.305 mV/LSB) and
//! a 14-bit DAC (1.221 mV/LSB) (sec. 2.3.1, 2.4). The firmware keeps that convention so that
//! records, gains and margins carry over: [`AdcCode`] and [`DacCode`] are signed two's
//! complement codes centred on 0 V. Conversions from volts saturate at the rails and round to
//! the nearest code; NaN maps to the code of 0 V (the caller's NaN guard has already flagged
//! it; a code has no NaN).
//!
//! The sensor monitor (E-509) reads 10 V for 12 um: [`volts_to_um`] and [`um_to_volts`].

use crate::params;

/// Round half away from zero and saturate to `[lo, hi]`, without `std`.
/// NaN gives 0 (as `as` casts do).
#[inline]
fn round_saturate(x: f32, lo: i32, hi: i32) -> i32 {
    let r = if x >= 0.0 { x + 0.5 } else { x - 0.5 };
    // `as` saturates at the i32 range and maps NaN to 0.
    (r as i32).clamp(lo, hi)
}

/// A 16-bit ADC code over +-10 V (two's complement; -32768 is -10 V).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct AdcCode(pub i16);

impl AdcCode {
    /// Volts per least significant bit: 20 V / 2^16 = 0.305 mV.
    pub const VOLT_PER_LSB: f32 =
        (params::CONVERTER_SPAN_V / (1u32 << params::ADC_BITS) as f64) as f32;
    /// Lowest code.
    pub const MIN: Self = Self(i16::MIN);
    /// Highest code.
    pub const MAX: Self = Self(i16::MAX);

    /// The code nearest to `volts`, saturated at the rails.
    #[inline]
    pub fn from_volts(volts: f32) -> Self {
        Self(round_saturate(volts / Self::VOLT_PER_LSB, i16::MIN as i32, i16::MAX as i32) as i16)
    }

    /// The code's value in volts.
    #[inline]
    pub fn volts(self) -> f32 {
        self.0 as f32 * Self::VOLT_PER_LSB
    }

    /// The unsigned (offset binary) form a right-aligned 16-bit ADC register reads: 0 is -10 V.
    #[inline]
    pub fn from_offset_binary(raw: u16) -> Self {
        Self((raw ^ 0x8000) as i16)
    }

    /// True when the code is within `margin` codes of either rail (sensor saturated or
    /// disconnected input floating to a rail).
    #[inline]
    pub fn near_rail(self, margin: u16) -> bool {
        let m = margin as i32;
        (self.0 as i32) <= i16::MIN as i32 + m || (self.0 as i32) >= i16::MAX as i32 - m
    }
}

/// A 14-bit DAC code over +-10 V (two's complement, -8192..=8191; -8192 is -10 V).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct DacCode(i16);

impl DacCode {
    /// Volts per least significant bit: 20 V / 2^14 = 1.221 mV.
    pub const VOLT_PER_LSB: f32 =
        (params::CONVERTER_SPAN_V / (1u32 << params::DAC_BITS) as f64) as f32;
    /// Lowest code (-10 V).
    pub const MIN: Self = Self(-(1 << (params::DAC_BITS - 1)));
    /// Highest code (+10 V - 1 LSB).
    pub const MAX: Self = Self((1 << (params::DAC_BITS - 1)) - 1);

    /// A code from its signed value, saturated to the 14-bit range.
    #[inline]
    pub fn new(code: i16) -> Self {
        Self(code.clamp(Self::MIN.0, Self::MAX.0))
    }

    /// The signed value, -8192..=8191.
    #[inline]
    pub fn value(self) -> i16 {
        self.0
    }

    /// The code nearest to `volts`, saturated at the rails.
    #[inline]
    pub fn from_volts(volts: f32) -> Self {
        Self(round_saturate(
            volts / Self::VOLT_PER_LSB,
            Self::MIN.0 as i32,
            Self::MAX.0 as i32,
        ) as i16)
    }

    /// The code's value in volts.
    #[inline]
    pub fn volts(self) -> f32 {
        self.0 as f32 * Self::VOLT_PER_LSB
    }

    /// Straight binary 0..=16383 (0 is -10 V), as a unipolar DAC behind a +-10 V output stage
    /// takes it.
    #[inline]
    pub fn offset_binary(self) -> u16 {
        (self.0 as i32 - Self::MIN.0 as i32) as u16
    }

    /// The 16-bit SPI frame of a DAC8311/AD5641-class part: PD1 PD0 = 00 (normal operation),
    /// then D13..D0.
    #[inline]
    pub fn spi_frame(self) -> u16 {
        self.offset_binary() & 0x3FFF
    }
}

/// Sensor monitor volts to stage travel in micrometres (10 V = 12 um, sec. 2.4).
#[inline]
pub fn volts_to_um(volts: f32) -> f32 {
    volts / params::SENSOR_V_PER_UM as f32
}

/// Stage travel in micrometres to sensor monitor volts.
#[inline]
pub fn um_to_volts(um: f32) -> f32 {
    um * params::SENSOR_V_PER_UM as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lsb_sizes_match_the_ds1103() {
        assert!((AdcCode::VOLT_PER_LSB - 0.305_175_78e-3).abs() < 1e-9);
        assert!((DacCode::VOLT_PER_LSB - 1.220_703_1e-3).abs() < 1e-9);
    }

    #[test]
    fn conversions_saturate_and_round() {
        assert_eq!(DacCode::from_volts(100.0), DacCode::MAX);
        assert_eq!(DacCode::from_volts(-100.0), DacCode::MIN);
        assert_eq!(DacCode::from_volts(f32::NAN).value(), 0);
        assert_eq!(DacCode::from_volts(0.6 * DacCode::VOLT_PER_LSB).value(), 1);
        assert_eq!(
            DacCode::from_volts(-0.6 * DacCode::VOLT_PER_LSB).value(),
            -1
        );
        assert_eq!(AdcCode::from_volts(10.0), AdcCode::MAX);
        assert_eq!(AdcCode::from_volts(-10.0), AdcCode::MIN);
        assert!(AdcCode::MAX.near_rail(4));
        assert!(!AdcCode::from_volts(5.0).near_rail(4));
        assert_eq!(DacCode::MIN.offset_binary(), 0);
        assert_eq!(DacCode::MAX.spi_frame(), 0x3FFF);
        assert_eq!(AdcCode::from_offset_binary(0), AdcCode::MIN);
        assert_eq!(AdcCode::from_offset_binary(0x8000).0, 0);
    }

    #[test]
    fn round_trip_within_half_lsb() {
        for i in -1000..1000 {
            let v = i as f32 * 0.00997;
            let d = DacCode::from_volts(v).volts();
            assert!(
                (d - v).abs() <= 0.5001 * DacCode::VOLT_PER_LSB,
                "{v} -> {d}"
            );
            let a = AdcCode::from_volts(v).volts();
            assert!(
                (a - v).abs() <= 0.5001 * AdcCode::VOLT_PER_LSB,
                "{v} -> {a}"
            );
        }
        assert!((volts_to_um(10.0) - 12.0).abs() < 1e-5);
        assert!((um_to_volts(12.0) - 10.0).abs() < 1e-5);
    }
}
