//! The HTML page of a comparison, built with [`crate::report`].
//!
//! With one model, each figure shows that model. With a baseline, every figure that exists for
//! both models overlays them: the error over time, the error binned against each cause and the
//! residual correlations as two series on one set of axes per state dimension ("before:
//! `<baseline>`", "after: `<model>`"), the position map as two panels on one colour scale.

use crate::report::{Chart, Heatmap, HeatmapPanels, LineChart, Report, Series, Table};

use super::{CompareReport, CorrelationReport, ModelComparison};

/// Size of an overlay chart of one state dimension (several stand side by side).
const OVERLAY_SIZE: (u32, u32) = (420, 270);

/// Most points drawn per chart (series are thinned evenly beyond this).
const MAX_POINTS: usize = 4000;

fn thin(points: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    if points.len() <= MAX_POINTS {
        return points;
    }
    let step = points.len().div_ceil(MAX_POINTS);
    points.into_iter().step_by(step).collect()
}

/// Builds the report page (append more sections before writing it, e.g. a diagnosis).
pub fn report(r: &CompareReport) -> Report {
    let m = &r.model;
    let title = match &r.baseline {
        Some(b) => format!(
            "{} against {} on {}",
            m.label,
            b.label,
            r.data.bags.join(", ")
        ),
        None => format!("{} on {}", m.label, r.data.bags.join(", ")),
    };
    let mut rep = Report::new(title);
    let k = r.config.steps;

    // errors
    {
        let s = rep.section("Errors");
        s.text(format!(
            "{} world, {} windows of {} open-loop steps (step {:.4} s). Model: {} ({}).{}",
            r.world,
            m.eval.windows,
            k,
            r.data.dt_s,
            m.label,
            m.eval.kind,
            r.baseline
                .as_ref()
                .map(|b| format!(" Baseline: {} ({}).", b.label, b.eval.kind))
                .unwrap_or_default()
        ));
        s.table(r.error_table().caption(if r.baseline.is_some() {
            "RMSE per state dimension and k, baseline → model (negative change: the model is better)"
        } else {
            "errors per state dimension (angles wrapped)"
        }));
        if r.baseline.is_none()
            && let Some(t) = &m.eval.tve
        {
            s.text(format!(
                "TVE over {} segments of {:.1} s: {:.4}",
                t.segments, t.segment_s, t.tve
            ));
        }
        for w in &r.data.warnings {
            s.note(format!("warning: {w}"));
        }
    }

    // data
    {
        let s = rep.section("Data");
        for (bag, notes) in r.data.bags.iter().zip(&r.data.notes) {
            s.text(format!("{bag}:"));
            s.pre(notes.join("\n"));
        }
    }

    let models: Vec<&ModelComparison> = std::iter::once(m).chain(r.baseline.as_ref()).collect();

    // over time
    if let Some(b) = &r.baseline {
        over_time_overlay(&mut rep, r, b);
    } else {
        let s = rep.section("Error over time");
        s.text(format!(
            "{k}-step error per state dimension against seconds from the bag start (RMS over blocks of windows), one line per bag."
        ));
        for (d, name) in r.states.iter().enumerate() {
            let charts: Vec<LineChart> = models
                .iter()
                .map(|mc| {
                    let mut c = LineChart::new(
                        format!("{name}: {k}-step error, {}", mc.label),
                        "time from bag start (s)",
                        name.clone(),
                    );
                    for (bi, bag) in r.data.bags.iter().enumerate() {
                        let pts: Vec<(f64, f64)> = mc
                            .over_time
                            .iter()
                            .filter(|e| e.bag == bi)
                            .flat_map(|e| {
                                e.t_s
                                    .iter()
                                    .zip(&e.rmse[d])
                                    .map(|(&t, &v)| (t, v))
                                    .chain([(f64::NAN, f64::NAN)])
                            })
                            .collect();
                        c = c.series(Series::points(bag.clone(), thin(pts)));
                    }
                    c
                })
                .collect();
            let refs: Vec<&dyn Chart> = charts.iter().map(|c| c as &dyn Chart).collect();
            s.chart_row(&refs);
        }
    }

    // binned
    if let Some(b) = &r.baseline {
        binned_overlay(&mut rep, r, b);
    } else {
        let s = rep.section("Error against its causes");
        s.text(format!(
            "{k}-step RMSE in bins of each quantity at the window start, divided by the model's overall {k}-step RMSE of that dimension (1 = average; above 1: the model is worse there). Counts per bin in the tables."
        ));
        for qi in 0..m.binned.len() {
            let charts: Vec<LineChart> = models
                .iter()
                .map(|mc| {
                    let bb = &mc.binned[qi];
                    let centres: Vec<f64> =
                        bb.edges.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
                    let mut c = LineChart::new(
                        format!("{} ({}), {}", bb.quantity, bb.unit, mc.label),
                        format!("{} ({})", bb.quantity, bb.unit),
                        "relative error",
                    )
                    .hline(1.0, "mean");
                    for (d, name) in r.states.iter().enumerate() {
                        let norm = mc.eval.k_step[d].rmse;
                        let pts = centres
                            .iter()
                            .zip(&bb.rmse[d])
                            .zip(&bb.counts)
                            .filter(|(_, c)| **c > 0)
                            .map(|((&x, &v), _)| (x, if norm > 0.0 { v / norm } else { 0.0 }))
                            .collect();
                        c = c.series(Series::line(name.clone(), pts));
                    }
                    c
                })
                .collect();
            let refs: Vec<&dyn Chart> = charts.iter().map(|c| c as &dyn Chart).collect();
            s.chart_row(&refs);
            s.table(binned_table(r, &models, qi));
        }
    }

    // map
    if let Some(b) = &r.baseline {
        map_overlay(&mut rep, r, b);
    } else {
        let s = rep.section(if r.world == dynlab_learn::World::Car {
            "Error over the floor"
        } else {
            "Error over the table"
        });
        s.text(format!(
            "RMS of the {k}-step position error √(e_x² + e_y²) by the position at the window start; grey: no data."
        ));
        let maps: Vec<Heatmap> = models
            .iter()
            .map(|mc| position_heatmap(mc, format!("position error (m), {}", mc.label)))
            .collect();
        let refs: Vec<&dyn Chart> = maps.iter().map(|c| c as &dyn Chart).collect();
        s.chart_row(&refs);
    }

    // correlations
    if let Some(b) = &r.baseline {
        correlation_overlay(&mut rep, r, b);
    } else {
        for mc in &models {
            let c = &mc.correlation;
            let s = rep.section(format!("Residual correlations, {}", mc.label));
            s.text(format!(
            "One-step residuals over {} samples; dashed: the 95 % band ±1.96/√N = ±{:.3}. Positive lag: the input leads the residual (one step = {:.4} s). A white residual stays inside the band; a peak of an input at a positive lag means an unmodelled delay or lag.",
            c.n, c.band, c.dt_s
        ));
            for f in &c.findings {
                s.note(f.message.clone());
            }
            if c.findings.is_empty() {
                s.text("No lagged input peak outside the band.");
            }
            let lags: Vec<f64> = c.lags.iter().map(|&l| l as f64).collect();
            let mut ac = LineChart::new("residual autocorrelation", "lag (steps)", "r")
                .hline(c.band, "+95 %")
                .hline(-c.band, "−95 %");
            for a in &c.autocorrelation {
                ac = ac.series(Series::line(
                    a.state.clone(),
                    lags.iter().copied().zip(a.r.iter().copied()).collect(),
                ));
            }
            let mut charts = vec![ac];
            for inp in &r.inputs {
                let mut cc = LineChart::new(format!("residual × input {inp}"), "lag (steps)", "r")
                    .hline(c.band, "+95 %")
                    .hline(-c.band, "−95 %");
                for x in c.cross.iter().filter(|x| &x.with == inp) {
                    cc = cc.series(Series::line(
                        x.state.clone(),
                        lags.iter().copied().zip(x.r.iter().copied()).collect(),
                    ));
                }
                charts.push(cc);
            }
            let refs: Vec<&dyn Chart> = charts.iter().map(|c| c as &dyn Chart).collect();
            s.chart_row(&refs);
            s.table(correlation_table(c));
        }
    }

    // worst segments
    for mc in &models {
        let s = rep.section(format!("Worst segments, {}", mc.label));
        s.text("Windows with the largest k-step error (score: mean over dimensions of the squared error relative to that dimension's RMSE; 1 is typical), not overlapping.");
        let mut header = vec![
            "rank".to_string(),
            "bag".into(),
            "from (s)".into(),
            "to (s)".into(),
            "start stamp (ns)".into(),
            "end stamp (ns)".into(),
            "score".into(),
        ];
        header.extend(r.states.iter().map(|n| format!("e_{n}")));
        let mut t = Table::new(header);
        for w in &mc.worst {
            let mut row = vec![
                w.rank.to_string(),
                r.data.bags.get(w.bag).cloned().unwrap_or_default(),
                format!("{:.3}", w.start_s),
                format!("{:.3}", w.end_s),
                w.start_ns.to_string(),
                w.end_ns.to_string(),
                format!("{:.1}", w.score),
            ];
            row.extend(w.error.iter().map(|e| format!("{e:+.3e}")));
            t.push(row);
        }
        s.table(t);
    }
    rep
}

