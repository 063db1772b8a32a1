//! CSV records and model files: bad input gets a clear error naming the line and the problem,
//! never a panic (fuzzed with proptest); the writer round-trips; built-in models round-trip
//! through TOML.

use host_tests::io::csv::{Record, RecordError};
use host_tests::io::model_file::ModelFile;
use proptest::prelude::*;

fn err(text: &str) -> String {
    let e = Record::parse(text).expect_err("must be refused");
    let s = e.to_string();
    println!("{text:?} -> {s}");
    s
}

#[test]
fn bad_records_get_errors_naming_line_and_problem() {
    assert!(err("").contains("empty record"));
    assert!(err("# only a comment\n\n").contains("empty record"));
    assert!(err("t,y\n0,1\n").contains("line 1: header has no column `u`"));
    assert!(err("u,y\n0,1\n").contains("no column `t`"));
    assert!(err("t,u,t\n0,1,2\n").contains("appears twice"));
    assert!(err("t,u\n0,1\n1e-3,abc\n").contains("line 3: column `u`: `abc` is not a number"));
    assert!(err("t,u\n0,1\n1e-3,NaN\n").contains("line 3: column `u` is NaN"));
    assert!(err("t,u\n0,1\n1e-3,inf\n").contains("line 3"));
    assert!(
        err("t,u,y\n0,1,2\n1e-3,1\n").contains("line 3: 2 fields, but the header names 3 columns")
    );
    assert!(err("t,u\n0,1\n").contains("1 sample"));
    assert!(err("t,u\n").contains("0 sample"));
    assert!(err("t,u\n0,1\n0,1\n").contains("line 3: time 0 s does not increase"));
    assert!(err("t,u\n0,0\n1,0\n2,0\n3.5,0\n4,0\n").contains("line 5: sampling interval"));
    // Comments and blank lines in between keep the line numbers of the file.
    assert!(err("# c\nt,u\n\n0,0\n# c\n0.001,x\n").contains("line 6"));
    let bytes = b"t,u\n0,0\n\xff\xfe,1\n";
    let e = Record::parse_bytes(bytes).unwrap_err();
    println!("non-UTF-8 -> {e}");
    assert_eq!(e, RecordError::NotText { line: 3 });
    let e = Record::read(std::path::Path::new("/nonexistent/record.csv")).unwrap_err();
    assert!(e.to_string().contains("cannot read"));
    // Mismatched columns handed to the constructor.
    let e = Record::new(vec![0.0, 1.0], vec![0.0], None, None).unwrap_err();
    assert!(e.to_string().contains("different lengths"));
}

#[test]
fn good_records_parse_at_any_rate_and_ignore_other_columns() {
    let text = "# recorded 2001\n t , u, extra ,y, r\n0,0,a,0.1,0\n0.25,1,b,0.2,1\n0.5,2,c,0.3,2\n";
    let r = Record::parse(text).unwrap();
    assert_eq!(r.u_v, vec![0.0, 1.0, 2.0]);
    assert_eq!(r.y_v.as_deref(), Some(&[0.1, 0.2, 0.3][..]));
    assert_eq!(r.r_v.as_deref(), Some(&[0.0, 1.0, 2.0][..]));
    assert!((r.rate_hz() - 4.0).abs() < 1e-12);
    // 50 kHz with times printed to 7 significant digits still counts as uniform.
    let mut s = String::from("t,u\n");
    for i in 0..1000 {
        s.push_str(&format!("{:.7e},0\n", i as f64 * 2e-5));
    }
    let r = Record::parse(&s).unwrap();
    println!("50 kHz record: rate {:.3} Hz", r.rate_hz());
    assert!((r.rate_hz() - 50_000.0).abs() < 1.0);
    assert!(
        Record::parse("t,u\n0,1\n1,1\n")
            .unwrap()
            .require_y()
            .is_err()
    );
}

