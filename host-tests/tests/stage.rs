//! The non-linear stage (issue #4): drift against eq. 5.1-5.3, the composed stage against an
//! independent f64 reference, limits and energy sanity, each effect switchable, the drift
//! feedforward, and drift identification from a synthesised step record.

use host_tests::identify::drift::identify_drift;
use host_tests::oracle::drift::{DriftRef, step_response};
use host_tests::oracle::stage::{RefSwitches, StageRef};
use host_tests::sim::open_loop::simulate;
use model_core::drift::{Drift, DriftConfig, DriftState};
use model_core::gain::{FastGain, FastGainConfig};
use model_core::hysteresis::{HysteresisMemory, HysteresisTable};
use model_core::params;
use model_core::stage::{Feedforward, ModeConfig, Stage, StageConfig, StageState};
use model_core::{AdcCode, DacCode};
use proptest::prelude::*;

const T: f64 = params::STAGE_PERIOD_S;

/// thesis-full without noise, ADC and hysteresis table: deterministic and comparable with the
/// f64 reference (the table has its own tests on branch `hysteresis`; its wiring is checked in
/// `hysteresis_is_wired_before_the_dynamics`).
fn clean_full() -> StageConfig {
    let mut c = StageConfig::thesis_full();
    c.sensor.noise_v = 0.0;
    c.sensor.adc = false;
    c.hysteresis = None;
    c
}

#[test]
fn drift_step_responses_match_eq_5_1_to_5_3() {
    // Steps of 1..6 V from rest at 0 V, 30 s each (2.5 time constants of the slowest lag),
    // f32 model-core at 50 kHz against the closed form.
    let d = Drift::new(&DriftConfig::default(), T).unwrap();
    for h in 1..=6 {
        let h = h as f64;
        let mut s = DriftState::default();
        let n = (30.0 / T) as usize;
        let mut worst: f64 = 0.0;
        let mut last = 0.0;
        for k in 0..n {
            let y = d.step(&mut s, h as f32) as f64;
            // The lag driven by a held input over step k ends at (k + 1) T.
            let want = step_response(h, (k + 1) as f64 * T);
            worst = worst.max((y - want).abs());
            last = want;
        }
        let rel = worst / last;
        println!(
            "drift step {h} V: drift after 30 s {last:.5} V, max |error| {worst:.2e} V ({rel:.2e} of the drift)"
        );
        assert!(rel < 2e-5, "step {h} V: relative error {rel}");
    }
    // The 1 V step is eq. 5.1 alone (K(1) = 1 within the printed digits).
    let one = step_response(1.0, 1e6);
    assert!((one - 0.155).abs() < 2e-4, "{one}");
}

#[test]
fn drift_follows_the_reference_for_an_arbitrary_input() {
    // A slow staircase with a ramp and a return to 0.5 V, 20 s.
    let d = Drift::new(&DriftConfig::default(), T).unwrap();
    let mut s = d.steady_state(0.0);
    let mut r = DriftRef::thesis(T);
    let n = (20.0 / T) as usize;
    let mut worst: f64 = 0.0;
    for k in 0..n {
        let t = k as f64 * T;
        let u = if t < 5.0 {
            3.0
        } else if t < 12.0 {
            3.0 + (t - 5.0)
        } else {
            0.5
        };
        let a = d.step(&mut s, u as f32) as f64;
        let b = r.step(u as f32 as f64);
        worst = worst.max((a - b).abs());
    }
    println!("drift, arbitrary input over 20 s: max |f32 - f64| {worst:.2e} V");
    assert!(worst < 2e-5);
}

fn mixed_input(k: usize) -> f64 {
    // Steps (slew-limited at 3 V per sample), a sine, a ramp into the 12 V clamp and below -2 V.
    let t = k as f64 * T;
    if t < 0.01 {
        0.0
    } else if t < 0.03 {
        9.0
    } else if t < 0.06 {
        5.0 + 3.0 * (2.0 * std::f64::consts::PI * 200.0 * t).sin()
    } else if t < 0.08 {
        2.0 + 600.0 * (t - 0.06)
    } else {
        -3.0
    }
}

