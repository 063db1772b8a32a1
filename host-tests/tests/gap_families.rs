//! The randomised model-gap suite of issue #12, item 6: the workflow on protocols and truths it
//! was not shaped for.
//!
//! Each case draws (from `StdRng::seed_from_u64(1000 + i)`, so `GAP_SEED=N` re-runs case N) a
//! protocol family (`families::Family`: the identification protocol, one long sine, a chirp, or
//! random levels, at 1-50 kHz), then a kind (clean, one effect, or a pair) among the effects that
//! protocol can show (the rule is in `families`), then a truth for each effect in a form the
//! workflow does not fit:
//! * `hysteresis`: Bouc-Wen, Duhem (Coleman-Hodgdon), a Preisach plane with a Gaussian or
//!   Lorentzian density (asymmetric), or Prandtl-Ishlinskii with random radii; loop 5-15 % of
//!   the span; half the cases start after earlier excursions (not on a major curve). Scaled
//!   to that width, some truths move the position against the input just after a reversal
//!   (`Hysteresis::min_slope` below zero), which no Everett table can: the per-form table
//!   counts them apart (`hyst-branch:backward`, else `hyst-branch:monotone`);
//! * `drift`: log creep or fractional (power-law `t^a`, a = 0.05-0.3) creep, 2-8 % of a step
//!   at 10 s;
//! * `nonlinear-gain`: a static map of tanh, exp or softplus shape (not a polynomial), with the
//!   catalogue's convention `m(0) = 0`, `m'(0) = 1`, deviating 40-200 mV (input) at most;
//! * `sensor-gain`: scale 0.95-1.05 (at least 0.5 % off), `offset`: 5-30 mV either sign (the
//!   model file's `[converters] sensor_gain` and `[offset]`);
//! * `time-delay` 150-400 us, `slew-rate-limit` 2e4-2e5 V/s at the amplifier output,
//!   `resonance` 3-12 kHz (damping 0.02-0.08): the model file's own blocks.
//!
//! The hysteresis, creep and static map are applied to the input (in that order, creep on the
//! raw input) before the truth's `thesis-linear` stage; every record has 1 mV of sensor noise.
//! The workflow starts from `thesis-linear` and is told nothing else. A case is exact when the
//! named set equals the truth's set of catalogue names. `GAP_DEBUG=1` prints each case's table;
//! `GAP_DUMP=DIR` writes each case's records to `DIR/SEED-NAME` (`1037-sine.csv`, for `piezo gap`).
//! A case whose records the diagnosis refuses (an error, not a diagnosis) prints a `REFUSED`
//! line with its seed, counts as naming nothing, and fails the suite's test.

mod families;

use families::{Creep, Family, HystForm, Hysteresis, Protocol, StaticMap, draw_protocol, lu};
use host_tests::gap::shrink::{CUT_MIN, FLOOR_MAX, ResidualCut, shortfall};
use host_tests::gap::{self, Data, Options, diagnose};
use host_tests::io::csv::Record;
use host_tests::io::model_file::{
    DelaySection, ModelFile, OffsetSection, ResonanceSection, SlewSection,
};
use host_tests::sim::open_loop::simulate;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::collections::BTreeMap;

/// A drawn case: the protocol and the truth.
#[derive(Debug)]
struct Case {
    seed: u64,
    protocol: Protocol,
    /// The truth's effects, catalogue names, sorted.
    effects: Vec<&'static str>,
    hysteresis: Option<Hysteresis>,
    creep: Option<Creep>,
    static_map: Option<StaticMap>,
    sensor_gain: Option<f64>,
    offset_v: Option<f64>,
    delay_s: Option<f64>,
    slew_v_per_s: Option<f64>,
    mode: Option<(f64, f64)>,
}

impl Case {
    fn draw(seed: u64) -> Self {
        let mut rng = StdRng::seed_from_u64(seed);
        let family = Family::ALL[rng.gen_range(0..Family::ALL.len())];
        let protocol = draw_protocol(family, &mut rng);
        let allowed = protocol.allowed();
        // Kinds: 15 % clean, 45 % one effect, 40 % a pair.
        let r: f64 = rng.r#gen();
        let mut effects: Vec<&'static str> = Vec::new();
        let count = if r < 0.15 {
            0
        } else if r < 0.6 {
            1
        } else {
            2
        };
        while effects.len() < count {
            let e = allowed[rng.gen_range(0..allowed.len())];
            if !effects.contains(&e) {
                effects.push(e);
            }
        }
        effects.sort();
        let has = |e: &str| effects.contains(&e);
        let hysteresis = has("hysteresis").then(|| Hysteresis::draw(&mut rng));
        let creep = has("drift").then(|| Creep::draw(&mut rng));
        let static_map = has("nonlinear-gain").then(|| StaticMap::draw(&mut rng));
        let sensor_gain = has("sensor-gain").then(|| {
            let s = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
            1.0 + s * rng.gen_range(0.005..0.05)
        });
        let offset_v = has("offset").then(|| {
            let s = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
            s * rng.gen_range(0.005..0.03)
        });
        let delay_s = has("time-delay").then(|| lu(&mut rng, 150e-6, 400e-6));
        let slew_v_per_s = has("slew-rate-limit").then(|| lu(&mut rng, 2e4, 2e5));
        let mode = has("resonance").then(|| {
            let top = 12_000.0f64.min(protocol.step_rate_hz.unwrap_or(0.0) / 4.0);
            (lu(&mut rng, 3000.0, top), lu(&mut rng, 0.02, 0.08))
        });
        Self {
            seed,
            protocol,
            effects,
            hysteresis,
            creep,
            static_map,
            sensor_gain,
            offset_v,
            delay_s,
            slew_v_per_s,
            mode,
        }
    }

    /// A case of `effects` on `protocol` whose truths are set by the caller (the fields left
    /// `None` here).
    fn of(seed: u64, protocol: Protocol, effects: Vec<&'static str>) -> Self {
        Self {
            seed,
            protocol,
            effects,
            hysteresis: None,
            creep: None,
            static_map: None,
            sensor_gain: None,
            offset_v: None,
            delay_s: None,
            slew_v_per_s: None,
            mode: None,
        }
    }

    /// The truth forms, for the per-form table.
    fn forms(&self) -> Vec<&'static str> {
        let mut v = Vec::new();
        if let Some(h) = &self.hysteresis {
            v.push(h.form.label());
            v.push(if h.before.is_empty() {
                "hyst-start:rest"
            } else {
                "hyst-start:excursion"
            });
            v.push(if h.min_slope() < 0.0 {
                "hyst-branch:backward"
            } else {
                "hyst-branch:monotone"
            });
        }
        if let Some(c) = &self.creep {
            v.push(c.label());
        }
        if let Some(m) = &self.static_map {
            v.push(m.label());
        }
        v
    }

    /// One line on the truth's parameters (the Everett table is left out).
    fn describe(&self) -> String {
        let mut s = format!("{} [{}]", self.protocol.family.name(), self.protocol.desc);
        if let Some(h) = &self.hysteresis {
            s += &format!(
                "; {:?} loop {:.1} % start {:?} least slope {:.2}",
                h.form,
                100.0 * h.share,
                h.before,
                h.min_slope()
            );
        }
        if let Some(c) = &self.creep {
            s += &format!("; {c:?}");
        }
        if let Some(m) = &self.static_map {
            s += &format!("; {:?} {:.0} mV", m.shape, 1e3 * m.amp_v);
        }
        if let Some(g) = self.sensor_gain {
            s += &format!("; sensor gain {g:.4}");
        }
        if let Some(o) = self.offset_v {
            s += &format!("; offset {:.1} mV", 1e3 * o);
        }
        if let Some(d) = self.delay_s {
            s += &format!("; delay {:.0} us", 1e6 * d);
        }
        if let Some(v) = self.slew_v_per_s {
            s += &format!("; slew {v:.3e} V/s");
        }
        if let Some((f, z)) = self.mode {
            s += &format!("; mode {f:.0} Hz zeta {z:.3}");
        }
        s
    }

    /// The truth's linear stage: `thesis-linear` with 1 mV noise and the model-file effects.
    fn model(&self) -> ModelFile {
        let mut m = ModelFile::built_in("thesis-linear").expect("built-in");
        m.converters.noise_v = 1e-3;
        if let Some(g) = self.sensor_gain {
            m.converters.sensor_gain = g;
        }
        if let Some(offset_v) = self.offset_v {
            m.offset = Some(OffsetSection { offset_v });
        }
        if let Some(delay_s) = self.delay_s {
            m.time_delay = Some(DelaySection { delay_s });
        }
        if let Some(output_v_per_s) = self.slew_v_per_s {
            m.slew_rate_limit = Some(SlewSection { output_v_per_s });
        }
        if let Some((mode_hz, damping)) = self.mode {
            m.resonance = Some(ResonanceSection { mode_hz, damping });
        }
        m
    }

    /// The input the truth's linear stage sees: hysteresis, then the static map, plus creep.
    fn predistort(&self, t_s: &[f64], u: &[f64]) -> Vec<f64> {
        let mut v = u.to_vec();
        if let Some(h) = &self.hysteresis {
            for (vi, hi) in v.iter_mut().zip(h.apply(u)) {
                *vi += hi;
            }
        }
        if let Some(m) = &self.static_map {
            for vi in v.iter_mut() {
                *vi = m.map(*vi);
            }
        }
        if let Some(c) = &self.creep {
            for (vi, ci) in v.iter_mut().zip(c.apply(t_s, u)) {
                *vi += ci;
            }
        }
        v
    }

    /// The records, each with its own noise seed.
    fn records(&self) -> Vec<Data> {
        let m = self.model();
        self.protocol
            .records
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let mut mi = m.clone();
                mi.converters.seed = self.seed * 2 + i as u64;
                let stage = mi.build_stage().expect("truth model");
                let y = simulate(
                    &stage,
                    mi.period_s,
                    &r.t_s,
                    &self.predistort(&r.t_s, &r.u_v),
                );
                let rec = Record::new(r.t_s.clone(), r.u_v.clone(), Some(y), None).expect("record");
                // `GAP_DUMP=DIR` writes the case's records as CSV, for `piezo gap` and its
                // report.
                if let Ok(dir) = std::env::var("GAP_DUMP") {
                    let path = std::path::Path::new(&dir).join(format!("{}-{}", self.seed, r.name));
                    rec.write(&path).expect("GAP_DUMP: write the record");
                }
                Data::from_record(&r.name, rec).expect("record loads")
            })
            .collect()
    }
}

struct Outcome {
    family: Family,
    truth: Vec<String>,
    forms: Vec<&'static str>,
    named: Vec<String>,
    /// The effects in the diagnosis' pairs the records cannot tell (`cannot_tell`), less the
    /// standing note on the offset (`gap::STANDING_OFFSET_NOTE`).
    reported: Vec<String>,
    final_over_floor: f64,
    /// Each correctly named effect and what its kept steps did to the residual
    /// (`gap::Diagnosis::residual_cuts`: the issue's requirement, as the hidden-effect suite
    /// measures it).
    cuts: Vec<(String, Vec<ResidualCut>)>,
    describe: String,
    seconds: f64,
    /// The diagnosis refused the records (an error, not a diagnosis): named nothing.
    refused: bool,
}

impl Outcome {
    /// The correctly named effects short of the issue's residual cut, each with how its first
    /// step short of it fell short (or that no kept step names it).
    fn cut_failures(&self) -> Vec<String> {
        self.cuts
            .iter()
            .filter_map(|(e, cs)| shortfall(e, cs))
            .collect()
    }
}

