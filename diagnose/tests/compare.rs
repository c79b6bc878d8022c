//! `compare` on the bundled bags with the unfitted physics models: the numbers agree with
//! `evaluate`, every window is counted once, the worst segments are ranked and stamped, the
//! report survives JSON, and bad input gets clear errors.

use std::path::PathBuf;

use dynlab_diagnose::compare::{
    CompareConfig, CompareReport, compare, compare_with_baseline, html,
};
use dynlab_learn::dynamics::data::SavGol;
use dynlab_learn::train::{default_physics_solver, physics_model};
use dynlab_learn::{Model, ModelKind, TimedDataset, Topics, World, evaluate, load_bags_timed};

fn bag(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../bags")
        .join(name)
}

fn physics(world: World, dt: f64, effects: &[&str]) -> Model {
    let effects: Vec<String> = effects.iter().map(|s| s.to_string()).collect();
    Model::new(
        ModelKind::Physics,
        world,
        dt,
        None,
        None,
        Some(physics_model(world, &effects).unwrap()),
        default_physics_solver(world),
    )
    .unwrap()
}

fn load(name: &str) -> TimedDataset {
    load_bags_timed(&[bag(name)], None, &Topics::default(), &SavGol::default()).unwrap()
}

fn cfg() -> CompareConfig {
    CompareConfig {
        steps: 5,
        ..Default::default()
    }
}

#[test]
fn car_comparison_is_consistent_with_evaluate_and_counts_every_window() {
    let data = load("car_nominal");
    let model = physics(World::Car, data.data.pose_dt_s, &[]);
    let r = compare("physics", &model, &data, &cfg()).unwrap();
    let ev = evaluate(&model, &data.data, 5, 3.0).unwrap();
    // the same numbers as eval-model (sums in another order: equal to rounding)
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1e-300);
    assert_eq!(r.model.eval.windows, ev.windows);
    for (a, b) in r
        .model
        .eval
        .one_step
        .iter()
        .chain(&r.model.eval.k_step)
        .zip(ev.one_step.iter().chain(&ev.k_step))
    {
        assert!(close(a.rmse, b.rmse) && close(a.mae, b.mae), "{a:?} {b:?}");
    }
    assert!(close(r.model.eval.loss, ev.loss));
    let (t1, t2) = (r.model.eval.tve.as_ref().unwrap(), ev.tve.as_ref().unwrap());
    assert_eq!(t1.segments, t2.segments);
    assert!(close(t1.tve, t2.tve), "{t1:?} {t2:?}");
    // thread count does not change a bit
    let one = compare(
        "physics",
        &model,
        &data,
        &CompareConfig {
            threads: 1,
            ..cfg()
        },
    )
    .unwrap();
    assert_eq!(one.model, r.model);
    assert_eq!(r.states, vec!["x", "y", "psi", "vx", "vy", "omega"]);
    assert!(r.model.eval.tve.is_some());
    let n = ev.windows;
    // every window in exactly one bin (or excluded), and in the map
    assert_eq!(r.model.binned.len(), 7);
    for b in &r.model.binned {
        assert_eq!(
            b.counts.iter().sum::<usize>() + b.excluded,
            n,
            "{}",
            b.quantity
        );
        assert_eq!(b.edges.len(), b.counts.len() + 1);
        assert!(b.edges.windows(2).all(|w| w[1] > w[0]));
        assert_eq!(b.rmse.len(), 6);
    }
    let sideslip = r
        .model
        .binned
        .iter()
        .find(|b| b.quantity == "sideslip")
        .unwrap();
    assert!(sideslip.excluded > 0, "slow windows have no sideslip");
    let map = &r.model.position_map;
    assert_eq!(map.counts.iter().flatten().sum::<usize>(), n);
    // the RMS of the per-window k-step error over all bins equals the overall k-step RMSE
    let speed = &r.model.binned[0];
    for d in 0..6 {
        let ss: f64 = speed.rmse[d]
            .iter()
            .zip(&speed.counts)
            .map(|(e, &c)| e * e * c as f64)
            .sum();
        let overall = (ss / n as f64).sqrt();
        let want = ev.k_step[d].rmse;
        assert!(
            (overall - want).abs() <= 1e-9 * want.max(1e-12),
            "dim {d}: {overall} vs {want}"
        );
    }
    // correlations: 41 lags, the white-noise band, autocorrelation 1 at lag 0
    let c = &r.model.correlation;
    assert_eq!(c.lags.len(), 41);
    assert!((c.band - 1.96 / (c.n as f64).sqrt()).abs() < 1e-12);
    assert_eq!(c.n, n);
    for a in &c.autocorrelation {
        assert!((a.r[20] - 1.0).abs() < 1e-9);
    }
    assert_eq!(c.cross.len(), 6 * 2);
    // worst segments: ranked, stamped inside the bag, not overlapping
    let w = &r.model.worst;
    assert_eq!(w.len(), 10);
    assert!(w.windows(2).all(|p| p[0].score >= p[1].score));
    assert!(w[0].score > 1.0);
    for s in w {
        assert!(s.end_ns > s.start_ns);
        assert!((s.end_s - s.start_s - 5.0 * data.data.pose_dt_s).abs() < 1e-6);
        assert!(s.start_s >= 0.0 && s.end_s < 100.0);
        let t0 = data.stamps.bag_start_ns[0];
        assert!((s.start_s - (s.start_ns - t0) as f64 * 1e-9).abs() < 1e-9);
    }
    for (i, a) in w.iter().enumerate() {
        for b in &w[i + 1..] {
            assert!(a.trajectory != b.trajectory || a.start_index.abs_diff(b.start_index) > 5);
        }
    }
    // error over time: one series per trajectory, increasing times, bounded points
    assert_eq!(r.model.over_time.len(), data.data.trajectories.len());
    for e in &r.model.over_time {
        assert!(e.t_s.windows(2).all(|p| p[1] > p[0]));
        assert!(e.t_s.len() <= 400);
        assert_eq!(e.rmse.len(), 6);
    }
    // the data notes say the episodes were split at gaps
    assert!(
        r.data.notes[0].iter().any(|n| n.contains("2 gap(s)")),
        "{:?}",
        r.data.notes
    );
    // JSON round trip and the page
    let json = serde_json::to_string(&r).unwrap();
    let back: CompareReport = serde_json::from_str(&json).unwrap();
    assert_eq!(back.model.worst, r.model.worst);
    assert_eq!(back.schema, "dynlab.compare/1");
    let page = html::report(&r).to_html();
    for s in [
        "Errors",
        "Error over time",
        "Error against its causes",
        "Error over the floor",
        "Worst segments",
    ] {
        assert!(page.contains(&format!(">{s}")), "section {s}");
    }
    let summary = r.summary();
    assert!(summary.contains("worst segments"));
    assert!(summary.contains("RMSE 5-step"));
}

