//! MATLAB v5 `.mat` records as dSPACE / Simulink log them: `--vars t=NAME,u=NAME,y=NAME`
//! names the variables that hold time, amplifier input and sensor output.
//!
//! # Reading
//! A level-5 MAT file is a 128-byte header (text, version, the endian mark `IM` or `MI`) and a
//! sequence of data elements, each a tag (type, byte count; or the 4-byte "small element" form)
//! and its data padded to 8 bytes. A variable is an `miMATRIX` element, alone or inside an
//! `miCOMPRESSED` one (a zlib stream, decompressed here with `libflate` and bounded by
//! [`MAX_DECOMPRESSED_BYTES`]). Inside: the array flags (class, complex), the dimensions, the
//! name, then for a numeric class the real part (any storage type: MATLAB stores an `int32`
//! array of small values as `miINT8`, for instance) and the imaginary part if complex.
//!
//! The reader is our own, over byte slices with every length checked, so nothing panics and
//! every refusal says what is wrong in the file's terms: the variable (by position and name),
//! its class and elements. Numeric classes of every width (double, single, int8..uint64,
//! logical) load as `f64`; char, sparse, cell, struct, object and function variables are
//! named as such, with what is expected instead. Each variable used must be a real vector
//! (`1 x n` or `n x 1`). [`write_v5`] writes the plain (uncompressed, double) form, for tests
//! and the demo.

use crate::io::csv::Record;
use anyhow::{Context, bail, ensure};
use std::io::Read;
use std::path::Path;

/// The largest decompressed size of one compressed variable, bytes (1 GiB): a larger one is
/// refused rather than filling the memory.
pub const MAX_DECOMPRESSED_BYTES: u64 = 1 << 30;

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

/// One variable of a MAT file, as far as a record needs it.
#[derive(Clone, Debug)]
pub struct Variable {
    /// Its name.
    pub name: String,
    /// The MATLAB class number (6 double, 7 single, 8..15 integers, 4 char, ...).
    pub class: u8,
    /// Dimensions.
    pub dims: Vec<u64>,
    /// True for a complex array.
    pub complex: bool,
    /// The real part as `f64`, for numeric classes.
    pub real: Option<Vec<f64>>,
}

/// What a MATLAB class is, in words.
pub fn class_name(class: u8) -> &'static str {
    match class {
        1 => "a cell array",
        2 => "a struct",
        3 => "an object",
        4 => "a char array (text)",
        5 => "a sparse matrix",
        6 => "double",
        7 => "single",
        8 => "int8",
        9 => "uint8",
        10 => "int16",
        11 => "uint16",
        12 => "int32",
        13 => "uint32",
        14 => "int64",
        15 => "uint64",
        16 => "a function handle",
        17 => "an opaque object",
        _ => "of an unknown class",
    }
}

fn is_numeric(class: u8) -> bool {
    (6..=15).contains(&class)
}

/// A bounds-checked reader over a byte slice in the file's byte order.
struct Bytes<'a> {
    b: &'a [u8],
    pos: usize,
    big_endian: bool,
}