fn run_case(seed: u64) -> Outcome {
    let started = std::time::Instant::now();
    let case = Case::draw(seed);
    let data = case.records();
    let base = ModelFile::built_in("thesis-linear").unwrap();
    // (the case's outcome from what the diagnosis named and reported)
    let outcome = |named, reported, final_over_floor, cuts, refused| Outcome {
        family: case.protocol.family,
        truth: case.effects.iter().map(|s| s.to_string()).collect(),
        forms: case.forms(),
        named,
        reported,
        final_over_floor,
        cuts,
        describe: case.describe(),
        seconds: started.elapsed().as_secs_f64(),
        refused,
    };
    // (a refusal of a drawn case is a failure of the workflow: counted, named with its seed
    // to rerun it, and the rest of the run still measured)
    let d = match diagnose(&base, &data, &Options::default()) {
        Ok(d) => d,
        Err(e) => {
            println!("REFUSED seed {seed} truth {:?}: {e:#}", case.effects);
            return outcome(Vec::new(), Vec::new(), f64::INFINITY, Vec::new(), true);
        }
    };
    if std::env::var("GAP_DEBUG").is_ok() {
        println!(
            "seed {seed} truth {:?}: {}\n{}",
            case.effects,
            case.describe(),
            d.table()
        );
        print!("{}", d.trace());
        let g = &d.signatures;
        println!(
            "base signatures: held loop {:.2} mV, tail {:.2} mV, loop {:.2} mV, noise {:.2} mV",
            1e3 * g.held_loop_v,
            1e3 * g.tail_v,
            1e3 * g.loop_v,
            1e3 * g.noise_v
        );
    }
    if std::env::var("GAP_TELL").is_ok() {
        for c in &d.cannot_tell {
            println!(
                "TELL seed {seed} {} / {} {:?} rms {:.3} alternative {:.3} floor {:.3} mV",
                c.named,
                c.alternative,
                c.taken_out,
                1e3 * c.rms_v,
                1e3 * c.alternative_rms_v,
                1e3 * d.noise_floor_v,
            );
        }
    }
    let mut named = d.named.clone();
    named.sort();
    let cuts = named
        .iter()
        .filter(|n| case.effects.contains(&n.as_str()))
        .map(|n| (n.clone(), d.residual_cuts(n, &data, &base)))
        .collect();
    // (not the standing note on the offset: it is given on a protocol's account, whatever
    // the records show)
    let reported = d
        .cannot_tell
        .iter()
        .filter(|c| !c.why.starts_with(gap::STANDING_OFFSET_NOTE))
        .flat_map(|c| [c.named.clone(), c.alternative.clone()])
        .collect();
    outcome(
        named,
        reported,
        d.final_rms_v / d.noise_floor_v,
        cuts,
        false,
    )
}

/// Tallies of one group of cases (a family, a form, or all).
#[derive(Default)]
struct Tally {
    cases: usize,
    exact: usize,
    names_given: usize,
    false_names: usize,
    missed: usize,
    clean: usize,
    clean_named: usize,
    /// Cases exact, or with no false name and every missed effect in a pair the diagnosis
    /// reports the records cannot tell ([`Outcome::said`]).
    said: usize,
    /// Correctly named effects, and those whose steps meet the issue's residual cut.
    right_names: usize,
    cut_met: usize,
    seconds: f64,
    /// Cases whose records the diagnosis refused ([`Outcome::refused`]).
    refused: usize,
}

impl Outcome {
    /// Not exact, but honest: no false name, and each missed effect is in a pair the
    /// diagnosis says the records cannot tell (issue #12 item 1: say so instead of guessing).
    /// A measure of what the misses are, beside the exact figure, not in its place.
    fn said(&self) -> bool {
        let no_false = self.named.iter().all(|n| self.truth.contains(n));
        let missed_reported = self
            .truth
            .iter()
            .filter(|t| !self.named.contains(t))
            .all(|t| self.reported.contains(t));
        no_false && missed_reported
    }
}

impl Tally {
    fn add(&mut self, o: &Outcome) {
        self.cases += 1;
        self.seconds += o.seconds;
        self.refused += o.refused as usize;
        self.exact += (o.truth == o.named) as usize;
        self.said += o.said() as usize;
        self.right_names += o.cuts.len();
        self.cut_met += o.cuts.len() - o.cut_failures().len();
        self.names_given += o.named.len();
        self.false_names += o.named.iter().filter(|n| !o.truth.contains(n)).count();
        self.missed += o.truth.iter().filter(|t| !o.named.contains(t)).count();
        if o.truth.is_empty() {
            self.clean += 1;
            self.clean_named += (!o.named.is_empty()) as usize;
        }
    }

    fn exact_pct(&self) -> f64 {
        100.0 * self.exact as f64 / self.cases.max(1) as f64
    }

    fn false_pct(&self) -> f64 {
        100.0 * self.false_names as f64 / self.names_given.max(1) as f64
    }

    fn cut_pct(&self) -> f64 {
        100.0 * self.cut_met as f64 / self.right_names.max(1) as f64
    }

    fn line(&self, label: &str) -> String {
        format!(
            "{label:<24}{:>6}{:>8.1} %{:>6} /{:>4} ={:>6.1} %{:>8}{:>6} /{:>3}{:>9.1}",
            self.cases,
            self.exact_pct(),
            self.false_names,
            self.names_given,
            self.false_pct(),
            self.missed,
            self.clean_named,
            self.clean,
            self.seconds / self.cases.max(1) as f64
        )
    }
}

const TALLY_HEADER: &str =
    "                         cases   exact  false / given          missed  clean named  s/case";

/// Runs the drawn cases (release, the README's test command: 100, seeds 1000..1099,
/// `GAP_CASES` changes the count, `GAP_FIRST` the first seed, `GAP_SEED=N` runs case N alone
/// (`GAP_ALL` prints the cases named exactly too, `GAP_TELL` each case's `cannot_tell` pairs,
/// `GAP_DRAW` each case's truth alone, without diagnosing it);
/// debug builds run 6), prints
/// the confusion table and the tallies by family, hidden effect and truth form, and returns the
/// overall tally (`None` for a chosen list of seeds, or for `GAP_DRAW`, which diagnoses
/// nothing).
fn run_suite() -> Option<Tally> {
    let release = !cfg!(debug_assertions);
    let n_cases: u64 = std::env::var("GAP_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(if release { 100 } else { 6 });
    // (`GAP_SEED` takes a comma-separated list too: the failures of a run, re-run alone)
    let only: Option<Vec<u64>> = std::env::var("GAP_SEED").ok().and_then(|s| {
        s.split(',')
            .map(|x| x.trim().parse().ok())
            .collect::<Option<Vec<u64>>>()
    });
    // (`GAP_FIRST`: another first seed, for draws no rule was shaped on)
    let first: u64 = std::env::var("GAP_FIRST")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1000);
    let seeds: Vec<u64> = match only.clone() {
        Some(s) => s,
        None => (first..first + n_cases).collect(),
    };
    // (`GAP_DRAW`: each case's truth and protocol, without a diagnosis, to pick the cases of
    // one kind from many seeds)
    if std::env::var("GAP_DRAW").is_ok() {
        for &seed in &seeds {
            let case = Case::draw(seed);
            println!(
                "DRAW seed {seed} truth {:?} {}",
                case.effects,
                case.describe()
            );
        }
        return None;
    }
    let started = std::time::Instant::now();
    let outcomes = host_tests::util::par_map(&seeds, |s| run_case(*s));
    let elapsed_s = started.elapsed().as_secs_f64();

    // Confusion table: rows are the hidden effects (and "clean"), columns the names given.
    let mut cols: Vec<&str> = gap::catalogue::EFFECTS.to_vec();
    cols.push("(none)");
    let mut table: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    let mut all = Tally::default();
    let mut by_family: BTreeMap<Family, Tally> = BTreeMap::new();
    let mut by_form: BTreeMap<&str, Tally> = BTreeMap::new();
    let mut by_effect: BTreeMap<String, Tally> = BTreeMap::new();
    for (o, seed) in outcomes.iter().zip(&seeds) {
        all.add(o);
        by_family.entry(o.family).or_default().add(o);
        for f in &o.forms {
            by_form.entry(f).or_default().add(o);
        }
        for f in o.cut_failures() {
            println!(
                "CUT seed {seed} {f} (final {:.2}x floor) {}",
                o.final_over_floor, o.describe
            );
        }
        if o.truth == o.named && std::env::var("GAP_ALL").is_ok() {
            println!(
                "PASS seed {seed} truth {:?} (final {:.2}x floor) {}",
                o.truth, o.final_over_floor, o.describe
            );
        }
        if o.truth != o.named {
            println!(
                "FAIL seed {seed} truth {:?}: named {:?}{} (final {:.2}x floor, {:.1} s) {}",
                o.truth,
                o.named,
                if o.said() {
                    ", each missed effect reported as one the records cannot tell"
                } else {
                    ""
                },
                o.final_over_floor,
                o.seconds,
                o.describe
            );
        }
        let rows = if o.truth.is_empty() {
            vec!["clean".to_string()]
        } else {
            o.truth.clone()
        };
        for r in rows {
            by_effect.entry(r.clone()).or_default().add(o);
            let row = table.entry(r).or_default();
            if o.named.is_empty() {
                *row.entry("(none)".into()).or_default() += 1;
            }
            for x in &o.named {
                *row.entry(x.clone()).or_default() += 1;
            }
        }
    }
    println!(
        "\nConfusion table ({} cases; rows: hidden effect, columns: effects named)",
        outcomes.len()
    );
    print!("{:<16}{:>6}", "", "cases");
    for c in &cols {
        print!("{:>9}", &c[..c.len().min(8)]);
    }
    println!();
    for (r, row) in &table {
        print!("{r:<16}{:>6}", by_effect[r].cases);
        for c in &cols {
            print!("{:>9}", row.get(*c).copied().unwrap_or(0));
        }
        println!();
    }
    println!("\n{TALLY_HEADER}");
    for (f, t) in &by_family {
        println!("{}", t.line(f.name()));
    }
    println!("{}", all.line("all"));
    println!("\nby hidden effect\n{TALLY_HEADER}");
    for (e, t) in &by_effect {
        println!("{}", t.line(e));
    }
    println!("\nby truth form\n{TALLY_HEADER}");
    for (f, t) in &by_form {
        println!("{}", t.line(f));
    }
    let mut ratios: Vec<f64> = outcomes.iter().map(|o| o.final_over_floor).collect();
    ratios.sort_by(f64::total_cmp);
    println!(
        "\nfinal residual / floor: median {:.2}, worst {:.2}; {} cases in {elapsed_s:.1} s",
        ratios[ratios.len() / 2],
        ratios[ratios.len() - 1],
        outcomes.len()
    );
    println!(
        "named set exactly right: {}/{} = {:.1} %; false names: {} of {} given ({:.1} %); clean records named: {}/{}",
        all.exact,
        all.cases,
        all.exact_pct(),
        all.false_names,
        all.names_given,
        all.false_pct(),
        all.clean_named,
        all.clean
    );
    println!(
        "exact, or no false name and every missed effect reported as one the records cannot tell: {}/{} = {:.1} %",
        all.said,
        all.cases,
        100.0 * all.said as f64 / all.cases.max(1) as f64
    );
    println!(
        "correctly named effects meeting the residual cut (>= {CUT_MIN}x, or to <= {FLOOR_MAX}x the floor): {}/{} = {:.1} %",
        all.cut_met,
        all.right_names,
        all.cut_pct()
    );
    println!("cases whose records the diagnosis refused: {}", all.refused);
    only.is_none().then_some(all)
}