#[test]
fn baseline_side_by_side_reports_the_error_change() {
    let data = load("push_com_offset");
    let nominal = physics(World::Push, data.data.pose_dt_s, &[]);
    let with_effect = physics(World::Push, data.data.pose_dt_s, &["com_offset"]);
    let same =
        compare_with_baseline(("a", &nominal), Some(("b", &nominal)), &data, &cfg()).unwrap();
    assert!(!same.change.is_empty());
    for c in &same.change {
        assert_eq!(c.change, 0.0, "{c:?}");
        assert!(c.change_pct.is_none_or(|p| p == 0.0));
    }
    let r = compare_with_baseline(
        ("effect", &with_effect),
        Some(("nominal", &nominal)),
        &data,
        &cfg(),
    )
    .unwrap();
    let b = r.baseline.as_ref().unwrap();
    assert_eq!(b.label, "nominal");
    for c in &r.change {
        if c.metric == "rmse" {
            let (bm, mm) = if c.steps == 1 {
                (&b.eval.one_step, &r.model.eval.one_step)
            } else {
                (&b.eval.k_step, &r.model.eval.k_step)
            };
            let d = r.states.iter().position(|s| *s == c.state).unwrap();
            assert_eq!(c.baseline, bm[d].rmse);
            assert_eq!(c.model, mm[d].rmse);
            let pct = 100.0 * (c.model - c.baseline) / c.baseline;
            assert!((c.change_pct.unwrap() - pct).abs() < 1e-9);
        }
    }
    let table = r.error_table().to_text();
    assert!(table.contains("change %"));
    let page = html::report(&r).to_html();
    assert!(page.contains("Worst segments, nominal"));
    assert!(page.contains("Worst segments, effect"));
}

#[test]
fn bad_input_gets_clear_errors() {
    let data = load("car_nominal");
    let push = physics(World::Push, 0.1, &[]);
    let e = compare("push-model", &push, &data, &cfg())
        .unwrap_err()
        .to_string();
    assert!(e.contains("world mismatch") && e.contains("car"), "{e}");
    let car = physics(World::Car, 0.01, &[]);
    let long = CompareConfig {
        steps: 100_000,
        ..Default::default()
    };
    let e = compare("car", &car, &data, &long).unwrap_err().to_string();
    assert!(e.contains("too little data"), "{e}");
    let zero = CompareConfig {
        steps: 0,
        ..Default::default()
    };
    let e = compare("car", &car, &data, &zero).unwrap_err().to_string();
    assert!(e.contains("steps"), "{e}");
    // a missing topic names the topic and the ones that are there
    let e = load_bags_timed(
        &[bag("car_nominal")],
        Some(World::Car),
        &Topics {
            pose: Some("/mocap/car".into()),
            cmd: None,
        },
        &SavGol::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("/mocap/car") && e.contains("/car/pose"), "{e}");
}

/// The inline SVG figures of a page, in order.
fn svgs(page: &str) -> Vec<&str> {
    page.match_indices("<svg")
        .map(|(i, _)| {
            let end = page[i..].find("</svg>").expect("an unclosed <svg>");
            &page[i..i + end]
        })
        .collect()
}