#[test]
fn stage_matches_the_f64_reference() {
    let sw = RefSwitches {
        dac: true,
        drift: true,
        nonlinear_gain: true,
        second_mode: None,
    };
    let stage = Stage::new(&clean_full()).unwrap();
    let mut s = stage.steady_state(0.0);
    let mut r = StageRef::new(sw, 0.0);
    let mut worst: f64 = 0.0;
    let mut worst_amp: f64 = 0.0;
    for k in 0..5000 {
        let u = mixed_input(k);
        let y = stage.step(&mut s, u as f32) as f64;
        let yr = r.step(u as f32 as f64);
        worst = worst.max((y - yr).abs());
        worst_amp = worst_amp.max((s.signals().amplifier_v as f64 - r.amplifier_v()).abs());
    }
    println!(
        "stage vs f64 reference, 0.1 s mixed input: max |dy| {worst:.2e} V, max |d amplifier| {worst_amp:.2e} V"
    );
    assert!(worst < 2e-4, "{worst}");
    assert!(worst_amp < 1e-4, "{worst_amp}");
}

#[test]
fn second_mode_matches_the_f64_reference() {
    // The 5-state exact discretisation against the reference's continuous second mode.
    let (f2, z2) = (params::SECOND_MODE_HZ, params::SECOND_MODE_DAMPING);
    let mut c = clean_full();
    c.second_mode = Some(ModeConfig {
        mode_hz: f2,
        damping: z2,
    });
    let sw = RefSwitches {
        dac: true,
        drift: true,
        nonlinear_gain: true,
        second_mode: Some((f2, z2)),
    };
    let stage = Stage::new(&c).unwrap();
    let mut s = stage.steady_state(0.0);
    let mut r = StageRef::new(sw, 0.0);
    let (mut worst, mut peak): (f64, f64) = (0.0, 0.0);
    for k in 0..5000 {
        let u = mixed_input(k);
        let y = stage.step(&mut s, u as f32) as f64;
        let yr = r.step(u as f32 as f64);
        worst = worst.max((y - yr).abs());
        peak = peak.max(yr.abs());
    }
    println!(
        "second mode {f2} Hz: max |dy| {worst:.2e} V against a peak of {peak:.2} V ({:.2} %)",
        100.0 * worst / peak
    );
    assert!(worst < 5e-4, "{worst}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Limits and energy sanity: whatever the command (NaN, huge, negative, jumping), the
    /// amplifier stays within its ranges, never slews faster than its limit, and the stage's
    /// output stays finite and bounded by the static output range times the peak gain of the
    /// dynamics.
    #[test]
    fn limits_hold_for_any_command(cmds in prop::collection::vec(
        prop_oneof![
            -20.0f32..20.0,
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(-1e30f32),
            Just(12.0f32),
            Just(-2.0f32),
        ], 1..40),
        hold in 1usize..200,
    ) {
        let stage = Stage::new(&StageConfig::thesis_full()).unwrap();
        let amp = stage.amplifier();
        let (lo, hi) = amp.output_range_v();
        let slew = amp.slew_v_per_step();
        let mut s = stage.steady_state(0.0);
        let mut last = s.signals().amplifier_v;
        // The largest static displacement (drift settled); the dynamics' impulse response has
        // an L1 norm below 8 for damping 0.08 (bounded input, bounded output).
        let d_max = stage.static_output(12.0).abs().max(stage.static_output(-2.0).abs()) as f64;
        let bound = 8.0 * d_max;
        for &c in &cmds {
            for _ in 0..hold {
                let y = stage.step(&mut s, c);
                let v = s.signals().amplifier_v;
                prop_assert!(y.is_finite() && (y as f64).abs() <= bound, "y {} bound {}", y, bound);
                prop_assert!(v >= lo && v <= hi, "amplifier {}", v);
                prop_assert!((v - last).abs() <= slew * (1.0 + 1e-6), "slew {} > {}", v - last, slew);
                last = v;
            }
        }
    }
}

#[test]
fn output_settles_to_the_static_map() {
    // Drift off (checked on its own above): its 60 ms lag still moves at 50 ms.
    let stage = Stage::new(&StageConfig {
        drift: None,
        ..clean_full()
    })
    .unwrap();
    for u in [0.5f32, 3.0, 7.5, 10.0] {
        let mut s = stage.steady_state(0.0);
        let mut y = 0.0;
        for _ in 0..(0.05 / T) as usize {
            y = stage.step(&mut s, u);
        }
        let want = host_tests::oracle::gain::fast_output(DacCode::from_volts(u).volts() as f64);
        println!("u {u} V: y {y:.6} V after 50 ms, reference fast map {want:.6} V");
        assert!(((y as f64) - want).abs() < 2e-5);
    }
}

fn response(c: &StageConfig, u: f32, n: usize) -> Vec<f32> {
    let stage = Stage::new(c).unwrap();
    let mut s = stage.steady_state(0.0);
    (0..n).map(|_| stage.step(&mut s, u)).collect()
}

#[test]
fn each_effect_switches_on_and_off() {
    let base = clean_full();
    // drift: 1 s after a 4 V step the drift adds K(4) 4 G_drift(1 s).
    let on = response(&base, 4.0, 50_000);
    let off = response(
        &StageConfig {
            drift: None,
            ..base
        },
        4.0,
        50_000,
    );
    let d = (on[49_999] - off[49_999]) as f64;
    let want = step_response(DacCode::from_volts(4.0).volts() as f64, 1.0);
    println!("drift: on - off after 1 s = {d:.5} V, eq. 5.1-5.3 {want:.5} V");
    assert!((d - want).abs() < 1e-4);
    // nonlinear-gain: fast gain at 10 V is 1.1 times the linear one.
    let base_nd = StageConfig {
        drift: None,
        ..base
    };
    let on = response(&base_nd, 10.0, 2000);
    let off = response(
        &StageConfig {
            nonlinear_gain: None,
            ..base_nd
        },
        10.0,
        2000,
    );
    let ratio = on[1999] / off[1999];
    println!("nonlinear-gain: y ratio at 10 V {ratio:.5} (K'(10) = 1.1)");
    assert!((ratio - 1.1).abs() < 1e-4);
    // slew-rate-limit: a 0 -> 10 V command moves the output 30 V in the first sample with the
    // limiter, 100 V without.
    let stage_on = Stage::new(&base).unwrap();
    let mut no_slew = base;
    no_slew.amplifier.slew_v_per_s = None;
    let stage_off = Stage::new(&no_slew).unwrap();
    let (mut a, mut b) = (stage_on.steady_state(0.0), stage_off.steady_state(0.0));
    stage_on.step(&mut a, 10.0);
    stage_off.step(&mut b, 10.0);
    println!(
        "slew-rate-limit: amplifier after one sample {} V (limiter) vs {} V",
        a.signals().amplifier_v,
        b.signals().amplifier_v
    );
    assert!((a.signals().amplifier_v - 30.0).abs() < 1e-3);
    // (the DAC's top code is 10 V - 1 LSB)
    assert!((b.signals().amplifier_v - 10.0 * DacCode::from_volts(10.0).volts()).abs() < 1e-3);
    // saturation: -5 V is clamped to -2 V (-20 V out) with it, not without.
    let mut no_sat = base;
    no_sat.amplifier.saturation = false;
    no_sat.amplifier.slew_v_per_s = None;
    let mut sat = base;
    sat.amplifier.slew_v_per_s = None;
    let (p, q) = (Stage::new(&sat).unwrap(), Stage::new(&no_sat).unwrap());
    let (mut a, mut b) = (p.steady_state(0.0), q.steady_state(0.0));
    p.step(&mut a, -5.0);
    q.step(&mut b, -5.0);
    println!(
        "saturation: amplifier at a -5 V command {} V (on) vs {} V (off)",
        a.signals().amplifier_v,
        b.signals().amplifier_v
    );
    assert!(
        (a.signals().amplifier_v + 20.0).abs() < 1e-3
            && (b.signals().amplifier_v + 50.0).abs() < 0.01
    );
    // time-delay: the first moving sample is the 5th (85 us = 4.25 samples) with it, the 1st
    // without.
    let first = |c: &StageConfig| response(c, 1.0, 20).iter().position(|y| y.abs() > 1e-9);
    let with = first(&base);
    let without = first(&StageConfig {
        delay_s: 0.0,
        ..base
    });
    println!("time-delay: first moving sample {with:?} (85 us) vs {without:?} (none)");
    assert_eq!((with, without), (Some(4), Some(0)));
    // amplifier-pole: without the 2 kHz pole the 10-90 % rise is faster.
    let rise = |c: &StageConfig| {
        let y = response(c, 1.0, 2000);
        let f = y[1999];
        let a = y.iter().position(|v| *v > 0.1 * f).unwrap_or(0);
        let b = y.iter().position(|v| *v > 0.9 * f).unwrap_or(0);
        (b - a) as f64 * T
    };
    let (r_on, r_off) = (
        rise(&base_nd),
        rise(&StageConfig {
            amp_pole_hz: None,
            ..base_nd
        }),
    );
    println!(
        "amplifier-pole: 10-90 % rise {:.1} us with, {:.1} us without",
        r_on * 1e6,
        r_off * 1e6
    );
    assert!(r_on > r_off);
    // resonance: a second mode keeps the static gain and changes the transient.
    let m2 = StageConfig {
        second_mode: Some(ModeConfig {
            mode_hz: params::SECOND_MODE_HZ,
            damping: params::SECOND_MODE_DAMPING,
        }),
        ..base_nd
    };
    let (y1, y2) = (response(&base_nd, 1.0, 5000), response(&m2, 1.0, 5000));
    let diff = y1
        .iter()
        .zip(&y2)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    println!(
        "resonance: static {:.5} vs {:.5} V, max transient difference {diff:.4} V",
        y1[4999], y2[4999]
    );
    assert!((y1[4999] - y2[4999]).abs() < 1e-4 && diff > 0.01);
    // dac: 0.4 mV is below half a DAC LSB (0.61 mV): no motion with the DAC, some without.
    let small = |c: &StageConfig| response(c, 4e-4, 2000)[1999];
    let no_dac = StageConfig {
        dac: false,
        ..base_nd
    };
    println!(
        "dac: y for a 0.4 mV command {} V (DAC) vs {} V",
        small(&base_nd),
        small(&no_dac)
    );
    assert!(small(&base_nd) == 0.0 && small(&no_dac) > 0.0);
    // adc: every reading is a whole number of ADC codes.
    let mut adc = base_nd;
    adc.sensor.adc = true;
    let y = response(&adc, 3.3, 500);
    assert!(y.iter().all(|v| AdcCode::from_volts(*v).volts() == *v));
    // noise: the standard deviation at rest is the configured 2.5 mV.
    let mut noisy = base_nd;
    noisy.sensor.noise_v = params::SENSOR_NOISE_V;
    let y = response(&noisy, 0.0, 100_000);
    let m = y.iter().map(|v| *v as f64).sum::<f64>() / y.len() as f64;
    let sd = (y.iter().map(|v| (*v as f64 - m).powi(2)).sum::<f64>() / y.len() as f64).sqrt();
    println!(
        "noise: measured sigma {:.3} mV (configured {:.3} mV)",
        sd * 1e3,
        params::SENSOR_NOISE_V * 1e3
    );
    assert!((sd / params::SENSOR_NOISE_V - 1.0).abs() < 0.02);
}

/// Open-loop tracking of `r`: `u = r / 0.79` uncompensated, or the feedforward's command.
/// Errors over the second half, relative to the 8 V span: (RMS, peak).
fn track(
    stage: &Stage,
    ff: Option<&Feedforward>,
    r: &dyn Fn(f64) -> f64,
    seconds: f64,
) -> (f64, f64) {
    let n = (seconds / T) as usize;
    let mut s = stage.steady_state(0.0);
    let mut fs = ff.map(|f| f.steady_state(0.0));
    let (mut sq, mut peak, mut cnt) = (0.0, 0.0f64, 0usize);
    for k in 0..n {
        let t = k as f64 * T;
        // The plant delays by 85 us: command what is wanted one delay ahead.
        let rr = r(t + params::PLANT_DELAY_S);
        let u = match (ff, fs.as_mut()) {
            (Some(f), Some(st)) => f.step(st, rr as f32),
            _ => (rr / params::PLANT_GAIN) as f32,
        };
        let y = stage.step(&mut s, u) as f64;
        if t > seconds / 2.0 {
            let e = y - r(t + T);
            sq += e * e;
            peak = peak.max(e.abs());
            cnt += 1;
        }
    }
    ((sq / cnt as f64).sqrt() / 8.0, peak / 8.0)
}

#[test]
fn drift_and_gain_feedforward_cut_open_loop_tracking_error() {
    // Issue #4 item 8, the drift (and static gain) part, on the virtual stage without a
    // hysteresis table: 1 Hz 0-8 V sine and 1/6 Hz 0-8 V triangle, 12 s each.
    let stage = Stage::new(&clean_full()).unwrap();
    // The drift keeps the output above 0 V at a 0 V command: reaching 0 V needs commands down
    // to the amplifier's -2 V (open loop there is no controller window to respect).
    let ff = Feedforward::new(&stage, -2.0, 12.0).unwrap();
    let sine = |t: f64| 4.0 * (1.0 - (2.0 * std::f64::consts::PI * t).cos());
    let tri = |t: f64| {
        let p = (t / 6.0).rem_euclid(1.0);
        8.0 * if p < 0.5 { 2.0 * p } else { 2.0 - 2.0 * p }
    };
    for (name, r) in [
        ("1 Hz sine", &sine as &dyn Fn(f64) -> f64),
        ("1/6 Hz triangle", &tri),
    ] {
        let (rms0, pk0) = track(&stage, None, r, 12.0);
        let (rms1, pk1) = track(&stage, Some(&ff), r, 12.0);
        println!(
            "{name}: uncompensated RMS {:.2} % peak {:.2} % of span; drift+gain feedforward RMS {:.3} % peak {:.3} %",
            100.0 * rms0,
            100.0 * pk0,
            100.0 * rms1,
            100.0 * pk1
        );
        assert!(pk0 > 0.10, "uncompensated peak {pk0}");
        assert!(pk1 < 0.015, "compensated peak {pk1}");
    }
}

#[test]
fn drift_identified_from_a_synthesised_step() {
    // Hidden truth: other drift gains and time constants than the thesis'; 1 mV noise and the
    // 16-bit ADC; 60 s step record of 3 V at 1 kHz. The identification starts from the thesis
    // drift and must find the truth's step response.
    let mut truth = StageConfig::thesis_full();
    truth.sensor.noise_v = 1e-3;
    truth.sensor.seed = 42;
    let hidden = DriftConfig {
        gains: [0.03, 0.08, 0.04],
        taus_s: [0.1, 1.5, 7.0],
        ..DriftConfig::default()
    };
    truth.drift = Some(hidden);
    let stage = Stage::new(&truth).unwrap();
    let rate = 1000.0;
    let n = (60.0 * rate) as usize;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / rate).collect();
    let u: Vec<f64> = t.iter().map(|&t| if t < 0.5 { 0.0 } else { 3.0 }).collect();
    let y = simulate(&stage, T, &t, &u);
    let fit = identify_drift(&t, &u, &y, &DriftConfig::default()).unwrap();
    println!(
        "identified gains {:?} taus {:?}, residual {:.3} mV",
        fit.config.gains,
        fit.config.taus_s,
        1e3 * fit.rms_residual_v
    );
    // Compare the drift step responses over 0..60 s.
    let h = DacCode::from_volts(3.0).volts() as f64;
    let dw = hidden.weight(h);
    let resp = |c: &DriftConfig, t: f64| -> f64 {
        (0..3)
            .map(|i| c.gains[i] * dw * (1.0 - (-t / c.taus_s[i]).exp()))
            .sum()
    };
    let mut worst: f64 = 0.0;
    for k in 1..=6000 {
        let tt = k as f64 * 0.01;
        worst = worst.max((resp(&fit.config, tt) - resp(&hidden, tt)).abs());
    }
    let total = resp(&hidden, 1e6);
    println!(
        "identified drift step response: max error {:.3} mV over 60 s (drift {:.1} mV)",
        1e3 * worst,
        1e3 * total
    );
    assert!(worst < 2e-3, "{worst}");
    assert!(fit.rms_residual_v < 1e-3);
}