/// What the workflow holds on the drawn cases today, as a guard against regressions (the
/// test command runs it and prints the confusion table): no name on a clean record, and at
/// least 81 % exact named sets with at most 1.9 % false names, at least 97 % of the
/// correctly named effects meeting the issue's residual cut (`gap::shrink`), and at least 95 %
/// of the cases exact or honest, in release with the default 100 cases (`GAP_CASES` and
/// `GAP_FIRST` unset). Measured in session 45 (without holds a drift gives way to a shape
/// fitted with an offset; an offset beside a curvature that a cubic does without; beside a
/// loop the simplest of the static shapes alike in each other's place, `select.rs` steps 9,
/// 14 (c) and 15): 83.0 % exact, 0 false names of 104, 0 of 15 clean cases named, 97 exact
/// or honest, the cut 103 of 104 (1006's true scale beside a loop now missed: an offset and a
/// curvature left clearly less in its place); on seeds 1700-1899, run for the first time
/// before and after it: 82.0 -> 83.5 % exact, 16 -> 13 false names. Measured in session 44 (a scale beside a curvature gives way to a
/// curvature of one more order where that leaves as little, `gap::scale_order`: 1079's false
/// scale gone): 84.0 % exact, 0 false names of 105, 0 of 15 clean cases named, 98 exact or
/// honest, the cut 104 of 105; on seeds 1500-1699, run for the first time before and after
/// it: 75.5 -> 79.5 % exact, 30 -> 20 false names (host-tests/GAP.md, session 44). Measured in
/// session 42 (what the final check takes out is said: the shapes that could do
/// the work of an offset it takes out as an unshown level, and a scale or curvature beside
/// the table it takes out below its bar after a growth over 1.25x, are reported in pairs):
/// the names and figures of session 41, case by case, and 97 exact or honest (1001, 1020,
/// 1061 and 1068's missed effects now in pairs). Measured in session 41 (a look-alike named only
/// beside a stepping stone the final check took out is not named, `select.rs` after the final
/// check: 1074's false curvature gone, and 1040's scale, named by the same path, now reported
/// as a pair the records cannot tell): 83.0 % exact, 1 false name of 106 (0.9 %), 0 of 15
/// clean cases named, 93 exact or honest, the cut 104 of 105 (99.0 %). Session 40 (the held levels' loop
/// with a quartic static part on many levels, `HELD_LOOP_QUARTIC_LEVELS`: 1046's false loop
/// gone): 84.0 % exact, 2 false names of 108 (1.9 %), 0 of 15 clean cases named, 92 exact or
/// honest; the cut, first measured then: 105 of 106 (99.1 %), the one short case 1002, a
/// Duhem loop whose branches run backwards (least slope -3.95), which no Everett table the
/// stage accepts can follow (4.1x; the margin is two more such cases). Session 39 (an offset
/// beside a table on records that read no sensor zero kept as the table's level, `select.rs`
/// step 13: 1044's false offset gone): 83.0 % exact, 3 false names of 109 (2.8 %), 0 of 15 clean cases named, 91
/// exact or honest (1071's missed offset is now only in the standing note, which the tally
/// does not count as a pair). Session 30 (ci profile, 2 cores, 320 s: eleven
/// bands for the band and rise splits, `everett::HYST_BANDS_BAND`): 82.0 % exact, 4 false
/// names of 110 (3.6 %), 0 of 15 clean cases named, 92 exact or honest (no false name, every
/// missed effect in a reported pair); the loops fitted closer (median final residual of the
/// 33 cases with a loop 6.6x -> 3.7x the floor). Session 25 (250 s; 235 s re-measured in
/// session 30 with four bands): 83.0 % exact, 5 false
/// names of 112 (4.5 %), 93 exact or honest (session 24: 82.0 % and 6 of 112,
/// before a drift explaining alike went with the look-alike shapes on records without holds,
/// and 1006's true scale stayed against a curvature's better score; session 23: 83.0 % and
/// 6 of 113, before the rise split took 1068's loop and left its curvature alike to a scale
/// and an offset; session 22: 79.0 % and 10 of 116, before step 12 read the three drift
/// records' false offsets, 1073, 1087 and 1096, as the drift's start, and the swaps'
/// fewer-parameter rule put 1074's true scale in place of a curvature); the margins are three
/// exact cases and two false names of the 100, so a change that moves the workflow's
/// decisions on a handful of cases shows here. The issue's own
/// figures are the ignored test below. Session 46 (steps 16 and 17, GAP.md): 81.0 % exact,
/// 0 false names, 98 exact or honest: the bounds are unchanged (step 17 takes out static
/// shapes beside a loop that the records do not tell from it, 1043's and 1054's true ones
/// among them; on 900 seeds it cut the false names from 3.4 % to 2.2 % for 0.4 points of
/// exact sets).
#[test]
fn randomised_families_hold_their_measured_rates() {
    let full_run = std::env::var("GAP_CASES").is_err() && std::env::var("GAP_FIRST").is_err();
    suite_meets(
        [81.0, 1.9, 97.0, 95.0],
        full_run,
        "the measured 83 %, 0.0 %, 99.0 % and 97 % with their margins",
    );
}

/// Runs the suite ([`run_suite`]) and asserts no name on a clean record and, in release
/// where `rates` (with 100 cases at least), at least `exact_pct` exact named sets, at most
/// `false_pct` false names, at least `cut_pct` of the correctly named effects meeting the
/// residual cut and at least `said_pct` cases exact or honest ([`Outcome::said`]; 0 where
/// the figures are the issue's, which asks for exact sets only); `what` names the figures in
/// the messages.
fn suite_meets([exact_pct, false_pct, cut_pct, said_pct]: [f64; 4], rates: bool, what: &str) {
    let Some(all) = run_suite() else {
        return;
    };
    assert_eq!(all.clean_named, 0, "clean records must get no name");
    assert_eq!(
        all.refused, 0,
        "drawn cases the diagnosis refused (REFUSED lines)"
    );
    if !cfg!(debug_assertions) && rates {
        assert!(all.cases >= 100, "{} cases, at least 100", all.cases);
        assert!(
            all.exact_pct() >= exact_pct,
            "exact {:.1} % below {exact_pct} % ({what})",
            all.exact_pct()
        );
        assert!(
            all.false_pct() <= false_pct,
            "false names {:.1} % above {false_pct} % ({what})",
            all.false_pct()
        );
        assert!(
            all.cut_pct() >= cut_pct,
            "residual cut met by {:.1} % below {cut_pct} % ({what})",
            all.cut_pct()
        );
        let said = 100.0 * all.said as f64 / all.cases as f64;
        assert!(
            said >= said_pct,
            "exact or honest {said:.1} % below {said_pct} % ({what})"
        );
    }
}

/// Issue #12's requirements on 100 drawn cases: >= 95 % exact named sets, <= 1 % false names
/// (of the names given), no name on a clean record, every correctly named effect meeting the
/// residual cut. Not met: 81.0 % exact on seeds 1000-1099 (session 46; false names 0 of 102,
/// met there, 5.2 % on the held-out seeds 1900-2099; see the test above and
/// `host-tests/GAP.md`); most failures are a loop of another form (Bouc-Wen, Duhem) on a sine
/// or a chirp beside a static shape the records cannot tell from the table's misfit, now
/// reported rather than named. Session 52, over the 600 seeds 3100-3699 (3500-3699 held out):
/// 85.2 % exact, 12 false names of 643 (1.9 %; 1 of 215 on 3500-3699); of the 89 misses, 32
/// are loops whose branches run backwards (no Everett table follows them) and 23 a loop
/// beside a static shape on records without holds (GAP.md, session 52, by class). Session 58:
/// 86.0 % exact, 7 false names of 643 (1.1 %), 95.7 % exact or honest (a scale beside a
/// curvature no longer named as an offset: GAP.md, step 14 (d)). Session 59: 86.3 % exact,
/// 4 false names of 640 (0.6 %: that figure met on this suite), 96.7 % exact or honest (a
/// curvature that was the band split's own centre line taken out: GAP.md, step 21). Session
/// 60, on fresh seeds 8000-8399 (`GAP_FIRST=8000 GAP_CASES=400`): 85.5 % exact and 13 false
/// names of 465 (2.8 %) at the session's start, 86.2 % and 7 of 459 (1.5 %) with step 21
/// beside the span split's table: the false-name figure is not met on seeds no rule was
/// shaped on. Session 65, over 3100-3699: 86.3 % exact, 3 false names of 639 (0.5 %), 96.8 %
/// exact or honest (a creep no stage could have left out: GAP.md, step 5); the fresh ranges
/// 8000-11399 unchanged at 81.0-86.2 % exact and 1.5-3.0 % false names.
#[test]
#[ignore = "issue #12: workflow does not yet meet this on all families"]
fn randomised_families_are_named() {
    suite_meets([95.0, 1.0, 100.0, 0.0], true, "issue #12's figures");
}

