//! The firmware's per-sample function (model-core `Controller`) closing the loop around the
//! virtual stage of ch. 6 (`thesis-full`: hysteresis, drift, non-linear gain, amplifier
//! limits, 1 mV sensor noise), through the one closed-loop harness as `piezo track --model
//! thesis-full` runs it: what hysteresis feedforward adds inside the loop (issue #4 item 8),
//! and that the loop stays inside its limits on the non-linear stage.

use host_tests::sim::tracking::{TrackRun, TrackShape, TrackSpec, simulate};
use model_core::prefilter::PreFilterMode;
use model_core::stage::StageConfig;

/// `piezo track --model thesis-full --shape SHAPE --freq F --ff on|off`: the one closed-loop
/// harness around `Controller::step` (1 mV sensor noise, pre-filter on, preview).
fn run(shape: TrackShape, freq_hz: f64, hysteresis_ff: bool) -> TrackRun {
    let spec = TrackSpec::new(shape, freq_hz, 3.0, 4.0, PreFilterMode::Full)
        .with_stage(StageConfig::thesis_full())
        .with_feedforward(hysteresis_ff);
    simulate(&spec, false).unwrap()
}

#[test]
fn hysteresis_feedforward_inside_the_closed_loop() {
    println!("6 V p-p around 4 V on thesis-full, pre-filter on, preview; error of the position");
    println!(
        "{:<10}{:>6}{:>16}{:>16}{:>16}{:>16}",
        "shape", "Hz", "ff off rms mV", "ff off peak", "ff on rms mV", "ff on peak"
    );
    for (name, shape) in [
        ("sine", TrackShape::Sine),
        ("triangle", TrackShape::Triangle),
    ] {
        for f in [10.0, 100.0] {
            let off = run(shape, f, false);
            let on = run(shape, f, true);
            println!(
                "{name:<10}{f:>6}{:>16.2}{:>16.2}{:>16.2}{:>16.2}",
                off.figures.rms_error_v * 1e3,
                off.figures.max_error_v * 1e3,
                on.figures.rms_error_v * 1e3,
                on.figures.max_error_v * 1e3
            );
            for r in [&off, &on] {
                // Inside the window and the slew limit (3 V per sample: 150 V/ms) at every
                // measured sample.
                assert!(r.command_range_v.0 >= 0.0 && r.command_range_v.1 <= 10.0);
                assert!(r.figures.max_slew_v_per_ms <= 150.0 * (1.0 + 1e-6));
            }
            let (off_rms, on_rms) = (off.figures.rms_error_v, on.figures.rms_error_v);
            // The loop tracks the non-linear stage to within 2 % of the 6 V span either way;
            // the feedforward must not make it worse by more than the noise.
            assert!(off_rms < 0.12 && on_rms < 0.12, "{off_rms} {on_rms}");
            // Measured 1.8x (sine) and 2.0x (triangle) at 10 Hz, 1.8x and 1.4x at 100 Hz, with
            // the table the stage itself uses: require 1.4x at 10 Hz and any gain at 100 Hz.
            let need = if f == 10.0 { 1.4 } else { 1.0 };
            assert!(
                on_rms * need <= off_rms,
                "ff at {f} Hz: {on_rms} vs {off_rms}"
            );
        }
    }
}
