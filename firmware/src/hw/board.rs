//! The board: clocks, pins and interrupt priorities of the NUCLEO-H743ZI2.
//!
//! Clocks: HSE 8 MHz from the ST-LINK's MCO (bypass), PLL1 to 400 MHz system clock (voltage
//! scale 1), AHB 200 MHz, APB1..4 100 MHz, timers 200 MHz. PLL2 P at 32 MHz clocks the ADC
//! (below the 36 MHz limit of 16-bit conversions on both silicon revisions). PLL1 Q at 100 MHz
//! clocks SPI1 (divided by 8 for the DAC's 12.5 MHz).
//!
//! | function                 | pin   | NUCLEO connector        |
//! |--------------------------|-------|-------------------------|
//! | ADC1 INP15 (sensor in)   | PA3   | CN9 A0                  |
//! | SPI1 SCK (DAC SCLK)      | PA5   | CN7 D13                 |
//! | SPI1 MOSI (DAC DIN)      | PB5   | CN7 D11                 |
//! | DAC SYNC (GPIO)          | PD14  | CN7 D10                 |
//! | output enable (GPIO)     | PD15  | CN7 D9                  |
//! | internal DAC1 OUT1       | PA4   | CN7 D24 (feature `internal-dac`) |
//! | USART3 TX / RX (VCP)     | PD8 / PD9 | ST-LINK virtual COM port |
//! | LD1 green (heartbeat)    | PB0   |                         |
//! | LD3 red (fault latched)  | PB14  |                         |

use embassy_stm32::interrupt::Priority;
use embassy_stm32::time::Hertz;

/// The clocks this file sets up (`firmware::design_parameters`, where the virtual board
/// reads them too).
pub use firmware::design_parameters::{CPU_HZ, TIMER_CLOCK_HZ};

/// The control interrupt: the highest priority.
pub const PRIO_CONTROL: Priority = Priority::P0;
/// The embassy time driver (TIM3).
pub const PRIO_TIME: Priority = Priority::P4;
/// USART3 of the command link.
pub const PRIO_UART: Priority = Priority::P5;
/// Every DMA controller (none is used, but their default would be P0).
pub const PRIO_DMA: Priority = Priority::P6;

/// The embassy configuration: clocks and the DMA priorities below the control interrupt.
pub fn config() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut config = embassy_stm32::Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(8_000_000),
        mode: HseMode::Bypass,
    });
    config.rcc.hsi = None;
    config.rcc.csi = false;
    config.rcc.hsi48 = Some(Hsi48Config {
        sync_from_usb: false,
    });
    config.rcc.pll1 = Some(Pll {
        source: PllSource::HSE,
        prediv: PllPreDiv::DIV2, // 4 MHz
        mul: PllMul::MUL200,     // 800 MHz VCO
        fracn: None,
        divp: Some(PllDiv::DIV2), // 400 MHz system clock
        divq: Some(PllDiv::DIV8), // 100 MHz: SPI1 kernel clock
        divr: None,
    });
    config.rcc.pll2 = Some(Pll {
        source: PllSource::HSE,
        prediv: PllPreDiv::DIV2, // 4 MHz
        mul: PllMul::MUL64,      // 256 MHz VCO
        fracn: None,
        divp: Some(PllDiv::DIV8), // 32 MHz: ADC kernel clock
        divq: None,
        divr: None,
    });
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.ahb_pre = AHBPrescaler::DIV2;
    config.rcc.apb1_pre = APBPrescaler::DIV2;
    config.rcc.apb2_pre = APBPrescaler::DIV2;
    config.rcc.apb3_pre = APBPrescaler::DIV2;
    config.rcc.apb4_pre = APBPrescaler::DIV2;
    config.rcc.voltage_scale = VoltageScale::Scale1;
    config.rcc.mux.adcsel = mux::Adcsel::PLL2_P;
    config.rcc.mux.spi123sel = mux::Saisel::PLL1_Q;
    config.bdma_interrupt_priority = PRIO_DMA;
    config.dma_interrupt_priority = PRIO_DMA;
    config.mdma_interrupt_priority = PRIO_DMA;
    config
}