/// The table of the k-step RMSE per bin of quantity `qi`, one column per model and dimension.
fn binned_table(r: &CompareReport, models: &[&ModelComparison], qi: usize) -> Table {
    let k = r.config.steps;
    let b = &r.model.binned[qi];
    let mut header = vec![format!("{} ({})", b.quantity, b.unit), "count".into()];
    for mc in models {
        for n in &r.states {
            header.push(if models.len() > 1 {
                format!("{n} [{}]", mc.label)
            } else {
                n.clone()
            });
        }
    }
    let mut t = Table::new(header).caption(format!(
        "{k}-step RMSE per bin of {}{}",
        b.quantity,
        if b.excluded > 0 {
            format!(" ({} windows excluded: undefined there)", b.excluded)
        } else {
            String::new()
        }
    ));
    for i in 0..b.counts.len() {
        let mut row = vec![
            format!("{:.3} … {:.3}", b.edges[i], b.edges[i + 1]),
            b.counts[i].to_string(),
        ];
        for mc in models {
            for d in 0..r.states.len() {
                row.push(format!("{:.3e}", mc.binned[qi].rmse[d][i]));
            }
        }
        t.push(row);
    }
    t
}

/// The position map of a model as a heatmap (cells without windows left grey).
fn position_heatmap(mc: &ModelComparison, title: String) -> Heatmap {
    let pm = &mc.position_map;
    Heatmap {
        title,
        x_label: "x (m)".into(),
        y_label: "y (m)".into(),
        x_edges: pm.x_edges.clone(),
        y_edges: pm.y_edges.clone(),
        values: pm
            .rmse
            .iter()
            .zip(&pm.counts)
            .map(|(r, c)| {
                r.iter()
                    .zip(c)
                    .map(|(&v, &c)| (c > 0).then_some(v))
                    .collect()
            })
            .collect(),
        size: (460, 420),
    }
}

