//! MATLAB v5 `.mat` records as dSPACE / Simulink log them: `--vars t=NAME,u=NAME,y=NAME`
//! names the variables that hold time, amplifier input and sensor output.
//!
//! Reading uses the `matfile` crate (level-5 MAT files, compressed or not, every numeric class;
//! each variable must be a real vector: `1 x n` or `n x 1`). The crate is called behind
//! `catch_unwind`, so a malformed file gives an error, never a panic. [`write_v5`] writes the
//! plain (uncompressed, double) form, for tests and the demo.

use crate::io::csv::Record;
use anyhow::{Context, bail, ensure};
use matfile::{MatFile, NumericData};
use std::path::Path;

/// The variable names of `--vars` (`t=NAME,u=NAME,y=NAME`; all three required).
pub fn parse_vars(spec: &str) -> anyhow::Result<[String; 3]> {
    let mut t = None;
    let mut u = None;
    let mut y = None;
    for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let Some((k, v)) = part.split_once('=') else {
            bail!("--vars: `{part}` is not KEY=NAME (expected t=NAME,u=NAME,y=NAME)");
        };
        let v = v.trim();
        ensure!(
            !v.is_empty(),
            "--vars: empty variable name for `{}`",
            k.trim()
        );
        match k.trim() {
            "t" => t = Some(v.to_string()),
            "u" => u = Some(v.to_string()),
            "y" => y = Some(v.to_string()),
            other => bail!("--vars: unknown key `{other}` (expected t, u and y)"),
        }
    }
    match (t, u, y) {
        (Some(t), Some(u), Some(y)) => Ok([t, u, y]),
        _ => bail!("--vars must name t, u and y: t=NAME,u=NAME,y=NAME (got `{spec}`)"),
    }
}

fn to_f64(d: &NumericData) -> Option<Vec<f64>> {
    Some(match d {
        NumericData::Double { real, imag: None } => real.clone(),
        NumericData::Single { real, imag: None } => real.iter().map(|&x| x as f64).collect(),
        NumericData::Int8 { real, imag: None } => real.iter().map(|&x| x as f64).collect(),
        NumericData::UInt8 { real, imag: None } => real.iter().map(|&x| x as f64).collect(),
        NumericData::Int16 { real, imag: None } => real.iter().map(|&x| x as f64).collect(),
        NumericData::UInt16 { real, imag: None } => real.iter().map(|&x| x as f64).collect(),
        NumericData::Int32 { real, imag: None } => real.iter().map(|&x| x as f64).collect(),
        NumericData::UInt32 { real, imag: None } => real.iter().map(|&x| x as f64).collect(),
        NumericData::Int64 { real, imag: None } => real.iter().map(|&x| x as f64).collect(),
        NumericData::UInt64 { real, imag: None } => real.iter().map(|&x| x as f64).collect(),
        _ => return None,
    })
}

/// Parse `.mat` bytes into a record with the variables `vars` (t, u, y).
pub fn parse_record(bytes: &[u8], vars: &str) -> anyhow::Result<Record> {
    let names = parse_vars(vars)?;
    let owned = bytes.to_vec();
    let parsed = std::panic::catch_unwind(move || MatFile::parse(std::io::Cursor::new(owned)));
    let mat = match parsed {
        Ok(Ok(m)) => m,
        Ok(Err(e)) => bail!("not a readable MATLAB v5 file: {e}"),
        Err(_) => bail!("not a readable MATLAB v5 file (the reader gave up on its structure)"),
    };
    let mut cols = Vec::new();
    for (key, name) in ["t", "u", "y"].iter().zip(&names) {
        let Some(a) = mat.find_by_name(name) else {
            let found: Vec<&str> = mat.arrays().iter().map(|a| a.name()).collect();
            bail!(
                "variable `{name}` (for {key}) is not in the file (found: {})",
                found.join(", ")
            );
        };
        let size = a.size();
        let vector = size.len() == 2 && (size[0] == 1 || size[1] == 1);
        ensure!(vector, "variable `{name}` is {:?}, not a vector", size);
        let Some(v) = to_f64(a.data()) else {
            bail!("variable `{name}` is complex: a real vector is needed");
        };
        cols.push(v);
    }
    let y = cols.pop().unwrap_or_default();
    let u = cols.pop().unwrap_or_default();
    let t = cols.pop().unwrap_or_default();
    Ok(Record::new(t, u, Some(y), None)?)
}

/// Read a `.mat` record.
pub fn read_record(path: &Path, vars: &str) -> anyhow::Result<Record> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    parse_record(&bytes, vars).with_context(|| format!("record {}", path.display()))
}

/// A level-5 MAT file (uncompressed) holding the given real column vectors as doubles.
pub fn write_v5(vars: &[(&str, &[f64])]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut text = b"MATLAB 5.0 MAT-file, written by piezo".to_vec();
    text.resize(116, b' ');
    out.extend(text);
    out.extend([0u8; 8]);
    out.extend(0x0100u16.to_le_bytes());
    out.extend(b"IM");
    let pad8 = |v: &mut Vec<u8>| {
        while !v.len().is_multiple_of(8) {
            v.push(0);
        }
    };
    for (name, data) in vars {
        let mut body = Vec::new();
        body.extend(6u32.to_le_bytes()); // miUINT32
        body.extend(8u32.to_le_bytes());
        body.extend(6u32.to_le_bytes()); // mxDOUBLE_CLASS
        body.extend(0u32.to_le_bytes());
        body.extend(5u32.to_le_bytes()); // miINT32
        body.extend(8u32.to_le_bytes());
        body.extend((data.len() as i32).to_le_bytes());
        body.extend(1i32.to_le_bytes());
        body.extend(1u32.to_le_bytes()); // miINT8
        body.extend((name.len() as u32).to_le_bytes());
        body.extend(name.as_bytes());
        pad8(&mut body);
        body.extend(9u32.to_le_bytes()); // miDOUBLE
        body.extend(((8 * data.len()) as u32).to_le_bytes());
        for x in data.iter() {
            body.extend(x.to_le_bytes());
        }
        pad8(&mut body);
        out.extend(14u32.to_le_bytes()); // miMATRIX
        out.extend((body.len() as u32).to_le_bytes());
        out.extend(body);
    }
    out
}
