//! Generators of the randomised model-gap suite (issue #12, item 6): the recording protocols a
//! lab might use ([`Family`]) and ground truths written in forms the workflow does not fit
//! ([`Truth`]). Every truth form is its own f64 code here; nothing calls the workflow's fits.
//!
//! # Protocol families (rates drawn within each family's range)
//! * `identification`: the recommended protocol, `protocol::fast_input(50 kHz, 0.2 s)` and
//!   `protocol::slow_input(1 kHz, 30 s)`;
//! * `long-sine`: one record, 10-14 s at 1-10 kHz, a 0.5-2 Hz sine of 3.5-4.5 V amplitude
//!   about a centre drawn so that it stays within 0.3..9.7 V, random start phase;
//! * `sweep`: one record, 5-7 s at 5-50 kHz (at most 150k samples), a logarithmic chirp from
//!   0.5-1 Hz to 100-250 Hz, 3-4.5 V amplitude about 4.8-5.2 V;
//! * `random-levels`: one record, 5-10 s at 1-50 kHz (at most 150k samples), levels uniform in
//!   0.5..9.5 V (at least 0.2 V apart) held 20 ms..2 s (log-uniform).
//!
//! The lengths are the short ends of what a lab would take: the workflow's cost grows with a
//! record's duration (it simulates at the stage's 50 kHz step whatever the record's rate, and
//! its fast-effect search simulates every record of 5 kHz or more), and the suite must run in
//! minutes.
//!
//! # Which effects a protocol can show (the rule the case generator follows)
//! * `hysteresis`, `nonlinear-gain`, `sensor-gain`, `offset`: every family (each sweeps most of
//!   the range with reversals, so the loop, the curvature of the static map, the scale and the
//!   zero all show);
//! * `drift`: only with holds (identification, random-levels): on a sine or a sweep, creep is a
//!   rate-dependent loop plus a slow trend that the records cannot tell from hysteresis (issue
//!   #12, item 1: the workflow should say so, not guess), so it is not a fair hidden effect there;
//! * `time-delay`, `slew-rate-limit`: only with steps sampled at >= 10 kHz (the edges are the
//!   only place they show apart from a phase lag, which an amplifier pole mimics on a sine);
//! * `resonance` (mode 3-12 kHz): only with steps sampled at >= 4x the mode frequency (so the
//!   mode is drawn within 3 kHz..min(12 kHz, rate / 4), and needs a rate >= 12 kHz).

use host_tests::gap::protocol;
use model_core::params;
use rand::Rng;
use rand::rngs::StdRng;
use std::f64::consts::PI;

/// Log-uniform draw in `lo..hi`.
pub fn lu(rng: &mut StdRng, lo: f64, hi: f64) -> f64 {
    (lo.ln() + (hi.ln() - lo.ln()) * rng.r#gen::<f64>()).exp()
}

/// A random sign.
fn sign(rng: &mut StdRng) -> f64 {
    if rng.gen_bool(0.5) { 1.0 } else { -1.0 }
}

/// The protocol families.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Family {
    Identification,
    LongSine,
    Sweep,
    RandomLevels,
}

impl Family {
    pub const ALL: [Family; 4] = [
        Family::Identification,
        Family::LongSine,
        Family::Sweep,
        Family::RandomLevels,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Family::Identification => "identification",
            Family::LongSine => "long-sine",
            Family::Sweep => "sweep",
            Family::RandomLevels => "random-levels",
        }
    }
}

/// One record's input.
#[derive(Clone, Debug)]
pub struct Input {
    pub name: String,
    pub t_s: Vec<f64>,
    pub u_v: Vec<f64>,
}

/// A drawn protocol: its records and what they can show.
#[derive(Clone, Debug)]
pub struct Protocol {
    pub family: Family,
    pub records: Vec<Input>,
    /// Words for the tables (rates, lengths, frequencies).
    pub desc: String,
    /// The rate of the records with steps, Hz (`None`: no steps).
    pub step_rate_hz: Option<f64>,
    /// Holds long enough to show creep tails.
    pub holds: bool,
}

