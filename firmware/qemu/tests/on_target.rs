//! On-target tests of model-core (defmt-test, run on QEMU by `piezo qemu test` and by
//! `host-tests/tests/qemu.rs`): the blocks on the Cortex-M's own f32 unit against reference
//! vectors from host-tests' independent f64 references (`tests/vectors/mod.rs`, generated),
//! and the controller's and blocks' safety properties. Each test prints what it measured.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod vectors;

#[cfg(target_os = "none")]
use piezo_qemu as _;

/// An `f32` from its IEEE bits (the vectors' encoding).
#[cfg(target_os = "none")]
fn f(bits: u32) -> f32 {
    f32::from_bits(bits)
}

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use crate::f;
    use crate::vectors;
    use model_core::codes::{AdcCode, DacCode};
    use model_core::controller::{Faults, Mode};
    use model_core::hysteresis::{HysteresisMemory, HysteresisTable};
    use model_core::lag::{LagCompensator, LagConfig, LagState};
    use model_core::limits::{Flags, OutputLimits};
    use model_core::params;
    use model_core::plant::{LinearPlant, LinearPlantConfig, PlantState};
    use model_core::prefilter::{PreFilter, PreFilterConfig};
    use model_core::scenarios::thesis_controller;

    /// Report the CPU, so the host can check it runs on the machine it asked for.
    #[init]
    fn init() {
        defmt::println!("CPU {=u32}", piezo_qemu::cpu_part());
    }

    /// The lag compensator (f32, delta form, compensated sums) against the f64 Tustin direct
    /// form: within a quarter of a DAC step over the whole vector.
    #[test]
    fn lag_compensator_matches_the_f64_reference() {
        let lag = LagCompensator::new(&LagConfig::default()).unwrap();
        let mut st = LagState::new(f(vectors::LAG_U0_V));
        let tol = 0.25 * DacCode::VOLT_PER_LSB;
        let mut worst = 0.0f32;
        for (e, want) in vectors::LAG_ERROR_V
            .iter()
            .zip(vectors::LAG_COMMAND_V.iter())
        {
            let (u, flags) = lag.update_flags(&mut st, f(*e));
            defmt::assert_eq!(
                flags.0,
                Flags::NONE.0,
                "the vector must stay inside the limits"
            );
            let d = (u - f(*want)).abs();
            if d > worst {
                worst = d;
            }
        }
        defmt::println!(
            "lag: worst |f32 - f64 reference| = {=f32} V over {=usize} samples (tolerance {=f32} V)",
            worst,
            vectors::LAG_ERROR_V.len(),
            tol
        );
        defmt::assert!(worst <= tol);
    }

    /// Window, slew limit and NaN guard against the f64 reference: same flags, output within
    /// two f32 ulps at 10 V.
    #[test]
    fn output_limits_match_the_f64_reference() {
        let l = OutputLimits::default();
        let tol = 2.0 * f32::EPSILON * 10.0;
        let mut worst = 0.0f32;
        for (last, raw, want, flags) in vectors::LIMIT_CASES {
            let (out, got) = l.apply(f(last), f(raw));
            defmt::assert_eq!(
                got.0,
                flags,
                "flags for last {=f32} raw {=f32}",
                f(last),
                f(raw)
            );
            defmt::assert!(out.is_finite());
            let d = (out - f(want)).abs();
            if d > worst {
                worst = d;
            }
        }
        defmt::println!(
            "limits: {=usize} cases, flags equal, worst |out - f64 reference| = {=f32} V",
            vectors::LIMIT_CASES.len(),
            worst
        );
        defmt::assert!(worst <= tol);
    }

    /// Volts to 16-bit ADC and 14-bit DAC codes: exactly the f64 reference's codes.
    #[test]
    fn converter_codes_match_the_f64_reference() {
        for (v, adc, dac) in vectors::CODE_CASES {
            defmt::assert_eq!(
                AdcCode::from_volts(f(v)).0,
                adc,
                "ADC code of {=f32} V",
                f(v)
            );
            defmt::assert_eq!(
                DacCode::from_volts(f(v)).value(),
                dac,
                "DAC code of {=f32} V",
                f(v)
            );
        }
        defmt::assert_eq!(DacCode::from_volts(f32::NAN).value(), 0);
        defmt::println!("codes: {=usize} cases exact", vectors::CODE_CASES.len());
    }

    /// The pre-filter's unit step response against the f64 transfer-function reference
    /// (inverse FFT): within 2e-5 of its peak (the host test's tolerance).
    #[test]
    fn prefilter_step_response_matches_the_f64_reference() {
        let pf = PreFilter::new(
            &LagConfig::default(),
            &LinearPlantConfig::default(),
            &PreFilterConfig::default(),
        )
        .unwrap();
        let mut s = pf.settled_state(0.0);
        let mut worst = 0.0f32;
        let mut peak = 0.0f32;
        for want in vectors::PREFILTER_STEP_V {
            let d = (pf.step(&mut s, 1.0) - f(want)).abs();
            if d > worst {
                worst = d;
            }
            if f(want).abs() > peak {
                peak = f(want).abs();
            }
        }
        let tol = 2e-5 * peak.max(1.0);
        defmt::println!(
            "prefilter: step response peak {=f32}, worst |f32 - f64 reference| = {=f32} over {=usize} samples (tolerance {=f32})",
            peak,
            worst,
            vectors::PREFILTER_STEP_V.len(),
            tol
        );
        defmt::assert!(worst <= tol);
    }

    /// The linear plant: nothing moves during the 4.25-sample delay, then the output settles
    /// at the static gain of eq. 4.4.
    #[test]
    fn linear_plant_delay_and_static_gain() {
        let p = LinearPlant::new(&LinearPlantConfig::default()).unwrap();
        let mut s = PlantState::default();
        for _ in 0..p.delay_samples() {
            defmt::assert_eq!(p.step(&mut s, 1.0), 0.0);
        }
        let mut y = 0.0;
        for _ in 0..5000 {
            y = p.step(&mut s, 1.0);
        }
        let err = (y - params::PLANT_GAIN as f32).abs();
        defmt::println!(
            "plant: static gain {=f32} (eq. 4.4: 0.79), error {=f32}",
            y,
            err
        );
        defmt::assert!(err < 1e-5);
    }

    /// The controller: a NaN reference latches a fault, the command ramps to the safe value
    /// at the safe-ramp rate and stays there, inside the window; clearing returns to safe mode.
    #[test]
    fn controller_latches_a_nan_reference_and_ramps_to_safe() {
        let c = thesis_controller().unwrap();
        let mut st = model_core::controller::ControllerState::new(&c);
        st.set_mode(Mode::OpenLoop);
        st.set_reference(9.0);
        let adc = AdcCode::from_volts(5.0);
        for _ in 0..10 {
            c.step(&mut st, adc);
        }
        defmt::assert_eq!(st.command_v(), 9.0);
        st.set_reference(f32::NAN);
        // The ramp to safe moves at the safe-ramp rate (1 V/ms: 20 mV per sample), not at
        // the slew limit: 9 V takes 450 samples.
        let ramp = c.safe_ramp_v_per_step();
        let mut last = st.command_v();
        let mut steps = 0;
        for _ in 0..600 {
            let s = c.step(&mut st, adc);
            defmt::assert!(s.faults.contains(Faults::NONFINITE));
            defmt::assert!(c.lag.limits.contains(s.command_v));
            defmt::assert!((s.command_v - last).abs() <= ramp + 1e-5);
            if s.command_v != c.safe_v() {
                steps += 1;
            }
            last = s.command_v;
        }
        defmt::println!(
            "controller: NaN reference -> safe in {=u32} steps",
            steps + 1
        );
        defmt::assert_eq!(last, c.safe_v());
        st.clear_faults();
        defmt::assert!(st.mode() == Mode::Safe);
        defmt::assert!(st.faults().is_empty());
    }

    /// A saturated sensor latches at once; an absurd gain is refused.
    #[test]
    fn controller_refuses_absurd_gains_and_latches_sensor_faults() {
        let c = thesis_controller().unwrap();
        let mut st = model_core::controller::ControllerState::new(&c);
        st.set_mode(Mode::ClosedLoop);
        st.set_reference(5.0);
        let s = c.step(&mut st, AdcCode::MAX);
        defmt::assert!(s.faults.contains(Faults::SENSOR_RANGE));
        for kc in [model_core::scenarios::ABSURD_KC, f64::NAN, -1.0, 0.0] {
            let lag = LagConfig {
                kc,
                ..LagConfig::default()
            };
            defmt::assert!(LagCompensator::new(&lag).is_err());
        }
        defmt::println!("controller: sensor rail latched, 4 absurd gains refused");
    }

    /// The hysteresis table against the f64 Preisach sum over the turning-point stack (nested
    /// minor loops, then wiped out): within a third of an ADC step.
    #[test]
    fn hysteresis_matches_the_f64_preisach_sum() {
        let t = HysteresisTable::thesis_default();
        let mut m = HysteresisMemory::new();
        let mut worst = 0.0f32;
        for (u, want) in vectors::HYST_INPUT_V
            .iter()
            .zip(vectors::HYST_OUTPUT_V.iter())
        {
            let d = (t.forward(&mut m, f(*u)) - f(*want)).abs();
            if d > worst {
                worst = d;
            }
        }
        defmt::println!(
            "hysteresis: worst |f32 - f64 Preisach sum| = {=f32} V over {=usize} samples",
            worst,
            vectors::HYST_INPUT_V.len()
        );
        defmt::assert!(worst < 1e-4);
    }

    /// The hysteresis table on the target: branches are monotone and a minor loop closes
    /// exactly where it started (return-point memory), and the inverse is the forward map's
    /// inverse within 1 mV.
    #[test]
    fn hysteresis_closes_minor_loops_and_inverts() {
        let t = HysteresisTable::thesis_default();
        let mut m = HysteresisMemory::new();
        let mut prev = t.forward(&mut m, 0.0);
        for k in 1..=80 {
            let y = t.forward(&mut m, k as f32 * 0.1);
            defmt::assert!(
                y >= prev,
                "rising branch not monotone at {=f32} V",
                k as f32 * 0.1
            );
            prev = y;
        }
        let at_turn = t.forward(&mut m, 8.0);
        t.forward(&mut m, 3.0);
        let back = t.forward(&mut m, 8.0);
        defmt::println!(
            "hysteresis: minor loop 8 -> 3 -> 8 V returns to {=f32} V (left at {=f32} V)",
            back,
            at_turn
        );
        defmt::assert!((back - at_turn).abs() < 1e-5);
        let mut worst = 0.0f32;
        for k in 0..40 {
            let wanted = 1.0 + 0.15 * k as f32;
            let mut probe = m.clone();
            let u = t.inverse(&mut m, wanted);
            let y = t.forward(&mut probe, u);
            let d = (y - wanted).abs();
            if d > worst {
                worst = d;
            }
        }
        defmt::println!("hysteresis: inverse then forward, worst {=f32} V", worst);
        defmt::assert!(worst < 1e-3);
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("these tests run on QEMU: cargo run -p host-tests --bin piezo -- qemu test");
}
