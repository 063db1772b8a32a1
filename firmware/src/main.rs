//! The board image: the 50 kHz piezo loop on a NUCLEO-H743ZI2 (see `firmware/README.md`).
//! On the host this binary is an empty stub so that workspace-wide `cargo clippy` works; the
//! real image is built for thumbv7em-none-eabihf and its register code lives in `hw/`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod hw;

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "the firmware runs on the board: cargo build -p firmware --release --target thumbv7em-none-eabihf"
    );
}
