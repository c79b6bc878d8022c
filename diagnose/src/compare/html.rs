//! The HTML page of a comparison, built with [`crate::report`].

use crate::report::{Chart, Heatmap, LineChart, Report, Series, Table};

use super::{CompareReport, ModelComparison};

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
    {
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
    {
        let s = rep.section("Error against its causes");
        s.text(format!(
            "{k}-step RMSE in bins of each quantity at the window start, divided by the model's overall {k}-step RMSE of that dimension (1 = average; above 1: the model is worse there). Counts per bin in the tables."
        ));
        for (qi, b) in m.binned.iter().enumerate() {
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
            let mut header = vec![format!("{} ({})", b.quantity, b.unit), "count".into()];
            for mc in &models {
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
                for mc in &models {
                    for d in 0..r.states.len() {
                        row.push(format!("{:.3e}", mc.binned[qi].rmse[d][i]));
                    }
                }
                t.push(row);
            }
            s.table(t);
        }
    }

    // map
    {
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
            .map(|mc| {
                let pm = &mc.position_map;
                Heatmap {
                    title: format!("position error (m), {}", mc.label),
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
            })
            .collect();
        let refs: Vec<&dyn Chart> = maps.iter().map(|c| c as &dyn Chart).collect();
        s.chart_row(&refs);
    }

    // correlations
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
        s.table(t);
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
