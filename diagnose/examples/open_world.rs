//! Open-world recovery of `diagnose` on the car: the loop a user runs, over several seeds.
//!
//! For every case and seed: a car whose parameters are perturbed from the datasheet (every
//! parameter scaled by its own seeded factor in [1 − f, 1 + f]; `--perturb 0` for the datasheet
//! car), nominal data from it, the physics model fitted on those (`dynlab train --kind physics`),
//! then data of the same car with the hidden effects, diagnosed. Cases: nominal, each library
//! effect alone (the simulator's steering-servo rate limit is the library's `steering_lag`),
//! pairs of library effects, and effects outside the library (the steering gain falling with
//! speed, a low-grip band across the floor).
//!
//! Per case: how often the selected set is exactly the hidden library effects (outside the
//! library and nominal: nothing named); the held-out 50-step error the selected effects remove
//! from the fitted model (refitted jointly; min–mean–max over seeds); the fitted strength
//! against the truth; and the term search beyond the library: in how many seeds it found a
//! significant term, the error that term removes on top of the selected effects (mean), and
//! the terms found (each with how often). Where no library effect is named (the cases outside
//! the library), the "removed" column is what the discovered terms remove, every held-out
//! window counted as the selected effects' are. Beside it, the share of the error above the
//! true model's (the simulator's car with its effects at their true values; the steering gain
//! as the custom term `δ += −1·δ·vₓ²/(vₓ² + v₀²)`; the band as the strip `μ += −0.5·s(0.5, 0.263; 0.8)`)
//! that is removed.
//!
//! `cargo run --release -p dynlab-diagnose --example open_world -- [--seeds N]
//! [--first-seed N] [--nominal-seeds N] [--perturb F] [--episodes N] [--duration S]
//! [--only CASE,CASE] [--noise X] [--fit-iterations N] [--fit-windows N] [--car-refit BOOL]
//! [--refit-tolerance F] [--train-steps K] [--train-gamma G] [--physics-free a,b]`
//! (defaults 5 seeds from 0, 20 nominal seeds, f = 0.1, 4 × 15 s, noise ×2; the baseline is
//! fitted with `dynlab train`'s defaults, which `--train-steps`, `--train-gamma` and `--physics-free` change; `--only` takes case names as printed, e.g.
//! `"aero_drag,none (nominal)"`; `--car-refit true` refits the car's nominal parameters in the
//! diagnosis, within ±F of the model's values with `--refit-tolerance F`); `VERBOSE=1` prints
//! every diagnosis.

use std::collections::BTreeSet;
use std::time::Instant;

use dynlab_control::racing::true_car_model;
use dynlab_diagnose::diagnosis::simdata::{car_dataset, low_grip_band, over_low_grip_band};
use dynlab_diagnose::diagnosis::{DiagnoseConfig, diagnose};
use dynlab_learn::dynamics::physics::{CustomEffect, Effect, PhysicsModel, Target};
use dynlab_learn::train::{KindDefaults, TrainConfig, train};
use dynlab_learn::{Model, ModelKind, World};
use dynlab_sim::car::{
    AeroDrag, CommandDelay, GripPatch, MotorLag, SteeringGainSpeed, SteeringOffset,
    SteeringRateLimit,
};
use dynlab_sim::{CarScenario, Region, RegionShape};

fn opt<T: std::str::FromStr>(name: &str) -> Option<T> {
    let a: Vec<String> = std::env::args().collect();
    a.iter()
        .position(|x| x == name)
        .and_then(|i| a.get(i + 1))
        .and_then(|v| v.parse().ok())
}

fn arg<T: std::str::FromStr>(name: &str, default: T) -> T {
    opt(name).unwrap_or(default)
}

/// A hidden effect of the simulator: its switch, the library effect that models it (`None`:
/// outside the library) and the strength to compare with (`(parameter, truth)`).
#[derive(Clone, Copy, PartialEq)]
enum Hidden {
    Drag,
    Lag,
    Offset,
    Disc,
    GainSpeed,
    RateLimit,
    Band,
    Delay,
}

