//! Hidden-effect tests of the model-gap workflow (issue #7, item 4), and its bad-input tests.
//!
//! Records are synthesised from a ground truth that uses **other functional forms** than the
//! workflow fits: drift is a logarithmic creep law `gamma ln(1 + t / tau0)` per volt of step
//! (superposed over the input's history; the workflow fits three first-order lags), hysteresis
//! is a Bouc-Wen model (the workflow fits eight play operators). Non-linear gain, slew limit,
//! extra delay and a second mode use the stage's own blocks with random parameters. Every
//! record has 1 mV of sensor noise. The truth is written to its own JSON file, apart from the
//! CSV records the workflow reads; the workflow starts from `thesis-linear` and is told
//! nothing else.

use host_tests::gap::{self, Data, Options, diagnose, protocol};
use host_tests::io::csv::Record;
use host_tests::io::model_file::{GainSection, ModelFile, ResonanceSection, SlewSection};
use host_tests::sim::open_loop::simulate;
use model_core::params;
use rand::{Rng, SeedableRng};
use std::collections::BTreeMap;

const HIDDEN: [&str; 6] = [
    "drift",
    "hysteresis",
    "nonlinear-gain",
    "slew-rate-limit",
    "time-delay",
    "resonance",
];

/// A ground truth: the effects and their parameters (kept apart from the records).
#[derive(Clone, Debug, serde::Serialize)]
struct Truth {
    effects: Vec<String>,
    /// Log creep: gamma (sensor V per input V per e-fold of time), tau0 (s).
    creep: Option<(f64, f64)>,
    /// Bouc-Wen: alpha, beta (1/V), gamma (1/V).
    bouc_wen: Option<(f64, f64, f64)>,
    gain: Option<(f64, f64)>,
    slew_v_per_s: Option<f64>,
    delay_s: Option<f64>,
    mode: Option<(f64, f64)>,
    seed: u64,
}