impl Protocol {
    /// A protocol of one record, `name`, whose input is `u_v` at the times `t_s`.
    pub fn one_record(
        family: Family,
        name: &str,
        (t_s, u_v): (Vec<f64>, Vec<f64>),
        desc: String,
        (step_rate_hz, holds): (Option<f64>, bool),
    ) -> Self {
        Self {
            family,
            records: vec![Input {
                name: name.into(),
                t_s,
                u_v,
            }],
            desc,
            step_rate_hz,
            holds,
        }
    }

    /// The effects this protocol can show (the rule in the module note), in catalogue order.
    pub fn allowed(&self) -> Vec<&'static str> {
        let mut v = Vec::new();
        if let Some(r) = self.step_rate_hz {
            if r >= 10e3 {
                v.push("time-delay");
            }
            if r >= 4.0 * 3000.0 {
                v.push("resonance");
            }
        }
        if self.holds {
            v.push("drift");
        }
        v.extend(["hysteresis", "nonlinear-gain"]);
        if self.step_rate_hz.is_some_and(|r| r >= 10e3) {
            v.push("slew-rate-limit");
        }
        v.extend(["sensor-gain", "offset"]);
        v
    }
}

fn times(rate_hz: f64, seconds: f64) -> Vec<f64> {
    let n = (seconds * rate_hz).round() as usize;
    (0..n).map(|i| i as f64 / rate_hz).collect()
}

/// At most this many samples in a one-record protocol (keeps a case to seconds of work).
const MAX_SAMPLES: f64 = 150_000.0;

/// Draw a protocol of `family`.
pub fn draw_protocol(family: Family, rng: &mut StdRng) -> Protocol {
    match family {
        Family::Identification => {
            let (tf, uf) = protocol::fast_input(50_000.0, 0.2);
            let (ts, us) = protocol::slow_input(1_000.0, 30.0);
            Protocol {
                family,
                records: vec![
                    Input {
                        name: "fast.csv".into(),
                        t_s: tf,
                        u_v: uf,
                    },
                    Input {
                        name: "slow.csv".into(),
                        t_s: ts,
                        u_v: us,
                    },
                ],
                desc: "50 kHz 0.2 s steps + 1 kHz 30 s slow".into(),
                step_rate_hz: Some(50_000.0),
                holds: true,
            }
        }
        Family::LongSine => {
            let rate = (lu(rng, 1_000.0, 10_000.0) / 100.0).round() * 100.0;
            let secs = rng.gen_range(10.0..14.0);
            let f = rng.gen_range(0.5..2.0);
            let amp = rng.gen_range(3.5..4.5);
            let room = 4.7 - amp;
            let centre = 5.0 + rng.gen_range(-room..=room);
            let phase = rng.gen_range(0.0..2.0 * PI);
            let t = times(rate, secs);
            let u = t
                .iter()
                .map(|&x| centre + amp * (2.0 * PI * f * x + phase).sin())
                .collect();
            Protocol {
                family,
                records: vec![Input {
                    name: "sine.csv".into(),
                    t_s: t,
                    u_v: u,
                }],
                desc: format!(
                    "{:.1} kHz {secs:.1} s, {f:.2} Hz sine {centre:.2} +- {amp:.2} V",
                    rate / 1e3
                ),
                step_rate_hz: None,
                holds: false,
            }
        }
        Family::Sweep => {
            let rate = (lu(rng, 5_000.0, 50_000.0) / 1000.0).round() * 1000.0;
            let secs = rng.gen_range(5.0..7.0f64).min(MAX_SAMPLES / rate);
            let f0: f64 = rng.gen_range(0.5..1.0);
            let f1 = rng.gen_range(100.0..250.0);
            let amp = rng.gen_range(3.0..4.5);
            let centre = rng.gen_range(4.8..5.2);
            let k = (f1 / f0).ln() / secs;
            let t = times(rate, secs);
            let u = t
                .iter()
                .map(|&x| centre + amp * (2.0 * PI * f0 * ((k * x).exp() - 1.0) / k).sin())
                .collect();
            Protocol {
                family,
                records: vec![Input {
                    name: "sweep.csv".into(),
                    t_s: t,
                    u_v: u,
                }],
                desc: format!(
                    "{:.0} kHz {secs:.1} s, chirp {f0:.2}->{f1:.0} Hz {centre:.2} +- {amp:.2} V",
                    rate / 1e3
                ),
                step_rate_hz: None,
                holds: false,
            }
        }
        Family::RandomLevels => {
            let rate = lu(rng, 1_000.0, 50_000.0);
            let rate = if rate < 10_000.0 {
                (rate / 100.0).round() * 100.0
            } else {
                (rate / 1000.0).round() * 1000.0
            };
            let secs = rng.gen_range(5.0..10.0f64).min(MAX_SAMPLES / rate);
            let t = times(rate, secs);
            let mut u = Vec::with_capacity(t.len());
            let mut level: f64 = rng.gen_range(0.5..9.5);
            let mut until = lu(rng, 0.02, 2.0);
            let mut levels = 1;
            for &x in &t {
                while x >= until {
                    let mut next = rng.gen_range(0.5..9.5);
                    while (next - level).abs() < 0.2 {
                        next = rng.gen_range(0.5..9.5);
                    }
                    level = next;
                    until += lu(rng, 0.02, 2.0);
                    levels += 1;
                }
                u.push(level);
            }
            Protocol {
                family,
                records: vec![Input {
                    name: "levels.csv".into(),
                    t_s: t,
                    u_v: u,
                }],
                desc: format!("{:.1} kHz {secs:.1} s, {levels} levels", rate / 1e3),
                step_rate_hz: Some(rate),
                holds: true,
            }
        }
    }
}

