//! Iterative learning control (issue #14): the learning maths against an independent `f64`
//! reference (the filters' frequency responses applied through the DFT), convergence and
//! safety on the one closed-loop harness, and the robustness corners.

use host_tests::sim::tracking::{TrackShape, TrackSpec, simulate};
use model_core::controller::{ControllerConfig, Faults, ReferenceSource};
use model_core::learning::{Halt, Learning, LearningConfig, LearningState, Period, Status};
use model_core::plant::LinearPlantConfig;
use model_core::prefilter::{DelayHandling, PreFilterMode};
use model_core::reference::{ReferenceConfig, ReferenceGenerator, Shape};
use model_core::stage::StageConfig;
use rustfft::FftPlanner;
use rustfft::num_complex::Complex64;
use std::f64::consts::PI;

fn controller_config(shape: Shape, freq_hz: f64) -> ControllerConfig {
    ControllerConfig {
        reference: ReferenceConfig {
            shape,
            offset_v: 4.0,
            amplitude_v: 3.0,
            freq_hz,
            ..ReferenceConfig::default()
        },
        source: ReferenceSource::Generator,
        ..ControllerConfig::default()
    }
}

/// Circular filtering by a frequency response `h(w)` (w in rad/sample) through the DFT.
fn circular(x: &[f64], h: impl Fn(f64) -> Complex64) -> Vec<f64> {
    let n = x.len();
    let mut p = FftPlanner::new();
    let mut v: Vec<Complex64> = x.iter().map(|&r| Complex64::new(r, 0.0)).collect();
    p.plan_fft_forward(n).process(&mut v);
    for (k, c) in v.iter_mut().enumerate() {
        // Bins above n/2 are negative frequencies.
        let kk = if k <= n / 2 {
            k as f64
        } else {
            k as f64 - n as f64
        };
        *c *= h(2.0 * PI * kk / n as f64);
    }
    p.plan_fft_inverse(n).process(&mut v);
    v.iter().map(|c| c.re / n as f64).collect()
}

/// `(c1 s + c0) / (d1 s + d0)` by Tustin at `z = e^{jw}`.
fn tustin1(c: [f64; 2], d: [f64; 2], t: f64, w: f64) -> Complex64 {
    let z = Complex64::from_polar(1.0, w);
    let s = (z - 1.0) / (z + 1.0) * (2.0 / t);
    (s * c[0] + c[1]) / (s * d[0] + d[1])
}

/// The pre-filter `H'(e^{jw})` of the thesis loop (default delay handling), written from the
/// design equations of `prefilter.rs` independently of its sections.
fn h_prime(tau: f64, w: f64) -> Complex64 {
    let lag = model_core::lag::LagConfig::default();
    let plant = LinearPlantConfig::default();
    let t = lag.period_s;
    let z = Complex64::from_polar(1.0, w);
    let s = (z - 1.0) / (z + 1.0) * (2.0 / t);
    let delay = plant.delay_s + 0.5 * t;
    let lag_samples = (delay + 4.0 * tau) / t;
    let k = (lag_samples - 1e-9).ceil();
    let in_frac = k - lag_samples;
    let input = 1.0 - in_frac * (1.0 - 1.0 / z);
    let f = tustin1([0.0, 1.0], [tau, 1.0], t, w).powi(4);
    let dw = (delay / t + 1e-9).floor();
    let df = delay / t - dw;
    let direct = f * (z.powf(-dw) * (1.0 - df) + z.powf(-dw - 1.0) * df);
    let we = 2.0 * PI * plant.amp_pole_hz;
    let wn = 2.0 * PI * plant.mode_hz;
    let kck = lag.kc * plant.gain;
    let hp = s / (s + lag.zero_rad_s);
    let lagf = (s / (lag.pole_rad_s * kck) + 1.0 / kck) / (s * tau + 1.0);
    let amp = (s / we + 1.0) / (s * tau + 1.0);
    let stage = (s * s / (wn * wn) + s * 2.0 * plant.damping / wn + 1.0)
        / (s * s * tau * tau + s * 2.0 * tau + 1.0);
    input * (direct + hp * lagf * amp * stage)
}