/// The legend texts of the baseline and the model.
fn legends(r: &CompareReport, b: &ModelComparison) -> (String, String) {
    (
        format!("before: {}", b.label),
        format!("after: {}", r.model.label),
    )
}

/// The k-step error of dimension `d` over the trajectories of bag `bag`, one line per
/// trajectory (NaN between them breaks the line).
fn over_time_points(mc: &ModelComparison, bag: usize, d: usize) -> Vec<(f64, f64)> {
    mc.over_time
        .iter()
        .filter(|e| e.bag == bag)
        .flat_map(|e| {
            e.t_s
                .iter()
                .zip(&e.rmse[d])
                .map(|(&t, &v)| (t, v))
                .chain([(f64::NAN, f64::NAN)])
        })
        .collect()
}

/// Error over time with a baseline: per state dimension and bag, one chart with both models.
fn over_time_overlay(rep: &mut Report, r: &CompareReport, b: &ModelComparison) {
    let k = r.config.steps;
    let (before, after) = legends(r, b);
    let s = rep.section("Error over time");
    s.text(format!(
        "{k}-step error per state dimension against seconds from the bag start (RMS over blocks of windows), before ({}) and after ({}) on the same axes; one chart per bag.",
        b.label, r.model.label
    ));
    for (d, name) in r.states.iter().enumerate() {
        let charts: Vec<LineChart> = r
            .data
            .bags
            .iter()
            .enumerate()
            .map(|(bi, bag)| {
                let title = if r.data.bags.len() > 1 {
                    format!("{name}: {k}-step error, {bag}")
                } else {
                    format!("{name}: {k}-step error")
                };
                LineChart::new(title, "time from bag start (s)", name.clone())
                    .series(Series::line(
                        before.clone(),
                        thin(over_time_points(b, bi, d)),
                    ))
                    .series(Series::line(
                        after.clone(),
                        thin(over_time_points(&r.model, bi, d)),
                    ))
            })
            .collect();
        let refs: Vec<&dyn Chart> = charts.iter().map(|c| c as &dyn Chart).collect();
        s.chart_row(&refs);
    }
}