#[test]
fn hysteresis_is_wired_before_the_dynamics() {
    // thesis-full without noise and drift: along a slow triangle with reversals, the stage
    // output equals K'(ue) H(ue) of a separate table memory driven by the same inputs, i.e. the
    // table sits between the amplifier and the unity-gain dynamics.
    let mut c = StageConfig::thesis_full();
    c.sensor.noise_v = 0.0;
    c.sensor.adc = false;
    c.drift = None;
    let stage = Stage::new(&c).unwrap();
    let table = HysteresisTable::thesis_default();
    let g = FastGain::new(&FastGainConfig::default()).unwrap();
    let mut mem = HysteresisMemory::new();
    mem.reset(&table, 0.0);
    let mut s = stage.steady_state(0.0);
    let (mut worst, mut width): (f64, f64) = (0.0, 0.0);
    let n = (2.0 / T) as usize;
    let (mut up, mut down) = (None, None);
    for k in 0..n {
        let t = k as f64 * T;
        // 0 -> 9 -> 3 -> 7 V at 1 V per 100 ms (quasi-static).
        let u = if t < 0.9 {
            10.0 * t
        } else if t < 1.5 {
            9.0 - 10.0 * (t - 0.9)
        } else {
            3.0 + 10.0 * (t - 1.5)
        };
        let u = u.min(7.0 + 10.0 * (2.0 - t).max(0.0)) as f32;
        let y = stage.step(&mut s, u);
        let ue = s.signals().amplifier_v / 10.0;
        let want = g.gain(ue) * table.forward(&mut mem, ue);
        // Compare with the input 85 us earlier: the plant's delay and lag.
        if k > 100 {
            worst = worst.max((s.signals().fast_v - want).abs() as f64);
        }
        if (t - 0.5).abs() < T / 2.0 {
            up = Some(y);
        }
        if (t - 1.3).abs() < T / 2.0 {
            down = Some(y);
        }
    }
    if let (Some(a), Some(b)) = (up, down) {
        width = (b - a) as f64;
    }
    println!(
        "hysteresis wiring: max |fast - K' H| {worst:.2e} V; at 5 V the falling branch is {width:.3} V above the rising one"
    );
    assert!(worst < 1e-5);
    assert!(width > 0.5, "{width}");
    // Switched off, the same input gives no loop.
    let off = Stage::new(&StageConfig {
        hysteresis: None,
        ..c
    })
    .unwrap();
    let mut s = off.steady_state(0.0);
    let mut ys = vec![];
    for k in 0..(1.5 / T) as usize {
        let t = k as f64 * T;
        let u = if t < 0.9 {
            10.0 * t
        } else {
            9.0 - 10.0 * (t - 0.9)
        };
        ys.push(off.step(&mut s, u as f32));
    }
    let w = ys[(1.3 / T) as usize] - ys[(0.5 / T) as usize];
    // Only the dynamics' lag remains: about 0.17 ms (delay + pole) at 10 V/s on each branch.
    println!("hysteresis off: falling - rising at 5 V = {w:.5} V (dynamic lag only)");
    assert!(w.abs() < 5e-3);
}