/// Time stamps rounded by the logger (`f32`, a few printed decimals) or jittery, on a record
/// whose converters ran on a steady clock: taken as uniform at the mean interval, with a note;
/// a real gap is still refused.
#[test]
fn rounded_time_stamps_are_taken_as_uniform_with_a_note() {
    // 10 s at 50 kHz with f32 time stamps: intervals off by up to a few % near 10 s.
    let n = 500_000;
    let t: Vec<f64> = (0..n).map(|i| (i as f64 * 2e-5) as f32 as f64).collect();
    let mean = (t[n - 1] - t[0]) / (n - 1) as f64;
    let given = t
        .windows(2)
        .map(|w| ((w[1] - w[0]) - mean).abs() / mean)
        .fold(0.0, f64::max);
    assert!(given > 0.01 && given < 0.2, "{given}");
    let u = vec![1.0; n];
    let r = Record::new(t, u, None, None).unwrap();
    assert_eq!(r.original_jitter, Some(given));
    assert!(r.time_jitter() < 1e-6, "{}", r.time_jitter());
    assert!((r.rate_hz() - 50_000.0).abs() < 0.01, "{}", r.rate_hz());
    let note = r.time_note("f32.csv").expect("a note");
    println!("{note}");
    assert!(note.contains("f32.csv") && note.contains("taken as uniform"));
    // 3 kHz printed with five decimals (0.00033, 0.00067, 0.00100, ...): 1.5 % off.
    let mut s = String::from("t,u\n");
    for i in 0..3000 {
        s.push_str(&format!("{:.5},0\n", i as f64 / 3000.0));
    }
    let r = Record::parse(&s).unwrap();
    assert!(r.original_jitter.is_some_and(|j| j > 0.01));
    assert!((r.rate_hz() - 3000.0).abs() < 0.01, "{}", r.rate_hz());
    // Exact times: kept as given, no note.
    let r = Record::parse("t,u\n0,0\n0.25,1\n0.5,2\n").unwrap();
    assert_eq!(r.original_jitter, None);
    assert_eq!(r.t_s, vec![0.0, 0.25, 0.5]);
    assert!(r.time_note("exact.csv").is_none());
    // A missing sample (one interval twice the others) is refused.
    let mut s = String::from("t,u\n");
    for i in (0..100).filter(|&i| i != 50) {
        s.push_str(&format!("{},0\n", i as f64 * 1e-3));
    }
    assert!(err(&s).contains("sampling interval"), "{}", err(&s));
}

/// Spreadsheets in decimal-comma locales export with semicolons (or tabs) and decimal commas,
/// loggers and MATLAB write blank-separated columns, and many put a units row under the
/// header: each read as the comma-separated file with points would be.
#[test]
fn semicolon_and_tab_separated_records_read_with_decimal_commas() {
    let commas = Record::parse("t,u,y\n0,0.5,0.25\n0.001,1.5,-0.75\n0.002,2,1e-3\n").unwrap();
    let semis = Record::parse("t;u;y\n0;0,5;0,25\n0,001;1,5;-0,75\n0,002;2;1e-3\n").unwrap();
    let tabs = Record::parse("t\tu\ty\n0\t0.5\t0.25\n0.001\t1,5\t-0.75\n0.002\t2\t1e-3\n").unwrap();
    assert_eq!(semis, commas);
    assert_eq!(tabs, commas);
    // A field that is not a number either way is refused with its text.
    let e = err("t;u\n0;1\n0,001;1,2,3\n");
    assert!(e.contains("line 3") && e.contains("1,2,3"), "{e}");
    // Blank-separated columns (a `.txt` as MATLAB or a logger writes it), and a units row
    // under the header, read as the same record.
    let blanks = Record::parse("t  u y\n0 0.5\t0.25\n  0.001 1.5 -0.75\n0.002 2 1e-3\n").unwrap();
    assert_eq!(blanks, commas);
    let units = Record::parse("t,u,y\ns,V,V\n0,0.5,0.25\n0.001,1.5,-0.75\n0.002,2,1e-3\n").unwrap();
    assert_eq!(units, commas);
    let units = Record::parse("t;u;y\n[s];[V];[V]\n0;0,5;0,25\n0,001;1,5;-0,75\n0,002;2;1e-3\n");
    assert_eq!(units.unwrap(), commas);
    // Only one such row, and only first: text further down is refused with its line.
    let e = err("t,u,y\ns,V,V\ns,V,V\n0,0.5,0.25\n");
    assert!(e.contains("line 3") && e.contains("`s`"), "{e}");
    let e = err("t,u,y\n0,0.5,0.25\ns,V,V\n");
    assert!(e.contains("line 3"), "{e}");
    // A row with one number among text is no units row, nor a row of missing values.
    let e = err("t,u,y\ns,1,V\n0,0.5,0.25\n");
    assert!(e.contains("line 2"), "{e}");
    let e = err("t,u,y\nNA,NA,NA\n0,0.5,0.25\n");
    assert!(e.contains("line 2"), "{e}");
    // Every field in double quotes (a spreadsheet's or a data frame's "quote all"), with
    // points, or with decimal commas under semicolons; a header with a comma inside its
    // quotes is separated by its semicolons.
    let quoted = Record::parse(
        "\"t\",\"u\",\"y\"\n\"0\",\"0.5\",\"0.25\"\n\"0.001\",\"1.5\",\"-0.75\"\n\"0.002\",\"2\",\"1e-3\"\n",
    );
    assert_eq!(quoted.unwrap(), commas);
    let quoted = Record::parse(
        "\"t\";\"u\";\"y\"\n\"0\";\"0,5\";\"0,25\"\n\"0,001\";\"1,5\";\"-0,75\"\n\"0,002\";\"2\";\"1e-3\"\n",
    );
    assert_eq!(quoted.unwrap(), commas);
    let named = Record::parse_named(
        "\"t, s\";\"u\";\"y\"\n0;0,5;0,25\n0,001;1,5;-0,75\n0,002;2;1e-3\n",
        ["t, s", "u", "y"],
    );
    assert_eq!(named.unwrap(), commas);
    // Under commas a quoted comma is a thousands separator or a decimal comma: refused.
    let e = err("t,u,y\n0,\"1,234\",0.5\n0.001,1,0.5\n");
    assert!(e.contains("line 2") && e.contains("1,234"), "{e}");
    // Quotes that do not close leave the line's fields unsplit after them: refused by count.
    let e = err("t,u,y\n0,\"0.5,0.25\n");
    assert!(e.contains("line 2") && e.contains("fields"), "{e}");
}