// ------------------------------------------------------------------------------------------
// Hysteresis truths. Each operator maps the input history to a value added to the input (input
// volts; the loop is counter-clockwise: rising branch below the falling one), then scaled so
// that the major loop of a 0-10-0 V cycle is `share` of the 10 V span wide.
// ------------------------------------------------------------------------------------------

/// The hysteresis forms.
#[derive(Clone, Debug)]
pub enum HystForm {
    /// Bouc-Wen: `dh = alpha du - beta |du| h - gamma du |h|`, output `-h`.
    BoucWen { alpha: f64, beta: f64, gamma: f64 },
    /// Duhem (Coleman-Hodgdon): `dw = alpha |du| (u - w) + g(u) du`,
    /// `g(u) = 1 - d (1 + e (u - 5) / 5)` (loop width varying along the range), output `w - u`.
    Duhem { alpha: f64, d: f64, e: f64 },
    /// Preisach plane of 0/1 relays with a smooth density over centre `m = (a + b) / 2` and
    /// half-width `r = (a - b) / 2`: Gaussian in `m` about `centre` (sd `spread`, skewed by
    /// `skew`), log-normal (or Lorentzian) in `r` about `r0`; the major loop's centre curve
    /// removed, so the truth is a loop, not a static map.
    Preisach {
        centre: f64,
        spread: f64,
        skew: f64,
        r0: f64,
        r_width: f64,
        lorentz: bool,
    },
    /// Prandtl-Ishlinskii play operators with their own radii and weights.
    Pi {
        radii_v: Vec<f64>,
        weights: Vec<f64>,
    },
}

impl HystForm {
    pub fn label(&self) -> &'static str {
        match self {
            HystForm::BoucWen { .. } => "hyst:bouc-wen",
            HystForm::Duhem { .. } => "hyst:duhem",
            HystForm::Preisach { lorentz: false, .. } => "hyst:preisach-gauss",
            HystForm::Preisach { lorentz: true, .. } => "hyst:preisach-lorentz",
            HystForm::Pi { .. } => "hyst:pi",
        }
    }

    pub fn draw(rng: &mut StdRng) -> Self {
        match rng.gen_range(0..4) {
            0 => {
                let beta = lu(rng, 0.5, 1.5);
                let gamma = beta * (lu(rng, 0.1, 0.7) - 0.4);
                HystForm::BoucWen {
                    alpha: 1.0,
                    beta,
                    gamma,
                }
            }
            1 => {
                let alpha = lu(rng, 0.8, 4.0);
                HystForm::Duhem {
                    alpha,
                    d: 0.3,
                    e: rng.gen_range(-0.5..0.5),
                }
            }
            2 => HystForm::Preisach {
                centre: rng.gen_range(2.5..7.5),
                spread: rng.gen_range(1.5..5.0),
                skew: rng.gen_range(-0.6..0.6),
                r0: lu(rng, 0.1, 1.5),
                r_width: rng.gen_range(0.4..1.0),
                lorentz: rng.gen_bool(0.5),
            },
            _ => {
                let k = rng.gen_range(5..=12);
                let mut radii_v: Vec<f64> = (0..k).map(|_| lu(rng, 0.02, 5.0)).collect();
                radii_v.sort_by(f64::total_cmp);
                let weights = (0..k).map(|_| rng.gen_range(0.2..1.0)).collect();
                HystForm::Pi { radii_v, weights }
            }
        }
    }
}

