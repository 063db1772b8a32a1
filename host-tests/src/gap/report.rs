//! What a [`Diagnosis`] shows a person: the table `piezo gap` and `piezo demo` print
//! ([`Diagnosis::table`]; the tests print it too, so it lives here, not in the verbs), and the
//! HTML report of `piezo gap --report DIR`: one `index.html` with inline SVG plots
//! (plotters) a person would look at:
//! * measured vs simulated, base and final model, for every record;
//! * the residual before and after each step, for every record;
//! * the unexplained residual, when there is one ([`super::unexplained`]), against the input;
//! * each effect's evidence: residual against input (hysteresis loop, every record with
//!   reversals, base and final model), residual during holds
//!   (drift tails), static residual against input (gain curve), the first step edges of the
//!   fast record (delay, pole, slew), the residual spectrum (resonance).

use super::catalogue;
use super::constants::CANNOT_TELL_RATIO;
use super::data::Data;
use super::everett::CentreLine;
use super::select::{CannotTell, Diagnosis, TakenOut};
use crate::io::model_file::ModelFile;
use anyhow::Context;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

impl Diagnosis {
    /// The terminal table.
    pub fn table(&self) -> String {
        let mut s = String::new();
        s.push_str(&format!(
            "{:<4} {:<16} {:>12} {:>12}  {:<40} {}\n",
            "step", "effect", "rms before", "rms after", "fitted parameters", "evidence"
        ));
        for (i, st) in self.steps.iter().enumerate() {
            let p: Vec<String> = st
                .params
                .iter()
                .map(|(k, v)| format!("{k}={}", fmt_num(v.as_f64().unwrap_or(f64::NAN))))
                .collect();
            s.push_str(&format!(
                "{:<4} {:<16} {:>9.2} mV {:>9.2} mV  {:<40} {}\n",
                i + 1,
                format!(
                    "{}{}",
                    st.effect,
                    if st.removed {
                        " (removed)"
                    } else if st.refit {
                        " (refit)"
                    } else {
                        ""
                    }
                ),
                1e3 * st.rms_before_v,
                1e3 * st.rms_after_v,
                p.join(" "),
                st.evidence
            ));
        }
        // The parameters of the final model: the slow effects are refitted together at every
        // step, so a row's parameters are those of its own step.
        for e in &self.named {
            let p: Vec<String> = catalogue::params_of(&self.model, e)
                .iter()
                .map(|(k, v)| format!("{k}={}", fmt_num(*v)))
                .collect();
            s.push_str(&format!("final {e}: {}\n", p.join(" ")));
        }
        if self.named.iter().any(|e| e == "hysteresis") || self.centre_line.by_diagnosis.is_some() {
            let c = &self.centre_line;
            let (kept, other) = c.kept_and_other();
            let (name, what) = c.chosen.describe();
            let other_name = c.other().describe().0;
            // The band split's figure beside the rise split's, whichever was kept.
            let band = match (c.chosen, c.rise_noise_var) {
                (CentreLine::Rise, _) => format!(" (the band split {})", fmt_num(c.band_noise_var)),
                (CentreLine::Band, Some(r)) => format!(" (the rise split {})", fmt_num(r)),
                _ => String::new(),
            };
            s.push_str(&format!(
                "hysteresis basis: the {name} split ({what}): hysteresis and drift alone left {} \
                 noise variances over the records{band}, the {other_name} split {}\n",
                fmt_num(kept),
                fmt_num(other)
            ));
            if let Some(r) = &c.by_diagnosis {
                s.push_str(&format!(
                    "hysteresis basis: the two splits' loops alone were within {CANNOT_TELL_RATIO}x \
                     (RMS) of each other, so both diagnoses ran and the one explaining every \
                     record where only one did, else the one naming fewer effects (a drift \
                     the holds' tails show not counted; then ending lower), was kept; the {} \
                     split's diagnosis named [{}] and ended at {} noise variances\n",
                    r.split.describe().0,
                    r.named.join(", "),
                    fmt_num(r.final_noise_var)
                ));
            }
        }
        s.push_str(&format!(
            "named: [{}]; noise floor {:.2} mV; final residual {:.2} mV ({:.2}x the floor)\n",
            self.named.join(", "),
            1e3 * self.noise_floor_v,
            1e3 * self.final_rms_v,
            self.final_rms_v / self.noise_floor_v.max(1e-12)
        ));
        for n in &self.noise_notes {
            s.push_str(&format!("noise: {n}\n"));
        }
        for c in &self.cannot_tell {
            s.push_str(&format!(
                "cannot tell {} from {}: {}\n",
                c.named, c.alternative, c.why
            ));
        }
        if let Some(u) = &self.unexplained {
            s.push_str(&format!(
                "unexplained: {:.2} mV above the noise, {}; where: {}\n",
                1e3 * u.rms_v,
                unexplained_words(self.final_rms_v, &self.cannot_tell),
                u.where_
            ));
        }
        s
    }