#[test]
fn feedforward_with_hysteresis_table() {
    // Issue #4 item 8 on the full virtual stage (table, drift, K', converters; no noise): the
    // figures for the lead. The table covers 0..10 V at the amplifier input, so outputs below the
    // accumulated drift cannot be reached near r = 0 (reported, asserted only as an improvement).
    let mut c = StageConfig::thesis_full();
    c.sensor.noise_v = 0.0;
    let stage = Stage::new(&c).unwrap();
    let ff = Feedforward::new(&stage, -2.0, 12.0).unwrap();
    let sine = |t: f64| 4.0 * (1.0 - (2.0 * std::f64::consts::PI * t).cos());
    let tri = |t: f64| {
        let p = (t / 6.0).rem_euclid(1.0);
        8.0 * if p < 0.5 { 2.0 * p } else { 2.0 - 2.0 * p }
    };
    let sine_hi = |t: f64| 1.0 + 4.0 * (1.0 - (2.0 * std::f64::consts::PI * t).cos());
    for (name, r) in [
        ("1 Hz sine 0-8 V", &sine as &dyn Fn(f64) -> f64),
        ("1/6 Hz triangle 0-8 V", &tri),
        ("1 Hz sine 1-9 V", &sine_hi),
    ] {
        let (rms0, pk0) = track(&stage, None, r, 12.0);
        let (rms1, pk1) = track(&stage, Some(&ff), r, 12.0);
        println!(
            "full stage, {name}: uncompensated RMS {:.2} % peak {:.2} % of span; feedforward RMS {:.3} % peak {:.3} %",
            100.0 * rms0,
            100.0 * pk0,
            100.0 * rms1,
            100.0 * pk1
        );
        assert!(pk0 > 0.10 && rms1 < 0.5 * rms0);
    }
}

