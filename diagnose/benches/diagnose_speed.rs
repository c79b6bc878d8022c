//! Speed of `diagnose` on car data: 10 minutes and one hour of 100 Hz data (simulated in
//! process, hidden aero drag), all four car candidates, default settings. Target (issue 5):
//! one hour in under 30 s on this machine. Prints a table; `cargo bench -p dynlab-diagnose`.

use std::time::Instant;

use dynlab_diagnose::diagnosis::simdata::{car_dataset, car_scenario};
use dynlab_diagnose::diagnosis::{DiagnoseConfig, diagnose};
use dynlab_learn::dynamics::physics::{Effect, PhysicsModel};
use dynlab_learn::train::default_physics_solver;
use dynlab_learn::{Model, ModelKind, World};

fn main() {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "{:<10} {:>12} {:>12} {:>12} {:>9} {:>10}",
        "data", "transitions", "simulate/s", "diagnose/s", "vs 30 s", "verdict"
    );
    let mut first = None;
    for minutes in std::env::var("DIAG_MINUTES")
        .ok()
        .and_then(|v| v.parse().ok())
        .map_or(vec![10u64, 60], |m| vec![m])
    {
        let t0 = Instant::now();
        let data = car_dataset(
            &car_scenario(Some(Effect::AeroDrag), 1.0),
            minutes * 2,
            30.0,
            7,
            threads,
        )
        .expect("simulate");
        let sim_s = t0.elapsed().as_secs_f64();
        let model = Model::new(
            ModelKind::Physics,
            World::Car,
            data.pose_dt_s,
            None,
            None,
            Some(PhysicsModel::car(&[]).expect("model")),
            default_physics_solver(World::Car),
        )
        .expect("model");
        let t1 = Instant::now();
        let d = diagnose(&model, &data, &DiagnoseConfig::default()).expect("diagnose");
        let diag_s = t1.elapsed().as_secs_f64();
        if d.verdict.is_none() {
            print!("{}", d.table());
        }
        let base = *first.get_or_insert(diag_s);
        println!(
            "{:<10} {:>12} {:>12.1} {:>12.2} {:>8.2}× {:>10}   ({:.2}× the 10-min time)",
            format!("{minutes} min"),
            data.transitions(),
            sim_s,
            diag_s,
            diag_s / 30.0,
            d.verdict.as_deref().unwrap_or("none"),
            diag_s / base
        );
    }
}