#[test]
fn learning_filter_matches_the_f64_circular_inverse() {
    let cfg = controller_config(Shape::Sine, 100.0);
    let lc = LearningConfig::default();
    let l = Learning::new(&lc, &cfg).unwrap();
    let n = l.period_samples() as usize;
    let k = l.advance_samples() as usize;
    assert_eq!(cfg.prefilter.delay, DelayHandling::PreviewWithHold);
    // An error of the kind the loop leaves: a few harmonics, a mean and a sharp feature.
    let e: Vec<f64> = (0..n)
        .map(|i| {
            let x = 2.0 * PI * i as f64 / n as f64;
            0.01 + 0.05 * x.sin()
                + 0.02 * (3.0 * x + 0.4).cos()
                + 0.004 * (41.0 * x).sin()
                + if i == n / 3 { 0.01 } else { 0.0 }
        })
        .collect();
    let ef: Vec<f32> = e.iter().map(|&v| v as f32).collect();
    let mut out = vec![0.0f32; n];
    assert!(l.learning_filter(&ef, &mut out));
    let reference = circular(&e, |w| {
        h_prime(lc.tau_s, w) * Complex64::from_polar(1.0, w * k as f64)
    });
    let peak = reference.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let worst = out
        .iter()
        .zip(&reference)
        .fold(0.0f64, |a, (&o, &r)| a.max((o as f64 - r).abs()));
    println!(
        "learning filter: worst {worst:.3e} V against the f64 DFT reference (peak {peak:.3} V)"
    );
    assert!(worst < 1e-5 * peak.max(1.0), "{worst}");
}

#[test]
fn robustness_filter_matches_the_f64_zero_phase_response() {
    for (freq, cutoff) in [(100.0, 2000.0), (300.0, 10_000.0), (2500.0, 500.0)] {
        let cfg = controller_config(Shape::Triangle, freq);
        let lc = LearningConfig {
            cutoff_hz: cutoff,
            ..LearningConfig::default()
        };
        let l = Learning::new(&lc, &cfg).unwrap();
        let n = l.period_samples() as usize;
        let x: Vec<f64> = (0..n)
            .map(|i| ((i * 7919) % 101) as f64 / 101.0 - 0.5 + if i < n / 2 { 0.3 } else { 0.0 })
            .collect();
        let mut y: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        assert!(l.robustness_filter(&mut y));
        let p = (-2.0 * PI * cutoff * cfg.lag.period_s).exp();
        let reference = circular(&x, |w| {
            let q1 = (1.0 - p) / (1.0 - p * Complex64::from_polar(1.0, -w));
            Complex64::new(q1.norm_sqr(), 0.0)
        });
        let worst = y
            .iter()
            .zip(&reference)
            .fold(0.0f64, |a, (&o, &r)| a.max((o as f64 - r).abs()));
        println!("Q at {cutoff} Hz over {n} samples: worst {worst:.3e} against the f64 reference");
        assert!(worst < 2e-6, "{worst}");
    }
}

#[test]
fn repeat_covers_whole_periods_and_refuses_others() {
    let r = |f: f64| {
        ReferenceGenerator::new(
            &ReferenceConfig {
                shape: Shape::Triangle,
                freq_hz: f,
                ..ReferenceConfig::default()
            },
            0,
        )
        .unwrap()
        .repeat_samples()
    };
    assert_eq!(r(100.0), 500);
    assert_eq!(r(300.0), 500);
    assert_eq!(r(2500.0), 20);
    assert_eq!(r(10.0), 0, "5000 samples: longer than the table");
    assert!(
        Learning::new(
            &LearningConfig::default(),
            &controller_config(Shape::Sine, 10.0)
        )
        .is_err()
    );
    assert!(
        Learning::new(
            &LearningConfig {
                gain: 1.5,
                ..LearningConfig::default()
            },
            &controller_config(Shape::Sine, 100.0)
        )
        .is_err()
    );
}

