//! The diagnosis as an HTML fragment (for `diagnosis.html` and for embedding in a report).

use std::fmt::Write as _;

use super::{
    Candidate, Diagnosis, Drift, Score, coupled_alone_text, coupled_text, cross_fit_text, g4,
    param_text,
};

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The diagnosis as a self-contained HTML fragment (a `<section>` with inline styles): the
/// verdict, a table of candidates with a bar per error reduction, and the residual correlations.
/// Wrap it in a page with [`diagnosis_page`] or embed it in another report.
pub fn diagnosis_html(d: &Diagnosis) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "<section class=\"diagnosis\" style=\"font-family:sans-serif;max-width:60em\">"
    );
    let _ = writeln!(o, "<h2>Diagnosis: which physical effect is missing?</h2>");
    let colour = if d.verdict.is_some() {
        "#1a7f37"
    } else {
        "#9a6700"
    };
    let _ = writeln!(
        o,
        "<p style=\"font-size:1.2em;color:{colour}\"><b>{}</b></p>",
        esc(&d.summary)
    );
    let _ = writeln!(
        o,
        "<p>{} {} model{}; {}-step open-loop error on {} held-out segments ({} windows), candidates fitted on {} other segments. Baseline error {} (normalised: 1 = the error of a model that predicts no motion).</p>",
        d.world,
        esc(&d.model_kind),
        if d.model_effects.is_empty() {
            String::new()
        } else {
            format!(" with {}", esc(&d.model_effects.join(", ")))
        },
        d.steps,
        d.segments[1],
        d.windows[1],
        d.segments[0],
        g4(d.baseline_error)
    );
    if let Some(h) = d.config.fitted_starts {
        let _ = writeln!(
            o,
            "<p>Fitted starts: each model compared (the baseline and every candidate) starts each window from its own fit to the {h} s of poses before it{}.</p>",
            match d.config.score {
                Score::Poses =>
                    ", and is scored on the poses alone: nothing it is compared with is an estimate",
                Score::States => "",
            }
        );
    }
    if let Some(c) = d.model_states_caution() {
        let _ = writeln!(o, "<p>States from the model: {}.</p>", esc(&c));
    }
    if let Some(f) = &d.noise_floor {
        let _ = writeln!(
            o,
            "<p>Of that error, {}: the velocities estimated from noisy poses are noisy themselves, at the start of every window and in every state it is compared with. Read the error each effect removes against it.</p>",
            esc(&f.text())
        );
    }
    if !d.nominal_refit.is_empty() {
        let p: Vec<String> = d
            .nominal_refit
            .iter()
            .map(|(k, v)| format!("{} = {}", esc(k), g4(*v)))
            .collect();
        let measured: Vec<String> = d
            .nominal_measured
            .iter()
            .map(|(k, t)| format!("{} within ±{:.0} %", esc(k), 100.0 * t))
            .collect();
        let _ = writeln!(
            o,
            "<p>The model's nominal parameters are refitted on the fit half for the baseline ({}) and jointly with every candidate, so an effect is credited only with what the nominal model cannot absorb.{}</p>",
            p.join(", "),
            match measured.is_empty() {
                true => String::new(),
                false => format!(
                    " Measured ones are refitted for the baseline alone and held at the model's value with the candidates: {}.",
                    measured.join(", ")
                ),
            }
        );
    }
    for b in &d.nominal_on_bound {
        let _ = writeln!(
            o,
            "<p>On a bound: the baseline's {} (the nominal model does not follow these data there; an effect found may stand in for what it lacks).</p>",
            esc(b)
        );
    }
    if let Some(s) = &d.one_start {
        let _ = writeln!(o, "<p>Data: {}.</p>", esc(&s.text()));
    }
    for step in &d.selection {
        let _ = writeln!(
            o,
            "<h3>Step {}: candidates against the model{}</h3><p>Held-out error before this step {}.</p>",
            step.step,
            if step.given.is_empty() {
                String::new()
            } else {
                format!(" + {}", esc(&step.given.join(" + ")))
            },
            g4(step.error_before)
        );
        o.push_str(&candidate_table(&step.candidates, step.added.as_deref(), d));
        let _ = match &step.added {
            Some(e) => writeln!(
                o,
                "<p>→ <b>{}</b> added: held-out error {} → {} ({:+.0} %).</p>",
                esc(e),
                g4(step.error_before),
                g4(step.error_after),
                100.0 * (step.error_after / step.error_before.max(1e-300) - 1.0)
            ),
            None => writeln!(
                o,
                "<p>→ no candidate is significant: the selection stops.</p>"
            ),
        };
    }
    if !d.dropped.is_empty() {
        let _ = writeln!(
            o,
            "<h3>Backward check: dropped</h3><p>Each selected effect scored again against the model with the other selected effects and the terms the term search found after them. These no longer count, and are not in the set below:</p>"
        );
        o.push_str(&candidate_table(&d.dropped, None, d));
    }
    if let Some(j) = &d.joint {
        let _ = writeln!(
            o,
            "<h3>The selected effects refitted together</h3><p><b>{}</b>: held-out error {} → {}, {:.1} % removed (bootstrap lower bound {:.1} %). Add them with <code>dynlab train --kind physics --effects {}</code>, starting from the values below (<code>--set effect.name=value</code> for each; the terminal prints the whole command).</p><table style=\"border-collapse:collapse\"><tr><th align=left>parameter</th><th align=right>value</th><th align=right>± std</th><th align=left>unit</th></tr>",
            esc(&j.effects.join(" + ")),
            g4(j.error_before),
            g4(j.error_after),
            100.0 * j.error_reduction,
            100.0 * j.ci_lower.max(-9.99),
            esc(&j.effects.join(","))
        );
        for (name, v) in &j.params {
            let sd = j.param_std.get(name).copied().unwrap_or(0.0);
            let _ = writeln!(
                o,
                "<tr><td>{}</td><td align=right>{}</td><td align=right>{}</td><td>{}</td></tr>",
                esc(name),
                g4(*v),
                match j.on_bound.get(name) {
                    Some(side) => format!("on its {side} bound"),
                    None if sd > 0.0 => g4(sd),
                    None => "–".into(),
                },
                esc(j.param_units.get(name).map_or("", |u| u.as_str()))
            );
        }
        for (name, v) in d.coupled_nominal(&j.nominal_params) {
            let _ = writeln!(
                o,
                "<tr><td>{} (nominal, refitted with the effects)</td><td align=right>{}</td><td align=right>–</td><td></td></tr>",
                esc(name),
                g4(v)
            );
        }
        let _ = writeln!(o, "</table>");
        if !j.spin_windows.is_empty() {
            let _ = writeln!(
                o,
                "<p>Without the {} held-out windows that both the model as given and the model with the effects roll out through a spin: {} → {}, {:.1} % removed from the model as given.</p>",
                j.spin_windows.len(),
                g4(j.model_error_calm),
                g4(j.error_after_calm),
                100.0 * j.reduction_vs_model_calm
            );
        }
    }
    if let Some(disc) = &d.discovery {
        o.push_str(&crate::discovery::discovery_html(disc));
    }
    if let Some(dr) = &d.drift {
        o.push_str(&drift_html(dr));
    }
    if !d.correlations.is_empty() {
        let _ = writeln!(
            o,
            "<h3>What the one-step residual correlates with</h3><table style=\"border-collapse:collapse\"><tr><th align=left>residual of</th><th align=left>feature</th><th>r</th></tr>"
        );
        for c in &d.correlations {
            let _ = writeln!(
                o,
                "<tr><td>{}</td><td>{}</td><td align=right>{:+.2}</td></tr>",
                esc(&c.dimension),
                esc(&c.feature),
                c.r
            );
        }
        let _ = writeln!(o, "</table>");
    }
    let _ = writeln!(o, "</section>");
    o
}