/// The Everett function of a Preisach density, tabulated: `E(a, b)` = the density's mass over
/// the relays `b <= beta <= alpha <= a`.
#[derive(Clone, Debug)]
pub struct Everett {
    lo: f64,
    step: f64,
    n: usize,
    e: Vec<f64>,
}

impl Everett {
    const LO: f64 = -0.5;
    const HI: f64 = 10.5;

    fn new(form: &HystForm) -> Self {
        let HystForm::Preisach {
            centre,
            spread,
            skew,
            r0,
            r_width,
            lorentz,
        } = *form
        else {
            unreachable!()
        };
        let step = 0.025;
        let n = ((Self::HI - Self::LO) / step).round() as usize + 1;
        let x = |i: usize| Self::LO + step * i as f64;
        let mu = |a: f64, b: f64| {
            let m = 0.5 * (a + b);
            let r = 0.5 * (a - b);
            let dm = (m - centre) / spread;
            let pm = (-0.5 * dm * dm).exp() * (1.0 + skew * (m - 5.0) / 5.0).max(0.0);
            let pr = if lorentz {
                1.0 / (1.0 + ((r - r0) / (r_width * r0.max(0.2))).powi(2))
            } else if r <= 0.0 {
                0.0
            } else {
                let l = (r / r0).ln() / r_width;
                (-0.5 * l * l).exp()
            };
            pm * pr
        };
        let mut e = vec![0.0; n * n];
        for i in 1..n {
            // Row i: E(a_i, b_j) = E(a_{i-1}, b_j) + sum_{k=j}^{i} mu(a_i, b_k) step^2.
            let mut s = 0.0;
            for j in (0..=i).rev() {
                s += mu(x(i), x(j)) * step * step;
                e[i * n + j] = e[(i - 1) * n + j] + s;
            }
        }
        Self {
            lo: Self::LO,
            step,
            n,
            e,
        }
    }

    /// `E(a, b)`, bilinear between the table's points; 0 for `a <= b`.
    fn at(&self, a: f64, b: f64) -> f64 {
        if a <= b {
            return 0.0;
        }
        let hi = (self.n - 1) as f64 - 1e-9;
        let fa = ((a - self.lo) / self.step).clamp(0.0, hi);
        let fb = ((b - self.lo) / self.step).clamp(0.0, hi);
        let (i, j) = (fa as usize, fb as usize);
        let (da, db) = (fa - i as f64, fb - j as f64);
        let g = |i: usize, j: usize| if j > i { 0.0 } else { self.e[i * self.n + j] };
        (1.0 - da) * ((1.0 - db) * g(i, j) + db * g(i, j + 1))
            + da * ((1.0 - db) * g(i + 1, j) + db * g(i + 1, j + 1))
    }
}

/// A hysteresis operator with its state.
pub enum HystOp<'a> {
    BoucWen {
        alpha: f64,
        beta: f64,
        gamma: f64,
        h: f64,
        u: f64,
    },
    Duhem {
        alpha: f64,
        d: f64,
        e: f64,
        w: f64,
        u: f64,
    },
    /// Turning points `q` (`q[0]` = the table's low end, then maxima and minima alternating)
    /// and the current input.
    Preisach {
        table: &'a Everett,
        q: Vec<f64>,
        u: f64,
    },
    Pi {
        radii_v: &'a [f64],
        weights: &'a [f64],
        z: Vec<f64>,
    },
}