impl Hidden {
    fn library(self) -> Option<(&'static str, &'static str, f64)> {
        match self {
            Hidden::Drag => Some(("aero_drag", "aero_drag.c", 0.01)),
            Hidden::Lag => Some(("motor_lag", "motor_lag.tau", 0.2)),
            Hidden::Offset => Some(("steering_offset", "steering_offset.delta0", 0.03)),
            Hidden::Disc => Some(("grip_patch", "grip_patch.k", 0.5)),
            // the library's servo model: a lag with a (smooth) rate limit
            Hidden::RateLimit => Some(("steering_lag", "steering_lag.rate", 3.0)),
            Hidden::Delay => Some(("command_delay", "command_delay.delay", 0.06)),
            _ => None,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Hidden::GainSpeed => "steering_gain_speed*",
            Hidden::Band => "grip_band*",
            h => h.library().map_or("", |l| l.0),
        }
    }

    fn apply(self, s: &mut CarScenario) {
        let e = &mut s.effects;
        match self {
            Hidden::Drag => e.aero_drag = Some(AeroDrag::default()),
            Hidden::Lag => {
                e.motor_lag = Some(MotorLag {
                    enabled: true,
                    tau: 0.2,
                })
            }
            Hidden::Offset => e.steering_offset = Some(SteeringOffset::default()),
            Hidden::Disc => {
                e.grip_patch = Some(GripPatch {
                    enabled: true,
                    scale: 0.5,
                    region: Region {
                        shape: RegionShape::Disc,
                        centre: [0.5, 0.0],
                        radius: 0.6,
                        ..Region::default()
                    },
                })
            }
            Hidden::Band => e.grip_patch = Some(low_grip_band()),
            Hidden::GainSpeed => {
                e.steering_gain_speed = Some(SteeringGainSpeed {
                    enabled: true,
                    v0: 2.0,
                })
            }
            Hidden::RateLimit => {
                e.steering_rate_limit = Some(SteeringRateLimit {
                    enabled: true,
                    rate: 3.0,
                    tau: 0.05,
                })
            }
            Hidden::Delay => e.command_delay = Some(CommandDelay::default()),
        }
    }
}

/// The simulator's car as a physics model, with the hidden effects at their true values: the
/// error a model with every parameter right still makes on the held-out windows (pose noise,
/// velocities estimated from poses, the chaos of 0.5 s open-loop rollouts). The steering gain
/// that falls with speed, outside the library, is the custom term `δ += −1·δ·vₓ²/(vₓ² + v₀²)`
/// (the simulator's `δ/(1 + vₓ²/v₀²)` exactly); the band, the grip term `μ += (scale − 1)·s(a, d; w)`
/// (the simulator's band with the strip's soft edges).
fn true_model(car: &CarScenario, case: &[Hidden], like: &Model) -> Option<Model> {
    let effects: Vec<Effect> = case
        .iter()
        .filter(|h| !matches!(h, Hidden::GainSpeed | Hidden::Band))
        .map(|h| h.library().and_then(|l| Effect::from_name(l.0)))
        .collect::<Option<_>>()?;
    let nominal = true_car_model(&car.car, like.dt()).ok()?;
    let mut p = nominal.physics()?.with_effects(&effects).ok()?;
    if case.contains(&Hidden::GainSpeed) {
        let v0 = car.effects.steering_gain_speed.as_ref()?.v0;
        let toml = format!(
            "name = \"gain\"\n[[term]]\nstate = \"delta\"\nfeature = \"delta*sat_vx2({v0})\"\ncoefficient = -1.0\n"
        );
        p.add_custom(CustomEffect::from_toml(&toml).ok()?).ok()?;
    }
    if case.contains(&Hidden::Band) {
        // the band as a strip: its centre line's distance from the origin along its normal
        let patch = car.effects.grip_patch.as_ref()?;
        let r = &patch.region;
        let (s, c) = r.angle.sin_cos();
        let d = c * r.centre[1] - s * r.centre[0];
        let toml = format!(
            "name = \"band\"\n[[term]]\nstate = \"grip\"\nfeature = \"strip({},{d},{})\"\ncoefficient = {}\n",
            r.angle,
            r.width,
            patch.scale - 1.0
        );
        p.add_custom(CustomEffect::from_toml(&toml).ok()?).ok()?;
    }
    for h in case {
        let values: &[(&str, f64)] = match h {
            Hidden::Drag => &[("aero_drag.c", 0.01)],
            Hidden::Lag => &[("motor_lag.tau", 0.2)],
            Hidden::Offset => &[("steering_offset.delta0", 0.03)],
            // the simulator's disc has a sharp edge, the model's the smallest width it allows
            Hidden::RateLimit => &[("steering_lag.tau", 0.05), ("steering_lag.rate", 3.0)],
            Hidden::Disc => &[
                ("grip_patch.cx", 0.5),
                ("grip_patch.cy", 0.0),
                ("grip_patch.r", 0.6),
                ("grip_patch.k", 0.5),
            ],
            // the simulator's delay is exact, the model's a Padé filter
            Hidden::Delay => &[("command_delay.delay", 0.06)],
            Hidden::GainSpeed | Hidden::Band => &[],
        };
        for &(name, v) in values {
            p.set_param(name, v).ok()?;
        }
    }
    physics_like(like, p)
}