/// One step's candidates as a table with a bar per error reduction (`added` in bold).
fn candidate_table(cands: &[Candidate], added: Option<&str>, d: &Diagnosis) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "<table style=\"border-collapse:collapse\"><tr><th align=left>effect</th><th align=left>held-out error removed</th><th title=\"the larger of the one-sided bootstrap bounds of the total held-out error's reduction and of the typical segment's (geometric mean of the segments' error ratios), each at half the error probability\">bootstrap lower bound</th><th>significant</th><th title=\"held-out windows both models roll out through a spin, left out of this candidate's scores\">spins left out</th><th align=left>fitted parameters (± std)</th></tr>"
    );
    for c in cands {
        let w = (c.error_reduction * 200.0).round();
        let mut params: Vec<String> = c
            .params
            .iter()
            .map(|(k, v)| {
                esc(&param_text(
                    k,
                    *v,
                    &c.param_std,
                    &c.param_units,
                    &c.on_bound,
                ))
            })
            .collect();
        params.extend(coupled_text(d, &c.nominal_params).map(|t| esc(&t)));
        params.extend(c.coupled_alone.map(|r| esc(&coupled_alone_text(r))));
        let bold = if added == Some(c.effect.as_str()) {
            "font-weight:bold;"
        } else {
            ""
        };
        let _ = writeln!(
            o,
            "<tr style=\"{bold}border-top:1px solid #ddd\"><td title=\"{}\">{}</td><td><span style=\"display:inline-block;height:0.8em;width:{w}px;background:{}\"></span> {:.1} %</td><td align=right>{:.1} %</td><td align=center>{}</td><td align=right>{}</td><td>{}</td></tr>",
            esc(&c.description),
            esc(&c.effect),
            if c.significant { "#1a7f37" } else { "#aaa" },
            100.0 * c.error_reduction,
            100.0 * c.ci_lower.max(-9.99),
            if c.significant { "yes" } else { "no" },
            c.chaotic_windows,
            params.join(", ")
        );
        for x in [&c.cross_fit, &c.fold_fit].into_iter().flatten() {
            let _ = writeln!(
                o,
                "<tr><td></td><td colspan=5 style=\"color:#555\">{}</td></tr>",
                esc(&cross_fit_text(x))
            );
        }
        if let Some(n) = &c.note {
            let _ = writeln!(
                o,
                "<tr><td></td><td colspan=5 style=\"color:#9a6700\">not counted: {}</td></tr>",
                esc(n)
            );
        }
        if let Some(n) = &c.paired {
            let _ = writeln!(
                o,
                "<tr><td></td><td colspan=5 style=\"color:#1a7f37\">added {}</td></tr>",
                esc(n)
            );
        }
    }
    let _ = writeln!(o, "</table>");
    o
}

