//! The lag compensator (model-core, f32) against the independent f64 reference, and its
//! limits: anti-windup, slew, NaN.

use host_tests::oracle::lag::RefLag;
use model_core::DacCode;
use model_core::lag::{LagCompensator, LagConfig, LagState};
use model_core::limits::Flags;
use proptest::prelude::*;
use rand::{Rng, SeedableRng, rngs::StdRng};

/// Drive both with `errors` from `u0`; return the largest DAC-code difference and the largest
/// difference in volts.
fn compare(cfg: &LagConfig, u0: f64, errors: impl Iterator<Item = f64>) -> (i32, f64) {
    let lag = LagCompensator::new(cfg).unwrap();
    let mut st = LagState::new(u0 as f32);
    let mut r = RefLag::new(cfg.kc, cfg.zero_rad_s, cfg.pole_rad_s, cfg.period_s, u0);
    let mut worst_lsb = 0;
    let mut worst_v: f64 = 0.0;
    for e in errors {
        let (u, flags) = lag.update_flags(&mut st, e as f32);
        let ur = r.step(e);
        assert_eq!(
            flags,
            Flags::NONE,
            "the test signal must stay inside the limits (u = {ur})"
        );
        let d = (DacCode::from_volts(u).value() as i32
            - DacCode::from_volts(ur as f32).value() as i32)
            .abs();
        worst_lsb = worst_lsb.max(d);
        worst_v = worst_v.max((u as f64 - ur).abs());
    }
    (worst_lsb, worst_v)
}

/// 1.2e6 samples of steps, ramps, sines and noise, chosen to keep the command inside 0..10 V
/// (the integrator turns 1 mV of error into 0.2 V/ms, so the error signals are small and
/// mostly zero-mean, as a working loop's are).
fn mixed_errors(seed: u64) -> impl Iterator<Item = f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    let t = 20e-6;
    (0..1_200_000usize).map(move |n| {
        let seg = n / 200_000;
        let k = (n % 200_000) as f64;
        let tt = k * t;
        match seg {
            // Square steps of +-1 mV every 50 ms.
            0 => {
                if (k as usize / 2500).is_multiple_of(2) {
                    1e-3
                } else {
                    -1e-3
                }
            }
            // Ramps: a triangle of +-2 mV at 5 Hz.
            1 => 2e-3 * (1.0 - 4.0 * ((tt * 5.0 + 0.25).fract() - 0.5).abs()),
            // Sines of 5 mV at 100 Hz, then 0.2 V at 3 kHz (near crossover).
            2 => 5e-3 * (2.0 * std::f64::consts::PI * 100.0 * tt).cos(),
            3 => 0.2 * (2.0 * std::f64::consts::PI * 3000.0 * tt).cos(),
            // White noise of 1 mV rms plus 1 ADC LSB-sized dither.
            4 => rng.gen_range(-1.7e-3..1.7e-3),
            // A tiny constant (slow drift of the integrator) with noise on top.
            _ => 5e-6 + rng.gen_range(-3e-4..3e-4),
        }
    })
}

#[test]
fn dac_codes_match_f64_reference_over_a_million_steps() {
    let cfg = LagConfig::default();
    let (lsb, volts) = compare(&cfg, 5.0, mixed_errors(1));
    println!(
        "1.2e6 steps: largest DAC difference {lsb} LSB, largest command difference {volts:.3e} V"
    );
    assert!(lsb <= 1, "DAC codes differ by {lsb} LSB");
    // Half an LSB in volts is what rounding allows at a code boundary; the f32 path holds far
    // tighter than that.
    assert!(
        volts < 0.5 * DacCode::VOLT_PER_LSB as f64,
        "command differs by {volts} V"
    );
}