    /// The workings behind the table, for debugging a diagnosis: every candidate tried at
    /// each step (effect, score, explained fraction, admissible) and the fast effects whose
    /// search it left out (with why), then each step's residual per record, mV.
    pub fn trace(&self) -> String {
        let mut s = String::new();
        for (i, t) in self.tried.iter().enumerate() {
            s.push_str(&format!("  tried at step {}: {t:?}\n", i + 1));
            if let Some(left) = self.not_searched.get(i).filter(|l| !l.is_empty()) {
                s.push_str(&format!("  left out at step {}: {left:?}\n", i + 1));
            }
        }
        let mv = |v: &[f64]| v.iter().map(|x| x * 1e3).collect::<Vec<_>>();
        for st in &self.steps {
            s.push_str(&format!(
                "  {}{} per record mV: {:.2?} -> {:.2?}\n",
                st.effect,
                if st.removed {
                    " (removed)"
                } else if st.refit {
                    " (refit)"
                } else {
                    ""
                },
                mv(&st.record_rms_before_v),
                mv(&st.record_rms_after_v)
            ));
        }
        s
    }
}

/// Why the unexplained residual stays, in words: no catalogued effect is admissible, or, where
/// the final check took an offset beside the table out as a level the records do not show
/// ([`TakenOut::Unshown`]), the final model is still that check's (its residual is
/// the pair's figure without the offset, to the bit) and the offset left clearly less
/// ([`CannotTell::alternative_clearly_less`]), what it left and why it is not named: the residual is not
/// beyond the catalogue, the records do not show that constant as a level. Both figures are
/// residual RMS, noise included (the unexplained part's own figure has the noise taken out).
/// Look-alikes left unnamed (`neither_named`) are listed, after the offset's words where both
/// stand (there, the shapes that could have done its work, [`TakenOut::InOffsetsPlace`]);
/// else static shapes the final check took out below their bars beside a table
/// ([`TakenOut::BelowBar`]): they took part of the residual, but the others' refit, the
/// table's among them, took up most of the same work. Static shapes taken out beside a table
/// as ones the records do not tell from the loop ([`TakenOut::Untold`]) come first.
pub(super) fn unexplained_words(final_rms_v: f64, pairs: &[CannotTell]) -> String {
    let taken_out = pairs.iter().find(|c| {
        c.taken_out == TakenOut::Unshown
            && c.rms_v.to_bits() == final_rms_v.to_bits()
            && c.alternative_clearly_less()
    });
    // Look-alikes left unnamed: each explains part of the residual, and the records cannot
    // tell which (a plain "none admissible" beside the pairs' "would explain 90 %" read as a
    // contradiction).
    let alike: Vec<String> = pairs
        .iter()
        .filter(|c| c.neither_named && c.taken_out == TakenOut::No)
        .map(|c| format!("{} / {}", c.named, c.alternative))
        .collect();
    // Shapes that could have done the work of an offset the final check took out.
    let in_place: Vec<String> = pairs
        .iter()
        .filter(|k| k.taken_out == TakenOut::InOffsetsPlace)
        .map(|k| k.named.clone())
        .collect();
    let in_place_words = match in_place.as_slice() {
        [one] => format!(
            "{one} fitted in its place explains a step's share of what was left, and the records \
             do not say whether the offset did its work (the pair above), so neither is named"
        ),
        _ => format!(
            "{} fitted in its place each explain a step's share of what was left, and the \
             records do not say which shape's work it did, if any (the pairs above), so none \
             of them is named",
            in_place.join(" and ")
        ),
    };
    let alike_words = |opening: &str| {
        format!(
            "{opening}the look-alikes {} explain part of it alike and the records cannot tell \
             which (the pairs above), so none of them is named",
            alike.join(", ")
        )
    };
    // Static shapes the final check took out below their bars beside a table: each took part
    // of it, and the others' refit (the table's among them) took up most of the same work.
    let below_bar: Vec<String> = pairs
        .iter()
        .filter(|c| c.taken_out == TakenOut::BelowBar)
        .map(|c| format!("{} / {}", c.named, c.alternative))
        .collect();
    // Static shapes taken out beside a table as ones the records do not tell from the loop
    // (GAP.md step 17): they took part of it, and a loop of another form could leave it.
    let untold: Vec<String> = pairs
        .iter()
        .filter(|c| c.taken_out == TakenOut::Untold)
        .map(|c| format!("{} / {}", c.named, c.alternative))
        .collect();
    match taken_out {
        None if !untold.is_empty() => format!(
            "no catalogued effect is admissible that the records tell from the loop: a static \
             shape beside the table took part of it, but a loop of another form than the \
             table's leaves a centre line and a constant of its own, and these records have no \
             held levels or rest at 0 V to tell the two ({} above)",
            pairs_words(&untold)
        ),
        None if !alike.is_empty() => alike_words("no catalogued effect is admissible on its own: "),
        None if !in_place.is_empty() => format!(
            "no catalogued effect is admissible that the records show: the final check took out \
             an offset beside the table whose work was not a level; {in_place_words}"
        ),
        None if !below_bar.is_empty() => format!(
            "no catalogued effect earns its parameters on these records: the final check took \
             out a static shape that took part of it beside the table, the others' refit (the \
             table's among them) takes up most of the same work, and the records cannot tell \
             the two ({} above)",
            pairs_words(&below_bar)
        ),
        None => "no catalogued effect is admissible".into(),
        Some(c) => {
            let taken = format!(
                "no catalogued effect is admissible that the records show: an {} beside the \
                 final model's effects left {:.2} mV of residual (the final model {:.2} mV), \
                 but the final check took it out as a level the residual without it does not \
                 show (the {} / {} pair above)",
                c.alternative,
                1e3 * c.alternative_rms_v,
                1e3 * final_rms_v,
                c.named,
                c.alternative
            );
            if in_place.is_empty() {
                taken
            } else {
                format!("{taken}; {in_place_words}")
            }
        }
    }
}