/// A record without a header (a logger's or a published data set's: the first row is data)
/// names its columns by their 1-based numbers; named columns are refused with the numbers to
/// use; under a header a number names a column where no column has that name.
#[test]
fn a_record_without_a_header_names_its_columns_by_number() {
    let want = Record::parse("t,u,y\n0,0.5,0.25\n0.001,1.5,-0.75\n0.002,2,1e-3\n").unwrap();
    // (as the published actuator record: an empty index column, time, output, input)
    let bare = ",0,0.25,0.5\n,0.001,-0.75,1.5\n,0.002,1e-3,2\n";
    assert_eq!(Record::parse_named(bare, ["2", "4", "3"]).unwrap(), want);
    let e = Record::parse(bare).unwrap_err().to_string();
    assert!(
        e.contains("line 1") && e.contains("1 to 4") && e.contains("t=1,u=2,y=3"),
        "{e}"
    );
    let e = Record::parse_named(bare, ["2", "5", "3"])
        .unwrap_err()
        .to_string();
    assert!(e.contains("`5`"), "{e}");
    // A comment before the first row is still a comment.
    let commented = format!("# logged 2026-12-06\n{bare}");
    assert_eq!(
        Record::parse_named(&commented, ["2", "4", "3"]).unwrap(),
        want
    );
    let headed = "i,time,out,in\n,0,0.25,0.5\n,0.001,-0.75,1.5\n,0.002,1e-3,2\n";
    assert_eq!(Record::parse_named(headed, ["2", "4", "3"]).unwrap(), want);
    assert_eq!(
        Record::parse_named(headed, ["time", "in", "out"]).unwrap(),
        want
    );
    // A data frame's unnamed columns (`,0,1,2`, or `0,1,2` without its index) are a header of
    // those labels, and a number under it is a label, never a position.
    let frame = ",0,1,2\n0,0,0.5,0.25\n1,0.001,1.5,-0.75\n2,0.002,2,1e-3\n";
    assert_eq!(Record::parse_named(frame, ["0", "1", "2"]).unwrap(), want);
    let labelled = Record::parse_named(frame, ["0", "1", "3"]).unwrap();
    assert_eq!(labelled.u_v, want.u_v);
    assert!(
        labelled.y_v.is_none(),
        "`3` is no label, and not a position"
    );
    // Without a header, from a decimal-comma locale: semicolons or tabs, decimal commas.
    for sep in [";", "\t"] {
        let text = format!("0{sep}0,5{sep}0,25\n0,001{sep}1,5{sep}-0,75\n0,002{sep}2{sep}1e-3\n");
        assert_eq!(
            Record::parse_named(&text, ["1", "2", "3"]).unwrap(),
            want,
            "{sep:?}"
        );
    }
    let bare_frame = "0,1,2\n0,0.5,0.25\n0.001,1.5,-0.75\n0.002,2,1e-3\n";
    assert_eq!(
        Record::parse_named(bare_frame, ["0", "1", "2"]).unwrap(),
        want
    );
}