/// What a real recording adds, on cases drawn as the suite draws them but from seeds it never
/// ran (3000-3011): 2 mV RMS of mains hum at 50 Hz (the grid 0.3 % off at most) with 1 mV at
/// its second harmonic, on every record, and three glitches of one to three samples
/// (0.2-0.8 V) in the longest, away from its input's edges. The diagnosis names the same effects as on the records
/// without them. Each record whose hum was taken out ends as it ended without the artefacts,
/// within 10 % or 0.2 of its floor (2.2 mV of hum left on a 1 mV floor would add 140 %); a
/// record whose hum was left (the identification protocol's 0.2 s fast record: its steps,
/// every 18 ms, have lines of their own at 55.6 Hz, one 5 Hz bin from the hum) ends no
/// further than the hum itself takes it, 10 % over the two in quadrature. `GAP_DEBUG=1`
/// prints each pair's figures.
#[test]
fn recording_artefacts_leave_the_diagnosis_as_it_was() {
    let seeds: Vec<u64> = std::env::var("GAP_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .map_or((3000..3012).collect(), |s| vec![s]);
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let runs = host_tests::util::par_map(&seeds, |&seed| {
        let case = Case::draw(seed);
        let clean = case.records();
        let mut rng = StdRng::seed_from_u64(seed + 77);
        let mut dirty = clean.clone();
        let tau = 2.0 * std::f64::consts::PI;
        let grid_hz = 50.0 * (1.0 + rng.gen_range(-0.003..0.003));
        let (p1, p2): (f64, f64) = (rng.gen_range(0.0..tau), rng.gen_range(0.0..tau));
        for d in dirty.iter_mut() {
            let t = d.t_s.clone();
            for (y, t) in d.y_v.iter_mut().zip(t) {
                *y += 2e-3 * 2f64.sqrt() * (tau * grid_hz * t + p1).sin()
                    + 1e-3 * 2f64.sqrt() * (tau * 2.0 * grid_hz * t + p2).sin();
            }
        }
        let longest = (0..dirty.len()).max_by_key(|&r| dirty[r].len()).unwrap();
        let n = dirty[longest].len();
        let mut bursts = Vec::new();
        for _ in 0..3 {
            // (away from the input's edges, where a stage's edge response is not told from
            // a glitch and the rule leaves the samples: `gap::data::glitches`)
            let at = loop {
                let at = rng.gen_range(50..n - 50);
                if !(at - 6..at + 9).any(|j| dirty[longest].is_jump(j)) {
                    break at;
                }
            };
            let len = rng.gen_range(1..=3);
            let v = rng.gen_range(0.2..0.8) * if rng.r#gen::<bool>() { 1.0 } else { -1.0 };
            for k in 0..len {
                dirty[longest].y_v[at + k] += v;
            }
            bursts.push(format!(
                "{len} at t = {:.4} s, {v:+.2} V",
                dirty[longest].t_s[at]
            ));
        }
        let a = diagnose(&base, &clean, &Options::default()).expect("clean");
        let b = diagnose(&base, &dirty, &Options::default()).expect("with artefacts");
        (seed, case.effects.clone(), a, b, bursts)
    });
    let mut failures = Vec::new();
    for (seed, truth, a, b, bursts) in &runs {
        let (ra, rb) = (
            a.final_rms_v / a.noise_floor_v,
            b.final_rms_v / b.noise_floor_v,
        );
        let line = format!(
            "seed {seed} truth {truth:?}: clean {:?} {ra:.2}x; with artefacts {:?} {rb:.2}x \
             (bursts {}); {}",
            a.named,
            b.named,
            bursts.join(", "),
            b.noise_notes.join(" | ")
        );
        if std::env::var("GAP_DEBUG").is_ok() {
            println!("{line}");
        }
        let mut na = a.named.clone();
        let mut nb = b.named.clone();
        na.sort();
        nb.sort();
        let hum_v = (2e-3f64.powi(2) + 1e-3f64.powi(2)).sqrt();
        let records_hold = (0..b.record_final_rms_v.len()).all(|r| {
            let (clean_v, dirty_v) = (a.record_final_rms_v[r], b.record_final_rms_v[r]);
            let floor_v = b.record_noise_v[r];
            if b.hum[r].is_empty() {
                dirty_v <= 1.1 * clean_v.hypot(hum_v)
            } else {
                dirty_v <= (1.1 * clean_v).max(clean_v + 0.2 * floor_v)
            }
        });
        if na != nb || !records_hold {
            failures.push(format!(
                "{line}\n  per record: clean {:?}, with artefacts {:?} V, hum taken {:?}",
                a.record_final_rms_v,
                b.record_final_rms_v,
                b.hum.iter().map(|h| h.len()).collect::<Vec<_>>()
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The truth forms do what the module notes say: every loop counter-clockwise and as wide as
/// drawn; the Preisach plane and the play operators keep return-point memory and wipe out
/// (Bouc-Wen and Duhem need not); the creep banks follow their laws within 2 % from 10 ms to
/// 30 s; the static maps keep `m(0) = 0`, `m'(0) = 1` and deviate `amp` at most.
#[test]
fn truth_forms_follow_their_laws() {
    let grid: Vec<f64> = (0..=500).map(|i| i as f64 * 0.02).collect();
    let mut worst_width = 0.0f64;
    for seed in 0..40u64 {
        let mut rng = StdRng::seed_from_u64(seed);
        let h = Hysteresis::draw(&mut rng);
        let mut path = vec![0.0, 10.0, 0.0];
        path.extend(&grid);
        path.extend(grid.iter().rev());
        let y = Hysteresis {
            before: Vec::new(),
            ..h
        };
        let out = y.apply(&path);
        assert!(out.iter().all(|v| v.is_finite()), "{:?}", y.form);
        let up = &out[3..3 + grid.len()];
        let down: Vec<f64> = out[3 + grid.len()..].iter().rev().copied().collect();
        let gaps: Vec<f64> = up.iter().zip(&down).map(|(a, b)| b - a).collect();
        let width = gaps.iter().copied().fold(0.0f64, f64::max);
        let crossing = gaps.iter().copied().fold(0.0f64, f64::min);
        // Bouc-Wen's branches may cross by a hair next to the reversal points.
        assert!(
            crossing >= -0.01 * width,
            "{:?}: rising above falling by {crossing}",
            y.form
        );
        worst_width = worst_width.max((width / (10.0 * y.share) - 1.0).abs());
        if matches!(
            y.form,
            families::HystForm::Preisach { .. } | families::HystForm::Pi { .. }
        ) {
            let a = y.apply(&[2.0, 8.0, 4.0, 6.0, 4.0, 9.0]);
            let b = y.apply(&[2.0, 9.0]);
            assert!(
                (a[2] - a[4]).abs() < 1e-9,
                "{}: return point",
                y.form.label()
            );
            assert!((a[5] - b[1]).abs() < 1e-9, "{}: wiping out", y.form.label());
        }
    }
    println!(
        "loop widths within {:.2} % of the drawn ones",
        100.0 * worst_width
    );
    assert!(worst_width < 1e-6);
    let t: Vec<f64> = (0..30_000).map(|i| i as f64 * 1e-3).collect();
    let mut u = vec![1.0; t.len()];
    u[0] = 0.0;
    for seed in 0..10u64 {
        let mut rng = StdRng::seed_from_u64(seed);
        let c = Creep::draw(&mut rng);
        let out = c.apply(&t, &u);
        let law = |s: f64| match c {
            Creep::Log { gamma, tau0_s } => gamma * (1.0 + s / tau0_s).ln(),
            Creep::Power { a, tau0_s, share } => {
                share * ((s + tau0_s).powf(a) - tau0_s.powf(a))
                    / ((10.0 + tau0_s).powf(a) - tau0_s.powf(a))
            }
        };
        for i in [11usize, 101, 1001, 10_001, 29_999] {
            // Sample i holds the bank's state after i - 1 steps of the held unit input.
            let got = out[i] * model_core::params::PLANT_GAIN;
            let want = law(t[i - 1]);
            assert!(
                (got / want - 1.0).abs() < 0.02,
                "{c:?} at {} s: {got} against {want}",
                t[i - 1]
            );
        }
        let m = StaticMap::draw(&mut rng);
        assert!(m.map(0.0).abs() < 1e-12);
        assert!(((m.map(1e-4) - m.map(-1e-4)) / 2e-4 - 1.0).abs() < 1e-4);
        let dev = grid
            .iter()
            .map(|&v| (m.map(v) - v).abs())
            .fold(0.0f64, f64::max);
        assert!((dev / m.amp_v.abs() - 1.0).abs() < 1e-3, "{m:?}");
    }
}

/// Step 12 on creeps it was not shaped on: log and power creeps drawn anew (seeds 3001-3006,
/// not the suite's; the step was shaped on the suite's 1073, 1087 and 1096), counted from the
/// first input as the families count them, on random levels (whose first level is not 0 V).
/// Alone, the constant they leave against the model's settled lags is the drift's start, or
/// too small to name where the first level is low: `drift` named and no `offset`. Beside a
/// true sensor offset of -40..-80 mV (the sign of the creep taken back, so that the two add),
/// the offset is beyond the step's tenth of the creep and stays named. (First drawn with
/// offsets of the other sign, seeds 3005 and 3006 named `drift` alone at 1.11x and 1.14x:
/// their +42.5 and +64.6 mV cancelled most of the creep's constant at first inputs of 2.0 and
/// 2.6 V, and the records hold no level to name, a limit of any fit on such records.)
/// Measured in session 23: 3001 and 3003 would have named an `offset` without step 12 (the
/// pair is reported, the constant in `[drift] unsettled_v`; asserted: the step fires twice at
/// least); 3002 and 3004 (first levels 1.77 and 0.59 V) name none either way; the residuals,
/// 1.44-3.14x, are the three lags' misfit of these creeps, not asserted here. Release only
/// (as the suite: the test command's `ci` profile).
#[test]
fn creep_counted_from_the_first_input_is_not_a_sensor_offset() {
    if cfg!(debug_assertions) {
        return;
    }
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let mut lines = Vec::new();
    let mut fired = 0;
    for seed in 3001..=3006u64 {
        let mut rng = StdRng::seed_from_u64(seed);
        let protocol = draw_protocol(Family::RandomLevels, &mut rng);
        let creep = Creep::draw(&mut rng);
        let with_offset = seed > 3004;
        let offset_v = with_offset.then(|| -rng.gen_range(0.04..0.08));
        let mut effects = vec!["drift"];
        if with_offset {
            effects.push("offset");
        }
        let case = Case {
            creep: Some(creep),
            offset_v,
            ..Case::of(seed, protocol, effects)
        };
        let data = case.records();
        let d = diagnose(&base, &data, &Options::default()).expect("diagnosis");
        let mut named = d.named.clone();
        named.sort();
        let ratio = d.final_rms_v / d.noise_floor_v;
        let pair = d
            .cannot_tell
            .iter()
            .any(|c| c.named == "drift" && c.alternative == "offset");
        lines.push(format!(
            "seed {seed} ({}; first input {:.2} V): named {named:?}, {ratio:.2}x, pair reported {pair}",
            case.describe(),
            data[0].u_v[0]
        ));
        // Where the step read the offset as the drift's start, the model carries it there,
        // and it is the settled creep at the first input taken back (within the step's tenth).
        let start_ok = !pair
            || d.model
                .drift
                .as_ref()
                .and_then(|x| x.unsettled_v)
                .is_some_and(|c| {
                    let creep = d.model.settled_creep_reading_v(data[0].u_v[0]).unwrap();
                    d.model.offset.is_none()
                        && (c + creep).abs() <= gap::CREEP_START_SHARE * creep.abs()
                });
        fired += pair as usize;
        let ok = start_ok
            && if with_offset {
                named == ["drift", "offset"] && !pair
            } else {
                named == ["drift"]
            };
        if !ok {
            lines.push(format!("  FAIL seed {seed}\n{}", d.table()));
        }
    }
    let report = lines.join("\n");
    println!("{report}");
    assert!(!report.contains("FAIL"), "{report}");
    // The step ran where a false offset came (3001 and 3003): it is exercised, not idle.
    assert!(
        fired >= 2,
        "step 12 fired on {fired} of the creep-only cases\n{report}"
    );
}

/// A creep and a loop together, the pair every piezo stage has, which the suite's draws
/// almost never make (drift is one of eight effects, and only on protocols with holds: none
/// of the 100 cases has the pair). Drift and hysteresis from the families' own generators
/// (log or power creep; Bouc-Wen, Duhem, PI or Preisach loops, at rest or after an
/// excursion), on random levels (odd seeds) and on the identification protocol (even), seeds
/// 4001-4016 drawn for this test (4001-4007 then set `HELD_LOOP_OVER_TAIL`).
///
/// Before session 28 the held levels' gap did not admit the loop while the holds showed a
/// tail: the random-levels cases named `drift` with a false `nonlinear-gain` (4001, 63x) or
/// nothing (4003, 4005, 4007 at 122-256x). Now the loop is admitted beside a drift in the
/// model, and a creep and a loop are offered as one step where the gap stands clear of the
/// tails (4007: drift alone explained nothing). Measured in session 28: hysteresis named on
/// all 16, drift on 14 (not on 4003, 4013), 4 false names, 10 exact. Session 30 (eleven bands
/// along the relay centres, and a drift whose removal brings its tails back kept by the final
/// check and the swaps, `select::tails_back`): hysteresis and drift on all 16, 4 false names
/// (a `nonlinear-gain` or `sensor-gain` beside a loop of another form: 4001, 4005, 4014,
/// 4015), 12 exact; with the eleven bands alone the drift was missing on 4003, 4011, 4013 and
/// 4015 (on 4011 and 4015 taken out after an offset the loop had traded for, with tails of 61
/// and 76 mV back; on 4003 a curvature swapped in; 4013 had lacked it since session 28).
/// Session 31 (step 12's span for lags slower than a third of a record): 4001 exact at 3.14x,
/// 3 false names (4005, 4014, 4015), 13 exact. The identification cases' Duhem loops that run
/// backwards after reversals end at 42-101x (their misfit, as in the suite). Session 39 (a
/// stage at rest reads through its sensor: the first sample of a model with a scale was off
/// by the scale's error times the first level, 570 mV on 4005): 4005 ends at 1.12x the floor
/// (was 3.13x with a drift whose K(u) had run to k1 = 78), named with its false scale and a
/// curvature beside it (the Preisach plane's own centre curve on these levels, which the
/// generator leaves: GAP.md, session 30), so 4 false names (4005 twice, 4014, 4015), 13
/// exact. Asserted at those counts: a guard, not the issue's figure.
#[test]
fn a_creep_and_a_loop_together_are_both_named() {
    if cfg!(debug_assertions) {
        return;
    }
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let mut lines = Vec::new();
    let (mut loops, mut creeps, mut false_names) = (0, 0, 0);
    let only: Option<u64> = std::env::var("CREEP_SEED")
        .ok()
        .and_then(|s| s.parse().ok());
    let seeds: Vec<u64> = (4001..=4016u64)
        .filter(|s| only.is_none_or(|o| o == *s))
        .collect();
    for &seed in &seeds {
        let mut rng = StdRng::seed_from_u64(seed);
        let family = if seed % 2 == 0 {
            Family::Identification
        } else {
            Family::RandomLevels
        };
        let protocol = draw_protocol(family, &mut rng);
        let hysteresis = Hysteresis::draw(&mut rng);
        let creep = Creep::draw(&mut rng);
        let case = Case {
            hysteresis: Some(hysteresis),
            creep: Some(creep),
            ..Case::of(seed, protocol, vec!["drift", "hysteresis"])
        };
        let data = case.records();
        let d = diagnose(&base, &data, &Options::default()).expect("diagnosis");
        let mut named = d.named.clone();
        named.sort();
        let ratio = d.final_rms_v / d.noise_floor_v;
        loops += named.iter().any(|n| n == "hysteresis") as usize;
        creeps += named.iter().any(|n| n == "drift") as usize;
        false_names += named
            .iter()
            .filter(|n| !case.effects.contains(&n.as_str()))
            .count();
        let g = &d.signatures;
        lines.push(format!(
            "seed {seed} ({}): named {named:?}, {ratio:.2}x; holds' gap {:.1} mV, tail {:.1} mV",
            case.describe(),
            1e3 * g.held_loop_v,
            1e3 * g.tail_v
        ));
        if std::env::var("GAP_DEBUG").is_ok() {
            lines.push(d.table());
            for (i, t) in d.tried.iter().enumerate() {
                lines.push(format!("  tried at step {}: {t:?}", i + 1));
            }
        }
    }
    let report = lines.join("\n");
    println!("{report}");
    println!(
        "hysteresis named on {loops} of {n}, drift on {creeps}, {false_names} false names",
        n = seeds.len()
    );
    if only.is_none() {
        assert_eq!(loops, seeds.len(), "{report}");
        assert_eq!(
            creeps,
            seeds.len(),
            "drift named on {creeps} of 16\n{report}"
        );
        assert!(false_names <= 4, "{false_names} false names\n{report}");
    }
}

/// A creep alone on random levels with few long holds takes no loop: the guard of session
/// 29's rule (`Signatures::held_loop_untold`), which admits the loop beside a drift where the
/// held levels give no answer (the levels reached from below all at one end). The families'
/// log and power creeps, which the drift's three lags fit only in part, on the inputs of the
/// thesis-stage test of that rule (`piezo synth --protocol steps`, holds of 1.5-3 s, its
/// seeds 54-56 and three more), seeds 5401-5406 for the creeps: `hysteresis` must be named
/// on none, and `drift` on every one.
#[test]
fn a_creep_alone_on_few_long_holds_takes_no_loop() {
    use host_tests::sim::synth::{SynthSpec, synth};
    if cfg!(debug_assertions) {
        return;
    }
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let inputs: [(u64, f64, f64, f64, f64, f64); 6] = [
        // (seed, seconds, rate Hz, lowest input V, span V, hold s)
        (54, 24.0, 4_000.0, 1.0, 8.0, 3.0),
        (55, 16.0, 2_000.0, 0.5, 9.0, 1.6),
        (56, 30.0, 1_000.0, 0.0, 9.0, 1.5),
        (50, 20.0, 2_000.0, 0.5, 9.0, 2.0),
        (52, 20.0, 2_000.0, 0.5, 9.0, 2.0),
        (53, 30.0, 1_000.0, 0.0, 10.0, 2.5),
    ];
    let mut lines = Vec::new();
    let mut failed = Vec::new();
    for (i, (seed, seconds, rate, offset, amplitude, hold)) in inputs.into_iter().enumerate() {
        let spec = SynthSpec::steps(
            "thesis-linear",
            (seed, seconds, rate),
            (offset, amplitude),
            Some(hold),
        );
        let rec = synth(&spec).unwrap();
        let protocol = Protocol::one_record(
            Family::RandomLevels,
            "levels.csv",
            (rec.t_s.clone(), rec.u_v.clone()),
            format!("{rate:.0} Hz {seconds:.0} s, holds {hold} s"),
            (Some(rate), true),
        );
        let case_seed = 5401 + i as u64;
        let mut rng = StdRng::seed_from_u64(case_seed);
        let case = Case {
            creep: Some(Creep::draw(&mut rng)),
            ..Case::of(case_seed, protocol, vec!["drift"])
        };
        let d = diagnose(&base, &case.records(), &Options::default()).expect("diagnosis");
        let ratio = d.final_rms_v / d.noise_floor_v;
        let line = format!(
            "seed {case_seed} ({}): named {:?}, {ratio:.2}x",
            case.describe(),
            d.named
        );
        if d.named.iter().any(|n| n == "hysteresis") || !d.named.iter().any(|n| n == "drift") {
            failed.push(line.clone());
        }
        lines.push(line);
    }
    println!("{}", lines.join("\n"));
    assert!(failed.is_empty(), "{failed:#?}");
}

/// A creep on records without holds is named as drift: the families' log and power creeps
/// alone on one long sine or one chirp (seeds 6101-6106, drawn after session 31's rule was
/// shaped on seed 6008, a creep and a PI loop on a sine). Such a creep counts from the record's
/// first input, the model's drift starts settled there: the drift is admissible only beside an
/// offset that takes its settled creep back (`select::creep_start`, step 12 of GAP.md), and its
/// slowest lag (longer than a third of the record) leaves that constant loose. Measured in
/// session 31: `drift` alone on all six, 1.01-1.70x the floor (before: on three, 6102, 6104
/// and 6106, at 6.61, 17.1 and 1.70x; nothing on 6101, 6103 and 6105, at 6.8-16.3x). 6107
/// and 6108 of the same draw, left out for time: now `drift` at 1.78 and 1.36x, before a false
/// `hysteresis` at 11.7x and `drift` at 1.36x. Asserted: `drift` named on every case and
/// nothing else, each ending within 2x its floor.
#[test]
fn a_creep_without_holds_is_named_as_drift() {
    if cfg!(debug_assertions) {
        return;
    }
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let mut lines = Vec::new();
    let mut failed = Vec::new();
    for seed in 6101..=6106u64 {
        let mut rng = StdRng::seed_from_u64(seed);
        let family = if seed % 2 == 0 {
            Family::LongSine
        } else {
            Family::Sweep
        };
        let protocol = draw_protocol(family, &mut rng);
        // (the loop the creep-and-loop probe of the same seeds draws, not used here, keeps
        // the creep's draw the same)
        let _ = Hysteresis::draw(&mut rng);
        let case = Case {
            creep: Some(Creep::draw(&mut rng)),
            ..Case::of(seed, protocol, vec!["drift"])
        };
        let d = diagnose(&base, &case.records(), &Options::default()).expect("diagnosis");
        let ratio = d.final_rms_v / d.noise_floor_v;
        let line = format!(
            "seed {seed} ({}): named {:?}, {ratio:.2}x",
            case.describe(),
            d.named
        );
        if d.named != ["drift"] || ratio > 2.0 {
            failed.push(line.clone());
        }
        lines.push(line);
    }
    println!("{}", lines.join("\n"));
    assert!(failed.is_empty(), "{failed:#?}");
}

/// A stage parked after a scan that died away around another level than the record's first
/// input (a lab's stage left after work elsewhere, then moved to where the record starts):
/// one long sine each (the families' protocol), a Prandtl-Ishlinskii or Preisach truth (forms
/// a table holds, so that what differs is the start), the scan drawn off the start search's
/// grid: centred 1.5-2.5 V from the first input towards the middle of the range, its first
/// excursion 1-2.5 V past the first input (so that the move there leaves its outer turns in
/// the memory), each turn 0.55-0.8 of the last. The same stage at rest at the record's first
/// input is the reference. A guard at the figures measured in session 34 (`GAP.md`): parked,
/// `hysteresis` named and no name the reference lacks, and the final residual within 2.5x of
/// the reference's or 2x the floor (measured 0.72-1.07x of it with session 33's candidates,
/// 0.99-2.03x with session 34's: the start search picks from a grid of rest states, and an
/// off-grid one is fitted by the nearest, which leaves part of its head). Session 41: 4203's
/// parked stage no longer names the false `sensor-gain` its reference names (a look-alike of
/// a curvature, named only beside a stepping stone the final check took out) and ends at
/// 3.69x the floor, 2.07x its reference's 1.78x.
#[test]
fn a_stage_parked_after_a_scan_elsewhere_is_fitted_from_there() {
    // (the scan's last turn, volts: below the table's grid step)
    const SCAN_END_V: f64 = 0.05;
    if cfg!(debug_assertions) {
        return;
    }
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let mut lines = Vec::new();
    let mut failed = Vec::new();
    for seed in 4201..=4204u64 {
        let mut rng = StdRng::seed_from_u64(seed);
        let protocol = draw_protocol(Family::LongSine, &mut rng);
        let hysteresis = loop {
            let h = Hysteresis::draw(&mut rng);
            if matches!(h.form, HystForm::Pi { .. } | HystForm::Preisach { .. }) {
                break h;
            }
        };
        let u0: f64 = protocol.records[0].u_v[0];
        let towards: f64 = if u0 > 5.0 { -1.0 } else { 1.0 };
        let distance = rng.gen_range(1.5..2.5);
        let centre = u0 + towards * distance;
        let mut amp: f64 = distance + rng.gen_range(1.0..2.5);
        let decay = rng.gen_range(0.55..0.8);
        // (from a turn on the far side, one step larger, so that every truth's operator,
        // PI plays centred there or a Preisach plane come up from its bottom, holds the scan
        // from its first turn; then the first excursion past the first input)
        let mut sign = -towards;
        let mut scan = vec![(centre + towards * amp / decay).clamp(0.0, 10.0)];
        while amp > SCAN_END_V {
            scan.push((centre + sign * amp).clamp(0.0, 10.0));
            amp *= decay;
            sign = -sign;
        }
        let run = |before: Vec<f64>| {
            let case = Case {
                hysteresis: Some(Hysteresis {
                    before,
                    ..hysteresis.clone()
                }),
                ..Case::of(seed, protocol.clone(), vec!["hysteresis"])
            };
            let d = diagnose(&base, &case.records(), &Options::default()).expect("diagnosis");
            (d.named.clone(), d.final_rms_v / d.noise_floor_v)
        };
        let (named, parked) = run(scan.clone());
        let (named_at_rest, at_rest) = run(Vec::new());
        let line = format!(
            "seed {seed} ({}, first input {u0:.2} V, scan {scan:.2?}): named {named:?}, \
             {parked:.2}x the floor (at rest {named_at_rest:?}, {at_rest:.2}x)",
            hysteresis.form.label()
        );
        if !named.iter().any(|n| n == "hysteresis")
            || named.iter().any(|n| !named_at_rest.contains(n))
            || parked > (2.5 * at_rest).max(2.0)
        {
            failed.push(line.clone());
        }
        lines.push(line);
    }
    println!("{}", lines.join("\n"));
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}

/// The final check's unshown offset beside a curvature and no table (GAP.md, step 7): a
/// softplus or tanh curvature with a sensor offset on one chirp (seeds 3252, 3638), whose
/// inputs stay above 1.9 V, name the curvature alone; the offset, taken out as a level the
/// residual without it does not show, is reported as one the records cannot tell from the
/// curvature's work (it was in no pair before session 59). Written on these cases: a guard.
#[test]
fn an_offset_a_curvature_took_up_is_reported() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    for seed in [3252, 3638] {
        let d = diagnose(&base, &Case::draw(seed).records(), &Options::default()).unwrap();
        assert_eq!(d.named, ["nonlinear-gain"], "seed {seed}: {}", d.table());
        assert!(
            d.cannot_tell.iter().any(|c| c.named == "nonlinear-gain"
                && c.alternative == "offset"
                && c.taken_out == gap::select::TakenOut::Unshown),
            "seed {seed}: {}",
            d.table()
        );
    }
}

/// Step 21 end to end, on two drawn cases of random levels (`select.rs`; the unit test beside
/// `everett::CentreLine::Own` checks the basis): a Lorentz Preisach plane alone (seed 3450),
/// once named with a false curvature that took back the band split's bent centre line (2.75x
/// the floor), is named alone, the curvature's removal said in a step and the pair reported;
/// an exponential K'(u) beside a Gaussian plane (seed 3594), a curvature the own-line table
/// does not take, keeps it, and the table moves to the own-line split. Both within 1.5x the
/// floor (measured 1.21x and 0.99x). Written on these cases: a guard of the step, not
/// evidence of its generality (the families suite's other seeds are).
#[test]
fn a_curvature_that_is_the_band_splits_own_centre_line_goes() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let run = |seed: u64| {
        let data = Case::draw(seed).records();
        diagnose(&base, &data, &Options::default()).expect("diagnosis")
    };
    let d = run(3450);
    assert_eq!(d.named, ["hysteresis"], "{}", d.table());
    assert!(
        d.steps.iter().any(|s| s.effect == "nonlinear-gain"
            && s.removed
            && s.evidence.starts_with("the table's own centre line")),
        "{}",
        d.table()
    );
    assert!(
        d.cannot_tell
            .iter()
            .any(|c| c.named == "hysteresis" && c.alternative == "nonlinear-gain")
    );
    assert!(d.final_rms_v < 1.5 * d.noise_floor_v, "{}", d.table());
    let d = run(3594);
    let mut named = d.named.clone();
    named.sort();
    assert_eq!(named, ["hysteresis", "nonlinear-gain"], "{}", d.table());
    assert!(
        d.steps.iter().any(|s| s.effect == "hysteresis"
            && s.refit
            && s.evidence.starts_with("the table's own centre line")),
        "{}",
        d.table()
    );
    assert!(d.final_rms_v < 1.5 * d.noise_floor_v, "{}", d.table());
}

/// Step 21 beside the span split's table (session 60), on two drawn Lorentz Preisach planes
/// alone, whose generator takes the plane's centre curve out: on the identification protocol
/// (seed 8286) a curvature, an offset and a scale once named together beside the span split's
/// table (3.14x the floor) go together, each removal said in a step and each pair reported;
/// on random levels (seed 8093) a curvature alone (2.14x) goes. Both are then named
/// `hysteresis` alone, the table on the own-line split, and end nearer the floor than before
/// (measured 2.50x and 1.30x; bound 3x and 1.5x). Written on these cases: a guard of the step,
/// not evidence of its generality (the families suite's other seeds are).
#[test]
fn static_shapes_beside_the_span_splits_table_go_on_its_own_line() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    for (seed, gone, bound) in [
        (8286, &["nonlinear-gain", "offset", "sensor-gain"][..], 3.0),
        (8093, &["nonlinear-gain"][..], 1.5),
    ] {
        let data = Case::draw(seed).records();
        let d = diagnose(&base, &data, &Options::default()).expect("diagnosis");
        assert_eq!(d.named, ["hysteresis"], "seed {seed}\n{}", d.table());
        for e in gone {
            assert!(
                d.steps.iter().any(|s| s.effect == *e
                    && s.removed
                    && s.evidence.starts_with("the table's own centre line")),
                "seed {seed}: {e}\n{}",
                d.table()
            );
            assert!(
                d.cannot_tell
                    .iter()
                    .any(|c| c.named == "hysteresis" && c.alternative == *e),
                "seed {seed}: {e}"
            );
        }
        assert!(
            d.final_rms_v < bound * d.noise_floor_v,
            "seed {seed}\n{}",
            d.table()
        );
    }
}

/// Step 14 end to end, on two drawn cases (`select.rs`; the unit test beside `scale_order`
/// checks the fits): a tanh-like curvature alone on the identification protocol (seed 1079),
/// once named with a false 0.2 % scale, is named alone, its K'(u) with a cubic term, the
/// scale's removal said in a step (and the pair reported where step 14 took it out; since
/// session 61 the final check takes it out beside step 14 (e)'s cubic); an exp curvature with a 20 mV offset
/// on a long sine (seed 1222), once named with a false 1.8 % scale in the offset's place, is
/// named with the offset (swapped in by step 14 (b) until session 58; since, the final check
/// takes the scale out first), and both end within 1.5x the floor; step 14 (c) on a
/// third (seed 1593, below), and the orders above the cubic on a fourth (seed 2577, below).
#[test]
fn a_scale_beside_a_curvature_gives_way_to_its_cubic_or_to_an_offset() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let run = |seed: u64| {
        let data = Case::draw(seed).records();
        diagnose(&base, &data, &Options::default()).expect("diagnosis")
    };
    let d = run(1079);
    assert_eq!(d.named, ["nonlinear-gain"], "{}", d.table());
    let higher = d.model.nonlinear_gain.as_ref().unwrap().poly[3..].to_vec();
    assert!(higher.iter().any(|c| *c != 0.0) && d.model.sensor_gain.is_none());
    // (the scale's removal is said in a step: step 14's, the curvature of higher order in its
    // place (its parameters, the pair reported), or since session 61 the final check's,
    // beside the curvature that step 14 (e) refitted to its own order first on these records,
    // which start at rest at 0 V: there the scale did not earn its place, no look-alike)
    let by_step_14 = d.steps.iter().any(|s| {
        s.effect == "sensor-gain"
            && s.removed
            && s.params
                .keys()
                .any(|k| k.starts_with('c') && k != "c1_per_v" && k != "c2_per_v2")
    }) && d
        .cannot_tell
        .iter()
        .any(|c| c.named == "nonlinear-gain" && c.alternative == "sensor-gain");
    let own_order = d.steps.iter().position(|s| {
        s.effect == "nonlinear-gain" && s.refit && s.evidence.starts_with("a curvature of order")
    });
    let by_final_check = own_order.is_some_and(|i| {
        d.steps[i..].iter().any(|s| {
            s.effect == "sensor-gain"
                && s.removed
                && s.evidence.starts_with("removed in the final check")
        })
    });
    assert!(by_step_14 || by_final_check, "{}", d.table());
    assert!(d.final_rms_v < 1.5 * d.noise_floor_v);
    let d = run(1222);
    let mut named = d.named.clone();
    named.sort();
    assert_eq!(named, ["nonlinear-gain", "offset"], "{}", d.table());
    assert!(d.model.sensor_gain.is_none());
    // (since session 58 the final check takes the scale out first, its removal leaving less
    // above the floor, where it took the offset out first as a level the residual did not
    // show and step 14 (b) swapped it back in for the scale: either way a step says the
    // scale went)
    assert!(d.steps.iter().any(|s| {
        (s.effect == "offset" && !s.removed && s.evidence.starts_with("swapped in for sensor-gain"))
            || (s.effect == "sensor-gain" && s.removed)
    }));
    // (no pair left that names the scale)
    assert!(
        d.cannot_tell
            .iter()
            .all(|c| c.neither_named || c.named != "sensor-gain")
    );
    assert!(d.final_rms_v < 1.5 * d.noise_floor_v);
    // Step 14 (c): a softplus curvature alone on a long sine (seed 1593), once named with a
    // false 3 mV offset beside the cubic that took its scale's place, is named alone.
    let d = run(1593);
    assert_eq!(d.named, ["nonlinear-gain"], "{}", d.table());
    assert!(d.model.offset.is_none() && d.model.sensor_gain.is_none());
    assert!(d.steps.iter().any(|s| {
        s.effect == "offset"
            && s.removed
            && s.params
                .keys()
                .any(|k| k.starts_with('c') && k != "c1_per_v" && k != "c2_per_v2")
    }));
    assert!(
        d.cannot_tell
            .iter()
            .any(|c| c.named == "nonlinear-gain" && c.alternative == "offset")
    );
    assert!(d.final_rms_v < 1.5 * d.noise_floor_v);
    // Above the cubic (session 49): a tanh plateau alone on one sine over 1.4-9.3 V (seed
    // 2577), once named with a false 1.6 % scale at 4.22x the floor (the cubic without the
    // scale left 1.7x as much above the floor), is named alone with K'(u) of a higher order,
    // the pair reported, and ends lower than with the scale.
    let d = run(2577);
    assert_eq!(d.named, ["nonlinear-gain"], "{}", d.table());
    let poly = d.model.nonlinear_gain.as_ref().unwrap().poly;
    assert!(poly[4..].iter().any(|c| *c != 0.0) && d.model.sensor_gain.is_none());
    assert!(
        d.cannot_tell
            .iter()
            .any(|c| c.named == "nonlinear-gain" && c.alternative == "sensor-gain")
    );
    assert!(d.final_rms_v < 3.0 * d.noise_floor_v, "{}", d.table());
}

/// GAP.md step 9's pairs: without holds, a drift whose lags stand for an offset beside a scale
/// or a curvature (a 20-25 s lag started settled at the first input holds the offset, a 2.5 ms
/// one the scale) gives way to the shape fitted with an offset, which is named as one step, and
/// the pair is reported. Seeds 1597 (a scale and an offset on one long sine) and 1647 (a
/// curvature and an offset): each was named `drift` before.
#[test]
fn a_drift_without_holds_gives_way_to_a_shape_with_an_offset() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    for (seed, shape) in [(1597, "sensor-gain"), (1647, "nonlinear-gain")] {
        let data = Case::draw(seed).records();
        let d = diagnose(&base, &data, &Options::default()).expect("diagnosis");
        let mut named = d.named.clone();
        named.sort();
        let mut want = vec![shape, "offset"];
        want.sort();
        assert_eq!(named, want, "seed {seed}: {}", d.table());
        assert!(
            d.steps
                .iter()
                .any(|s| s.effect == format!("{shape}+offset") && !s.removed),
            "seed {seed}"
        );
        assert!(
            d.cannot_tell
                .iter()
                .any(|c| c.named == shape && c.alternative == "drift"),
            "seed {seed}"
        );
        assert!(d.final_rms_v < 1.5 * d.noise_floor_v, "seed {seed}");
    }
}

/// GAP.md step 15: beside a loop of another form, the static shapes that leave alike in each
/// other's place: the one with the fewest parameters is named (seed 1615, a
/// Prandtl-Ishlinskii loop and a 1.1 % scale on random levels, where a curvature was named),
/// and where two have as few, neither (seed 1684, a Preisach loop alone on one long sine,
/// where a scale was named and an offset and a curvature left as little; since session 46
/// the scale a later step names there goes by step 17, reported beside the loop).
#[test]
fn beside_a_loop_the_simplest_of_alike_static_shapes_is_named() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let run = |seed: u64| {
        let data = Case::draw(seed).records();
        diagnose(&base, &data, &Options::default()).expect("diagnosis")
    };
    let d = run(1615);
    let mut named = d.named.clone();
    named.sort();
    assert_eq!(named, ["hysteresis", "sensor-gain"], "{}", d.table());
    assert!(d.steps.iter().any(|s| s.effect == "sensor-gain"
        && !s.removed
        && s.evidence.starts_with("swapped in for nonlinear-gain")));
    assert!(d.cannot_tell.iter().any(|c| c.named == "sensor-gain"
        && c.alternative == "nonlinear-gain"
        && !c.neither_named));
    let d = run(1684);
    assert_eq!(d.named, ["hysteresis"], "{}", d.table());
    // (since session 46 the scale a step named there goes by step 17, the records having no
    // held level to tell it from the loop's centre line, and the pair says so)
    assert!(
        d.cannot_tell
            .iter()
            .any(|c| (c.named == "sensor-gain" && c.neither_named)
                || (c.named == "hysteresis" && c.alternative == "sensor-gain")),
        "{}",
        d.table()
    );
}

