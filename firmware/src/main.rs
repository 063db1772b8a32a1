//! The board image. On the host this binary is an empty stub so that workspace-wide
//! `cargo clippy` works; the real image is built for thumbv7em-none-eabihf.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod board {
    use cortex_m_rt::entry;

    #[entry]
    fn main() -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[panic_handler]
    fn panic(_: &core::panic::PanicInfo) -> ! {
        cortex_m::asm::udf()
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "the firmware runs on the board: cargo build -p firmware --release --target thumbv7em-none-eabihf"
    );
}
