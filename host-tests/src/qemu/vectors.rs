//! Reference vectors for the on-target tests (`firmware/qemu/tests/on_target.rs`), produced
//! by the host's independent `f64` references and written as a Rust source file that the
//! Cortex-M test image compiles in: `firmware/qemu/tests/vectors/mod.rs`.
//!
//! The file is checked in; the test `host-tests/tests/qemu_vectors.rs` fails when it is not
//! what [`generate`] produces now (regenerate with `piezo qemu vectors --write`).
//!
//! * **Lag compensator**: [`RefLag`] (Tustin on the polynomial coefficients, direct form,
//!   `f64`) driven by a deterministic error signal (two sines and a small step, a few mV: the
//!   command stays inside the window), from a 5 V command.
//! * **Output limits**: slew limit then window, in `f64`, on seeded random cases with the
//!   special values (NaN, infinities, far outside the window); cases within 1e-4 V of a
//!   boundary are skipped so that `f32` rounding cannot flip a flag.
//! * **Converter codes**: round-half-away-from-zero and saturate, in `f64`, on seeded random
//!   volts; values within 1e-3 LSB of a half code are skipped for the same reason.
//!
//! * **Hysteresis table**: the Preisach sum over the wiped-out turning-point stack, in `f64`
//!   ([`hysteresis_reference`]): `y = offset + sum of +E(s_k, s_k-1)` over rising segments and
//!   `-E(s_k-1, s_k)` over falling ones, with `E` interpolated in `f64` from the grid of
//!   `HysteresisTable::thesis_default()` (the table's data, not its arithmetic: model-core keeps
//!   the output at each turning point and adds one Everett difference per step, in `f32`).
//!   Input: nested reversals inside the range (0.5..9.5 V), then a rise that wipes them out.
//!
//! * **Pre-filter**: the step response of the default pre-filter (tau = 50 us, delay and
//!   hold shifted into the preview) from [`RefPreFilter`]: the transfer function evaluated on
//!   the unit circle and inverted by FFT, independent of model-core's sections.
//!
//! Values go in as IEEE bits (`u32`) so the target reads exactly what the host wrote.

use crate::oracle::lag::RefLag;
use crate::oracle::prefilter::RefPreFilter;
use crate::util::workspace_root;
use anyhow::{Context, Result};
use model_core::hysteresis::{GRID_NODES, HysteresisTable};
use model_core::params;
use rand::{Rng, SeedableRng, rngs::StdRng};
use std::fmt::Write as _;
use std::path::PathBuf;

/// Samples of the lag compensator's vector.
pub const LAG_SAMPLES: usize = 400;
/// Cases of the limits' vector.
pub const LIMIT_CASES: usize = 64;
/// Cases of the codes' vector.
pub const CODE_CASES: usize = 64;
/// Seed of the random cases.
pub const SEED: u64 = 0x5eed_0006;

/// Turning points of the hysteresis vector's input, volts at the amplifier input.
pub const HYST_TURNS_V: [f64; 12] = [0.5, 9.0, 2.0, 8.0, 3.0, 7.0, 4.0, 6.0, 4.5, 5.5, 9.2, 1.0];
/// Input step between samples of the hysteresis vector, volts.
pub const HYST_STEP_V: f64 = 0.1;

/// Samples of the pre-filter's step response.
pub const PREFILTER_SAMPLES: usize = 300;

/// The default pre-filter's unit step response from rest, `f64` reference.
pub fn prefilter_reference() -> Vec<f64> {
    RefPreFilter::thesis(params::PREFILTER_TAU_S)
        .with_hold()
        .step_response(PREFILTER_SAMPLES)
}

/// Where the generated file lives.
pub fn vectors_path() -> PathBuf {
    workspace_root().join("firmware/qemu/tests/vectors/mod.rs")
}

/// The lag compensator's test signal, volts of error (already `f32`, as the target sees it).
pub fn lag_errors() -> Vec<f32> {
    let t = 1.0 / params::SAMPLE_RATE_HZ;
    (0..LAG_SAMPLES)
        .map(|n| {
            let time = n as f64 * t;
            let e = 2e-3 * (2.0 * std::f64::consts::PI * 1500.0 * time).sin()
                + 1e-3 * (2.0 * std::f64::consts::PI * 230.0 * time).cos()
                + if n >= LAG_SAMPLES / 2 { -1e-3 } else { 0.0 };
            e as f32
        })
        .collect()
}