/// "the A / B pair" or "the A / B and C / D pairs".
fn pairs_words(pairs: &[String]) -> String {
    match pairs {
        [one] => format!("the {one} pair"),
        _ => format!("the {} pairs", pairs.join(" and ")),
    }
}

fn fmt_num(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-2..1e4).contains(&a) {
        format!("{v:.3e}")
    } else {
        format!("{v:.4}")
    }
}

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(80, 80, 80),
];

type Series = (String, Vec<(f64, f64)>);

/// At most `max` points, evenly picked.
fn thin(v: Vec<(f64, f64)>, max: usize) -> Vec<(f64, f64)> {
    if v.len() <= max {
        return v;
    }
    let step = v.len() as f64 / max as f64;
    (0..max)
        .filter_map(|i| v.get((i as f64 * step) as usize).copied())
        .collect()
}

/// A line (or point) plot as an SVG string.
fn plot(title: &str, xl: &str, yl: &str, series: &[Series], points: bool, log_y: bool) -> String {
    let mut svg = String::new();
    let r = (|| -> Result<(), Box<dyn std::error::Error>> {
        let root = SVGBackend::with_string(&mut svg, (760, 330)).into_drawing_area();
        root.fill(&WHITE)?;
        let all = series.iter().flat_map(|s| s.1.iter());
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for &(x, y) in all {
            if x.is_finite() && y.is_finite() && (!log_y || y > 0.0) {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
        if !(x0.is_finite() && y0.is_finite()) {
            return Ok(());
        }
        if x1 <= x0 {
            x1 = x0 + 1.0;
        }
        if y1 <= y0 {
            y1 = y0 + 1e-6;
        }
        let pad = 0.05 * (y1 - y0);
        let mut b = ChartBuilder::on(&root);
        b.caption(title, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(36)
            .y_label_area_size(64);
        if log_y {
            let mut c = b.build_cartesian_2d(x0..x1, (y0.max(1e-9)..y1 * 1.5).log_scale())?;
            c.configure_mesh().x_desc(xl).y_desc(yl).draw()?;
            for (i, (name, pts)) in series.iter().enumerate() {
                let col = COLORS[i % COLORS.len()];
                c.draw_series(LineSeries::new(
                    pts.iter().copied().filter(|p| p.1 > 0.0),
                    col.stroke_width(1),
                ))?
                .label(name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], col));
            }
            c.configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()?;
        } else {
            let mut c = b.build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))?;
            c.configure_mesh().x_desc(xl).y_desc(yl).draw()?;
            for (i, (name, pts)) in series.iter().enumerate() {
                let col = COLORS[i % COLORS.len()];
                if points {
                    c.draw_series(pts.iter().map(|p| Circle::new(*p, 1, col.filled())))?
                        .label(name.as_str())
                        .legend(move |(x, y)| Circle::new((x + 8, y), 3, col.filled()));
                } else {
                    c.draw_series(LineSeries::new(pts.iter().copied(), col.stroke_width(1)))?
                        .label(name.as_str())
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], col));
                }
            }
            c.configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()?;
        }
        root.present()?;
        Ok(())
    })();
    if let Err(e) = r {
        return format!("<p>plot failed: {e}</p>");
    }
    svg
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// Write `dir/index.html`.
pub fn write(dir: &Path, base: &ModelFile, data: &[Data], d: &Diagnosis) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    // (the records as the diagnosis read them: glitches replaced, as the notes say)
    let cleaned = d.cleaned(data);
    let data: &[Data] = &cleaned;
    let mut h = String::new();
    let _ = write!(
        h,
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>piezo gap report</title>\
         <style>body{{font-family:sans-serif;max-width:1600px;margin:auto}}table{{border-collapse:collapse}}\
         td,th{{border:1px solid #aaa;padding:3px 8px;font-size:13px}}.row{{display:flex;flex-wrap:wrap}}</style></head><body>\
         <h1>Model gap: {} &rarr; named [{}]</h1><p>Noise floor {:.2} mV; residual {:.2} mV with the base model, {:.2} mV at the end.</p>",
        esc(&base.name),
        esc(&d.named.join(", ")),
        1e3 * d.noise_floor_v,
        1e3 * d.steps.first().map_or(d.final_rms_v, |s| s.rms_before_v),
        1e3 * d.final_rms_v
    );
    for n in &d.noise_notes {
        let _ = write!(h, "<p>Noise: {}.</p>", esc(n));
    }
    h.push_str("<h2>Steps</h2><table><tr><th>step</th><th>effect</th><th>evidence</th><th>parameters</th><th>RMS before</th><th>RMS after</th></tr>");
    for (i, s) in d.steps.iter().enumerate() {
        let p: Vec<String> = s.params.iter().map(|(k, v)| format!("{k} = {v}")).collect();
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}{}</td><td>{}</td><td>{}</td><td>{:.2} mV</td><td>{:.2} mV</td></tr>",
            i + 1,
            esc(&s.effect),
            if s.removed {
                " (removed)"
            } else if s.refit {
                " (refit)"
            } else {
                ""
            },
            esc(&s.evidence),
            esc(&p.join(", ")),
            1e3 * s.rms_before_v,
            1e3 * s.rms_after_v
        );
    }
    h.push_str("</table>");
    let final_sims: Vec<&Vec<f64>> = (0..data.len())
        .map(|r| d.steps.last().map_or(&d.base_sims[r], |s| &s.sims[r]))
        .collect();
    h.push_str("<h2>Measured and simulated</h2><div class=\"row\">");
    for (r, rec) in data.iter().enumerate() {
        let pts = |v: &[f64]| {
            thin(
                rec.t_s.iter().copied().zip(v.iter().copied()).collect(),
                3000,
            )
        };
        h.push_str(&plot(
            &format!("{}: measured and simulated", rec.name),
            "t (s)",
            "y (V)",
            &[
                ("measured".into(), pts(&rec.y_v)),
                ("base model".into(), pts(&d.base_sims[r])),
                ("final model".into(), pts(final_sims[r])),
            ],
            false,
            false,
        ));
    }
    h.push_str("</div><h2>Residual before and after each step</h2><div class=\"row\">");
    for (r, rec) in data.iter().enumerate() {
        let res = |s: &[f64]| {
            thin(
                rec.t_s
                    .iter()
                    .zip(rec.y_v.iter().zip(s))
                    .map(|(t, (y, m))| (*t, 1e3 * (y - m)))
                    .collect(),
                3000,
            )
        };
        let mut series = vec![("base".to_string(), res(&d.base_sims[r]))];
        for (i, s) in d.steps.iter().enumerate() {
            series.push((format!("after {}: {}", i + 1, s.effect), res(&s.sims[r])));
        }
        h.push_str(&plot(
            &format!("{}: residual", rec.name),
            "t (s)",
            "residual (mV)",
            &series,
            false,
            false,
        ));
    }
    h.push_str("</div>");
    for c in &d.cannot_tell {
        let _ = write!(
            h,
            "<h2>Cannot tell {} from {}</h2><p>{}</p>",
            esc(&c.named),
            esc(&c.alternative),
            esc(&c.why)
        );
    }
    if let Some(u) = &d.unexplained {
        let _ = write!(
            h,
            "<h2>Unexplained</h2><p>{:.2} mV RMS above the noise stays after the last step: \
             {}. Where: {}</p><div class=\"row\">",
            1e3 * u.rms_v,
            esc(&unexplained_words(d.final_rms_v, &d.cannot_tell)),
            esc(&u.where_)
        );
        for (r, rec) in data.iter().enumerate() {
            let res = residual_against_input(rec, final_sims[r]);
            h.push_str(&plot(
                &format!("{}: final residual against input", rec.name),
                "u (V)",
                "residual (mV)",
                &[("final residual".into(), thin(res, 4000))],
                true,
                false,
            ));
        }
        h.push_str("</div>");
    }
    h.push_str("<h2>Evidence (base model's residual)</h2><div class=\"row\">");
    // Residual against input (loop, gain curve) for every record with reversals, before and
    // after; tails for every record with holds.
    for (r, rec) in data.iter().enumerate() {
        let res: Vec<f64> = rec
            .y_v
            .iter()
            .zip(&d.base_sims[r])
            .map(|(y, m)| 1e3 * (y - m))
            .collect();
        if rec.reversals() > 0 {
            let loop_pts = thin(
                rec.u_v.iter().copied().zip(res.iter().copied()).collect(),
                4000,
            );
            let after = residual_against_input(rec, final_sims[r]);
            h.push_str(&plot(
                &format!(
                    "{}: residual against input ({} reversals; hysteresis loop, gain curve)",
                    rec.name,
                    rec.reversals()
                ),
                "u (V)",
                "residual (mV)",
                &[
                    ("base model".into(), loop_pts),
                    ("final model".into(), thin(after, 4000)),
                ],
                true,
                false,
            ));
        }
        // Tails: residual during holds, time since the hold began.
        let mut tails: Vec<Series> = Vec::new();
        let t = rec.period_s();
        for hold in rec.holds().into_iter().take(6) {
            let s = hold.start;
            let pts: Vec<(f64, f64)> = hold
                .map(|k| ((k - s) as f64 * t, res[k] - res[s]))
                .collect();
            tails.push((format!("hold at {:.2} V", rec.u_v[s]), thin(pts, 1500)));
        }
        if !tails.is_empty() {
            h.push_str(&plot(
                &format!("{}: residual during holds (drift tails)", rec.name),
                "time since the step (s)",
                "residual change (mV)",
                &tails,
                false,
                false,
            ));
        }
    }
    for (r, rec) in data.iter().enumerate().filter(|(_, x)| x.is_fast()).take(1) {
        let n = rec.len().min((0.03 / rec.period_s()) as usize);
        let pts = |v: &[f64]| {
            rec.t_s[..n]
                .iter()
                .copied()
                .zip(v[..n].iter().copied())
                .collect::<Vec<_>>()
        };
        h.push_str(&plot(
            &format!(
                "{}: first step edges (delay, pole, slew, ringing)",
                rec.name
            ),
            "t (s)",
            "y (V)",
            &[
                ("measured".into(), pts(&rec.y_v)),
                ("base model".into(), pts(&d.base_sims[r])),
                ("final model".into(), pts(final_sims[r])),
            ],
            false,
            false,
        ));
    }
    if !d.signatures.spectrum.is_empty() {
        let pts: Vec<(f64, f64)> = d
            .signatures
            .spectrum
            .iter()
            .map(|(f, a)| (*f, *a * 1e3))
            .collect();
        h.push_str(&plot(
            "residual spectrum of the fast record (base model)",
            "f (Hz)",
            "amplitude (mV)",
            &[("residual".into(), thin(pts, 4000))],
            false,
            true,
        ));
    }
    h.push_str("</div><h2>Candidates tried</h2>");
    for (i, t) in d.tried.iter().enumerate() {
        let _ = write!(h, "<p>step {}: ", i + 1);
        for (e, s, x, ok) in t {
            let _ = write!(
                h,
                "{} (score {:.0}, explains {:.0} %{}); ",
                esc(e),
                s,
                100.0 * x,
                if *ok { "" } else { ", not admissible" }
            );
        }
        if let Some(left) = d.not_searched.get(i).filter(|l| !l.is_empty()) {
            for (e, why) in left {
                let _ = write!(h, "{} (left out: {}); ", esc(e), esc(why));
            }
        }
        h.push_str("</p>");
    }
    let _ = write!(
        h,
        "<h2>Augmented model</h2><pre>{}</pre></body></html>",
        esc(&d.model.to_toml().unwrap_or_default())
    );
    crate::io::checks::write_bytes(&dir.join("index.html"), h.as_bytes())?;
    Ok(())
}

