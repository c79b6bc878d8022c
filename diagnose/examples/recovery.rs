//! Recovery rate of `diagnose`: for each world and each effect of the library, simulator data
//! with only that effect on (plus nominal data), several seeds; does the diagnosis name the
//! effect first and significant (and nothing on nominal data)?
//!
//! `cargo run --release -p dynlab-diagnose --example recovery -- [--seeds N] [--first-seed S] [--noise X]
//! [--car-episodes N] [--car-duration S] [--push-episodes N] [--only NAME] [--world car|push]
//! [--steps K] [--fit-baseline] [--no-refit] [--no-bonferroni] [--refit a,c,kappa]`
//!
//! `--refit` names the nominal parameters the diagnosis refits (default: the model's free ones).
//! `--no-refit` holds the nominal parameters (no joint refit of the pushing `c`, `κ`),
//! `--no-bonferroni` tests every candidate at the plain confidence: both together are the
//! diagnosis of the previous version.
//!
//! The model under diagnosis is the nominal physics model at its documented values (what a fit
//! on nominal data returns; the simulator's nominal world is those values).

use std::time::Instant;

use dynlab_diagnose::diagnosis::push_level_dataset;
use dynlab_diagnose::diagnosis::simdata::{car_dataset, car_scenario, push_dataset, push_scenario};
use dynlab_diagnose::diagnosis::{DiagnoseConfig, diagnose};
use dynlab_learn::dynamics::physics::{Effect, PhysicsModel};
use dynlab_learn::train::{TrainConfig, default_physics_solver, train};
use dynlab_learn::{Model, ModelKind, World};

fn arg<T: std::str::FromStr>(name: &str, default: T) -> T {
    let a: Vec<String> = std::env::args().collect();
    a.iter()
        .position(|x| x == name)
        .and_then(|i| a.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seeds: u64 = arg("--seeds", 5);
    let first_seed: u64 = arg("--first-seed", 0);
    let noise: f64 = arg("--noise", 2.0);
    let car_eps: u64 = arg("--car-episodes", 4);
    let car_dur: f64 = arg("--car-duration", 15.0);
    let push_eps: u64 = arg("--push-episodes", 20);
    let only: String = arg("--only", String::new());
    let only_world: String = arg("--world", String::new());
    let steps: usize = arg("--steps", 0);
    let fit_baseline = std::env::args().any(|a| a == "--fit-baseline");
    // the significance rule of the previous version, for before/after tables
    let no_refit = std::env::args().any(|a| a == "--no-refit");
    let no_bonferroni = std::env::args().any(|a| a == "--no-bonferroni");
    let refit: String = arg("--refit", String::new());
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "recovery over {seeds} seeds, noise ×{noise}: car {car_eps} × {car_dur} s, pushing {push_eps} × 10 pushes"
    );
    println!(
        "{:<8} {:<16} {:>9} {:>11} {:>14} {:>8}",
        "world", "hidden effect", "recovered", "mean reduct.", "mean strength", "time/s"
    );
    let mut cases: Vec<(World, Option<Effect>)> = vec![(World::Car, None)];
    for e in Effect::ALL {
        if e.robot() == World::Car.robot() {
            cases.push((World::Car, Some(e)));
        }
    }
    cases.push((World::Push, None));
    for e in Effect::ALL {
        if e.robot() == World::Push.robot() {
            cases.push((World::Push, Some(e)));
        }
    }
    for (world, effect) in cases {
        let name = effect.map_or("none (nominal)", |e| e.name());
        if !only_world.is_empty() && world.name() != only_world {
            continue;
        }
        if !only.is_empty() && !name.starts_with(&only) {
            continue;
        }
        let t0 = Instant::now();
        let mut ok = 0;
        let mut red = 0.0;
        let mut par = Vec::new();
        for seed in first_seed..first_seed + seeds {
            let data = match world {
                World::Car => car_dataset(
                    &car_scenario(effect, noise),
                    car_eps,
                    car_dur,
                    1000 + seed,
                    threads,
                )?,
                World::Push => push_dataset(
                    &push_scenario(effect, noise),
                    push_eps,
                    10,
                    2000 + seed,
                    threads,
                )?,
            };
            let model = if fit_baseline {
                // the baseline a user has: the physics model fitted on nominal data
                let nominal = match world {
                    World::Car => car_dataset(
                        &car_scenario(None, noise),
                        car_eps,
                        car_dur,
                        5000 + seed,
                        threads,
                    )?,
                    World::Push => push_level_dataset(push_dataset(
                        &push_scenario(None, noise),
                        push_eps,
                        10,
                        6000 + seed,
                        threads,
                    )?),
                };
                let cfg = TrainConfig {
                    kind: ModelKind::Physics,
                    steps: if world == World::Car { 5 } else { 1 },
                    seed,
                    physics_iterations: 15,
                    physics_max_windows: 800,
                    ..TrainConfig::default()
                };
                train(&nominal, &cfg, &mut |_| {})?.model
            } else {
                let phys = PhysicsModel::new(world.robot(), &[])?;
                Model::new(
                    ModelKind::Physics,
                    world,
                    data.pose_dt_s,
                    None,
                    None,
                    Some(phys),
                    default_physics_solver(world),
                )?
            };
            let cfg = DiagnoseConfig {
                seed,
                steps: (steps > 0).then_some(steps),
                refit_nominal: no_refit.then_some(false),
                refit_params: (!refit.is_empty())
                    .then(|| refit.split(',').map(String::from).collect()),
                correct_for_candidates: !no_bonferroni,
                ..DiagnoseConfig::default()
            };
            let d = diagnose(&model, &data, &cfg)?;
            if std::env::var("VERBOSE").is_ok() {
                print!("{}", d.table());
            }
            let hit = match effect {
                Some(e) => d.verdict.as_deref() == Some(e.name()),
                None => d.verdict.is_none(),
            };
            ok += usize::from(hit);
            if let Some(e) = effect
                && let Some(c) = d.candidates.iter().find(|c| c.effect == e.name())
            {
                red += c.error_reduction;
                // the parameter that says how strong the effect is
                let key = match e {
                    Effect::AeroDrag => "c",
                    Effect::MotorLag => "tau",
                    Effect::SteeringOffset => "delta0",
                    Effect::SteeringLag => "rate",
                    Effect::CommandDelay => "delay",
                    Effect::GripPatch => "k",
                    Effect::ComOffset => "ox",
                    Effect::TableTilt => "gx",
                    Effect::FrictionPatch => "k",
                    Effect::PusherFriction => "mu",
                    Effect::FlatPusher => "half_width",
                };
                if let Some(v) = c.params.get(key) {
                    par.push(*v);
                }
            } else if let Some(c) = d.candidates.first() {
                red += c.error_reduction;
            }
        }
        let mp = if par.is_empty() {
            "—".to_string()
        } else {
            format!("{:.4}", par.iter().sum::<f64>() / par.len() as f64)
        };
        println!(
            "{:<8} {:<16} {:>5}/{:<3} {:>10.1}% {:>14} {:>8.1}",
            world.name(),
            name,
            ok,
            seeds,
            100.0 * red / seeds as f64,
            mp,
            t0.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