#[test]
fn learning_stops_on_faults_and_reference_changes_and_freezes_on_growth() {
    let cfg = controller_config(Shape::Sine, 100.0);
    let l = Learning::new(&LearningConfig::default(), &cfg).unwrap();
    let g = model_core::controller::Controller::new(&cfg)
        .unwrap()
        .generator;
    let n = l.period_samples() as usize;
    let (mut table, mut scratch) = (vec![0.0f32; n], vec![0.0f32; n]);
    let mut st = LearningState::new();
    // Growing error: three repeats in a row 20 % up freeze it, the table in force.
    let mut amp = 1e-3f32;
    let mut error = vec![0.0f32; n];
    for k in 0..6 {
        for (i, v) in error.iter_mut().enumerate() {
            *v = amp * (2.0 * PI as f32 * i as f32 / n as f32).sin();
        }
        let p = Period {
            error_v: &error,
            faults: Faults::NONE,
            closed_loop: true,
            generator: &g,
        };
        let s = l.update(&mut st, &mut table, &mut scratch, &p);
        println!("repeat {k}: {s:?}");
        amp *= 1.2;
    }
    assert_eq!(st.status(), Status::Frozen(Halt::Growing));
    assert!(st.diverging());
    assert!(table.iter().any(|&c| c != 0.0), "frozen keeps the table");
    // A fault stops it; reset clears the table and starts again.
    st.reset(&mut table);
    assert!(table.iter().all(|&c| c == 0.0));
    let p = Period {
        error_v: &error,
        faults: Faults::SENSOR_RANGE,
        closed_loop: true,
        generator: &g,
    };
    assert_eq!(
        l.update(&mut st, &mut table, &mut scratch, &p),
        Status::Stopped(Halt::Fault(Faults::SENSOR_RANGE))
    );
    // A change of reference stops it and clears the table.
    st.reset(&mut table);
    let p = Period {
        error_v: &error,
        faults: Faults::NONE,
        closed_loop: true,
        generator: &g,
    };
    l.update(&mut st, &mut table, &mut scratch, &p);
    assert!(table.iter().any(|&c| c != 0.0));
    let other = model_core::controller::Controller::new(&controller_config(Shape::Triangle, 100.0))
        .unwrap()
        .generator;
    let p = Period {
        generator: &other,
        ..p
    };
    assert_eq!(
        l.update(&mut st, &mut table, &mut scratch, &p),
        Status::Stopped(Halt::ReferenceChanged)
    );
    assert!(table.iter().all(|&c| c == 0.0));
    // Short buffers and NaN stop it without a panic.
    st.reset(&mut table);
    let short = [0.0f32; 10];
    let p = Period {
        error_v: &short,
        faults: Faults::NONE,
        closed_loop: true,
        generator: &g,
    };
    assert_eq!(
        l.update(&mut st, &mut table, &mut scratch, &p),
        Status::Stopped(Halt::ShortBuffer)
    );
    st.reset(&mut table);
    error[7] = f32::NAN;
    let p = Period {
        error_v: &error,
        faults: Faults::NONE,
        closed_loop: true,
        generator: &g,
    };
    assert_eq!(
        l.update(&mut st, &mut table, &mut scratch, &p),
        Status::Stopped(Halt::NonFinite)
    );
    assert!(table.iter().all(|&c| c == 0.0));
    // The interrupt's read outside the table is 0, its record outside the buffer nothing.
    assert_eq!(model_core::learning::correction(&table, u32::MAX), 0.0);
}

fn full(shape: TrackShape, freq: f64) -> TrackSpec {
    TrackSpec::new(shape, freq, 3.0, 4.0, PreFilterMode::Full)
        .with_stage(StageConfig::thesis_full())
}