/// Polylines stroked in `colour` (a data line or its legend swatch) in one SVG.
fn polylines(svg: &str, colour: &str) -> usize {
    svg.split("<polyline")
        .skip(1)
        .filter(|p| p.split('>').next().is_some_and(|a| a.contains(colour)))
        .count()
}

#[test]
fn baseline_figures_overlay_before_and_after_on_the_same_axes() {
    let data = load("push_com_offset");
    let nominal = physics(World::Push, data.data.pose_dt_s, &[]);
    let with_effect = physics(World::Push, data.data.pose_dt_s, &["com_offset"]);
    let r = compare_with_baseline(
        ("effect", &with_effect),
        Some(("nominal", &nominal)),
        &data,
        &cfg(),
    )
    .unwrap();
    let page = html::report(&r).to_html();
    assert!(
        !page.contains("figure not drawn"),
        "every figure drawn (needs a sans-serif font)"
    );
    let (ns, ni, nq, nb) = (
        r.states.len(),
        r.inputs.len(),
        r.model.binned.len(),
        r.data.bags.len(),
    );
    assert_eq!((ns, ni, nb), (3, 3, 1));
    assert!(nq >= 3);
    let figs = svgs(&page);
    // one chart per figure: over time per dimension and bag, binned per quantity and dimension,
    // one map of two panels, autocorrelation and cross-correlation per input per dimension
    assert_eq!(figs.len(), ns * nb + nq * ns + 1 + ns * (1 + ni));
    assert_eq!(page.matches("<figure>").count(), figs.len());
    // every chart holds both models, with their legends
    for (i, svg) in figs.iter().enumerate() {
        assert!(
            svg.contains("before: nominal") && svg.contains("after: effect"),
            "figure {i} lacks a legend"
        );
    }
    // the line charts draw both series (blue before, red after): a legend swatch and data
    let line_charts: Vec<&&str> = figs
        .iter()
        .filter(|s| !s.contains("shared scale"))
        .collect();
    assert_eq!(line_charts.len(), figs.len() - 1);
    for svg in line_charts {
        assert!(polylines(svg, "#1F77B4") >= 2, "before not drawn");
        assert!(polylines(svg, "#D62728") >= 2, "after not drawn");
    }
    // the map: two panels under one colour scale, the larger of the two maxima
    let max_of = |mc: &dynlab_diagnose::compare::ModelComparison| {
        let pm = &mc.position_map;
        pm.rmse
            .iter()
            .flatten()
            .zip(pm.counts.iter().flatten())
            .filter(|(_, c)| **c > 0)
            .map(|(v, _)| *v)
            .fold(0.0, f64::max)
    };
    let (mb, mm) = (max_of(r.baseline.as_ref().unwrap()), max_of(&r.model));
    let map = figs.iter().find(|s| s.contains("shared scale")).unwrap();
    assert!(map.contains(&format!("shared scale, max {:.4}", mb.max(mm))));
    assert!(map.contains(&format!("before: nominal (max {mb:.4})")));
    assert!(map.contains(&format!("after: effect (max {mm:.4})")));
    // no figure of one model alone any more
    assert!(!page.contains("position error (m), nominal"));
    assert!(!page.contains("5-step error, nominal"));
    // the tables still list both models
    assert!(page.contains("Worst segments, nominal") && page.contains("Worst segments, effect"));
    assert!(page.contains("peaks, nominal") && page.contains("peaks, effect"));
}

#[test]
fn single_model_report_keeps_one_figure_per_model_figure() {
    let data = load("push_com_offset");
    let nominal = physics(World::Push, data.data.pose_dt_s, &[]);
    let r = compare("nominal", &nominal, &data, &cfg()).unwrap();
    let page = html::report(&r).to_html();
    assert!(!page.contains("figure not drawn"));
    let (ns, ni, nq) = (r.states.len(), r.inputs.len(), r.model.binned.len());
    let figs = svgs(&page);
    // over time per dimension, binned per quantity (all dimensions in one), one map,
    // autocorrelation and one cross-correlation chart per input
    assert_eq!(figs.len(), ns + nq + 1 + (1 + ni));
    assert!(!page.contains("before:") && !page.contains("after:"));
    assert!(!page.contains("shared scale"));
    for s in [
        "x: 5-step error, nominal",
        "position error (m), nominal",
        "Residual correlations, nominal",
        "Worst segments, nominal",
    ] {
        assert!(page.contains(s), "{s}");
    }
    // the binned charts: one series per state dimension, relative to the overall error
    let binned = figs
        .iter()
        .find(|s| s.contains(&format!("{} (", r.model.binned[0].quantity)))
        .unwrap();
    for name in &r.states {
        assert!(binned.contains(&format!(">\n{name}\n</text>")), "{name}");
    }
    assert!(binned.contains("relative error"));
    // the same page whether or not the baseline slot was used
    let none = compare_with_baseline(("nominal", &nominal), None, &data, &cfg()).unwrap();
    assert_eq!(html::report(&none).to_html(), page);
}
