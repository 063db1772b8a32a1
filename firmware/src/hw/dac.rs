//! The DAC output, written by registers from the control interrupt.
//!
//! **External 14-bit DAC (default)**: a DAC8311 / AD5641-class part on SPI1, mode 1
//! (CPOL 0, CPHA 1: the part samples on the falling edge), 16-bit frames `PD1 PD0 D13..D0`
//! from `DacCode::spi_frame()`, SYNC on a GPIO. embassy's SPI driver configures pins, clock
//! and mode once; after that this module owns the registers: SPI1 is switched to simplex
//! transmit, 16-bit frames, endless transfer (TSIZE = 0), so a write is one store to TXDR
//! and one to CR1.CSTART. SYNC is handled without waiting in the interrupt: [`Dac::begin`] at the
//! start of the next sample raises SYNC (the frame finished long ago: 1.3 us at 12.5 MHz) and
//! [`Dac::write`] lowers it and queues the frame. The part updates its output on the 16th
//! clock edge, so the output latency is the frame time only.
//!
//! **Internal DAC (feature `internal-dac`)**: DAC1 channel 1 on PA4, 12 bits, 0..3.3 V: the
//! 14-bit code loses its 2 lowest bits (see `firmware::scaling::internal_dac_value`). For
//! bring-up on a bare board; the README's output stage is for the external part.

use embassy_stm32::pac;
use model_core::DacCode;

#[cfg(not(feature = "internal-dac"))]
pub use external::Dac;
#[cfg(feature = "internal-dac")]
pub use internal::Dac;

#[cfg(not(feature = "internal-dac"))]
mod external {
    use super::*;
    use embassy_stm32::Peri;
    use embassy_stm32::gpio::{Level, Output, Speed};
    use embassy_stm32::pac::spi::vals::Comm;
    use embassy_stm32::peripherals::{PA5, PB5, PD14, SPI1};
    use embassy_stm32::spi::{self, Spi};
    use embassy_stm32::time::Hertz;
    use firmware::design_parameters;

    /// The external DAC: SPI1 registers plus the SYNC pin.
    pub struct Dac {
        sync: Output<'static>,
    }

    impl Dac {
        /// Configures SPI1 and SYNC and writes `safe` to the DAC (blocking, before the loop).
        pub fn new(
            spi: Peri<'static, SPI1>,
            sck: Peri<'static, PA5>,
            mosi: Peri<'static, PB5>,
            sync: Peri<'static, PD14>,
            safe: DacCode,
        ) -> Self {
            let mut cfg = spi::Config::default();
            cfg.mode = spi::MODE_1;
            cfg.frequency = Hertz(design_parameters::DAC_SPI_HZ);
            cfg.nss_output_disable = true;
            let driver = Spi::new_blocking_txonly(spi, sck, mosi, cfg);
            // The driver's Drop would disable SPI1: keep it configured forever; from here on
            // this module owns the registers.
            core::mem::forget(driver);
            let r = pac::SPI1;
            r.cr1().modify(|w| w.set_spe(false));
            r.cfg1().modify(|w| w.set_dsize(15)); // 16-bit frames
            r.cfg2().modify(|w| w.set_comm(Comm::TRANSMITTER));
            r.cr2().modify(|w| w.set_tsize(0));
            r.ifcr().write(|w| w.0 = 0xFFFF_FFFF);
            r.cr1().modify(|w| w.set_spe(true));
            r.cr1().modify(|w| w.set_cstart(true));
            let mut dac = Self {
                sync: Output::new(sync, Level::High, Speed::VeryHigh),
            };
            dac.write(safe);
            // Let the first frame finish before the loop starts (16 bits at 12.5 MHz).
            let mut spins = 0u32;
            while !r.sr().read().txc() && spins < 100_000 {
                spins += 1;
            }
            dac.begin();
            dac
        }

        /// Start of a sample: ends the previous frame (SYNC high). Returns false if the
        /// previous frame had not finished (the DAC kept its old value).
        #[inline(always)]
        pub fn begin(&mut self) -> bool {
            let done = pac::SPI1.sr().read().txc();
            self.sync.set_high();
            done
        }

        /// Sends `code`: SYNC low, one store to TXDR.
        #[inline(always)]
        pub fn write(&mut self, code: DacCode) {
            self.sync.set_low();
            // A 16-bit store pushes exactly one 16-bit frame into the TX FIFO; CSTART (kept
            // set by the endless transfer, set again as embassy's own driver does) sends it.
            let r = pac::SPI1;
            r.txdr16().write_value(code.spi_frame());
            r.cr1().modify(|w| w.set_cstart(true));
        }
    }
}

#[cfg(feature = "internal-dac")]
mod internal {
    use super::*;
    use embassy_stm32::Peri;
    use embassy_stm32::dac::DacChannel;
    use embassy_stm32::peripherals::{DAC1, PA4};
    use firmware::scaling::internal_dac_value;

    /// The internal 12-bit DAC, channel 1.
    pub struct Dac;

    impl Dac {
        /// Enables DAC1 channel 1 on PA4 and writes `safe`.
        pub fn new(dac: Peri<'static, DAC1>, pin: Peri<'static, PA4>, safe: DacCode) -> Self {
            let ch = DacChannel::new_blocking(dac, pin);
            // Dropping the channel would disable it: keep it enabled forever.
            core::mem::forget(ch);
            let mut d = Self;
            d.write(safe);
            d
        }

        /// Nothing to finish for the internal DAC.
        #[inline(always)]
        pub fn begin(&mut self) -> bool {
            true
        }

        /// Writes the 12-bit value; the output changes at once (no trigger).
        #[inline(always)]
        pub fn write(&mut self, code: DacCode) {
            pac::DAC1
                .dhr12r(0)
                .write(|w| w.set_dhr(internal_dac_value(code)));
        }
    }
}
