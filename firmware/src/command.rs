//! The line command language of the ST-LINK virtual COM port: parsing and validation.
//!
//! One command per line, words separated by spaces, lower case. Quantities carry their unit
//! glued to the number (`6um`, `4.5v`, `10hz`, `1.5khz`, `0.2ms`), so a value can never be
//! read in the wrong unit; a bare number is accepted only where the quantity has no unit
//! (`kc`). Every value is checked here for being finite and inside the range in
//! [`crate::design_parameters`] (or `model_core::params` for the loop's own numbers: gain,
//! rate); the controller's own constructor checks the
//! combination again when the task builds the new configuration. A line that fails either
//! check changes nothing and gets `err ...` back.
//!
//! | line                              | effect                                              |
//! |-----------------------------------|-----------------------------------------------------|
//! | `mode safe\|open\|closed\|hold`   | operating mode                                      |
//! | `ref step LEVEL`                  | step reference to LEVEL (`um` or `v` of the sensor) |
//! | `ref sine OFFSET AMPL FREQ`       | sine reference                                      |
//! | `ref triangle OFFSET AMPL FREQ`   | triangle reference                                  |
//! | `kc VALUE`                        | lag compensator gain                                |
//! | `tau VALUE`                       | pre-filter time constant (`s`, `ms`, `us`)          |
//! | `ff on\|off`                      | hysteresis feedforward                              |
//! | `rate FREQ`                       | loop rate, 10..200 kHz (safe mode only)             |
//! | `cal GAIN OFFSET`                 | ADC correction `y = GAIN * nominal + OFFSET` (`v`)  |
//! | `status`, `faults`, `clear`       | report, report faults, clear latched faults         |
//! | `capture DURATION`                | record r, y, u, flags for DURATION (`s`, `ms`)      |
//! | `capture status`                  | state of the capture                                |
//! | `capture send [FIRST COUNT]`      | send the capture (or a part) as frames              |
//! | `learn on\|off\|freeze\|reset`    | iterative learning of the periodic reference        |
//! | `help`                            | list the commands                                   |
//!
//! Parsing takes a `&str` and allocates nothing; a line is at most [`MAX_LINE`] bytes.

use crate::design_parameters;
use model_core::params;

/// Longest command line accepted, bytes (longer lines are refused whole).
pub const MAX_LINE: usize = 96;

/// The operating mode a command asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModeRequest {
    /// Output held at the safe value.
    Safe,
    /// Output follows the reference without feedback.
    Open,
    /// The closed loop.
    Closed,
    /// The output frozen at its present value.
    Hold,
}

/// The reference a command asks for; levels are sensor monitor volts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ReferenceRequest {
    /// A constant level.
    Step {
        /// Level, sensor volts.
        level_v: f64,
    },
    /// `offset + amplitude sin(2 pi f t)`.
    Sine {
        /// Centre, sensor volts.
        offset_v: f64,
        /// Peak deviation, sensor volts.
        amplitude_v: f64,
        /// Frequency, Hz.
        freq_hz: f64,
    },
    /// A symmetric triangle between `offset - amplitude` and `offset + amplitude`.
    Triangle {
        /// Centre, sensor volts.
        offset_v: f64,
        /// Peak deviation, sensor volts.
        amplitude_v: f64,
        /// Frequency, Hz.
        freq_hz: f64,
    },
}

/// What a `capture` line asks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CaptureRequest {
    /// Record for this many seconds.
    Arm {
        /// Duration, seconds (> 0).
        duration_s: f64,
    },
    /// Report the capture's state.
    Status,
    /// Send records `first .. first + count` (the whole capture when `None`).
    Send {
        /// First record and count.
        range: Option<(u32, u32)>,
    },
}

/// What a `learn` line asks for (iterative learning control, issue 14 item 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LearnRequest {
    /// Start learning from a zero table (closed loop, periodic reference).
    On,
    /// Stop: no correction, no updates.
    Off,
    /// Keep the table in force, no more updates.
    Freeze,
    /// Clear the table and the iteration count; learning starts again if it was on.
    Reset,
}

/// A parsed, range-checked command.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    /// `help`.
    Help,
    /// `status`.
    Status,
    /// `faults`.
    Faults,
    /// `clear`.
    Clear,
    /// `mode ...`.
    Mode(ModeRequest),
    /// `ref ...`.
    Reference(ReferenceRequest),
    /// `kc VALUE`.
    Kc(f64),
    /// `tau VALUE`, seconds.
    Tau(f64),
    /// `ff on|off`.
    Feedforward(bool),
    /// `rate FREQ`, Hz.
    Rate(f64),
    /// `cal GAIN OFFSET`: ADC gain and offset (volts) correction, range-checked.
    Calibrate {
        /// Gain.
        gain: f64,
        /// Offset, volts.
        offset_v: f64,
    },
    /// `capture ...`.
    Capture(CaptureRequest),
    /// `selftest`: the loopback bring-up test (`app` module).
    SelfTest,
    /// `learn on|off|freeze|reset`.
    Learn(LearnRequest),
}