/// The k-step RMSE of dimension `d` at the centres of the non-empty bins of quantity `qi`.
fn binned_points(mc: &ModelComparison, qi: usize, d: usize) -> Vec<(f64, f64)> {
    let bb = &mc.binned[qi];
    bb.edges
        .windows(2)
        .map(|w| 0.5 * (w[0] + w[1]))
        .zip(&bb.rmse[d])
        .zip(&bb.counts)
        .filter(|(_, c)| **c > 0)
        .map(|((x, &v), _)| (x, v))
        .collect()
}

/// Error against its causes with a baseline: per quantity and state dimension, one chart of
/// the k-step RMSE per bin with both models (absolute, so that the drop shows).
fn binned_overlay(rep: &mut Report, r: &CompareReport, b: &ModelComparison) {
    let k = r.config.steps;
    let (before, after) = legends(r, b);
    let models = [&r.model, b];
    let s = rep.section("Error against its causes");
    s.text(format!(
        "{k}-step RMSE in bins of each quantity at the window start, per state dimension, before ({}) and after ({}) on the same axes. Counts per bin in the tables.",
        b.label, r.model.label
    ));
    for (qi, q) in r.model.binned.iter().enumerate() {
        let charts: Vec<LineChart> = r
            .states
            .iter()
            .enumerate()
            .map(|(d, name)| {
                LineChart::new(
                    format!("{name} against {}", q.quantity),
                    format!("{} ({})", q.quantity, q.unit),
                    format!("{name}: {k}-step RMSE"),
                )
                .size(OVERLAY_SIZE.0, OVERLAY_SIZE.1)
                .series(Series::line(before.clone(), binned_points(b, qi, d)))
                .series(Series::line(after.clone(), binned_points(&r.model, qi, d)))
            })
            .collect();
        let refs: Vec<&dyn Chart> = charts.iter().map(|c| c as &dyn Chart).collect();
        s.chart_row(&refs);
        s.table(binned_table(r, &models, qi));
    }
}

/// The position maps with a baseline: two panels on one colour scale.
fn map_overlay(rep: &mut Report, r: &CompareReport, b: &ModelComparison) {
    let k = r.config.steps;
    let (before, after) = legends(r, b);
    let s = rep.section(if r.world == dynlab_learn::World::Car {
        "Error over the floor"
    } else {
        "Error over the table"
    });
    s.text(format!(
        "RMS of the {k}-step position error √(e_x² + e_y²) by the position at the window start, before and after on one colour scale (the same colour is the same error in both panels); grey: no data."
    ));
    s.chart(&HeatmapPanels::new(
        "position error (m)",
        format!("{k}-step position error (m)"),
        vec![
            position_heatmap(b, before),
            position_heatmap(&r.model, after),
        ],
        (460, 420),
    ));
}