/// GAP.md step 16: a table is memory, and its gate is read on what a map of the input alone
/// leaves. A tanh or softplus curvature with an offset on a chirp (seeds 1699 and 1356), read
/// against the input in the chirp's faster octaves, drew a loop of 3-6 mV through the stage's
/// dynamics, and the table's memoryless parts took the curvature: `hysteresis` was named alone
/// at the floor. The memoryless twin leaves no loop there, the table is not admissible, and the
/// truth's two shapes are named. A stage's loop is left whole by any map: the twin's trace
/// entry of a loop case (seed 1615, a Prandtl-Ishlinskii loop on random levels) says the loop
/// is shown, and hysteresis is named.
#[test]
fn a_static_curvature_on_a_chirp_is_not_a_loop() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    for seed in [1699, 1356] {
        let data = Case::draw(seed).records();
        let d = diagnose(&base, &data, &Options::default()).expect("diagnosis");
        let mut named = d.named.clone();
        named.sort();
        assert_eq!(
            named,
            ["nonlinear-gain", "offset"],
            "seed {seed}: {}",
            d.table()
        );
        // (the first step's twin left no loop: its gate said no)
        let twin = d.tried[0]
            .iter()
            .find(|t| t.0 == gap::memory::TWIN_NAME)
            .unwrap_or_else(|| panic!("seed {seed}: no twin at step 1"));
        assert!(!twin.3, "seed {seed}: {twin:?}");
        assert!(d.final_rms_v < 1.5 * d.noise_floor_v, "seed {seed}");
    }
    let data = Case::draw(1615).records();
    let d = diagnose(&base, &data, &Options::default()).expect("diagnosis");
    assert!(d.named.iter().any(|n| n == "hysteresis"), "{}", d.table());
    let twin = d
        .tried
        .iter()
        .flatten()
        .find(|t| t.0 == gap::memory::TWIN_NAME)
        .expect("a twin of the loop");
    assert!(twin.3, "{twin:?}");
}

