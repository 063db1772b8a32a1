//! Files in and out: measured-style records ([`csv`], MATLAB v5 [`mat`]) and the TOML model
//! file with the built-in models ([`model_file`]); the checks every verb shares ([`checks`]:
//! flag ranges, work bounds, finite results, atomic outputs).

pub mod checks;
pub mod csv;
pub mod mat;
pub mod model_file;