#[test]
fn learning_brings_the_100_hz_sine_on_thesis_full_under_2_mv_in_30_repeats() {
    let before = simulate(&full(TrackShape::Sine, 100.0), false).unwrap();
    let r = simulate(&full(TrackShape::Sine, 100.0).with_learning(30), false).unwrap();
    let f = r.figures;
    println!(
        "sine 100 Hz: {:.2} -> {:.3} mV rms, peak {:.3} mV, status {:?}, per repeat {:?}",
        before.figures.rms_error_v * 1e3,
        f.rms_error_v * 1e3,
        f.max_error_v * 1e3,
        r.learn_status,
        r.learn_rms_error_v
            .iter()
            .map(|v| (v * 1e5).round() / 100.0)
            .collect::<Vec<_>>()
    );
    assert!(f.rms_error_v <= 2e-3, "{}", f.rms_error_v);
    assert_eq!(r.learn_status, Some(Status::Learning));
    assert_eq!(r.learn_limited_samples, 0);
    assert_eq!(f.dac_saturated_fraction, 0.0);
    assert!(r.learn_command_range_v.0 >= 0.0 && r.learn_command_range_v.1 <= 10.0);
    assert_eq!(r.slew_limited_fraction, 0.0);
    // --json: the four keys and the per-repeat list.
    let v = r.json().unwrap();
    assert_eq!(v["learn_rms_error_v"].as_array().unwrap().len(), 30);
    let v0 = before.json().unwrap();
    assert_eq!(v0.as_object().unwrap().len(), 4);
}

#[test]
fn learning_cuts_the_300_hz_triangle_on_thesis_full_tenfold_in_30_repeats() {
    let before = simulate(&full(TrackShape::Triangle, 300.0), false).unwrap();
    let r = simulate(&full(TrackShape::Triangle, 300.0).with_learning(30), false).unwrap();
    let f = r.figures;
    let cut = before.figures.rms_error_v / f.rms_error_v;
    let (peak, clamp, predicted) = r.learn_table_peak_v;
    println!(
        "triangle 300 Hz: {:.2} -> {:.2} mV rms ({cut:.1}x), peak {:.1} mV, table peak {peak:.3} V, clamp {clamp:.3} V (predicted {predicted:.3} V), per repeat {:?}",
        before.figures.rms_error_v * 1e3,
        f.rms_error_v * 1e3,
        f.max_error_v * 1e3,
        r.learn_rms_error_v
            .iter()
            .map(|v| (v * 1e5).round() / 100.0)
            .collect::<Vec<_>>()
    );
    assert!(cut >= 10.0, "only {cut:.1}x");
    assert_eq!(r.learn_status, Some(Status::Learning));
    assert_eq!(r.learn_limited_samples, 0);
    assert_eq!(f.dac_saturated_fraction, 0.0);
    assert_eq!(r.slew_limited_fraction, 0.0);
    assert!(r.learn_command_range_v.0 >= 0.0 && r.learn_command_range_v.1 <= 10.0);
    // The corners need a table of about 1.5 V: more than the former fixed 1 V clamp, which
    // stalled this case at 30 mV (5.7x). The derived clamp leaves it room.
    assert!(peak > 1.0 && peak < clamp, "{peak} {clamp}");
}

#[test]
fn clamp_is_the_allowance_plus_twice_the_predicted_table() {
    let lc = LearningConfig::default();
    let predicted = |shape, freq, amp| {
        let mut cfg = controller_config(shape, freq);
        cfg.reference.amplitude_v = amp;
        let l = Learning::new(&lc, &cfg).unwrap();
        let clamp = lc.max_correction_v + lc.correction_margin * l.predicted_peak_v() as f64;
        assert!((l.max_correction_v() as f64 - clamp).abs() < 1e-5);
        l.predicted_peak_v() as f64
    };
    // Linear in the amplitude (the design model is linear), and larger for the triangle's
    // corners than for the sine.
    for (shape, freq) in [(Shape::Triangle, 300.0), (Shape::Sine, 300.0)] {
        let (p3, p1) = (predicted(shape, freq, 3.0), predicted(shape, freq, 1.5));
        println!("{shape:?} {freq} Hz: predicted peak {p3:.4} V at 3 V, {p1:.4} V at 1.5 V");
        assert!((p1 / p3 - 0.5).abs() < 1e-3, "{p1} {p3}");
    }
    assert!(predicted(Shape::Triangle, 300.0, 3.0) > 10.0 * predicted(Shape::Sine, 300.0, 3.0));
    // On the design model itself (thesis-linear: no hysteresis), the table the learning
    // converges to: at most the prediction (which is before Q, and Q rounds the corners'
    // spikes) and not below half of it (the prediction is not uselessly loose). Triangles:
    // their corners set the peak; a sine's table is mostly the 1 mV noise through Lf.
    for freq in [100.0, 300.0] {
        let spec = TrackSpec::new(TrackShape::Triangle, freq, 3.0, 4.0, PreFilterMode::Full)
            .with_learning(30);
        let r = simulate(&spec, false).unwrap();
        let (peak, _, predicted) = r.learn_table_peak_v;
        println!(
            "thesis-linear triangle {freq} Hz: table peak {peak:.3} V, predicted {predicted:.3} V"
        );
        assert!(
            peak <= predicted && peak >= 0.5 * predicted,
            "{peak} {predicted}"
        );
    }
}