#[test]
fn writer_round_trips_exactly() {
    let t: Vec<f64> = (0..100).map(|i| i as f64 * 1e-3).collect();
    let u: Vec<f64> = t.iter().map(|t| (t * 7.0).sin() * 3.1).collect();
    let y: Vec<f64> = u.iter().map(|u| u * 0.79 + 1e-9).collect();
    let r = Record::new(t, u, Some(y), None).unwrap();
    let back = Record::parse(&r.to_csv()).unwrap();
    assert_eq!(r, back);
}

#[test]
fn model_files_round_trip_and_refuse_unknown_keys() {
    for name in ["thesis-linear", "thesis-full"] {
        let m = ModelFile::load(name).unwrap();
        let text = m.to_toml().unwrap();
        let back = ModelFile::parse(&text).unwrap();
        assert_eq!(m, back, "{name}");
        back.build_stage().unwrap();
    }
    let full = ModelFile::load("thesis-full").unwrap().to_toml().unwrap();
    let linear = ModelFile::load("thesis-linear").unwrap();
    assert!(
        linear.drift.is_none() && linear.nonlinear_gain.is_none() && linear.saturation.is_none()
    );
    assert!(linear.time_delay.is_some() && linear.amplifier_pole.is_some());
    // A typo in a key, an unknown table, a value of the wrong type, an absurd value.
    let cases = [
        (full.replace("static_gain", "static_gian"), "static_gian"),
        (format!("{full}\n[creep]\nlaw = \"log\"\n"), "creep"),
        (
            full.replace("mode_hz = 5792.0", "mode_hz = \"fast\""),
            "mode_hz",
        ),
        (
            full.replace("delay_s = 0.000085", "delay_s = 5.0"),
            "[time-delay] delay_s",
        ),
        (
            full.replace("taus_s = [0.06, 0.75, 12.0]", "taus_s = [0.06, 0.75]"),
            "taus_s",
        ),
    ];
    for (text, needle) in cases {
        let e = format!("{:#}", ModelFile::parse(&text).unwrap_err());
        println!("model file error: {}", e.lines().next().unwrap_or(""));
        assert!(e.contains(needle), "{e}");
    }
    let e = ModelFile::load("no-such-model").unwrap_err().to_string();
    assert!(e.contains("thesis-linear, thesis-full"), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    /// Arbitrary bytes never panic the record reader.
    #[test]
    fn record_reader_never_panics_on_bytes(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        let _ = Record::parse_bytes(&bytes);
    }

    /// Strings built from the CSV alphabet (more likely to get deep into the parser) never
    /// panic, and an accepted record is always uniform, finite and at least 2 samples long.
    #[test]
    fn record_reader_never_panics_on_csv_like_text(s in "(t,u(,y)?(,r)?\n)?([0-9.eE+-]{0,6}(,[0-9.eE+-naNif]{0,5}){0,4}\n|#[a-z]*\n|\n){0,12}") {
        if let Ok(r) = Record::parse(&s) {
            prop_assert!(r.len() >= 2);
            prop_assert!(r.t_s.iter().chain(&r.u_v).all(|v| v.is_finite()));
        }
    }

    /// Arbitrary text never panics the model-file reader.
    #[test]
    fn model_reader_never_panics(s in "\\PC{0,300}") {
        let _ = ModelFile::parse(&s);
    }

    /// Mutating one value of a valid model file never panics: it parses to a buildable model or
    /// is refused with an error.
    #[test]
    fn model_reader_survives_mutated_values(pos in 0usize..2000, v in prop_oneof![
        Just("nan".to_string()), Just("-1e308".to_string()), Just("0".to_string()),
        Just("1e400".to_string()), Just("-0.0".to_string()), Just("[]".to_string()), Just("true".to_string()),
        any::<f64>().prop_map(|f| format!("{f:?}")),
    ]) {
        let full = ModelFile::load("thesis-full").unwrap().to_toml().unwrap();
        let lines: Vec<&str> = full.lines().collect();
        let k = pos % lines.len();
        let mut out = String::new();
        for (i, l) in lines.iter().enumerate() {
            if i == k && l.contains(" = ") {
                let key = l.split(" = ").next().unwrap_or("");
                out.push_str(&format!("{key} = {v}\n"));
            } else {
                out.push_str(l);
                out.push('\n');
            }
        }
        if let Ok(m) = ModelFile::parse(&out) {
            prop_assert!(m.build_stage().is_ok());
        }
    }
}