/// Why a line was refused; [`ParseError::message`] is the reply text.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParseError {
    /// An empty line.
    Empty,
    /// The line is longer than [`MAX_LINE`] or not ASCII.
    TooLong,
    /// The first word is not a command.
    UnknownCommand,
    /// Too few or too many words for the command.
    WrongArgumentCount,
    /// A word is not one of the allowed keywords.
    BadKeyword,
    /// A number could not be read.
    BadNumber,
    /// The number is NaN or infinite.
    NotFinite,
    /// The unit is missing or not one this quantity takes.
    BadUnit,
    /// The value is outside its range.
    OutOfRange,
}

impl ParseError {
    /// The reply text (after `err `).
    pub fn message(self) -> &'static str {
        match self {
            Self::Empty => "empty line",
            Self::TooLong => "line too long or not ASCII",
            Self::UnknownCommand => "unknown command (try help)",
            Self::WrongArgumentCount => "wrong number of arguments (try help)",
            Self::BadKeyword => "unknown keyword (try help)",
            Self::BadNumber => "not a number",
            Self::NotFinite => "value is NaN or infinite",
            Self::BadUnit => "missing or wrong unit",
            Self::OutOfRange => "value out of range",
        }
    }
}

/// The text of `help`.
pub const HELP: &str = "commands: mode safe|open|closed|hold; ref step LEVEL; ref sine OFFSET AMPL FREQ; \
ref triangle OFFSET AMPL FREQ (levels in um or v, FREQ in hz or khz); kc VALUE; tau VALUE(s|ms|us); \
ff on|off; rate FREQ (safe mode only); cal GAIN OFFSET(v); status; faults; clear; capture DURATION(s|ms); capture status; \
capture send [FIRST COUNT]; selftest (loopback cable, amplifier disconnected); learn on|off|freeze|reset \
(closed loop, ref sine or triangle)";

/// The units a number may carry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Quantity {
    /// Sensor level: `v` or `um` (10 V = 12 um).
    Level,
    /// Frequency: `hz`, `khz`.
    Frequency,
    /// Duration: `s`, `ms`, `us`.
    Duration,
}

/// Reads `word` as a number with a unit of `q` and returns it in SI units (level in volts).
fn quantity(word: &str, q: Quantity) -> Result<f64, ParseError> {
    let split = word
        .find(|c: char| c.is_ascii_alphabetic() && c != 'e' && c != 'E')
        .ok_or(ParseError::BadUnit)?;
    let (num, unit) = word.split_at(split);
    // "inf"/"nan" start with a letter: refuse them as not finite rather than as a bad unit.
    if num.is_empty() {
        return Err(if unit.starts_with("inf") || unit.starts_with("nan") {
            ParseError::NotFinite
        } else {
            ParseError::BadNumber
        });
    }
    let x = number(num)?;
    let scale = match (q, unit) {
        (Quantity::Level, "v") => 1.0,
        (Quantity::Level, "um") => params::SENSOR_V_PER_UM,
        (Quantity::Frequency, "hz") => 1.0,
        (Quantity::Frequency, "khz") => 1e3,
        (Quantity::Duration, "s") => 1.0,
        (Quantity::Duration, "ms") => 1e-3,
        (Quantity::Duration, "us") => 1e-6,
        _ => return Err(ParseError::BadUnit),
    };
    Ok(x * scale)
}

/// A bare number: finite.
fn number(word: &str) -> Result<f64, ParseError> {
    let x: f64 = word.parse().map_err(|_| ParseError::BadNumber)?;
    if x.is_finite() {
        Ok(x)
    } else {
        Err(ParseError::NotFinite)
    }
}

/// A voltage with the unit `v` (not a sensor level: `um` is refused, negative allowed).
fn signed_volts(word: &str) -> Result<f64, ParseError> {
    match word.strip_suffix('v') {
        Some(num) => number(num),
        None => Err(ParseError::BadUnit),
    }
}

fn in_range(x: f64, lo: f64, hi: f64) -> Result<f64, ParseError> {
    if (lo..=hi).contains(&x) {
        Ok(x)
    } else {
        Err(ParseError::OutOfRange)
    }
}

