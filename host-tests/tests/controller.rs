//! The firmware's per-sample function (model-core `Controller`) closing the loop around the
//! virtual stage of ch. 6 (`Stage::thesis_full`: hysteresis, drift, non-linear gain,
//! amplifier limits, 1 mV sensor noise): what hysteresis feedforward adds inside the loop
//! (issue #4 item 8), and that the loop stays inside its limits on the non-linear stage.

use model_core::AdcCode;
use model_core::controller::{
    Controller, ControllerConfig, ControllerState, Mode, ReferenceSource,
};
use model_core::reference::{ReferenceConfig, Shape};
use model_core::stage::{Stage, StageConfig};

struct Run {
    rms_v: f64,
    peak_v: f64,
    max_step_v: f32,
    min_u_v: f32,
    max_u_v: f32,
}

fn run(shape: Shape, freq_hz: f64, hysteresis_ff: bool) -> Run {
    let mut scfg = StageConfig::thesis_full();
    scfg.sensor.noise_v = 1e-3;
    let stage = Stage::new(&scfg).unwrap();
    let cfg = ControllerConfig {
        reference: ReferenceConfig {
            shape,
            offset_v: 4.0,
            amplitude_v: 3.0,
            freq_hz,
            ..ReferenceConfig::default()
        },
        source: ReferenceSource::Generator,
        hysteresis_ff,
        ..ControllerConfig::default()
    };
    let c = Controller::new(&cfg).unwrap();
    let mut st = ControllerState::new(&c);
    // Bring the stage to the start of the reference in open loop, then close the loop.
    let u0 = 1.0 / model_core::params::PLANT_GAIN as f32;
    let mut ss = stage.steady_state(u0);
    st.set_mode(Mode::OpenLoop);
    st.set_reference(u0);
    let mut y = stage.step(&mut ss, u0);
    for _ in 0..20_000 {
        let s = c.step(&mut st, AdcCode::from_volts(y));
        y = stage.step(&mut ss, s.dac.volts());
    }
    st.set_mode(Mode::ClosedLoop);
    let period = (model_core::params::SAMPLE_RATE_HZ / freq_hz) as usize;
    let total = 40_000usize.max(6 * period);
    let measure_from = total - 2 * period;
    let (mut sum2, mut peak, mut n) = (0.0f64, 0.0f64, 0usize);
    let mut last_u = st.command_v();
    let (mut max_step, mut min_u, mut max_u) = (0.0f32, f32::MAX, f32::MIN);
    for k in 0..total {
        let s = c.step(&mut st, AdcCode::from_volts(y));
        assert!(s.faults.is_empty(), "fault {:?} at sample {k}", s.faults);
        max_step = max_step.max((s.command_v - last_u).abs());
        min_u = min_u.min(s.command_v);
        max_u = max_u.max(s.command_v);
        last_u = s.command_v;
        if k >= measure_from {
            // The position without the sensor noise against the reference now.
            let e = (ss.signals().position_v - s.reference_v) as f64;
            sum2 += e * e;
            peak = peak.max(e.abs());
            n += 1;
        }
        y = stage.step(&mut ss, s.dac.volts());
    }
    Run {
        rms_v: (sum2 / n as f64).sqrt(),
        peak_v: peak,
        max_step_v: max_step,
        min_u_v: min_u,
        max_u_v: max_u,
    }
}

#[test]
fn hysteresis_feedforward_inside_the_closed_loop() {
    println!("6 V p-p around 4 V on thesis-full, pre-filter on, preview; error of the position");
    println!(
        "{:<10}{:>6}{:>16}{:>16}{:>16}{:>16}",
        "shape", "Hz", "ff off rms mV", "ff off peak", "ff on rms mV", "ff on peak"
    );
    for (name, shape) in [("sine", Shape::Sine), ("triangle", Shape::Triangle)] {
        for f in [10.0, 100.0] {
            let off = run(shape, f, false);
            let on = run(shape, f, true);
            println!(
                "{name:<10}{f:>6}{:>16.2}{:>16.2}{:>16.2}{:>16.2}",
                off.rms_v * 1e3,
                off.peak_v * 1e3,
                on.rms_v * 1e3,
                on.peak_v * 1e3
            );
            for r in [&off, &on] {
                // Inside the window and the slew limit (3 V per sample) at every sample.
                assert!(r.min_u_v >= 0.0 && r.max_u_v <= 10.0);
                assert!(r.max_step_v <= 3.0 + 1e-6);
            }
            // The loop tracks the non-linear stage to within 2 % of the 6 V span either way;
            // the feedforward must not make it worse by more than the noise.
            assert!(
                off.rms_v < 0.12 && on.rms_v < 0.12,
                "{} {}",
                off.rms_v,
                on.rms_v
            );
            // Measured 1.8x (sine) and 2.0x (triangle) at 10 Hz, 1.8x and 1.4x at 100 Hz, with
            // the table the stage itself uses: require 1.4x at 10 Hz and any gain at 100 Hz.
            let need = if f == 10.0 { 1.4 } else { 1.0 };
            assert!(
                on.rms_v * need <= off.rms_v,
                "ff at {f} Hz: {} vs {}",
                on.rms_v,
                off.rms_v
            );
        }
    }
}