/// GAP.md step 10 (session 47): without holds, a drift that explains less than the static
/// shape a step drops as a look-alike goes with it. On one long sine, a loop beside a scale
/// (seed 1540) or a curvature (seed 2000), the shapes were dropped as look-alikes and the
/// drift, leaving 1.5-1.6x what the curvature left, was named in their place by its lags'
/// constant and scale. Now the loop is named without a drift, and the drift is reported as
/// one the records cannot tell from a static shape.
#[test]
fn without_holds_a_drift_no_better_than_a_shape_is_not_named() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    for seed in [1540, 2000] {
        let data = Case::draw(seed).records();
        let d = diagnose(&base, &data, &Options::default()).expect("diagnosis");
        assert!(
            d.named.iter().any(|n| n == "hysteresis"),
            "seed {seed}: {}",
            d.table()
        );
        assert!(
            !d.named.iter().any(|n| n == "drift"),
            "seed {seed}: {}",
            d.table()
        );
        assert!(
            d.cannot_tell.iter().any(|c| c.alternative == "drift"),
            "seed {seed}: the drift is not reported: {}",
            d.table()
        );
    }
}

/// Never silent where the memoryless twin keeps a loop out (step 16a) and nothing else takes
/// the residual down. Families case 3219, a Preisach loop and a 2.5 % scale on random levels
/// that reach each of their nine levels once: a map through the nine levels explains as much
/// as the table, and the diagnosis named nothing at 227x the floor without a word on the
/// loop. The pair is said now, with what each side left; nothing false is named.
#[test]
fn a_loop_the_twin_keeps_out_is_reported_when_the_records_stay_above_the_floor() {
    let case = Case::draw(3219);
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let d = diagnose(&base, &case.records(), &Options::default()).expect("diagnosis");
    assert!(
        d.named.iter().all(|n| case.effects.contains(&n.as_str())),
        "{}",
        d.table()
    );
    let pair = d
        .cannot_tell
        .iter()
        .find(|c| {
            [c.named.as_str(), c.alternative.as_str()].contains(&"hysteresis")
                && [c.named.as_str(), c.alternative.as_str()].contains(&"nonlinear-gain")
        })
        .unwrap_or_else(|| panic!("the loop / curve pair is reported: {}", d.table()));
    // (both sides leave little beside the residual the diagnosis ends with)
    assert!(
        pair.rms_v < 0.5 * d.final_rms_v && pair.alternative_rms_v < 0.5 * d.final_rms_v,
        "{pair:?}"
    );
}

/// A creep that counts from the records' first input (GAP.md step 18). Families case 3131, a
/// power-law creep alone on random levels that start at 8.5 V: the model's lags start settled
/// there, so the drift alone pays the settled creep at every sample and fitted zero gains, and
/// a curvature, a scale and a loop were named at the floor in its place (three false names).
/// Fitted with the offset that takes that creep back, the drift is the first step's choice,
/// and step 12 moves the offset into the drift's start: the drift alone, near the floor.
#[test]
fn a_creep_from_the_first_input_is_fitted_with_its_start() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let d = diagnose(&base, &Case::draw(3131).records(), &Options::default()).expect("diagnosis");
    assert_eq!(d.named, vec!["drift".to_string()], "{}", d.table());
    let pair = d
        .tried
        .first()
        .and_then(|step| step.iter().find(|t| t.0 == "drift+offset"))
        .expect("the pair is tried at the first step");
    let alone = d.tried[0]
        .iter()
        .find(|t| t.0 == "drift")
        .expect("drift tried");
    assert!(
        pair.3 && pair.2 > 0.99 && alone.2 < 0.1,
        "{pair:?} {alone:?}"
    );
    assert!(
        d.model.drift.as_ref().and_then(|x| x.unsettled_v).is_some(),
        "the drift's start: {}",
        d.table()
    );
    assert!(d.final_rms_v <= 1.5 * d.noise_floor_v, "{}", d.table());
}