impl<'a> Bytes<'a> {
    fn take(&mut self, n: usize) -> anyhow::Result<&'a [u8]> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.b.len());
        let Some(end) = end else {
            bail!(
                "the file ends early: {n} bytes announced at byte {}, {} left",
                self.pos,
                self.b.len() - self.pos
            );
        };
        let s = &self.b[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn u32(&mut self) -> anyhow::Result<u32> {
        let s = self.take(4)?;
        let a = [s[0], s[1], s[2], s[3]];
        Ok(if self.big_endian {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        })
    }

    fn at_end(&self) -> bool {
        self.pos >= self.b.len()
    }

    /// The next data element: its type and data. Padding to 8 bytes is skipped (not after a
    /// compressed element, and not beyond the end).
    fn element(&mut self) -> anyhow::Result<(u32, &'a [u8])> {
        let start = self.pos;
        let w = self.u32()?;
        if w >> 16 != 0 {
            // Small data element: type in the low half, size in the high half, 4 data bytes.
            let (ty, n) = (w & 0xffff, (w >> 16) as usize);
            ensure!(
                n <= 4,
                "a small data element announces {n} bytes (at most 4)"
            );
            let data = self.take(4)?;
            return Ok((ty, &data[..n]));
        }
        let n = self.u32()? as usize;
        let data = self.take(n)?;
        if w != MI_COMPRESSED {
            let len = self.pos - start;
            let padded = start + len.div_ceil(8) * 8;
            self.pos = padded.min(self.b.len());
        }
        Ok((w, data))
    }
}

const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;

/// Numbers of storage type `ty` as `f64`.
fn numbers(ty: u32, data: &[u8], big_endian: bool) -> anyhow::Result<Vec<f64>> {
    macro_rules! conv {
        ($t:ty) => {{
            const W: usize = std::mem::size_of::<$t>();
            ensure!(
                data.len().is_multiple_of(W),
                "{} bytes of data are not a whole number of {W}-byte values",
                data.len()
            );
            data.chunks_exact(W)
                .map(|c| {
                    let mut a = [0u8; W];
                    a.copy_from_slice(c);
                    (if big_endian {
                        <$t>::from_be_bytes(a)
                    } else {
                        <$t>::from_le_bytes(a)
                    }) as f64
                })
                .collect()
        }};
    }
    Ok(match ty {
        1 => conv!(i8),
        2 => conv!(u8),
        3 => conv!(i16),
        4 => conv!(u16),
        5 => conv!(i32),
        6 => conv!(u32),
        7 => conv!(f32),
        9 => conv!(f64),
        12 => conv!(i64),
        13 => conv!(u64),
        other => bail!("data of storage type {other}, which is not numeric"),
    })
}

/// One `miMATRIX` element's data.
fn matrix(data: &[u8], big_endian: bool) -> anyhow::Result<Variable> {
    let mut r = Bytes {
        b: data,
        pos: 0,
        big_endian,
    };
    let (ty, flags) = r.element().context("array flags")?;
    ensure!(
        ty == 6 && flags.len() == 8,
        "the array flags are missing (storage type {ty}, {} bytes)",
        flags.len()
    );
    let word = numbers(6, &flags[..4], big_endian)?[0] as u32;
    let class = (word & 0xff) as u8;
    let complex = word & 0x0800 != 0;
    let (ty, d) = r.element().context("dimensions")?;
    ensure!(ty == 5, "the dimensions are missing (storage type {ty})");
    let dims: Vec<u64> = numbers(5, d, big_endian)?
        .into_iter()
        .map(|x| x.max(0.0) as u64)
        .collect();
    ensure!(
        dims.len() >= 2,
        "{} dimension(s): at least 2 are stored",
        dims.len()
    );
    let (ty, n) = r.element().context("name")?;
    ensure!(
        ty == 1 || ty == 2,
        "the name is missing (storage type {ty})"
    );
    let name = String::from_utf8_lossy(n).into_owned();
    let mut v = Variable {
        name,
        class,
        dims,
        complex,
        real: None,
    };
    if !is_numeric(class) {
        return Ok(v);
    }
    let count = v
        .dims
        .iter()
        .try_fold(1u64, |a, &d| a.checked_mul(d))
        .context("the dimensions overflow")?;
    let (ty, d) = r
        .element()
        .with_context(|| format!("the data of `{}`", v.name))?;
    let real = numbers(ty, d, big_endian).with_context(|| format!("the data of `{}`", v.name))?;
    ensure!(
        real.len() as u64 == count,
        "`{}` is {} but holds {} element(s)",
        v.name,
        dims_text(&v.dims),
        real.len()
    );
    v.real = Some(real);
    Ok(v)
}

fn dims_text(dims: &[u64]) -> String {
    dims.iter()
        .map(u64::to_string)
        .collect::<Vec<_>>()
        .join(" x ")
}

/// Every variable of a level-5 MAT file, in file order.
pub fn variables(bytes: &[u8]) -> anyhow::Result<Vec<Variable>> {
    ensure!(
        bytes.len() >= 128,
        "not a MATLAB v5 file: {} bytes, shorter than the 128-byte header",
        bytes.len()
    );
    let big_endian = match &bytes[126..128] {
        b"IM" => false,
        b"MI" => true,
        _ => bail!(
            "not a MATLAB v5 file: no endian mark `IM` or `MI` at bytes 126..128 (MATLAB v4 and v7.3/HDF5 files are not read; save with -v7 or -v6)"
        ),
    };
    let mut r = Bytes {
        b: bytes,
        pos: 128,
        big_endian,
    };
    let mut out = Vec::new();
    while !r.at_end() {
        let k = out.len() + 1;
        let at = r.pos;
        let (ty, data) = r
            .element()
            .with_context(|| format!("variable {k} (at byte {at})"))?;
        let v = match ty {
            MI_MATRIX => matrix(data, big_endian),
            MI_COMPRESSED => {
                let mut plain = Vec::new();
                let dec = libflate::zlib::Decoder::new(data)
                    .map_err(|e| anyhow::anyhow!("the compressed data is corrupt ({e})"))
                    .and_then(|d| {
                        d.take(MAX_DECOMPRESSED_BYTES + 1)
                            .read_to_end(&mut plain)
                            .map_err(|e| anyhow::anyhow!("the compressed data is corrupt ({e})"))
                    });
                dec.and_then(|_| {
                    ensure!(
                        plain.len() as u64 <= MAX_DECOMPRESSED_BYTES,
                        "decompresses to more than {MAX_DECOMPRESSED_BYTES} bytes"
                    );
                    let mut inner = Bytes {
                        b: &plain,
                        pos: 0,
                        big_endian,
                    };
                    let (ty, d) = inner.element()?;
                    ensure!(
                        ty == MI_MATRIX,
                        "the compressed data holds storage type {ty}, not a variable"
                    );
                    matrix(d, big_endian)
                })
            }
            // Other top-level elements (none in practice) are not variables.
            _ => continue,
        }
        .with_context(|| format!("variable {k} (at byte {at})"))?;
        out.push(v);
    }
    Ok(out)
}

/// Parse `.mat` bytes into a record with the variables `vars` (t, u, y).
pub fn parse_record(bytes: &[u8], vars: &str) -> anyhow::Result<Record> {
    let names = parse_vars(vars)?;
    let all = variables(bytes).context("not a readable MATLAB v5 file")?;
    let mut cols = Vec::new();
    for (key, name) in ["t", "u", "y"].iter().zip(&names) {
        let Some(a) = all.iter().find(|v| &v.name == name) else {
            let found: Vec<String> = all
                .iter()
                .map(|v| format!("{} ({})", v.name, class_name(v.class)))
                .collect();
            bail!(
                "variable `{name}` (for {key}) is not in the file (found: {})",
                if found.is_empty() {
                    "no variables".to_string()
                } else {
                    found.join(", ")
                }
            );
        };
        let want = "a real numeric vector (double, single or an integer class) is expected";
        ensure!(
            is_numeric(a.class),
            "variable `{name}` (for {key}) is {}: {want}",
            class_name(a.class)
        );
        ensure!(
            !a.complex,
            "variable `{name}` (for {key}) is complex: {want}"
        );
        let vector = a.dims.len() == 2 && (a.dims[0] == 1 || a.dims[1] == 1);
        ensure!(
            vector,
            "variable `{name}` (for {key}) is {} {}, not a vector: {want}",
            dims_text(&a.dims),
            class_name(a.class)
        );
        cols.push(a.real.clone().unwrap_or_default());
    }
    let y = cols.pop().unwrap_or_default();
    let u = cols.pop().unwrap_or_default();
    let t = cols.pop().unwrap_or_default();
    Record::new(t, u, Some(y), None).with_context(|| {
        format!(
            "variables t=`{}`, u=`{}`, y=`{}`",
            names[0], names[1], names[2]
        )
    })
}

/// Read a `.mat` record.
pub fn read_record(path: &Path, vars: &str) -> anyhow::Result<Record> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    parse_record(&bytes, vars).with_context(|| format!("record {}", path.display()))
}

