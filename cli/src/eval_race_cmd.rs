//! `dynlab eval race`: closed-loop laps of the racer against the simulator, with the learned
//! model and with the simulator's true model inside the optimiser, side by side.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use dynlab_control::racing::{
    CarDynamics, GdSettings, InputLimits, LapReport, LapSettings, Manoeuvre, Optimizer, Plant,
    Racer, RacerSettings, SimCar, SqpSettings, run_laps, solve_gd, solve_sqp,
};
use dynlab_learn::{Model, World, load_model};
use dynlab_sim::{CarInput, CarWorld, wrap_angle};
use dynlab_sim::{CarScenario, Track};

/// `dynlab eval race …`
#[derive(Debug, Args)]
pub struct RaceArgs {
    /// Learned car model directory (`dynlab train --world car …`).
    #[arg(long)]
    model: PathBuf,
    /// Optimiser inside the racer.
    #[arg(long, value_enum, default_value_t = OptimizerArg::Sqp)]
    optimizer: OptimizerArg,
    /// Laps to drive with each model.
    #[arg(long, default_value_t = 2)]
    laps: usize,
    /// Track file (MPCC track.json layout: X, Y, X_i, Y_i, X_o, Y_o in m); default: the
    /// scenario's track, else launch_scripts/tracks/default.json.
    #[arg(long, value_name = "FILE")]
    track: Option<PathBuf>,
    /// Car scenario (TOML; its car parameters and noise are used; the start is the track's
    /// first point). Default: the nominal ORCA car.
    #[arg(long, value_name = "FILE")]
    scenario: Option<PathBuf>,
    /// Racer settings (TOML with the fields of RacerSettings, e.g. `progress_weight = 10.0`).
    #[arg(long, value_name = "FILE")]
    settings: Option<PathBuf>,
    /// Give up a run after this much simulated time (s); default 30 s per lap.
    #[arg(long)]
    max_time: Option<f64>,
    /// Seed of the pose noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Skip the run with the simulator's true model.
    #[arg(long)]
    no_true_model: bool,
    /// Instead of laps: the offline manoeuvres (parallel parking, dynamic reverse, drifting turn)
    /// solved with GD and SQP on the model and played open-loop on the simulator (Table I).
    #[arg(long)]
    offline: bool,
    /// Offline: solve on the physics car model with the simulator's own parameters (the
    /// nominal car, no friction ellipse) instead of loading --model.
    #[arg(long)]
    true_physics: bool,
    /// Offline: largest number of gradient-descent iterations (each tries 512 step sizes).
    #[arg(long, default_value_t = 300)]
    gd_iterations: usize,
    /// Offline: largest number of SQP iterations (QPs solved).
    #[arg(long, default_value_t = 50)]
    sqp_iterations: usize,
    /// Output directory for report.json and the plots (race_MODEL.png).
    #[arg(long, default_value = "race_eval")]
    out: PathBuf,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum OptimizerArg {
    Sqp,
    Gd,
}

pub fn run(args: RaceArgs) -> anyhow::Result<()> {
    if args.offline && args.true_physics {
        let car = match &args.scenario {
            Some(p) => CarScenario::from_file(p)?.car,
            None => CarScenario::floor().car,
        };
        return offline(&dynlab_control::racing::true_car_model(&car, 0.01)?, &args);
    }
    let (learned, _) = load_model(&args.model, None, Some(World::Car))
        .with_context(|| format!("loading {}", args.model.display()))?;
    if args.offline {
        return offline(&learned, &args);
    }
    let mut scenario = match &args.scenario {
        Some(p) => CarScenario::from_file(p)?,
        None => CarScenario::floor(),
    };
    let track = match (&args.track, &scenario.track_data) {
        (Some(p), _) => Track::from_file(p)?,
        (None, Some(t)) => t.clone(),
        (None, None) => Track::from_file("launch_scripts/tracks/default.json").context(
            "no --track given and launch_scripts/tracks/default.json not found; pass --track FILE",
        )?,
    };
    let on = CarScenario::on_track(track.clone());
    scenario.start = on.start;
    scenario.arena = on.arena;
    scenario.track_data = Some(track.clone());
    let mut settings: RacerSettings = match &args.settings {
        Some(p) => toml::from_str(&std::fs::read_to_string(p)?)
            .with_context(|| format!("reading racer settings {}", p.display()))?,
        None => RacerSettings::default(),
    };
    settings.optimizer = match args.optimizer {
        OptimizerArg::Sqp => Optimizer::Sqp,
        OptimizerArg::Gd => Optimizer::Gd,
    };
    settings.limits.steering_max = scenario.car.steering_max;
    settings.limits.throttle_min = scenario.car.throttle_min;
    settings.limits.throttle_max = scenario.car.throttle_max;
    if args.laps == 0 {
        bail!("--laps must be at least 1");
    }
    let laps = LapSettings {
        laps: args.laps,
        max_time: args.max_time.unwrap_or(30.0 * args.laps as f64),
        seed: args.seed,
        estimate: true,
    };
    let mut runs: Vec<(&str, LapReport)> = Vec::new();
    runs.push((
        "learned",
        drive(&learned, &track, &scenario, settings, &laps)?,
    ));
    if !args.no_true_model {
        let truth = SimCar::new(&scenario, learned.dt())?;
        runs.push(("true", drive(&truth, &track, &scenario, settings, &laps)?));
    }
    std::fs::create_dir_all(&args.out)?;
    println!(
        "track: {} ({:.2} m), optimizer {:?}, n = {}, {:.0} Hz, {} lap(s)",
        args.track
            .as_deref()
            .or(args.scenario.as_deref())
            .map_or("default".into(), |p| p.display().to_string()),
        track.length(),
        settings.optimizer,
        settings.horizon,
        1.0 / (learned.dt() * settings.hold as f64),
        args.laps
    );
    println!(
        "{:<8} {:>6} {:>22} {:>6} {:>10} {:>10} {:>9} {:>9} {:>9} {:>8} {:>8}",
        "model",
        "laps",
        "lap times (s)",
        "exc.",
        "off (s)",
        "min d (m)",
        "top v",
        "p50 (ms)",
        "p99 (ms)",
        "elastic",
        "recover"
    );
    for (name, r) in &runs {
        let times = r
            .lap_times
            .iter()
            .map(|t| format!("{t:.2}"))
            .collect::<Vec<_>>()
            .join(" ");
        println!(
            "{:<8} {:>6} {:>22} {:>6} {:>10.2} {:>10.3} {:>9.2} {:>9.2} {:>9.2} {:>8} {:>8}",
            name,
            format!("{}/{}", r.lap_times.len(), args.laps),
            times,
            r.excursions,
            r.time_off_track,
            r.min_border_distance,
            r.top_speed,
            1e3 * r.solve_quantile(0.5),
            1e3 * r.solve_quantile(0.99),
            r.elastic_qps,
            r.recoveries
        );
        plot(&args.out.join(format!("race_{name}.png")), &track, r, name)?;
    }
    if runs.len() == 2 {
        let last = |r: &LapReport| r.lap_times.last().copied();
        if let (Some(a), Some(b)) = (last(&runs[0].1), last(&runs[1].1)) {
            println!(
                "last lap: learned {a:.2} s vs true {b:.2} s ({:+.1} %)",
                100.0 * (a / b - 1.0)
            );
        }
    }
    let json = serde_json::json!({
        "track_length": track.length(),
        "settings": settings,
        "runs": runs.iter().map(|(n, r)| serde_json::json!({
            "model": n,
            "lap_times": r.lap_times,
            "excursions": r.excursions,
            "time_off_track": r.time_off_track,
            "min_border_distance": r.min_border_distance,
            "top_speed": r.top_speed,
            "solve_p50_s": r.solve_quantile(0.5),
            "solve_p99_s": r.solve_quantile(0.99),
            "statuses": r.statuses,
            "elastic_qps": r.elastic_qps,
            "recoveries": r.recoveries,
        })).collect::<Vec<_>>(),
    });
    std::fs::write(
        args.out.join("report.json"),
        serde_json::to_string_pretty(&json)?,
    )?;
    println!("wrote {}", args.out.display());
    Ok(())
}

fn drive(
    model: &dyn CarDynamics,
    track: &Track,
    scenario: &CarScenario,
    settings: RacerSettings,
    laps: &LapSettings,
) -> anyhow::Result<LapReport> {
    let mut racer = Racer::new(model, track, settings)?;
    let t0 = Instant::now();
    Ok(run_laps(&mut racer, scenario, track, laps, || {
        t0.elapsed().as_secs_f64()
    })?)
}

/// The driven line over the track borders, coloured by speed (blue slow → red fast).
fn plot(path: &Path, track: &Track, r: &LapReport, name: &str) -> anyhow::Result<()> {
    use plotters::prelude::*;
    let (lo, hi) = (track.bounds_min(0.1), track.bounds_max(0.1));
    let w = 900u32;
    let h = ((w as f64) * (hi[1] - lo[1]) / (hi[0] - lo[0])).clamp(300.0, 1200.0) as u32;
    let root = BitMapBackend::new(path, (w, h + 60)).into_drawing_area();
    root.fill(&WHITE)?;
    let vmax = r.top_speed.max(0.1);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "{name} model: laps {:?} s, top speed {:.2} m/s (colour: speed 0 … {:.1} m/s)",
                r.lap_times
                    .iter()
                    .map(|t| (t * 100.0).round() / 100.0)
                    .collect::<Vec<_>>(),
                r.top_speed,
                vmax
            ),
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(40)
        .build_cartesian_2d(lo[0]..hi[0], lo[1]..hi[1])?;
    chart
        .configure_mesh()
        .x_desc("x (m)")
        .y_desc("y (m)")
        .draw()?;
    for side in 0..2 {
        let pts: Vec<(f64, f64)> = (0..=track.len())
            .map(|i| {
                let b = track.borders(i % track.len())[side];
                (b[0], b[1])
            })
            .collect();
        chart.draw_series(LineSeries::new(pts, &BLACK))?;
    }
    let colour = |v: f64| {
        let f = (v / vmax).clamp(0.0, 1.0);
        RGBColor((255.0 * f) as u8, 40, (255.0 * (1.0 - f)) as u8)
    };
    chart.draw_series(r.trace.windows(2).map(|p| {
        PathElement::new(
            vec![(p[0].x, p[0].y), (p[1].x, p[1].y)],
            colour(p[1].speed).stroke_width(2),
        )
    }))?;
    root.present()?;
    Ok(())
}