#[test]
fn constant_error_integrates_without_drift() {
    // 2e-5 V for 10 s (5e5 samples): the command rises 2 V plus the lag's small dip. The f32
    // state must track the f64 reference to far better than an LSB over all of it.
    let cfg = LagConfig::default();
    let lag = LagCompensator::new(&cfg).unwrap();
    let mut st = LagState::new(3.0);
    let mut r = RefLag::new(cfg.kc, cfg.zero_rad_s, cfg.pole_rad_s, cfg.period_s, 3.0);
    let e = 2e-5;
    let mut worst: f64 = 0.0;
    let mut u = 0.0;
    for _ in 0..500_000 {
        u = lag.update(&mut st, e as f32) as f64;
        worst = worst.max((u - r.step(e)).abs());
    }
    // Continuous response, step taken at T/2 (Tustin): u0 + Kc e (t + (p - z)/p (1 - e^{-pt})).
    let t = 10.0 - 10e-6;
    let p = cfg.pole_rad_s;
    let want = 3.0 + cfg.kc * e * (t + (p - 1.0) / p * (1.0 - (-p * t).exp()));
    println!("after 10 s: f32 {u:.6} V, continuous {want:.6} V, worst f32-f64 gap {worst:.2e} V");
    assert!(worst < 1e-4, "drift {worst}");
    assert!((u - want).abs() < 2e-4);
}

#[test]
fn a_plain_f32_direct_form_would_not_hold() {
    // Why the realisation matters: the same loop in a plain f32 direct form II transposed
    // misplaces the lag pole. Measured against the f64 reference with the same input.
    let cfg = LagConfig::default();
    let k = 2.0 / cfg.period_s;
    let (kc, z, p) = (cfg.kc, cfg.zero_rad_s, cfg.pole_rad_s);
    let a0 = k * k + p * k;
    let b = [
        kc * p * (k + z) / a0,
        2.0 * kc * p * z / a0,
        kc * p * (z - k) / a0,
    ]
    .map(|v| v as f32);
    let a = [(-2.0 * k * k) / a0, (k * k - p * k) / a0].map(|v| v as f32);
    let (mut s1, mut s2) = (-(a[0] + a[1]) * 3.0, -a[1] * 3.0);
    let mut r = RefLag::new(kc, z, p, cfg.period_s, 3.0);
    let mut worst: f64 = 0.0;
    for _ in 0..500_000 {
        let e = 2e-5f32;
        let y = b[0] * e + s1;
        s1 = b[1] * e - a[0] * y + s2;
        s2 = b[2] * e - a[1] * y;
        worst = worst.max((y as f64 - r.step(e as f64)).abs());
    }
    println!("plain f32 direct form: worst gap {worst:.3} V over 10 s");
    assert!(worst > 10.0 * DacCode::VOLT_PER_LSB as f64);
}

#[test]
fn long_saturation_recovers_at_once() {
    // Drive the command into the 10 V clamp for 10 s with a large error, then reverse the
    // error: with anti-windup the command leaves the clamp within a few samples and reaches
    // mid-window at the slew/integration rate, not after unwinding 10 s of integral.
    let cfg = LagConfig::default();
    let lag = LagCompensator::new(&cfg).unwrap();
    let mut st = LagState::new(5.0);
    for _ in 0..500_000 {
        let (u, f) = lag.update_flags(&mut st, 1.0);
        assert!(u <= 10.0);
        let _ = f;
    }
    assert_eq!(st.output_v(), 10.0);
    let mut left_after = None;
    let mut below_5_after = None;
    for n in 0..50_000 {
        let u = lag.update(&mut st, -0.01);
        if left_after.is_none() && u < 10.0 {
            left_after = Some(n);
        }
        if u < 5.0 {
            below_5_after = Some(n);
            break;
        }
    }
    println!(
        "left the clamp after {left_after:?} samples, below 5 V after {below_5_after:?} samples"
    );
    assert!(left_after.unwrap() <= 2);
    // Without windup the way down is what the compensator does from rest: for t << 1/p its
    // gain is Kc p / s, so 5 V at Kc p 0.01 = 39.8 V/s takes 126 ms. Allow 5 % for the lag
    // term's curvature; a wound-up state would add seconds.
    let expect = 5.0 / (cfg.kc * cfg.pole_rad_s * 0.01) / cfg.period_s;
    println!("expected without windup: {expect:.0} samples");
    assert!((below_5_after.unwrap() as f64) < 1.05 * expect);
}