/// A level-5 MAT file (uncompressed) holding the given real column vectors as doubles.
pub fn write_v5(vars: &[(&str, &[f64])]) -> Vec<u8> {
    write_v5_with(vars, false, false)
}

/// [`write_v5`] in either byte order (`big_endian`: the `MI` mark, every number big-endian,
/// as MATLAB writes on a big-endian machine), with names of at most 4 bytes in small data
/// elements when `small_names` (as MATLAB packs them): the layouts the reader must take.
pub fn write_v5_with(vars: &[(&str, &[f64])], big_endian: bool, small_names: bool) -> Vec<u8> {
    let u32b = |x: u32| {
        if big_endian {
            x.to_be_bytes()
        } else {
            x.to_le_bytes()
        }
    };
    let mut out = Vec::new();
    let mut text = b"MATLAB 5.0 MAT-file, written by piezo".to_vec();
    text.resize(116, b' ');
    out.extend(text);
    out.extend([0u8; 8]);
    if big_endian {
        out.extend(0x0100u16.to_be_bytes());
        out.extend(b"MI");
    } else {
        out.extend(0x0100u16.to_le_bytes());
        out.extend(b"IM");
    }
    let pad8 = |v: &mut Vec<u8>| {
        while !v.len().is_multiple_of(8) {
            v.push(0);
        }
    };
    for (name, data) in vars {
        let mut body = Vec::new();
        body.extend(u32b(6)); // miUINT32
        body.extend(u32b(8));
        body.extend(u32b(6)); // mxDOUBLE_CLASS
        body.extend(u32b(0));
        body.extend(u32b(5)); // miINT32
        body.extend(u32b(8));
        body.extend(u32b(data.len() as u32));
        body.extend(u32b(1));
        if small_names && name.len() <= 4 {
            // Small data element: size in the high half, miINT8 in the low half.
            body.extend(u32b(((name.len() as u32) << 16) | 1));
            let mut n = name.as_bytes().to_vec();
            n.resize(4, 0);
            body.extend(n);
        } else {
            body.extend(u32b(1)); // miINT8
            body.extend(u32b(name.len() as u32));
            body.extend(name.as_bytes());
            pad8(&mut body);
        }
        body.extend(u32b(9)); // miDOUBLE
        body.extend(u32b((8 * data.len()) as u32));
        for x in data.iter() {
            if big_endian {
                body.extend(x.to_be_bytes());
            } else {
                body.extend(x.to_le_bytes());
            }
        }
        pad8(&mut body);
        out.extend(u32b(14)); // miMATRIX
        out.extend(u32b(body.len() as u32));
        out.extend(body);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record written in either byte order, with plain or small-element names, reads back
    /// bit for bit; a file whose endian mark contradicts its numbers is refused with an
    /// error, never read as nonsense.
    #[test]
    fn both_byte_orders_and_small_names_read_back_exactly() {
        let t: Vec<f64> = (0..300).map(|i| i as f64 * 2e-4).collect();
        let u: Vec<f64> = t.iter().map(|x| 4.0 + (7.0 * x).sin()).collect();
        let y: Vec<f64> = u.iter().map(|x| 0.79 * x - 1e-3 / 3.0).collect();
        for big_endian in [false, true] {
            for small in [false, true] {
                let bytes =
                    write_v5_with(&[("t", &t), ("u", &u), ("ymeas", &y)], big_endian, small);
                let rec = parse_record(&bytes, "t=t,u=u,y=ymeas")
                    .unwrap_or_else(|e| panic!("big-endian {big_endian}, small {small}: {e:#}"));
                assert_eq!(rec.t_s, t);
                assert_eq!(rec.u_v, u);
                assert_eq!(rec.y_v.as_deref(), Some(&y[..]));
            }
            let mut bad = write_v5_with(&[("t", &t), ("u", &u), ("y", &y)], big_endian, false);
            bad[126..128].copy_from_slice(if big_endian { b"IM" } else { b"MI" });
            assert!(parse_record(&bad, "t=t,u=u,y=y").is_err());
        }
    }
}