/// The reference commands for [`lag_errors`] from `u0_v`.
pub fn lag_reference(u0_v: f64, errors: &[f32]) -> Vec<f64> {
    let mut r = RefLag::new(
        params::LAG_KC,
        params::LAG_ZERO_RAD_S,
        params::LAG_POLE_RAD_S,
        1.0 / params::SAMPLE_RATE_HZ,
        u0_v,
    );
    errors.iter().map(|&e| r.step(e as f64)).collect()
}

/// Window and slew limit in `f64`: `(out, flags)` with the bits of `model_core::limits::Flags`
/// (1 clamped, 2 slew-limited, 4 non-finite).
pub fn limits_reference(last: f64, raw: f64) -> (f64, u8) {
    let slew = params::AMP_SLEW_INPUT_V_PER_S / params::SAMPLE_RATE_HZ;
    let (lo_w, hi_w) = (params::SAFE_WINDOW_MIN_V, params::SAFE_WINDOW_MAX_V);
    let mut flags = 0u8;
    let mut out = if raw.is_finite() {
        raw
    } else {
        flags |= 4;
        last
    };
    if out > last + slew {
        out = last + slew;
        flags |= 2;
    } else if out < last - slew {
        out = last - slew;
        flags |= 2;
    }
    if out > hi_w {
        out = hi_w;
        flags |= 1;
    } else if out < lo_w {
        out = lo_w;
        flags |= 1;
    }
    (out, flags)
}

fn near_limit_boundary(last: f64, raw: f64) -> bool {
    let slew = params::AMP_SLEW_INPUT_V_PER_S / params::SAMPLE_RATE_HZ;
    let edges = [
        last + slew,
        last - slew,
        params::SAFE_WINDOW_MIN_V,
        params::SAFE_WINDOW_MAX_V,
    ];
    raw.is_finite() && edges.iter().any(|e| (raw - e).abs() < 1e-4)
        || [last + slew, last - slew].iter().any(|e| {
            (e - params::SAFE_WINDOW_MIN_V).abs() < 1e-4
                || (e - params::SAFE_WINDOW_MAX_V).abs() < 1e-4
        })
}

/// `volts` to a code of `bits` bits over +-10 V in `f64`: nearest, half away from zero,
/// saturated.
pub fn code_reference(volts: f64, bits: u32) -> i32 {
    let lsb = params::CONVERTER_SPAN_V / (1u64 << bits) as f64;
    let max = (1i64 << (bits - 1)) - 1;
    let min = -(1i64 << (bits - 1));
    let x = volts / lsb;
    let r = if x >= 0.0 {
        (x + 0.5).floor()
    } else {
        (x - 0.5).ceil()
    };
    (r as i64).clamp(min, max) as i32
}

fn near_half_code(volts: f64) -> bool {
    [params::ADC_BITS, params::DAC_BITS].iter().any(|&bits| {
        let lsb = params::CONVERTER_SPAN_V / (1u64 << bits) as f64;
        let frac = (volts / lsb).abs().fract();
        (frac - 0.5).abs() < 1e-3
    })
}

/// The hysteresis vector's input: straight lines of [`HYST_STEP_V`] steps through
/// [`HYST_TURNS_V`], from the bottom of the range.
pub fn hysteresis_input() -> Vec<f32> {
    let mut u = Vec::new();
    let mut at = params::HYST_DEFAULT_INPUT_MIN_V;
    for &target in &HYST_TURNS_V {
        let n = ((target - at).abs() / HYST_STEP_V).ceil() as usize;
        for k in 1..=n {
            u.push((at + (target - at) * k as f64 / n as f64) as f32);
        }
        at = target;
    }
    u
}