impl<'a> HystOp<'a> {
    /// At rest at `u0` (Bouc-Wen and Duhem: no hysteretic state; play operators centred;
    /// Preisach: on the rising major curve from negative saturation).
    pub fn new(form: &'a HystForm, table: Option<&'a Everett>, u0: f64) -> Self {
        match form {
            &HystForm::BoucWen { alpha, beta, gamma } => HystOp::BoucWen {
                alpha,
                beta,
                gamma,
                h: 0.0,
                u: u0,
            },
            &HystForm::Duhem { alpha, d, e } => HystOp::Duhem {
                alpha,
                d,
                e,
                w: u0,
                u: u0,
            },
            HystForm::Preisach { .. } => {
                let table = table.expect("Everett table");
                let mut op = HystOp::Preisach {
                    table,
                    q: vec![table.lo],
                    u: table.lo,
                };
                op.step(u0);
                op
            }
            HystForm::Pi { radii_v, weights } => HystOp::Pi {
                radii_v,
                weights,
                z: vec![u0; radii_v.len()],
            },
        }
    }

    /// Move the input to `x`; the operator's output (input volts, before scaling).
    pub fn step(&mut self, x: f64) -> f64 {
        match self {
            HystOp::BoucWen {
                alpha,
                beta,
                gamma,
                h,
                u,
            } => {
                let m = ((x - *u).abs() / 0.005).ceil().max(1.0) as usize;
                let du = (x - *u) / m as f64;
                for _ in 0..m {
                    *h += *alpha * du - *beta * du.abs() * *h - *gamma * du * h.abs();
                }
                *u = x;
                -*h
            }
            HystOp::Duhem { alpha, d, e, w, u } => {
                let m = ((x - *u).abs() / 0.005).ceil().max(1.0) as usize;
                let du = (x - *u) / m as f64;
                for _ in 0..m {
                    let g = 1.0 - *d * (1.0 + *e * (*u - 5.0) / 5.0);
                    *w += *alpha * du.abs() * (*u - *w) + g * du;
                    *u += du;
                }
                *u = x;
                *w - x
            }
            HystOp::Preisach { table, q, u } => {
                let x = x.clamp(Everett::LO, Everett::HI);
                // q.len() odd: the last turning point is a minimum (rising); even: falling.
                if x > *u {
                    if q.len() % 2 == 0 {
                        q.push(*u);
                    }
                    while q.len() >= 3 && x >= q[q.len() - 2] {
                        q.pop();
                        q.pop();
                    }
                } else if x < *u {
                    if q.len() % 2 == 1 {
                        q.push(*u);
                    }
                    while q.len() >= 3 && x <= q[q.len() - 2] {
                        q.pop();
                        q.pop();
                    }
                }
                *u = x;
                let mut p = 0.0;
                for k in 1..q.len() {
                    p += if k % 2 == 1 {
                        table.at(q[k], q[k - 1])
                    } else {
                        -table.at(q[k - 1], q[k])
                    };
                }
                let last = q[q.len() - 1];
                p += if q.len() % 2 == 1 {
                    table.at(x, last)
                } else {
                    -table.at(last, x)
                };
                // The major loop's centre curve, (up + down) / 2.
                let (lo, hi) = (Everett::LO, Everett::HI);
                let centre = 0.5 * (table.at(x, lo) + table.at(hi, lo) - table.at(hi, x));
                p - centre
            }
            HystOp::Pi {
                radii_v,
                weights,
                z,
            } => {
                let mut h = 0.0;
                for ((zi, r), w) in z.iter_mut().zip(radii_v.iter()).zip(weights.iter()) {
                    *zi = zi.max(x - r).min(x + r);
                    h += w * (*zi - x);
                }
                h
            }
        }
    }
}

/// A hysteresis truth: form, scale and the excursions before each record.
#[derive(Clone, Debug)]
pub struct Hysteresis {
    pub form: HystForm,
    /// Loop width on a 0-10-0 V cycle as a share of the 10 V span.
    pub share: f64,
    /// Scale from the operator's output to input volts.
    pub scale: f64,
    /// Levels visited before each record (from rest at the first; empty: at rest at the
    /// record's first input).
    pub before: Vec<f64>,
    pub table: Option<Everett>,
}

