//! The record -> model-file chain of the `piezo` verbs, through their library calls: a FORC
//! record synthesised from `thesis-full` (1 mV noise), the hysteresis identified into the base
//! model, and the identified model checked on an input it was not identified on.

use host_tests::identify::into_model::hysteresis_into;
use host_tests::io::model_file::ModelFile;
use host_tests::sim::open_loop::simulate;
use host_tests::sim::synth::{Protocol, SynthSpec, synth};

fn args(protocol: Protocol) -> SynthSpec {
    SynthSpec {
        model: "thesis-full".into(),
        protocol,
        seed: 5,
        seconds: 4.0,
        rate: 1000.0,
        amplitude: 10.0,
        offset: 0.0,
        freq: 1.0,
        freq_end: 100.0,
        hold: None,
        noise_v: Some(1e-3),
    }
}

#[test]
fn hysteresis_identified_from_a_forc_record_reproduces_the_stage() {
    let forc = synth(&args(Protocol::Forc)).unwrap();
    let mut model = ModelFile::load("thesis-full").unwrap();
    let dropped = hysteresis_into(&mut model, &forc, "forc").unwrap();
    assert!(
        dropped,
        "thesis-full has [nonlinear-gain], which the table replaces"
    );
    // Round trip through the TOML text as the command line would.
    let model = ModelFile::parse(&model.to_toml().unwrap()).unwrap();
    // Unseen input: a 0.5 Hz, 0-8 V triangle, both models noise-free.
    let tri = synth(&SynthSpec {
        freq: 0.5,
        amplitude: 8.0,
        noise_v: Some(0.0),
        ..args(Protocol::Triangle)
    })
    .unwrap();
    let mut ident = model.clone();
    ident.converters.noise_v = 0.0;
    let stage = ident.build_stage().unwrap();
    let y = simulate(&stage, ident.period_s, &tri.t_s, &tri.u_v);
    let truth = tri.require_y().unwrap();
    let n = y.len() as f64;
    let rms = (y
        .iter()
        .zip(truth)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    let peak = y
        .iter()
        .zip(truth)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    println!(
        "identified from {} FORC samples; unseen 0.5 Hz triangle: RMS {:.2} mV, peak {:.2} mV (of an 8.7 V span)",
        forc.len(),
        rms * 1e3,
        peak * 1e3
    );
    assert!(rms < 0.02 && peak < 0.05, "rms {rms} peak {peak}");
}