/// The Everett function of `table`'s grid at `(alpha, beta)`, bilinear in `f64`, with the
/// antisymmetric extension in the diagonal cells (as the table defines it).
pub fn everett_reference(table: &HysteresisTable, alpha: f64, beta: f64) -> f64 {
    let (lo, hi) = table.input_range_v();
    let (lo, hi) = (lo as f64, hi as f64);
    let top = (GRID_NODES - 1) as f64;
    let step = (hi - lo) / top;
    let x = ((alpha - lo) / step).clamp(0.0, top);
    let y = ((beta - lo) / step).clamp(0.0, x);
    let i = (x.floor() as usize).min(GRID_NODES - 2);
    let j = (y.floor() as usize).min(GRID_NODES - 2);
    let (fx, fy) = (x - i as f64, y - j as f64);
    let e = |a: usize, b: usize| table.node(a, b) as f64;
    if i == j {
        return e(i + 1, i) * (fx - fy);
    }
    let a = e(i, j) + (e(i + 1, j) - e(i, j)) * fx;
    let b = e(i, j + 1) + (e(i + 1, j + 1) - e(i, j + 1)) * fx;
    a + (b - a) * fy
}

/// The Preisach output for the input sequence `u`, from the bottom of the range, in `f64`:
/// a stack of alternating turning points with wiping-out, summed afresh at every sample.
pub fn hysteresis_reference(table: &HysteresisTable, u: &[f32]) -> Vec<f64> {
    let (lo, _) = table.input_range_v();
    let mut stack: Vec<f64> = vec![lo as f64];
    let mut c = lo as f64;
    let offset = table.offset_v() as f64;
    let seg = |a: f64, b: f64| {
        if b >= a {
            everett_reference(table, b, a)
        } else {
            -everett_reference(table, a, b)
        }
    };
    u.iter()
        .map(|&x| {
            let x = x as f64;
            let rising = (stack.len() - 1).is_multiple_of(2);
            if x != c && (x > c) != rising && c != *stack.last().unwrap_or(&c) {
                stack.push(c);
            }
            loop {
                let n = stack.len() - 1;
                if n == 0 {
                    break;
                }
                let rising = n.is_multiple_of(2);
                let prev = stack[n - 1];
                let passes = if rising { x >= prev } else { x <= prev };
                if !passes {
                    break;
                }
                if n >= 2 {
                    stack.truncate(n - 1);
                } else {
                    stack.truncate(1);
                    break;
                }
            }
            c = x;
            let mut y = offset;
            for w in stack.windows(2) {
                y += seg(w[0], w[1]);
            }
            y + seg(*stack.last().unwrap_or(&x), x)
        })
        .collect()
}

fn bits_list(out: &mut String, name: &str, doc: &str, v: impl Iterator<Item = f32>) {
    let v: Vec<String> = v.map(|x| format!("0x{:08x}", x.to_bits())).collect();
    let _ = writeln!(out, "/// {doc}");
    let _ = writeln!(out, "pub const {name}: [u32; {}] = [", v.len());
    for chunk in v.chunks(8) {
        let _ = writeln!(out, "    {},", chunk.join(", "));
    }
    let _ = writeln!(out, "];");
}