impl Hysteresis {
    pub fn draw(rng: &mut StdRng) -> Self {
        let form = HystForm::draw(rng);
        let share = rng.gen_range(0.05..0.15);
        let before = if rng.gen_bool(0.5) {
            (0..rng.gen_range(2..=4))
                .map(|_| rng.gen_range(0.0..10.0))
                .collect()
        } else {
            Vec::new()
        };
        let table = matches!(form, HystForm::Preisach { .. }).then(|| Everett::new(&form));
        let mut h = Self {
            form,
            share,
            scale: 1.0,
            before,
            table,
        };
        // Widest gap between the falling and the rising branch of a 0-10-0 V cycle (after one
        // cycle to settle onto the major loop).
        let mut op = HystOp::new(&h.form, h.table.as_ref(), 0.0);
        op.step(10.0);
        op.step(0.0);
        let grid: Vec<f64> = (0..=500).map(|i| i as f64 * 0.02).collect();
        let up: Vec<f64> = grid.iter().map(|&x| op.step(x)).collect();
        let down: Vec<f64> = grid.iter().rev().map(|&x| op.step(x)).collect();
        let width = up
            .iter()
            .zip(down.iter().rev())
            .map(|(a, b)| (b - a).abs())
            .fold(0.0f64, f64::max);
        h.scale = share * 10.0 / width.max(1e-12);
        h
    }

    /// The least slope of the input plus the hysteresis term along a settled 0-10-0 V cycle
    /// (0.02 V steps), volts per volt. Below zero the truth's position moves against its
    /// input just after a reversal (a Duhem or Bouc-Wen loop, play operators, or a Preisach
    /// plane less its major loop's centre curve, scaled to a wide loop from a narrow one),
    /// which no Preisach density (>= 0), and so no Everett table the stage accepts, can do:
    /// the per-form table counts those truths apart.
    pub fn min_slope(&self) -> f64 {
        let mut op = HystOp::new(&self.form, self.table.as_ref(), 0.0);
        op.step(10.0);
        op.step(0.0);
        let up = (0..=500).map(|i| i as f64 * 0.02);
        let path: Vec<f64> = up.clone().chain(up.rev().skip(1)).collect();
        let y: Vec<f64> = path.iter().map(|&x| x + self.scale * op.step(x)).collect();
        path.windows(2)
            .zip(y.windows(2))
            .map(|(x, y)| (y[1] - y[0]) / (x[1] - x[0]))
            .fold(f64::INFINITY, f64::min)
    }

    /// The hysteresis term of a record, input volts.
    pub fn apply(&self, u: &[f64]) -> Vec<f64> {
        let start = self.before.first().copied().unwrap_or(u[0]);
        let mut op = HystOp::new(&self.form, self.table.as_ref(), start);
        for &x in self.before.iter().skip(1) {
            op.step(x);
        }
        u.iter().map(|&x| self.scale * op.step(x)).collect()
    }
}

// ------------------------------------------------------------------------------------------
// Creep truths: the creep's step response per input volt, superposed over the input's history
// by a dense bank of first-order lags (quarter-decade spacing, 1e-4..1e6 /s): not the
// workflow's three-lag form.
// ------------------------------------------------------------------------------------------

#[derive(Clone, Debug)]
pub enum Creep {
    /// `gamma ln(1 + t / tau0)` sensor volts per input volt.
    Log { gamma: f64, tau0_s: f64 },
    /// Fractional (power-law) creep `c ((t + tau0)^a - tau0^a)`, scaled so that it reaches
    /// `share` of the step at 10 s.
    Power { a: f64, tau0_s: f64, share: f64 },
}