#[test]
fn stage_refuses_absurd_configurations() {
    let ok = StageConfig::thesis_full();
    let bad = [
        StageConfig {
            period_s: 1.0,
            ..ok
        },
        StageConfig { delay_s: 1.0, ..ok },
        StageConfig {
            static_gain: f64::NAN,
            ..ok
        },
        StageConfig {
            second_mode: Some(ModeConfig {
                mode_hz: 30e3,
                damping: 0.1,
            }),
            ..ok
        },
        StageConfig {
            drift: Some(DriftConfig {
                taus_s: [-1.0, 1.0, 2.0],
                ..DriftConfig::default()
            }),
            ..ok
        },
    ];
    for c in bad {
        assert!(Stage::new(&c).is_err(), "{c:?}");
    }
}

/// A stage at rest reads, before its first step, what its first step with the input held
/// reads: the sensor's scale and offset included (before session 39 the reading at rest was
/// the position itself, so the first sample of every simulation of a model with a sensor
/// offset lacked it). Checked with and without the second mode, the ADC and a hysteresis
/// table, at several inputs, to within one ADC code (the step quantises its reading).
#[test]
fn the_reading_at_rest_is_the_first_steps_reading() {
    for (second_mode, adc, table) in [
        (false, false, false),
        (true, false, false),
        (false, true, true),
    ] {
        let mut c = clean_full();
        c.sensor.gain = 1.03;
        c.sensor.offset_v = 0.012;
        c.sensor.adc = adc;
        if second_mode {
            c.second_mode = Some(ModeConfig {
                mode_hz: 4000.0,
                damping: 0.05,
            });
        }
        if table {
            c.hysteresis = StageConfig::thesis_full().hysteresis;
        }
        let stage = Stage::new(&c).unwrap();
        for u in [0.0f32, 2.5, 7.0] {
            let mut s = stage.steady_state(u);
            let at_rest = s.signals().measured_v as f64;
            let first = stage.step(&mut s, u) as f64;
            let tol = if adc {
                AdcCode::VOLT_PER_LSB as f64
            } else {
                1e-5
            };
            assert!(
                (at_rest - first).abs() <= tol,
                "mode {second_mode}, adc {adc}, table {table}, u {u} V: at rest {at_rest} V, \
                 first step {first} V"
            );
            // (the offset is in it: a reading at 0 V is the offset, not 0)
            if u == 0.0 && !table {
                assert!((at_rest - 0.012).abs() <= tol, "{at_rest}");
            }
        }
    }
}

