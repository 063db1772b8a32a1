//! The on-target tests' reference vectors (`firmware/qemu/tests/vectors/mod.rs`) are what the
//! host's f64 references produce now, and the references themselves hold what the vectors
//! claim: the lag vector stays inside the window and the codes saturate at the rails.
use host_tests::qemu::vectors as v;
use model_core::params;

#[test]
fn checked_in_vectors_are_current() {
    let want = v::generate();
    let have = std::fs::read_to_string(v::vectors_path()).unwrap_or_default();
    println!(
        "vectors: {} bytes generated, {} bytes checked in",
        want.len(),
        have.len()
    );
    assert!(
        have == want,
        "{} is stale: run `cargo run -p host-tests --bin piezo -- qemu vectors --write`",
        v::vectors_path().display()
    );
}

#[test]
fn the_lag_vector_stays_inside_the_window_and_moves() {
    let e = v::lag_errors();
    let u = v::lag_reference(model_core::scenarios::STEP_V, &e);
    let lo = u.iter().cloned().fold(f64::MAX, f64::min);
    let hi = u.iter().cloned().fold(f64::MIN, f64::max);
    println!("lag vector: command spans {lo:.4} .. {hi:.4} V");
    assert!(lo > params::SAFE_WINDOW_MIN_V && hi < params::SAFE_WINDOW_MAX_V);
    // It must exercise the compensator: more than a DAC step of movement.
    assert!(hi - lo > 0.01, "{lo} {hi}");
    let slew = params::AMP_SLEW_INPUT_V_PER_S / params::SAMPLE_RATE_HZ;
    let worst_step = u
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .fold(0.0, f64::max);
    println!("lag vector: largest step {worst_step:.4} V (slew limit {slew} V)");
    assert!(worst_step < slew);
}

#[test]
fn code_reference_rounds_and_saturates() {
    assert_eq!(v::code_reference(10.0, 16), i16::MAX as i32);
    assert_eq!(v::code_reference(-10.0, 16), i16::MIN as i32);
    assert_eq!(v::code_reference(-20.0, 14), -8192);
    let lsb = 20.0 / 16384.0;
    assert_eq!(v::code_reference(0.5 * lsb, 14), 1);
    assert_eq!(v::code_reference(-0.5 * lsb, 14), -1);
    assert_eq!(v::code_reference(0.49 * lsb, 14), 0);
}

#[test]
fn hysteresis_reference_agrees_with_model_core_on_the_host() {
    use model_core::hysteresis::{HysteresisMemory, HysteresisTable};
    let t = HysteresisTable::thesis_default();
    let u = v::hysteresis_input();
    let want = v::hysteresis_reference(&t, &u);
    let mut m = HysteresisMemory::new();
    let mut worst: f64 = 0.0;
    for (x, w) in u.iter().zip(&want) {
        let y = t.forward(&mut m, *x) as f64;
        worst = worst.max((y - w).abs());
    }
    let (lo, hi) = want
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), y| (a.min(*y), b.max(*y)));
    println!(
        "hysteresis: {} samples, output {lo:.3}..{hi:.3} V, worst |f32 model - f64 Preisach sum| = {worst:.3e} V",
        u.len()
    );
    // A third of an ADC step (0.1 mV): f32 rounding of a few Everett differences of up to 8 V.
    assert!(worst < 1e-4, "{worst}");
    // The reference is not trivially the input: the loop is open.
    assert!(hi - lo > 5.0);
}