/// GAP.md step 16a (session 48): where the held levels cannot tell a loop (every step up of a
/// random-levels record landed above 5 V and every step down below it, so the direction into
/// a hold follows from its level), the memoryless twin asks the records instead. Families
/// case 2548, a 6.7 % Bouc-Wen loop and an offset on random levels: the gate refused the
/// table (explaining 99.6 % of the base residual above the floor) and `nonlinear-gain` was
/// named alone at 144x the floor; the best map of the input alone leaves 12 % of it, 29 times
/// what the table leaves, so the loop is named now and no static shape the truth lacks is.
/// Cases 1019 and 1024 (static shapes only, on the same protocol) keep their loop out: their
/// twins explain all of it.
#[test]
fn untold_held_levels_leave_the_loop_to_the_memoryless_twin() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let d = diagnose(&base, &Case::draw(2548).records(), &Options::default()).expect("diagnosis");
    assert!(d.named.iter().any(|n| n == "hysteresis"), "{}", d.table());
    assert!(
        d.named
            .iter()
            .all(|n| ["hysteresis", "offset"].contains(&n.as_str())),
        "{}",
        d.table()
    );
    let twin = d
        .tried
        .first()
        .and_then(|step| step.iter().find(|t| t.0 == gap::memory::TWIN_NAME))
        .expect("the twin is tried at the first step");
    assert!(
        twin.3 && twin.2 <= 1.0 - gap::select::UNTOLD_TWIN_LEFT_MIN,
        "{twin:?}"
    );
    for seed in [1019, 1024] {
        let d = diagnose(&base, &Case::draw(seed).records(), &Options::default()).unwrap();
        assert!(
            !d.named.iter().any(|n| n == "hysteresis"),
            "seed {seed}: {}",
            d.table()
        );
    }
}

/// Issue #12's single-sine requirement (one 10 s record at 5 kHz of a 1 Hz sine over
/// 0.5-9.5 V, a Preisach-class loop 10-15 % of the span, a sensor offset of 10-30 mV either
/// sign, 1 mV of noise) with loops this workflow was not shaped on: Preisach planes
/// (Gaussian or Lorentzian density) and Prandtl-Ishlinskii operators with random radii, drawn
/// as the suite draws them, with monotone branches (a Preisach density is >= 0), half of them
/// after earlier excursions. A probe, not a gate: it prints each seed's names, final residual,
/// whether a missed offset is reported as one the records cannot tell, and the count meeting
/// the requirement (`SINE_SEEDS=a,b,...`, default 7001-7016; `GAP_DEBUG=1` each diagnosis'
/// table; `SINE_CENTRE=1` the truth's centre line over the record's cycles after the first,
/// less `g u` and the offset, by 0.5 V bin: how far the relays the sine never switches bend
/// it). Measured in session 56 (GAP.md): the requirement met on 1 of 16, the final residual
/// within 2x the floor on 3; in session 57, with step 20's tents: met on 1, within 2x on 6.
#[test]
#[ignore = "a probe of issue #12's single-sine requirement on the families' loops"]
fn the_issues_single_sine_with_the_families_loops() {
    let seeds: Vec<u64> = std::env::var("SINE_SEEDS").map_or((7001..7017).collect(), |s| {
        s.split(',').map(|x| x.parse().unwrap()).collect()
    });
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let runs = host_tests::util::par_map(&seeds, |&seed| {
        let mut rng = StdRng::seed_from_u64(seed);
        let hysteresis = loop {
            let mut h = Hysteresis::draw(&mut rng);
            if matches!(h.form, HystForm::Preisach { .. } | HystForm::Pi { .. })
                && h.min_slope() >= 0.0
            {
                // The requirement's loop: 10-15 % of the span.
                let share = rng.gen_range(0.10..0.15);
                h.scale *= share / h.share;
                h.share = share;
                break h;
            }
        };
        let offset_v = rng.gen_range(0.01..0.03) * if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
        let rate_hz = 5_000.0;
        let t_s: Vec<f64> = (0..50_000).map(|i| i as f64 / rate_hz).collect();
        let u_v = t_s
            .iter()
            .map(|t| 5.0 - 4.5 * (2.0 * std::f64::consts::PI * t).cos())
            .collect();
        let protocol = Protocol::one_record(
            Family::LongSine,
            "sine.csv",
            (t_s, u_v),
            "5 kHz 10 s, 1 Hz sine 5.0 +- 4.5 V".into(),
            (None, false),
        );
        let mut case = Case::of(seed, protocol, vec!["hysteresis", "offset"]);
        case.hysteresis = Some(hysteresis);
        case.offset_v = Some(offset_v);
        let recs = case.records();
        if std::env::var("SINE_CENTRE").is_ok() {
            // The truth's centre line over the record's cycles after the first: in each
            // 0.5 V bin of the input, the mean of its rising and of its falling samples, less
            // g u and the offset, averaged.
            let r = &recs[0];
            let g = base.plant.static_gain;
            let nb = 18;
            let mut up = vec![(0.0, 0usize); nb];
            let mut dn = vec![(0.0, 0usize); nb];
            for i in 5_000..r.u_v.len() - 1 {
                let k = (((r.u_v[i] - 0.5) / 9.0 * nb as f64) as usize).min(nb - 1);
                let e = r.y_v[i] - g * r.u_v[i] - offset_v;
                let b = if r.u_v[i + 1] > r.u_v[i] {
                    &mut up[k]
                } else {
                    &mut dn[k]
                };
                b.0 += e;
                b.1 += 1;
            }
            let c: Vec<f64> = (0..nb)
                .map(|k| 0.5 * (up[k].0 / up[k].1 as f64 + dn[k].0 / dn[k].1 as f64))
                .collect();
            println!(
                "seed {seed}: centre line less g u, mV by bin: {:?}",
                c.iter().map(|x| (1e3 * x).round()).collect::<Vec<_>>()
            );
        }
        let d = diagnose(&base, &recs, &Options::default()).expect("diagnosis");
        (case.describe(), d)
    });
    let mut met = 0;
    for (seed, (describe, d)) in seeds.iter().zip(&runs) {
        let mut named = d.named.clone();
        named.sort();
        let ratio = d.final_rms_v / d.noise_floor_v;
        let ok = named == ["hysteresis", "offset"] && ratio <= 2.0;
        met += usize::from(ok);
        if std::env::var("GAP_DEBUG").is_ok() {
            println!("{}", d.table());
        }
        let offset_said = d
            .cannot_tell
            .iter()
            .any(|k| k.named == "offset" || k.alternative == "offset");
        println!(
            "{} seed {seed}: named {named:?}, final {ratio:.2}x the floor, offset {:.1} mV{}; {describe}",
            if ok { "ok  " } else { "MISS" },
            1e3 * d.model.offset.as_ref().map_or(0.0, |o| o.offset_v),
            if offset_said {
                " (offset: cannot tell)"
            } else {
                ""
            },
        );
    }
    println!("the requirement met on {met} of {} seeds", seeds.len());
}

/// A creep beside a loop whose held levels' gap the creep's tails dwarf (session 61, fresh
/// seed 9001: a Gaussian Preisach plane with a 5.5 % loop beside a power-law creep on random
/// levels; tails of 86 mV against an 11 mV gap, so the table alone is held back, while the
/// drift alone explains nothing). Named nothing at 120x the floor before; the joint creep and
/// loop step, offered where the drift alone explains less than `MIN_EXPLAINED`, names both
/// (measured 1.06x; bound 1.5x). Written on this case: a guard of the rule, not evidence of
/// its generality (the families suite's other seeds are).
#[test]
fn a_creep_the_drift_alone_cannot_take_is_fitted_with_its_loop() {
    let (d, named) = diagnosed_sorted(9001);
    assert_eq!(named, ["drift", "hysteresis"], "{}", d.table());
    assert!(
        d.steps.iter().any(|s| s.effect == "drift+hysteresis"),
        "{}",
        d.table()
    );
    assert!(d.final_rms_v < 1.5 * d.noise_floor_v, "{}", d.table());
}

/// Step 14 (e) on the identification protocol (session 61, fresh seeds 9192 and 9044: a tanh
/// curvature beside a 1.3 % and a 0.7 % scale). Beside the catalogue's quadratic the scale
/// was taken out by the final check (9192, 12x the floor) or never explained enough to be
/// named (9044, 5.7x); with K'(u) refitted to its own order before the final check, and the
/// scale offered beside it, both are named and end near the floor (measured 1.11x and 1.10x;
/// bound 1.5x), K'(u) above the quadratic. Written on these cases: a guard of the step.
#[test]
fn a_curvature_of_its_own_order_keeps_the_scale_beside_it() {
    for seed in [9192, 9044] {
        let (d, named) = diagnosed_sorted(seed);
        assert_eq!(
            named,
            ["nonlinear-gain", "sensor-gain"],
            "seed {seed}\n{}",
            d.table()
        );
        let higher = d.model.nonlinear_gain.as_ref().unwrap().poly[3..].to_vec();
        assert!(higher.iter().any(|c| *c != 0.0), "seed {seed}");
        assert!(
            d.final_rms_v < 1.5 * d.noise_floor_v,
            "seed {seed}\n{}",
            d.table()
        );
    }
}

/// A step down to a held level rings the model's output past the record while the input
/// holds (session 62, fresh seed 10264: a Lorentzian Preisach plane with a 7.9 % loop on
/// random levels, the lowest held level 1.29 V for 0.12 s). The saturation test read the
/// line's ringing there as the model's output going on where the record stood still, and the
/// diagnosis refused the record as a saturated sensor; the line's move now counts only as far
/// as the input's own goes. Diagnosed, the loop is named and ends near the floor (measured
/// 1.12x; bound 1.5x). Written on this case: a guard of the refusal's reading, beside the
/// saturated sine that `gap.rs` still refuses.
#[test]
fn a_ringing_after_a_step_to_the_lowest_level_is_not_a_saturated_sensor() {
    let (d, named) = diagnosed_sorted(10264);
    assert_eq!(named, ["hysteresis"], "{}", d.table());
    assert!(d.final_rms_v < 1.5 * d.noise_floor_v, "{}", d.table());
}

/// Without holds, near the floor, a drift gives way to a static shape that leaves alike in
/// every record (session 62, fresh seed 10292: a Bouc-Wen loop of 5.4 % beside a 0.75 % scale
/// on one long sine). After the table the drift left 1.01 mV and the scale 1.02 mV over a
/// 1.01 mV floor; their pooled shares left (0.08 % against 0.56 %) are both noise, and their
/// ratio named a false `drift`. Now no drift is named; the static shapes it gave way to are
/// alike among themselves and beside the table, and the true scale is reported in a pair
/// (honest, not exact). Written on this case: a guard of the rule.
#[test]
fn without_holds_a_drift_alike_near_the_floor_is_not_named() {
    let (d, named) = diagnosed_sorted(10292);
    assert!(!named.iter().any(|n| n == "drift"), "{}", d.table());
    assert!(named.iter().any(|n| n == "hysteresis"), "{}", d.table());
    assert!(
        named.iter().any(|n| n == "sensor-gain")
            || d.cannot_tell
                .iter()
                .any(|c| c.named == "sensor-gain" || c.alternative == "sensor-gain"),
        "{}",
        d.table()
    );
    assert!(d.final_rms_v < 1.5 * d.noise_floor_v, "{}", d.table());
}

/// The table's level is read as a sensor offset (step 13a) only where the records show the
/// stage's start was a scan that died away at the first input (session 63). Fresh seeds 10116
/// (a Lorentzian Preisach plane of 8.8 % on random levels, after excursions to 6.8, 7.1 and
/// 3.2 V) and 9088 (a Bouc-Wen loop of 5.4 % on one long sine, at rest with no hysteretic
/// state), no sensor offset in either: the start search kept a centred scan, and step 13a
/// named false offsets of 168 and 30 mV. Refitted on an off-centre start, both fitted better
/// (1.08 against 1.18 mV, 1.37 against 1.60 mV), so the convention is not read, and no offset
/// is named; the issue's single sines (PI operators centred on the first input) still name
/// theirs (`gap.rs`). Written on these cases: a guard of the rule.
#[test]
fn an_off_centre_start_is_not_read_as_a_sensor_offset() {
    for seed in [10116, 9088] {
        let (d, named) = diagnosed_sorted(seed);
        assert_eq!(named, ["hysteresis"], "seed {seed}\n{}", d.table());
        assert!(
            d.final_rms_v < 1.5 * d.noise_floor_v,
            "seed {seed}\n{}",
            d.table()
        );
    }
}