/// `(u V, y - sim mV)` of a record: the residual against the input.
fn residual_against_input(rec: &Data, sims: &[f64]) -> Vec<(f64, f64)> {
    rec.u_v
        .iter()
        .zip(rec.y_v.iter().zip(sims))
        .map(|(u, (y, m))| (*u, 1e3 * (y - m)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair(rms_v: f64, alt_v: f64, taken_out: bool) -> CannotTell {
        CannotTell {
            named: "hysteresis".into(),
            alternative: "offset".into(),
            rms_v,
            alternative_rms_v: alt_v,
            neither_named: false,
            taken_out: if taken_out {
                TakenOut::Unshown
            } else {
                TakenOut::No
            },
            why: String::new(),
        }
    }

    /// The unexplained part says what an offset the final check took out left only where
    /// that check's model is the final one (its residual to the bit), and the offset left
    /// clearly less (families case 1001: 1.53 mV with it, 52.57 mV without); other pairs
    /// with the final model on one side (a rest reading the offset did not take), a check's
    /// model that later steps changed, or an offset that left about as much, keep the plain
    /// words; look-alikes left unnamed (`neither_named`) are listed in them, the shapes that
    /// could have done a taken-out offset's work after its words (or alone where later steps
    /// changed the model), and shapes taken out below their bars beside a table by their
    /// pairs.
    #[test]
    fn the_unexplained_part_says_what_an_offset_taken_out_left() {
        let plain = "no catalogued effect is admissible";
        let final_v = 52.57e-3;
        assert_eq!(unexplained_words(final_v, &[]), plain);
        let other_kind = pair(final_v, 1.53e-3, false);
        let changed_since = pair(60e-3, 1.53e-3, true);
        let alike = pair(final_v, final_v / 1.2, true);
        assert_eq!(
            unexplained_words(final_v, &[other_kind.clone(), changed_since.clone(), alike]),
            plain
        );
        let look_alike = CannotTell {
            named: "nonlinear-gain".into(),
            alternative: "sensor-gain".into(),
            neither_named: true,
            ..pair(final_v, final_v / 3.0, false)
        };
        let w = unexplained_words(final_v, &[other_kind.clone(), look_alike]);
        assert!(
            w.starts_with("no catalogued effect is admissible on its own: the look-alikes nonlinear-gain / sensor-gain explain part of it alike"),
            "{w}"
        );
        let taken = pair(final_v, 1.53e-3, true);
        let w = unexplained_words(final_v, &[other_kind.clone(), taken.clone()]);
        assert!(
            w.contains("an offset beside the final model's effects left 1.53 mV of residual (the final model 52.57 mV)"),
            "{w}"
        );
        assert!(!w.contains("look-alikes"), "{w}");
        // The shapes that could have done that offset's work are listed after it, and
        // without it where later steps changed the final model (not as look-alikes).
        let in_its_place = CannotTell {
            named: "sensor-gain".into(),
            alternative: "offset".into(),
            neither_named: true,
            taken_out: TakenOut::InOffsetsPlace,
            ..pair(1.6e-3, 1.53e-3, false)
        };
        let w = unexplained_words(final_v, &[taken, in_its_place.clone()]);
        assert!(
            w.contains("(the hysteresis / offset pair above); sensor-gain fitted in its place explains a step's share"),
            "{w}"
        );
        let w = unexplained_words(final_v, &[changed_since, in_its_place]);
        assert!(
            w.starts_with("no catalogued effect is admissible that the records show: the final check took out an offset beside the table whose work was not a level; sensor-gain fitted")
                && !w.contains("look-alikes"),
            "{w}"
        );
        // A shape taken out below its bar beside the table is named in the words.
        let below = CannotTell {
            alternative: "nonlinear-gain".into(),
            taken_out: TakenOut::BelowBar,
            ..pair(final_v, final_v / 1.5, false)
        };
        let w = unexplained_words(final_v, &[other_kind.clone(), below.clone()]);
        assert!(
            w.starts_with("no catalogued effect earns its parameters on these records")
                && w.contains("(the hysteresis / nonlinear-gain pair above)"),
            "{w}"
        );
        let scale = CannotTell {
            alternative: "sensor-gain".into(),
            ..below.clone()
        };
        let w = unexplained_words(final_v, &[other_kind, below, scale]);
        assert!(
            w.contains(
                "(the hysteresis / nonlinear-gain and hysteresis / sensor-gain pairs above)"
            ),
            "{w}"
        );
    }
}