/// A complete offline HTML page around [`diagnosis_html`].
pub fn diagnosis_page(d: &Diagnosis) -> String {
    format!(
        "<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>dynlab diagnosis</title></head><body>\n{}</body></html>\n",
        diagnosis_html(d)
    )
}

/// The drift check: the best parameter's drift, every parameter's share, and for a significant
/// drift the plot of its per-block values against the line fitted over the recording.
fn drift_html(dr: &Drift) -> String {
    use crate::report::{Chart, LineChart, Series};
    let mut o = String::new();
    let _ = writeln!(
        o,
        "<h3>Did the robot change while it was recorded?</h3><p>{}.</p>",
        esc(&dr.text())
    );
    let _ = writeln!(
        o,
        "<p>Held-out error removed by each quantity's line through its blocks, against their median: {}. {}</p>",
        esc(&dr.tried_text()),
        if dr.significant {
            esc(&format!("Significant: {}.", dr.advice()))
        } else {
            "None significant: the robot stayed the same as far as these data tell.".to_string()
        }
    );
    if dr.blocks.is_empty() {
        return o;
    }
    let chart = LineChart::new(
        format!("{} along the recording", dr.quantity),
        "share of the recording before",
        format!("scale of {} (× the model's)", dr.params.join(", ")),
    )
    .series(Series::points(
        "fitted on one block alone",
        dr.blocks.iter().map(|b| (b[0], b[1])).collect(),
    ))
    .series(Series::line(
        "the line through them",
        vec![(0.0, dr.start), (1.0, dr.end)],
    ))
    .hline(1.0, "the model's values");
    match chart.render_svg() {
        Ok(svg) => {
            let _ = writeln!(
                o,
                "<figure>{svg}<figcaption>{} ({}) fitted on each sixth of the recording alone (points) and the line through them</figcaption></figure>",
                esc(&dr.quantity),
                esc(&dr.params.join(", "))
            );
        }
        Err(e) => {
            let _ = writeln!(o, "<p><i>plot not drawn: {}</i></p>", esc(&e.to_string()));
        }
    }
    o
}
