//! The discrete closed loop (model-core compensator + plant, 16-bit ADC, 14-bit DAC, 85 us
//! delay) against the thesis' figures as recomputed independently with a 6th-order Pade
//! delay (model card, sec. 4.1.2): GM 11.5 dB, PM 60.5 deg, crossover 3076 rad/s, -3 dB
//! 1001 Hz. Tolerances from issue #2: 1.5 dB, 4 deg, 10 %, 10 %.

use host_tests::sim::analysis::{LoopSetup, loop_figures, open_loop_response};
use model_core::params;

fn report(name: &str, measured: f64, reference: f64, unit: &str) {
    let d = measured - reference;
    let dir = if d < 0.0 { "below" } else { "above" };
    println!(
        "{name}: {measured:.2} {unit}, {:.2} {unit} ({:.1} %) {dir} the recomputation {reference} {unit}",
        d.abs(),
        100.0 * d.abs() / reference
    );
}

#[test]
fn thesis_loop_margins_and_bandwidth() {
    let f = loop_figures(&LoopSetup::thesis(params::SAMPLE_RATE_HZ, params::LAG_KC)).unwrap();
    let gm = f.gain_margin_db.unwrap();
    let pm = f.phase_margin_deg.unwrap();
    let wc = f.crossover_rad_s.unwrap();
    let bw = f.bandwidth_hz.unwrap();
    report("gain margin", gm, params::RECOMPUTED_GAIN_MARGIN_DB, "dB");
    report(
        "phase margin",
        pm,
        params::RECOMPUTED_PHASE_MARGIN_DEG,
        "deg",
    );
    report("crossover", wc, params::RECOMPUTED_CROSSOVER_RAD_S, "rad/s");
    report("bandwidth", bw, params::RECOMPUTED_BANDWIDTH_HZ, "Hz");
    println!(
        "(the zero-order hold adds half a sample, 10 us, to the plant's 85 us: 1.8 deg at crossover)"
    );
    println!(
        "step: overshoot {:.2} %, settling {:.2} ms",
        f.step_overshoot_pct.unwrap(),
        f.settling_2pct_ms.unwrap()
    );
    assert!((gm - params::RECOMPUTED_GAIN_MARGIN_DB).abs() <= 1.5);
    assert!((pm - params::RECOMPUTED_PHASE_MARGIN_DEG).abs() <= 4.0);
    assert!((wc / params::RECOMPUTED_CROSSOVER_RAD_S - 1.0).abs() <= 0.10);
    assert!((bw / params::RECOMPUTED_BANDWIDTH_HZ - 1.0).abs() <= 0.10);
}

#[test]
fn measured_response_matches_the_continuous_loop_with_the_sampling_delay() {
    // An independent check of the measurement: the continuous L(jw) of eq. 4.4 x eq. 4.5
    // with the delay lengthened by the zero-order hold's half sample (Td + T/2), evaluated directly in f64 complex arithmetic. At 500..5000 rad/s the
    // measured discrete response must agree within 2 % in magnitude and 1.5 deg in phase
    // (Tustin's warp and the quantisers account for less than that).
    use rustfft::num_complex::Complex64;
    let setup = LoopSetup::thesis(params::SAMPLE_RATE_HZ, params::LAG_KC);
    let t = setup.lag.period_s;
    for &w in &[500.0, 1500.0, 3000.0, 5000.0] {
        let s = Complex64::new(0.0, w);
        let c = params::LAG_KC * (s + params::LAG_ZERO_RAD_S)
            / (s * (s / params::LAG_POLE_RAD_S + 1.0));
        let we = 2.0 * std::f64::consts::PI * params::AMP_POLE_HZ;
        let wn = 2.0 * std::f64::consts::PI * params::STAGE_MODE_HZ;
        let p = params::PLANT_GAIN
            / (s / we + 1.0)
            / (s * s / (wn * wn) + 2.0 * params::STAGE_DAMPING * s / wn + 1.0);
        let delay = (-s * (params::PLANT_DELAY_S + 0.5 * t)).exp();
        let l_cont = c * p * delay;
        let l_meas = open_loop_response(&setup, w, 0.2, 5.0);
        let mag = l_meas.norm() / l_cont.norm();
        let dphase = (l_meas / l_cont).arg().to_degrees();
        println!("w = {w} rad/s: |L| ratio {mag:.4}, phase difference {dphase:.2} deg");
        assert!((mag - 1.0).abs() < 0.02);
        assert!(dphase.abs() < 1.5);
    }
}

#[test]
fn step_response_has_zero_static_error() {
    let setup = LoopSetup::thesis(params::SAMPLE_RATE_HZ, params::LAG_KC);
    let (overshoot, settle_ms, trace) =
        host_tests::sim::analysis::step_figures(&setup, 2.0, 1.0, 0.3);
    let final_v = trace.last().unwrap().1;
    println!(
        "overshoot {overshoot:.2} %, settling {settle_ms:.2} ms, output after 0.3 s {final_v:.5} V"
    );
    // Zero static error up to the ADC's resolution (0.3 mV) and the lag's slow tail.
    assert!((final_v - 3.0).abs() < 2e-3);
    assert!(overshoot < 20.0 && settle_ms < 20.0);
}