/// A stage off the design model: the learning filter is designed on `thesis-linear` (the
/// controller's design plant), the stage is `thesis-full` with its amplifier gain scaled by
/// `gain`, its delay moved by `delay_s` and its mode scaled by `mode` (issue #14, item 5).
fn off_model(gain: f64, delay_s: f64, mode: f64) -> StageConfig {
    let mut s = StageConfig::thesis_full();
    s.amplifier.gain *= gain;
    s.delay_s += delay_s;
    s.mode.mode_hz *= mode;
    s
}

#[test]
fn learning_converges_on_stages_off_by_gain_delay_and_mode() {
    // Gain -30 % cannot reach 7 V inside the 0..10 V window (7 V / (0.79 * 0.7) = 12.7 V):
    // that corner runs 1..5 V (4 V p-p around 3 V), every other one 6 V p-p around 4 V.
    let corners: [(&str, f64, f64, f64); 7] = [
        ("nominal", 1.0, 0.0, 1.0),
        ("gain +30 %", 1.3, 0.0, 1.0),
        ("gain -30 %", 0.7, 0.0, 1.0),
        ("delay +20 us", 1.0, 20e-6, 1.0),
        ("delay -20 us", 1.0, -20e-6, 1.0),
        ("mode +15 %", 1.0, 0.0, 1.15),
        ("mode -15 %", 1.0, 0.0, 0.85),
    ];
    println!("thesis-full off the design model, 30 repeats; RMS / peak, mV");
    for (shape_name, shape, freq) in [
        ("sine", TrackShape::Sine, 100.0),
        ("triangle", TrackShape::Triangle, 100.0),
        ("sine", TrackShape::Sine, 300.0),
        ("triangle", TrackShape::Triangle, 300.0),
    ] {
        for (name, gain, delay_s, mode) in corners {
            let (amp, off) = if gain < 1.0 { (2.0, 3.0) } else { (3.0, 4.0) };
            let spec = TrackSpec::new(shape, freq, amp, off, PreFilterMode::Full)
                .with_stage(off_model(gain, delay_s, mode));
            let before = simulate(&spec, false).unwrap().figures;
            let r = simulate(&spec.with_learning(30), false).unwrap();
            let cut = before.rms_error_v / r.figures.rms_error_v;
            println!(
                "{shape_name:<9}{freq:>4} Hz {name:<14} {:>7.2} / {:>7.2} -> {:>6.2} / {:>6.2}  ({cut:>5.1}x) {:?}",
                before.rms_error_v * 1e3,
                before.max_error_v * 1e3,
                r.figures.rms_error_v * 1e3,
                r.figures.max_error_v * 1e3,
                r.learn_status
            );
            assert!(cut >= 10.0, "{shape_name} {freq} Hz {name}: only {cut:.1}x");
            assert_eq!(r.learn_limited_samples, 0, "{shape_name} {freq} Hz {name}");
            assert!(r.learn_command_range_v.0 >= 0.0 && r.learn_command_range_v.1 <= 10.0);
            assert_eq!(
                r.slew_limited_fraction, 0.0,
                "{shape_name} {freq} Hz {name}"
            );
        }
    }
}