/// The stages `Stage::step_held` is checked on: every block the simulations use, the
/// thesis' full stage with its noise and converters (the noise sequence must be the same),
/// a second mode, play operators beside a DAC and a slew limit, and the linear model.
fn held_step_stages() -> Vec<StageConfig> {
    let full = StageConfig::thesis_full();
    let mut two_modes = clean_full();
    two_modes.second_mode = Some(ModeConfig {
        mode_hz: params::SECOND_MODE_HZ,
        damping: params::SECOND_MODE_DAMPING,
    });
    two_modes.hysteresis = Some(HysteresisTable::thesis_default());
    let mut play = StageConfig::thesis_linear();
    play.dac = true;
    play.amplifier = model_core::amplifier::AmplifierConfig::default();
    play.play = Some(model_core::play::PlayConfig {
        radii_v: params::PLAY_RADII_V,
        weights: [0.02, -0.01, 0.03, 0.0, 0.015, 0.01, -0.005, 0.02],
    });
    vec![full, two_modes, play, StageConfig::thesis_linear()]
}

/// `n` single steps of the command `u` from `s`: the reading after them (the last one's
/// before them if `n` is 0).
fn single_steps(stage: &Stage, s: &mut StageState, u: f32, n: u32) -> f32 {
    let mut y = s.signals().measured_v;
    for _ in 0..n {
        y = stage.step(s, u);
    }
    y
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// A hold of `n` steps at once leaves the state and the reading of `n` single steps, to
    /// the bit: through slewing, the table's turning points, a command held at the code it
    /// already had, non-finite commands (the amplifier holds), and the sensor's noise. The
    /// states are compared through their `Debug` text, which tells every finite `f32` apart
    /// (-0.0 from 0.0 too) and shows a NaN as NaN, where `==` would take -0.0 for 0.0 and a
    /// NaN for unequal to itself.
    #[test]
    fn a_held_command_steps_as_its_single_steps(
        which in 0usize..4,
        holds in proptest::collection::vec(
            (
                prop_oneof![
                    16 => -1.0f32..11.0,
                    1 => Just(f32::NAN),
                    1 => Just(f32::INFINITY),
                    1 => Just(f32::NEG_INFINITY),
                ],
                0u32..120,
                any::<bool>(),
            ),
            1..40,
        ),
    ) {
        let stage = Stage::new(&held_step_stages()[which]).unwrap();
        let mut one = stage.steady_state(holds[0].0);
        let mut held = one.clone();
        let mut last_u = holds[0].0;
        for &(u, n, repeat) in &holds {
            let u = if repeat { last_u } else { u };
            last_u = u;
            let y_one = single_steps(&stage, &mut one, u, n);
            let y_held = stage.step_held(&mut held, u, n);
            prop_assert_eq!(y_one.to_bits(), y_held.to_bits(), "reading after {} steps at {} V", n, u);
            prop_assert_eq!(format!("{one:?}"), format!("{held:?}"));
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// The closed form of a hold (`Stage::held_map`, one product past the fast part's fixed
    /// point) leaves the reading and the position of `n` single steps to within
    /// `HELD_CLOSED_TOL_V`, hold after hold (so the state it leaves is right too): through
    /// slewing, the table's turning points, a second mode, play operators and the drift's
    /// lags. With the sensor's noise (the thesis' full stage) the map is not used and the
    /// readings are the single steps', to the bit.
    #[test]
    fn a_hold_in_closed_form_reads_as_its_single_steps(
        which in 0usize..4,
        holds in proptest::collection::vec((-1.0f32..11.0, 0u32..400, any::<bool>()), 1..40),
    ) {
        let stage = Stage::new(&held_step_stages()[which]).unwrap();
        let noisy = which == 0;
        let mut one = stage.steady_state(holds[0].0);
        let mut held = one.clone();
        let mut last_u = holds[0].0;
        let mut maps = std::collections::HashMap::new();
        for &(u, n, repeat) in &holds {
            let u = if repeat { last_u } else { u };
            last_u = u;
            let y_one = single_steps(&stage, &mut one, u, n);
            let left = stage.settle_held(&mut held, u, n);
            let map = maps.entry(left).or_insert_with(|| stage.held_map(left));
            let y_held = stage.finish_held(&mut held, left, map.as_ref());
            if noisy {
                prop_assert_eq!(y_one.to_bits(), y_held.to_bits());
            }
            for (what, a, b) in [
                ("reading", y_one, y_held),
                ("position", one.signals().position_v, held.signals().position_v),
                ("drift", one.signals().drift_v, held.signals().drift_v),
            ] {
                prop_assert!(
                    (a - b).abs() <= HELD_CLOSED_TOL_V[which],
                    "{} after {} steps at {} V: {} stepped, {} closed",
                    what, n, u, a, b
                );
            }
        }
    }
}

/// How far the closed form of a hold may read from the single steps, per stage of
/// `held_step_stages`: a twentieth of a 16-bit code over the sensor's 20 V (15 uV) on the
/// plant, a quarter (76 uV) on the two modes. The closed form keeps full `f32` precision
/// against an `f64` reference (model-core's `a_hold_in_closed_form_matches_the_f64_reference`,
/// which checks the delay line's inputs too); the single steps round at every step, and
/// through the lightly damped second mode that rounding builds up. Measured over 1200 random
/// cases when this test was written (session 43): 44 uV apart at most on the two modes, 5.7 uV
/// on the linear model, 3.8 uV with play operators. (The thesis' full stage is noisy: no map,
/// the bits compared.)
const HELD_CLOSED_TOL_V: [f32; 4] = [
    0.0,
    0.25 * AdcCode::VOLT_PER_LSB,
    0.05 * AdcCode::VOLT_PER_LSB,
    0.05 * AdcCode::VOLT_PER_LSB,
];