/// `model` with the custom effect `effect` added (its coefficients as fitted).
fn with_custom(model: &Model, effect: &CustomEffect) -> Option<Model> {
    let mut p = model.physics()?.clone();
    p.add_custom(effect.clone()).ok()?;
    physics_like(model, p)
}

/// A car physics model of `physics` with the step and solver of `like`.
fn physics_like(like: &Model, physics: PhysicsModel) -> Option<Model> {
    Model::new(
        ModelKind::Physics,
        World::Car,
        like.dt(),
        None,
        None,
        Some(physics),
        like.physics_solver(),
    )
    .ok()
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seeds: u64 = arg("--seeds", 5);
    let nominal_seeds: u64 = arg("--nominal-seeds", 20);
    let perturb: f64 = arg("--perturb", 0.1);
    let episodes: u64 = arg("--episodes", 4);
    let duration: f64 = arg("--duration", 15.0);
    let noise: f64 = arg("--noise", 2.0);
    let only: String = arg("--only", String::new());
    let first_seed: u64 = arg("--first-seed", 0);
    let refit: Option<bool> = opt("--car-refit");
    let refit_tolerance: Option<f64> = opt("--refit-tolerance");
    let defaults = TrainConfig::default();
    let fit_iterations: usize = arg("--fit-iterations", defaults.physics_iterations);
    let fit_windows: usize = arg("--fit-windows", defaults.physics_max_windows);
    let kind_defaults = KindDefaults::for_kind(World::Car, ModelKind::Physics);
    let train_steps: usize = arg("--train-steps", kind_defaults.steps);
    let train_gamma: f64 = arg("--train-gamma", kind_defaults.gamma);
    let physics_free: Option<Vec<String>> = opt::<String>("--physics-free")
        .map(|s| s.split(',').map(|x| x.trim().to_string()).collect());
    let verbose = std::env::var("VERBOSE").is_ok();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    use Hidden::*;
    let cases: Vec<Vec<Hidden>> = vec![
        vec![],
        vec![Drag],
        vec![Lag],
        vec![Offset],
        vec![Disc],
        vec![Drag, Offset],
        vec![Drag, Lag],
        vec![Offset, Disc],
        vec![GainSpeed],
        vec![RateLimit],
        vec![Band],
        vec![Delay],
    ];
    println!(
        "open-world recovery: car {episodes} × {duration} s, noise ×{noise}, parameters perturbed ±{:.0} % from the datasheet; * = outside the library",
        100.0 * perturb
    );
    println!(
        "{:<36} {:>9} {:>24} {:>24}   {:<44} {:>7}",
        "hidden effects",
        "recovered",
        "removed min/mean/max",
        "w/o spins min/mean/max",
        "fitted strength (truth)",
        "time/s"
    );
    for case in cases {
        let name = if case.is_empty() {
            "none (nominal)".to_string()
        } else {
            case.iter()
                .map(|h| h.name())
                .collect::<Vec<_>>()
                .join(" + ")
        };
        if !only.is_empty() && !only.split(',').any(|o| o == name) {
            continue;
        }
        let truth: BTreeSet<&str> = case
            .iter()
            .filter_map(|h| h.library().map(|l| l.0))
            .collect();
        let n = if case.is_empty() {
            nominal_seeds
        } else {
            seeds
        };
        let t0 = Instant::now();
        let (mut ok, mut removed, mut strength) = (0, Vec::new(), Vec::new());
        // the same on the held-out windows not both the model and the result spin on
        let mut removed_calm = Vec::new();
        // share of the error above the true model's that the selected effects remove (all
        // held-out windows; without the spins)
        let (mut removable, mut removable_calm): (Vec<f64>, Vec<f64>) = (Vec::new(), Vec::new());
        let mut wrong: BTreeSet<String> = BTreeSet::new();
        let mut beyond: Vec<f64> = Vec::new();
        let mut terms: std::collections::BTreeMap<String, usize> = Default::default();
        // the band: seeds whose first significant term is less grip over it
        let mut on_band = 0;
        for seed in first_seed..first_seed + n {
            let mut car = CarScenario::default();
            car.noise.position_std = 0.0005 * noise;
            car.noise.yaw_std = 0.002 * noise;
            if perturb > 0.0 {
                car = car.perturbed(7000 + seed, perturb)?;
            }
            // the model a user has: physics fitted on nominal data of this car
            let nominal = car_dataset(&car, episodes, duration, 5000 + seed, threads)?;
            let tc = TrainConfig {
                kind: ModelKind::Physics,
                steps: train_steps,
                gamma: train_gamma,
                seed,
                physics_iterations: fit_iterations,
                physics_max_windows: fit_windows,
                physics_free: physics_free.clone(),
                ..TrainConfig::default()
            };
            let model = train(&nominal, &tc, &mut |_| {})?.model;
            if verbose
                && let (Some(fit), Ok(truth)) =
                    (model.physics(), true_car_model(&car.car, model.dt()))
                && let Some(tp) = truth.physics()
            {
                let row: Vec<String> = fit
                    .param_names()
                    .iter()
                    .zip(fit.params().iter().zip(tp.params()))
                    .map(|(n, (f, t))| format!("{n} {:+.1}%", 100.0 * (f / t - 1.0)))
                    .collect();
                println!(
                    "fitted nominal parameters against the car's: {}",
                    row.join(", ")
                );
            }
            let mut hidden = car.clone();
            for h in &case {
                h.apply(&mut hidden);
            }
            let data = car_dataset(&hidden, episodes, duration, 1000 + seed, threads)?;
            let cfg = DiagnoseConfig {
                seed,
                refit_nominal: refit.or(DiagnoseConfig::default().refit_nominal),
                refit_tolerance,
                ..DiagnoseConfig::default()
            };
            let d = diagnose(&model, &data, &cfg)?;
            // the true model's error on the same held-out windows (same split and subsample)
            let tcfg = DiagnoseConfig {
                effects: Some(Vec::new()),
                refit_nominal: Some(false),
                discover: false,
                ..cfg.clone()
            };
            let floor = match true_model(&hidden, &case, &model) {
                Some(m) => Some(diagnose(&m, &data, &tcfg)?.held_out_errors),
                None => None,
            };
            // with no library effect named, the discovered terms' share of the removable, on
            // the same held-out windows and in the same units as the floor
            let term_errors = match (
                &d.joint,
                d.discovery.as_ref().and_then(|x| x.effect.as_ref()),
            ) {
                (None, Some(e)) => match with_custom(&model, e) {
                    Some(m) => Some(diagnose(&m, &data, &tcfg)?.held_out_errors),
                    None => None,
                },
                _ => None,
            };
            let share = |before: f64, after: f64, floor: f64| {
                (before - after) / (before - floor).max(1e-12)
            };
            if let (Some(f), Some(j)) = (&floor, &d.joint) {
                let kept: Vec<f64> = (0..f.len())
                    .filter(|i| !j.spin_windows.contains(i))
                    .map(|i| f[i])
                    .collect();
                removable.push(share(j.model_error, j.error_after, mean(f)));
                removable_calm.push(share(j.model_error_calm, j.error_after_calm, mean(&kept)));
            } else if let (Some(f), Some(t)) = (&floor, &term_errors) {
                let base = mean(&d.held_out_errors);
                removable.push(share(base, mean(t), mean(f)));
                if verbose {
                    println!(
                        "the discovered terms: held-out error {:.4} → {:.4} ({:.1} % removed; true model {:.4}: {:.0} % of the removable)",
                        base,
                        mean(t),
                        100.0 * (1.0 - mean(t) / base),
                        mean(f),
                        100.0 * share(base, mean(t), mean(f))
                    );
                }
            } else if floor.is_some() && !case.is_empty() {
                removable.push(0.0);
                // the spin-free share is the selected effects' (none outside the library)
                if case.iter().all(|h| h.library().is_some()) {
                    removable_calm.push(0.0);
                }
            }
            if verbose {
                println!("--- {name}, seed {seed}\n{}", d.table());
                if let Some(f) = &floor {
                    println!(
                        "true model (simulator's parameters and effects): held-out error {:.4}",
                        mean(f)
                    );
                }
            }
            let got: BTreeSet<&str> = d.effects.iter().map(|s| s.as_str()).collect();
            ok += usize::from(got == truth);
            for g in got.difference(&truth) {
                wrong.insert(g.to_string());
            }
            if let Some(disc) = &d.discovery {
                let sig: Vec<_> = disc.terms.iter().filter(|t| t.significant).collect();
                if !sig.is_empty() {
                    beyond.push(disc.error_reduction);
                    let t = sig[0];
                    on_band += usize::from(
                        matches!(case[..], [Hidden::Band])
                            && t.state == Target::Grip.name()
                            && t.coefficient < 0.0
                            && over_low_grip_band(&t.feature),
                    );
                    for t in sig {
                        let key = format!(
                            "{} {} {}",
                            Target::from_name(&t.state).map_or(t.state.as_str(), |x| x.symbol()),
                            if t.coefficient < 0.0 { "−" } else { "+" },
                            t.symbol
                        );
                        *terms.entry(key).or_insert(0usize) += 1;
                    }
                }
            }
            if let Some(j) = &d.joint {
                removed.push(j.reduction_vs_model);
                removed_calm.push(j.reduction_vs_model_calm);
                for h in &case {
                    if let Some((_, key, _)) = h.library()
                        && let Some(v) = j.params.get(key)
                    {
                        strength.push((key, *v));
                    }
                }
            } else if let Some(t) = &term_errors {
                // what the discovered terms remove, every held-out window counted
                removed.push(1.0 - mean(t) / mean(&d.held_out_errors).max(1e-12));
            } else {
                removed.push(0.0);
                // the discovered terms' column has no spin-free counterpart: none for any seed
                if case.iter().any(|h| h.library().is_some()) {
                    removed_calm.push(0.0);
                }
            }
        }
        let spread = |v: &[f64]| {
            if v.is_empty() {
                return format!("{:>8} {:>7} {:>7}", "—", "—", "—");
            }
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            format!(
                "{:>7.0}% {:>6.0}% {:>6.0}%",
                100.0 * lo,
                100.0 * mean(v),
                100.0 * hi
            )
        };
        let mut fitted = Vec::new();
        for h in &case {
            if let Some((_, key, t)) = h.library() {
                let v: Vec<f64> = strength
                    .iter()
                    .filter(|(k, _)| *k == key)
                    .map(|(_, v)| *v)
                    .collect();
                if !v.is_empty() {
                    let m = v.iter().sum::<f64>() / v.len() as f64;
                    fitted.push(format!(
                        "{} {m:.4} ({t})",
                        key.split('.').nth(1).unwrap_or(key)
                    ));
                }
            }
        }
        if !removable.is_empty() {
            let min = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
            let calm = if removable_calm.is_empty() {
                String::new()
            } else {
                format!(
                    " (w/o spins {:.0} %, {:.0} %)",
                    100.0 * mean(&removable_calm),
                    100.0 * min(&removable_calm)
                )
            };
            fitted.push(format!(
                "of the error above the true model's: {:.0} % mean, {:.0} % min{calm}",
                100.0 * mean(&removable),
                100.0 * min(&removable),
            ));
        }
        if !beyond.is_empty() {
            let mut t: Vec<(String, usize)> = terms.into_iter().collect();
            t.sort_by_key(|x| std::cmp::Reverse(x.1));
            fitted.push(format!(
                "beyond the library in {}/{n}, {:.0} % more removed: {}",
                beyond.len(),
                100.0 * beyond.iter().sum::<f64>() / beyond.len() as f64,
                t.iter()
                    .take(4)
                    .map(|(k, c)| format!("{k} ×{c}"))
                    .collect::<Vec<_>>()
                    .join("; ")
            ));
        }
        if matches!(case[..], [Hidden::Band]) {
            fitted.push(format!("less grip over the band in {on_band}/{n}"));
        }
        if !wrong.is_empty() {
            fitted.push(format!(
                "named wrongly: {}",
                wrong.into_iter().collect::<Vec<_>>().join(", ")
            ));
        }
        println!(
            "{:<36} {:>5}/{:<3} {} {}   {:<44} {:>7.1}",
            name,
            ok,
            n,
            spread(&removed),
            spread(&removed_calm),
            fitted.join(", "),
            t0.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