impl Creep {
    pub fn label(&self) -> &'static str {
        match self {
            Creep::Log { .. } => "drift:log",
            Creep::Power { .. } => "drift:power",
        }
    }

    pub fn draw(rng: &mut StdRng) -> Self {
        if rng.gen_bool(0.5) {
            Creep::Log {
                gamma: lu(rng, 0.004, 0.01),
                tau0_s: lu(rng, 0.005, 0.05),
            }
        } else {
            Creep::Power {
                a: rng.gen_range(0.05..0.3),
                tau0_s: lu(rng, 0.005, 0.05),
                share: rng.gen_range(0.02..0.06),
            }
        }
    }

    /// The bank: (rate /s, weight). `ln(1 + t/tau0) = int (1 - e^{-st}) e^{-s tau0} dx` and
    /// `(t + tau0)^a - tau0^a` is proportional to `int (1 - e^{-st}) e^{-s tau0} s^{-a} dx`
    /// over `x = ln s`.
    fn bank(&self) -> Vec<(f64, f64)> {
        let dx = std::f64::consts::LN_10 / 4.0;
        let rates = (0..40).map(|k| 1e-4 * (k as f64 * dx).exp());
        match *self {
            Creep::Log { gamma, tau0_s } => rates
                .map(|s| (s, gamma * dx * (-s * tau0_s).exp()))
                .collect(),
            Creep::Power { a, tau0_s, share } => {
                let raw: Vec<(f64, f64)> = rates
                    .map(|s| (s, dx * (-s * tau0_s).exp() * s.powf(-a)))
                    .collect();
                let at = |t: f64| -> f64 {
                    raw.iter()
                        .map(|(s, w)| w * (1.0 - (-s * t).exp()))
                        .sum::<f64>()
                };
                let c = share / at(10.0);
                raw.into_iter().map(|(s, w)| (s, c * w)).collect()
            }
        }
    }

    /// The creep of a record (started at rest at its first input), input volts.
    pub fn apply(&self, t_s: &[f64], u: &[f64]) -> Vec<f64> {
        let dt = if t_s.len() > 1 { t_s[1] - t_s[0] } else { 1.0 };
        let mut bank: Vec<(f64, f64, f64)> = self
            .bank()
            .into_iter()
            .map(|(s, w)| (w, (-s * dt).exp(), 0.0))
            .collect();
        u.iter()
            .map(|&x| {
                let mut c = 0.0;
                for (w, a, st) in bank.iter_mut() {
                    c += *w * *st;
                    *st = *a * *st + (1.0 - *a) * (x - u[0]);
                }
                c / params::PLANT_GAIN
            })
            .collect()
    }
}

// ------------------------------------------------------------------------------------------
// Non-linear gain: a static map `v + amp dev(v)` with a non-polynomial shape `phi`, in the
// catalogue's convention `m(0) = 0`, `m'(0) = 1` (the gain at 0 V is the nominal one, so the
// truth holds no offset and no scale error): `dev(v) = phi(v) - phi(0) - phi'(0) v`, its largest
// deviation over 0..10 V = |amp| (input volts).
// ------------------------------------------------------------------------------------------

#[derive(Clone, Debug)]
pub enum GainShape {
    Tanh {
        centre: f64,
        width: f64,
    },
    Exp {
        length: f64,
    },
    /// `ln(1 + e^((v - centre) / width))`: a knee, the gain rising above `centre`.
    Softplus {
        centre: f64,
        width: f64,
    },
}

#[derive(Clone, Debug)]
pub struct StaticMap {
    pub shape: GainShape,
    pub amp_v: f64,
    norm: f64,
}

impl StaticMap {
    pub fn label(&self) -> &'static str {
        match self.shape {
            GainShape::Tanh { .. } => "gain:tanh",
            GainShape::Exp { .. } => "gain:exp",
            GainShape::Softplus { .. } => "gain:softplus",
        }
    }

    pub fn draw(rng: &mut StdRng) -> Self {
        let shape = match rng.gen_range(0..3) {
            0 => GainShape::Tanh {
                centre: rng.gen_range(2.0..8.0),
                width: rng.gen_range(1.5..4.0),
            },
            1 => GainShape::Exp {
                length: rng.gen_range(2.0..6.0),
            },
            _ => GainShape::Softplus {
                centre: rng.gen_range(3.0..7.0),
                width: rng.gen_range(0.7..2.0),
            },
        };
        let mut m = Self {
            shape,
            amp_v: sign(rng) * lu(rng, 0.04, 0.2),
            norm: 1.0,
        };
        m.norm = (0..=1000)
            .map(|i| m.raw(i as f64 * 0.01).abs())
            .fold(0.0f64, f64::max);
        m
    }

    fn phi(&self, v: f64) -> f64 {
        match self.shape {
            GainShape::Tanh { centre, width } => ((v - centre) / width).tanh(),
            GainShape::Exp { length } => (v / length).exp(),
            GainShape::Softplus { centre, width } => ((v - centre) / width).exp().ln_1p(),
        }
    }

    fn raw(&self, v: f64) -> f64 {
        let h = 1e-5;
        let slope0 = (self.phi(h) - self.phi(-h)) / (2.0 * h);
        self.phi(v) - self.phi(0.0) - slope0 * v
    }

    pub fn map(&self, v: f64) -> f64 {
        v + self.amp_v * self.raw(v) / self.norm
    }
}