fn truth(effects: &[&str], seed: u64) -> Truth {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut lu = |lo: f64, hi: f64| (lo.ln() + (hi.ln() - lo.ln()) * rng.r#gen::<f64>()).exp();
    let has = |e: &str| effects.contains(&e);
    let creep = has("drift").then(|| (lu(0.004, 0.01), lu(0.005, 0.05)));
    let bouc_wen = has("hysteresis").then(|| {
        let beta = lu(0.5, 1.5);
        let g = beta * (lu(0.1, 0.7) - 0.4);
        (lu(0.15, 0.3), beta, g)
    });
    let gain = has("nonlinear-gain").then(|| {
        let a = lu(0.006, 0.02);
        (a, -a / 20.0 * lu(0.3, 1.0))
    });
    let slew_v_per_s = has("slew-rate-limit").then(|| lu(2e4, 2e5));
    let delay_s = has("time-delay").then(|| lu(150e-6, 400e-6));
    let mode = has("resonance").then(|| (lu(3000.0, 12000.0), lu(0.02, 0.08)));
    Truth {
        effects: effects.iter().map(|s| s.to_string()).collect(),
        creep,
        bouc_wen,
        gain,
        slew_v_per_s,
        delay_s,
        mode,
        seed,
    }
}

/// The input seen by the stage's linear part: the record's input plus the creep and the
/// Bouc-Wen hysteresis, in input volts (both act on the displacement before the dynamics).
fn predistort(tr: &Truth, t_s: &[f64], u: &[f64]) -> Vec<f64> {
    let n = u.len();
    let dt = if n > 1 { t_s[1] - t_s[0] } else { 1.0 };
    let mut extra = vec![0.0; n];
    if let Some((gamma, tau0)) = tr.creep {
        // ln(1 + t/tau0) = integral over x of (1 - exp(-e^x t)) exp(-e^x tau0) dx: a dense bank
        // of first-order lags (quarter-decade spacing over 9 decades): the log law within
        // 0.5 %, not the workflow's three-lag form.
        let dx = std::f64::consts::LN_10 / 4.0;
        let mut bank: Vec<(f64, f64, f64)> = (0..40)
            .map(|k| {
                let s = 1e-4 * (k as f64 * dx).exp();
                (dx * (-s * tau0).exp(), (-s * dt).exp(), 0.0)
            })
            .collect();
        for i in 0..n {
            let mut c = 0.0;
            for (w, a, x) in bank.iter_mut() {
                c += *w * *x;
                *x = *a * *x + (1.0 - *a) * (u[i] - u[0]);
            }
            extra[i] += gamma * c / params::PLANT_GAIN;
        }
    }
    if let Some((alpha, beta, gamma)) = tr.bouc_wen {
        let mut h = 0.0;
        for i in 1..n {
            let du_all = u[i] - u[i - 1];
            let m = (du_all.abs() / 0.005).ceil().max(1.0) as usize;
            let du = du_all / m as f64;
            for _ in 0..m {
                h += alpha * du - beta * du.abs() * h - gamma * du * h.abs();
            }
            extra[i] -= h;
        }
    }
    u.iter().zip(&extra).map(|(a, b)| a + b).collect()
}

fn truth_model(tr: &Truth) -> ModelFile {
    let mut m = ModelFile::built_in("thesis-linear").expect("built-in");
    m.converters.noise_v = 1e-3;
    m.converters.seed = tr.seed;
    if let Some((a, b)) = tr.gain {
        m.nonlinear_gain = Some(GainSection {
            poly: [1.0, a, b, 0.0, 0.0, 0.0, 0.0],
            range_v: [0.0, 10.0],
        });
    }
    if let Some(s) = tr.slew_v_per_s {
        m.slew_rate_limit = Some(SlewSection { output_v_per_s: s });
    }
    if let Some(d) = tr.delay_s {
        m.time_delay = Some(host_tests::io::model_file::DelaySection { delay_s: d });
    }
    if let Some((f, z)) = tr.mode {
        m.resonance = Some(ResonanceSection {
            mode_hz: f,
            damping: z,
        });
    }
    m
}

/// Write the case's records (CSV) and its truth (JSON) into `dir`; return the record paths.
fn synthesise(tr: &Truth, dir: &std::path::Path, slow_s: f64) -> Vec<std::path::PathBuf> {
    let m = truth_model(tr);
    let mut paths = Vec::new();
    for (i, (name, (t, u))) in [
        ("fast.csv", protocol::fast_input(50_000.0, 0.2)),
        ("slow.csv", protocol::slow_input(1_000.0, slow_s)),
    ]
    .into_iter()
    .enumerate()
    {
        let mut mi = m.clone();
        mi.converters.seed = tr.seed * 2 + i as u64;
        let stage = mi.build_stage().expect("truth model");
        let y = simulate(&stage, mi.period_s, &t, &predistort(tr, &t, &u));
        let rec = Record::new(t, u, Some(y), None).expect("record");
        let p = dir.join(name);
        rec.write(&p).expect("write record");
        paths.push(p);
    }
    std::fs::write(
        dir.join("truth.json"),
        serde_json::to_string_pretty(tr).unwrap(),
    )
    .unwrap();
    paths
}

struct Outcome {
    truth: Vec<String>,
    named: Vec<String>,
    cuts_ok: bool,
    worst_cut: String,
    final_over_floor: f64,
}

fn run_case(kind: &[&str], seed: u64, slow_s: f64) -> Outcome {
    let tr = truth(kind, seed);
    let dir = std::env::temp_dir().join(format!("piezo-gap-test-{}-{seed}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let paths = synthesise(&tr, &dir, slow_s);
    let data = gap::load_data(&paths, None).expect("records load");
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let d = diagnose(&base, &data, &Options::default()).expect("diagnosis");
    let _ = std::fs::remove_dir_all(&dir);
    if std::env::var("GAP_DEBUG").is_ok() {
        println!("seed {seed} truth {tr:?}\n{}", d.table());
        for (r, rec) in data.iter().enumerate() {
            let y = gap::sim(&d.model, rec).unwrap();
            let (mut e_edge, mut n_edge, mut e_set, mut n_set) = (0.0, 0, 0.0, 0);
            let mut since = usize::MAX;
            let win = (3e-3 / rec.period_s()).ceil() as usize;
            for (i, yi) in y.iter().enumerate() {
                if i > 0 && (rec.u_v[i] - rec.u_v[i - 1]).abs() > 0.02 {
                    since = 0;
                } else {
                    since = since.saturating_add(1);
                }
                let e = (rec.y_v[i] - yi).powi(2);
                if since <= win {
                    e_edge += e;
                    n_edge += 1;
                } else {
                    e_set += e;
                    n_set += 1;
                }
            }
            println!(
                "  record {r}: final RMS within 3 ms of edges {:.2} mV ({n_edge}), elsewhere {:.2} mV ({n_set})",
                1e3 * (e_edge / n_edge.max(1) as f64).sqrt(),
                1e3 * (e_set / n_set.max(1) as f64).sqrt()
            );
        }
        print!("{}", d.trace());
    }
    // Each correctly named effect: its step cuts the residual >= 5x, or brings it within 1.5x
    // of the noise floor, or (in a pair) removing it from the final model raises the residual
    // >= 5x (`gap::shrink`).
    let mut cuts_ok = true;
    let mut worst_cut = String::new();
    for effect in tr.effects.iter().filter(|e| d.named.contains(e)) {
        if let Some(s) = gap::shrink::shortfall(effect, &d.residual_cuts(effect, &data, &base)) {
            cuts_ok = false;
            worst_cut = s;
        }
    }
    Outcome {
        truth: tr.effects.clone(),
        named: d.named.clone(),
        cuts_ok,
        worst_cut,
        final_over_floor: d.final_rms_v / d.noise_floor_v,
    }
}

fn kinds() -> Vec<Vec<&'static str>> {
    let mut k: Vec<Vec<&str>> = vec![vec![], vec![]];
    for e in HIDDEN {
        k.push(vec![e]);
    }
    for (i, a) in HIDDEN.iter().enumerate() {
        for b in &HIDDEN[i + 1..] {
            k.push(vec![*a, *b]);
        }
    }
    k
}

#[test]
fn hidden_effects_are_named() {
    // Release (the README's test command): 92 cases, 4 of each of the 23 kinds (2 clean,
    // 6 single effects, 15 pairs; `GAP_PER_KIND` changes the 4), 30 s slow records. Debug
    // builds run 8 cases so the file stays quick; the 95 % figure is asserted on the release
    // run.
    let release = !cfg!(debug_assertions);
    let ks = kinds();
    let per_kind: usize = std::env::var("GAP_PER_KIND")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(4);
    let n_cases = if release { per_kind * ks.len() } else { 8 };
    let only: Option<u64> = std::env::var("GAP_SEED").ok().and_then(|s| s.parse().ok());
    let slow_s = 30.0;
    let cases: Vec<(Vec<&str>, u64)> = (0..n_cases)
        .map(|i| (ks[(i * 7) % ks.len()].clone(), 1000 + i as u64))
        .filter(|c| only.is_none_or(|s| s == c.1))
        .collect();
    let outcomes = host_tests::util::par_map(&cases, |(k, seed)| run_case(k, *seed, slow_s));
    // Confusion table: rows are the hidden effects (and "clean"), columns the names given.
    let mut names: Vec<&str> = gap::catalogue::EFFECTS.to_vec();
    names.push("(none)");
    let mut table: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    let mut exact = 0;
    let mut clean_total = 0;
    let mut clean_named = 0;
    let mut false_names = 0;
    let mut names_given = 0;
    let mut cut_fail = Vec::new();
    for (o, (k, seed)) in outcomes.iter().zip(&cases) {
        let mut t: Vec<String> = o.truth.clone();
        t.sort();
        let mut n = o.named.clone();
        n.sort();
        let ok = t == n;
        exact += ok as usize;
        if !ok {
            eprintln!(
                "case seed {seed} truth {k:?}: named {:?} (final {:.2}x floor)",
                o.named, o.final_over_floor
            );
        }
        if !o.cuts_ok {
            cut_fail.push(format!("seed {seed} {k:?}: {}", o.worst_cut));
        }
        let rows: Vec<String> = if t.is_empty() {
            vec!["clean".into()]
        } else {
            t.clone()
        };
        for r in &rows {
            let row = table.entry(r.clone()).or_default();
            if n.is_empty() {
                *row.entry("(none)".into()).or_default() += 1;
            }
            for x in &n {
                *row.entry(x.clone()).or_default() += 1;
            }
        }
        names_given += n.len();
        false_names += n.iter().filter(|x| !t.contains(x)).count();
        if t.is_empty() {
            clean_total += 1;
            clean_named += (!n.is_empty()) as usize;
        }
    }
    println!(
        "\nConfusion table ({} cases; rows: hidden effect, columns: effects named)",
        outcomes.len()
    );
    print!("{:<16}", "");
    for c in &names {
        print!("{:>9}", &c[..c.len().min(8)]);
    }
    println!();
    for (r, row) in &table {
        print!("{:<16}", r);
        for c in &names {
            print!("{:>9}", row.get(*c).copied().unwrap_or(0));
        }
        println!();
    }
    let acc = exact as f64 / outcomes.len() as f64;
    println!(
        "named set exactly right: {exact}/{} = {:.1} %; false names: {false_names} of {names_given} given ({:.1} %); clean records named: {clean_named}/{clean_total}",
        outcomes.len(),
        100.0 * acc,
        100.0 * false_names as f64 / names_given.max(1) as f64
    );
    println!("residual-cut failures: {}", cut_fail.len());
    for c in &cut_fail {
        println!("  {c}");
    }
    if only.is_some() {
        return;
    }
    assert!(outcomes.len() >= if release { 50 } else { 8 });
    assert_eq!(clean_named, 0, "clean records must get no name");
    if release {
        assert!(acc >= 0.95, "accuracy {:.1} % below 95 %", 100.0 * acc);
        // Issue #12's bar on false names: at most 1 % of the names given. Measured 0 of 144
        // since session 20 (both splits' diagnoses where the loop alone cannot choose, the
        // one naming fewer effects kept); 2 of 144 before (a false `offset` beside Bouc-Wen
        // loops under the `Span` split).
        assert!(
            false_names * 100 <= names_given,
            "false names {false_names} of {names_given} above 1 %"
        );
    } else {
        assert!(
            acc >= 0.75,
            "accuracy {:.1} % on the small debug sample",
            100.0 * acc
        );
    }
    // Every correctly named effect should cut the residual of the record that shows it >= 5x
    // or bring it within 1.5x of the floor (`gap::shrink`, measured the same way on the
    // randomised families). Measured on the 92 cases in session 40: 144 of 144. When this
    // was first measured, with play operators for the loop: all but two, both a
    // second mode under a Bouc-Wen hysteresis with strongly non-congruent minor loops (cuts
    // 1.9x and 1.7x). Bouc-Wen's small reversals are not wiped out when the input moves on, so
    // no Preisach-type form (play operators, the Everett table) fits the fast record's reversal
    // history: 15-18 mV of hysteresis misfit stays there, and the mode, which removes all the
    // ringing, cannot cut more. Asserted: at least 98 % of the correctly named effects.
    let correct: usize = outcomes
        .iter()
        .map(|o| o.named.iter().filter(|n| o.truth.contains(n)).count())
        .sum();
    let cut_ok = 1.0 - cut_fail.len() as f64 / correct.max(1) as f64;
    println!(
        "correctly named effects meeting the residual cut: {}/{correct} = {:.1} %",
        correct - cut_fail.len(),
        100.0 * cut_ok
    );
    assert!(
        cut_ok >= 0.98,
        "effects that did not cut the residual enough: {cut_fail:?}"
    );
}

// ----- bad input -----

fn good_record() -> Record {
    let (t, u) = protocol::fast_input(50_000.0, 0.05);
    let y = u.iter().map(|x| 0.79 * x).collect();
    Record::new(t, u, Some(y), None).unwrap()
}

fn write_tmp(name: &str, text: &[u8]) -> std::path::PathBuf {
    let p = std::env::temp_dir().join(format!("piezo-gap-bad-{}-{name}", std::process::id()));
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn bad_records_give_clear_errors() {
    let cases: Vec<(&str, &str, &str)> = vec![
        ("empty.csv", "", "empty record"),
        (
            "malformed.csv",
            "t,u,y\n0,0,0\n1e-5,zero,0\n",
            "not a number",
        ),
        (
            "nonuniform.csv",
            "t,u,y\n0,0,0\n1,0,0\n3,1,0\n",
            "sampling interval",
        ),
        ("nan.csv", "t,u,y\n0,0,0\n1,NaN,0\n2,0,0\n", "finite"),
        ("mismatched.csv", "t,u,y\n0,0,0\n1,0\n", "fields"),
        ("no_y.csv", "t,u\n0,0\n1,1\n", "no `y` column"),
    ];
    for (name, text, want) in cases {
        let p = write_tmp(name, text.as_bytes());
        let e = gap::load_data(std::slice::from_ref(&p), None).expect_err(name);
        let msg = format!("{e:#}");
        println!("{name}: {msg}");
        assert!(msg.contains(want), "{name}: `{msg}` does not say `{want}`");
        let _ = std::fs::remove_file(p);
    }
    // Too short to show anything.
    let mut text = String::from("t,u,y\n");
    for i in 0..50 {
        text.push_str(&format!("{},{},{}\n", i as f64 * 1e-3, i as f64 * 0.1, 0.0));
    }
    let p = write_tmp("short.csv", text.as_bytes());
    let msg = format!(
        "{:#}",
        gap::load_data(std::slice::from_ref(&p), None).unwrap_err()
    );
    println!("short: {msg}");
    assert!(msg.contains("too short"));
    let _ = std::fs::remove_file(p);
    // An input that never moves.
    let mut text = String::from("t,u,y\n");
    for i in 0..500 {
        text.push_str(&format!("{},1.0,0.79\n", i as f64 * 1e-3));
    }
    let p = write_tmp("flat.csv", text.as_bytes());
    let msg = format!(
        "{:#}",
        gap::load_data(std::slice::from_ref(&p), None).unwrap_err()
    );
    println!("flat: {msg}");
    assert!(msg.contains("never moves"));
    let _ = std::fs::remove_file(p);
    // A good record loads.
    let p = write_tmp("good.csv", good_record().to_csv().as_bytes());
    assert!(gap::load_data(std::slice::from_ref(&p), None).is_ok());
    let _ = std::fs::remove_file(p);
}

#[test]
fn bad_models_give_clear_errors() {
    let good = ModelFile::built_in("thesis-linear")
        .unwrap()
        .to_toml()
        .unwrap();
    let typo = good.replace("[plant]", "[plant]\nstatic_gian = 0.8");
    let e = ModelFile::parse(&typo).unwrap_err();
    println!("unknown key: {e:#}");
    assert!(format!("{e:#}").contains("static_gian"));
    let unknown_effect = format!("{good}\n[creep]\nrate = 1.0\n");
    let e = ModelFile::parse(&unknown_effect).unwrap_err();
    println!("unknown table: {e:#}");
    assert!(format!("{e:#}").contains("creep"));
    let n = params::PLAY_OPERATORS;
    let bad_hyst = format!(
        "{good}\n[hysteresis-play]\nradii_v = {:?}\nweights = [500.0{}]\n",
        params::PLAY_RADII_V,
        ", 0.0".repeat(n - 1)
    );
    let e = ModelFile::parse(&bad_hyst).unwrap_err();
    println!("bad hysteresis: {e:#}");
    assert!(format!("{e:#}").contains("invalid model"));
    let e = ModelFile::load("no-such-model").unwrap_err();
    assert!(format!("{e:#}").contains("neither a file nor a built-in"));
}

#[test]
fn mat_records_read_and_refuse_garbage() {
    let rec = good_record();
    let y = rec.y_v.clone().unwrap();
    let bytes =
        host_tests::io::mat::write_v5(&[("time", &rec.t_s), ("uin", &rec.u_v), ("ymeas", &y)]);
    let r = host_tests::io::mat::parse_record(&bytes, "t=time,u=uin,y=ymeas").expect("mat parses");
    assert_eq!(r.t_s, rec.t_s);
    assert_eq!(r.u_v, rec.u_v);
    assert_eq!(r.y_v.as_deref(), Some(&y[..]));
    let e = host_tests::io::mat::parse_record(&bytes, "t=time,u=uin,y=nothere").unwrap_err();
    println!("missing var: {e:#}");
    assert!(format!("{e:#}").contains("nothere"));
    let e = host_tests::io::mat::parse_vars("t=a,u=b").unwrap_err();
    assert!(format!("{e:#}").contains("must name t, u and y"));
    // Mismatched lengths.
    let bytes2 = host_tests::io::mat::write_v5(&[("t", &rec.t_s), ("u", &rec.u_v[1..]), ("y", &y)]);
    let e = host_tests::io::mat::parse_record(&bytes2, "t=t,u=u,y=y").unwrap_err();
    println!("mismatched: {e:#}");
    assert!(format!("{e:#}").contains("different lengths"));
    // Truncated and random bytes never panic.
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    for cut in (0..bytes.len()).step_by(97) {
        let _ = host_tests::io::mat::parse_record(&bytes[..cut], "t=time,u=uin,y=ymeas");
    }
    for _ in 0..200 {
        let mut b = bytes.clone();
        for _ in 0..8 {
            let i = rng.gen_range(0..b.len());
            b[i] = rng.r#gen();
        }
        let _ = host_tests::io::mat::parse_record(&b, "t=time,u=uin,y=ymeas");
    }
}

#[test]
fn clean_record_gets_no_name_and_table_has_contract_keys() {
    let tr = truth(&[], 77);
    let dir = std::env::temp_dir().join(format!("piezo-gap-clean-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let paths = synthesise(&tr, &dir, 20.0);
    let data: Vec<Data> = gap::load_data(&paths, None).unwrap();
    let d = diagnose(
        &ModelFile::built_in("thesis-linear").unwrap(),
        &data,
        &Options::default(),
    )
    .unwrap();
    let j = d.to_json();
    println!("{}", d.table());
    for k in ["named", "steps", "noise_floor_v", "final_rms_v"] {
        assert!(j.get(k).is_some(), "JSON lacks {k}");
    }
    println!("noise floor {:.3} mV (truth 1 mV)", 1e3 * d.noise_floor_v);
    assert!((d.noise_floor_v - 1e-3).abs() < 0.1e-3);
    assert!(d.named.is_empty());
    // Never silent, and never crying wolf: a clean record leaves nothing unexplained.
    assert!(j["unexplained"].is_null(), "{}", j["unexplained"]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Never silent (issue #12, item 5): a 37 Hz line of 20 mV on the monitor (a pump's or a
/// building's vibration: no mains frequency, which would be taken out as the measurement's
/// interference, `gap::mains`), which no effect of the catalogue can make from the input,
/// stays in the residual; the JSON says so, with its size (the line's RMS, 14.1 mV, within
/// 20 %) and where it is (the line's frequency).
#[test]
fn a_residual_no_effect_explains_is_reported_as_unexplained() {
    let mut truth = ModelFile::built_in("thesis-linear").unwrap();
    truth.converters.noise_v = 1e-3;
    truth.converters.seed = 91;
    let stage = truth.build_stage().unwrap();
    let (t, u) = protocol::slow_input(1_000.0, 20.0);
    let y: Vec<f64> = simulate(&stage, truth.period_s, &t, &u)
        .iter()
        .zip(&t)
        .map(|(y, t)| y + 0.02 * (2.0 * std::f64::consts::PI * 37.0 * t).sin())
        .collect();
    let data =
        vec![Data::from_record("line.csv", Record::new(t, u, Some(y), None).unwrap()).unwrap()];
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let d = diagnose(&base, &data, &Options::default()).unwrap();
    println!("{}", d.table());
    let j = d.to_json();
    println!("unexplained: {}", j["unexplained"]);
    let un = d
        .unexplained
        .as_ref()
        .expect("the line must be reported as unexplained");
    let line_rms_v = 0.02 / std::f64::consts::SQRT_2;
    assert!(
        (un.rms_v - line_rms_v).abs() < 0.2 * line_rms_v,
        "unexplained {} V against the line's {line_rms_v} V",
        un.rms_v
    );
    assert!(un.where_.contains("37.0"), "{}", un.where_);
    assert!(j["unexplained"]["rms_v"].is_number() && j["unexplained"]["where"].is_string());
}

/// `truth`'s identification records (0.2 s at 50 kHz, 40 s at 1 kHz, its own noise and seed)
/// diagnosed from `thesis-linear`.
fn diagnose_from_thesis_linear(truth: &ModelFile) -> gap::Diagnosis {
    let stage = truth.build_stage().unwrap();
    let mut data = Vec::new();
    for (name, (t, u)) in [
        ("fast.csv", protocol::fast_input(50_000.0, 0.2)),
        ("slow.csv", protocol::slow_input(1_000.0, 40.0)),
    ] {
        let y = simulate(&stage, truth.period_s, &t, &u);
        data.push(Data::from_record(name, Record::new(t, u, Some(y), None).unwrap()).unwrap());
    }
    let base = ModelFile::built_in("thesis-linear").unwrap();
    diagnose(&base, &data, &Options::default()).unwrap()
}

/// The thesis' own Everett table alone (`thesis-full` without drift, K'(u), slew limit and
/// saturation; converters and 2.5 mV noise kept), diagnosed from `thesis-linear` on the
/// identification protocol: a Preisach-class table whose major loop is centred exactly on the
/// base's `0.79 u`, so a form the workflow claims to hold. With one split of the basis (each
/// centre band's relays less `clamp(u, band)`, four bands, a 0.5 V margin) the hysteresis
/// step left 121.5 mV (48x the floor) and a `nonlinear-gain` and a -356 mV `offset` the truth
/// lacks took it to 36.2 mV (14.4x). The records now choose between that split and one whose
/// elements leave out their own centre line over the records' span, on eleven bands with
/// edge relays (`everett::CentreLine`): they choose `Span`, and hysteresis alone ended at
/// 5.73 mV, 2.28x the floor, until that split's elements were cut along the span's triangle
/// (session 19: the relays with a threshold beyond the records' inputs in columns of their
/// own): 2.52 mV, 1.00x. Asserted: hysteresis alone named, final within 1.5x the floor (the
/// margin is the noise seed's; fails on the 2.28x before).
#[test]
fn the_thesis_table_alone_is_fitted_near_the_floor() {
    let mut truth = ModelFile::built_in("thesis-full").unwrap();
    truth.drift = None;
    truth.nonlinear_gain = None;
    truth.slew_rate_limit = None;
    truth.saturation = None;
    let d = diagnose_from_thesis_linear(&truth);
    println!("{}", d.table());
    assert_eq!(d.named, vec!["hysteresis".to_string()]);
    assert!(
        d.final_rms_v <= 1.5 * d.noise_floor_v,
        "final {:.2} mV, {:.1}x the floor",
        1e3 * d.final_rms_v,
        d.final_rms_v / d.noise_floor_v
    );
}

/// `thesis-full`'s slow effects (drift, hysteresis, nonlinear-gain) are named, and nothing
/// beyond what the stage has over `thesis-linear` (those, its slew limit and saturation).
fn assert_thesis_slow_effects_named(d: &gap::Diagnosis) {
    assert_thesis_stage_names(d, &["drift", "hysteresis", "nonlinear-gain"], "");
}

/// `required` of `thesis-full`'s effects are named, and nothing beyond what the stage has
/// over `thesis-linear` (its drift, hysteresis, nonlinear-gain, slew limit and saturation);
/// `case` opens the failure messages.
fn assert_thesis_stage_names(d: &gap::Diagnosis, required: &[&str], case: &str) {
    for e in required {
        assert!(
            d.named.iter().any(|n| n == e),
            "{case}{e} not named: {:?}",
            d.named
        );
    }
    let truth_effects = [
        "drift",
        "hysteresis",
        "nonlinear-gain",
        "slew-rate-limit",
        "saturation",
    ];
    assert!(
        d.named.iter().all(|n| truth_effects.contains(&n.as_str())),
        "{case}a name the truth lacks: {:?}",
        d.named
    );
}

/// The full thesis stage (`thesis-full`: Everett hysteresis, drift with its K(u), K'(u), slew
/// limit, saturation, 2.5 mV noise) diagnosed from `thesis-linear`: the three slow effects
/// must be named and kept, no effect the truth lacks named, and the gap must shrink to the
/// floor: measured 663 mV to 2.56 mV (259x, 1.02x the floor) with drift, hysteresis,
/// nonlinear-gain and the truth's slew limit (the records choose the `Span` split of the
/// basis, held levels tell the K'(u) curvature from a scale error,
/// `select::held_level_error`, and the drift's K(u) is held above a fitted knee, as the
/// truth's is above 6 V). Before the span's triangle and the slow effects' last refit
/// (session 19): 8.1 mV, 3.2x the floor; before the knee (session 15): 12.46 mV, 4.97x;
/// before the two splits: 42.1 mV, 16.8x, with a `sensor-gain` the truth lacks.
#[test]
fn full_thesis_stage_names_its_slow_effects() {
    let truth = ModelFile::built_in("thesis-full").unwrap();
    let d = diagnose_from_thesis_linear(&truth);
    println!("{}", d.table());
    let base_rms = d.steps.first().map_or(d.final_rms_v, |s| s.rms_before_v);
    println!(
        "thesis-full from thesis-linear: {:.1} mV -> {:.1} mV ({:.1}x), floor {:.2} mV",
        1e3 * base_rms,
        1e3 * d.final_rms_v,
        base_rms / d.final_rms_v,
        1e3 * d.noise_floor_v
    );
    // Issue #12 asks for drift, hysteresis and nonlinear-gain: the catalogue's split (the
    // table the loop about the base model's reversible map, `nonlinear-gain` the centre line's
    // curvature, `everett::HYST_FIT_REVERSIBLE`). Asserted: those three named, and a cut of
    // the residual of at least 10x (measured 259x, to 1.02x the floor; 82x before session 19;
    // 15.8x with one split of the basis; the play-sum form cut 5.4x; fitting the bands'
    // reversible slopes too cut 14.8x but took K'(u) into the table and never named
    // `nonlinear-gain`).
    assert_thesis_slow_effects_named(&d);
    assert!(
        d.final_rms_v * 10.0 <= base_rms,
        "cut only {:.1}x",
        base_rms / d.final_rms_v
    );
    // Issue #12's figure for the 150 s records (`thesis_full_150_s_records_end_near_the_floor`)
    // holds on these 40 s ones too: measured 1.02x; fails on the 3.2x before session 19.
    assert!(
        d.final_rms_v <= 1.5 * d.noise_floor_v,
        "final {:.1}x the floor",
        d.final_rms_v / d.noise_floor_v
    );
}

/// The full thesis stage on random levels, the protocol a lab reaches for first (`piezo synth
/// --protocol steps`): a stage that creeps and has a loop shows both in its holds, tails and
/// levels that sit apart by the direction of the step into them. The loop was admitted only
/// on flat holds, so such records named `drift` alone and ended at 41-55x the floor (session
/// 28, seeds 1 and 4-6 of the CLI, holds of 0.5 and 2 s); a drift in the model now owns the
/// tails. Three records from seeds no rule was read on, holds of 0.25, 0.8 and 3 s, three
/// spans and rates: drift and hysteresis named, nothing the stage lacks, and within the
/// issue's 2x of the floor for a single record (measured 1.26, 1.65 and 1.21x).
#[test]
fn the_thesis_stage_on_random_levels_names_its_loop_beside_its_drift() {
    thesis_stage_on_random_levels(&[
        // (seed, seconds, rate Hz, lowest input V, span V, hold s)
        (41, 15.0, 4_000.0, 0.5, 9.0, 0.25),
        (42, 30.0, 2_000.0, 0.0, 10.0, 0.8),
        (43, 45.0, 1_000.0, 1.5, 7.0, 3.0),
    ]);
}

/// The full thesis stage's record of `piezo synth --protocol steps` (one step from rest at
/// 0 V, then levels drawn over `offset + [0, amplitude]` V every `hold` s; without one, the
/// first level held to the end), `seconds` long at `rate` Hz, noise seed `seed`.
fn thesis_stage_steps(
    seed: u64,
    seconds: f64,
    rate: f64,
    (offset, amplitude): (f64, f64),
    hold: Option<f64>,
) -> Vec<Data> {
    use host_tests::sim::synth::{SynthSpec, synth};
    let spec = SynthSpec::steps(
        "thesis-full",
        (seed, seconds, rate),
        (offset, amplitude),
        hold,
    );
    vec![Data::from_record("steps.csv", synth(&spec).unwrap()).unwrap()]
}

/// The full thesis stage's random-levels records (`piezo synth --model thesis-full
/// --protocol steps`), one per case `(seed, seconds, rate Hz, lowest input V, span V, hold
/// s)`, each diagnosed alone from `thesis-linear`: drift and hysteresis named, nothing the
/// stage lacks, within the issue's 2x of the floor for a single record.
fn thesis_stage_on_random_levels(cases: &[(u64, f64, f64, f64, f64, f64)]) {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    for &(seed, seconds, rate, offset, amplitude, hold) in cases {
        let data = thesis_stage_steps(seed, seconds, rate, (offset, amplitude), Some(hold));
        let d = diagnose(&base, &data, &Options::default()).unwrap();
        let ratio = d.final_rms_v / d.noise_floor_v;
        println!(
            "seed {seed}: named {:?}, final {ratio:.2}x the floor",
            d.named
        );
        assert_thesis_stage_names(&d, &["drift", "hysteresis"], &format!("seed {seed}: "));
        assert!(ratio <= 2.0, "seed {seed}: final {ratio:.2}x the floor");
    }
}

/// The creep bound (`catalogue::implausible`, `CREEP_SHARE_MAX`) admits the thesis' own
/// creep (sec. 5.2: `G_drift(0) K(u)`, at most 22 % of the plant's static reading over its
/// 0-6 V range) with room for a stage that creeps twice as much, and refuses one that adds
/// more than half the stage's reading: on the identification protocol's 150 s records the
/// thesis' drift with its gains scaled by 2 is admitted, by 3 refused. It counts the lags the
/// records settle: on one 10 s sine the 12 s lag is a ramp, and the same creep is admitted.
#[test]
fn the_creep_bound_admits_the_thesis_creep_and_refuses_a_lag_as_large_as_the_stage() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let full = ModelFile::built_in("thesis-full").unwrap();
    let thesis_drift = full.drift.clone().expect("the thesis' drift");
    let with_gains = |k: f64| {
        let mut m = base.clone();
        let mut d = thesis_drift.clone();
        d.gains.iter_mut().for_each(|g| *g *= k);
        m.drift = Some(d);
        m
    };
    let long = protocol_data(&full, 150.0);
    for k in [1.0, 2.0] {
        let m = with_gains(k);
        assert_eq!(
            gap::catalogue::implausible(&m, &base, &long),
            None,
            "gains x{k}"
        );
    }
    let why = gap::catalogue::implausible(&with_gains(3.0), &base, &long).expect("x3 refused");
    assert!(why.contains("settled creep"), "{why}");
    let short = [thesis_full_sine(5_000.0)];
    assert_eq!(
        gap::catalogue::implausible(&with_gains(3.0), &base, &short),
        None
    );
    // (a drift the base already holds, unchanged, is the user's, not a fit's)
    let absurd = with_gains(3.0);
    assert_eq!(gap::catalogue::implausible(&absurd, &absurd, &long), None);
}

/// A step response, the record a lab makes first: the full thesis stage from rest at 0 V to
/// one level held for the whole 10 s record (session 64). Low steps (2-4.5 V) named nothing
/// at 46-70x the floor: the scale, the curvature and the offset each explained 67-68 % of
/// the residual, alike, so none was named, and the drift alone explained nothing (its
/// non-negative gains cannot take its tails beside a static level of the other sign). Now
/// the drift is fitted beside each look-alike as one step. One level cannot tell a scale
/// from a curvature, so a static shape named there must come with the pair it is a guess
/// between; without a reversal no loop is named. Measured: 2 V 0.99x, 4.5 V 1.06x (drift
/// and a shape, the pair said); 7 V drift alone at 3.69x (the look-alikes unnamed, said).
#[test]
fn a_step_response_names_its_creep_and_says_what_one_level_cannot_tell() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    // (seed, rate Hz, level V)
    for (seed, rate, level) in [(61, 5_000.0, 2.0), (62, 2_000.0, 4.5), (63, 5_000.0, 7.0)] {
        let data = thesis_stage_steps(seed, 10.0, rate, (0.0, level), None);
        let d = diagnose(&base, &data, &Options::default()).unwrap();
        let ratio = d.final_rms_v / d.noise_floor_v;
        println!(
            "{level} V: named {:?}, final {ratio:.2}x the floor",
            d.named
        );
        let table = d.table();
        assert!(d.named.iter().any(|n| n == "drift"), "{level} V\n{table}");
        assert!(
            !d.named.iter().any(|n| n == "hysteresis"),
            "{level} V\n{table}"
        );
        let shapes: Vec<&String> = d
            .named
            .iter()
            .filter(|n| ["offset", "sensor-gain", "nonlinear-gain"].contains(&n.as_str()))
            .collect();
        for n in &shapes {
            assert!(
                d.cannot_tell
                    .iter()
                    .any(|c| &&c.named == n || &&c.alternative == n),
                "{level} V: {n} named with no pair\n{table}"
            );
        }
        // (a shape named beside the creep takes the level: near the floor; none named, the
        // pair the records cannot tell is said instead)
        if shapes.is_empty() {
            assert!(!d.cannot_tell.is_empty(), "{level} V\n{table}");
        } else {
            assert!(ratio <= 1.5, "{level} V: {ratio:.2}x\n{table}");
        }
    }
}

/// The full thesis stage on random levels with few long holds (1.5-3 s), drawn after
/// session 29's two changes were made on other records (seeds 44 and 50): its rises went to
/// high levels, so no record's held levels could tell a loop from a static shape
/// (`Signatures::held_loop_untold`), and the loop was never admitted (seed 54: `drift` alone
/// at 69x the floor, seed 55 at 55x); K'(u) beside the drift's K took one round (seed 56:
/// 2.60x, its curvature missed). Measured after: 1.52, 1.00 and 1.01x with drift and
/// hysteresis named and nothing the stage lacks; the test asserts those and the issue's 2x
/// for a single record.
#[test]
fn the_thesis_stage_on_few_long_holds_names_its_loop() {
    thesis_stage_on_random_levels(&[
        // (seed, seconds, rate Hz, lowest input V, span V, hold s)
        (54, 24.0, 4_000.0, 1.0, 8.0, 3.0),
        (55, 16.0, 2_000.0, 0.5, 9.0, 1.6),
        (56, 30.0, 1_000.0, 0.0, 9.0, 1.5),
    ]);
}

/// Issue #12's requirement on the full thesis stage: its identification records (150 s slow
/// record, `piezo synth --model thesis-full --protocol identification --seconds 150`, noise
/// seeds 1-5) diagnosed from `thesis-linear` name drift, hysteresis and nonlinear-gain, no
/// effect the stage lacks, and end within 1.5x the floor. Measured 1.11-1.12x with the
/// stage's slew limit named too (session 19; 2.55-2.59x before the span's triangle and the
/// slow effects' last refit, each of which alone left it there). These records are the ones
/// the session's change was measured on, so this guards the figure; the hidden-effect and
/// families suites are the evidence that it is no fit to them alone.
#[test]
fn thesis_full_150_s_records_end_near_the_floor() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    for seed in 1..=5u64 {
        let data: Vec<Data> = protocol::synth_identification("thesis-full", seed, None, 150.0)
            .unwrap()
            .into_iter()
            .map(|(tag, rec)| Data::from_record(&format!("{tag}.csv"), rec).unwrap())
            .collect();
        let d = diagnose(&base, &data, &Options::default()).unwrap();
        let ratio = d.final_rms_v / d.noise_floor_v;
        println!(
            "seed {seed}: named {:?}, final {ratio:.2}x the floor",
            d.named
        );
        assert_thesis_slow_effects_named(&d);
        assert!(ratio <= 1.5, "seed {seed}: final {ratio:.2}x the floor");
    }
}

/// One 10 s record at 5 kHz of a 1 Hz sine over 0-9 V (the issue's real-record protocol) of
/// the full thesis stage, from `thesis-linear`: the drift, whose removal raised the residual
/// 2.6x in session 7, is a true effect and must stay (with the keep rule at 1000 variances it
/// was pruned and the record ended at 25x its floor). Measured in session 15: hysteresis,
/// drift and nonlinear-gain, 2.92 mV, 1.15x the floor. The record holds no level, so the
/// drift's K(u) is not fitted (`slow_fit::fit_slow`): with it, a K held above a knee took the
/// static curvature and `nonlinear-gain`, a true effect, was lost at 1.39x. Asserted: the
/// three named, nothing the truth lacks, and within 2x the floor (the issue's bound for a
/// single sine).
#[test]
fn a_sine_of_the_thesis_stage_keeps_its_drift() {
    let d = thesis_sine_diagnosed(thesis_full_sine(5_000.0));
    // A sine has no hold: the drift's evidence says so (it read "tails after steps up to
    // 0.0 mV during holds").
    let drift = d.steps.iter().find(|s| s.effect == "drift").unwrap();
    assert!(drift.evidence.starts_with("no hold"), "{}", drift.evidence);
}

/// A record averaged from a faster one (as `piezo gap` averages records beyond its samples
/// bound, `gap::data::decimate_to_fit`) is diagnosed as the record above, sampled at the
/// averaged rate, is: the same sine of the full thesis stage at 20 kHz, averaged by 4 to
/// 5 kHz, names the same three effects and ends within the same 2x of its floor (which the
/// average lowers by half). The simulations run on the input at 20 kHz and are averaged
/// alike; the workflow reads the averaged input's middle samples.
#[test]
fn an_averaged_record_is_read_as_one_sampled_slower() {
    let averaged = gap::data::decimated(&thesis_full_sine(20_000.0), 4);
    assert!((1.0 / averaged.period_s() - 5_000.0).abs() < 1e-6);
    thesis_sine_diagnosed(averaged);
}

/// 10 s of a 1 Hz sine over 0-9 V at `rate_hz` through the full thesis stage (its noise).
fn thesis_full_sine(rate_hz: f64) -> Data {
    let truth = ModelFile::built_in("thesis-full").unwrap();
    let stage = truth.build_stage().unwrap();
    let (t, u) = raised_cosine(rate_hz, 10.0, 1.0, 4.5, 4.5);
    let y = simulate(&stage, truth.period_s, &t, &u);
    Data::from_record("sine.csv", Record::new(t, u, Some(y), None).unwrap()).unwrap()
}

/// The sine record diagnosed from `thesis-linear`: the thesis stage's slow effects named,
/// nothing it lacks, within 2x the floor (the issue's bound for a single sine).
fn thesis_sine_diagnosed(record: Data) -> gap::Diagnosis {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let d = diagnose(&base, &[record], &Options::default()).unwrap();
    println!("{}", d.table());
    let ratio = d.final_rms_v / d.noise_floor_v;
    assert_thesis_slow_effects_named(&d);
    assert!(ratio <= 2.0, "final {ratio:.2}x the floor");
    d
}

/// Records of `truth` on the identification protocol (`slow_s` seconds of slow record), each
/// record with its own noise seed.
fn protocol_data(truth: &ModelFile, slow_s: f64) -> Vec<Data> {
    let mut data = Vec::new();
    for (i, (name, (t, u))) in [
        ("fast.csv", protocol::fast_input(50_000.0, 0.2)),
        ("slow.csv", protocol::slow_input(1_000.0, slow_s)),
    ]
    .into_iter()
    .enumerate()
    {
        let mut m = truth.clone();
        m.converters.seed = truth.converters.seed * 2 + i as u64;
        let stage = m.build_stage().unwrap();
        let y = simulate(&stage, m.period_s, &t, &u);
        data.push(Data::from_record(name, Record::new(t, u, Some(y), None).unwrap()).unwrap());
    }
    data
}

/// A monitor with a scale error and a zero error (a real lab's first two effects): both are
/// named, each alone and together, with their values within a few noise levels, and the
/// residual ends at the floor. The truth sets `[converters] sensor_gain` (not the effect's
/// table) and the offset through the stage's sensor.
#[test]
fn sensor_gain_and_offset_are_named() {
    let cases: [(&str, f64, f64); 3] = [
        ("offset", 1.0, 0.015),
        ("sensor-gain", 0.97, 0.0),
        ("both", 1.025, -0.02),
    ];
    for (i, (label, gain, offset_v)) in cases.into_iter().enumerate() {
        let mut truth = ModelFile::built_in("thesis-linear").unwrap();
        truth.converters.noise_v = 1e-3;
        truth.converters.seed = 40 + i as u64;
        truth.converters.sensor_gain = gain;
        if offset_v != 0.0 {
            truth.offset = Some(host_tests::io::model_file::OffsetSection { offset_v });
        }
        let data = protocol_data(&truth, 20.0);
        let base = ModelFile::built_in("thesis-linear").unwrap();
        let d = diagnose(&base, &data, &Options::default()).unwrap();
        println!("{label}: gain {gain}, offset {offset_v} V\n{}", d.table());
        let mut want: Vec<&str> = Vec::new();
        if gain != 1.0 {
            want.push("sensor-gain");
        }
        if offset_v != 0.0 {
            want.push("offset");
        }
        let mut named: Vec<&str> = d.named.iter().map(String::as_str).collect();
        named.sort();
        want.sort();
        assert_eq!(named, want, "{label}");
        let fitted_gain = d.model.sensor_gain.as_ref().map_or(1.0, |g| g.gain);
        let fitted_off = d.model.offset.as_ref().map_or(0.0, |o| o.offset_v);
        println!(
            "{label}: fitted gain {fitted_gain:.5} (truth {gain}), offset {:.3} mV (truth {:.3} mV)",
            1e3 * fitted_off,
            1e3 * offset_v
        );
        // One noise level over a few hundred thousand samples: the values come back to 1e-3
        // of the gain and to 0.2 mV of the offset (the noise's mean over the settled samples
        // is far smaller; the tolerance covers the ADC-free truth's f32 arithmetic).
        assert!(
            (fitted_gain - gain).abs() < 1e-3,
            "{label}: gain {fitted_gain}"
        );
        assert!(
            (fitted_off - offset_v).abs() < 2e-4,
            "{label}: offset {fitted_off}"
        );
        assert!(
            d.final_rms_v <= 1.5 * d.noise_floor_v,
            "{label}: final {:.2} mV, floor {:.2} mV",
            1e3 * d.final_rms_v,
            1e3 * d.noise_floor_v
        );
    }
}

/// A base model with slow effects of its own (the lab's `thesis-full`, or a model an earlier
/// diagnosis wrote) is held as it is given: a step names what the records add to it, and a
/// refit of the base's table, drift or K'(u) that no step names does not take that work
/// (GAP.md, session 55). Before, every candidate refitted the base's slow effects beside
/// it: a 20 mV sensor offset went into a refitted table (fitted at 164 mV, then taken out
/// as a level the records do not show) and nothing was named, at 1.59x the floor; a K'(u)
/// half the thesis' was taken up by such refits, nothing named, at 1.50x and 1.29x. The
/// truths are the thesis stage with one thing changed; the records a 1 Hz sine over 0-9 V
/// (10 s at 5 kHz) and a 0.5-50 Hz chirp over 1-9 V (8 s at 20 kHz), the thesis' noise.
#[test]
fn a_base_with_slow_effects_of_its_own_is_held_as_given() {
    let base = ModelFile::built_in("thesis-full").unwrap();
    let record = |truth: &ModelFile, seed: u64, (t, u): (Vec<f64>, Vec<f64>)| {
        let mut m = truth.clone();
        m.converters.seed = seed;
        let y = simulate(&m.build_stage().unwrap(), m.period_s, &t, &u);
        vec![Data::from_record("record.csv", Record::new(t, u, Some(y), None).unwrap()).unwrap()]
    };
    let sine = || raised_cosine(5_000.0, 10.0, 1.0, 4.5, 4.5);
    let chirp = || {
        let (rate_hz, seconds, f0, f1) = (20_000.0, 8.0, 0.5, 50.0);
        let t: Vec<f64> = (0..(seconds * rate_hz) as usize)
            .map(|i| i as f64 / rate_hz)
            .collect();
        let u = t
            .iter()
            .map(|&x| {
                let phase = f0 * x + 0.5 * (f1 - f0) * x * x / seconds;
                5.0 - 4.0 * (2.0 * std::f64::consts::PI * phase).cos()
            })
            .collect();
        (t, u)
    };
    let diagnosed_from = |base: &ModelFile, label: &str, data: &[Data]| {
        let d = diagnose(base, data, &Options::default()).unwrap();
        println!("{label}\n{}", d.table());
        let mut named: Vec<String> = d.named.clone();
        named.sort();
        // (the thesis' noise is white: a model that holds what the records add ends at the
        // floor; 1.2x leaves room for the floor's estimate, not for a misfit)
        let ratio = d.final_rms_v / d.noise_floor_v;
        assert!(ratio <= 1.2, "{label}: final {ratio:.2}x the floor");
        (named, d)
    };
    let diagnosed = |label: &str, data: &[Data]| diagnosed_from(&base, label, data);
    // The stage as the base gives it: nothing to name.
    let (named, _) = diagnosed("the base's own stage", &record(&base, 71, sine()));
    assert!(named.is_empty(), "the base's own stage: named {named:?}");
    // A sensor offset: named, at its value (noise of 2.5 mV over 50 000 samples; the
    // tolerance covers the table's f32 grid and the ADC's codes), from `thesis-full` and from
    // a base with a sensor scale of its own (not held: it scales the others in the stage;
    // before, that diagnosis was refused: a split's fit came out NaN).
    let mut scaled = base.clone();
    scaled.sensor_gain = Some(host_tests::io::model_file::SensorGainSection { gain: 1.02 });
    for (label, from, seed) in [
        ("a 20 mV offset", &base, 72),
        ("a scaled base", &scaled, 74),
    ] {
        let mut truth = from.clone();
        truth.offset = Some(host_tests::io::model_file::OffsetSection { offset_v: 0.02 });
        let (named, d) = diagnosed_from(from, label, &record(&truth, seed, sine()));
        assert_eq!(named, ["offset"], "{label}");
        let offset_v = d.model.offset.as_ref().map_or(0.0, |o| o.offset_v);
        assert!(
            (offset_v - 0.02).abs() < 1e-3,
            "{label}: offset {:.2} mV for 20 mV",
            1e3 * offset_v
        );
    }
    // K'(u) half the thesis', on the chirp: the base's own K'(u) refitted and named, its
    // terms within a few per cent (they came back to 1e-3 of them).
    let mut truth = base.clone();
    let gain = truth.nonlinear_gain.as_mut().unwrap();
    gain.poly[1] = 0.01;
    gain.poly[2] = -0.0005;
    let (named, d) = diagnosed("K'(u) halved", &record(&truth, 73, chirp()));
    assert_eq!(named, ["nonlinear-gain"], "K'(u) halved");
    let poly = d.model.nonlinear_gain.as_ref().unwrap().poly;
    assert!(
        (poly[1] - 0.01).abs() < 5e-4 && (poly[2] + 0.0005).abs() < 5e-5,
        "K'(u) terms {:.4e}, {:.4e} for 1e-2, -5e-4",
        poly[1],
        poly[2]
    );
}

/// A Prandtl-Ishlinskii truth with its own radii (not the catalogue's): operators of radii
/// `radii_v` and weights `weights` (input volts per volt), started at `z0` (positions, input
/// volts; `None`: at the first input), applied to `u` before the linear stage.
fn pi_predistort(u: &[f64], radii_v: &[f64], weights: &[f64], z0: Option<&[f64]>) -> Vec<f64> {
    let mut z: Vec<f64> = match z0 {
        Some(z) => z.to_vec(),
        None => vec![u[0]; radii_v.len()],
    };
    u.iter()
        .map(|&x| {
            let mut h = 0.0;
            for ((zi, r), w) in z.iter_mut().zip(radii_v).zip(weights) {
                *zi = zi.max(x - r).min(x + r);
                h += w * (*zi - x);
            }
            x + h
        })
        .collect()
}

/// The seeds of the single-sine requirement's run (`--ignored`): the two the guard runs and
/// six more, new in session 21 (not held out since: that session's choice of pairing the
/// static shapes with an offset only was made on seeds 23 and 27).
const SINGLE_SINE_SEEDS: [u64; 8] = [21, 22, 23, 24, 25, 26, 27, 28];

/// A Prandtl-Ishlinskii truth for the single-sine record: ten operators with radii drawn
/// log-uniformly over 0.02..5 V and raw weights over 0.2..1, scaled so that the loop on the
/// 0.5..9.5 V sine is a drawn 10-15 % of the input span. Returns (radii, weights, share).
///
/// The issue asks for a Preisach-class truth: `u + sum w_i (z_i - u)` is one only while the
/// weights sum to less than 1 (its slope just after a reversal is `1 - sum w_i`, the
/// density on the Preisach plane's diagonal); a draw whose narrow operators need weights
/// beyond that to make the loop's height runs backwards after every reversal, which no
/// Preisach density does, and is drawn again (from the same generator). Before session 21
/// such draws were kept: seed 22's truth summed to 1.026.
fn draw_preisach_pi(rng: &mut rand::rngs::StdRng) -> (Vec<f64>, Vec<f64>, f64) {
    let k = 10;
    loop {
        let mut radii_v: Vec<f64> = (0..k)
            .map(|_| (0.02f64.ln() + (5.0f64.ln() - 0.02f64.ln()) * rng.r#gen::<f64>()).exp())
            .collect();
        radii_v.sort_by(f64::total_cmp);
        let raw: Vec<f64> = (0..k).map(|_| rng.gen_range(0.2..1.0)).collect();
        // Loop height on this sine: 2 sum w_i min(r_i, 4.5) input volts; scaled to the drawn
        // share of the 9 V input span.
        let share = rng.gen_range(0.10..0.15);
        let h: f64 = raw
            .iter()
            .zip(&radii_v)
            .map(|(w, r)| 2.0 * w * r.min(4.5))
            .sum();
        let weights: Vec<f64> = raw.iter().map(|w| w * share * 9.0 / h).collect();
        if weights.iter().sum::<f64>() < 1.0 {
            return (radii_v, weights, share);
        }
    }
}

/// Issue #12's single-sine record: 10 s at 5 kHz of a 1 Hz sine over most of the range
/// (0.5..9.5 V), a Prandtl-Ishlinskii hysteresis with random radii (a Preisach-class truth of
/// another shape than the catalogue's radii), a loop of 10-15 % of the input span, started
/// with every operator centred on the first input (not on the major curve), and a sensor
/// offset, 1 mV noise. Returns per seed the names given, the final residual over the floor,
/// and the diagnosed and the true sensor offsets (volts; the diagnosed one 0 where the model
/// has none).
fn single_sine_outcomes(seeds: &[u64]) -> Vec<SineOutcome> {
    let (t, u) = raised_cosine(5_000.0, 10.0, 1.0, 5.0, 4.5);
    let mut results = Vec::new();
    for &seed in seeds {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let (radii_v, weights, share) = draw_preisach_pi(&mut rng);
        let offset_v = rng.gen_range(0.01..0.03) * if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
        let mut truth = ModelFile::built_in("thesis-linear").unwrap();
        truth.converters.noise_v = 1e-3;
        truth.converters.seed = seed;
        truth.offset = Some(host_tests::io::model_file::OffsetSection { offset_v });
        let stage = truth.build_stage().unwrap();
        let y = simulate(
            &stage,
            truth.period_s,
            &t,
            &pi_predistort(&u, &radii_v, &weights, None),
        );
        let data = vec![
            Data::from_record(
                "sine.csv",
                Record::new(t.clone(), u.clone(), Some(y), None).unwrap(),
            )
            .unwrap(),
        ];
        let base = ModelFile::built_in("thesis-linear").unwrap();
        let d = diagnose(&base, &data, &Options::default()).unwrap();
        println!(
            "seed {seed}: truth radii {radii_v:.3?} weights {weights:.4?} (sum {:.3}; loop {:.0} % of the span), offset {:.1} mV\n{}",
            weights.iter().sum::<f64>(),
            100.0 * share,
            1e3 * offset_v,
            d.table()
        );
        // The same residual after the first cycle (the input has then visited both of its
        // extremes, which wipes out the start memory of every relay it can switch): how much
        // of the figure is the start.
        let y_fit = gap::sim(&d.model, &data[0]).unwrap();
        let tail: Vec<usize> = (0..t.len()).filter(|&i| t[i] >= 1.0).collect();
        let tail_rms = (tail
            .iter()
            .map(|&i| (data[0].y_v[i] - y_fit[i]).powi(2))
            .sum::<f64>()
            / tail.len() as f64)
            .sqrt();
        println!(
            "seed {seed}: after the first cycle {:.2}x the floor",
            tail_rms / d.noise_floor_v
        );
        if std::env::var("GAP_DEBUG").is_ok() {
            for (i, t) in d.tried.iter().enumerate() {
                println!("seed {seed}: tried at step {}: {t:?}", i + 1);
            }
            for c in &d.cannot_tell {
                println!("seed {seed}: cannot tell {c:?}");
            }
        }
        results.push(SineOutcome {
            seed,
            named: d.named.clone(),
            ratio: d.final_rms_v / d.noise_floor_v,
            offset_v: d.model.offset.as_ref().map_or(0.0, |o| o.offset_v),
            truth_offset_v: offset_v,
        });
    }
    for o in &results {
        println!(
            "seed {}: named {:?}, final {:.2}x the floor, offset {:.1} mV (truth {:.1} mV)",
            o.seed,
            o.named,
            o.ratio,
            1e3 * o.offset_v,
            1e3 * o.truth_offset_v
        );
    }
    results
}

/// One single-sine record's outcome ([`single_sine_outcomes`]).
struct SineOutcome {
    seed: u64,
    named: Vec<String>,
    ratio: f64,
    offset_v: f64,
    truth_offset_v: f64,
}

/// What the workflow achieves on the single-sine records today: hysteresis and offset named,
/// the offset of the truth's sign and within half its size, within a bound per seed on the
/// residual. Session 48 (step 13a: the table's level at the demagnetised start the start search
/// finds is read as the sensor's offset): seed 21 hysteresis and a 19.3 mV offset (truth 25.5)
/// at 1.93x, seed 22 and 20.0 mV (truth 21.3) at 1.30x, the same residuals as before (the
/// move reads the same). Measured since session 30 (eleven bands along the centre axis for the band and rise splits, was four:
/// `everett::HYST_BANDS_BAND`): seed 21 hysteresis alone at 1.93x, seed 22 at 1.30x; the
/// offsets still not named (the scale, the curvature and the drift explain alike beside the
/// table: reported as pairs). The bounds fail on four bands (4.88x on seed 21). Session 25 (a drift that explains alike to the static shapes goes with them when no record
/// holds, instead of being named in their place): seed 21 hysteresis alone at 4.88x, seed
/// 22 hysteresis alone at 1.34x (the issue's 2x), the 25.5 and 21.3 mV offsets not named and
/// reported, with the scale, the curvature and the drift, as ones the records cannot tell.
/// Session 24 (the rise split): 1.66x (hysteresis and a false `nonlinear-gain` swapped in
/// for a drift named in the look-alikes' place) and 1.34x. Session 21: 3.24x (hysteresis
/// and offset, 26.9 mV for the truth's 25.5 mV; 1.79x after the
/// first cycle) and 4.92x (hysteresis alone: the true 21.3 mV offset is fitted at 30.8 mV and
/// removed by the final check, the residual without it sitting only 2.3 mV off zero; 3.15x
/// after the first cycle). The history on the two seeds as drawn before session 21 (seed 22
/// then a truth outside the Preisach class): session 16's start search (three candidates
/// refitted on a single record) 3.24x and 6.78x, from 7.2x; before static shapes that
/// explain alike were left unnamed, 3.3x and 3.8x (the second with a `nonlinear-gain` the
/// truth lacks) with the start candidate's depth refined; 10.6x and 9.0x with the candidates
/// alone; with the fixed geometric radii before the basis followed the table 14.7x, and 6.2x
/// with `nonlinear-gain`; with the bands' reversible slopes fitted 7.1x and 6.3x, but the
/// families suite lost 11 points of exact names; without a start memory and with the table
/// ending at the records' extremes 33x and 26x.
#[test]
fn single_sine_record_names_hysteresis_and_its_start() {
    // (seed, bound on the final residual over the floor: the measured figure with a margin
    // of about a seventh (1.93x and 1.30x in session 30))
    let bounds = [(21, 2.2), (22, 1.5)];
    let outcomes = single_sine_outcomes(&bounds.map(|b| b.0));
    for (o, (_, bound)) in outcomes.into_iter().zip(bounds) {
        let seed = o.seed;
        let mut named = o.named.clone();
        named.sort();
        assert_eq!(named, ["hysteresis", "offset"], "seed {seed}");
        // The offset read from the table's level at the demagnetised start (step 13a): the
        // truth's sign and size within half of it (measured in session 48: 19.3 mV for 25.5,
        // 20.0 mV for 21.3; over the eight seeds of the ignored requirement 7.0-29.4 mV for
        // 13.5-29.6, one of them 48 % off). The table's fit at the record's head sets it.
        assert!(
            (o.offset_v - o.truth_offset_v).abs() <= 0.5 * o.truth_offset_v.abs(),
            "seed {seed}: offset {:.1} mV for the truth's {:.1} mV",
            1e3 * o.offset_v,
            1e3 * o.truth_offset_v
        );
        assert!(
            o.ratio <= bound,
            "seed {seed}: final {:.2}x the floor (bound {bound}x)",
            o.ratio
        );
    }
}

/// Issue #12's requirement on the single-sine record: hysteresis and offset named, the
/// residual within 2x its floor, on eight seeds. Not met yet. Session 54 (after step 19 of
/// session 53): 23 and 26 at 1.95x and 1.87x with hysteresis alone; on the fresh seeds 31-46
/// (`SINE_SEEDS`) 9 of 16 met (GAP.md, session 54). Session 48 (step 13a): met on
/// six of eight (21, 22, 24, 25, 27, 28: hysteresis and offset, 1.30-1.99x, offsets 7.0-29.4
/// mV of the truths' sign for 13.5-29.6 mV); 23 and 26 end at 2.29x and 2.43x with hysteresis
/// alone (the model leaves an `unexplained` part there, so step 13a does not read the table's
/// level: without that condition it names their offsets too, 16.6 and 20.5 mV for 23.9 and
/// 29.6). What is left is the basis' resolution: operators narrower than half a grid interval
/// (0.11 V; six of seed 23's ten). Session 30 (eleven bands):
/// hysteresis alone on all eight, no false name, final 1.30-2.43x the floor, under 2x on six
/// (21, 22, 24, 25, 27, 28); the offset named on none (the look-alikes as before). Session 25: hysteresis alone on
/// all eight, no false name, final 1.34-5.76x the floor (median 4.8x), under 2x on 22 only;
/// the offset, the scale, the curvature and the drift each explain alike beside the table
/// (reported as pairs the records cannot tell; the offset also by the standing note that no
/// record rests at 0 V). Session 24 (the rise split):
/// final 1.27-5.76x the floor (median 3.5x), under 2x on 21, 22 and 24, the offset named on
/// none (the static shapes explain alike beside the table: none named, or `nonlinear-gain`
/// through a swap for a drift on 21 and 24); hysteresis and drift alone leave 1.7-25 noise
/// variances (1.2-5.0x), and what the final check then drops is that level. `SINE_SEEDS=21,27`
/// runs some seeds, `GAP_DEBUG=1` prints the candidates tried at each step. Before (session
/// 21: offset named on 3
/// of 8, final 2.99-7.05x the floor, median 4.9x, a `sensor-gain` the truth lacks on seed 23;
/// after the first cycle 1.43-4.39x): the
/// truth's start, every operator centred on the first input at the sine's bottom, needs a
/// history below the table's range, and operators narrower than the table's first radius
/// (half a grid interval, 0.11 V) are smeared over it. Run with `--ignored`; it prints every
/// seed's outcome before it fails.
#[test]
#[ignore = "issue #12: not met yet (hysteresis and offset on 6 of 8 seeds; 23 and 26 name hysteresis alone at 1.95x and 1.87x; 9 of 16 on seeds 31-46)"]
fn single_sine_record_names_hysteresis_and_offset() {
    let seeds: Vec<u64> = std::env::var("SINE_SEEDS").map_or(SINGLE_SINE_SEEDS.to_vec(), |s| {
        s.split(',').map(|x| x.parse().unwrap()).collect()
    });
    let outcomes = single_sine_outcomes(&seeds);
    let failed: Vec<String> = outcomes
        .iter()
        .filter(|o| {
            let mut named = o.named.clone();
            named.sort();
            named != ["hysteresis", "offset"] || o.ratio > 2.0
        })
        .map(|o| format!("seed {}: {:?} at {:.2}x", o.seed, o.named, o.ratio))
        .collect();
    assert!(
        failed.is_empty(),
        "{} of {} seeds miss: {}",
        failed.len(),
        outcomes.len(),
        failed.join("; ")
    );
}

/// `piezo gap --json` on a clean record exits 0 with `"unexplained": null` (the verb's check
/// that every figure is finite must not take the designed null for a NaN).
#[test]
fn gap_verb_on_a_clean_record_exits_0_with_unexplained_null() {
    let dir = std::env::temp_dir().join(format!("piezo-gap-verb-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let rec = dir.join("clean.csv");
    let piezo = env!("CARGO_BIN_EXE_piezo");
    let synth = std::process::Command::new(piezo)
        .args(["synth", "--model", "thesis-linear", "--protocol", "steps"])
        .args([
            "--seconds",
            "5",
            "--rate",
            "5000",
            "--noise-v",
            "0.001",
            "--output",
        ])
        .arg(&rec)
        .output()
        .unwrap();
    assert!(
        synth.status.success(),
        "{}",
        String::from_utf8_lossy(&synth.stderr)
    );
    let out = std::process::Command::new(piezo)
        .args(["gap", "--model", "thesis-linear", "--json", "--data"])
        .arg(&rec)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    assert!(j["unexplained"].is_null());
    assert!(j["final_rms_v"].as_f64().is_some_and(f64::is_finite));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `seconds` of `mid_v - amp_v cos(2 pi freq_hz t)` sampled at `rate_hz`: (t, u).
fn raised_cosine(
    rate_hz: f64,
    seconds: f64,
    freq_hz: f64,
    mid_v: f64,
    amp_v: f64,
) -> (Vec<f64>, Vec<f64>) {
    let t: Vec<f64> = (0..(seconds * rate_hz) as usize)
        .map(|i| i as f64 / rate_hz)
        .collect();
    let u = t
        .iter()
        .map(|&x| mid_v - amp_v * (2.0 * std::f64::consts::PI * freq_hz * x).cos())
        .collect();
    (t, u)
}

/// `thesis-linear` with 1 mV of noise (seed `seed`) and a drift of three lags, K(u) = 1.
fn linear_with_drift(seed: u64, gains: [f64; 3], taus_s: [f64; 3]) -> ModelFile {
    let mut m = ModelFile::built_in("thesis-linear").unwrap();
    m.converters.noise_v = 1e-3;
    m.converters.seed = seed;
    m.drift = Some(host_tests::io::model_file::DriftSection {
        gains,
        taus_s,
        poly: [1.0, 0.0, 0.0, 0.0],
        poly_range_v: [0.0, 10.0],
        unsettled_v: None,
    });
    m
}

/// Issue #12 item 1: without holds, a drift and a hysteresis loop both shape a slow periodic
/// residual, so the workflow fits the other in the named one's place and says when it cannot
/// tell them apart ([`gap::CannotTell`], `"cannot_tell"` in the JSON). On one 20 s, 0.2 Hz sine
/// at 1 kHz the two are told apart both ways, so no note may pair them: a drift lag (0.8 s, 8 %
/// of the step; measured 1.00 mV, the floor, against 16.9 mV for hysteresis and a sensor gain
/// in its place) is named `drift` alone, and a Bouc-Wen loop (measured 1.09 mV against
/// 115 mV for a drift in its place) `hysteresis` alone. (The note is for records where both
/// forms miss alike, as on a real stage whose creep and loop are neither form.)
#[test]
fn single_sine_tells_drift_from_hysteresis() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let (t, u) = raised_cosine(1_000.0, 20.0, 0.2, 5.0, 4.0);
    let drift = linear_with_drift(31, [0.08, 0.0, 0.0], [0.8, 10.0, 100.0]);
    let bouc_wen = Truth {
        effects: vec!["hysteresis".into()],
        creep: None,
        bouc_wen: Some((0.2, 1.0, 0.2)),
        gain: None,
        slew_v_per_s: None,
        delay_s: None,
        mode: None,
        seed: 31,
    };
    let cases = [
        ("drift", drift, u.clone()),
        (
            "hysteresis",
            truth_model(&bouc_wen),
            predistort(&bouc_wen, &t, &u),
        ),
    ];
    for (effect, model, u_stage) in cases {
        let stage = model.build_stage().unwrap();
        let y = simulate(&stage, model.period_s, &t, &u_stage);
        let rec = Record::new(t.clone(), u.clone(), Some(y), None).unwrap();
        let d = diagnose(
            &base,
            &[Data::from_record("sine.csv", rec).unwrap()],
            &Options::default(),
        )
        .unwrap();
        println!("{}", d.table());
        assert_eq!(d.named, [effect]);
        // No pair of drift and a loop; the one note a table may carry is the standing one on
        // the offset (no record rests at 0 V, so a sensor offset is not told from the table's
        // constant), which the drift alone, with no table, does not get.
        let allowed = |c: &gap::CannotTell| {
            effect == "hysteresis"
                && c.named == "hysteresis"
                && c.alternative == "offset"
                && c.why.starts_with(gap::STANDING_OFFSET_NOTE)
        };
        assert!(d.cannot_tell.iter().all(allowed), "{:?}", d.cannot_tell);
        assert!(
            d.to_json()["cannot_tell"]
                .as_array()
                .is_some_and(|a| a.len() == d.cannot_tell.len())
        );
        assert!(d.final_rms_v < 1.5 * d.noise_floor_v, "{}", d.final_rms_v);
    }
}

/// A lab that records the amplifier's input through a converter gets an input with noise: a
/// held level wanders by a few tenths of a millivolt. Holds must still be found (within
/// `HOLD_BAND_SIGMAS` of the input's own noise), so the drift's evidence (its tails during
/// holds), the report's tail plots and the cannot-tell check see what they see on the exact
/// command: random levels held 0.5-2 s for 30 s at 1 kHz, a drift of two lags (0.15 s and
/// 2.5 s), the recorded input with 0.3 mV of noise (the stage saw the exact levels). Before
/// the band, the noisy record had no hold and its drift's evidence read "tails after steps up
/// to 0.0 mV during holds".
#[test]
fn drift_is_named_when_the_recorded_input_is_noisy() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let rate_hz = 1_000.0;
    let mut rng = rand::rngs::StdRng::seed_from_u64(41);
    let n = (30.0 * rate_hz) as usize;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / rate_hz).collect();
    let mut u = Vec::with_capacity(n);
    while u.len() < n {
        let level = rng.gen_range(0.5..9.5);
        let hold = (rng.gen_range(0.5..2.0) * rate_hz) as usize;
        u.extend(std::iter::repeat_n(level, hold.min(n - u.len())));
    }
    let truth = linear_with_drift(41, [0.04, 0.05, 0.0], [0.15, 2.5, 100.0]);
    let stage = truth.build_stage().unwrap();
    let y = simulate(&stage, truth.period_s, &t, &u);
    let noisy: Vec<f64> = u
        .iter()
        .map(|v| {
            // Gaussian by Box-Muller, 0.3 mV.
            let (a, b): (f64, f64) = (rng.r#gen::<f64>().max(1e-300), rng.r#gen());
            v + 3e-4 * (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
        })
        .collect();
    let mut outcomes = Vec::new();
    for (what, u_rec) in [("exact input", &u), ("noisy input", &noisy)] {
        let rec = Record::new(t.clone(), u_rec.clone(), Some(y.clone()), None).unwrap();
        let data = Data::from_record("levels.csv", rec).unwrap();
        let holds = data.holds().len();
        let d = diagnose(&base, &[data], &Options::default()).unwrap();
        let ratio = d.final_rms_v / d.noise_floor_v;
        println!(
            "{what}: {holds} holds, named {:?}, final {ratio:.2}x the floor, cannot tell: {:?}",
            d.named, d.cannot_tell
        );
        let evidence = d
            .steps
            .iter()
            .find(|s| s.effect == "drift" && !s.removed)
            .map(|s| s.evidence.clone())
            .unwrap_or_default();
        println!("{what}: drift evidence: {evidence}");
        outcomes.push((holds, d.named.clone(), ratio, evidence));
    }
    let (exact_holds, exact_named, _, exact_evidence) = &outcomes[0];
    let (noisy_holds, noisy_named, noisy_ratio, noisy_evidence) = &outcomes[1];
    let tails = |e: &str| e.split(';').next().unwrap_or("").to_string();
    assert_eq!(tails(noisy_evidence), tails(exact_evidence));
    assert!(*exact_holds >= 10, "{exact_holds}");
    assert_eq!(noisy_holds, exact_holds, "the same holds found");
    assert_eq!(exact_named, &["drift"]);
    assert_eq!(noisy_named, exact_named);
    assert!(*noisy_ratio <= 1.5, "{noisy_ratio}");
}

/// The full thesis stage with sensor offsets drawn at random (10-60 mV, either sign), on the
/// identification protocol (40 s slow record), from `thesis-linear`. Both records start at
/// rest at 0 V, where no catalogued effect but an offset moves the sensor (GAP.md, session
/// 22). Two draws: seeds 31-36 (rng 2611), drawn after the rest's evidence in the final check
/// was made on the four offsets of [`thesis_stage_with_a_sensor_offset_ends_near_the_floor`]
/// (its negatives then went unnamed here, which shaped the naming rule that followed), and
/// seeds 41-46 (rng 2612), drawn before that rule was run on them. Asserted: the thesis'
/// three slow effects and the offset named, nothing the truth lacks, the offset within 5 mV
/// of the truth (two noise floors), the residual within 1.5x the floor (the issue's bar for
/// `thesis-full`). Measured on 41-46 when drawn: +45.1, +22.2, +23.5, -45.7, -28.8 and
/// +49.9 mV fitted at +46.7, +22.4, +24.9, -44.3, -27.4 and +48.5 mV, 1.01-1.05x the floor.
#[test]
fn thesis_stage_offsets_drawn_at_random() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let mut cases = Vec::new();
    for (rng_seed, seeds) in [(2611u64, 31u64..=36), (2612, 41..=46)] {
        let mut rng = rand::rngs::StdRng::seed_from_u64(rng_seed);
        for seed in seeds {
            let size_v = rng.gen_range(0.01..0.06);
            let sign = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
            cases.push((seed, size_v * sign));
        }
    }
    let mut outcomes = Vec::new();
    for (seed, offset_v) in cases {
        let mut truth = ModelFile::built_in("thesis-full").unwrap();
        truth.converters.seed = seed;
        truth.offset = Some(host_tests::io::model_file::OffsetSection { offset_v });
        let d = diagnose(&base, &protocol_data(&truth, 40.0), &Options::default()).unwrap();
        let ratio = d.final_rms_v / d.noise_floor_v;
        let fitted_v = d.model.offset.as_ref().map(|o| o.offset_v);
        println!(
            "offset {:+.1} mV (seed {seed}): named {:?}, fitted {}, final {ratio:.2}x the floor",
            1e3 * offset_v,
            d.named,
            fitted_v.map_or("none".to_string(), |v| format!("{:+.1} mV", 1e3 * v))
        );
        outcomes.push((offset_v, d.named.clone(), ratio, fitted_v));
    }
    let named = outcomes.iter().filter(|o| o.3.is_some()).count();
    println!("offset named on {named} of {}", outcomes.len());
    for (offset_v, named, ratio, fitted_v) in &outcomes {
        let at = format!("offset {:+.1} mV", 1e3 * offset_v);
        assert_thesis_stage_with_offset_named(&at, named, *ratio, *fitted_v, *offset_v);
    }
}

/// The full thesis stage with a sensor offset of another size than the demo's (issue #12
/// item 3: an offset is the first effect a real lab meets), on the identification protocol
/// (40 s slow record), from `thesis-linear`: the thesis' three slow effects and the offset
/// named (within 5 mV, two noise floors), nothing the truth lacks, and the residual within
/// 1.5x the floor (5x until session 22). Before session 21 the offsets of
/// +30 and +60 mV ended at 19.5x and 19.2x with drift and hysteresis alone: `nonlinear-gain`
/// and `sensor-gain` explained 82-85 % of the pooled residual each and neither was named,
/// though the records told them apart one by one. Measured in session 21: +18 mV 1.51x, +30 mV 2.18x,
/// -25 mV 1.08x, +60 mV 4.14x, each with drift, hysteresis, nonlinear-gain and the slew
/// limit; the offset itself was not named (the fitted table's constant takes it up, GAP.md),
/// and where it was 30 mV or more the table said it cannot tell it from that constant
/// (fitted at 33.2 and 59.0 mV for +30 and +60 mV).
/// These offsets and seeds were drawn after the change was made on the demo's records
/// shifted by +12 and +30 mV. Since session 22 the records' rest at 0 V input shows the
/// offset (GAP.md): +18, +30 and +60 mV named at 20.3, 31.0 and 58.4 mV in the final check,
/// and -25 mV, which the table's own constant at rest took up, by the reading at rest, at
/// -24.3 mV (1.02-1.04x). Session 22 was shaped on these four, so
/// [`thesis_stage_offsets_drawn_at_random`] holds the evidence on offsets drawn after it.
#[test]
fn thesis_stage_with_a_sensor_offset_ends_near_the_floor() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let mut outcomes = Vec::new();
    for (seed, offset_v) in [(7u64, 0.018), (8, 0.030), (9, -0.025), (10, 0.060)] {
        let mut truth = ModelFile::built_in("thesis-full").unwrap();
        truth.converters.seed = seed;
        truth.offset = Some(host_tests::io::model_file::OffsetSection { offset_v });
        let d = diagnose(&base, &protocol_data(&truth, 40.0), &Options::default()).unwrap();
        let ratio = d.final_rms_v / d.noise_floor_v;
        println!(
            "offset {:+.0} mV (seed {seed}): named {:?}, final {ratio:.2}x the floor\n{}",
            1e3 * offset_v,
            d.named,
            d.table()
        );
        let fitted_v = d.model.offset.as_ref().map(|o| o.offset_v);
        outcomes.push((offset_v, d.named.clone(), ratio, fitted_v));
    }
    for (offset_v, named, ratio, _) in &outcomes {
        println!(
            "offset {:+.0} mV: named {named:?}, final {ratio:.2}x the floor",
            1e3 * offset_v
        );
    }
    for (offset_v, named, ratio, fitted_v) in &outcomes {
        let at = format!("offset {:+.0} mV", 1e3 * offset_v);
        assert_thesis_stage_with_offset_named(&at, named, *ratio, *fitted_v, *offset_v);
    }
}

/// The full thesis stage with a sensor offset of `offset_v`, diagnosed from `thesis-linear`:
/// its three slow effects and the offset named, the offset fitted within 5 mV of the truth
/// (two noise floors of the stage's 2.5 mV), nothing the truth lacks (its slew limit and
/// amplifier saturation may show), and the residual within 1.5x the floor (the issue's bar
/// for `thesis-full`).
fn assert_thesis_stage_with_offset_named(
    at: &str,
    named: &[String],
    ratio: f64,
    fitted_v: Option<f64>,
    offset_v: f64,
) {
    assert!(
        fitted_v.is_some_and(|v| (v - offset_v).abs() <= 5e-3),
        "{at}: fitted {fitted_v:?}"
    );
    for e in ["drift", "hysteresis", "nonlinear-gain", "offset"] {
        assert!(
            named.iter().any(|n| n == e),
            "{at}: {e} not named: {named:?}"
        );
    }
    let truth = [
        "drift",
        "hysteresis",
        "nonlinear-gain",
        "slew-rate-limit",
        "saturation",
        "offset",
    ];
    assert!(
        named.iter().all(|n| truth.contains(&n.as_str())),
        "{at}: a name the truth lacks: {named:?}"
    );
    assert!(ratio <= 1.5, "{at}: final {ratio:.2}x the floor");
}

/// Gaussian noise of `sigma_v` standard deviation through a first-order low-pass at
/// `corner_hz`, sampled at `rate_hz` (`n` samples): a sensor whose bandwidth is below the
/// record's Nyquist rate.
fn coloured_noise(n: usize, rate_hz: f64, corner_hz: f64, sigma_v: f64, seed: u64) -> Vec<f64> {
    host_tests::testing::filtered_noise(n, rate_hz, corner_hz, 1, seed)
        .into_iter()
        .map(|x| sigma_v * x)
        .collect()
}

/// The lab's own rig: the thesis' E-509 sensor has a 10 kHz bandwidth (sec. 2.4), so its
/// 2.5 mV of noise sampled at 50 kHz is coloured (first order here), and the 1 kHz slow
/// record sees it white. The floor is the noise's whole standard deviation (the stride-1
/// estimate alone gives 0.78 of it on the fast record: the pooled floor 10 % low), and the
/// full thesis stage with a +20 mV sensor offset is diagnosed as on white noise: its three
/// slow effects and the offset named, nothing the truth lacks, within 1.5x the floor.
#[test]
fn coloured_sensor_noise_is_the_floor_not_an_effect() {
    let sigma_v = 2.5e-3;
    let offset_v = 0.020;
    let mut truth = ModelFile::built_in("thesis-full").unwrap();
    truth.converters.noise_v = 0.0;
    truth.converters.seed = 12;
    truth.offset = Some(host_tests::io::model_file::OffsetSection { offset_v });
    let mut data = protocol_data(&truth, 40.0);
    for (i, d) in data.iter_mut().enumerate() {
        let rate_hz = 1.0 / (d.t_s[1] - d.t_s[0]);
        let corner_hz = if rate_hz > 20e3 { 10e3 } else { 1e9 };
        let noise = coloured_noise(d.len(), rate_hz, corner_hz, sigma_v, 60 + i as u64);
        for (y, w) in d.y_v.iter_mut().zip(noise) {
            *y += w;
        }
    }
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let d = diagnose(&base, &data, &Options::default()).unwrap();
    let ratio = d.final_rms_v / d.noise_floor_v;
    println!(
        "coloured noise: floor {:.3} mV, named {:?}, final {ratio:.2}x the floor\n{}",
        1e3 * d.noise_floor_v,
        d.named,
        d.table()
    );
    assert!(
        (d.noise_floor_v / sigma_v - 1.0).abs() < 0.05,
        "floor {:.3} mV against the noise's {:.3} mV",
        1e3 * d.noise_floor_v,
        1e3 * sigma_v
    );
    let fitted_v = d.model.offset.as_ref().map(|o| o.offset_v);
    assert_thesis_stage_with_offset_named("coloured noise", &d.named, ratio, fitted_v, offset_v);
}

/// A real record's glitches (three single samples 0.5-1.2 V off, as an ADC or a logger
/// makes them, and bursts of two and three samples) in a clean thesis-stage sine: nothing is
/// named, the record ends at its floor (with the singles in, 6.8x the floor and an
/// `unexplained` part; with the bursts, 9.2x before runs were looked for), and the glitches
/// are said.
#[test]
fn glitches_of_the_recording_are_replaced_and_said() {
    let (t, u) = raised_cosine(5_000.0, 10.0, 1.0, 5.0, 4.5);
    let mut truth = ModelFile::built_in("thesis-linear").unwrap();
    truth.converters.noise_v = 1e-3;
    truth.converters.seed = 31;
    let stage = truth.build_stage().unwrap();
    let mut y = simulate(&stage, truth.period_s, &t, &u);
    for (i, v) in [
        (10_000usize, 0.5),
        (15_000, 0.6),
        (15_001, 0.5),
        (25_000, -0.8),
        (30_000, -0.4),
        (30_001, -0.5),
        (30_002, -0.4),
        (40_000, 1.2),
    ] {
        y[i] += v;
    }
    let data =
        vec![Data::from_record("glitchy.csv", Record::new(t, u, Some(y), None).unwrap()).unwrap()];
    let d = diagnose(&truth, &data, &Options::default()).unwrap();
    let ratio = d.final_rms_v / d.noise_floor_v;
    println!("{}", d.table());
    assert!(d.named.is_empty(), "{:?}", d.named);
    assert!(ratio <= 1.1, "final {ratio:.2}x the floor");
    assert!(d.unexplained.is_none());
    assert!(
        d.noise_notes
            .iter()
            .any(|n| n.contains("5 runs of 1-3 samples")
                && n.contains("t = 2.0000, 3.0000, 5.0000, 6.0000, 8.0000 s")),
        "{:?}",
        d.noise_notes
    );
}

/// The mains' hum on a lab's records (2 mV RMS at 50.02 Hz and 1 mV at its second harmonic,
/// a rectifier's, on the identification protocol's records beside the thesis' 2.5 mV of
/// noise), with the full thesis stage and a +20 mV sensor offset. On the 40 s slow record the
/// hum is taken out and said, and that record ends where it ends without hum (within 5 %;
/// 2.2 mV of hum left in it would add 30 % in quadrature; measured 2.66 against 2.60 mV
/// until session 28, 2.66 against 2.57 since session 29, whose settled K'(u) moved the
/// record without hum and not the one with it, the two fits taking their steps in another
/// order), with the same names: its three
/// slow effects, the slew limit and the offset. The 0.2 s fast record keeps its hum: around
/// 50 Hz its residual from the base model is the steps' misfit, broadband and as strong, and
/// the line does not stand out of it (the rule takes no line it cannot tell).
#[test]
fn mains_hum_is_the_measurements_not_the_stages() {
    let offset_v = 0.020;
    let mut truth = ModelFile::built_in("thesis-full").unwrap();
    truth.converters.seed = 13;
    truth.offset = Some(host_tests::io::model_file::OffsetSection { offset_v });
    let clean = protocol_data(&truth, 40.0);
    let mut data = clean.clone();
    let tau = 2.0 * std::f64::consts::PI;
    for d in data.iter_mut() {
        let t = d.t_s.clone();
        for (y, t) in d.y_v.iter_mut().zip(t) {
            *y += 2e-3 * 2f64.sqrt() * (tau * 50.02 * t + 0.4).sin()
                + 1e-3 * 2f64.sqrt() * (tau * 100.04 * t + 1.9).sin();
        }
    }
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let without = diagnose(&base, &clean, &Options::default()).unwrap();
    let d = diagnose(&base, &data, &Options::default()).unwrap();
    let ratio = d.final_rms_v / d.noise_floor_v;
    println!(
        "mains hum: floor {:.3} mV, named {:?}, final {ratio:.2}x the floor; per record {:?} mV, \
         without hum {:?} mV\n{}",
        1e3 * d.noise_floor_v,
        d.named,
        d.record_final_rms_v,
        without.record_final_rms_v,
        d.table()
    );
    assert!(
        d.noise_notes.iter().any(|n| n.starts_with("slow.csv")
            && n.contains("mains interference")
            && n.contains("50.0")
            && n.contains("100.0")),
        "{:?}",
        d.noise_notes
    );
    assert_eq!(d.named, without.named);
    let (slow, slow_without) = (d.record_final_rms_v[1], without.record_final_rms_v[1]);
    assert!(
        (slow / slow_without - 1.0).abs() <= 0.05,
        "slow record {:.3} mV, without hum {:.3} mV",
        1e3 * slow,
        1e3 * slow_without
    );
    let fitted_v = d.model.offset.as_ref().map(|o| o.offset_v);
    assert_thesis_stage_with_offset_named("mains hum", &d.named, ratio, fitted_v, offset_v);
}

/// Five slips a real record's maker makes, refused with words that say which: a time column
/// in milliseconds (the record reads 1000 times slower than the 1 kHz the workflow needs, and
/// the refusal names the rate it would have in seconds), a sensor wired with its sign
/// reversed (the output moves against the model's, correlation -1: named as such, not
/// diagnosed as thousands of floors of unexplained residual as before), an output in
/// millivolts (1000 times the model's: before, an error that a figure came out as NaN), the
/// amplifier's monitor logged as the input (10x the command, beyond the amplifier's input
/// range: the words ask about u too), and
/// the input and output columns swapped (the sensor's noisy reading as the input, the exact
/// command as the output: before, a `sensor-gain` of 1.60, an `amplifier-pole` and a
/// `time-delay` at 115x the floor).
#[test]
fn a_record_in_milliseconds_or_with_a_reversed_sign_is_refused_clearly() {
    let (truth, t, u, y) = clean_thesis_sine(2.0);
    let t_ms: Vec<f64> = t.iter().map(|x| 1e3 * x).collect();
    let err = Data::from_record(
        "ms.csv",
        Record::new(t_ms, u.clone(), Some(y.clone()), None).unwrap(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("sampled at 5.0 Hz")
            && err.contains("milliseconds")
            && err.contains("5000.0 Hz"),
        "{err}"
    );
    let millivolts: Vec<f64> = y.iter().map(|v| 1e3 * v).collect();
    let data = vec![
        Data::from_record(
            "mv.csv",
            Record::new(t.clone(), u.clone(), Some(millivolts), None).unwrap(),
        )
        .unwrap(),
    ];
    let err = refusal(&truth, &data);
    assert!(
        err.contains("mv.csv")
            && err.contains("1000.0")
            && err.contains("times as far")
            && err.contains("other units")
            && !err.contains("Its input u spans"),
        "{err}"
    );
    // The amplifier's monitor logged as the input: 10x the command, beyond what the
    // amplifier accepts; the model then moves 10x as far as the record, and the words ask
    // about u as well as y.
    let monitor: Vec<f64> = u.iter().map(|v| 10.0 * v).collect();
    let data = vec![
        Data::from_record(
            "monitor.csv",
            Record::new(t.clone(), monitor, Some(y.clone()), None).unwrap(),
        )
        .unwrap(),
    ];
    let err = refusal(&truth, &data);
    assert!(
        err.contains("monitor.csv")
            && err.contains("times as far")
            && err.contains("beyond the amplifier's input range")
            && err.contains("amplifier's output"),
        "{err}"
    );
    let swapped = vec![
        Data::from_record(
            "swapped.csv",
            Record::new(t.clone(), y.clone(), Some(u.clone()), None).unwrap(),
        )
        .unwrap(),
    ];
    let err = refusal(&truth, &swapped);
    assert!(
        err.contains("swapped.csv")
            && err.contains("input column is noisy")
            && err.contains("in each other's columns"),
        "{err}"
    );
    let reversed: Vec<f64> = y.iter().map(|v| -v).collect();
    let data = vec![
        Data::from_record(
            "reversed.csv",
            Record::new(t, u, Some(reversed), None).unwrap(),
        )
        .unwrap(),
    ];
    let err = refusal(&truth, &data);
    assert!(
        err.contains("reversed.csv") && err.contains("moves against") && err.contains("-1.00"),
        "{err}"
    );
}

/// A sensor that is not there or not in range, refused with words that say which: one
/// unplugged (the output is its own 1 mV of noise: before, a false `hysteresis` at 2767x the
/// floor), and one clipped by its logger at 7 V, below the stage's top (before: nothing named,
/// 24.8x the floor, an `unexplained` part at the top of the input), exactly or under the
/// converter's own noise (session 56: `hysteresis` named before). A clean record of the
/// same stage is not refused, nor one 16 ms late and rounded to 8 bits (its top code at 4 %
/// of the samples, where the model's output moves), nor one held at its top level and rounded
/// by a coarse (8-bit)
/// converter: at the sine's bottom and in the hold its output reads one code for hundreds of
/// samples, and the model's output moves less than a code there.
#[test]
fn a_disconnected_or_clipped_sensor_is_refused_clearly() {
    let (truth, t, u, y) = clean_thesis_sine(2.0);
    let noise: Vec<f64> = host_tests::testing::filtered_noise(t.len(), 5e3, 0.0, 0, 5)
        .iter()
        .map(|w| 1e-3 * w)
        .collect();
    let one = |name: &str, y: Vec<f64>| {
        vec![
            Data::from_record(
                name,
                Record::new(t.clone(), u.clone(), Some(y), None).unwrap(),
            )
            .unwrap(),
        ]
    };
    let err = refusal(&truth, &one("unplugged.csv", noise));
    assert!(
        err.contains("unplugged.csv")
            && err.contains("does not follow")
            && err.contains("connected"),
        "{err}"
    );
    let clipped: Vec<f64> = y.iter().map(|v| v.min(7.0)).collect();
    let err = refusal(&truth, &one("clipped.csv", clipped));
    assert!(
        err.contains("clipped.csv")
            && err.contains("exactly 7.0000 V")
            && err.contains("clipped at its range"),
        "{err}"
    );
    // (the same saturation before the converter, read with 1 mV of the converter's own
    // noise: no two readings equal; before: `hysteresis` named at 10-17x the floor)
    let jitter = host_tests::testing::filtered_noise(t.len(), 5e3, 0.0, 0, 6);
    let saturated: Vec<f64> = y
        .iter()
        .zip(&jitter)
        .map(|(v, w)| v.min(7.0) + 1e-3 * w)
        .collect();
    let err = refusal(&truth, &one("saturated.csv", saturated));
    assert!(
        err.contains("saturated.csv") && err.contains("of 7.00") && err.contains("saturated"),
        "{err}"
    );
    assert_eq!(refusal(&truth, &one("clean.csv", y.clone())), "");
    // (an output 16 ms late, as a loop lags, rounded to 8 bits over 9 V: its top code holds
    // 4 % of the samples while the model's output moves 0.1 V over them, but the record's
    // line on the model stays within a code of it)
    let code = 9.0 / 256.0;
    let late: Vec<f64> = (0..y.len())
        .map(|i| (y[i.saturating_sub(80)] / code).round() * code)
        .collect();
    let err = refusal(&truth, &one("late.csv", late));
    assert!(
        !err.contains("clipped") && !err.contains("saturated"),
        "{err}"
    );
    // (held at 9 V for a second after the sine, rounded to 8 bits of 10 V: one code)
    let (mut th, mut uh, mut yh) = (t.clone(), u.clone(), y.clone());
    let stage = truth.build_stage().unwrap();
    let dt = t[1] - t[0];
    for i in 0..5_000 {
        th.push(t[t.len() - 1] + (i + 1) as f64 * dt);
        uh.push(9.0);
    }
    let yfull = simulate(&stage, truth.period_s, &th, &uh);
    yh.extend_from_slice(&yfull[t.len()..]);
    let step = 10.0 / 256.0;
    let rounded: Vec<f64> = yh.iter().map(|v| (v / step).round() * step).collect();
    let data = vec![
        Data::from_record(
            "held.csv",
            Record::new(th, uh, Some(rounded), None).unwrap(),
        )
        .unwrap(),
    ];
    assert_eq!(refusal(&truth, &data), "");
}

/// A lab's own CSV header (`time_s;input_V;sensor_V`, semicolons) is read through `--vars`,
/// and without it the refusal names the columns found and the flag; the same record diagnoses
/// as under the house header.
#[test]
fn a_labs_own_column_names_are_read_through_vars() {
    let (truth, t, u, y) = clean_thesis_sine(2.0);
    let dir = std::env::temp_dir().join(format!("piezo-gap-vars-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("lab.csv");
    let mut text = String::from("time_s;input_V;sensor_V\n");
    for i in 0..t.len() {
        text.push_str(&format!("{};{};{}\n", t[i], u[i], y[i]));
    }
    std::fs::write(&path, text).unwrap();
    let err = gap::load_data(std::slice::from_ref(&path), None)
        .err()
        .map(|e| format!("{e:#}"))
        .unwrap_or_default();
    assert!(
        err.contains("no column `t`")
            && err.contains("time_s,input_V,sensor_V")
            && err.contains("--vars"),
        "{err}"
    );
    let err = gap::load_data(
        std::slice::from_ref(&path),
        Some("t=time_s,u=input_V,y=sensor_v"),
    )
    .err()
    .map(|e| format!("{e:#}"))
    .unwrap_or_default();
    assert!(
        err.contains("no `sensor_v` column") && err.contains("--vars"),
        "{err}"
    );
    let data = gap::load_data(
        std::slice::from_ref(&path),
        Some("t=time_s,u=input_V,y=sensor_V"),
    )
    .unwrap();
    assert_eq!(data[0].y_v, y);
    let d = diagnose(&truth, &data, &Options::default()).unwrap();
    assert!(d.named.is_empty(), "{:?}", d.named);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The thesis-linear stage (1 mV of noise) on `seconds` of a 1 Hz sine over 0.5-9.5 V at
/// 5 kHz: (the model, t, u, y).
fn clean_thesis_sine(seconds: f64) -> (ModelFile, Vec<f64>, Vec<f64>, Vec<f64>) {
    let (t, u) = raised_cosine(5_000.0, seconds, 1.0, 5.0, 4.5);
    let mut truth = ModelFile::built_in("thesis-linear").unwrap();
    truth.converters.noise_v = 1e-3;
    let stage = truth.build_stage().unwrap();
    let y = simulate(&stage, truth.period_s, &t, &u);
    (truth, t, u, y)
}

/// The words of the diagnosis' refusal of `data` from `base` (empty if it was not refused).
fn refusal(base: &ModelFile, data: &[Data]) -> String {
    diagnose(base, data, &Options::default())
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default()
}

/// A measured input's noise (`gap::input_noise`): a lab that logs the amplifier's input
/// through an ADC records the command plus that converter's noise, which the stage never saw
/// but the model, fed the recorded input, carries into its output. Three stages and protocols
/// no rule here was read on (the rule was built on a `thesis-full` sine): the full thesis
/// stage on random levels (2 kHz, 20 s), and `thesis-linear` with a 250 us delay, or with a
/// 2 kHz amplifier pole, under a 0.5-150 Hz chirp at 20 kHz (where the stage's bandwidth
/// colours the carried noise), each with 3 mV of white noise on the recorded input:
/// * clean: no note;
/// * measured only (the stage driven by the clean input): the note is given, the floor holds
///   the carried noise beside the output's own (between half and all of the input's noise at
///   the stage's static gain), the true names the clean record gets are found and no false
///   one comes with the noise, and the final residual is within 2x the floor (or within a
///   tenth of the clean record's ratio where that is above);
/// * the same noise driving the stage (recorded as it was): no note (the output's own floor
///   holds what the stage carried), also where the stage has a pole the model lacks.
#[test]
fn a_measured_inputs_noise_is_part_of_the_floor() {
    use host_tests::io::model_file::DelaySection;
    use host_tests::sim::synth::{Protocol, SynthSpec, synth};
    use rand_distr::{Distribution, Normal};
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let mut delayed = ModelFile::built_in("thesis-linear").unwrap();
    delayed.time_delay = Some(DelaySection { delay_s: 250e-6 });
    delayed.converters.noise_v = 1e-3;
    let full = ModelFile::built_in("thesis-full").unwrap();
    let mut slowed = ModelFile::built_in("thesis-linear").unwrap();
    slowed.amplifier_pole = Some(host_tests::io::model_file::PoleSection { pole_hz: 2_000.0 });
    slowed.converters.noise_v = 1e-3;
    let full_effects = [
        "drift",
        "hysteresis",
        "nonlinear-gain",
        "slew-rate-limit",
        "saturation",
    ];
    let cases = [
        (
            "levels",
            full,
            &full_effects[..],
            Protocol::Steps,
            20.0,
            2_000.0,
            Some(0.5),
            44u64,
        ),
        (
            "chirp",
            delayed,
            &["time-delay"][..],
            Protocol::Chirp,
            4.0,
            20_000.0,
            None,
            45,
        ),
        (
            "pole",
            slowed,
            &["amplifier-pole"][..],
            Protocol::Chirp,
            4.0,
            20_000.0,
            None,
            46,
        ),
    ];
    for (name, mut truth, truths, protocol, seconds, rate, hold, seed) in cases {
        let spec = SynthSpec {
            model: "thesis-linear".into(),
            protocol,
            seed,
            seconds,
            rate,
            amplitude: 9.0,
            offset: 0.5,
            freq: 0.5,
            freq_end: 150.0,
            hold,
            noise_v: None,
        };
        let input = synth(&spec).unwrap();
        let (t, u) = (input.t_s.clone(), input.u_v.clone());
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let normal = Normal::new(0.0, 3e-3).unwrap();
        let u_noisy: Vec<f64> = u.iter().map(|x| x + normal.sample(&mut rng)).collect();
        truth.converters.seed = seed;
        let stage = truth.build_stage().unwrap();
        let run = |u_rec: &[f64], u_drive: &[f64]| {
            let y = simulate(&stage, truth.period_s, &t, u_drive);
            let rec = Record::new(t.clone(), u_rec.to_vec(), Some(y), None).unwrap();
            let data = vec![Data::from_record(&format!("{name}.csv"), rec).unwrap()];
            // (the output's own floor, as the workflow reads it before the input is looked at)
            let s = gap::sim(&base, &data[0]).unwrap();
            let own_v = gap::noise_floor(&data[0], Some(&s));
            (diagnose(&base, &data, &Options::default()).unwrap(), own_v)
        };
        let (clean, _) = run(&u, &u);
        let (measured, own_v) = run(&u_noisy, &u);
        let (driven, _) = run(&u_noisy, &u_noisy);
        let ratio = |d: &gap::Diagnosis| d.final_rms_v / d.noise_floor_v;
        for (what, d) in [
            ("clean", &clean),
            ("measured", &measured),
            ("driven", &driven),
        ] {
            println!(
                "{name} {what}: floor {:.3} mV, named {:?}, final {:.2}x; notes {:?}",
                1e3 * d.noise_floor_v,
                d.named,
                ratio(d),
                d.noise_notes
            );
        }
        let noted = |d: &gap::Diagnosis| {
            d.noise_notes
                .iter()
                .any(|n| n.contains("the input column carries"))
        };
        assert!(!noted(&clean), "{name}: {:?}", clean.noise_notes);
        assert!(noted(&measured), "{name}: no note on the measured input");
        // (the stage carries the input's noise at most at its static gain, at these rates
        // below its resonance: the floor holds between half that and all of it beside the
        // output's own)
        let gain_v = base.plant.static_gain * 3e-3;
        assert!(
            measured.noise_floor_v >= own_v.hypot(0.5 * gain_v)
                && measured.noise_floor_v <= 1.05 * own_v.hypot(gain_v),
            "{name}: floor {:.3} mV beside the output's own {:.3} mV",
            1e3 * measured.noise_floor_v,
            1e3 * own_v
        );
        // (the names the clean record gets that the truth has are found again, and no name
        // the truth lacks comes with the noise)
        for e in clean.named.iter().filter(|e| truths.contains(&e.as_str())) {
            assert!(
                measured.named.contains(e),
                "{name}: {e} lost: {:?}",
                measured.named
            );
        }
        for e in &measured.named {
            assert!(
                truths.contains(&e.as_str()) || clean.named.contains(e),
                "{name}: {e} the truth lacks: {:?} (clean {:?})",
                measured.named,
                clean.named
            );
        }
        assert!(
            ratio(&measured) <= 2.0f64.max(1.1 * ratio(&clean)),
            "{name}: final {:.2}x the floor (clean {:.2}x)",
            ratio(&measured),
            ratio(&clean)
        );
        assert!(!noted(&driven), "{name}: {:?}", driven.noise_notes);
    }
}