#[test]
fn slew_limit_is_never_exceeded_and_nan_never_reaches_the_output() {
    let cfg = LagConfig::default();
    let lag = LagCompensator::new(&cfg).unwrap();
    let mut st = LagState::new(0.0);
    let mut rng = StdRng::seed_from_u64(7);
    let mut last = 0.0f32;
    let mut worst_step: f32 = 0.0;
    for n in 0..200_000 {
        let e = match n % 1000 {
            0 => f32::NAN,
            1 => f32::INFINITY,
            2 => f32::NEG_INFINITY,
            _ => rng.gen_range(-50.0..50.0),
        };
        let u = lag.update(&mut st, e);
        assert!(u.is_finite());
        assert!((0.0..=10.0).contains(&u));
        worst_step = worst_step.max((u - last).abs());
        if !e.is_finite() {
            assert_eq!(u, last, "a non-finite error holds the command");
        }
        last = u;
    }
    println!(
        "largest step {worst_step} V per sample (limit {})",
        lag.limits.slew_v_per_step
    );
    assert!(worst_step <= lag.limits.slew_v_per_step * (1.0 + 1e-6));
}

#[test]
fn reset_is_bumpless() {
    let lag = LagCompensator::new(&LagConfig::default()).unwrap();
    let mut st = LagState::new(0.0);
    for _ in 0..1000 {
        lag.update(&mut st, 0.01);
    }
    st.reset_to(4.0);
    let u = lag.update(&mut st, 0.0);
    assert!((u - 4.0).abs() < 1e-6, "{u}");
    st.reset_to(f32::NAN);
    assert!((st.output_v() - 4.0).abs() < 1e-6);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Random compensators and rates, random small error sequences: DAC codes within 1 LSB
    /// of the f64 reference at every step.
    #[test]
    fn random_parameters_agree_with_reference(
        kc in 1e3f64..3e4,
        zero in 0.2f64..20.0,
        ratio in 0.1f64..0.9,
        rate in 10e3f64..200e3,
        amp in 1e-5f64..2e-3,
        freq in 0.5f64..2000.0,
        seed in any::<u64>(),
    ) {
        let cfg = LagConfig {
            kc,
            zero_rad_s: zero,
            pole_rad_s: zero * ratio,
            period_s: 1.0 / rate,
            ..LagConfig::default()
        };
        let mut rng = StdRng::seed_from_u64(seed);
        let t = cfg.period_s;
        // Zero-mean: a sine plus noise; integral amplitude kc*amp/(2 pi f) stays in the window.
        let amp = amp.min(2.0 * std::f64::consts::PI * freq * 2.0 / kc);
        let errors: Vec<f64> = (0..20_000)
            .map(|n| amp * (2.0 * std::f64::consts::PI * freq * n as f64 * t).cos() + rng.gen_range(-1.0..1.0) * amp * 0.1)
            .collect();
        // Skip cases where the lag's DC part or the noise's random walk would leave the window.
        let lag = LagCompensator::new(&cfg).unwrap();
        let mut probe = LagState::new(5.0);
        let mut r = RefLag::new(kc, zero, zero * ratio, t, 5.0);
        let inside = errors.iter().all(|&e| { let u = r.step(e); lag.update(&mut probe, e as f32); (0.5..9.5).contains(&u) });
        prop_assume!(inside);
        let (lsb, _) = compare(&cfg, 5.0, errors.into_iter());
        prop_assert!(lsb <= 1, "{} LSB", lsb);
    }
}
