//! Files in and out: measured-style records ([`csv`], MATLAB v5 [`mat`]) and the TOML model
//! file with the built-in models ([`model_file`]).

pub mod csv;
pub mod mat;
pub mod model_file;