/// The generated file's text.
pub fn generate() -> String {
    let mut s = String::new();
    s += "//! Reference vectors for the on-target tests, from host-tests' independent f64\n";
    s += "//! references. GENERATED by `cargo run -p host-tests --bin piezo -- qemu vectors --write`\n";
    s +=
        "//! (host-tests/src/qemu/vectors.rs); `host-tests/tests/qemu_vectors.rs` fails if it is\n";
    s += "//! stale. Values are IEEE `f32` bits.\n";
    s += "#![allow(dead_code)]\n\n";

    let u0 = model_core::scenarios::STEP_V;
    let errors = lag_errors();
    let reference = lag_reference(u0, &errors);
    let _ = writeln!(
        s,
        "/// Initial command of the lag vector, volts.\npub const LAG_U0_V: u32 = 0x{:08x};",
        (u0 as f32).to_bits()
    );
    bits_list(
        &mut s,
        "LAG_ERROR_V",
        "Error signal, volts.",
        errors.iter().copied(),
    );
    bits_list(
        &mut s,
        "LAG_COMMAND_V",
        "f64 reference command (RefLag), rounded to f32, volts.",
        reference.iter().map(|&u| u as f32),
    );

    bits_list(
        &mut s,
        "PREFILTER_STEP_V",
        "Unit step response of the default pre-filter from rest (RefPreFilter, f64), volts.",
        prefilter_reference().iter().map(|&y| y as f32),
    );

    let table = HysteresisTable::thesis_default();
    let hu = hysteresis_input();
    let hy = hysteresis_reference(&table, &hu);
    bits_list(
        &mut s,
        "HYST_INPUT_V",
        "Hysteresis input, volts at the amplifier input (from the bottom of the range).",
        hu.iter().copied(),
    );
    bits_list(
        &mut s,
        "HYST_OUTPUT_V",
        "f64 Preisach sum over the turning-point stack (thesis_default grid), sensor volts.",
        hy.iter().map(|&y| y as f32),
    );

    let mut rng = StdRng::seed_from_u64(SEED);
    let specials = [
        (5.0, f64::NAN),
        (5.0, f64::INFINITY),
        (5.0, f64::NEG_INFINITY),
        (9.5, 50.0),
        (0.5, -50.0),
        (5.0, 5.5),
        (5.0, 1.0),
        (9.9, 10.05),
    ];
    let mut cases: Vec<(f32, f32, f32, u8)> = specials
        .iter()
        .map(|&(l, r)| {
            let (o, f) = limits_reference(l, r);
            (l as f32, r as f32, o as f32, f)
        })
        .collect();
    while cases.len() < LIMIT_CASES {
        // f32 inputs first, so the reference sees exactly what the target sees.
        let last = rng.gen_range(0.0f32..10.0);
        let raw = rng.gen_range(-5.0f32..15.0);
        if near_limit_boundary(last as f64, raw as f64) {
            continue;
        }
        let (o, f) = limits_reference(last as f64, raw as f64);
        cases.push((last, raw, o as f32, f));
    }
    let _ = writeln!(
        s,
        "/// Limits cases `(last, raw, expected out, expected flags)` from the f64 reference."
    );
    let _ = writeln!(
        s,
        "pub const LIMIT_CASES: [(u32, u32, u32, u8); {}] = [",
        cases.len()
    );
    for (l, r, o, f) in &cases {
        let _ = writeln!(
            s,
            "    (0x{:08x}, 0x{:08x}, 0x{:08x}, {f}),",
            l.to_bits(),
            r.to_bits(),
            o.to_bits()
        );
    }
    s += "];\n";

    let mut codes: Vec<(f32, i32, i32)> = Vec::new();
    for v in [0.0f32, 9.99, 10.0, 12.0, -10.0, -11.0, 1e30, -1e30] {
        codes.push((
            v,
            code_reference(v as f64, params::ADC_BITS),
            code_reference(v as f64, params::DAC_BITS),
        ));
    }
    while codes.len() < CODE_CASES {
        let v = rng.gen_range(-10.5f32..10.5);
        if near_half_code(v as f64) {
            continue;
        }
        codes.push((
            v,
            code_reference(v as f64, params::ADC_BITS),
            code_reference(v as f64, params::DAC_BITS),
        ));
    }
    let _ = writeln!(
        s,
        "/// Codes cases `(volts, 16-bit ADC code, 14-bit DAC code)` from the f64 reference."
    );
    let _ = writeln!(
        s,
        "pub const CODE_CASES: [(u32, i16, i16); {}] = [",
        codes.len()
    );
    for (v, a, d) in &codes {
        let _ = writeln!(s, "    (0x{:08x}, {a}, {d}),", v.to_bits());
    }
    s += "];\n";
    s
}

/// Write the file (`piezo qemu vectors --write`); returns its path.
pub fn write() -> Result<PathBuf> {
    let path = vectors_path();
    let text = generate();
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

/// Check that the file is what [`generate`] produces now (`piezo qemu vectors`); returns its
/// path, or an error saying how to regenerate it.
pub fn check() -> Result<PathBuf> {
    let path = vectors_path();
    let text = generate();
    let current = std::fs::read_to_string(&path).unwrap_or_default();
    if current != text {
        anyhow::bail!(
            "{} is stale: regenerate with `cargo run -p host-tests --bin piezo -- qemu vectors --write`",
            path.display()
        );
    }
    Ok(path)
}