/// A scale no sensor or stage could have is not named (session 64,
/// `catalogue::implausible`). Fresh seed 11178: a Prandtl-Ishlinskii loop of 14.6 % whose
/// branches run backwards after each reversal (least slope -3.87), no Everett table's form,
/// with a 23 mV offset, on eight random levels that read no zero. Beside the table a
/// `sensor-gain` of 0.438 took 97 % of what was left (19.4x the floor), a scale far outside
/// a sensor's calibration. Now the step leaves it out and says why; the table's own centre
/// line takes what a scale within the range can (step 19), the offset is reported as one the
/// records cannot tell from the table, and the unexplained part and its backward branches
/// are said. Written on this case: a guard of the rule.
#[test]
fn a_scale_no_sensor_could_have_is_not_named() {
    let d = loop_alone_with_the_value_left_out(11178, "sensor-gain", "outside");
    let (lo, hi) = host_tests::gap::constants::SENSOR_GAIN_RANGE;
    assert!(
        d.model
            .sensor_gain
            .as_ref()
            .is_none_or(|g| (lo..=hi).contains(&g.gain)),
        "{}",
        d.table()
    );
}

/// A creep no piezo stage could have is not named (session 65, `catalogue::implausible`,
/// [`host_tests::gap::constants::CREEP_SHARE_MAX`]). In-sample seed 3187: a Gaussian Preisach
/// plane of 9.8 % whose branches run backwards after each reversal (least slope -1.10, no
/// Everett table's form), with a -18.9 mV offset, on one 1.26 Hz sine. Beside the table a
/// `drift` whose 1.2 s lag, longer than the sine's 0.8 s period, settled at 87 % of the
/// stage's linear reading at 2.5 V took 67 % of what was left: a phase lag drawing the loop's
/// misfit, named at 28x the floor. Now the step leaves it out and says why, the offset is
/// reported as one the records cannot tell from the table, and what is left is said. Written
/// on this case: a guard of the rule.
#[test]
fn a_creep_no_stage_could_have_is_not_named() {
    loop_alone_with_the_value_left_out(3187, "drift", "settled creep");
}

/// Case `seed` diagnosed: the loop alone named, `effect` left out at some step for a value no
/// stage or sensor could have (its reason holding `because`), the hysteresis / offset pair
/// said, and what is left said.
fn loop_alone_with_the_value_left_out(seed: u64, effect: &str, because: &str) -> gap::Diagnosis {
    let (d, named) = diagnosed_sorted(seed);
    assert_eq!(named, ["hysteresis"], "seed {seed}\n{}", d.table());
    assert!(
        d.not_searched
            .iter()
            .flatten()
            .any(|(e, why)| e == effect && why.contains(because)),
        "seed {seed}\n{}",
        d.trace()
    );
    assert!(
        d.cannot_tell
            .iter()
            .any(|c| c.named == "hysteresis" && c.alternative == "offset"),
        "seed {seed}\n{}",
        d.table()
    );
    assert!(d.unexplained.is_some(), "seed {seed}\n{}", d.table());
    d
}

/// The drawn case `seed` diagnosed from `thesis-linear`, and its named set sorted.
fn diagnosed_sorted(seed: u64) -> (gap::Diagnosis, Vec<String>) {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let data = Case::draw(seed).records();
    let d = diagnose(&base, &data, &Options::default()).expect("diagnosis");
    let mut named = d.named.clone();
    named.sort();
    (d, named)
}

/// A creep beside a scale error on a staircase of levels (session 66: the creep that counts
/// from the first input fitted with a scale, GAP.md step 18, and the swaps' fit of the
/// drift's start). Both rules were written on the families' random levels (3158, 3457: a log
/// creep and a 1.1 % or 3.4 % scale, nothing named at 43x and the scale missed at 7.5x; 10287,
/// 11308: a drift and a false offset at 14.5x and 4.2x); the staircase
/// ([`staircase_diagnosed`]) is a protocol neither was shaped on. No name may be false, the
/// creep is named in every case, no record is left above 1.5x its floor unsaid, and the scale
/// is named in 11 of the 12 cases or more. Measured on seeds 13000-13011: before both rules
/// the scale was named in 9, with four false names (13001: a loop and a curvature, 13002: a
/// loop, in the scale's place, the joint `drift+hysteresis` step; 13007: an offset at
/// 2.20x); with the swaps' rule alone in 10 (13007 exact at 1.01x); with both in 12, no false
/// name.
#[test]
fn a_creep_beside_a_scale_on_a_staircase_names_both() {
    let (lines, failed, named) = staircase_diagnosed(13000..13012, |_| "sensor-gain");
    let scales = named
        .iter()
        .filter(|n| n.iter().any(|e| e == "sensor-gain"))
        .count();
    println!(
        "{}\nscale named in {scales} of {}",
        lines.join("\n"),
        lines.len()
    );
    assert!(failed.is_empty(), "{}", failed.join("\n"));
    assert!(
        scales + 1 >= lines.len(),
        "scale named in {scales}\n{}",
        lines.join("\n")
    );
}

/// The creep on the same staircase alone or beside an offset or a curvature (no scale): the
/// two rules of session 66 offer a scale beside the creep, and must not name one the
/// records do not hold. No name may be false, the creep is named in every case, and no record
/// is left above 1.5x its floor unsaid. Measured on seeds 13100-13117 (six of each truth):
/// see GAP.md, session 66, for the counts before and after.
#[test]
fn a_creep_on_a_staircase_names_no_false_scale() {
    let (lines, failed, _) = staircase_diagnosed(13100..13118, |seed| {
        ["", "offset", "nonlinear-gain"][(seed % 3) as usize]
    });
    println!("{}", lines.join("\n"));
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}

/// Diagnoses, one per seed of `seeds` (or of `GAP_SEED=a,b,...`), of a creep (the families')
/// beside the static shape `shape(seed)` (`""`: none; a scale of 1-5 %, an offset of 5-30 mV
/// either way, or a curvature: [`creep_case_diagnosed`]) on one record: a staircase of 6-12
/// levels up and down, each held 0.15-1 s, from a level of 2-8 V (no rest at 0 V), 2-20 kHz.
/// Returns a line per case, the lines of the cases that fail, and each case's named set.
fn staircase_diagnosed(
    seeds: std::ops::Range<u64>,
    shape: impl Fn(u64) -> &'static str,
) -> (Vec<String>, Vec<String>, Vec<Vec<String>>) {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let mut lines = Vec::new();
    let mut failed = Vec::new();
    let mut named = Vec::new();
    let seeds: Vec<u64> = std::env::var("GAP_SEED").map_or(seeds.collect(), |s| {
        s.split(',').filter_map(|x| x.trim().parse().ok()).collect()
    });
    for seed in seeds {
        let mut rng = StdRng::seed_from_u64(seed);
        let rate: f64 = lu(&mut rng, 2000.0, 20000.0).round();
        let n_levels: usize = rng.gen_range(6..=12);
        let mut level: f64 = rng.gen_range(2.0..8.0);
        let mut up = rng.gen_bool(0.5);
        let (mut t_s, mut u_v) = (Vec::new(), Vec::new());
        for _ in 0..n_levels {
            let hold_s: f64 = rng.gen_range(0.15..1.0);
            let n0 = t_s.len();
            for i in 0..(hold_s * rate) as usize {
                t_s.push((n0 + i) as f64 / rate);
                u_v.push(level);
            }
            let step: f64 = rng.gen_range(0.5..2.5);
            if (up && level + step > 9.5) || (!up && level - step < 0.5) {
                up = !up;
            }
            level += if up { step } else { -step };
        }
        let seconds = t_s.len() as f64 / rate;
        let protocol = Protocol::one_record(
            Family::RandomLevels,
            "staircase.csv",
            (t_s, u_v),
            format!("a staircase of {n_levels} levels, {rate:.0} Hz {seconds:.1} s"),
            (Some(rate), true),
        );
        let (line, ok, n) =
            creep_case_diagnosed(&base, (seed, &mut rng), protocol, shape(seed), 0.01);
        if !ok {
            failed.push(line.clone());
        }
        lines.push(line);
        named.push(n);
    }
    (lines, failed, named)
}

/// One record of `protocol` from a stage with one of the families' creeps (drawn from `rng`)
/// beside the static shape `shape` (`""`: none; a scale of `scale_min`-5 % or an offset of
/// 5-30 mV, either way, or one of the families' curvatures), diagnosed from `thesis-linear`.
/// Returns a line for the case, whether it holds (no false name, the creep named, and no
/// record above 1.5x its floor without a pair said: a missed shape is said), and the named
/// set. `GAP_DEBUG=1` prints the table and the trace.
fn creep_case_diagnosed(
    base: &ModelFile,
    (seed, rng): (u64, &mut StdRng),
    protocol: Protocol,
    shape: &'static str,
    scale_min: f64,
) -> (String, bool, Vec<String>) {
    let mut effects = vec!["drift"];
    if !shape.is_empty() {
        effects.push(shape);
    }
    effects.sort();
    let mut case = Case::of(seed, protocol, effects.clone());
    case.creep = Some(Creep::draw(rng));
    let sign = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
    match shape {
        "offset" => case.offset_v = Some(sign * rng.gen_range(0.005..0.03)),
        "sensor-gain" => case.sensor_gain = Some(1.0 + sign * rng.gen_range(scale_min..0.05)),
        "nonlinear-gain" => case.static_map = Some(StaticMap::draw(rng)),
        _ => {}
    }
    let d = diagnose(base, &case.records(), &Options::default()).expect("diagnosis");
    if std::env::var("GAP_DEBUG").is_ok() {
        println!("{}\n{}", d.table(), d.trace());
    }
    let false_names = d
        .named
        .iter()
        .filter(|n| !effects.contains(&n.as_str()))
        .count();
    let pairs: Vec<String> = d
        .cannot_tell
        .iter()
        .map(|c| format!("{} / {}", c.named, c.alternative))
        .collect();
    let line = format!(
        "{seed} {effects:?} {} {}: named {:?}, {:.2}x; cannot tell {pairs:?}",
        case.creep.as_ref().map_or("", Creep::label),
        case.protocol.desc,
        d.named,
        d.final_rms_v / d.noise_floor_v
    );
    let silent = d.final_rms_v > 1.5 * d.noise_floor_v && d.cannot_tell.is_empty();
    let ok = false_names == 0 && d.named.iter().any(|n| n == "drift") && !silent;
    (line, ok, d.named)
}

/// The step response rule's evidence away from the record it came from (session 64: the drift
/// fitted beside each look-alike static shape as one step, written on the `thesis-full`
/// stage's step responses, `gap.rs`): the families' creeps (log and power, their own gains
/// and lags) alone or beside an offset, a scale or a curvature, each on one record of a single
/// step from rest at 0 V to 1.5-9 V held 6-12 s at 2-10 kHz, none of which the rule was
/// written on. Measured on seeds 12000-12019: no false name, the creep named on all twenty,
/// the five offsets named (the rest at 0 V shows them), one scale of five (7.40 V: with the
/// creep as one step, its pair with a curvature said; the others missed, 1.5-47x, the pair
/// said where above 1.5x), no curvature (1.0-2.1x the floor). (On the 40 seeds 12000-12039,
/// drawn in another order, the rule fired twice, both on a true scale; no false name.)
#[test]
fn a_step_response_of_other_creeps_names_nothing_false() {
    let base = ModelFile::built_in("thesis-linear").unwrap();
    let mut lines = Vec::new();
    let mut failed = Vec::new();
    for seed in 12000u64..12020 {
        let mut rng = StdRng::seed_from_u64(seed);
        let rate: f64 = lu(&mut rng, 2000.0, 10000.0);
        let seconds: f64 = rng.gen_range(6.0..12.0);
        let level: f64 = rng.gen_range(1.5..9.0);
        let n = (seconds * rate) as usize;
        let t_s: Vec<f64> = (0..n).map(|i| i as f64 / rate).collect();
        let u_v: Vec<f64> = t_s
            .iter()
            .map(|&t| if t < 0.1 { 0.0 } else { level })
            .collect();
        let protocol = Protocol::one_record(
            Family::RandomLevels,
            "step.csv",
            (t_s, u_v),
            format!("one step to {level:.2} V, {rate:.0} Hz {seconds:.1} s"),
            (Some(rate), true),
        );
        // (the creep alone, or beside one static shape, in turn)
        let shape = ["", "offset", "sensor-gain", "nonlinear-gain"][(seed % 4) as usize];
        let (line, ok, _) = creep_case_diagnosed(&base, (seed, &mut rng), protocol, shape, 0.005);
        if !ok {
            failed.push(line.clone());
        }
        lines.push(line);
    }
    println!("{}", lines.join("\n"));
    assert!(failed.is_empty(), "{}", failed.join("\n"));
}