/// Table I: each manoeuvre solved on the model with GD and SQP, then played open-loop on the
/// simulator from the same start; end-pose error against the final target.
fn offline(model: &Model, args: &RaceArgs) -> anyhow::Result<()> {
    let scenario = match &args.scenario {
        Some(p) => CarScenario::from_file(p)?,
        None => CarScenario::floor(),
    };
    let limits = InputLimits {
        steering_max: scenario.car.steering_max,
        throttle_min: scenario.car.throttle_min,
        throttle_max: scenario.car.throttle_max,
    };
    let plant = Plant::new(model, 5)?;
    println!(
        "{:<18} {:<4} {:>12} {:>6} {:>15} {:>9} {:>12} {:>12} {:>10}",
        "scenario",
        "opt",
        "cost",
        "iter",
        "status",
        "time (s)",
        "end err (m)",
        "yaw err (°)",
        "model (m)"
    );
    let mut rows = Vec::new();
    for m in Manoeuvre::all() {
        let problem = m.problem(plant, [0.0; 6], limits);
        for opt in ["gd", "sqp"] {
            let t0 = Instant::now();
            let sol = if opt == "gd" {
                solve_gd(
                    &problem,
                    &m.initial_inputs(),
                    &GdSettings {
                        iterations: args.gd_iterations,
                        ..GdSettings::default()
                    },
                )?
            } else {
                solve_sqp(
                    &problem,
                    &m.initial_inputs(),
                    &SqpSettings {
                        iterations: args.sqp_iterations,
                        ..SqpSettings::default()
                    },
                )?
            };
            let secs = t0.elapsed().as_secs_f64();
            let mut world = CarWorld::new(&scenario)?;
            world.reset(dynlab_sim::CarState::default())?;
            for u in &sol.inputs {
                world.step(CarInput::new(u[0], u[1]), plant.dt())?;
            }
            let end = world.state();
            let target = m.end_target();
            let pos_err = (end.x - target[0]).hypot(end.y - target[1]);
            let yaw_err = wrap_angle(end.psi - target[2]).abs().to_degrees();
            let pred = sol.states.last().copied().unwrap_or([0.0; 6]);
            let model_err = (pred[0] - target[0]).hypot(pred[1] - target[1]);
            println!(
                "{:<18} {:<4} {:>12.4} {:>6} {:>15} {:>9.2} {:>12.3} {:>12.1} {:>10.3}",
                m.name,
                opt,
                sol.cost,
                sol.iterations,
                sol.status.to_string(),
                secs,
                pos_err,
                yaw_err,
                model_err
            );
            rows.push(serde_json::json!({
                "scenario": m.name, "optimizer": opt, "cost": sol.cost,
                "iterations": sol.iterations, "status": sol.status.to_string(),
                "seconds": secs, "end_position_error_m": pos_err,
                "end_yaw_error_deg": yaw_err, "model_end_error_m": model_err,
            }));
        }
    }
    std::fs::create_dir_all(&args.out)?;
    std::fs::write(
        args.out.join("offline.json"),
        serde_json::to_string_pretty(&rows)?,
    )?;
    println!("wrote {}", args.out.join("offline.json").display());
    Ok(())
}
