//! The model-gap workflow on a measured record of a real piezoelectric actuator (issue #12's
//! "real laboratory record"; `tests/data/README.md` says where it comes from, how it is read
//! as a record of the P-753 loop, and its licence).
//!
//! The actuator is not the lab's P-753 and its record is not the recommended protocol: one
//! 10 s record at 5 kHz, a rest at the middle of the range, then a 1 Hz sine over the whole
//! range that starts with a jump. Against `thesis-linear` it leaves a loop 14 % of its span
//! wide, which issue #12 found named by nothing at 42x the floor. What this test asserts is
//! what any diagnosis of it must say, not the figures it came to (GAP.md, session 53):
//! the loop is named, the residual ends within [`FINAL_FLOOR_MAX`] of the floor, and what is
//! left above 2x the floor is said, with the jump's second among where it sits. The record
//! was read while step 19 was written, so it is not a held-out case.

use host_tests::gap::data::LineFit;
use host_tests::gap::{Data, Options, diagnose};
use host_tests::io::csv::Record;
use host_tests::io::model_file::ModelFile;

/// The record, as published (columns: empty index, time s, displacement um, drive V).
const RECORD: &str = include_str!("data/smarthysteresis_v150_1hz.csv");

/// The drive's amplitude, volts: mapped onto the amplifier's 0-10 V control input (our
/// assumption, `tests/data/README.md`).
const DRIVE_AMPLITUDE_V: f64 = 150.0;

/// The control input's span the drive is mapped onto, volts (the thesis' 0-10 V range).
const CONTROL_SPAN_V: f64 = 10.0;

/// The final residual may end at most this many times the noise floor (our bound: before
/// session 53 it ended at 4.08x and 9.2x with the two calibrations, after at 2.19x and
/// 2.41x; about half of what is left sits in the second after the sine's opening jump, the
/// actuator's own step response, which no catalogued effect of the P-753 loop has).
const FINAL_FLOOR_MAX: f64 = 3.0;

/// The end of the record's rest, seconds (the sine starts at 3.2572 s).
const REST_END_S: f64 = 3.2;

/// The floor read from the record may stand this far below the noise at its rest (the
/// first differences of the first 3.2 s, 9.2 mV): the 4.6 Hz lines and the slow wander of
/// the rest are not the sensor's white noise (our bound; the floor reads 8.3 mV).
const FLOOR_OF_REST_MIN: f64 = 0.7;

/// Which samples the calibration's least squares line is fitted over.
#[derive(Clone, Copy, Debug)]
enum Calibration {
    /// The sine, from its first sample on.
    OverTheSine,
    /// The whole record, its rest too (the "345 mV" before any effect: its own
    /// calibration, as far as the figure tells).
    OverTheRecord,
}

fn record(base: &ModelFile, cal: Calibration) -> Data {
    // The published file has no header: its columns by number (time, drive, displacement).
    let published = Record::parse_named(RECORD, ["2", "4", "3"]).expect("the published record");
    let (t, v) = (published.t_s, published.u_v);
    let d = published.y_v.expect("its displacement");
    let u: Vec<f64> = v
        .iter()
        .map(|v| CONTROL_SPAN_V * (v + DRIVE_AMPLITUDE_V) / (2.0 * DRIVE_AMPLITUDE_V))
        .collect();
    // y = a d + b: the least squares line of the plant's static gain times u on d.
    let from = match cal {
        Calibration::OverTheSine => v.iter().position(|v| *v != 0.0).expect("the sine starts"),
        Calibration::OverTheRecord => 0,
    };
    let target: Vec<f64> = u[from..]
        .iter()
        .map(|u| base.plant.static_gain * u)
        .collect();
    let line = LineFit::of(&target, &d[from..]).expect("samples to fit");
    let y: Vec<f64> = d.iter().map(|x| line.at(*x)).collect();
    Data::from_record(
        "smarthysteresis.csv",
        Record::new(t, u, Some(y), None).unwrap(),
    )
    .unwrap()
}

/// A measured actuator's loop is named, its residual ends near the floor, and what is left is
/// said where it sits (the opening jump's second), whichever samples the calibration's line
/// is fitted over.
#[test]
fn a_measured_actuators_loop_is_named_and_what_is_left_is_said() {
    let base = ModelFile::load("thesis-linear").unwrap();
    for cal in [Calibration::OverTheSine, Calibration::OverTheRecord] {
        diagnosed_near_the_floor(&base, cal);
    }
}

fn diagnosed_near_the_floor(base: &ModelFile, cal: Calibration) {
    let data = record(base, cal);
    let rest: Vec<f64> = data
        .t_s
        .iter()
        .zip(&data.y_v)
        .filter(|(t, _)| **t < REST_END_S)
        .map(|(_, y)| *y)
        .collect();
    let rest_noise_v = (rest.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum::<f64>()
        / (2.0 * (rest.len() - 1) as f64))
        .sqrt();
    let d = diagnose(base, std::slice::from_ref(&data), &Options::default()).unwrap();
    let ratio = d.final_rms_v / d.noise_floor_v;
    eprintln!(
        "{cal:?}: named {:?}; floor {:.2} mV (rest {:.2} mV); final {:.2} mV = {:.2}x; unexplained {:?}",
        d.named,
        1e3 * d.noise_floor_v,
        1e3 * rest_noise_v,
        1e3 * d.final_rms_v,
        ratio,
        d.unexplained.as_ref().map(|u| &u.where_)
    );
    assert!(
        d.named.iter().any(|n| n == "hysteresis"),
        "{cal:?}: {:?}",
        d.named
    );
    assert!(
        d.noise_floor_v >= FLOOR_OF_REST_MIN * rest_noise_v && d.noise_floor_v <= rest_noise_v,
        "floor {:.2} mV against the rest's {:.2} mV",
        1e3 * d.noise_floor_v,
        1e3 * rest_noise_v
    );
    assert!(
        ratio <= FINAL_FLOOR_MAX,
        "{cal:?}: final {ratio:.2}x the floor"
    );
    if ratio > 2.0 {
        let u = d
            .unexplained
            .as_ref()
            .expect("never silent above 2x the floor");
        assert!(u.where_.contains("t = 3."), "{}", u.where_);
    }
}
