//! The board on the host's side of the cable: the serial [`link`] and the [`capture`]
//! receiver that assembles a capture from the board's frames (`piezo record`).

pub mod capture;
pub mod link;

pub use capture::{Assembler, Options, Recording, TransferReport, record, write_csv};
pub use link::{Link, SerialLink};
