//! TIM2, the control timer: a free-running 32-bit up-counter whose update event is TRGO,
//! the ADC's conversion trigger. The sampling instant is set by this counter, not by software.
//! Its own interrupt stays disabled (the ADC's end-of-conversion interrupt runs the loop).

use embassy_stm32::Peri;
use embassy_stm32::pac;
use embassy_stm32::pac::timer::vals::Mms;
use embassy_stm32::peripherals::TIM2;
use embassy_stm32::timer::low_level::Timer;
use firmware::scaling::TimerSetting;

/// Enables TIM2's clock and sets its period; the counter stays stopped until [`start`].
pub fn init(tim: Peri<'static, TIM2>, setting: &TimerSetting) {
    let t = Timer::new(tim);
    // `Timer` disables the timer's clock when dropped (toolchain notes): keep it forever.
    core::mem::forget(t);
    let r = pac::TIM2;
    r.cr1().modify(|w| w.set_cen(false));
    r.cr2().modify(|w| w.set_mms(Mms::UPDATE));
    r.dier().write(|_| {});
    r.cr1().modify(|w| w.set_arpe(true));
    r.psc().write_value(setting.psc);
    r.arr().write_value(setting.arr);
    // Load PSC and ARR now, while the counter is stopped (before the ADC interrupt runs).
    r.egr().write(|w| w.set_ug(true));
}

/// Loads a new period while the loop runs. PSC and ARR are preloaded, so the new period starts
/// at the next natural update: no forced update event, hence no extra TRGO and no spurious
/// conversion (issue 13 item 9: UG here used to trigger a conversion mid-period, an overrun).
pub fn set_rate(setting: &TimerSetting) {
    let r = pac::TIM2;
    r.psc().write_value(setting.psc);
    r.arr().write_value(setting.arr);
}

/// Starts counting: conversions begin one period later.
pub fn start() {
    pac::TIM2.cr1().modify(|w| w.set_cen(true));
}