/// The residual correlation of `state` with `with` (itself for the autocorrelation) as points
/// over the lags.
fn lag_points(c: &CorrelationReport, state: &str, with: Option<&str>) -> Vec<(f64, f64)> {
    let x = match with {
        None => c.autocorrelation.iter().find(|a| a.state == state),
        Some(w) => c.cross.iter().find(|x| x.state == state && x.with == w),
    };
    x.map(|x| {
        c.lags
            .iter()
            .map(|&l| l as f64)
            .zip(x.r.iter().copied())
            .collect()
    })
    .unwrap_or_default()
}

/// Residual correlations with a baseline: per state dimension, the autocorrelation and the
/// cross-correlation with every input, each one chart with both models; findings and tables
/// per model.
fn correlation_overlay(rep: &mut Report, r: &CompareReport, b: &ModelComparison) {
    let (before, after) = legends(r, b);
    let (cb, cm) = (&b.correlation, &r.model.correlation);
    let s = rep.section("Residual correlations");
    s.text(format!(
        "One-step residuals over {} samples, before ({}) and after ({}) on the same axes; dashed: the 95 % band ±1.96/√N = ±{:.3}. Positive lag: the input leads the residual (one step = {:.4} s). A white residual stays inside the band; a peak of an input at a positive lag means an unmodelled delay or lag.",
        cm.n, b.label, r.model.label, cm.band, cm.dt_s
    ));
    for (legend, c) in [(&before, cb), (&after, cm)] {
        for f in &c.findings {
            s.note(format!("{legend}: {}", f.message));
        }
        if c.findings.is_empty() {
            s.text(format!("{legend}: no lagged input peak outside the band."));
        }
    }
    // the band depends on N only; both models see the same windows, but draw both if not
    let bands: Vec<f64> = if cb.band == cm.band {
        vec![cm.band]
    } else {
        vec![cb.band, cm.band]
    };
    let chart = |title: String, state: &str, with: Option<&str>| {
        let mut c = LineChart::new(title, "lag (steps)", "r").size(OVERLAY_SIZE.0, OVERLAY_SIZE.1);
        for &band in &bands {
            c = c.hline(band, "+95 %").hline(-band, "−95 %");
        }
        c.series(Series::line(before.clone(), lag_points(cb, state, with)))
            .series(Series::line(after.clone(), lag_points(cm, state, with)))
    };
    for name in &r.states {
        let mut charts = vec![chart(
            format!("residual {name}: autocorrelation"),
            name,
            None,
        )];
        for inp in &r.inputs {
            charts.push(chart(
                format!("residual {name} × input {inp}"),
                name,
                Some(inp),
            ));
        }
        let refs: Vec<&dyn Chart> = charts.iter().map(|c| c as &dyn Chart).collect();
        s.chart_row(&refs);
    }
    for mc in [b, &r.model] {
        s.table(correlation_table(&mc.correlation).caption(format!("peaks, {}", mc.label)));
    }
}

/// The peak of every residual correlation.
fn correlation_table(c: &CorrelationReport) -> Table {
    let mut t = Table::new([
        "residual",
        "with",
        "peak lag (steps)",
        "peak lag (s)",
        "peak r",
        "lags outside band",
    ]);
    for x in c.autocorrelation.iter().chain(&c.cross) {
        t.push([
            x.state.clone(),
            x.with.clone(),
            x.peak_lag.to_string(),
            format!("{:.3}", x.peak_lag as f64 * c.dt_s),
            format!("{:.3}", x.peak_r),
            format!("{:.0} %", 100.0 * x.outside_band),
        ]);
    }
    t
}
