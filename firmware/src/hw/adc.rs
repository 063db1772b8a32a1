//! ADC1, 16-bit, one channel (PA3 = INP15), converting on TIM2's TRGO, end-of-conversion
//! interrupt.
//!
//! embassy 0.6 has no timer-triggered mode on the H7, so embassy's `Adc::new` does only what it
//! does well (clock, prescaler, boost, regulator, linearity and offset calibration, enable) and
//! this module sets the trigger and the sequence through the PAC:
//! `CFGR.EXTEN = rising`, `CFGR.EXTSEL = 11` (tim2_trgo, RM0433 table "ADC1/2 external
//! triggers"), `CFGR.RES = 16 bit`, `DMNGT = DR` (the interrupt reads the data register),
//! `OVRMOD = overwrite` (a missed sample sets OVR, which the interrupt reports as an overrun),
//! one conversion of channel 15 per trigger, channel preselected in `PCSEL`.
//! Sampling time: 16.5 ADC cycles, so one conversion takes (16.5 + 8.5) / 32 MHz = 0.8 us
//! (1.6 us if the silicon halves the kernel clock), which leaves the rest of the 5 us period at
//! the fastest 200 kHz rate to the interrupt.

use embassy_stm32::Peri;
use embassy_stm32::adc::Adc;
use embassy_stm32::pac;
use embassy_stm32::pac::adc::vals::{Dmngt, Exten, Ovrmod, Pcsel, Res, SampleTime};
use embassy_stm32::peripherals::{ADC1, PA3};

/// The ADC channel of PA3.
const CHANNEL: u8 = 15;
/// EXTSEL code of tim2_trgo for ADC1/2 (RM0433).
const EXTSEL_TIM2_TRGO: u8 = 11;

/// Powers up and calibrates ADC1, then arms it for hardware-triggered single conversions of
/// PA3. The conversions start with the first TIM2 update.
pub fn init(adc: Peri<'static, ADC1>, _pin: Peri<'static, PA3>) {
    // The pin token is taken so nothing else can use PA3; the pin is made analog here.
    pac::GPIOA
        .moder()
        .modify(|w| w.set_moder(3, pac::gpio::vals::Moder::ANALOG));
    // Power-up and calibration. embassy's `Adc` has no Drop on this family: the ADC stays
    // enabled and calibrated when the driver goes out of scope, and the registers are ours.
    let _calibrated = Adc::new(adc);
    let r = pac::ADC1;
    r.cfgr().modify(|w| {
        w.set_res(Res::BITS16);
        w.set_cont(false);
        w.set_dmngt(Dmngt::DR);
        w.set_ovrmod(Ovrmod::OVERWRITE);
        w.set_extsel(EXTSEL_TIM2_TRGO);
        w.set_exten(Exten::RISING_EDGE);
    });
    r.cfgr2().modify(|w| w.set_lshift(0));
    r.pcsel()
        .modify(|w| w.set_pcsel(CHANNEL as usize, Pcsel::PRESELECTED));
    r.smpr(1)
        .modify(|w| w.set_smp((CHANNEL - 10) as usize, SampleTime::CYCLES16_5));
    r.sqr1().modify(|w| {
        w.set_l(0);
        w.set_sq(0, CHANNEL);
    });
    // Clear stale flags, then interrupt on end of conversion only.
    r.isr().write(|w| {
        w.set_eoc(true);
        w.set_eos(true);
        w.set_ovr(true);
    });
    r.ier().write(|w| w.set_eocie(true));
    // With EXTEN set, ADSTART arms the converter: each trigger starts one conversion.
    r.cr().modify(|w| w.set_adstart(true));
}

/// What the interrupt reads: the raw result and whether a conversion was lost.
#[derive(Clone, Copy)]
pub struct Reading {
    /// Right-aligned 16-bit result.
    pub raw: u32,
    /// The hardware overwrote an unread result (a missed sample).
    pub overrun: bool,
}

/// Reads the result (clearing EOC) and the overrun flag (clearing it). Interrupt only.
#[inline(always)]
pub fn read() -> Reading {
    let r = pac::ADC1;
    let overrun = r.isr().read().ovr();
    if overrun {
        r.isr().write(|w| w.set_ovr(true));
    }
    Reading {
        raw: u32::from(r.dr().read().rdata()),
        overrun,
    }
}

/// True when the next conversion has already finished (the interrupt ran longer than a period).
#[inline(always)]
pub fn next_pending() -> bool {
    pac::ADC1.isr().read().eoc()
}