fn level(word: &str) -> Result<f64, ParseError> {
    in_range(
        quantity(word, Quantity::Level)?,
        design_parameters::REF_MIN_V,
        design_parameters::REF_MAX_V,
    )
}

fn periodic(words: &[&str]) -> Result<(f64, f64, f64), ParseError> {
    let [o, a, f] = words else {
        return Err(ParseError::WrongArgumentCount);
    };
    let offset_v = quantity(o, Quantity::Level)?;
    let amplitude_v = quantity(a, Quantity::Level)?;
    let freq_hz = quantity(f, Quantity::Frequency)?;
    in_range(
        freq_hz,
        design_parameters::REF_MIN_FREQ_HZ,
        design_parameters::REF_MAX_FREQ_HZ,
    )?;
    // The whole swing must stay inside the sensor range.
    if amplitude_v < 0.0
        || offset_v - amplitude_v < design_parameters::REF_MIN_V
        || offset_v + amplitude_v > design_parameters::REF_MAX_V
    {
        return Err(ParseError::OutOfRange);
    }
    Ok((offset_v, amplitude_v, freq_hz))
}

/// Parses one line (without its line ending). Never panics.
///
/// ```
/// use firmware::command::{parse, Command, ReferenceRequest};
/// assert_eq!(parse("ref step 5v"), Ok(Command::Reference(ReferenceRequest::Step { level_v: 5.0 })));
/// assert!(parse("ref step 50v").is_err());
/// ```
pub fn parse(line: &str) -> Result<Command, ParseError> {
    if line.len() > MAX_LINE || !line.is_ascii() {
        return Err(ParseError::TooLong);
    }
    let mut buf = [""; 6];
    let mut n = 0;
    for w in line.split_ascii_whitespace() {
        // One word more than any command takes is enough to know the line is wrong.
        let slot = buf.get_mut(n).ok_or(ParseError::WrongArgumentCount)?;
        *slot = w;
        n += 1;
    }
    let words = buf.get(..n).unwrap_or(&[]);
    let Some((&head, args)) = words.split_first() else {
        return Err(ParseError::Empty);
    };
    let none = |c: Command| {
        if args.is_empty() {
            Ok(c)
        } else {
            Err(ParseError::WrongArgumentCount)
        }
    };
    match head {
        "help" => none(Command::Help),
        "status" => none(Command::Status),
        "faults" => none(Command::Faults),
        "clear" => none(Command::Clear),
        "selftest" => none(Command::SelfTest),
        "mode" => match args {
            ["safe"] => Ok(Command::Mode(ModeRequest::Safe)),
            ["open"] => Ok(Command::Mode(ModeRequest::Open)),
            ["closed"] => Ok(Command::Mode(ModeRequest::Closed)),
            ["hold"] => Ok(Command::Mode(ModeRequest::Hold)),
            [_] => Err(ParseError::BadKeyword),
            _ => Err(ParseError::WrongArgumentCount),
        },
        "ref" => match args {
            ["step", l] => Ok(Command::Reference(ReferenceRequest::Step {
                level_v: level(l)?,
            })),
            ["step", ..] => Err(ParseError::WrongArgumentCount),
            ["sine", rest @ ..] => {
                let (offset_v, amplitude_v, freq_hz) = periodic(rest)?;
                Ok(Command::Reference(ReferenceRequest::Sine {
                    offset_v,
                    amplitude_v,
                    freq_hz,
                }))
            }
            ["triangle", rest @ ..] => {
                let (offset_v, amplitude_v, freq_hz) = periodic(rest)?;
                Ok(Command::Reference(ReferenceRequest::Triangle {
                    offset_v,
                    amplitude_v,
                    freq_hz,
                }))
            }
            [] => Err(ParseError::WrongArgumentCount),
            _ => Err(ParseError::BadKeyword),
        },
        "kc" => match args {
            [v] => {
                let kc = number(v)?;
                if kc > 0.0 && kc <= params::LAG_KC_MAX {
                    Ok(Command::Kc(kc))
                } else {
                    Err(ParseError::OutOfRange)
                }
            }
            _ => Err(ParseError::WrongArgumentCount),
        },
        "tau" => match args {
            [v] => Ok(Command::Tau(in_range(
                quantity(v, Quantity::Duration)?,
                design_parameters::TAU_MIN_S,
                design_parameters::TAU_MAX_S,
            )?)),
            _ => Err(ParseError::WrongArgumentCount),
        },
        "learn" => match args {
            ["on"] => Ok(Command::Learn(LearnRequest::On)),
            ["off"] => Ok(Command::Learn(LearnRequest::Off)),
            ["freeze"] => Ok(Command::Learn(LearnRequest::Freeze)),
            ["reset"] => Ok(Command::Learn(LearnRequest::Reset)),
            [_] => Err(ParseError::BadKeyword),
            _ => Err(ParseError::WrongArgumentCount),
        },
        "ff" => match args {
            ["on"] => Ok(Command::Feedforward(true)),
            ["off"] => Ok(Command::Feedforward(false)),
            [_] => Err(ParseError::BadKeyword),
            _ => Err(ParseError::WrongArgumentCount),
        },
        "rate" => match args {
            [v] => Ok(Command::Rate(in_range(
                quantity(v, Quantity::Frequency)?,
                params::MIN_SAMPLE_RATE_HZ,
                params::MAX_SAMPLE_RATE_HZ,
            )?)),
            _ => Err(ParseError::WrongArgumentCount),
        },
        "cal" => match args {
            [g, o] => {
                let gain = number(g)?;
                let offset_v = signed_volts(o)?;
                if (gain - 1.0).abs() <= design_parameters::CAL_MAX_GAIN_ERROR
                    && offset_v.abs() <= design_parameters::CAL_MAX_OFFSET_V
                {
                    Ok(Command::Calibrate { gain, offset_v })
                } else {
                    Err(ParseError::OutOfRange)
                }
            }
            _ => Err(ParseError::WrongArgumentCount),
        },
        "capture" => match args {
            ["status"] => Ok(Command::Capture(CaptureRequest::Status)),
            ["send"] => Ok(Command::Capture(CaptureRequest::Send { range: None })),
            ["send", first, count] => {
                let first: u32 = first.parse().map_err(|_| ParseError::BadNumber)?;
                let count: u32 = count.parse().map_err(|_| ParseError::BadNumber)?;
                if count == 0 {
                    return Err(ParseError::OutOfRange);
                }
                Ok(Command::Capture(CaptureRequest::Send {
                    range: Some((first, count)),
                }))
            }
            ["send", ..] => Err(ParseError::WrongArgumentCount),
            [d] => {
                let duration_s = quantity(d, Quantity::Duration)?;
                if duration_s > 0.0 {
                    Ok(Command::Capture(CaptureRequest::Arm { duration_s }))
                } else {
                    Err(ParseError::OutOfRange)
                }
            }
            _ => Err(ParseError::WrongArgumentCount),
        },
        _ => Err(ParseError::UnknownCommand),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * b.abs().max(1.0)
    }

    #[test]
    fn good_lines() {
        assert_eq!(parse("mode closed"), Ok(Command::Mode(ModeRequest::Closed)));
        assert_eq!(
            parse("  mode   hold "),
            Ok(Command::Mode(ModeRequest::Hold))
        );
        match parse("ref step 6um") {
            Ok(Command::Reference(ReferenceRequest::Step { level_v })) => {
                assert!(close(level_v, 5.0))
            }
            other => panic!("{other:?}"),
        }
        match parse("ref sine 5v 2.4um 1.5khz") {
            Ok(Command::Reference(ReferenceRequest::Sine {
                offset_v,
                amplitude_v,
                freq_hz,
            })) => {
                assert!(close(offset_v, 5.0) && close(amplitude_v, 2.0) && close(freq_hz, 1500.0));
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            parse("ref triangle 5v 1v 10hz"),
            Ok(Command::Reference(ReferenceRequest::Triangle { .. }))
        ));
        assert_eq!(parse("kc 1e4"), Ok(Command::Kc(1e4)));
        match parse("tau 200us") {
            Ok(Command::Tau(t)) => assert!(close(t, 2e-4)),
            other => panic!("{other:?}"),
        }
        assert_eq!(parse("ff on"), Ok(Command::Feedforward(true)));
        assert_eq!(parse("rate 100khz"), Ok(Command::Rate(1e5)));
        assert_eq!(
            parse("capture 500ms"),
            Ok(Command::Capture(CaptureRequest::Arm { duration_s: 0.5 }))
        );
        assert_eq!(
            parse("capture send 10 20"),
            Ok(Command::Capture(CaptureRequest::Send {
                range: Some((10, 20))
            }))
        );
        assert_eq!(
            parse("capture send"),
            Ok(Command::Capture(CaptureRequest::Send { range: None }))
        );
        assert_eq!(parse("status"), Ok(Command::Status));
        for (line, want) in [
            ("learn on", LearnRequest::On),
            ("learn off", LearnRequest::Off),
            (" learn  freeze", LearnRequest::Freeze),
            ("learn reset", LearnRequest::Reset),
        ] {
            assert_eq!(parse(line), Ok(Command::Learn(want)), "{line}");
        }
        assert_eq!(
            parse("cal 1.0129 -0.0558v"),
            Ok(Command::Calibrate {
                gain: 1.0129,
                offset_v: -0.0558
            })
        );
    }

    #[test]
    fn bad_lines_are_refused_with_the_right_reason() {
        use ParseError::*;
        let cases: &[(&str, ParseError)] = &[
            ("", Empty),
            ("   ", Empty),
            ("fly", UnknownCommand),
            ("mode", WrongArgumentCount),
            ("mode fast", BadKeyword),
            ("mode safe now", WrongArgumentCount),
            ("status now", WrongArgumentCount),
            ("ref step", WrongArgumentCount),
            ("ref step 5", BadUnit),
            ("ref step 5mm", BadUnit),
            ("ref step 11v", OutOfRange),
            ("ref step -1v", OutOfRange),
            ("ref step 13um", OutOfRange),
            ("ref step nanv", NotFinite),
            ("ref step infv", NotFinite),
            ("ref step 1e400v", NotFinite),
            ("ref step v", BadNumber),
            ("ref step 1.2.3v", BadNumber),
            ("ref sine 5v 1v", WrongArgumentCount),
            ("ref sine 5v 6v 10hz", OutOfRange),
            ("ref sine 5v -1v 10hz", OutOfRange),
            ("ref sine 5v 1v 10khz", OutOfRange),
            ("ref sine 5v 1v 0hz", OutOfRange),
            ("ref sine 5v 1v 10v", BadUnit),
            ("ref square 5v", BadKeyword),
            ("kc 0", OutOfRange),
            ("kc -5", OutOfRange),
            ("kc 1e9", OutOfRange),
            ("kc nan", NotFinite),
            ("kc 1e4 2", WrongArgumentCount),
            ("tau 1", BadUnit),
            ("tau 1s", OutOfRange),
            ("tau 0us", OutOfRange),
            ("ff maybe", BadKeyword),
            ("learn", WrongArgumentCount),
            ("learn start", BadKeyword),
            ("learn on now", WrongArgumentCount),
            ("learn 1", BadKeyword),
            ("rate 5khz", OutOfRange),
            ("rate 300khz", OutOfRange),
            ("rate 50000", BadUnit),
            ("cal 1.0", WrongArgumentCount),
            ("cal 1.0 0.1", BadUnit),
            ("cal 1.0 0.1um", BadUnit),
            ("cal 1.0 0.1.1v", BadNumber),
            ("cal 1.5 0v", OutOfRange),
            ("cal 1.0 1v", OutOfRange),
            ("cal nan 0v", NotFinite),
            ("cal 1 nanv", NotFinite),
            ("capture 0s", OutOfRange),
            ("capture -1s", OutOfRange),
            ("capture 1", BadUnit),
            ("capture send 1", WrongArgumentCount),
            ("capture send -1 5", BadNumber),
            ("capture send 1 0", OutOfRange),
            ("a b c d e f g h", WrongArgumentCount),
            ("ref step 5v\u{e9}", TooLong),
        ];
        for (line, want) in cases {
            assert_eq!(parse(line), Err(*want), "line {line:?}");
            assert!(!want.message().is_empty());
        }
        let long = "x".repeat(MAX_LINE + 1);
        assert_eq!(parse(&long), Err(TooLong));
        println!(
            "{} bad lines refused with the expected reason",
            cases.len() + 1
        );
    }

    #[test]
    fn never_panics_on_arbitrary_bytes() {
        // A cheap deterministic fuzz: every line built from a small alphabet of fragments.
        let frags = [
            "ref",
            "step",
            "sine",
            "1",
            "e",
            "-",
            ".",
            "v",
            "um",
            "hz",
            "k",
            " ",
            "nan",
            "capture",
            "send",
            "9999999999",
        ];
        let mut seed = 0x1234_5678u32;
        let mut accepted = 0;
        for _ in 0..20_000 {
            let mut line = String::new();
            for _ in 0..(seed % 8) {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                line.push_str(frags[(seed >> 16) as usize % frags.len()]);
            }
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            if let Ok(Command::Reference(ReferenceRequest::Step { level_v })) = parse(&line) {
                assert!((0.0..=10.0).contains(&level_v));
                accepted += 1;
            } else if parse(&line).is_ok() {
                accepted += 1;
            }
        }
        println!("fuzz: {accepted} of 20000 random lines accepted, none panicked");
    }
}
